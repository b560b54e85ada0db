"""One force-terminated press: approach along the ray toward the object's centre, stop at the threshold, dwell, retract.

Strategies (each press records which it used):

* ``guarded``: constant speed from the stand-off until the press force reaches the threshold (the paper's procedure);
* ``two-phase``: fast until first contact, then slow to the threshold (shorter presses, the same final approach);
* ``force-ramp``: fast until first contact, then force control whose set-point rises at a fixed rate (N/s), stopping
  when the measured force reaches the threshold (slow force rise = small force-matching error).

Safety on every path: a hard force limit, a travel limit beyond first contact (a soft object that never reaches the
threshold fails the press instead of crushing the object), a protective stop, or Ctrl-C all stop the arm
(``drivers.motion.guarded_move`` and the ``finally`` blocks here), and whatever was recorded is kept.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, cast

import numpy as np

from drivers.arm import Arm, ArmState
from drivers.errors import DeviceError, DeviceTimeout, ProtectiveStop
from drivers.frames import TactileFrame
from drivers.motion import guarded_move
from drivers.sensor import TactileSensor
from unitac_rig.errors import SafetyLimit
from unitac_rig.rig.config import LimitsConfig, PressConfig
from unitac_rig.rig.poses import approach_direction, pose_from, press_force_n, press_rotation
from unitac_rig.storage.press_record import PressRecord, press_id

log = logging.getLogger(__name__)

UNLOADED_FORCE_N = 3.0  # mean wrist force (since the last zero) below which the pad counts as unloaded, N
# First contact is declared at max(contact_force_n, CONTACT_NOISE_SIGMAS x the press-force noise measured at the
# stand-off). A UR's wrist F/T has ~0.5 N of noise per 500 Hz sample even after its filter, so a fixed 1 N trigger
# fires on noise millimetres before the pad touches (every fast approach did on the simulated rig).
CONTACT_NOISE_SIGMAS = 4.5
# Force ramp anti-windup: the set-point may lead the measured press force (mean of the last RAMP_MEAN_PERIODS
# control periods) by at most this, N. Without it a set-point ramping while nothing pushes back drives the
# admittance loop to its speed limit and the pad hits the object with the set-point already near the threshold.
RAMP_MAX_LEAD_N = 3.0
RAMP_MEAN_PERIODS = 10


class ZeroedArm:
    """An :class:`Arm` whose force readings have a host-side offset removed (the mean over an unloaded window)."""

    def __init__(self, arm: Arm, offset: np.ndarray) -> None:
        self._arm = arm
        self.offset = np.asarray(offset, dtype=np.float64)

    def read_state(self) -> ArmState:
        from dataclasses import replace

        state = self._arm.read_state()
        return replace(state, tcp_force=np.asarray(state.tcp_force, dtype=np.float64) - self.offset)

    def __getattr__(self, name: str) -> Any:
        return getattr(self._arm, name)


@dataclass(frozen=True)
class PressPlan:
    """Where one press starts and which way it goes (base frame)."""

    rotation_deg: float
    angle_deg: float
    start_pose: np.ndarray  # (6,) stand-off pose
    direction: np.ndarray  # (3,) unit press direction
    contact_distance_m: float  # expected travel from the stand-off to first contact
    center_xy_m: tuple[float, float] = (0.0, 0.0)  # the object axis the press aims at (base frame)

    @property
    def press_id(self) -> str:
        return press_id(self.rotation_deg, self.angle_deg)


def make_plan(
    rotation_deg: float,
    angle_deg: float,
    center_m: tuple[float, float],
    press_height_m: float,
    support_distance_mm: float,
    standoff_mm: float,
) -> PressPlan:
    """Stand-off pose on the ray at ``angle_deg``; ``support_distance_mm``: how far the object reaches to the pad."""
    u = approach_direction(angle_deg)
    distance_m = (support_distance_mm + standoff_mm) / 1000.0
    position = np.array([center_m[0], center_m[1], press_height_m]) + u * distance_m
    direction = -u
    return PressPlan(
        rotation_deg=rotation_deg,
        angle_deg=angle_deg,
        start_pose=pose_from(position, press_rotation(direction)),
        direction=direction,
        contact_distance_m=standoff_mm / 1000.0,
        center_xy_m=(float(center_m[0]), float(center_m[1])),
    )


def move_clear(arm: Arm, plan: PressPlan, clearance_m: float, speed_m_s: float) -> None:
    """Move to ``plan.start_pose`` without sweeping the pad through the object.

    A straight line between two press rays far apart (the last angle of one sweep and the first of the next, or a
    new object) would cut through the prism. So unless the arm is already on the plan's ray, it backs out radially to
    ``clearance_m`` from the object axis, crosses at that radius, and comes in along the new ray.
    """
    here = np.asarray(arm.read_state().tcp_pose, dtype=np.float64)
    target = np.asarray(plan.start_pose, dtype=np.float64)
    center = np.array([*plan.center_xy_m, target[2]])
    outward = -np.asarray(plan.direction, dtype=np.float64)
    offset = here[:3] - center
    radial = float(np.linalg.norm(offset[:2]))
    on_ray = radial > 1e-6 and float(np.dot(offset[:2] / radial, outward[:2])) > np.cos(np.radians(3.0))
    if not on_ray:
        if radial < clearance_m:
            out_dir = offset / radial if radial > 1e-6 else outward
            arm.move_linear(np.concatenate([center + out_dir * clearance_m, here[3:]]), speed_m_s, 0.5)
        arm.move_linear(np.concatenate([center + outward * clearance_m, target[3:]]), speed_m_s, 0.5)
    arm.move_linear(target, speed_m_s, 0.5)


@dataclass
class TickInfo:
    """What the live panel shows, handed to ``on_tick`` once per control period."""

    press_id: str
    phase: str
    press_force_n: float
    latest_frame: TactileFrame | None


class _TravelLimit(Exception):
    """Raised inside the control loop when the pad went too far past first contact."""


@dataclass
class _Streams:
    """Accumulates the robot and tactile streams of one press, one control period at a time."""

    arm: Arm
    sensor: TactileSensor
    plan: PressPlan
    press: PressConfig
    limits: LimitsConfig
    stall_timeout_s: float
    on_tick: Callable[[TickInfo], None] | None
    contact_threshold_n: float  # press force that counts as first contact, N (above the F/T noise)
    robot_t: list[float] = field(default_factory=list)
    robot_force: list[np.ndarray] = field(default_factory=list)
    robot_pose: list[np.ndarray] = field(default_factory=list)
    press_force: list[float] = field(default_factory=list)
    frames: list[TactileFrame] = field(default_factory=list)
    events: list[tuple[float, str, str]] = field(default_factory=list)
    phase: str = "approach"
    contact_pose: np.ndarray | None = None
    last_frame_ns: int | None = None

    def event(self, kind: str, detail: str = "") -> None:
        self.events.append((self.arm.clock.now_ns() / 1e9, kind, detail))

    def tick(self, state: ArmState) -> None:
        force = press_force_n(state.tcp_force, self.plan.direction)
        self.robot_t.append(state.host_t_ns / 1e9)
        self.robot_force.append(np.asarray(state.tcp_force, dtype=np.float64))
        self.robot_pose.append(np.asarray(state.tcp_pose, dtype=np.float64))
        self.press_force.append(force)
        new = self.sensor.poll()
        if new:
            self.frames.extend(new)
            self.last_frame_ns = new[-1].host_t_ns
        now = state.host_t_ns
        if self.last_frame_ns is None:
            self.last_frame_ns = now
        elif now - self.last_frame_ns > self.stall_timeout_s * 1e9:
            self.event("stall", f"no tactile frame for {(now - self.last_frame_ns) / 1e9:.3f} s")
            raise DeviceTimeout(f"{self.sensor.layout.name} stopped sending frames during press {self.plan.press_id}")
        if self.contact_pose is None and force >= self.contact_threshold_n:
            self.contact_pose = np.asarray(state.tcp_pose, dtype=np.float64)
            self.event("contact", f"{force:.2f} N")
        if self.contact_pose is not None and self.phase in ("approach", "press"):
            travel_mm = 1000.0 * float(np.dot(state.tcp_pose[:3] - self.contact_pose[:3], self.plan.direction))
            if travel_mm > self.limits.max_travel_after_contact_mm:
                raise _TravelLimit(f"{travel_mm:.1f} mm past first contact below {self.press.threshold_n} N")
        if force >= self.limits.hard_force_n:
            raise SafetyLimit(
                f"press force {force:.1f} N passed the hard limit {self.limits.hard_force_n} N "
                f"during press {self.plan.press_id}"
            )
        if self.on_tick is not None:
            self.on_tick(TickInfo(self.plan.press_id, self.phase, force, self.frames[-1] if self.frames else None))

    def hold(self, seconds: float) -> None:
        for _ in range(max(0, round(seconds / self.arm.control_period_s))):
            self.arm.wait_period()
            self.tick(self.arm.read_state())


def settle_frames(arm: Arm, sensor: TactileSensor, seconds: float) -> tuple[list[TactileFrame], np.ndarray]:
    """Wait ``seconds`` at rest; returns the frames seen and the mean wrench (6,) over the window (N, N*m).

    The mean, not the largest sample: a UR's F/T has ~1 N of sample noise, while a real contact shifts the mean.
    """
    frames, wrenches = _settle_window(arm, sensor, seconds)
    return frames, wrenches.mean(axis=0)


def _settle_window(arm: Arm, sensor: TactileSensor, seconds: float) -> tuple[list[TactileFrame], np.ndarray]:
    """Wait ``seconds`` at rest; -> (frames seen, every wrench read (K, 6) in N, N*m)."""
    sensor.poll()  # drop anything queued during the transit move
    frames: list[TactileFrame] = []
    forces = []
    for _ in range(max(1, round(seconds / arm.control_period_s))):
        arm.wait_period()
        forces.append(np.asarray(arm.read_state().tcp_force, dtype=np.float64))
        frames.extend(sensor.poll())
    return frames, np.asarray(forces)


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
    """Do one press and return everything recorded (status complete, failed or aborted).

    Raises SafetyLimit (hard force limit), ProtectiveStop and KeyboardInterrupt *after* stopping the arm; the partial
    record is attached to the exception as ``exc.press_record`` so the caller can keep it.
    """
    _check_workspace(plan.start_pose, limits)
    move_clear(arm, plan, clearance_m, press.transit_speed_mm_s / 1000.0)

    # Unloaded check, F/T zero and tare. The check uses the mean force since the previous zero (a UR's F/T drifts
    # by well under UNLOADED_FORCE_N between presses); after zeroing, the mean over a second window is kept as a
    # host-side offset, because a zero taken from one noisy sample is off by ~0.5 N.
    _, mean_wrench = settle_frames(arm, sensor, settle_s)
    mean_force = float(np.linalg.norm(mean_wrench[:3]))
    if mean_force > UNLOADED_FORCE_N:
        raise SafetyLimit(
            f"wrist reads {mean_force:.2f} N at the stand-off pose of press {plan.press_id}: the pad is touching "
            "something, refusing to tare",
            hint="check the object's position in the rig file and the stand-off",
        )
    arm.zero_ft()
    frames, wrenches = _settle_window(arm, sensor, settle_s)
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

    streams = _Streams(arm, sensor, plan, press, limits, stall_timeout_s, on_tick, contact_threshold_n)
    streams.event("start", f"strategy={press.strategy} speed={press.speed_mm_s} mm/s")
    streams.event("contact_threshold", f"{contact_threshold_n:.2f} N (press-force noise {noise_n:.3f} N rms)")
    streams.event("ft_zero", json_list(ft_offset))
    streams.event("tare", f"{tare['n_frames']} frames, spread {tare['spread']:.3g}")
    status, reason = "aborted", "interrupted"
    pending: BaseException | None = None
    try:
        reason = _press_strategy(arm, streams, plan, press, limits)
        status = "complete" if reason == "force" else "failed"
        streams.event("stop", reason)
        streams.phase = "dwell"
        streams.hold(press.dwell_s)
        streams.phase = "retract"
        _retract(arm, streams, plan, press)
    except _TravelLimit as exc:
        status, reason = "failed", "travel"
        streams.event("stop", f"travel limit: {exc}")
        _safe_stop(arm)
        _retract_quietly(arm, streams, plan, press)
    except (SafetyLimit, ProtectiveStop, DeviceError, KeyboardInterrupt) as exc:
        status, reason, pending = "aborted", _abort_reason(exc), exc
        detail = "interrupted by the operator" if isinstance(exc, KeyboardInterrupt) else f"{reason}: {exc}"
        streams.event("abort", detail)
        if not isinstance(exc, ProtectiveStop):  # the controller has already stopped the arm
            _safe_stop(arm)
    record = _to_record(streams, plan, press, status, reason, baseline, tare, ft_offset)
    if pending is not None:
        pending.press_record = record  # type: ignore[attr-defined]
        raise pending
    return record


# Why a press was aborted, by exception type; the first match wins (DeviceTimeout is a DeviceError).
_ABORT_REASONS: tuple[tuple[type[BaseException], str], ...] = (
    (SafetyLimit, "hard_limit"),
    (ProtectiveStop, "protective_stop"),
    (DeviceTimeout, "stall"),
    (DeviceError, "device_error"),
    (KeyboardInterrupt, "interrupted"),
)


def _abort_reason(exc: BaseException) -> str:
    return next(reason for kind, reason in _ABORT_REASONS if isinstance(exc, kind))


def json_list(values: np.ndarray) -> str:
    return "[" + ", ".join(f"{v:.4f}" for v in np.asarray(values).ravel()) + "]"


def _press_strategy(arm: Arm, streams: _Streams, plan: PressPlan, press: PressConfig, limits: LimitsConfig) -> str:
    """Run the configured strategy; returns the stop reason ("force", "travel")."""
    backstop_m = plan.contact_distance_m + (limits.max_travel_after_contact_mm + 5.0) / 1000.0
    if press.strategy == "guarded":
        streams.phase = "press"
        result = guarded_move(
            arm, plan.direction, press.speed_mm_s / 1000.0, press.threshold_n,
            max_travel_m=backstop_m, hard_limit_n=limits.hard_force_n, on_period=streams.tick,
        )  # fmt: skip
        return _reason(result.reason)
    # two-phase and force-ramp: fast to first contact
    streams.phase = "approach"
    result = guarded_move(
        arm, plan.direction, press.fast_speed_mm_s / 1000.0, streams.contact_threshold_n,
        max_travel_m=backstop_m, hard_limit_n=limits.hard_force_n, on_period=streams.tick,
    )  # fmt: skip
    if result.reason != "force":
        return _reason(result.reason)
    streams.phase = "press"
    if press.strategy == "two-phase":
        result = guarded_move(
            arm, plan.direction, press.speed_mm_s / 1000.0, press.threshold_n,
            max_travel_m=(limits.max_travel_after_contact_mm + 1.0) / 1000.0,
            hard_limit_n=limits.hard_force_n, on_period=streams.tick,
        )  # fmt: skip
        return _reason(result.reason)
    return _force_ramp(arm, streams, plan, press)


def _reason(guarded_reason: str) -> str:
    if guarded_reason == "hard_limit":
        raise SafetyLimit("press force passed the hard limit")
    if guarded_reason == "protective_stop":
        raise ProtectiveStop("the controller reported a protective stop")
    return guarded_reason


def _force_ramp(arm: Arm, streams: _Streams, plan: PressPlan, press: PressConfig) -> str:
    """Force control along the press with a set-point rising at ``ramp_rate_n_s`` until the threshold is measured.

    The set-point is rate-limited from the force at the start and never leads the measured press force (mean of the
    last ``RAMP_MEAN_PERIODS`` readings) by more than ``RAMP_MAX_LEAD_N``: while nothing pushes back (contact lost,
    or the approach stopped short) the pad creeps at gain x lead instead of winding up to the speed limit.
    """
    task_frame = np.asarray(plan.start_pose, dtype=np.float64)
    selection = np.array([0, 0, 1, 0, 0, 0], dtype=np.float64)  # compliant along tool z (the press direction)
    limits = np.array([0.01, 0.01, press.speed_mm_s / 1000.0 * 4, 0.1, 0.1, 0.1])
    setpoint = streams.press_force[-1] if streams.press_force else press.contact_force_n
    step_n = press.ramp_rate_n_s * arm.control_period_s
    max_periods = math.ceil((press.threshold_n / press.ramp_rate_n_s + 5.0) / arm.control_period_s)
    try:
        for _ in range(max_periods):
            measured = float(np.mean(streams.press_force[-RAMP_MEAN_PERIODS:])) if streams.press_force else 0.0
            setpoint = min(setpoint + step_n, measured + RAMP_MAX_LEAD_N, press.threshold_n * 1.2)
            arm.force_mode(task_frame, selection, np.array([0, 0, setpoint, 0, 0, 0.0]), limits)
            arm.wait_period()
            state = arm.read_state()
            streams.tick(state)
            if state.protective_stop:
                raise ProtectiveStop("protective stop during force control")
            if streams.press_force[-1] >= press.threshold_n:
                return "force"
        return "travel"
    finally:
        arm.force_mode_stop()
        arm.stop()


def _retract(arm: Arm, streams: _Streams, plan: PressPlan, press: PressConfig) -> None:
    """Back off along the ray, still recording, until unloaded and clear of the contact point; then stop recording."""
    speed = min(press.transit_speed_mm_s, 4 * press.speed_mm_s) / 1000.0
    arm.speed_linear(np.concatenate([-plan.direction * speed, np.zeros(3)]), 0.5)
    try:
        start = np.asarray(arm.read_state().tcp_pose[:3])
        for _ in range(round(5.0 / arm.control_period_s)):
            arm.wait_period()
            state = arm.read_state()
            streams.tick(state)
            back_mm = 1000.0 * float(np.dot(start - state.tcp_pose[:3], plan.direction))
            if streams.press_force[-1] < 0.1 and back_mm > 1.0:
                break
    finally:
        arm.stop()
    streams.hold(0.02)


def _retract_quietly(arm: Arm, streams: _Streams, plan: PressPlan, press: PressConfig) -> None:
    streams.phase = "retract"
    try:
        _retract(arm, streams, plan, press)
    except (_TravelLimit, SafetyLimit, DeviceTimeout):
        _safe_stop(arm)


def _safe_stop(arm: Arm) -> None:
    try:
        arm.stop()
    except Exception:  # the arm may already be stopped or in a protective stop; stopping is best effort here
        log.exception("stopping the arm failed")


def _check_workspace(pose: np.ndarray, limits: LimitsConfig) -> None:
    lo, hi = np.asarray(limits.workspace_min_m), np.asarray(limits.workspace_max_m)
    p = np.asarray(pose[:3])
    if np.any(p < lo) or np.any(p > hi):
        raise SafetyLimit(
            f"start pose {np.round(p, 4).tolist()} m is outside the workspace box {lo.tolist()}..{hi.tolist()}",
            hint="check [object] center_m / press_height_m and [limits] workspace in the rig file",
        )


def _to_record(
    streams: _Streams,
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
    peak = float(pf.max()) if pf.size else 0.0
    t = np.asarray(streams.robot_t)
    return PressRecord(
        press_id=plan.press_id,
        rotation_deg=plan.rotation_deg,
        angle_deg=plan.angle_deg,
        status=status,
        reason=reason,
        robot_t_s=t,
        robot_force=np.asarray(streams.robot_force).reshape(-1, 6),
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
            "peak_force_n": peak,
            "overshoot_n": peak - press.threshold_n,
            "duration_s": float(t[-1] - t[0]) if t.size else 0.0,
            "ft_zero_offset": ft_offset.tolist(),
            "tare": tare,
            "start_pose": np.asarray(plan.start_pose).tolist(),
            "direction": np.asarray(plan.direction).tolist(),
        },
    )
