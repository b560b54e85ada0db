"""What makes a press faster without loosening what bounds it, on the fast twin: the smaller stand-off once a press
has found the object where the rig file says (never below limits.min_standoff_mm), the two-phase press going on from
its fast approach to its slow speed without stopping in between, and the return to the stand-off recorded (free-air
readings for the extraction's baseline). The force bounds themselves are tested in test_press_safety.py and
test_motion_safety.py, for the default press too.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from unitac_rig.collection.press import run_press
from unitac_rig.collection.safety_check import TickInfo
from unitac_rig.collection.session import collect_session, confirmed_standoff_mm, plan_presses, session_tare
from unitac_rig.collection.transit import make_plan, with_standoff
from unitac_rig.errors import ConfigError
from unitac_rig.rig.config import RigConfig, parse_rig_config
from unitac_rig.rig.objects import get_object
from unitac_rig.sim.fast_rig import SimRig
from unitac_rig.storage.reader import read_presses
from unitac_rig.storage.recorder import session_path


def few(count: int = 3, **sections: dict[str, object]) -> RigConfig:
    data: dict[str, object] = {"press": {"angle_count": count}}
    for key, value in sections.items():
        data[key] = {**data.get(key, {}), **value}  # type: ignore[dict-item]
    return parse_rig_config(data)


def test_presses_after_the_placement_is_confirmed_start_from_the_smaller_stand_off(tmp_path: Path) -> None:
    """The first press approaches from object.standoff_mm (8 mm); it finds the object where expected, so the next
    ones start 5 mm from it (press.confirmed_standoff_mm) and still touch it about 5 mm in."""
    config = few(3, press={"angle_min_deg": -2.0, "angle_max_deg": 2.0})
    with SimRig(config, seed=0) as rig:
        outcome = collect_session(rig, get_object("hex_tpu"), "uskin", tmp_path)
    assert outcome.stopped is None
    presses = sorted(read_presses(session_path(tmp_path, "hex_tpu", "uskin")), key=lambda p: p.angle_deg)
    assert [p.status for p in presses] == ["complete"] * 3
    assert [p.attrs["standoff_mm"] for p in presses] == pytest.approx([8.0, 5.0, 5.0])
    for press in presses[1:]:
        assert press.attrs["contact_travel_mm"] == pytest.approx(5.0, abs=1.5)


def test_the_confirmed_stand_off_stays_between_the_floor_and_the_rig_files_stand_off() -> None:
    floor = few(1, press={"confirmed_standoff_mm": 3.0}, limits={"min_standoff_mm": 6.0})
    assert confirmed_standoff_mm(floor) == 6.0
    above = few(1, press={"confirmed_standoff_mm": 12.0})
    assert confirmed_standoff_mm(above) == 8.0


def test_with_standoff_moves_the_start_along_the_ray_only() -> None:
    plan = make_plan(0.0, 20.0, (-0.15, 0.625), 0.2, support_distance_mm=30.0, standoff_mm=8.0)
    closer = with_standoff(plan, 5.0)
    step = np.asarray(closer.start_pose[:3]) - np.asarray(plan.start_pose[:3])
    assert step == pytest.approx(0.003 * np.asarray(plan.direction))
    assert closer.contact_distance_m == pytest.approx(0.005)
    assert np.asarray(closer.start_pose[3:]) == pytest.approx(np.asarray(plan.start_pose[3:]))


def test_the_retract_speed_is_bounded_like_every_other_speed() -> None:
    with pytest.raises((ConfigError, ValueError), match="retract_speed_mm_s"):
        few(1, press={"retract_speed_mm_s": 150.0})


def run_one(strategy: str, on_tick: object = None) -> tuple[object, object]:
    """One press of hex_tpu at 0 deg from the session's tared stand-off; -> (record, plan)."""
    config = few(1, press={"strategy": strategy})
    obj = get_object("hex_tpu")
    (plan,) = plan_presses(obj, config, [0.0])
    with SimRig(config, seed=0) as rig:
        sensor = rig.open_sensor("uskin")
        try:
            rig.mount(obj, 0.0, "uskin")
            session_tare(rig, sensor, plan)
            ticks = on_tick(rig) if callable(on_tick) else None
            record = run_press(rig.arm, sensor, plan, config.press, config.limits, on_tick=ticks)
        finally:
            sensor.disconnect()
    return record, plan


def test_two_phase_goes_on_from_its_fast_approach_to_its_slow_speed_without_stopping() -> None:
    """Before: the fast phase stopped the arm at first contact (and waited for it to settle) before the slow phase
    started from rest; now the slow phase takes over in the next control period."""
    speeds: list[tuple[str, float]] = []

    def watch(rig: SimRig) -> object:
        def on_tick(tick: TickInfo) -> None:
            speeds.append((tick.phase, float(np.linalg.norm(rig.sim_arm.read_state().tcp_speed[:3]))))

        return on_tick

    record, _ = run_one("two-phase", watch)
    assert record.status == "complete"  # type: ignore[attr-defined]
    first_press = next(i for i, (phase, _) in enumerate(speeds) if phase == "press")
    # the first 40 ms of the slow phase: never at rest (0.5 mm/s) in between
    assert min(speed for _, speed in speeds[first_press : first_press + 20]) > 0.0005


def test_the_return_to_the_stand_off_is_recorded_as_free_air() -> None:
    """The press record ends at the stand-off with the pad unloaded, not where the retract first felt it free."""
    record, plan = run_one("two-phase")
    pose = np.asarray(record.robot_pose)  # type: ignore[attr-defined]
    assert pose[-1, :3] == pytest.approx(np.asarray(plan.start_pose[:3]), abs=3e-4)  # type: ignore[attr-defined]
    force = np.asarray(record.press_force_n)  # type: ignore[attr-defined]
    assert abs(float(np.mean(force[-50:]))) < 0.5
