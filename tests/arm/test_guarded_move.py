"""guarded_move stops the arm on every way out: reached conditions, errors from callbacks or the arm, Ctrl-C."""

from __future__ import annotations

import numpy as np
import pytest

from drivers.arm import ArmState
from drivers.errors import ArmError, ProtectiveStop
from tests.arm.arm_fakes import PRESS_DIR, SpringWorld, make_arm
from unitac_rig.collection.guarded_motion import guarded_move, settle
from unitac_rig.sim.arm import SimArm


class RecordingArm:
    """A SimArm that records stop calls and can fail on the n-th wait_period or on stop."""

    def __init__(self, arm: SimArm, *, fail_at_period: int | None = None, error: BaseException | None = None) -> None:
        self.arm = arm
        self.clock = arm.clock
        self.control_period_s = arm.control_period_s
        self.stops: list[float] = []
        self.periods = 0
        self.fail_at_period = fail_at_period
        self.error = error
        self.stop_error: Exception | None = None

    def read_state(self) -> ArmState:
        return self.arm.read_state()

    def move_linear(self, pose: np.ndarray, speed_m_s: float, accel_m_s2: float) -> None:
        self.arm.move_linear(pose, speed_m_s, accel_m_s2)

    def speed_linear(self, twist: np.ndarray, accel_m_s2: float) -> None:
        self.arm.speed_linear(twist, accel_m_s2)

    def stop(self, decel_m_s2: float = 10.0) -> None:
        self.stops.append(decel_m_s2)
        if self.stop_error is not None:
            raise self.stop_error
        self.arm.stop(decel_m_s2)

    def zero_ft(self) -> None:
        self.arm.zero_ft()

    def force_mode(self, task_frame: np.ndarray, selection: np.ndarray, wrench: np.ndarray, limits: np.ndarray) -> None:
        self.arm.force_mode(task_frame, selection, wrench, limits)

    def force_mode_stop(self) -> None:
        self.arm.force_mode_stop()

    def wait_period(self) -> None:
        self.periods += 1
        if self.periods == self.fail_at_period and self.error is not None:
            raise self.error
        self.arm.wait_period()

    def close(self) -> None:
        self.arm.close()


def test_a_reached_threshold_stops_once_and_reports_every_period() -> None:
    arm = RecordingArm(make_arm(SpringWorld(1e4, 0.001)))
    seen: list[ArmState] = []
    result = guarded_move(arm, PRESS_DIR, 0.005, 5.0, max_travel_m=0.01, hard_limit_n=20.0, on_period=seen.append)
    assert result.reason == "force"
    assert arm.stops == [10.0]
    assert len(seen) == arm.periods  # the stopping transient is reported too
    assert seen.index(result.trigger_state) < len(seen) - 1
    assert max(-s.tcp_force[1] for s in seen) == pytest.approx(result.peak_press_force_n)
    arm.close()


def test_ctrl_c_mid_press_stops_the_arm_and_propagates() -> None:
    arm = RecordingArm(make_arm(SpringWorld(1e4, 0.05)), fail_at_period=20, error=KeyboardInterrupt())
    with pytest.raises(KeyboardInterrupt):
        guarded_move(arm, PRESS_DIR, 0.005, 5.0, max_travel_m=0.1, hard_limit_n=20.0)
    assert arm.stops == [10.0]
    arm.close()


def test_an_on_period_error_stops_the_arm_and_propagates() -> None:
    arm = RecordingArm(make_arm(SpringWorld(1e4, 0.05)))

    def explode(state: ArmState) -> None:
        raise RuntimeError("recorder full")

    with pytest.raises(RuntimeError, match="recorder full"):
        guarded_move(arm, PRESS_DIR, 0.005, 5.0, max_travel_m=0.1, hard_limit_n=20.0, on_period=explode)
    assert arm.stops == [10.0]
    arm.close()


def test_a_failing_stop_on_the_error_path_does_not_hide_the_error() -> None:
    arm = RecordingArm(make_arm(SpringWorld(1e4, 0.05)), fail_at_period=3, error=KeyboardInterrupt())
    arm.stop_error = ArmError("socket gone")
    with pytest.raises(KeyboardInterrupt):
        guarded_move(arm, PRESS_DIR, 0.005, 5.0, max_travel_m=0.1, hard_limit_n=20.0)
    assert arm.stops == [10.0]
    arm.close()


def test_an_arm_already_in_protective_stop_is_reported_not_moved() -> None:
    sim = make_arm(SpringWorld(1e4, 0.05))
    sim.trigger_protective_stop()
    arm = RecordingArm(sim)
    start = sim.true_tcp_pose()
    result = guarded_move(arm, PRESS_DIR, 0.005, 5.0, max_travel_m=0.1, hard_limit_n=20.0)
    assert result.reason == "protective_stop"
    assert np.allclose(sim.true_tcp_pose(), start)
    with pytest.raises(ProtectiveStop):
        sim.speed_linear(np.zeros(6), 1.0)
    arm.close()


@pytest.mark.parametrize(
    "kwargs",
    [
        {"speed_m_s": 0.0},
        {"force_threshold_n": 25.0},  # above the hard limit
        {"max_travel_m": 0.0},
        {"direction": np.zeros(3)},
        {"direction": np.array([1.0, 0.0])},
    ],
)
def test_nonsense_arguments_are_refused_before_moving(kwargs: dict[str, object]) -> None:
    sim = make_arm(SpringWorld(1e4, 0.05))
    arguments: dict[str, object] = {
        "direction": PRESS_DIR,
        "speed_m_s": 0.005,
        "force_threshold_n": 5.0,
        "max_travel_m": 0.01,
        "hard_limit_n": 20.0,
        **kwargs,
    }
    with pytest.raises(ArmError):
        guarded_move(sim, **arguments)  # type: ignore[arg-type]
    assert sim.clock.now_ns() == 0
    sim.close()


def test_settle_reads_every_period_for_the_duration() -> None:
    sim = make_arm(SpringWorld(1e4, 0.05))
    seen: list[ArmState] = []
    last = settle(sim, 0.1, seen.append)
    assert len(seen) == 50 and last is seen[-1]
    assert sim.clock.now_ns() == 100_000_000
    sim.close()
