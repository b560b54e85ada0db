"""The physics added to close the gap to the recorded signals (issue 12), each on a case worked by hand.

* the uSkin skin bulge: a lateral reading -kappa * dF/ds (the skin squeezed out from under a pressure gradient),
  and a soft wall's surface drag, the same form across the pad;
* the pad pitch: vertical shear tan(beta) x normal, capped by friction together with the in-plane shear;
* one fitted friction coefficient per pad (skin, pillars), the same on PLA and TPU, and shear that follows the
  outline's slope on soft walls too;
* the seeded object centring error and pad pitch, drawn per scene, and the simulated rig's seeding of them;
* a sensor pad mounted off the tool axis: a cylinder met off its crest, and the torque moved to the TCP;
* two terms the default scene leaves off (measured, docs/simulator.md): the prism bending as a cantilever (the
  contact deeper toward its base) and a seeded rotation of the object on its adapter;
* a third it leaves off (issue 38): the uSkin's magnets reading a load through the skin a contact leaves under it;
* the skin sheared along each flank's own normal, turned back by friction (issue 38; the realistic twin's
  ``flank_friction``): a corner's angle reaches the uSkin's shear.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from drivers.layouts import PAPILLARRAY, USKIN, SensorLayout
from unitac_rig.errors import ConfigError
from unitac_rig.rig.config import parse_rig_config
from unitac_rig.rig.objects import ObjectSpec, get_object
from unitac_rig.rig.poses import rotvec_to_matrix
from unitac_rig.sim.fast_rig import SimRig
from unitac_rig.sim.scene import PressScene, SceneParams, bending_tilt_rad_per_n
from unitac_rig.sim.scene_pads import PillarPad, flank_shear_ratio, tilted_profile

EXACT = SceneParams().exact()  # object placed and pad mounted exactly: only the term under test differs


def grid(object_id: str, layout: SensorLayout, angle_deg: float, params: SceneParams) -> np.ndarray:
    s = PressScene(get_object(object_id), 0.0, layout, params=params)
    return layout.to_grid(s.loads_at_force(angle_deg, 10.0).forces_n)


def gaussian(s_mm: float, sigma_mm: float) -> float:
    return math.exp(-0.5 * (s_mm / sigma_mm) ** 2) / (sigma_mm * math.sqrt(2.0 * math.pi))


def test_a_line_contact_pushes_the_skin_apart_by_the_stated_gain() -> None:
    # The square's corner at 45 deg is a line load F = 10 N on the boundary between columns 2 and 3 (s = 0). Spread
    # by the Gaussian (sigma), the line density at s = 0 is F g(0) and at s = -7.25 mm F g(7.25), so column 2's
    # lateral reading is -kappa (F g(0) - F g(7.25)), column 3's the opposite, and the outer columns get almost
    # nothing. The bulge is internal to the skin: it sums to zero and leaves the wrench alone.
    kappa, sigma = EXACT.skin_bulge_mm, EXACT.skin_spread_sigma_mm
    on = grid("square_pla", USKIN, 45, EXACT)
    off = grid("square_pla", USKIN, 45, replace(EXACT, skin_bulge_mm=0.0))
    bulge = (on - off)[..., 0]
    column = bulge.sum(axis=0)
    expected = -kappa * 10.0 * (gaussian(0.0, sigma) - gaussian(7.25, sigma))
    assert column[2] == pytest.approx(expected, rel=0.02)  # the contact is a hair wider than a line
    assert np.allclose(bulge, -bulge[:, ::-1], atol=1e-9)  # a symmetric contact: antisymmetric readings
    assert abs(column[1]) < 0.01 * abs(column[2])
    assert bulge.sum() == pytest.approx(0.0, abs=1e-9)
    assert np.allclose(bulge[:, 2] / column[2], on[:, 2, 2] / on[:, 2, 2].sum())  # rows share it like the load
    s = PressScene(get_object("square_pla"), 0.0, USKIN, params=EXACT)
    wrench = s.wrench_on_tool(s.pose_at_travel(45, s.travel_at_force_mm(45, 10.0)))
    a = math.radians(45)
    tool_x = np.array([math.cos(a), math.sin(a), 0.0])
    assert on[..., 0].sum() == pytest.approx(wrench[:3] @ tool_x, abs=1e-9)


def with_drag(object_id: str, drag_mm: float) -> ObjectSpec:
    obj = get_object(object_id)
    return replace(obj, material_params=replace(obj.material_params, skin_drag_mm=drag_mm))


def test_a_soft_wall_drags_the_skin_apart_like_a_larger_bulge_across_the_pad_only() -> None:
    # A stretching wall surface drags the skin outward from the contact with the same -drag * dF/ds form as the
    # bulge, across the pad only (the prism is uniform along its axis, so nothing stretches up the pad). On the
    # square's corner (a rigid wall, so the loads are the same with and without it): drag 0.7 mm and no bulge read
    # the same x as a bulge of 0.7 mm; the y readings (the bulge at the pad's top and bottom) are untouched, and
    # the drag, internal to the pad like the bulge, leaves the wrench alone.
    def loads(obj: ObjectSpec, params: SceneParams) -> tuple[np.ndarray, np.ndarray]:
        s = PressScene(obj, 0.0, USKIN, params=params)
        pose = s.pose_at_travel(45, s.travel_at_force_mm(45, 10.0))
        return USKIN.to_grid(s.taxel_loads(pose).forces_n), s.wrench_on_tool(pose)

    dragged, wrench = loads(with_drag("square_pla", 0.7), EXACT)
    plain, plain_wrench = loads(get_object("square_pla"), EXACT)
    as_bulge, _ = loads(get_object("square_pla"), replace(EXACT, skin_bulge_mm=EXACT.skin_bulge_mm + 0.7))
    assert np.abs(dragged[..., 0] - plain[..., 0]).max() > 0.1  # it moves the readings (N of shear)
    assert np.allclose(dragged[..., 0], as_bulge[..., 0], atol=1e-9)
    assert np.allclose(dragged[..., 1:], plain[..., 1:], atol=1e-9)
    assert np.allclose(wrench, plain_wrench, atol=1e-9)


@pytest.mark.parametrize(("drag_mm", "sigma_mm"), [(-0.1, 2.0), (0.5, 0.0)])
def test_a_negative_drag_or_one_without_spreading_is_a_config_error(drag_mm: float, sigma_mm: float) -> None:
    params = replace(EXACT, skin_bulge_mm=0.0, skin_spread_sigma_mm=sigma_mm)
    with pytest.raises(ConfigError):
        PressScene(with_drag("circle_tpu", drag_mm), 0.0, USKIN, params=params)


def test_the_bulge_pushes_the_top_and_bottom_rows_out_of_the_pad() -> None:
    # The prism is taller than the pad, so the pressure is uniform up the pad and drops to zero at its top and
    # bottom edges (30.6 mm apart). With sigma well under the 7.25 mm from the outer rows' inner edge to the pad edge,
    # the density at that edge is the column's load / pad height: the top row reads +kappa F_col / H (up, out of the
    # pad), the bottom row the opposite, the middle rows nothing.
    g = grid("circle_pla", USKIN, 0, EXACT)
    height = 2 * (1.5 * USKIN.pitch_mm + EXACT.skin_margin_y_mm)
    column_load = g[..., 2].sum(axis=0)
    assert np.allclose(g[0, :, 1], EXACT.skin_bulge_mm * column_load / height, rtol=1e-3, atol=1e-9)
    assert np.allclose(g[3, :, 1], -g[0, :, 1], atol=1e-9)
    assert np.abs(g[1:3, :, 1]).max() < 1e-3 * g[0, :, 1].max()
    # and a circle, pressed square on, now reads negative on the uSkin's x axis: the recorded sessions' minima
    assert g[..., 0].min() < -0.1 * g[..., 2].max()


def test_a_pitched_pad_gives_vertical_shear_tan_beta_times_the_normal_load() -> None:
    # the square's face pressed square on: no in-plane tilt, so each pillar's vertical shear is c tan(beta) x normal
    # (c = the shear projection, under the friction cap here)
    pitched = replace(EXACT, pad_pitch_deg=3.0)
    ratio = EXACT.shear_projection * math.tan(math.radians(3.0))
    pillars = grid("square_pla", PAPILLARRAY, 0, pitched)
    loaded = pillars[..., 2] > 0
    assert loaded.sum() >= 4
    assert np.allclose(pillars[..., 1][loaded], ratio * pillars[..., 2][loaded])
    s = PressScene(get_object("square_pla"), 0.0, PAPILLARRAY, params=pitched)
    loads = s.loads_at_force(0, 10.0)
    assert loads.displacement_mm is not None
    assert np.allclose(loads.displacement_mm[:, 1], loads.forces_n[:, 1] / EXACT.pillar_lateral_n_per_mm)
    # the pad's vertical axis is the base's: the wrist feels the sum as a vertical force
    wrench = s.wrench_on_tool(s.pose_at_travel(0, s.travel_at_force_mm(0, 10.0)))
    assert wrench[2] == pytest.approx(loads.forces_n[:, 1].sum(), rel=1e-6)
    assert wrench[2] == pytest.approx(ratio * 10.0, rel=1e-3)
    # the uSkin: the traction adds c tan(beta) x the total normal load up the pad (the bulge sums to zero)
    skin = grid("square_pla", USKIN, 0, pitched)
    assert skin[..., 1].sum() == pytest.approx(ratio * 10.0, rel=1e-6)
    # beta < 0 pushes down
    assert grid("square_pla", PAPILLARRAY, 0, replace(EXACT, pad_pitch_deg=-3.0))[1, 1, 1] < 0


def test_pitch_shear_is_capped_by_friction_with_the_in_plane_shear() -> None:
    frictionless = replace(EXACT, shear_projection=1.0, pillar_friction=0.32)  # the shear is the full tilt, capped
    mu = frictionless.pillar_friction
    # alone: a 30 deg pitch (tan 0.58) is capped at mu
    steep = grid("square_pla", PAPILLARRAY, 0, replace(frictionless, pad_pitch_deg=30.0))
    loaded = steep[..., 2] > 0
    assert np.allclose(steep[..., 1][loaded], mu * steep[..., 2][loaded])
    # with the face tilted 20 deg under the left column (tan 0.36) and a 10 deg pitch (tan 0.18): the shear vector
    # |(0.36, 0.18)| = 0.41 > mu is scaled back to mu along its own direction
    both = grid("square_pla", PAPILLARRAY, 20, replace(frictionless, pad_pitch_deg=10.0))
    column = both[:, 0]
    assert np.all(column[:, 2] > 0.5)
    assert np.allclose(np.hypot(column[:, 0], column[:, 1]), mu * column[:, 2])
    assert np.allclose(column[:, 1] / column[:, 0], math.tan(math.radians(10)) / math.tan(math.radians(20)))


def test_skin_shear_is_capped_by_the_skin_friction_on_pla_and_tpu_alike() -> None:
    # A steep projection (c = 1000) caps every tilted segment at the skin's friction. With almost no spreading the
    # circle's contact (centred on the boundary between columns 2 and 3) puts its left half in column 2, all pushed
    # toward -x: column 2 reads -mu x its normal load. The same holds on TPU (its wall's drag switched off here): a
    # soft wall does not flatten the interface's tilt away (the recorded TPU sessions' lateral readings are as large
    # as PLA's).
    params = replace(EXACT, shear_projection=1000.0, skin_spread_sigma_mm=0.01, skin_bulge_mm=0.0)
    for obj in (get_object("circle_pla"), with_drag("circle_tpu", 0.0)):
        g = USKIN.to_grid(PressScene(obj, 0.0, USKIN, params=params).loads_at_force(0, 10.0).forces_n)
        assert np.allclose(g[:, 2, 0], -params.skin_friction * g[:, 2, 2], rtol=0.02)
        assert np.allclose(g[:, 3, 0], params.skin_friction * g[:, 3, 2], rtol=0.02)


def test_seeded_errors_are_drawn_per_scene_and_repeat_with_the_seed() -> None:
    params = SceneParams(centring_error_mm=0.75, pad_pitch_deg=3.5, pad_pitch_sd_deg=0.5)
    obj = get_object("hex_pla")

    def draw(seed: int) -> tuple[float, float, float]:
        s = PressScene(obj, 0.0, PAPILLARRAY, params=params, rng=np.random.default_rng(seed))
        return (*s.center_mm.tolist(), s.pad_pitch_deg)

    assert draw(3) == draw(3)
    assert draw(3) != draw(4)
    pitches = np.array([draw(seed)[2] for seed in range(200)])
    assert pitches.mean() == pytest.approx(3.5, abs=0.15) and pitches.std() == pytest.approx(0.5, rel=0.2)
    fixed = PressScene(obj, 0.0, PAPILLARRAY, params=replace(params, pad_pitch_sd_deg=0.0))
    assert fixed.pad_pitch_deg == 3.5
    exact = PressScene(obj, 0.0, PAPILLARRAY, params=params.exact(), rng=np.random.default_rng(3))
    assert exact.pad_pitch_deg == 0.0 and np.allclose(exact.center_mm, [-150.0, 625.0])


def test_simulated_rig_seeds_the_scene_from_what_is_mounted() -> None:
    # the same seed, object and sensor give the same scene whatever ran before. Swapping the sensor keeps the object
    # where it stands (the paper's procedure), so both sensors see one placement error; the pad pitch is the
    # sensor mount's own
    config = parse_rig_config({})

    def mounted(seed: int, sensor: str, object_id: str = "square_tpu") -> tuple[tuple[float, ...], float]:
        with SimRig(config, seed=seed) as rig:
            rig.mount(get_object(object_id), 0.0, sensor)
            scene = rig.world.scene
            return tuple(scene.center_mm.tolist()), scene.pad_pitch_deg

    first = mounted(0, "papillarray")
    mounted(0, "uskin")
    assert mounted(0, "papillarray") == first
    uskin = mounted(0, "uskin")
    assert uskin[0] == first[0]  # one placement of the object for both sensors
    assert uskin[1] != first[1]  # two sensor mounts
    assert np.linalg.norm(np.array(first[0]) - [-150.0, 625.0]) > 0.0
    assert mounted(1, "papillarray")[0] != first[0]
    assert mounted(0, "papillarray", "square_pla")[0] != first[0]


def test_a_shared_placement_gives_both_pads_the_same_centring_error() -> None:
    params = SceneParams(centring_error_mm=1.0, pad_pitch_sd_deg=0.5)
    obj = get_object("hex_pla")
    a = PressScene(obj, 0.0, USKIN, params=params, rng=np.random.default_rng(1), placement_rng=np.random.default_rng(9))
    b = PressScene(
        obj, 0.0, PAPILLARRAY, params=params, rng=np.random.default_rng(2), placement_rng=np.random.default_rng(9)
    )
    alone = PressScene(obj, 0.0, PAPILLARRAY, params=params, rng=np.random.default_rng(2))
    expected = np.array([-150.0, 625.0]) + np.random.default_rng(9).standard_normal(2) * 1.0
    assert np.allclose(a.center_mm, expected) and np.allclose(b.center_mm, expected)
    assert a.pad_pitch_deg != b.pad_pitch_deg
    # without a placement generator the scene draws both from its own, centring first (the order a seed has meant)
    own = np.random.default_rng(2)
    assert np.allclose(alone.center_mm, np.array([-150.0, 625.0]) + own.standard_normal(2) * 1.0)
    assert alone.pad_pitch_deg == pytest.approx(params.pad_pitch_deg + own.standard_normal() * 0.5)


def test_a_pillar_pad_mounted_off_the_tool_axis_meets_a_cylinder_off_its_crest() -> None:
    # Pad centre m = -1.3 mm along its x from the TCP, press aimed at the cylinder's axis: the centre column's tips
    # (radius 3 mm) meet the circle (radius 25 mm) 1.3 mm off its crest, where the line between the centres leans
    # by m / sqrt(28^2 - m^2) = -0.04648; the shear follows that lean part-way: x / z = c * -0.04648 = -0.02556
    # (under the 0.45 friction cap). Centred, the cylinder gives no lateral load at all.
    m = -1.3
    params = replace(EXACT, pillar_pad_offset_mm=m)
    circle = get_object("circle_pla")
    loads = PAPILLARRAY.to_grid(PressScene(circle, 0.0, PAPILLARRAY, params=params).loads_at_force(0.0, 10.0).forces_n)
    centre = loads[:, 1]  # the middle column, every row
    assert np.all(centre[:, 2] > 0.5)
    lean = m / math.sqrt(28.0**2 - m**2)
    assert np.allclose(centre[:, 0] / centre[:, 2], params.shear_projection * lean, rtol=1e-3)
    centred = PAPILLARRAY.to_grid(PressScene(circle, 0.0, PAPILLARRAY, params=EXACT).loads_at_force(0.0, 10.0).forces_n)
    assert np.allclose(centred[..., 0], 0.0, atol=1e-9)
    # the offset is the PapillArray's mount: the uSkin scene reads its own (skin_pad_offset_mm), here 0
    skin = PressScene(circle, 0.0, USKIN, params=params).loads_at_force(0.0, 10.0).forces_n
    assert np.allclose(skin, PressScene(circle, 0.0, USKIN, params=EXACT).loads_at_force(0.0, 10.0).forces_n)


@pytest.mark.parametrize("layout", [PAPILLARRAY, USKIN], ids=["papillarray", "uskin"])
def test_an_offset_pad_reads_as_the_object_moved_and_its_torque_is_taken_about_the_tcp(layout: SensorLayout) -> None:
    # A pad m mm along the tool's x from the TCP sees what a centred pad sees with the object m mm the other way;
    # the force is the same, and the torque about the TCP gains r x F with r = (m, 0, 0) mm.
    m = 2.0
    key = "pillar_pad_offset_mm" if layout is PAPILLARRAY else "skin_pad_offset_mm"
    obj = get_object("hex_pla")
    offset = PressScene(obj, 0.0, layout, params=replace(EXACT, **{key: m}))
    moved = PressScene(obj, 0.0, layout, params=EXACT)
    pose = offset.pose_at_travel(10.0, 0.8)
    rot = rotvec_to_matrix(pose[3:])
    moved.center_mm = moved.center_mm - m * rot[:2, 0]  # the tool's x in the base plane
    assert offset.touch_distance_mm(10.0) == pytest.approx(moved.touch_distance_mm(10.0))
    assert np.allclose(offset.taxel_loads(pose).forces_n, moved.taxel_loads(pose).forces_n)
    w_offset, w_moved = offset.wrench_on_tool(pose), moved.wrench_on_tool(pose)
    force = rot.T @ w_moved[:3]
    assert np.allclose(rot.T @ w_offset[:3], force)
    assert abs(force[0]) > 0.1 and force[2] < -2.0  # a tilted face: shear as well as the press
    expected = rot.T @ w_moved[3:] + np.cross([m * 1e-3, 0.0, 0.0], force)
    assert np.allclose(rot.T @ w_offset[3:], expected, atol=1e-9)


def test_a_prism_tilts_as_a_cantilever_of_its_hollow_section() -> None:
    # theta / P = L^2 / (2 E I). Square tube, outer side a = 35.355 mm, inner b = 30.355 mm: I = (a^4 - b^4) / 12
    # = 59,453 mm^4; TPU E = 26 MPa, L = 70 mm: 4900 / (2 * 26 * 59,453) = 1.585e-3 rad/N (0.91 deg at 10 N).
    # Circle tube 25 / 22.5 mm: I = pi / 4 (25^4 - 22.5^4) = 105,507 mm^4 (the catalogue's polygon within 0.1 %).
    square, circle = get_object("square_tpu"), get_object("circle_tpu")
    a, b = 2 * 17.6777, 2 * 15.1777
    assert bending_tilt_rad_per_n(square, 70.0) == pytest.approx(70.0**2 / (2 * 26.0 * (a**4 - b**4) / 12), rel=1e-4)
    i_circle = math.pi / 4 * (25.0**4 - 22.5**4)
    assert bending_tilt_rad_per_n(circle, 70.0) == pytest.approx(70.0**2 / (2 * 26.0 * i_circle), rel=1e-3)
    # PLA is 135 times stiffer, and no lever is no bending
    assert bending_tilt_rad_per_n(get_object("square_pla"), 70.0) == pytest.approx(
        bending_tilt_rad_per_n(square, 70.0) * 26.0 / 3500.0
    )
    assert bending_tilt_rad_per_n(square, 0.0) == 0.0


def test_a_tilting_prism_presses_the_pillars_nearer_its_base_harder() -> None:
    # Nine pillars, all touching at once (gap 0), 1 N/mm each, pushed 1 mm: P = sum k (d - theta y) = 9 N because
    # the rows' heights (+7, 0, -7 mm) cancel, so theta = 0.01 rad/N * 9 N = 0.09 rad, and the top row carries
    # 1 - 0.09 * 7 = 0.37 N per pillar, the middle 1 N, the bottom 1.63 N.
    pad = PillarPad(PAPILLARRAY, EXACT, tilt_rad_per_n=0.01)
    normal = pad._normal_loads(np.array([1.0]), np.zeros(9), np.ones(9)).reshape(3, 3)
    assert np.allclose(normal, [[0.37] * 3, [1.0] * 3, [1.63] * 3])
    assert normal.sum() == pytest.approx(9.0)
    # without the tilt the rows are equal
    flat = PillarPad(PAPILLARRAY, EXACT)._normal_loads(np.array([1.0]), np.zeros(9), np.ones(9))
    assert np.allclose(flat, 1.0)


def test_the_tilt_shifts_a_skin_line_load_toward_the_base_and_keeps_its_total() -> None:
    # A line load 2 N/mm per mm of depth (2e) up a pad from y = -10 to +10 mm, pushed 0.5 mm: with the tilt the
    # depth at height y is 0.5 - theta y, P = 2 * 0.5 * 20 = 20 N (the heights cancel), theta = 0.002 * 20 = 0.04 rad,
    # so the load at y is 2 (0.5 - 0.04 y): 1.8 N/mm at y = +5, 2.2 at y = -5.
    depth = np.array([0.0, 0.25, 0.5, 1.0])
    line = np.stack([2.0 * depth, 3.0 * depth], axis=1)  # a second channel follows the same depth
    edges = np.linspace(-10.0, 10.0, 41)
    y, width = 0.5 * (edges[:-1] + edges[1:]), np.diff(edges)
    profile = tilted_profile(depth, line, y, width, 0.002, normal=0)
    at = profile[2]  # depth 0.5 mm
    assert np.allclose(at[:, 0], 2.0 * (0.5 - 0.04 * y))
    assert np.allclose(at[:, 1], 1.5 * at[:, 0])
    assert float(at[:, 0] @ width) == pytest.approx(20.0)
    # no tilt: the same load at every height
    assert np.allclose(tilted_profile(depth, line, y, width, 0.0, normal=0)[2, :, 0], 1.0)


def test_a_bending_tpu_prism_loads_the_skin_rows_nearer_its_base() -> None:
    # Off (the default) the rows carry equal shares top and bottom; on, the bottom row (3) carries more than the top
    # (0), the total stays the press force, and the pad feels a moment about its x axis (more load below: tau_x > 0).
    obj = get_object("square_tpu")
    flat = PressScene(obj, 0.0, USKIN, params=EXACT)
    bent = PressScene(obj, 0.0, USKIN, params=replace(EXACT, bending_lever_mm=90.0))
    f_flat = USKIN.to_grid(flat.loads_at_force(0.0, 10.0).forces_n)[..., 2].sum(axis=1)
    f_bent = USKIN.to_grid(bent.loads_at_force(0.0, 10.0).forces_n)[..., 2].sum(axis=1)
    assert f_flat[0] == pytest.approx(f_flat[3], rel=1e-9)
    assert f_bent[3] > 1.2 * f_bent[0]
    assert f_bent.sum() == pytest.approx(10.0, rel=1e-3)
    for scene, moment in ((flat, 0.0), (bent, None)):
        pose = scene.pose_at_travel(0.0, scene.travel_at_force_mm(0.0, 10.0))
        torque_tool = rotvec_to_matrix(pose[3:]).T @ scene.wrench_on_tool(pose)[3:]
        if moment is not None:
            assert abs(torque_tool[0]) < 1e-9
        else:
            assert torque_tool[0] > 0.01  # N*m: ~10 N shifted a few mm below the pad centre


def test_a_rotation_error_turns_the_object_and_leaves_the_centring_draw_alone() -> None:
    obj = get_object("square_pla")
    params = SceneParams(centring_error_mm=1.0, rotation_error_deg=2.0)
    turned = PressScene(
        obj, 0.0, USKIN, params=params, rng=np.random.default_rng(1), placement_rng=np.random.default_rng(9)
    )
    plain = PressScene(
        obj,
        0.0,
        USKIN,
        params=replace(params, rotation_error_deg=0.0),
        rng=np.random.default_rng(1),
        placement_rng=np.random.default_rng(9),
    )
    draws = np.random.default_rng(9).standard_normal(3)
    assert np.allclose(turned.center_mm, plain.center_mm)  # centring first, rotation after
    assert turned.rotation_error_deg == pytest.approx(2.0 * draws[2])
    assert plain.rotation_error_deg == 0.0 and plain.pad_pitch_deg == turned.pad_pitch_deg
    # the square's face turns with it: pressed square-on, the contact tilt is now the drawn angle, so the skin shear
    # no longer cancels across the pad
    shear = USKIN.to_grid(turned.loads_at_force(0.0, 10.0).forces_n)[..., 0].sum()
    assert abs(shear) > 0.05


@pytest.mark.parametrize(
    "bad",
    [
        {"pad_pitch_deg": 50.0},
        {"rotation_error_deg": -1.0},
        {"bending_lever_mm": -5.0},
        {"centring_error_mm": -1.0},
        {"skin_bulge_mm": -0.1},
        {"pillar_friction": -0.2},
        {"skin_bulge_mm": 0.5, "skin_spread_sigma_mm": 0.0},
        {"skin_flank_friction": -0.1},
    ],
)
def test_out_of_range_fidelity_parameters_are_config_errors(bad: dict[str, float]) -> None:
    with pytest.raises(ConfigError):
        SceneParams(**bad)


def test_a_flank_shears_the_skin_along_its_normal_turned_back_by_friction() -> None:
    """Coulomb's cone about the flank's normal: shear/normal tan(phi - atan mu) = (tan phi - mu) / (1 + mu tan phi),
    0 inside the cone. By hand at mu 0.25: a 90 deg corner's flank (tan phi 1) 0.6, an 80 deg one's (phi 50 deg)
    0.7256, a 120 deg one's (tan 30 deg) 0.2861, a flank tilted less than atan 0.25 (14 deg) none."""
    slopes = np.array([1.0, -1.0, math.tan(math.radians(50)), -math.tan(math.radians(30)), 0.2, 0.0])
    expected = [0.6, -0.6, 0.7256, -0.2861, 0.0, 0.0]
    np.testing.assert_allclose(flank_shear_ratio(slopes, 0.25), expected, atol=1e-4)


def test_the_corners_angle_reaches_the_skins_shear_through_its_flanks() -> None:
    """The square at 45 deg (a 90 deg corner) and the hexagon at 30 deg (120 deg): with almost no spreading and no
    bulge each column next to the corner holds one flank, and reads its shear/normal: +-0.6 and +-0.2861 at mu 0.25,
    where the clean twin's cap reads +-0.18 on both."""
    params = replace(EXACT, skin_spread_sigma_mm=0.01, skin_bulge_mm=0.0, skin_flank_friction=0.25)
    for object_id, angle, ratio in (("square_pla", 45.0, 0.6), ("hex_pla", 30.0, 0.2861)):
        g = grid(object_id, USKIN, angle, params)
        np.testing.assert_allclose(g[:, 2, 0], -ratio * g[:, 2, 2], rtol=2e-3)
        np.testing.assert_allclose(g[:, 3, 0], ratio * g[:, 3, 2], rtol=2e-3)
        clean = grid(object_id, USKIN, angle, replace(params, skin_flank_friction=0.0))
        np.testing.assert_allclose(clean[:, 3, 0], EXACT.skin_friction * clean[:, 3, 2], rtol=2e-3)
