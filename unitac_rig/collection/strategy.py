"""The press-strategy seam: how the pad goes from the stand-off to the stop force, behind one small interface.

A strategy is an object with one method, ``press(ctx) -> stop reason``, in its own module under
``collection/strategies/``, registered by name in ``unitac_rig/rig/strategies.py`` (the rig file's ``press.strategy``
is checked against that table). It never gets the arm: it moves the pad only through the :class:`PressContext` it is
handed, whose two motions carry the safety of every press whatever the strategy asks:

* :meth:`PressContext.move`: ``guarded_motion.guarded_move`` in the controller's force mode, with the press's own
  set-point (threshold + ``press.setpoint_margin_n``, never within ``HARD_LIMIT_CLEARANCE_N`` of the hard limit)
  whatever force the strategy asks to stop at: a host that freezes cannot push past it;
* :meth:`PressContext.force_control`: one control period of force control, its set-point capped the same way.

Every control period of both goes through the press's :meth:`~.safety_check.PressStreams.tick` and feeds the RTDE
watchdog; the arm is stopped after the strategy returns whatever it left running. The moves before and after are the
press's (collection/press.py), not the strategy's.

Stop reasons a strategy returns: ``"force"`` (the threshold was reached: the press is complete), ``"no_contact"`` (it
never touched anything: aborted, redone on resume), or a failure (``"travel"``, ``"timeout"``, ``"settled"``).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol, runtime_checkable

import numpy as np

from drivers.arm import Arm
from drivers.errors import ProtectiveStop
from unitac_rig.collection.guarded_motion import (
    DEFAULT_SETTLE_S,
    guarded_move,
    press_frame,
    send_force_mode,
    stop_arm,
)
from unitac_rig.collection.safety_check import PressStreams
from unitac_rig.collection.transit import PressPlan, backstop_m
from unitac_rig.errors import ConfigError, SafetyLimit
from unitac_rig.rig.config import LimitsConfig, PressConfig
from unitac_rig.rig.lazy import load
from unitac_rig.rig.strategies import PRESS_STRATEGIES

PRESS_EXTRA_S = 5.0  # a press motion may last its travel budget at its speed plus this long, then it fails (timeout)
HARD_LIMIT_CLEARANCE_N = 0.1  # force set-points sent to the controller stay at least this far under the hard limit
_PRESS_PHASES = ("approach", "press")  # the phases a strategy runs in (first contact and travel are watched in both)


@runtime_checkable
class PressStrategy(Protocol):
    """One way of pressing from the stand-off to the stop force; see the module docstring."""

    def press(self, ctx: PressContext) -> str:
        """Press through ``ctx``; -> the stop reason ("force", "no_contact", "travel", "timeout", "settled")."""
        ...


def press_strategy(name: str) -> PressStrategy:
    """The strategy registered as ``name`` in ``rig/strategies.py`` (imported on first use; the rig file's
    ``press.strategy`` was checked against that table when it was read)."""
    strategy = load(PRESS_STRATEGIES[name])
    if not isinstance(strategy, PressStrategy):
        raise ConfigError(f"press strategy {name!r} ({PRESS_STRATEGIES[name]}) has no press(ctx) method")
    return strategy


@dataclass(frozen=True)
class Move:
    """How one :meth:`PressContext.move` ended: its stop reason and the travel along the press from its start, m."""

    reason: str
    travel_m: float


def setpoint_ceiling_n(press: PressConfig, limits: LimitsConfig) -> float:
    """How high a settled press may raise the force set-point (N): threshold + ``setpoint_ceiling_margin_n``, but
    never past halfway from the first set-point to the hard limit (a tight hard limit keeps its margin)."""
    first = press.threshold_n + press.setpoint_margin_n
    return min(press.threshold_n + press.setpoint_ceiling_margin_n, max(first, 0.5 * (first + limits.hard_force_n)))


class PressContext:
    """What a strategy may do and read during one press; every motion is bounded as the module docstring says.

    ``press`` and ``limits``: the rig file's ``[press]`` and ``[limits]``; ``contact_threshold_n``: the press force
    that counts as first contact (above the wrist F/T's noise, N); ``backstop_m``: the travel budget from the
    stand-off (the expected contact distance + ``limits.max_travel_after_contact_mm`` + 5 mm).
    """

    def __init__(
        self, arm: Arm, streams: PressStreams, plan: PressPlan, press: PressConfig, limits: LimitsConfig
    ) -> None:
        self._arm, self._streams, self._plan = arm, streams, plan
        self.press, self.limits = press, limits
        self.contact_threshold_n = streams.contact_threshold_n
        self.control_period_s = arm.control_period_s
        self.backstop_m = backstop_m(plan, limits)
        # Set-points in the controller's zero (see PressStreams), kept under the hard limit whatever the offset.
        offset = streams.offset_along_press_n
        self._below_limit_n = limits.hard_force_n - HARD_LIMIT_CLEARANCE_N
        self._setpoint_n = min(press.threshold_n + press.setpoint_margin_n - offset, self._below_limit_n)
        self._ceiling_n = max(self._setpoint_n, min(setpoint_ceiling_n(press, limits) - offset, self._below_limit_n))
        self._force_cap_n = press.threshold_n + press.setpoint_margin_n  # force control's set-point cap, host zero
        # The dwell that follows a final stop reads on at rest, so the stop itself need not wait for the lagging F/T.
        self._final_settle_s = 0.0 if press.dwell_s >= DEFAULT_SETTLE_S else DEFAULT_SETTLE_S
        self._task_frame: np.ndarray | None = None
        self._moving = False  # the last motion left the arm moving (keep_moving, force control)
        arm.set_force_mode_parameters(press.force_mode_damping, press.force_mode_gain_scaling)

    @property
    def phase(self) -> str:
        """The phase the record marks ("approach" before first contact is expected, then "press")."""
        return self._streams.phase

    @phase.setter
    def phase(self, value: str) -> None:
        if value not in _PRESS_PHASES:
            raise ValueError(f"a press strategy runs in the phases {_PRESS_PHASES}, not {value!r}")
        self._streams.phase = value

    @property
    def last_press_force_n(self) -> float | None:
        """The latest press force read (N, positive into the object), None before the first reading."""
        return self._streams.press_force[-1] if self._streams.press_force else None

    def mean_press_force_n(self, periods: int) -> float:
        """Mean press force of the last ``periods`` readings, N (0 before the first)."""
        recent = self._streams.press_force[-periods:]
        return float(np.mean(recent)) if recent else 0.0

    def run(self, strategy: PressStrategy) -> str:
        """Let ``strategy`` press; the arm is stopped afterwards if its last motion left it moving."""
        try:
            return strategy.press(self)
        finally:
            if self._moving:
                self._moving = False
                stop_arm(self._arm)

    def move(
        self,
        speed_mm_s: float,
        until_n: float,
        *,
        samples: int = 1,
        travel_m: float | None = None,
        keep_moving: bool = False,
        final: bool = False,
    ) -> Move:
        """Along the press at up to ``speed_mm_s`` (cut to ``limits.max_speed_mm_s``) until the mean of the last
        ``samples`` press forces reaches ``until_n`` (N), in force mode with the press's set-point (see the module
        docstring).

        ``travel_m``: this move's travel budget (default: what is left of :attr:`backstop_m`; at most that plus
        ``limits.max_travel_after_contact_mm``). ``keep_moving``: on reaching ``until_n`` go straight on with the
        next motion without stopping (the controller keeps regulating the same bounded set-point). ``final``: the
        press's dwell follows this stop, so it need not wait for the F/T to settle. Raises SafetyLimit when
        ``until_n`` is at or above the hard limit or a hard limit is passed, ProtectiveStop on a protective stop; a
        move that ends without any contact returns "no_contact".
        """
        if not until_n < self.limits.hard_force_n:
            raise SafetyLimit(
                f"press strategy {self.press.strategy!r} asked to press until {until_n:g} N, at or above the hard "
                f"limit {self.limits.hard_force_n:g} N (press {self._plan.press_id})"
            )
        speed_m_s = min(speed_mm_s, self.limits.max_speed_mm_s) / 1000.0
        travelled_m = self._travelled_m()
        cap_m = self.backstop_m + self.limits.max_travel_after_contact_mm / 1000.0 - travelled_m
        budget_m = self.backstop_m - travelled_m if travel_m is None else min(travel_m, cap_m)
        if budget_m <= 0.0:
            return Move(self._reason("travel"), 0.0)
        result = guarded_move(
            self._arm,
            self._plan.direction,
            speed_m_s,
            until_n,
            max_travel_m=budget_m,
            stop_samples=samples,
            max_duration_s=budget_m / speed_m_s + PRESS_EXTRA_S,
            settle_s=self._final_settle_s if final else DEFAULT_SETTLE_S,
            keep_moving=keep_moving,
            hard_limit_n=self.limits.hard_force_n,
            hard_torque_nm=self.limits.hard_torque_nm,
            on_period=self._streams.tick,
            force_setpoint_n=self._setpoint_n,
            setpoint_ceiling_n=self._ceiling_n,
        )
        self._moving = keep_moving and result.reason == "force"
        return Move(self._reason(result.reason), result.travel_m)

    def force_control(self, setpoint_n: float, speed_limit_mm_s: float) -> float:
        """One control period of force control along the press toward ``setpoint_n`` (N, capped at threshold +
        ``press.setpoint_margin_n``), moving at most ``speed_limit_mm_s`` (cut to ``limits.max_speed_mm_s``);
        -> the press force read (N). The arm goes on regulating until the next motion or the strategy's end."""
        if self._task_frame is None:
            self._task_frame = press_frame(np.asarray(self._arm.read_state().tcp_pose[:3]), self._plan.direction)
        target = min(min(setpoint_n, self._force_cap_n) - self._streams.offset_along_press_n, self._below_limit_n)
        speed_m_s = min(speed_limit_mm_s, self.limits.max_speed_mm_s) / 1000.0
        self._moving = True
        send_force_mode(self._arm, self._task_frame, target, speed_m_s)
        self._arm.wait_period()
        self._streams.tick(self._arm.read_state())  # raises on a protective stop, a hard limit, ...
        return self._streams.press_force[-1]

    def _travelled_m(self) -> float:
        """Travel along the press from the stand-off to the last pose read, m."""
        if not self._streams.robot_pose:
            return 0.0
        here = np.asarray(self._streams.robot_pose[-1][:3]) - np.asarray(self._plan.start_pose[:3])
        return max(0.0, float(np.dot(here, self._plan.direction)))

    def _reason(self, guarded_reason: str) -> str:
        if guarded_reason == "hard_limit":
            raise SafetyLimit("the wrist force or torque passed the hard limit")
        if guarded_reason == "protective_stop":
            raise ProtectiveStop("the controller reported a protective stop")
        if guarded_reason == "travel" and self._streams.contact_pose is None:
            return "no_contact"
        return guarded_reason
