"""The two-phase and force-ramp strategies against the simulated arm's noisy wrist: first contact is real contact,
and the force ramp neither winds up before contact nor rises faster than asked."""

from __future__ import annotations

import numpy as np
import pytest

from drivers.clock import VirtualClock
from drivers.frames import TactileFrame
from drivers.layouts import PAPILLARRAY
from unitac_rig.collection.guarded_motion import move_to
from unitac_rig.collection.press import run_press
from unitac_rig.collection.safety_check import PressStreams, TickInfo
from unitac_rig.collection.session import plan_presses
from unitac_rig.collection.strategies.force_ramp import RAMP_MAX_LEAD_N, ramp
from unitac_rig.collection.strategy import PressContext
from unitac_rig.collection.transit import PressPlan
from unitac_rig.collection.wrist import settle_window
from unitac_rig.rig.config import LimitsConfig, PressConfig, parse_rig_config
from unitac_rig.rig.objects import get_object
from unitac_rig.sim.arm import SimArm, SimArmParams
from unitac_rig.sim.fast_rig import SimRig

PRESS_DIR = np.array([0.0, 1.0, 0.0])
START_POSE = np.array([0.0, 0.0, 0.2, -np.pi / 2, 0.0, 0.0])  # tool z (the compliant axis) along base +y


def _true_press_force(rig: SimRig, direction: np.ndarray) -> float:
    return -float(np.dot(rig.sim_arm.true_wrench()[:3], direction))


@pytest.mark.parametrize("strategy", ["two-phase", "force-ramp"])
def test_first_contact_is_declared_only_when_the_pad_touches(strategy: str) -> None:
    """The wrist F/T's ~0.5 N noise must not end the fast approach millimetres before the object."""
    config = parse_rig_config({"press": {"angle_count": 3, "strategy": strategy, "ramp_rate_n_s": 8.0}})
    obj = get_object("hex_pla")
    plans = plan_presses(obj, config, [0.0])
    with SimRig(config, seed=3) as rig:
        sensor = rig.open_sensor("papillarray")
        try:
            rig.mount(obj, 0.0, "papillarray")
            move_to(rig.arm, plans[0].start_pose, 0.05, 0.5)
            rig.arm.zero_ft()
            settle_window(rig.arm, sensor, 0.2)
            for plan in plans:
                truth: list[tuple[float, float]] = []

                def on_tick(
                    _: TickInfo, direction: np.ndarray = plan.direction, truth: list[tuple[float, float]] = truth
                ) -> None:
                    truth.append((rig.clock.now_ns() / 1e9, _true_press_force(rig, direction)))

                record = run_press(rig.arm, sensor, plan, config.press, config.limits, on_tick=on_tick)
                assert record.status == "complete"
                contact_t = next(t for t, kind, _ in record.events if kind == "contact")
                times, forces = np.array(truth).T
                assert forces[np.searchsorted(times, contact_t)] > 0.5, "contact declared in free air"
        finally:
            sensor.disconnect()


def test_force_ramp_rises_at_about_the_asked_rate() -> None:
    """16 N/s asked: before the anti-windup the pad hit the object at the speed limit and rose at 30-60 N/s."""
    config = parse_rig_config({"press": {"angle_count": 3, "strategy": "force-ramp", "ramp_rate_n_s": 16.0}})
    obj = get_object("hex_tpu")
    plans = plan_presses(obj, config, [0.0])
    with SimRig(config, seed=5) as rig:
        sensor = rig.open_sensor("uskin")
        try:
            rig.mount(obj, 0.0, "uskin")
            move_to(rig.arm, plans[0].start_pose, 0.05, 0.5)
            rig.arm.zero_ft()
            settle_window(rig.arm, sensor, 0.2)
            for plan in plans:
                record = run_press(rig.arm, sensor, plan, config.press, config.limits)
                t = record.robot_t_s
                # the slope of a straight line through the loading ramp, 5..9 N of measured press force
                loading = (record.press_force_n > 5.0) & (t < next(e for e, k, _ in record.events if k == "stop"))
                first = int(np.argmax(loading))
                last = first + int(np.argmax(record.press_force_n[first:] > 9.0))
                slope = np.polyfit(t[first:last], record.press_force_n[first:last], 1)[0]
                assert 8.0 < slope < 24.0
                assert record.attrs["overshoot_n"] < 2.5
        finally:
            sensor.disconnect()


class _Wall:
    """A flat wall ``gap_m`` ahead of START_POSE along PRESS_DIR: force = stiffness x penetration."""

    def __init__(self, stiffness_n_m: float, gap_m: float) -> None:
        self.stiffness_n_m, self.gap_m = stiffness_n_m, gap_m

    def wrench_on_tool(self, tcp_pose: np.ndarray) -> np.ndarray:
        penetration = float(np.dot(tcp_pose[:3] - START_POSE[:3], PRESS_DIR)) - self.gap_m
        wrench = np.zeros(6)
        wrench[:3] = -self.stiffness_n_m * max(0.0, penetration) * PRESS_DIR
        return wrench


class _OneFramePerPoll:
    layout = PAPILLARRAY

    def __init__(self, clock: VirtualClock) -> None:
        self.clock = clock

    def poll(self) -> list[TactileFrame]:
        return [TactileFrame("papillarray", self.clock.now_ns(), np.zeros((9, 3)))]


def test_force_ramp_started_short_of_the_object_creeps_instead_of_winding_up() -> None:
    """The ramp begins 3 mm before a 10 N/mm wall (an approach that stopped short): the set-point may lead the
    measured force by RAMP_MAX_LEAD_N only, so the pad approaches at <= gain x lead and lands softly."""
    params = SimArmParams(ft_noise_sigma_n=0.0, ft_bias_sigma_n=0.0, ft_bias_drift_n_per_sqrt_s=0.0)
    clock = VirtualClock()
    arm = SimArm(_Wall(1e4, 0.003), clock=clock, rng=np.random.default_rng(0), params=params, start_pose=START_POSE)
    press = PressConfig(strategy="force-ramp", ramp_rate_n_s=16.0)
    plan = PressPlan(0.0, 0.0, START_POSE, PRESS_DIR, 0.003)
    streams = PressStreams(arm, _OneFramePerPoll(clock), plan, press, LimitsConfig(), 0.5, None, 1.0)  # type: ignore[arg-type]
    speeds: list[float] = []
    true_forces: list[float] = []
    original_tick = streams.tick

    def tick(state):  # type: ignore[no-untyped-def]
        speeds.append(float(np.dot(state.tcp_speed[:3], PRESS_DIR)))
        true_forces.append(-float(arm.true_wrench()[1]))
        original_tick(state)

    streams.tick = tick  # type: ignore[method-assign]
    try:
        assert ramp(PressContext(arm, streams, plan, press, LimitsConfig())) == "force"
    finally:
        arm.close()
    assert RAMP_MAX_LEAD_N == 3.0 and params.force_mode_gain_m_s_per_n == 0.002  # the numbers worked below
    assert max(speeds) <= 0.006 + 1e-9  # gain 2 mm/s/N x 3 N lead, not the 20 mm/s speed limit
    # the F/T lags ~12 ms: at <= 16 N/s (+ the lead's share) the true force passes 10 N by well under 1 N
    assert 10.0 <= max(true_forces) < 11.0
