"""Motion primitives on top of :class:`drivers.arm.Arm`: a guarded (force-terminated) move and a settle helper.

``guarded_move`` is the press: a constant-speed ``speedL`` along a direction, one state read per control period, and a
stop as soon as the press force reaches a threshold. It keeps reading through the stopping transient (deceleration,
then the F/T sensor's latency and filter catching up) so the recorded peak includes the overshoot, and it stops the
arm on every exit path: a reached condition, an exception from a callback or the arm, or Ctrl-C.

"Press force" along a unit direction d is ``-dot(F[:3], d)`` (N): ``tcp_force`` is what the environment exerts on the
tool, which points against the press.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from dataclasses import dataclass
from typing import Literal

import numpy as np

from drivers.arm import Arm, ArmState
from drivers.errors import ArmError, ProtectiveStop

logger = logging.getLogger(__name__)

StopReason = Literal["force", "travel", "hard_limit", "protective_stop"]

REST_SPEED_M_S = 0.0005  # below 0.5 mm/s the TCP counts as at rest
DEFAULT_SETTLE_S = 0.05  # after rest: covers F/T latency (<= 20 ms) + 3 time constants of an 8 ms filter
STOP_GRACE_S = 0.5  # extra time allowed for the arm to come to rest beyond v / decel


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
    return -float(np.dot(np.asarray(state.tcp_force, dtype=np.float64)[:3], direction))


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
) -> GuardedMoveResult:
    """Move along ``direction`` at ``speed_m_s`` until the press force reaches ``force_threshold_n``.

    Also stops when the travel along the direction exceeds ``max_travel_m`` (reason "travel"), the press force
    reaches ``hard_limit_n`` ("hard_limit") or the controller reports a protective stop ("protective_stop");
    the caller decides what each reason means. ``on_period`` sees every state read, the stopping transient
    included (it may raise to abort; the arm is still stopped). After the arm is at rest, reading goes on for
    ``settle_s`` so a lagging F/T reading reaches its peak. Raises ArmError for nonsensical arguments.
    """
    unit = _unit_direction(direction)
    if not speed_m_s > 0:
        raise ArmError(f"guarded move speed must be > 0 m/s, got {speed_m_s}")
    if not 0 < force_threshold_n < hard_limit_n:
        raise ArmError(
            f"guarded move needs 0 < threshold ({force_threshold_n} N) < hard limit ({hard_limit_n} N)",
            hint="check the press threshold and the hard force limit in the rig file",
        )
    if not max_travel_m > 0:
        raise ArmError(f"guarded move travel limit must be > 0 m, got {max_travel_m}")
    if not (accel_m_s2 > 0 and stop_decel_m_s2 > 0):
        raise ArmError("guarded move accelerations must be > 0 m/s^2")

    twist = np.concatenate([unit * speed_m_s, np.zeros(3)])
    start_state = arm.read_state()
    start_position = np.asarray(start_state.tcp_pose[:3], dtype=np.float64)
    peak = press_force(start_state, unit)
    stop_sent = False
    try:
        if start_state.protective_stop:
            reason: StopReason = "protective_stop"
            trigger = start_state
        else:
            reason, trigger, peak = _approach(arm, twist, accel_m_s2, unit, start_position, max_travel_m,
                                             force_threshold_n, hard_limit_n, on_period, peak)  # fmt: skip
        arm.stop(stop_decel_m_s2)
        stop_sent = True
        final, peak = _ride_out_stop(arm, unit, speed_m_s, stop_decel_m_s2, settle_s, on_period, peak)
    finally:
        if not stop_sent:
            _stop_quietly(arm, stop_decel_m_s2)
    travel = float(np.dot(np.asarray(final.tcp_pose[:3]) - start_position, unit))
    logger.debug("guarded move stopped (%s): peak %.2f N, travel %.2f mm", reason, peak, travel * 1e3)
    return GuardedMoveResult(reason, trigger, peak, travel, np.asarray(final.tcp_pose, dtype=np.float64).copy())


def _approach(
    arm: Arm,
    twist: np.ndarray,
    accel_m_s2: float,
    unit: np.ndarray,
    start_position: np.ndarray,
    max_travel_m: float,
    force_threshold_n: float,
    hard_limit_n: float,
    on_period: Callable[[ArmState], None] | None,
    peak: float,
) -> tuple[StopReason, ArmState, float]:
    """Command the speed every period until a stop condition; -> (reason, state that triggered it, peak)."""
    while True:
        try:
            arm.speed_linear(twist, accel_m_s2)
        except ProtectiveStop:
            return "protective_stop", arm.read_state(), peak
        arm.wait_period()
        state = arm.read_state()
        force = press_force(state, unit)
        peak = max(peak, force)
        if on_period is not None:
            on_period(state)
        if state.protective_stop or state.emergency_stop:
            return "protective_stop", state, peak
        if force >= hard_limit_n:
            return "hard_limit", state, peak
        if force >= force_threshold_n:
            return "force", state, peak
        if float(np.dot(np.asarray(state.tcp_pose[:3]) - start_position, unit)) > max_travel_m:
            return "travel", state, peak


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


def _at_rest(state: ArmState, position: np.ndarray, previous: np.ndarray, period_s: float) -> bool:
    if state.tcp_speed is not None:
        speed = float(np.linalg.norm(np.asarray(state.tcp_speed)[:3]))
    else:
        speed = float(np.linalg.norm(position - previous)) / period_s
    return speed < REST_SPEED_M_S


def settle(arm: Arm, duration_s: float, on_period: Callable[[ArmState], None] | None = None) -> ArmState:
    """Wait ``duration_s`` one control period at a time, reading (and reporting) every state; -> the last state."""
    state = arm.read_state()
    for _ in range(max(0, round(duration_s / arm.control_period_s))):
        arm.wait_period()
        state = arm.read_state()
        if on_period is not None:
            on_period(state)
    return state


def _unit_direction(direction: np.ndarray) -> np.ndarray:
    vector = np.asarray(direction, dtype=np.float64).reshape(-1)
    norm = float(np.linalg.norm(vector)) if vector.shape == (3,) else 0.0
    if not np.isfinite(norm) or norm < 1e-9:
        raise ArmError(f"guarded move direction must be a non-zero 3-vector, got {direction!r}")
    return vector / norm


def _stop_quietly(arm: Arm, decel_m_s2: float) -> None:
    """Stop on an error path without hiding the error that got us here."""
    try:
        arm.stop(decel_m_s2)
    except Exception:
        logger.exception("could not stop the arm after an error; it may still be moving")
