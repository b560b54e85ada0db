"""A collection session: every planned press of one object with one sensor, resumable, into one session file.

The plan is 91 approach angles (-45..45 deg) per object rotation (four rotations for the irregular prism). Presses
already finished in the session file (complete or failed) are skipped, so the same command resumes after a crash,
a Ctrl-C, a termination signal or a protective stop. Library code: no printing; progress goes through callbacks the
CLI renders.

Before the first motion the whole plan is checked (:func:`~unitac_rig.collection.transit.check_session_plan`).

The session stops instead of carrying on blind on a protective stop, a stopped controller program, a lost robot state
stream, a hard force limit, or ``limits.max_failed_in_a_row`` presses in a row that do not complete (the object is
missing, misplaced or not what the rig file says); only a sensor that stalls or drops off is reconnected and its press
retried, once. After any abort, Ctrl-C and the termination signals included, the arm retracts from where it is
(:func:`~unitac_rig.collection.transit.retract_from_object`). While the host writes a press or waits for the
operator, :meth:`Arm.keep_alive` feeds the controller's watchdog. :func:`dry_run` visits every stand-off and
clearance waypoint without pressing.
"""

from __future__ import annotations

import contextlib
import logging
import math
import time
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from drivers.arm import Arm
from drivers.errors import ArmError, ControlScriptStopped, DeviceError, DeviceTimeout, ProtectiveStop
from drivers.sensor import TactileSensor
from unitac_rig.collection.guarded_motion import settle
from unitac_rig.collection.press import run_press
from unitac_rig.collection.safety_check import TickInfo
from unitac_rig.collection.transit import (
    PressPlan,
    check_session_plan,
    make_plan,
    move_clear,
    retract_from_object,
    transit_guard,
    with_standoff,
)
from unitac_rig.collection.wrist import Unloaded, load_left_note, read_zero, unload_wrist, write_zero, zero_wrist
from unitac_rig.errors import CarriesPressRecord, SafetyLimit, UnitacError
from unitac_rig.interrupts import acknowledged_interrupts, raise_if_interrupted
from unitac_rig.provenance import git_commit, package_version
from unitac_rig.rig.base import Rig
from unitac_rig.rig.config import LimitsConfig, RigConfig
from unitac_rig.rig.objects import ObjectSpec, pad_side_direction
from unitac_rig.storage.extraction import ExtractionSettings, extract_press
from unitac_rig.storage.press_record import PressRecord
from unitac_rig.storage.recorder import SessionWriter

log = logging.getLogger(__name__)

PLACEMENT_CONFIRMED_MM = 5.0  # a first contact this close to where expected confirms the object's placement, mm
SAFETY_BITS_WAIT_S = 0.1  # a stopped program is watched this long for the safety bits of a safety stop, s
RECONNECT_WAIT_S = 3.0  # how long a lost sensor may take to come back (USB replug, controller reboot), s
RECONNECT_POLL_S = 0.25  # pause between reconnect attempts, s
DRY_RUN_HOLD_S = 0.2  # a dry run rests this long at each stand-off, s
PROGRAM_STOPPED_HINT = (
    "the RTDE watchdog stops it when this computer sends nothing in time (a frozen or overloaded host, a cut cable); "
    "the arm is at rest: check the pendant's log and that the pad is clear, then run the same command again to resume"
)
PROTECTIVE_STOP_HINT = (
    "on the teach pendant: unlock the protective stop (if the pad still presses on something, move the arm clear in "
    "freedrive first), then run the same command again to resume"
)


@dataclass
class SessionOutcome:
    object_id: str
    sensor: str
    path: Path
    planned: int
    already_done: int = 0
    complete: int = 0
    failed: int = 0
    aborted: int = 0
    stopped: str | None = None  # why the session ended early, if it did
    recovery_notes: list[str] = field(default_factory=list)
    failure_streak: int = 0  # presses in a row so far that did not complete
    # the wrist reading (6,) right after the session's last unloaded zero (collection/wrist.py): what "unloaded"
    # reads, to say the load every way out of a fault leaves on the pad
    wrist_zero: np.ndarray | None = None
    last_reason: str | None = None  # how the last press of this run ended ("aborted: no_contact", ...)


@dataclass
class PressDone:
    """Handed to ``on_press`` after each press is recorded."""

    index: int
    planned: int
    record: PressRecord
    matched: int


def support_distance_mm(obj: ObjectSpec, rotation_deg: float, angle_deg: float) -> float:
    """How far the object's outline reaches from its axis toward the pad (mm): the first-contact distance."""
    u = pad_side_direction(angle_deg, rotation_deg)
    return float(np.max(np.asarray(obj.outer_mm) @ u))


def plan_presses(obj: ObjectSpec, config: RigConfig, rotations: Sequence[float]) -> list[PressPlan]:
    placement = config.object
    return [
        make_plan(
            rotation,
            angle,
            placement.center_m,
            placement.press_height_m,
            support_distance_mm(obj, rotation, angle),
            placement.standoff_mm,
        )
        for rotation in rotations
        for angle in config.angles_deg()
    ]


def collect_session(
    rig: Rig,
    obj: ObjectSpec,
    sensor_name: str,
    data_dir: Path,
    *,
    rotations: Sequence[float] | None = None,
    extraction: ExtractionSettings | None = None,
    on_press: Callable[[PressDone], None] | None = None,
    on_tick: Callable[[TickInfo], None] | None = None,
    ask_operator: Callable[[str], None] | None = None,
    max_presses: int | None = None,
) -> SessionOutcome:
    """Run (or resume) the session of ``obj`` with ``sensor_name`` on ``rig``; returns what happened."""
    config = rig.config
    extraction = extraction or ExtractionSettings()
    rotations = list(obj.rotations_deg if rotations is None else rotations)
    plans = plan_presses(obj, config, rotations)
    root_attrs = session_attrs(rig, obj, sensor_name, rotations, plans, extraction)
    writer = SessionWriter(data_dir, obj.id, sensor_name, root_attrs)
    done = writer.finished_press_ids()
    outcome = SessionOutcome(obj.id, sensor_name, writer.path, planned=len(plans), recovery_notes=writer.recovery_notes)
    outcome.already_done = sum(p.press_id in done for p in plans)
    outcome.wrist_zero = read_zero(writer.journal)  # a resume after a crash: the last unloaded zero it knew
    todo = [p for p in plans if p.press_id not in done]
    if max_presses is not None:
        todo = todo[:max_presses]
    if not todo:
        return outcome

    # At rest the driver holds the watchdog at a 10 s window (drivers/ur5e.py), so set-up cannot trip it; the slow
    # steps before the first press (opening a port, rewriting the session file on resume) still run kept alive, for
    # one that takes longer than that (a slow disk, a device that does not answer).
    try:
        arm = rig.arm
        check_session_plan(
            arm.read_state().tcp_pose,
            todo,
            config.object.clearance_mm / 1000.0,
            config.limits,
            confirmed_standoff_mm(config),
        )
        with _kept_alive(arm):  # python-can's slcan alone waits 2 s after opening the port
            sensor = rig.open_sensor(sensor_name)
    except BaseException:
        writer.discard_if_unused()  # a missing port must not leave an empty session file behind
        raise
    pressing = False
    try:
        try:
            with _kept_alive(arm):
                writer.update_root_attrs({"sensor_identity": sensor.identity(), "layout": sensor.layout.name})
            rig.mount(obj, todo[0].rotation_deg, sensor_name)
            tare = _first_move_and_tare(rig, sensor, todo[0], outcome)
            with _kept_alive(arm):  # republishes the session file (moves a single-file session's presses out first)
                writer.update_root_attrs({"session_tare": tare})
                outcome.wrist_zero = np.asarray(tare["ft_zero_offset"], dtype=np.float64)
                write_zero(writer.journal, outcome.wrist_zero)
            pressing = True
            run = _Run(rig, obj, sensor, sensor_name, writer, extraction, outcome, on_tick)
            run.press_all(todo, on_press, ask_operator, len(rotations))
        except BaseException as exc:
            if not pressing:
                writer.discard_if_unused()  # nor may an arm or sensor that fails before the first press
            _say_load_left(rig, exc, outcome)
            raise
        if outcome.stopped is None and outcome.complete == 0 and outcome.failed + outcome.aborted > 0:
            outcome.stopped = _not_completing(
                config,
                obj,
                f"no press completed ({outcome.failed} failed, {outcome.aborted} aborted; the last "
                f"{outcome.last_reason})",
            )
        if outcome.stopped is not None:
            outcome.stopped += load_left_note(rig.arm, outcome.wrist_zero)
    finally:
        sensor.disconnect()
    return outcome


@dataclass
class _Run:
    """One run of a session once the sensor is open and the first stand-off tared: the presses of ``todo``."""

    rig: Rig
    obj: ObjectSpec
    sensor: TactileSensor
    sensor_name: str
    writer: SessionWriter
    extraction: ExtractionSettings
    outcome: SessionOutcome
    on_tick: Callable[[TickInfo], None] | None

    def press_all(
        self,
        todo: list[PressPlan],
        on_press: Callable[[PressDone], None] | None,
        ask_operator: Callable[[str], None] | None,
        n_rotations: int,
    ) -> None:
        """Every press of ``todo`` in order, the object turned between rotations; stops as :func:`collect_session`
        says."""
        rig, obj, outcome = self.rig, self.obj, self.outcome
        config = rig.config
        current_rotation: float | None = None
        previous: PressPlan | None = None
        stop = False
        confirmed = False  # a press has found the object where the rig file says (since the last turn)
        limit = config.limits.max_failed_in_a_row
        for index, plan in enumerate(todo):
            raise_if_interrupted()
            if plan.rotation_deg != current_rotation:
                confirmed = False  # the placement is unknown again after the object is turned
                if previous is not None:  # out to the clearance radius before anyone turns the object by hand
                    retract_from_object(rig.arm, previous, rig.config)
                rig.mount(obj, plan.rotation_deg, self.sensor_name)
                if ask_operator is not None and not rig.simulated and n_rotations > 1:
                    with rig.arm.keep_alive():
                        ask_operator(f"Turn {obj.id} to {plan.rotation_deg:g} deg on its mount, then press Enter.")
                current_rotation = plan.rotation_deg
            if confirmed:  # the object stands where measured: a shorter free-air approach (and return to it)
                plan = with_standoff(plan, confirmed_standoff_mm(config))
            record, stop = self.one_press(plan, moves_limits(config, confirmed))
            previous = plan
            confirmed = confirmed or (record is not None and placement_confirmed(record, config))
            if on_press is not None and record is not None:
                matched = 0 if record.extraction is None else record.extraction.n_matched
                with rig.arm.keep_alive():
                    on_press(PressDone(outcome.already_done + index + 1, outcome.planned, record, matched))
            if record is not None:
                outcome.failure_streak = outcome.failure_streak + 1 if record.status != "complete" else 0
                outcome.last_reason = record_reason(record)
            if outcome.failure_streak >= limit:
                last = f"the last: {plan.press_id}, {record_reason(record)}"
                outcome.stopped = _not_completing(config, obj, f"{limit} presses in a row did not complete ({last})")
                break
            if stop:
                break
        if previous is not None and not stop:  # the stops above retracted already; the operator swaps things next
            retract_from_object(rig.arm, previous, rig.config, best_effort=True)  # out to the clearance radius

    def one_press(self, plan: PressPlan, limits: LimitsConfig) -> tuple[PressRecord | None, bool]:
        """Run one press and record it; also says whether the session must stop.

        A sensor that stalls or drops off the bus/port mid-press aborts the press (kept, marked ``aborted``); the
        sensor is reconnected and the press retried once. A second failure, or a sensor that does not come back,
        stops the session cleanly (the arm backed off to the stand-off). Safety stops, a stopped controller program,
        a lost robot state stream and Ctrl-C are re-raised after saving; a protective stop with what to do on the
        pendant.
        """
        rig, sensor, outcome = self.rig, self.sensor, self.outcome
        config = rig.config
        for attempt in (1, 2):
            try:
                record = run_press(
                    rig.arm,
                    sensor,
                    plan,
                    config.press,
                    limits,
                    on_tick=self.on_tick,
                    clearance_m=config.object.clearance_mm / 1000.0,
                )
            except (SafetyLimit, ProtectiveStop, ArmError, KeyboardInterrupt) as exc:
                partial = self.save_partial(exc)
                if isinstance(exc, KeyboardInterrupt):
                    outcome.stopped = f"interrupted at press {plan.press_id}"
                    with acknowledged_interrupts():  # a second Ctrl-C still ends the retract, arm stopped
                        retract_from_object(rig.arm, plan, rig.config, to_clearance=False, best_effort=True)
                    raise
                if isinstance(exc, SafetyLimit):
                    retract_from_object(rig.arm, plan, rig.config, best_effort=True)
                outcome.stopped = f"{type(exc).__name__} at press {plan.press_id}: {exc}"
                explained = _controller_stop_explained(rig, exc, f"at press {plan.press_id}")
                if explained is not exc:
                    explained.press_record = partial  # type: ignore[attr-defined]
                    raise explained from exc
                raise
            except DeviceError as exc:  # the sensor stalled (DeviceTimeout) or its link failed (port/bus gone)
                partial = self.save_partial(exc)
                what = "stalled" if isinstance(exc, DeviceTimeout) else "failed"
                retract_from_object(rig.arm, plan, rig.config, best_effort=True)
                if attempt == 1:
                    log.warning("%s; reconnecting the sensor and retrying the press once", exc)
                    try:
                        with rig.arm.keep_alive():
                            _reconnect(rig, sensor)
                    except DeviceError as again:
                        outcome.stopped = f"sensor {what} at press {plan.press_id} and did not come back: {again}"
                        return partial, True
                    outcome.recovery_notes.append(f"press {plan.press_id}: sensor {what} ({exc}); reconnected, retried")
                    continue
                outcome.stopped = f"sensor {what} twice at press {plan.press_id}: {exc}"
                return partial, True
            with rig.arm.keep_alive():
                self.save(record)
            return record, False
        return None, True

    def save_partial(self, exc: BaseException) -> PressRecord | None:
        """Keep what an aborted press recorded (carried by ``exc``); -> that record, None when it carries none."""
        partial = exc.press_record if isinstance(exc, CarriesPressRecord) else None
        if partial is not None:
            with _kept_alive(self.rig.arm):  # the arm is stopped; writing may take longer than the watchdog allows
                self.save(partial)
        return partial

    def save(self, record: PressRecord) -> None:
        """Write one press (its sensor health and, unless off-axis, its extraction with it) and count it."""
        outcome = self.outcome
        try:  # what the link lost so far (checksum errors, gaps, invalid frames...), kept with the press
            record.attrs.setdefault("sensor_health", self.sensor.health().as_dict())
        except DeviceError as exc:
            log.info("no sensor health for press %s: %s", record.press_id, exc)
        # a press off the object's face never feeds extraction (collection/safety_check.py)
        if record.reason != "off_axis":
            record.extraction = extract_press(
                record.robot_t_s, record.press_force_n, record.tactile_t_s, record.tactile_valid, self.extraction
            )
        self.writer.write_press(record)
        if "ft_zero_offset" in record.attrs:  # the press zeroed an unloaded wrist (zero_wrist refuses a loaded one)
            outcome.wrist_zero = np.asarray(record.attrs["ft_zero_offset"], dtype=np.float64)
            write_zero(self.writer.journal, outcome.wrist_zero)
        if record.status == "complete":
            outcome.complete += 1
        elif record.status == "failed":
            outcome.failed += 1
        else:
            outcome.aborted += 1


def _say_load_left(rig: Rig, exc: BaseException, outcome: SessionOutcome) -> None:
    """Add the load the pad is left under to a fault's one line (a project error's message; else the log), so every
    way out of a fault says whether the pad still presses on something."""
    note = load_left_note(rig.arm, outcome.wrist_zero)
    if not note:
        return
    if isinstance(exc, UnitacError) and exc.args and isinstance(exc.args[0], str):
        exc.args = (exc.args[0] + note, *exc.args[1:])
    else:  # Ctrl-C and the signals taken like it: the CLI adds it to the line saying what was kept
        exc.load_note = note  # type: ignore[attr-defined]
        log.info("the session stopped (%s)%s", type(exc).__name__, note)
    if outcome.stopped is not None:
        outcome.stopped += note


def session_attrs(
    rig: Rig,
    obj: ObjectSpec,
    sensor_name: str,
    rotations: Sequence[float],
    plans: Sequence[PressPlan],
    extraction: ExtractionSettings,
) -> dict[str, Any]:
    """The session file's root attributes: what was planned, with which rig, settings and code."""
    config = rig.config
    imperfections = getattr(rig, "imperfections", None)  # the simulated rig's (sim/imperfections.py)
    twin = {"sim_imperfections": imperfections.text} if rig.simulated and imperfections is not None else {}
    return {
        "object": obj.id,
        "sensor": sensor_name,
        "simulated": rig.simulated,
        **twin,
        "rig": config.name,
        "config": config.model_dump(mode="json"),
        "object_spec": {"id": obj.id, "shape": obj.shape, "material": obj.material, "outer_mm": obj.outer_mm},
        "rotations_deg": [float(r) for r in rotations],
        "planned_presses": [p.press_id for p in plans],
        "extraction_settings": extraction.to_dict(),
        "package_version": package_version(),
        "git_commit": git_commit(),
        "created_unix": time.time(),
    }


def _not_completing(config: RigConfig, obj: ObjectSpec, what: str) -> str:
    """Why a run whose presses do not complete stops (one line): ``what`` happened, and where to look."""
    return (
        f"{what}: is {obj.id} mounted at object.center_m = {list(config.object.center_m)}, press_height_m = "
        f"{config.object.press_height_m} as the rig file says, and is it the object named?"
    )


def _first_move_and_tare(rig: Rig, sensor: TactileSensor, first: PressPlan, outcome: SessionOutcome) -> dict[str, Any]:
    """:func:`session_tare`, retracting from where the arm is if the first move or the zero is aborted (the pad
    touched something on the way: the object is not where the rig file says). A pad found loaded at the start is
    noted in ``outcome.recovery_notes``."""
    try:
        free = unload_wrist(rig.arm, rig.config.limits, zero=outcome.wrist_zero)
        outcome.wrist_zero = free.free_reading  # what unloaded reads now, for the load a fault leaves
        if free.was_loaded:
            outcome.recovery_notes.append(free.describe())
        return session_tare(rig, sensor, first, free=free)
    except KeyboardInterrupt:
        with acknowledged_interrupts():
            retract_from_object(rig.arm, first, rig.config, to_clearance=False, best_effort=True)
        raise
    except (SafetyLimit, DeviceError) as exc:
        retract_from_object(rig.arm, first, rig.config, best_effort=True)
        raise _controller_stop_explained(rig, exc, f"before the first press ({first.press_id})") from exc


def _controller_stop_explained(rig: Rig, exc: BaseException, where: str) -> BaseException:
    """A protective stop or a stopped program as one line saying what happened and what to do (else ``exc``).

    A safety stop stops the program too, and the program's state can arrive before the safety bits: a stopped
    program is named a protective stop when :func:`_safety_stopped` sees the bits."""
    if isinstance(exc, ControlScriptStopped) and not isinstance(exc, ProtectiveStop) and _safety_stopped(rig):
        exc = ProtectiveStop(f"the program stopped in a safety stop ({exc})")
    if isinstance(exc, ProtectiveStop):
        return ProtectiveStop(f"protective stop {where} ({exc})", hint=PROTECTIVE_STOP_HINT)
    if isinstance(exc, ControlScriptStopped):
        return ControlScriptStopped(f"the controller's program stopped {where} ({exc})", hint=PROGRAM_STOPPED_HINT)
    return exc


def moves_limits(config: RigConfig, confirmed: bool) -> LimitsConfig:
    """The limits a press's moves run under: the rig file's, with the near zone shrunk to
    ``limits.near_zone_confirmed_mm`` once a press has confirmed the object's placement."""
    if not confirmed:
        return config.limits
    return config.limits.model_copy(update={"near_zone_mm": config.limits.near_zone_confirmed_mm})


def placement_confirmed(record: PressRecord, config: RigConfig) -> bool:
    """Whether a press found the object where the rig file says: complete, and first contact within
    ``PLACEMENT_CONFIRMED_MM`` of the press's stand-off distance. Then the near zone of the moves can shrink to
    ``limits.near_zone_confirmed_mm`` (docs/real-rig.md) and the stand-off to :func:`confirmed_standoff_mm`."""
    travel = float(record.attrs.get("contact_travel_mm", math.nan))
    expected = float(record.attrs.get("standoff_mm", config.object.standoff_mm))
    return record.status == "complete" and abs(travel - expected) <= PLACEMENT_CONFIRMED_MM


def confirmed_standoff_mm(config: RigConfig) -> float:
    """The stand-off (mm) once the placement is confirmed: ``press.confirmed_standoff_mm``, never below
    ``limits.min_standoff_mm`` nor above ``object.standoff_mm``."""
    return max(config.limits.min_standoff_mm, min(config.press.confirmed_standoff_mm, config.object.standoff_mm))


def record_reason(record: PressRecord | None) -> str:
    """How a press ended, for a one-line message (e.g. 'failed: settled')."""
    return "not recorded" if record is None else f"{record.status}: {record.reason}"


def session_tare(rig: Rig, sensor: TactileSensor, first: PressPlan, *, free: Unloaded | None = None) -> dict[str, Any]:
    """Zero the wrist F/T and tare the sensor (device bias where it has one) at the first stand-off pose.

    Never on a loaded wrist: before any motion toward the object the pad backs off along its axis until the reading
    stops changing (:func:`~unitac_rig.collection.wrist.unload_wrist`; ``free``: what a back-off the caller ran
    found, with the session's remembered unloaded reading), and the zero at the stand-off
    is refused when the reading there is more than ``UNLOADED_FORCE_N`` off the free one (the object stands closer
    than the rig file says). The dict holds the tare, ``ft_zero_offset`` (the reading after the zero: the new
    unloaded zero) and ``unloaded_at_start_n`` (the load found at the start, 0 when none).
    """
    config = rig.config
    free = free if free is not None else unload_wrist(rig.arm, config.limits)
    move_clear(
        rig.arm, first, config.object.clearance_mm / 1000.0, config.press.transit_speed_mm_s / 1000.0, config.limits
    )
    frames, wrenches = zero_wrist(
        rig.arm, sensor, 0.3, f"the first stand-off ({first.press_id})", reference=free.free_reading
    )
    with rig.arm.keep_alive():  # a device bias waits for the sensor to settle; the arm rests meanwhile
        record = sensor.tare(frames)
    sensor.poll()  # frames from during a device bias are not kept
    return {
        "method": record.method,
        "n_frames": record.n_frames,
        "spread": record.spread,
        "baseline": np.asarray(record.baseline).tolist(),
        "host_t_s": record.host_t_ns / 1e9,
        "ft_zero_offset": wrenches.mean(axis=0).tolist(),
        "unloaded_at_start_n": free.load_n if free.was_loaded else 0.0,
        "unloaded_note": free.describe() if free.was_loaded else "",
    }


def _safety_stopped(rig: Rig) -> bool:
    """Whether the controller is in a protective or emergency stop now (False when it cannot be read).

    A safety stop stops the program too, and the program's state can arrive before the safety bits (two RTDE
    streams): so a stopped program is looked at for up to SAFETY_BITS_WAIT_S before it counts as a plain stop."""
    deadline_ns = rig.clock.now_ns() + round(SAFETY_BITS_WAIT_S * 1e9)
    while True:
        try:
            state = rig.arm.read_state()
        except DeviceError:
            return False
        if state.protective_stop or state.emergency_stop:
            return True
        if rig.clock.now_ns() >= deadline_ns:
            return False
        rig.clock.sleep(0.004)


@contextlib.contextmanager
def _kept_alive(arm: Arm) -> Iterator[None]:
    """``arm.keep_alive()`` around non-motion work while the arm rests (opening a port, writing the file); if the arm
    cannot (closed, controller gone), the work still runs: keeping the press matters more than the watchdog of an
    arm that is stopped anyway."""
    with contextlib.ExitStack() as stack:
        try:
            stack.enter_context(arm.keep_alive())
        except DeviceError as exc:
            log.info("no watchdog keep-alive while saving: %s", exc)
        yield


def _reconnect(rig: Rig, sensor: TactileSensor) -> None:
    """Close and reopen the sensor's transport, trying for up to RECONNECT_WAIT_S (rig clock) before giving up."""
    deadline_ns = rig.clock.now_ns() + round(RECONNECT_WAIT_S * 1e9)
    while True:
        try:
            reconnect = getattr(sensor, "reconnect", None)
            if callable(reconnect):
                reconnect()  # keeps a bus the driver owns (disconnect() would shut it down for good)
            else:
                sensor.disconnect()
                sensor.connect()
            return
        except DeviceError as exc:
            if rig.clock.now_ns() >= deadline_ns:
                raise
            log.info("sensor not back yet (%s); retrying in %.2f s", exc, RECONNECT_POLL_S)
            raise_if_interrupted()  # a deferred Ctrl-C ends the wait (interrupts.py)
            rig.clock.sleep(RECONNECT_POLL_S)


@dataclass
class DryRunOutcome:
    """What a dry run visited: stand-off poses and all waypoints (clearance ones included)."""

    standoffs: int = 0
    waypoints: int = 0


def dry_run(
    rig: Rig,
    obj: ObjectSpec,
    *,
    rotations: Sequence[float] | None = None,
    on_standoff: Callable[[PressPlan, int, int], None] | None = None,
) -> DryRunOutcome:
    """Move through every stand-off and clearance waypoint of the session's plan without pressing or recording.

    For the first run on a new rig, with the object removed: every waypoint is checked against the workspace and the
    arm's reach before it is sent, and every move is watched as in a real session (a touch stops it). Waits
    ``DRY_RUN_HOLD_S`` at each stand-off. ``on_standoff(plan, index, total)`` after each.
    """
    config = rig.config
    plans = plan_presses(obj, config, list(obj.rotations_deg if rotations is None else rotations))
    arm: Arm = rig.arm
    outcome = DryRunOutcome()
    speed = config.press.transit_speed_mm_s / 1000.0
    clearance = config.object.clearance_mm / 1000.0
    check_session_plan(arm.read_state().tcp_pose, plans, clearance, config.limits, confirmed_standoff_mm(config))
    for index, plan in enumerate(plans):
        outcome.waypoints += move_clear(arm, plan, clearance, speed, config.limits)
        settle(arm, DRY_RUN_HOLD_S, on_period=transit_guard(arm, config.limits))
        outcome.standoffs += 1
        if on_standoff is not None:
            with arm.keep_alive():
                on_standoff(plan, index + 1, len(plans))
    return outcome
