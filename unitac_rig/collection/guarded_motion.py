"""The press's force policy and every other motion of a session, on top of :class:`drivers.arm.Arm`: watched moves
(:func:`move_to`), the guarded, force-terminated move (:func:`guarded_move`), settling, stopping. Policy, not I/O:
the driver only carries the commands.

Every motion here is started and then watched one control period at a time (``wait_period`` also feeds the
controller's watchdog), and every way out (a reached condition, an exception from a callback or the arm, Ctrl-C, a
second Ctrl-C during the stop) stops the arm before it returns or raises.

"Press force" along a unit direction d is ``-dot(F[:3], d)`` (N): ``tcp_force`` is what the environment exerts on the
tool, which points against the press.
"""

from __future__ import annotations

import logging
import math
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from typing import Literal

import numpy as np

from drivers.arm import Arm, ArmState
from drivers.errors import ArmError, ControlScriptStopped, ProtectiveStop
from drivers.rotations import angle_between, matrix_to_rotvec
from unitac_rig.rig.poses import press_force_n

logger = logging.getLogger(__name__)

StopReason = Literal["force", "travel", "timeout", "hard_limit", "protective_stop", "settled"]

REST_SPEED_M_S = 0.0005  # below 0.5 mm/s the TCP counts as at rest
DEFAULT_SETTLE_S = 0.05  # after rest: covers F/T latency (<= 20 ms) + 3 time constants of an 8 ms filter
STOP_GRACE_S = 0.5  # extra time allowed for the arm to come to rest beyond v / decel
MOVE_GRACE_S = 2.0  # a watched move may take this much longer than its trapezoid before it counts as stuck
MOVE_TOLERANCE_M = 2e-4  # a finished move must end within 0.2 mm ...
MOVE_TOLERANCE_RAD = 2e-3  # ... and 2 mrad of its target
ARRIVED_PERIODS = 5  # at rest on the target this many periods = arrived, even if the controller's progress word lags
CATCH_UP_S = 0.2  # after the progress word says finished, the pose may take this long to show it (two RTDE streams)
# Force mode: largest deviation the controller allows on the non-compliant axes (URScript force_mode ``limits``
# for those axes), m and rad.
FORCE_MODE_DEVIATION_M = 0.005
FORCE_MODE_DEVIATION_RAD = 0.05
# A force-mode press whose force stops rising below the threshold ("settled": the controller's regulated reading and
# the host's differ by more than the set-point margin) is noticed within PLATEAU_S: the pad moved less than
# PLATEAU_TRAVEL_M along the press and the mean press force of the window's second half is within PLATEAU_RISE_N of
# its first half, with the force above half the threshold (in contact). The set-point then rises by
# PLATEAU_STEP_N, up to the ceiling the caller allows; at the ceiling the move ends with reason "settled".
PLATEAU_S = 0.3
PLATEAU_TRAVEL_M = 5e-5
PLATEAU_RISE_N = 0.1
PLATEAU_STEP_N = 0.5


@dataclass(frozen=True)
class GuardedMoveResult:
    """How a guarded move ended.

    ``trigger_state``: the state on which the stop condition was seen. ``peak_press_force_n``: the largest press force
    read during the move and its stopping transient (N). ``travel_m``: distance along the direction from the start to
    the final rest pose (m). ``stop_pose``: (6,) pose at rest.
    """

    reason: StopReason
    trigger_state: ArmState
    peak_press_force_n: float
    travel_m: float
    stop_pose: np.ndarray


def press_force(state: ArmState, direction: np.ndarray) -> float:
    """Press force (N) along the unit ``direction``: positive while the tool pushes into something."""
    return press_force_n(state.tcp_force, direction)


def force_magnitude(state: ArmState) -> tuple[float, float]:
    """(|F| in N over all three force axes, |T| in N*m over the three torque axes)."""
    wrench = np.asarray(state.tcp_force, dtype=np.float64)
    return float(np.linalg.norm(wrench[:3])), float(np.linalg.norm(wrench[3:6]))


def check_controller(state: ArmState, what: str) -> None:
    """Raise if the controller stopped on its own: ProtectiveStop (safety stop) or ControlScriptStopped."""
    if state.protective_stop or state.emergency_stop:
        kind = "an emergency" if state.emergency_stop else "a protective"
        raise ProtectiveStop(f"{kind} stop during {what}")
    if not state.program_running:
        raise ControlScriptStopped(f"the control program stopped during {what}")


def move_to(
    arm: Arm,
    pose: np.ndarray,
    speed_m_s: float,
    accel_m_s2: float,
    *,
    on_period: Callable[[ArmState], None] | None = None,
) -> ArmState:
    """Straight-line move to ``pose``, started asynchronously and watched every control period; -> the state at rest.

    ``on_period`` sees every state and may raise to stop the move (the arm is stopped, the error propagates).
    Raises ProtectiveStop / ControlScriptStopped if the controller stops, ArmError if the move does not finish in
    time or ends away from ``pose`` (0.2 mm, 2 mrad).
    """
    target = np.asarray(pose, dtype=np.float64).reshape(-1)
    start = arm.read_state()
    distance = float(np.linalg.norm(target[:3] - np.asarray(start.tcp_pose[:3])))
    budget_s = _trapezoid_s(distance, speed_m_s, accel_m_s2) + MOVE_GRACE_S
    arm.start_move_linear(target, speed_m_s, accel_m_s2)
    try:
        arrived = 0
        for _ in range(max(1, math.ceil(budget_s / arm.control_period_s))):
            arm.wait_period()
            state = arm.read_state()
            check_controller(state, "a move")  # first: after a host freeze, a stopped program explains the rest
            if on_period is not None:
                on_period(state)
            finished = not arm.move_running()
            arrived = arrived + 1 if _on_target(state, target) and _resting(state) else 0
            if arrived >= ARRIVED_PERIODS or (finished and _on_target(state, target)):
                break
            if finished:
                # The progress word comes with the control client's RTDE stream, the pose with the receive client's:
                # the first can be a few periods ahead. Read on until the pose has caught up (or time runs out).
                state = _catch_up(arm, target, on_period)
                break
        else:
            raise ArmError(f"a move to {np.round(target[:3], 4).tolist()} m did not finish within {budget_s:.1f} s")
        if not finished:
            _end_arrived_move(arm)
        if not _on_target(state, target):  # whatever ended it, nothing may go on moving
            off_mm = 1000 * float(np.linalg.norm(np.asarray(state.tcp_pose[:3]) - target[:3]))
            raise ArmError(f"a move ended {off_mm:.1f} mm from its target {np.round(target[:3], 4).tolist()} m")
    except BaseException:
        stop_arm(arm)
        raise
    return state


def _end_arrived_move(arm: Arm) -> None:
    """A move that arrived by the pose while the controller's progress word still shows it: wait a few periods for
    the word, then stop it. Either way the driver sees the motion over, so nothing stays commanded (and a UR's
    watchdog leaves its tight window: a move left "running" kept it tight through the host's work at rest, which
    tripped it ~0.17 s after every session's last retract, issue 37)."""
    for _ in range(ARRIVED_PERIODS):
        arm.wait_period()
        if not arm.move_running():
            return
    arm.stop()


def _check_arguments(
    speed_m_s: float,
    max_travel_m: float,
    accels_m_s2: tuple[float, float],
    stop_samples: int,
    forces_n: tuple[float, float],
    force_setpoint_n: float | None,
    ceiling_n: float | None,
) -> None:
    """:func:`guarded_move`'s arguments checked before the arm moves: ArmError naming the first that is nonsense.
    ``forces_n``: (threshold, hard limit); ``ceiling_n``: the force-mode set-point ceiling, N."""
    threshold_n, hard_n = forces_n
    setpoint_n = force_setpoint_n
    for bad, message in (
        (not speed_m_s > 0, f"speed must be > 0 m/s, got {speed_m_s}"),
        (not max_travel_m > 0, f"travel limit must be > 0 m, got {max_travel_m}"),
        (not min(accels_m_s2) > 0, "accelerations must be > 0 m/s^2"),
        (stop_samples < 1, f"stop_samples must be >= 1, got {stop_samples}"),
        (not 0 < threshold_n < hard_n, f"needs 0 < threshold ({threshold_n} N) < hard limit ({hard_n} N)"),
        (
            setpoint_n is not None and not 0 < setpoint_n < hard_n,
            f"force set-point {setpoint_n} N must be within (0, {hard_n}) N",
        ),
        (
            setpoint_n is not None and ceiling_n is not None and not setpoint_n <= ceiling_n < hard_n,
            f"set-point ceiling {ceiling_n} N must be within [set-point, {hard_n}) N",
        ),
    ):
        if bad:
            raise ArmError(
                f"guarded move {message}", hint="check the press threshold and the force limits in the rig file"
            )


@dataclass(frozen=True)
class _StopRule:
    """When a guarded move ends, judged on every reading (see :func:`guarded_move`): forces N, torque N*m, travel m,
    duration s."""

    threshold_n: float
    hard_limit_n: float
    hard_torque_nm: float | None
    stop_samples: int
    max_travel_m: float
    max_duration_s: float | None

    def run(
        self,
        arm: Arm,
        command: _SpeedCommand | _ForceCommand,
        unit: np.ndarray,
        start_position: np.ndarray,
        on_period: Callable[[ArmState], None] | None,
        peak: float,
    ) -> tuple[StopReason, ArmState, float]:
        """Command the motion every period until a stop condition; -> (reason, state that triggered it, peak)."""
        recent: deque[float] = deque(maxlen=self.stop_samples)
        periods_left = math.inf if self.max_duration_s is None else self.max_duration_s / arm.control_period_s
        plateau = _Plateau(arm.control_period_s, self.threshold_n) if isinstance(command, _ForceCommand) else None
        while True:
            periods_left -= 1
            try:
                command()
            except ProtectiveStop:
                return "protective_stop", arm.read_state(), peak
            arm.wait_period()
            state = arm.read_state()
            force = press_force(state, unit)
            peak = max(peak, force)
            recent.append(force)
            if on_period is not None:
                on_period(state)
            if state.protective_stop or state.emergency_stop:
                return "protective_stop", state, peak
            check_controller(state, "a guarded move")
            magnitude, torque = force_magnitude(state)
            if magnitude >= self.hard_limit_n or (self.hard_torque_nm is not None and torque >= self.hard_torque_nm):
                return "hard_limit", state, peak
            if len(recent) == self.stop_samples and sum(recent) / self.stop_samples >= self.threshold_n:
                return "force", state, peak
            travel = float(np.dot(np.asarray(state.tcp_pose[:3]) - start_position, unit))
            if travel > self.max_travel_m:
                return "travel", state, peak
            if plateau is not None and plateau.settled(sum(recent) / len(recent), travel):
                if not command.raise_setpoint():
                    return "settled", state, peak
                plateau.reset()
            if periods_left <= 0:
                return "timeout", state, peak


def guarded_move(
    arm: Arm,
    direction: np.ndarray,
    speed_m_s: float,
    force_threshold_n: float,
    *,
    max_travel_m: float,
    hard_limit_n: float,
    accel_m_s2: float = 0.5,
    stop_decel_m_s2: float = 10.0,
    on_period: Callable[[ArmState], None] | None = None,
    settle_s: float = DEFAULT_SETTLE_S,
    force_setpoint_n: float | None = None,
    stop_samples: int = 1,
    hard_torque_nm: float | None = None,
    max_duration_s: float | None = None,
    setpoint_ceiling_n: float | None = None,
    keep_moving: bool = False,
) -> GuardedMoveResult:
    """Move along ``direction`` at ``speed_m_s`` until the press force reaches ``force_threshold_n``.

    ``force_setpoint_n``: run in controller-side force mode, compliant along ``direction`` with this force set-point
    (N, a little above the threshold, as the controller measures it) and ``speed_m_s`` as the speed limit: the
    controller regulates the contact force by itself, so a host that stalls mid-press cannot push it much past the
    set-point; the host only decides when to end the press. None: a plain ``speedL`` every period (for moves where
    nothing can be crushed). The stop rule takes the mean of the last ``stop_samples`` readings (one noise spike
    does not end a press early); the hard limit acts on any single reading of |F| (all force axes) or |T|.
    ``setpoint_ceiling_n``: in force mode, how far the set-point may be raised when the force settles below the
    threshold (see ``PLATEAU_S``); at the ceiling such a move ends with reason "settled" instead of waiting for
    ``max_duration_s``. None: the set-point is never raised (a plateau still ends the move, "settled").
    ``max_duration_s``: give up after this long (reason "timeout"): in force mode a set-point that the filtered
    force never quite reaches would otherwise hold the pad there for good, travelling nowhere.
    Also stops when the travel along the direction exceeds ``max_travel_m`` (reason "travel"), any single reading
    has |F| >= ``hard_limit_n`` or |T| >= ``hard_torque_nm`` ("hard_limit") or the controller reports a protective
    stop ("protective_stop"); the caller decides what each reason means. ``on_period`` sees every state read, the
    stopping transient included (it may raise to abort; the arm is still stopped). After the arm is at rest,
    reading goes on for ``settle_s`` so a lagging F/T reading reaches its peak. Raises ArmError for nonsensical
    arguments, ControlScriptStopped if the controller's program stops (the watchdog after a host stall).
    ``keep_moving``: when the move ends on the force threshold, return at once without stopping the arm, so the
    caller goes straight on with the next guarded move (a two-phase press switches from its fast to its slow speed
    limit without stopping and starting again). Meanwhile the controller goes on regulating the last command: in
    force mode that is still bounded by the set-point. Every other way out stops the arm as usual.
    """
    unit = _unit_direction(direction)
    ceiling_n = force_setpoint_n if setpoint_ceiling_n is None else setpoint_ceiling_n
    forces_n = (force_threshold_n, hard_limit_n)
    _check_arguments(
        speed_m_s, max_travel_m, (accel_m_s2, stop_decel_m_s2), stop_samples, forces_n, force_setpoint_n, ceiling_n
    )

    start_state = arm.read_state()
    start_position = np.asarray(start_state.tcp_pose[:3], dtype=np.float64)
    command: _SpeedCommand | _ForceCommand = _SpeedCommand(arm, unit, speed_m_s, accel_m_s2)
    if force_setpoint_n is not None:
        command = _ForceCommand(arm, unit, start_position, speed_m_s, force_setpoint_n, ceiling_n or force_setpoint_n)
    peak = press_force(start_state, unit)

    stop_sent = False
    try:
        rule = _StopRule(force_threshold_n, hard_limit_n, hard_torque_nm, stop_samples, max_travel_m, max_duration_s)
        reason: StopReason = "protective_stop"
        trigger = start_state
        if not (start_state.protective_stop or start_state.emergency_stop):
            reason, trigger, peak = rule.run(arm, command, unit, start_position, on_period, peak)
        if keep_moving and reason == "force":
            stop_sent = True  # nothing to stop: the next guarded move takes over within one control period
            travel = float(np.dot(np.asarray(trigger.tcp_pose[:3]) - start_position, unit))
            return GuardedMoveResult(reason, trigger, peak, travel, np.asarray(trigger.tcp_pose, dtype=np.float64))
        arm.stop(stop_decel_m_s2)
        stop_sent = True
        final, peak = _ride_out_stop(arm, unit, speed_m_s, stop_decel_m_s2, settle_s, on_period, peak)
    finally:
        if not stop_sent:
            stop_arm(arm, stop_decel_m_s2)
    travel = float(np.dot(np.asarray(final.tcp_pose[:3]) - start_position, unit))
    logger.debug("guarded move stopped (%s): peak %.2f N, travel %.2f mm", reason, peak, travel * 1e3)
    return GuardedMoveResult(reason, trigger, peak, travel, np.asarray(final.tcp_pose, dtype=np.float64).copy())


def press_frame(position: np.ndarray, direction: np.ndarray) -> np.ndarray:
    """A task frame (6,) [x, y, z (m), rotation vector (rad)] at ``position`` whose z axis is ``direction``."""
    z = _unit_direction(direction)
    helper = np.array([0.0, 0.0, 1.0]) if abs(z[2]) < 0.9 else np.array([1.0, 0.0, 0.0])
    x = np.cross(helper, z)
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    return np.concatenate([np.asarray(position, dtype=np.float64), matrix_to_rotvec(np.column_stack([x, y, z]))])


def send_force_mode(arm: Arm, frame: np.ndarray, setpoint_n: float, speed_m_s: float) -> None:
    """One force-mode command: compliant along the task ``frame``'s z toward ``setpoint_n`` (N) at most at
    ``speed_m_s``; on the other axes the controller holds position within the ``FORCE_MODE_DEVIATION_*`` limits."""
    d, r = FORCE_MODE_DEVIATION_M, FORCE_MODE_DEVIATION_RAD
    selection = np.array([0, 0, 1, 0, 0, 0], dtype=np.float64)
    arm.force_mode(
        frame, selection, np.array([0.0, 0.0, setpoint_n, 0.0, 0.0, 0.0]), np.array([d, d, speed_m_s, r, r, r])
    )


class _SpeedCommand:
    """speedL along the direction, sent every period (moves where nothing can be crushed)."""

    def __init__(self, arm: Arm, unit: np.ndarray, speed_m_s: float, accel_m_s2: float) -> None:
        self._arm, self._accel = arm, accel_m_s2
        self._twist = np.concatenate([unit * speed_m_s, np.zeros(3)])

    def __call__(self) -> None:
        self._arm.speed_linear(self._twist, self._accel)

    def raise_setpoint(self) -> bool:
        return False


class _ForceCommand:
    """forceMode along the direction with a set-point the host may raise (up to ``ceiling_n``) when the force
    settles below the threshold; the controller regulates toward whatever was sent last, host stalled or not."""

    def __init__(
        self, arm: Arm, unit: np.ndarray, position: np.ndarray, speed_m_s: float, setpoint_n: float, ceiling_n: float
    ) -> None:
        self._arm, self._frame, self._speed_m_s = arm, press_frame(position, unit), speed_m_s
        self.setpoint_n, self.ceiling_n = setpoint_n, ceiling_n

    def __call__(self) -> None:
        send_force_mode(self._arm, self._frame, self.setpoint_n, self._speed_m_s)

    def raise_setpoint(self) -> bool:
        """Raise the set-point one step toward the ceiling; False when it is already there."""
        if self.setpoint_n >= self.ceiling_n - 1e-9:
            return False
        self.setpoint_n = min(self.setpoint_n + PLATEAU_STEP_N, self.ceiling_n)
        logger.info("press force settled below the threshold: force set-point raised to %.2f N", self.setpoint_n)
        return True


class _Plateau:
    """Tells a force that has stopped rising below the threshold (see ``PLATEAU_S``) from one still loading."""

    def __init__(self, period_s: float, threshold_n: float) -> None:
        self._size = max(4, round(PLATEAU_S / period_s))
        self._forces: deque[float] = deque(maxlen=self._size)
        self._travel: deque[float] = deque(maxlen=self._size)
        self._floor_n = 0.5 * threshold_n

    def reset(self) -> None:
        self._forces.clear()
        self._travel.clear()

    def settled(self, force_n: float, travel_m: float) -> bool:
        self._forces.append(force_n)
        self._travel.append(travel_m)
        if len(self._forces) < self._size:
            return False
        forces = np.asarray(self._forces)
        half = self._size // 2
        rise = float(forces[half:].mean() - forces[:half].mean())
        moved = abs(self._travel[-1] - self._travel[0])
        return bool(forces.mean() > self._floor_n and rise < PLATEAU_RISE_N and moved < PLATEAU_TRAVEL_M)


def _ride_out_stop(
    arm: Arm,
    unit: np.ndarray,
    speed_m_s: float,
    decel_m_s2: float,
    settle_s: float,
    on_period: Callable[[ArmState], None] | None,
    peak: float,
) -> tuple[ArmState, float]:
    """Keep reading while the arm decelerates and for ``settle_s`` after it rests; -> (last state, peak)."""
    period = arm.control_period_s
    max_stop_periods = int((speed_m_s / decel_m_s2 + STOP_GRACE_S) / period) + 1
    settle_periods = max(0, round(settle_s / period))
    state = arm.read_state()
    previous_position = np.asarray(state.tcp_pose[:3], dtype=np.float64)
    rest_periods = 0
    for _ in range(max_stop_periods + settle_periods):
        arm.wait_period()
        state = arm.read_state()
        peak = max(peak, press_force(state, unit))
        if on_period is not None:
            on_period(state)
        position = np.asarray(state.tcp_pose[:3], dtype=np.float64)
        rest_periods = rest_periods + 1 if _at_rest(state, position, previous_position, period) else 0
        previous_position = position
        if rest_periods > settle_periods:
            return state, peak
    logger.warning("the arm was still moving %.2f s after the stop command", max_stop_periods * period)
    return state, peak


def _catch_up(arm: Arm, target: np.ndarray, on_period: Callable[[ArmState], None] | None) -> ArmState:
    """After the controller reported a move finished: read until the state shows the arm on the target and at rest,
    at most ``CATCH_UP_S``; -> the last state."""
    state = arm.read_state()
    for _ in range(max(1, round(CATCH_UP_S / arm.control_period_s))):
        if _on_target(state, target) and _resting(state):
            break
        arm.wait_period()
        state = arm.read_state()
        if on_period is not None:
            on_period(state)
        check_controller(state, "a move")
    return state


def _at_rest(state: ArmState, position: np.ndarray, previous: np.ndarray, period_s: float) -> bool:
    if state.tcp_speed is not None:
        speed = float(np.linalg.norm(np.asarray(state.tcp_speed)[:3]))
    else:
        speed = float(np.linalg.norm(position - previous)) / period_s
    return speed < REST_SPEED_M_S


def _resting(state: ArmState) -> bool:
    return state.tcp_speed is None or float(np.linalg.norm(np.asarray(state.tcp_speed)[:3])) < REST_SPEED_M_S


def _on_target(state: ArmState, target: np.ndarray) -> bool:
    pose = np.asarray(state.tcp_pose, dtype=np.float64)
    if float(np.linalg.norm(pose[:3] - target[:3])) > MOVE_TOLERANCE_M:
        return False
    return angle_between(pose[3:], target[3:]) <= MOVE_TOLERANCE_RAD


def settle(arm: Arm, duration_s: float, on_period: Callable[[ArmState], None] | None = None) -> ArmState:
    """Wait ``duration_s`` one control period at a time, reading (and reporting) every state; -> the last state."""
    state = arm.read_state()
    for _ in range(max(0, round(duration_s / arm.control_period_s))):
        arm.wait_period()
        state = arm.read_state()
        if on_period is not None:
            on_period(state)
    return state


def wait_until_at_rest(arm: Arm, timeout_s: float = 1.0, periods: int = 5) -> ArmState:
    """Wait (one control period at a time) until the TCP has been at rest for ``periods``; ArmError after timeout."""
    state = arm.read_state()
    quiet = 0
    for _ in range(max(1, round(timeout_s / arm.control_period_s))):
        arm.wait_period()
        state = arm.read_state()
        check_controller(state, "settling")
        quiet = quiet + 1 if _resting(state) else 0
        if quiet >= periods:
            return state
    raise ArmError(f"the arm did not come to rest within {timeout_s} s")


def stop_arm(arm: Arm, decel_m_s2: float = 10.0) -> None:
    """Stop on an error path without hiding the error that got us here; a second Ctrl-C cannot skip it.

    If the stop is interrupted (KeyboardInterrupt, or a termination signal turned into one) it is sent again before
    that interrupt propagates. Other failures are logged: the error being handled matters more.
    """
    held: BaseException | None = None
    for _ in range(3):
        try:
            arm.stop(decel_m_s2)
            break
        except Exception:
            logger.exception("could not stop the arm after an error; it may still be moving")
            break
        except BaseException as exc:
            logger.warning("interrupted while stopping the arm; sending the stop again")
            held = held or exc
    if held is not None:
        raise held


def _trapezoid_s(distance_m: float, speed_m_s: float, accel_m_s2: float) -> float:
    if distance_m <= 0 or speed_m_s <= 0 or accel_m_s2 <= 0:
        return 0.0
    if distance_m < speed_m_s**2 / accel_m_s2:
        return 2.0 * math.sqrt(distance_m / accel_m_s2)
    return distance_m / speed_m_s + speed_m_s / accel_m_s2


def _unit_direction(direction: np.ndarray) -> np.ndarray:
    vector = np.asarray(direction, dtype=np.float64).reshape(-1)
    norm = float(np.linalg.norm(vector)) if vector.shape == (3,) else 0.0
    if not np.isfinite(norm) or norm < 1e-9:
        raise ArmError(f"guarded move direction must be a non-zero 3-vector, got {direction!r}")
    return vector / norm
