"""A collection session: every planned press of one object with one sensor, resumable, into one session file.

The plan is 91 approach angles (-45..45 deg) per object rotation (four rotations for the irregular prism). Presses
already finished in the session file (complete or failed) are skipped, so the same command resumes after a crash,
a Ctrl-C or a protective stop. Library code: no printing; progress goes through callbacks the CLI renders.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from drivers.errors import ArmError, DeviceError, DeviceTimeout, ProtectiveStop
from drivers.sensor import TactileSensor
from unitac_rig.collection.press import PressPlan, TickInfo, make_plan, move_clear, run_press, settle_frames
from unitac_rig.errors import SafetyLimit
from unitac_rig.provenance import git_commit, package_version
from unitac_rig.rig.base import Rig
from unitac_rig.rig.config import RigConfig
from unitac_rig.rig.objects import ObjectSpec, pad_side_direction
from unitac_rig.storage.extraction import ExtractionSettings, extract_press
from unitac_rig.storage.press_record import PressRecord
from unitac_rig.storage.recorder import SessionWriter

log = logging.getLogger(__name__)

RECONNECT_WAIT_S = 3.0  # how long a lost sensor may take to come back (USB replug, controller reboot), s
RECONNECT_POLL_S = 0.25  # pause between reconnect attempts, s


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

    @property
    def finished(self) -> bool:
        return self.stopped is None


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
    root_attrs: dict[str, Any] = {
        "object": obj.id,
        "sensor": sensor_name,
        "simulated": rig.simulated,
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
    writer = SessionWriter(data_dir, obj.id, sensor_name, root_attrs)
    done = writer.finished_press_ids()
    outcome = SessionOutcome(obj.id, sensor_name, writer.path, planned=len(plans), recovery_notes=writer.recovery_notes)
    outcome.already_done = sum(p.press_id in done for p in plans)
    todo = [p for p in plans if p.press_id not in done]
    if max_presses is not None:
        todo = todo[:max_presses]
    if not todo:
        return outcome

    try:
        sensor = rig.open_sensor(sensor_name)
    except BaseException:
        writer.discard_if_unused()  # a missing port must not leave an empty session file behind
        raise
    try:
        try:
            writer.update_root_attrs({"sensor_identity": sensor.identity(), "layout": sensor.layout.name})
            rig.mount(obj, todo[0].rotation_deg, sensor_name)
            writer.update_root_attrs({"session_tare": _session_tare(rig, sensor, todo[0])})
        except BaseException:
            writer.discard_if_unused()  # nor may an arm or sensor that fails before the first press
            raise
        current_rotation: float | None = None
        for index, plan in enumerate(todo):
            if plan.rotation_deg != current_rotation:
                rig.mount(obj, plan.rotation_deg, sensor_name)
                if ask_operator is not None and not rig.simulated and len(rotations) > 1:
                    ask_operator(f"Turn {obj.id} to {plan.rotation_deg:g} deg on its mount, then press Enter.")
                current_rotation = plan.rotation_deg
            record, stop = _one_press(rig, sensor, plan, writer, extraction, outcome, on_tick)
            if on_press is not None and record is not None:
                matched = 0 if record.extraction is None else record.extraction.n_matched
                on_press(PressDone(outcome.already_done + index + 1, outcome.planned, record, matched))
            if stop:
                break
    finally:
        sensor.disconnect()
    return outcome


def _session_tare(rig: Rig, sensor: TactileSensor, first: PressPlan) -> dict[str, Any]:
    """Zero the wrist F/T and tare the sensor (device bias where it has one) at the first stand-off pose.

    The stand-off is clear of the object by construction (the object's outline plus the stand-off gap), so this is
    the one moment the session can assume the pad is unloaded without a previous zero to check against.
    """
    move_clear(rig.arm, first, rig.config.object.clearance_mm / 1000.0, rig.config.press.transit_speed_mm_s / 1000.0)
    rig.arm.zero_ft()
    frames, _ = settle_frames(rig.arm, sensor, 0.3)
    record = sensor.tare(frames)
    sensor.poll()  # frames from during a device bias are not kept
    return {
        "method": record.method,
        "n_frames": record.n_frames,
        "spread": record.spread,
        "baseline": np.asarray(record.baseline).tolist(),
        "host_t_s": record.host_t_ns / 1e9,
    }


def _one_press(
    rig: Rig,
    sensor: TactileSensor,
    plan: PressPlan,
    writer: SessionWriter,
    extraction: ExtractionSettings,
    outcome: SessionOutcome,
    on_tick: Callable[[TickInfo], None] | None,
) -> tuple[PressRecord | None, bool]:
    """Run one press and record it; also says whether the session must stop.

    A sensor that stalls or drops off the bus/port mid-press aborts the press (kept, marked ``aborted``); the sensor
    is reconnected and the press retried once. A second failure, or a sensor that does not come back, stops the
    session cleanly (the arm backed off to the stand-off). Safety stops and Ctrl-C are re-raised after saving.
    """
    config = rig.config
    for attempt in (1, 2):
        try:
            record = run_press(
                rig.arm, sensor, plan, config.press, config.limits, on_tick=on_tick,
                clearance_m=config.object.clearance_mm / 1000.0,
            )  # fmt: skip
        except (SafetyLimit, ProtectiveStop, ArmError, KeyboardInterrupt) as exc:
            partial = getattr(exc, "press_record", None)
            if partial is not None:
                _save(writer, sensor, partial, extraction, outcome)
            if isinstance(exc, KeyboardInterrupt):
                outcome.stopped = f"interrupted at press {plan.press_id}"
                raise
            if isinstance(exc, SafetyLimit):
                _back_off(rig, plan)
            outcome.stopped = f"{type(exc).__name__} at press {plan.press_id}: {exc}"
            raise
        except DeviceError as exc:  # the sensor stalled (DeviceTimeout) or its link failed (port/bus gone)
            partial = getattr(exc, "press_record", None)
            if partial is not None:
                _save(writer, sensor, partial, extraction, outcome)
            what = "stalled" if isinstance(exc, DeviceTimeout) else "failed"
            _back_off(rig, plan)
            if attempt == 1:
                log.warning("%s; reconnecting the sensor and retrying the press once", exc)
                try:
                    _reconnect(rig, sensor)
                except DeviceError as again:
                    outcome.stopped = f"sensor {what} at press {plan.press_id} and did not come back: {again}"
                    return partial, True
                outcome.recovery_notes.append(f"press {plan.press_id}: sensor {what} ({exc}); reconnected, retried")
                continue
            outcome.stopped = f"sensor {what} twice at press {plan.press_id}: {exc}"
            return partial, True
        _save(writer, sensor, record, extraction, outcome)
        return record, False
    return None, True


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
            rig.clock.sleep(RECONNECT_POLL_S)


def _back_off(rig: Rig, plan: PressPlan) -> None:
    """Move back to the press's stand-off after an abort, so a stopped session never leaves the pad loaded."""
    try:
        rig.arm.move_linear(plan.start_pose, rig.config.press.transit_speed_mm_s / 1000.0, 0.5)
    except Exception:  # best effort: the arm may be in a protective stop; the next run starts with the same move
        log.exception("backing off to the stand-off of press %s failed", plan.press_id)


def _save(
    writer: SessionWriter,
    sensor: TactileSensor,
    record: PressRecord,
    settings: ExtractionSettings,
    outcome: SessionOutcome,
) -> None:
    try:  # what the link lost so far (checksum errors, gaps, invalid frames...), kept with the press
        record.attrs.setdefault("sensor_health", sensor.health().as_dict())
    except DeviceError as exc:
        log.info("no sensor health for press %s: %s", record.press_id, exc)
    record.extraction = extract_press(
        record.robot_t_s, record.press_force_n, record.tactile_t_s, record.tactile_valid, settings
    )
    writer.write_press(record)
    if record.status == "complete":
        outcome.complete += 1
    elif record.status == "failed":
        outcome.failed += 1
    else:
        outcome.aborted += 1
