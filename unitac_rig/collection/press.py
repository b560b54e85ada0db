"""One force-terminated press: from the stand-off toward the object's centre, stop at the threshold, dwell, retract.

Before it: the move to the stand-off (``collection/transit.py``), the wrist F/T zeroed at rest on a pad checked
unloaded (``collection/wrist.py``), the tactile baseline. Then the rig file's ``press.strategy`` presses through the
seam of ``collection/strategy.py`` (controller-side force mode with a set-point just above the threshold, so a frozen
host cannot push past it), every control period through :meth:`~.safety_check.PressStreams.tick`, the checks of every
press whatever its strategy. After it: the dwell, the retract until the pad is unloaded, the move back to the
stand-off, the record. Every path out stops the arm (``guarded_motion`` and the ``finally`` blocks here), Ctrl-C
included, and whatever was recorded is kept.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable
from typing import Any, cast

import numpy as np

from drivers.arm import Arm, ArmState
from drivers.errors import ControlScriptStopped, DeviceError, DeviceTimeout, ProtectiveStop, RobotStateLost
from drivers.sensor import TactileSensor
from unitac_rig.collection.guarded_motion import move_to, stop_arm
from unitac_rig.collection.safety_check import OffAxisLimit, PressStreams, TickInfo, TravelLimit
from unitac_rig.collection.strategy import PressContext, press_strategy
from unitac_rig.collection.transit import (
    TRANSIT_ACCEL_M_S2,
    UNLOADED_FORCE_N,
    PressPlan,
    approach_legs,
    move_clear,
    transit_guard,
)
from unitac_rig.collection.wrist import UNLOADED_CHECK_S, rest, zero_wrist
from unitac_rig.errors import SafetyLimit, with_press_record
from unitac_rig.rig.config import LimitsConfig, PressConfig
from unitac_rig.storage.press_record import PressRecord

log = logging.getLogger(__name__)

# First contact is declared at max(contact_force_n, CONTACT_NOISE_SIGMAS x the press-force noise measured at the
# stand-off). A UR's wrist F/T has ~0.5 N of noise per 500 Hz sample even after its filter, so a fixed 1 N trigger
# fires on noise millimetres before the pad touches (every fast approach did on the simulated rig).
CONTACT_NOISE_SIGMAS = 4.5
RETRACT_UNLOADED_N = 0.3  # the retract ends once the mean press force of the last RETRACT_HOLD_PERIODS is below this
RETRACT_HOLD_PERIODS = 10  # ... (20 ms at 500 Hz) and none of them is above UNLOADED_FORCE_N, and 1 mm is gained


class ZeroedArm:
    """An :class:`Arm` whose force readings have a host-side offset removed (the mean over an unloaded window)."""

    def __init__(self, arm: Arm, offset: np.ndarray) -> None:
        self._arm = arm
        self.offset = np.asarray(offset, dtype=np.float64)

    def read_state(self) -> ArmState:
        state = self._arm.read_state()
        return state._replace(tcp_force=np.asarray(state.tcp_force, dtype=np.float64) - self.offset)

    def __getattr__(self, name: str) -> Any:
        return getattr(self._arm, name)


def run_press(
    arm: Arm,
    sensor: TactileSensor,
    plan: PressPlan,
    press: PressConfig,
    limits: LimitsConfig,
    *,
    on_tick: Callable[[TickInfo], None] | None = None,
    stall_timeout_s: float = 0.5,
    settle_s: float = 0.2,
    clearance_m: float = 0.09,
) -> PressRecord:
    """Do one press and return everything recorded (status complete, failed or aborted); the arm ends at rest at the
    stand-off.

    Raises SafetyLimit (hard force limit), ProtectiveStop, ControlScriptStopped, RobotStateLost and KeyboardInterrupt
    *after* stopping the arm, carrying the partial record in ``exc.press_record`` so the caller can keep it (Ctrl-C
    comes back as :class:`unitac_rig.errors.Interrupted`, a KeyboardInterrupt that carries it). A press that never
    touches anything ends ``aborted`` with reason ``no_contact`` (it is redone on resume, once the object is where it
    should be).
    """
    strategy = press_strategy(press.strategy)  # an unregistered name fails before the arm moves
    move_clear(arm, plan, clearance_m, press.transit_speed_mm_s / 1000.0, limits)
    rest(arm, sensor, press.rest_s)  # in free air at the stand-off, before the tare: the elastomer recovers
    frames, wrenches = zero_wrist(
        arm, sensor, settle_s, f"the stand-off of press {plan.press_id}", check_s=UNLOADED_CHECK_S
    )
    ft_offset = wrenches.mean(axis=0)
    arm = cast(Arm, ZeroedArm(arm, ft_offset))
    noise_n = float(np.std(-(wrenches[:, :3] @ plan.direction)))
    contact_threshold_n = max(press.contact_force_n, CONTACT_NOISE_SIGMAS * noise_n)
    if not frames:
        raise DeviceTimeout(f"{sensor.layout.name} sent no frames while settling before press {plan.press_id}")
    valid = [f for f in frames if f.valid] or frames
    stack = np.stack([f.values for f in valid]).astype(np.float64)
    # the median, not the mean: one frame damaged on the wire (a corrupt SLCAN line) must not shift the baseline
    baseline = np.median(stack, axis=0)
    tare = {"method": "host-median", "n_frames": len(valid), "spread": float(stack.std(axis=0).max())}

    streams = PressStreams(
        arm,
        sensor,
        plan,
        press,
        limits,
        stall_timeout_s,
        on_tick,
        contact_threshold_n,
        offset_along_press_n=float(np.dot(ft_offset[:3], plan.direction)),
    )
    streams.event("start", f"strategy={press.strategy} speed={press.speed_mm_s} mm/s")
    streams.event("contact_threshold", f"{contact_threshold_n:.2f} N (press-force noise {noise_n:.3f} N rms)")
    streams.event("ft_zero", "[" + ", ".join(f"{v:.4f}" for v in ft_offset) + "]")
    streams.event("tare", f"{tare['n_frames']} frames, spread {tare['spread']:.3g}")
    status, reason = "aborted", "interrupted"
    pending: BaseException | None = None
    try:
        reason = PressContext(arm, streams, plan, press, limits).run(strategy)
        status = "complete" if reason == "force" else ("aborted" if reason == "no_contact" else "failed")
        streams.event("stop", reason)
        streams.phase = "dwell"
        streams.hold(press.dwell_s)
        _back_off(arm, streams, plan, press)
    except TravelLimit as exc:
        status, reason = "failed", "off_axis" if isinstance(exc, OffAxisLimit) else "travel"
        streams.event("stop", f"{reason.replace('_', '-')} limit: {exc}")
        stop_arm(arm)
        try:
            _back_off(arm, streams, plan, press)
        except (TravelLimit, SafetyLimit, DeviceTimeout):  # ends the phase; the return to the stand-off follows
            stop_arm(arm)
    except (SafetyLimit, ProtectiveStop, DeviceError, KeyboardInterrupt) as exc:
        reason = next(why for kind, why in _ABORT_REASONS if isinstance(exc, kind))
        status, pending = "aborted", exc
        detail = "interrupted by the operator" if isinstance(exc, KeyboardInterrupt) else f"{reason}: {exc}"
        streams.event("abort", detail)
        if not isinstance(exc, ProtectiveStop | ControlScriptStopped):  # the controller has already stopped the arm
            stop_arm(arm)
    if pending is None:
        try:  # back out to the stand-off, so the next transit starts clear of the object
            streams.phase = "return"
            here = np.asarray(arm.read_state().tcp_pose, dtype=np.float64)
            for pose, speed in approach_legs(here, [plan.start_pose], plan, limits, press.transit_speed_mm_s / 1000.0):
                move_to(arm, pose, speed, TRANSIT_ACCEL_M_S2, on_period=streams.recording(transit_guard(arm, limits)))
        except BaseException as exc:
            pending = exc
    record = _to_record(streams, plan, press, status, reason, baseline, tare, ft_offset)
    if pending is not None:
        raise with_press_record(pending, record)  # the same exception (or Ctrl-C as Interrupted, caused by it)
    return record


# Why a press was aborted, by exception type; the first match wins (RobotStateLost and DeviceTimeout are
# DeviceErrors, RobotStateLost is also a DeviceTimeout).
_ABORT_REASONS: tuple[tuple[type[BaseException], str], ...] = (
    (SafetyLimit, "hard_limit"),
    (ProtectiveStop, "protective_stop"),
    (ControlScriptStopped, "program_stopped"),
    (RobotStateLost, "robot_state_lost"),
    (DeviceTimeout, "stall"),
    (DeviceError, "device_error"),
    (KeyboardInterrupt, "interrupted"),
)


def _back_off(arm: Arm, streams: PressStreams, plan: PressPlan, press: PressConfig) -> None:
    """The press's own retract phase: back off along the ray at ``press.retract_speed_mm_s``, still recording, until
    the pad is unloaded (a held, filtered condition: the mean of the last ``RETRACT_HOLD_PERIODS`` readings, not one
    noisy sample) and 1 mm back; then stop recording. Pulling away after an abort is
    :func:`unitac_rig.collection.transit.retract_from_object`."""
    streams.phase = "retract"
    speed = min(press.transit_speed_mm_s, press.retract_speed_mm_s) / 1000.0
    twist = np.concatenate([-plan.direction * speed, np.zeros(3)])
    start = np.asarray(arm.read_state().tcp_pose[:3])
    try:
        for _ in range(round(5.0 / arm.control_period_s)):
            arm.speed_linear(twist, 0.5)
            arm.wait_period()
            state = arm.read_state()
            streams.tick(state)
            back_mm = 1000.0 * float(np.dot(start - state.tcp_pose[:3], plan.direction))
            recent = streams.press_force[-RETRACT_HOLD_PERIODS:]
            if (
                back_mm > 1.0
                and len(recent) == RETRACT_HOLD_PERIODS
                and float(np.mean(recent)) < RETRACT_UNLOADED_N
                and max(recent) < UNLOADED_FORCE_N
            ):
                break
    finally:
        stop_arm(arm)
    streams.hold(0.02)


PEAK_WINDOW = 10  # the recorded peak is of |mean wrench| over this many readings (20 ms at 500 Hz)


def peak_force_magnitude_n(robot_force: np.ndarray) -> float:
    """The press's peak |F| (N) over all three force axes, of the wrench's moving mean over ``PEAK_WINDOW``
    readings: a UR's filtered reading still has ~0.4 N of noise per axis, whose extremes would add ~1.2 N to a peak
    of single readings; 20 ms is short against a press's stop and dwell (hundreds of ms), so the true peak is kept."""
    forces = np.asarray(robot_force, dtype=np.float64).reshape(-1, 6)[:, :3]
    if not forces.size:
        return 0.0
    window = min(PEAK_WINDOW, len(forces))
    sums = np.cumsum(np.vstack([np.zeros(3), forces]), axis=0)
    means = (sums[window:] - sums[:-window]) / window
    return float(np.linalg.norm(means, axis=1).max())


def contact_travel_mm(contact_pose: np.ndarray | None, plan: PressPlan) -> float:
    """Travel (mm) from the stand-off to where the press first felt the object (NaN: never): the stand-off distance
    when the object stands where the rig file says."""
    if contact_pose is None:
        return math.nan
    return 1000.0 * float(np.dot(np.asarray(contact_pose[:3]) - np.asarray(plan.start_pose[:3]), plan.direction))


def _to_record(
    streams: PressStreams,
    plan: PressPlan,
    press: PressConfig,
    status: str,
    reason: str,
    baseline: np.ndarray,
    tare: dict[str, Any],
    ft_offset: np.ndarray,
) -> PressRecord:
    frames = streams.frames
    layout = streams.sensor.layout
    n = len(frames)
    values = np.stack([f.values for f in frames]).astype(np.float32) if n else np.zeros((0, *layout.frame_shape))
    disp = None
    if layout.has_displacement:
        disp = np.zeros((n, *layout.frame_shape), np.float32)
        for i, f in enumerate(frames):
            if f.displacement_mm is not None:
                disp[i] = f.displacement_mm
    pf = np.asarray(streams.press_force)
    robot_force = np.asarray(streams.robot_force).reshape(-1, 6)
    peak = peak_force_magnitude_n(robot_force)
    t = np.asarray(streams.robot_t)
    return PressRecord(
        press_id=plan.press_id,
        rotation_deg=plan.rotation_deg,
        angle_deg=plan.angle_deg,
        status=status,
        reason=reason,
        robot_t_s=t,
        robot_force=robot_force,
        robot_pose=np.asarray(streams.robot_pose).reshape(-1, 6),
        press_force_n=pf,
        tactile_t_s=np.array([f.host_t_ns / 1e9 for f in frames]),
        tactile_values=values,
        tactile_seq=np.array([-1 if f.seq is None else f.seq for f in frames], dtype=np.int64),
        tactile_device_t_us=np.array([-1 if f.device_t_us is None else f.device_t_us for f in frames], np.int64),
        tactile_valid=np.array([f.valid for f in frames], dtype=bool),
        tactile_displacement_mm=disp,
        tare_baseline=baseline,
        events=streams.events,
        attrs={
            "strategy": press.strategy,
            "speed_mm_s": press.speed_mm_s,
            "fast_speed_mm_s": press.fast_speed_mm_s,
            "ramp_rate_n_s": press.ramp_rate_n_s,
            "threshold_n": press.threshold_n,
            "force_setpoint_n": press.threshold_n + press.setpoint_margin_n,
            "stop_samples": press.stop_samples,
            "contact_threshold_n": streams.contact_threshold_n,
            "peak_force_n": peak,  # |F| over every force axis: what the wrist felt
            "peak_press_force_n": float(pf.max()) if pf.size else 0.0,  # along the press axis only
            "overshoot_n": peak - press.threshold_n,
            "max_host_gap_s": streams.max_gap_s,
            "duration_s": float(t[-1] - t[0]) if t.size else 0.0,
            "ft_zero_offset": ft_offset.tolist(),
            "tare": tare,
            "contact_travel_mm": contact_travel_mm(streams.contact_pose, plan),
            "standoff_mm": 1000.0 * plan.contact_distance_m,  # where first contact was expected, mm
            "start_pose": np.asarray(plan.start_pose).tolist(),
            "direction": np.asarray(plan.direction).tolist(),
        },
    )
