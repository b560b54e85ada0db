"""Sensor output models, the scene signal source, the taxel-map figure, and a press through the simulated arm."""

from __future__ import annotations

import math

import numpy as np
import pytest
from matplotlib import _pylab_helpers

from drivers.layouts import PAPILLARRAY, USKIN
from unitac_rig.errors import ConfigError, DataError
from unitac_rig.plotting import draw_taxel_map, new_figure, save_figure
from unitac_rig.rig.objects import get_object
from unitac_rig.sim.scene import PressScene, SceneParams, TaxelLoads
from unitac_rig.sim.sensor_models import COUNTS_MAX, PapillArrayModel, PapillArrayParams, UskinModel, UskinParams
from unitac_rig.sim.source import SceneSensorSource


def _loads(layout_n: int, z: float = 0.0, x: float = 0.0) -> TaxelLoads:
    forces = np.zeros((layout_n, 3))
    forces[:, 0], forces[:, 2] = x, z
    return TaxelLoads(forces)


def test_uskin_baselines_are_seeded_and_in_the_32k_range() -> None:
    a, b = UskinModel(rng=np.random.default_rng(5)), UskinModel(rng=np.random.default_rng(5))
    assert np.array_equal(a.baseline_counts, b.baseline_counts)
    assert not np.array_equal(a.baseline_counts, UskinModel(rng=np.random.default_rng(6)).baseline_counts)
    assert 30_000 < a.baseline_counts.mean() < 36_000
    assert 1_000 < a.baseline_counts.std() < 3_500  # differs per taxel/axis by thousands


def test_uskin_counts_rise_with_load_at_the_gain_and_idle_noise_is_small() -> None:
    params = UskinParams(gain_sd_fraction=0.0, crosstalk_sd=0.0)
    model = UskinModel(params, np.random.default_rng(0))
    idle = np.stack([model.sample(_loads(24)).values for _ in range(200)])
    assert np.abs(idle.mean(axis=0) - model.baseline_counts).max() < 3.0
    assert idle.std(axis=0).mean() == pytest.approx(8.0, rel=0.15)
    pressed = model.expected_counts(_loads(24, z=1.0, x=-0.5)) - model.baseline_counts
    assert np.allclose(pressed[:, 2], 1100.0) and np.allclose(pressed[:, 0], -2500.0)  # the fitted nominal gains
    assert np.allclose(pressed[:, 1], 0.0)


def test_uskin_cross_talk_leaks_normal_load_into_shear_channels() -> None:
    model = UskinModel(UskinParams(crosstalk_sd=0.05), np.random.default_rng(2))
    delta = model.expected_counts(_loads(24, z=1.0)) - model.baseline_counts
    leak = np.abs(delta[:, :2]) / delta[:, 2:3]
    assert 0.01 < leak.mean() < 0.1


def test_uskin_counts_clip_to_16_bits() -> None:
    model = UskinModel(rng=np.random.default_rng(0))
    assert model.sample(_loads(24, z=100.0)).values.max() == COUNTS_MAX
    assert model.sample(_loads(24, z=-100.0)).values.min() == 0.0


def test_papillarray_readings_are_quantised_and_carry_displacement() -> None:
    model = PapillArrayModel(PapillArrayParams(offset_sd_mm=0.0), np.random.default_rng(0))
    # loads as the scene gives them: force = k * displacement, k = 1.2 N/mm lateral, 6 N/mm axial
    loads = TaxelLoads(np.tile([0.3, 0.0, 2.0], (9, 1)), np.tile([0.25, 0.0, 2.0 / 6.0], (9, 1)))
    samples = [model.sample(loads) for _ in range(300)]
    values = np.stack([s.values for s in samples])
    disp = np.stack([s.displacement_mm for s in samples if s.displacement_mm is not None])
    assert np.allclose(values * 1000, np.round(values * 1000), atol=1e-6)  # 1 mN steps
    assert np.allclose(disp * 1000, np.round(disp * 1000), atol=1e-6)  # 1 um steps
    assert values[..., 2].mean() == pytest.approx(2.0, abs=0.005)
    assert disp[..., 2].mean() == pytest.approx(0.333, abs=0.002)
    # the force is computed from the measured displacement: one noise, 0.005 mm on the tip, 6 x 0.005 = 0.03 N on z
    # and 1.2 x 0.005 = 0.006 N across; each reading's force is its displacement through the calibration
    assert disp[..., 2].std() == pytest.approx(0.005, rel=0.15)
    assert values[..., 2].std() == pytest.approx(0.03, rel=0.15)
    assert values[..., 0].std() == pytest.approx(0.006, rel=0.15)
    assert np.allclose(values, disp * [1.2, 1.2, 6.0], atol=0.005)


def test_unbiased_papillarray_shows_seeded_offsets_in_force_and_displacement_alike() -> None:
    model = PapillArrayModel(rng=np.random.default_rng(9))
    samples = [model.sample(TaxelLoads(np.zeros((9, 3)), np.zeros((9, 3)))) for _ in range(100)]
    idle = np.mean([s.values for s in samples], axis=0)
    idle_mm = np.mean([s.displacement_mm for s in samples if s.displacement_mm is not None], axis=0)
    assert np.allclose(idle, model.offset_n, atol=0.01) and np.allclose(idle_mm, model.offset_mm, atol=0.002)
    assert np.allclose(model.offset_n, model.offset_mm * [1.2, 1.2, 6.0])
    assert 0.05 < np.abs(model.offset_n[:, 2]).mean() < 0.2  # ~0.1 N on z until the hub's bias command


def test_scene_source_reads_the_pose_it_is_given() -> None:
    scene = PressScene(get_object("circle_pla"), 0.0, PAPILLARRAY, params=SceneParams().exact())
    model = PapillArrayModel(PapillArrayParams(offset_sd_mm=0.0, noise_mm=0.0), np.random.default_rng(0))
    poses = iter([scene.pose_at_travel(0, -1.0), scene.pose_at_travel(0, scene.travel_at_force_mm(0, 10.0))])
    source = SceneSensorSource(scene, model, lambda: next(poses))
    before, pressed = source.sample(0), source.sample(10_000_000)
    assert np.all(before.values == 0)
    assert pressed.values[:, 2].sum() == pytest.approx(10.0, abs=0.01)
    assert pressed.displacement_mm is not None and pressed.displacement_mm[4, 2] == pytest.approx(0.822, abs=0.002)
    assert source.samples == 2


def test_scene_source_builds_a_default_model_and_refuses_a_mismatched_one() -> None:
    scene = PressScene(get_object("hex_pla"), 0.0, USKIN)
    source = SceneSensorSource(scene, None, lambda: scene.pose_at_travel(0, -1.0))
    assert 20_000 < source.sample(0).values.mean() < 45_000
    with pytest.raises(ConfigError):
        SceneSensorSource(scene, PapillArrayModel(), lambda: np.zeros(6))


def test_taxel_map_colours_cells_by_normal_force_and_draws_shear_arrows(tmp_path: object) -> None:
    frame = np.zeros((24, 3))
    frame[:, 2] = np.arange(24)
    frame[7] = [1.0, -2.0, 3.0]
    fig = new_figure(3, 2)
    ax = fig.subplots()
    mesh = draw_taxel_map(ax, USKIN, frame, title="t")
    colours = np.asarray(mesh.get_array()).reshape(4, 6)
    assert np.array_equal(colours, USKIN.to_grid(frame)[..., 2])  # row 0 on top, columns left to right
    quiver = ax.collections[1]
    u, v = np.asarray(quiver.U), np.asarray(quiver.V)  # type: ignore[attr-defined]
    assert (u[7], v[7]) == (1.0, -2.0)
    assert np.count_nonzero(np.hypot(u, v)) == 1
    assert not _pylab_helpers.Gcf.get_all_fig_managers()  # nothing registered with pyplot
    from pathlib import Path

    out = save_figure(fig, Path(str(tmp_path)) / "map.png")
    assert out.read_bytes()[:4] == b"\x89PNG"
    with pytest.raises(DataError):
        draw_taxel_map(ax, PAPILLARRAY, frame)


def test_press_through_the_simulated_arm_overshoots_the_stop_like_the_recordings() -> None:
    # recorded peaks overshoot the 10 N stop by 0.6-1.8 N; the overshoot comes from the arm's stop latency and F/T
    # filter (unitac_rig.sim.arm) acting on this scene's stiffness
    clock_mod = pytest.importorskip("drivers.clock")
    motion = pytest.importorskip("unitac_rig.collection.guarded_motion")
    sim_arm = pytest.importorskip("unitac_rig.sim.arm")
    for object_id in ("square_pla", "circle_tpu"):
        for layout in (USKIN, PAPILLARRAY):
            peaks = []
            for seed in range(2):
                scene = PressScene(get_object(object_id), 0.0, layout)
                arm = sim_arm.SimArm(
                    scene,
                    clock=clock_mod.VirtualClock(),
                    rng=np.random.default_rng(seed),
                    start_pose=scene.pose_at_travel(20, -2.0),
                )
                try:
                    arm.zero_ft()
                    a = math.radians(20)
                    direction = np.array([-math.sin(a), math.cos(a), 0.0])
                    result = motion.guarded_move(arm, direction, 0.005, 10.0, max_travel_m=0.02, hard_limit_n=40.0)
                finally:
                    arm.close()
                assert result.reason == "force"
                peaks.append(result.peak_press_force_n)
            assert 10.2 < float(np.mean(peaks)) < 12.5, (object_id, layout.name, peaks)
