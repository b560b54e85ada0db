"""Never zero a loaded wrist (issue 37, item 2), on the fast twin: a session that starts with the pad left pressing on
the object (a resume after the host was killed or frozen at contact, the object closer than the rig file says) backs
off along the pad's axis until the load is gone before it zeroes, never adds force to the load it found, and says the
load it leaves; a contact that does not let go is refused with the measured load; the last unloaded zero is kept
with the session for a resume.

Forces are the simulator's ground truth (``SimArm.true_wrench``), not the wrist's reading.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from drivers.clock import VirtualClock
from tests.collection.test_motion_safety import MisplacedRig, few
from unitac_rig.collection.session import collect_session, plan_presses
from unitac_rig.collection.wrist import read_zero, unload_wrist
from unitac_rig.errors import SafetyLimit
from unitac_rig.rig.config import LimitsConfig
from unitac_rig.rig.objects import get_object
from unitac_rig.rig.poses import tool_z
from unitac_rig.sim.arm import SimArm
from unitac_rig.storage.reader import read_presses
from unitac_rig.storage.recorder import journal_dir, session_path

NEAR_ZERO_N = 1.0  # a zero taken with less than this true load on the pad is an unloaded zero


def _config():  # type: ignore[no-untyped-def]
    return few(3, press={"angle_count": 3, "angle_min_deg": -2.0, "angle_max_deg": 2.0})


class Watch:
    """Clock listener and ``zero_ft`` spy: the true |F| at every zero, and the true peak after the first zero."""

    def __init__(self, rig: MisplacedRig) -> None:
        self.arm = rig.sim_arm
        self.zeros_at_n: list[float] = []
        self.peak_after_zero_n = 0.0
        self.peak_n = 0.0
        zero = self.arm.zero_ft

        def spy() -> None:
            self.zeros_at_n.append(self._true())
            zero()

        self.arm.zero_ft = spy  # type: ignore[method-assign]
        rig.clock.on_advance(self)

    def _true(self) -> float:
        return float(np.linalg.norm(self.arm.true_wrench()[:3]))

    def __call__(self, now_ns: int) -> None:
        self.peak_n = max(self.peak_n, self._true())
        if self.zeros_at_n:
            self.peak_after_zero_n = max(self.peak_after_zero_n, self._true())


def _leave_pad_loaded(rig: MisplacedRig, load_n: float, sensor: str) -> float:
    """The state a killed or frozen host leaves: the pad pressed into the object on the first press's ray with
    ``load_n`` true, the controller's F/T zero taken earlier on an unloaded pad; -> the true load."""
    obj = get_object("circle_pla")
    rig.mount(obj, 0.0, sensor)
    arm = rig.sim_arm
    arm.zero_ft()
    plan = plan_presses(obj, rig.config, [0.0])[0]
    pose = plan.start_pose.copy()
    pose[:3] -= plan.direction * 0.03
    arm.move_linear(pose, 0.05, 0.5)
    while np.linalg.norm(arm.true_wrench()[:3]) < load_n:
        pose[:3] += plan.direction * 0.0002
        arm.move_linear(pose, 0.01, 0.5)
    return float(np.linalg.norm(arm.true_wrench()[:3]))


@pytest.mark.parametrize("closer_mm", [10.0, 20.0])
def test_a_resume_with_the_pad_left_loaded_and_the_object_closer_never_zeroes_it_nor_adds_force(
    tmp_path: Path, closer_mm: float
) -> None:
    """The issue's first row: 27.9-30.2 N true when the session zeroed the 17 N it found and pressed 10.8 N more."""
    config = _config()
    with MisplacedRig(config, (0.0, -closer_mm / 1000.0), seed=0) as rig:
        start_n = _leave_pad_loaded(rig, 17.0, "papillarray")
        watch = Watch(rig)
        with pytest.raises(SafetyLimit) as info:  # the stand-off lies inside the object: the first move touches
            collect_session(rig, get_object("circle_pla"), "papillarray", tmp_path)
        left_n = float(np.linalg.norm(rig.sim_arm.true_wrench()[:3]))
    assert all(z < NEAR_ZERO_N for z in watch.zeros_at_n)  # no zero under load (here: no zero at all)
    assert watch.peak_n <= start_n + 0.5  # nothing pressed harder than the fault had already
    assert watch.peak_after_zero_n <= 15.0
    assert "touched something" in str(info.value) and "the pad is left unloaded" in str(info.value)
    assert left_n < 0.5


def test_a_loaded_start_on_a_well_placed_object_unloads_zeroes_free_and_then_presses_within_bounds(
    tmp_path: Path,
) -> None:
    config = _config()
    with MisplacedRig(config, (0.0, 0.0), seed=0) as rig:
        _leave_pad_loaded(rig, 17.0, "uskin")
        watch = Watch(rig)
        outcome = collect_session(rig, get_object("circle_pla"), "uskin", tmp_path)
    assert outcome.complete == 3
    assert watch.zeros_at_n and max(watch.zeros_at_n) < NEAR_ZERO_N
    assert watch.peak_after_zero_n <= 15.0
    assert any("the pad was loaded with 1" in note for note in outcome.recovery_notes)  # ~17 N measured
    for record in read_presses(session_path(tmp_path, "circle_pla", "uskin")):
        assert record.attrs["peak_force_n"] < 12.5  # the zero did not hide a 17 N load under the press


def test_the_last_unloaded_zero_is_kept_with_the_session_for_a_resume(tmp_path: Path) -> None:
    config = _config()
    with MisplacedRig(config, (0.0, 0.0), seed=0) as rig:
        collect_session(rig, get_object("circle_pla"), "uskin", tmp_path, max_presses=2)
    records = read_presses(session_path(tmp_path, "circle_pla", "uskin"))
    kept = read_zero(journal_dir(tmp_path, "circle_pla", "uskin"))
    assert kept is not None
    assert any(np.allclose(kept, r.attrs["ft_zero_offset"]) for r in records)


class _SoftSpring:
    """A contact that lets go only slowly: 0.25 N per mm along the pad's axis, 20 N at the start pose."""

    def __init__(self, start: np.ndarray) -> None:
        self.start = np.asarray(start[:3], dtype=np.float64).copy()
        self.axis = tool_z(start)

    def wrench_on_tool(self, tcp_pose: np.ndarray) -> np.ndarray:
        depth_mm = 1000.0 * float(np.dot(np.asarray(tcp_pose[:3]) - self.start, self.axis)) + 80.0
        return np.concatenate([-self.axis * 0.25 * max(depth_mm, 0.0), np.zeros(3)])


def test_a_contact_that_does_not_let_go_is_refused_with_the_measured_load() -> None:
    start = np.array([-0.15, 0.55, 0.2, 0.0, 2.2214, -2.2214])
    arm = SimArm(_SoftSpring(start), clock=VirtualClock(), rng=np.random.default_rng(0), start_pose=start)
    with pytest.raises(SafetyLimit) as info:
        unload_wrist(arm, LimitsConfig())
    text = str(info.value)
    assert "still loaded after backing 45 mm" in text and "fell by 1" in text  # ~11 N of the 20 N measured
    assert float(np.linalg.norm(arm.true_wrench()[:3])) < 20.0  # it backed off, never pushed


def test_a_free_pad_costs_one_short_back_off() -> None:
    start = np.array([-0.15, 0.55, 0.2, 0.0, 2.2214, -2.2214])
    far = _SoftSpring(start)
    far.start = far.start + far.axis * 0.2  # the spring's surface is 120 mm ahead: nothing touches
    arm = SimArm(far, clock=VirtualClock(), rng=np.random.default_rng(0), start_pose=start)
    free = unload_wrist(arm, LimitsConfig())
    assert not free.was_loaded and free.backed_mm == pytest.approx(3.0, abs=0.3)
