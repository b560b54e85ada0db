"""The simulated arm: presses, stops, limits and the wrist F/T, checked against numbers worked by hand."""

from __future__ import annotations

import math

import numpy as np
import pytest

from drivers.arm import Arm
from drivers.clock import VirtualClock
from drivers.errors import ArmError, ControlScriptStopped, ProtectiveStop
from tests.arm.arm_fakes import EXACT_FT, PRESS_DIR, START_POSE, SpringWorld, make_arm
from unitac_rig.collection.guarded_motion import guarded_move, press_force
from unitac_rig.sim.arm import SimArm, SimArmParams
from unitac_rig.sim.world import FreeSpace

PERIOD_S = 0.002


def test_sim_arm_is_an_arm() -> None:
    arm = make_arm(SpringWorld(1e4, 0.002))
    assert isinstance(arm, Arm)
    assert arm.control_period_s == PERIOD_S
    arm.close()


@pytest.mark.parametrize(
    ("stiffness_n_m", "speed_m_s", "decel_m_s2", "latency_s"),
    [
        (1e4, 0.005, 0.5, 0.010),  # 10 N/mm, 5 mm/s: 0.50 N from latency + 0.25 N from braking = 0.75 N
        (2e4, 0.010, 10.0, 0.004),  # 20 N/mm, 10 mm/s: 0.80 N + 0.10 N = 0.90 N
    ],
)
def test_press_overshoot_is_stiffness_times_latency_travel_plus_stopping_distance(
    stiffness_n_m: float, speed_m_s: float, decel_m_s2: float, latency_s: float
) -> None:
    arm = make_arm(SpringWorld(stiffness_n_m, 0.002), SimArmParams(**{**EXACT_FT.__dict__, "ft_latency_s": latency_s}))
    threshold_n = 10.0
    result = guarded_move(
        arm, PRESS_DIR, speed_m_s, threshold_n, max_travel_m=0.01, hard_limit_n=30.0, stop_decel_m_s2=decel_m_s2
    )
    expected = stiffness_n_m * (speed_m_s * latency_s + speed_m_s**2 / (2 * decel_m_s2))
    # The threshold is only checked once per period, so the trigger can come up to one period of travel late.
    quantum = stiffness_n_m * speed_m_s * PERIOD_S
    overshoot = result.peak_press_force_n - threshold_n
    assert result.reason == "force"
    assert expected - 1e-6 <= overshoot <= expected + quantum + 1e-6
    # At rest the (exact, lagging) reading has caught up with the true force: the peak includes the transient.
    assert result.peak_press_force_n == pytest.approx(-arm.true_wrench()[1], abs=1e-9)
    assert np.allclose(arm.read_state().tcp_speed, 0.0)
    assert result.travel_m == pytest.approx(0.002 + result.peak_press_force_n / stiffness_n_m, abs=1e-9)
    arm.close()


def test_travel_limit_stops_a_press_into_a_too_soft_world() -> None:
    arm = make_arm(SpringWorld(100.0, 0.001))  # 0.1 N/mm: 0.4 N after 5 mm, never 10 N
    result = guarded_move(arm, PRESS_DIR, 0.005, 10.0, max_travel_m=0.005, hard_limit_n=30.0)
    assert result.reason == "travel"
    # travel is checked on the actual pose: at most one period (10 um) late, then v^2/2a = 1.25 um of braking
    assert 0.005 < result.travel_m <= 0.005 + 0.005 * PERIOD_S + 0.005**2 / 20 + 1e-9
    assert result.peak_press_force_n < 0.5
    assert np.allclose(result.stop_pose, arm.true_tcp_pose())
    arm.close()


class StepWorld:
    """A force that jumps from 0 to 40 N the moment the pad passes 1 mm along the press direction."""

    def wrench_on_tool(self, tcp_pose: np.ndarray) -> np.ndarray:
        touching = float(np.dot(tcp_pose[:3] - START_POSE[:3], PRESS_DIR)) > 0.001
        return np.concatenate([-40.0 * PRESS_DIR * touching, np.zeros(3)])


def test_hard_limit_fires_before_the_threshold_when_the_force_jumps() -> None:
    arm = SimArm(
        StepWorld(), clock=VirtualClock(), rng=np.random.default_rng(0), params=EXACT_FT, start_pose=START_POSE
    )
    result = guarded_move(arm, PRESS_DIR, 0.005, 10.0, max_travel_m=0.01, hard_limit_n=30.0)
    assert result.reason == "hard_limit"
    assert result.peak_press_force_n == pytest.approx(40.0)
    arm.close()


def test_protective_stop_during_a_linear_move_raises_with_the_arm_at_rest() -> None:
    params = SimArmParams(**{**EXACT_FT.__dict__, "protective_stop_n": 50.0})
    arm = make_arm(SpringWorld(1e5, 0.002), params)  # 100 N/mm wall 2 mm ahead
    goal = START_POSE + np.array([0.0, 0.010, 0.0, 0.0, 0.0, 0.0])
    with pytest.raises(ProtectiveStop):
        arm.move_linear(goal, 0.01, 0.5)
    state = arm.read_state()
    assert state.protective_stop and state.safety_mode == 3
    assert np.allclose(state.tcp_speed, 0.0)
    # it tripped on the true force, between 50 N and one period of travel beyond (100 N/mm x 10 um = 1 N)
    assert 50.0 < -arm.true_wrench()[1] <= 51.0 + 1e-6
    resting = arm.true_tcp_pose()
    for _ in range(10):
        arm.wait_period()
    assert np.allclose(arm.true_tcp_pose(), resting)
    with pytest.raises(ProtectiveStop):
        arm.speed_linear(np.array([0.0, -0.01, 0.0, 0.0, 0.0, 0.0]), 0.5)
    arm.stop()  # stopping a stopped arm is fine
    arm.close()


def test_guarded_move_reports_a_protective_stop_and_leaves_the_arm_stopped() -> None:
    params = SimArmParams(**{**EXACT_FT.__dict__, "protective_stop_n": 20.0})
    arm = make_arm(SpringWorld(1e4, 0.001), params)
    result = guarded_move(arm, PRESS_DIR, 0.005, 40.0, max_travel_m=0.01, hard_limit_n=60.0)
    assert result.reason == "protective_stop"
    assert result.trigger_state.protective_stop
    assert np.allclose(arm.read_state().tcp_speed, 0.0)
    arm.close()


def test_after_a_protective_stop_commands_are_refused_until_unlocked_and_the_program_reuploaded() -> None:
    """As on a real controller (hardware-facts 3.8): the program stops with the protective stop, and unlocking the
    stop alone does not start it again."""
    arm = make_arm(SpringWorld(1e4, 0.05))
    arm.trigger_protective_stop()
    state = arm.read_state()
    assert state.protective_stop and not state.program_running
    with pytest.raises(ProtectiveStop):
        arm.zero_ft()
    with pytest.raises(ProtectiveStop):
        arm.reupload_script()  # not while the stop is still locked
    arm.unlock_protective_stop()
    with pytest.raises(ControlScriptStopped):
        arm.speed_linear(np.array([0.0, 0.01, 0.0, 0.0, 0.0, 0.0]), 0.5)
    arm.reupload_script()
    arm.speed_linear(np.array([0.0, 0.01, 0.0, 0.0, 0.0, 0.0]), 0.5)
    arm.wait_period()
    state = arm.read_state()
    assert not state.protective_stop and state.program_running and state.tcp_speed[1] > 0
    arm.close()


def test_a_program_started_again_after_a_protective_stop_is_watched_by_the_watchdog_again() -> None:
    """A resumed session's first motion arms the watchdog as the first session's did (UR5eArm re-arms it at each
    motion start): a host that then stops writing stops the program, the arm brakes to rest."""
    clock = VirtualClock()
    arm = SimArm(
        FreeSpace(), clock=clock, rng=np.random.default_rng(0), params=EXACT_FT, start_pose=START_POSE, watchdog_hz=10.0
    )
    arm.trigger_protective_stop()
    arm.unlock_protective_stop()
    arm.reupload_script()
    arm.speed_linear(np.array([0.0, 0.01, 0.0, 0.0, 0.0, 0.0]), 0.5)
    for _ in range(100):  # 200 ms without a host write: past the 100 ms window of 10 Hz
        clock.advance_ns(2_000_000)
    assert not arm.program_running and "watchdog" in (arm.program_stop_reason or "")
    at_rest = arm.true_tcp_pose()
    clock.advance_ns(2_000_000)
    assert np.array_equal(arm.true_tcp_pose(), at_rest)
    arm.close()


def test_zero_ft_removes_the_bias() -> None:
    params = SimArmParams(**{**EXACT_FT.__dict__, "ft_bias_sigma_n": 2.0, "ft_filter_cutoff_hz": 20.0})
    arm = make_arm(SpringWorld(1e4, 0.05), params, seed=3)
    before = arm.read_state().tcp_force
    assert np.linalg.norm(before[:3]) > 0.5  # an un-zeroed sensor reads a few N with nothing touching it
    arm.zero_ft()
    for _ in range(50):
        arm.wait_period()
    assert np.allclose(arm.read_state().tcp_force, 0.0, atol=1e-9)
    arm.close()


def test_noise_is_filtered_and_zeroing_leaves_a_zero_mean() -> None:
    arm = SimArm(FreeSpace(), clock=make_arm(SpringWorld(1, 1)).clock, rng=np.random.default_rng(7))  # defaults
    arm.zero_ft()
    readings = []
    for _ in range(1000):
        arm.wait_period()
        readings.append(arm.read_state().tcp_force[:3])
    forces = np.array(readings)
    # raw sigma 1.5 N through a 20 Hz first-order filter at 500 Hz: sigma * sqrt(alpha / (2 - alpha)) = 0.53 N
    alpha = 1 - math.exp(-2 * math.pi * 20 * PERIOD_S)
    assert forces.std(axis=0) == pytest.approx([1.5 * math.sqrt(alpha / (2 - alpha))] * 3, rel=0.35)
    assert np.all(np.abs(forces.mean(axis=0)) < 0.3)
    arm.close()


def test_stop_decelerates_over_v_squared_over_2a() -> None:
    arm = make_arm(SpringWorld(1e4, 1.0))
    arm.speed_linear(np.array([0.0, 0.1, 0.0, 0.0, 0.0, 0.0]), 2.0)
    for _ in range(100):  # 0.05 s to reach 0.1 m/s at 2 m/s^2, then cruise
        arm.wait_period()
    assert arm.read_state().tcp_speed[1] == pytest.approx(0.1)
    y_at_stop = arm.true_tcp_pose()[1]
    arm.stop(decel_m_s2=4.0)
    for _ in range(30):
        arm.wait_period()
    assert arm.true_tcp_pose()[1] - y_at_stop == pytest.approx(0.1**2 / (2 * 4.0), abs=1e-12)  # 1.25 mm
    arm.close()


def test_move_linear_follows_a_trapezoid_to_the_goal() -> None:
    arm = make_arm(SpringWorld(1e4, 1.0))
    goal = START_POSE + np.array([0.1, 0.0, 0.0, 0.0, 0.0, 0.2])
    arm.move_linear(goal, 0.25, 1.2)
    assert np.allclose(arm.true_tcp_pose(), goal, atol=1e-12)
    # ramps of 0.25/1.2 s cover 0.052 m, the remaining 0.048 m at 0.25 m/s: 2 * 0.2083 + 0.1917 = 0.6083 s
    assert arm.clock.now_ns() / 1e9 == pytest.approx(0.6083, abs=PERIOD_S)
    assert np.allclose(arm.read_state().tcp_speed, 0.0)
    arm.close()


def test_force_mode_settles_at_the_target_force() -> None:
    arm = make_arm(SpringWorld(1e4, 0.001))
    task_frame = np.array([0.0, 0.0, 0.2, -math.pi / 2, 0.0, 0.0])  # tool z along base +y
    selection = np.array([0, 0, 1, 0, 0, 0])
    wrench = np.array([0.0, 0.0, 5.0, 0.0, 0.0, 0.0])
    limits = np.array([0.01, 0.01, 0.02, 0.1, 0.1, 0.1])
    for _ in range(1000):
        arm.force_mode(task_frame, selection, wrench, limits)
        arm.wait_period()
    assert press_force(arm.read_state(), PRESS_DIR) == pytest.approx(5.0, abs=0.01)
    assert arm.true_tcp_pose()[[0, 2]] == pytest.approx([0.0, 0.2])  # non-compliant axes held still
    arm.force_mode_stop()
    arm.close()


def test_time_advanced_by_others_moves_the_arm_too() -> None:
    arm = make_arm(SpringWorld(1e4, 1.0))
    arm.speed_linear(np.array([0.0, 0.01, 0.0, 0.0, 0.0, 0.0]), 100.0)
    arm.clock.sleep(0.1)
    assert arm.true_tcp_pose()[1] == pytest.approx(0.001, abs=1e-5)  # 10 mm/s for 0.1 s
    arm.close()


def test_closed_arm_refuses_commands_and_stops() -> None:
    arm = make_arm(SpringWorld(1e4, 1.0))
    arm.speed_linear(np.array([0.0, 0.01, 0.0, 0.0, 0.0, 0.0]), 1.0)
    arm.wait_period()
    arm.close()
    assert np.allclose(arm.read_state().tcp_speed, 0.0)
    with pytest.raises(ArmError):
        arm.speed_linear(np.zeros(6), 1.0)
    with pytest.raises(ArmError):
        arm.wait_period()
    arm.close()  # twice is fine


def test_bad_arguments_are_arm_errors() -> None:
    arm = make_arm(SpringWorld(1e4, 1.0))
    with pytest.raises(ArmError):
        arm.speed_linear(np.array([0.0, 5.0, 0.0, 0.0, 0.0, 0.0]), 1.0)  # 5 m/s > 3 m/s
    with pytest.raises(ArmError):
        arm.move_linear(np.zeros(5), 0.1, 1.0)
    with pytest.raises(ArmError):
        arm.speed_linear(np.zeros(6), 0.0)
    arm.close()


def test_same_seed_same_readings() -> None:
    def run(seed: int) -> np.ndarray:
        arm = SimArm(FreeSpace(), clock=make_arm(SpringWorld(1, 1)).clock, rng=np.random.default_rng(seed))
        for _ in range(20):
            arm.wait_period()
        force = arm.read_state().tcp_force
        arm.close()
        return force

    assert np.array_equal(run(5), run(5))
    assert not np.array_equal(run(5), run(6))


def test_a_force_mode_command_resent_every_period_holds_and_a_changed_one_acts_at_once() -> None:
    """The host re-sends force mode every 2 ms as a ur_rtde loop does: the arm settles at each set-point in turn,
    and a bad command is still refused after good ones."""
    arm = make_arm(SpringWorld(1e4, 0.001))
    task_frame = np.array([0.0, 0.0, 0.2, -math.pi / 2, 0.0, 0.0])  # tool z along base +y
    selection = np.array([0, 0, 1, 0, 0, 0])
    limits = np.array([0.01, 0.01, 0.02, 0.1, 0.1, 0.1])
    for target_n in (5.0, 8.0):
        wrench = np.array([0.0, 0.0, target_n, 0.0, 0.0, 0.0])
        for _ in range(1000):
            arm.force_mode(task_frame, selection, wrench.copy(), limits)
            arm.wait_period()
        assert press_force(arm.read_state(), PRESS_DIR) == pytest.approx(target_n, abs=0.01)
    with pytest.raises(ArmError):
        arm.force_mode(task_frame, selection, np.array([0.0, 0.0, np.nan, 0.0, 0.0, 0.0]), limits)
    arm.close()


def test_the_wrist_reading_is_the_arm_streams_draws_period_by_period() -> None:
    """The F/T readings are bit for bit those of drawing each period's six drift and six noise values from the arm's
    generator in turn (worked here with the filter passing all): a seed fixes a session's wrist readings."""
    params = SimArmParams(ft_filter_cutoff_hz=None, ft_latency_s=0.0)
    arm = SimArm(FreeSpace(), clock=VirtualClock(), rng=np.random.default_rng(11), params=params)
    reference = np.random.default_rng(11)
    scale = np.array([1.0, 1.0, 1.0] + [params.ft_torque_scale_m] * 3)
    bias = reference.normal(0.0, params.ft_bias_sigma_n, 6) * scale
    drift = params.ft_bias_drift_n_per_sqrt_s * math.sqrt(PERIOD_S)
    filtered = bias
    for _ in range(2500):  # past two of the arm's blocks
        arm.wait_period()
        bias = bias + reference.normal(0.0, drift, 6) * scale
        raw = bias + reference.normal(0.0, params.ft_noise_sigma_n, 6) * scale
        filtered = filtered + 1.0 * (raw - filtered)  # the first-order filter's step with alpha 1
        assert np.array_equal(arm.read_state().tcp_force, filtered)
    arm.close()
