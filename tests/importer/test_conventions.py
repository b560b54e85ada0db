"""The authors' rules, one by one, on values worked by hand; and the conventions file that overrides them."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from drivers.layouts import PAPILLARRAY, USKIN
from unitac_rig.errors import ConfigError
from unitac_rig.importer.conventions import ImportConventions, TactileMapping, load_conventions
from unitac_rig.importer.discovery import discover
from unitac_rig.importer.parsing import RawColumns
from unitac_rig.importer.presses import (
    approach_angle_deg,
    nominal_angle_deg,
    press_window,
    rotate_ft,
    segment_presses,
    streams_from_raw,
    to_our_frame,
)

H = math.sqrt(0.5)


def test_ft_rotation_by_45_degrees() -> None:
    ft = np.array([[1.0, 0.0, -7.0, 0.0, 2.0, 0.5], [0.0, 1.0, 0.0, 1.0, 1.0, 0.0]])
    out = rotate_ft(ft, 45.0)
    # x' = x cos - y sin, y' = x sin + y cos; Fz and Mz untouched
    np.testing.assert_allclose(out[0], [H, H, -7.0, -2 * H, 2 * H, 0.5], atol=1e-12)
    np.testing.assert_allclose(out[1], [-H, H, 0.0, 0.0, 2 * H, 0.0], atol=1e-12)


def test_segmentation_follows_their_strict_band_and_minimum_length() -> None:
    #            0    1    2     3     4    5     6   7     8     9    10  11
    fz = np.array([0, -5.0, -5.1, -12, -20.0, -7, -4.9, -6, -19.9, -8, -6, 0])
    runs = segment_presses(fz, (-20.0, -5.0), min_samples=2)
    # -5.0 and -20.0 are outside (strict); run 2..3 (len 2), run 5 (len 1, too short), run 7..10 (len 4)
    assert [(r.start, r.stop, r.peak) for r in runs] == [(2, 4, 3), (7, 11, 8)]
    assert [r.peak for r in segment_presses(fz, (-20.0, -5.0), min_samples=3)] == [8]


def test_approach_angle_from_the_pose_and_the_object_centre() -> None:
    conv = ImportConventions()
    # straight below the centre (y smaller): atan2(-0.1, 0) = -90 deg, + 90 = 0
    assert approach_angle_deg(-0.15, 0.525, conv) == pytest.approx(0.0)
    # 30 deg: dx = 0.1 sin 30 = 0.05, dy = -0.1 cos 30
    assert approach_angle_deg(-0.10, 0.625 - 0.1 * math.cos(math.radians(30)), conv) == pytest.approx(30.0)
    # level with the centre on +x: atan2(0, 0.1) = 0, + 90 = 90; on -x: 180 + 90 = 270 (outside their arc)
    assert approach_angle_deg(-0.05, 0.625, conv) == pytest.approx(90.0)
    assert approach_angle_deg(-0.25, 0.625, conv) == pytest.approx(270.0)
    # rounded like their Python round(): halves go to the even neighbour
    assert [nominal_angle_deg(a) for a in (0.5, 1.5, -2.5, 29.6, -44.51)] == [0, 2, -2, 30, -45]


def test_window_reaches_back_to_the_ramp_start_and_forward_by_the_margin() -> None:
    conv = ImportConventions(ramp_start_n=0.5, max_pre_margin_s=0.055, post_margin_s=0.025)
    t = np.arange(20) * 0.01
    force = np.array([0, 0, 0.2, 0.4, 0.5, 0.9, 3, 6, 9, 11, 8, 6, 2, 0.3, 0, 0, 0, 0, 0, 0.0])
    run = segment_presses(-force, (-20.0, -5.0), 1)[0]
    assert (run.start, run.stop, run.peak) == (7, 12, 9)
    # back: 5 samples of margin reach index 2; the last sample <= 0.5 N before the run is index 4
    assert press_window(t, force, run, 0, 20, conv) == (4, 14, True)
    # a previous press ending at 6 stops the search before the quiet samples
    assert press_window(t, force, run, 6, 20, conv) == (6, 14, False)
    # the next press starting at 13 bounds the end
    assert press_window(t, force, run, 0, 13, conv) == (4, 13, True)


def test_matrix_to_our_frame_and_papillarray_flip() -> None:
    grid = np.arange(3 * 3 * 3, dtype=float).reshape(1, 3, 3, 3)
    same = to_our_frame(grid, TactileMapping())
    assert same.shape == (1, 9, 3)
    np.testing.assert_array_equal(same[0, 5], grid[0, 1, 2])  # taxel 5 = row 1, col 2
    flipped = to_our_frame(grid, TactileMapping(flip_cols=True, axis_signs=(1, -1, 1)))
    np.testing.assert_array_equal(flipped[0, 5], grid[0, 1, 0] * [1, -1, 1])

    raw = RawColumns(
        rows=np.arange(12),
        time_s=np.arange(12) * 0.01,
        seq=np.arange(12),
        force=np.tile(np.array([0.3, -0.2, 1.0]), (12, 3, 3, 1)),
        displacement=np.tile(np.array([0.1, 0.05, 0.2]), (12, 3, 3, 1)),
        ft=np.zeros((12, 6)),
        pose=np.zeros((12, 6)),
    )
    streams = streams_from_raw(raw, PAPILLARRAY, ImportConventions(drop_first_rows=2, baseline_samples=5))
    np.testing.assert_allclose(streams.values[0, 4], [-0.3, 0.2, 1.0])
    assert streams.displacement_mm is not None
    np.testing.assert_allclose(streams.displacement_mm[0, 4], [-0.1, -0.05, 0.2])
    assert streams.rows[0] == 2 and streams.t_s[0] == 0.0
    kept = streams_from_raw(
        raw, PAPILLARRAY, ImportConventions(drop_first_rows=2, baseline_samples=5, papillarray_flip_xy=False)
    )
    np.testing.assert_allclose(kept.values[0, 4], [0.3, -0.2, 1.0])


def test_baseline_needs_enough_samples() -> None:
    raw = RawColumns(
        rows=np.arange(50),
        time_s=np.arange(50) * 0.01,
        seq=np.arange(50),
        force=np.zeros((50, 4, 6, 3)),
        displacement=None,
        ft=np.zeros((50, 6)),
        pose=np.zeros((50, 6)),
    )
    with pytest.raises(ValueError, match="only 40 usable samples"):
        streams_from_raw(raw, USKIN, ImportConventions())


def test_their_names_map_to_our_object_ids() -> None:
    conv = ImportConventions()
    assert conv.object_id("hexagonal", "TPU") == "hex_tpu"
    assert conv.object_id("hexagon", "PLA") == "hex_pla"
    assert conv.object_id("cylinder", "TPU") == "circle_tpu"
    assert conv.object_id("circular", "PLA") == "circle_pla"
    assert conv.object_id("oblong", "PLA") == "square_pla"
    assert conv.object_id("arbitrary", "pla") == "irregular_pla"
    with pytest.raises(ConfigError, match="triangle"):
        conv.object_id("triangle", "PLA")


def test_every_layout_of_theirs_is_recognised(tmp_path: Path) -> None:
    names = [
        "UniTac-NV Dataset/hexagonal_TPU/xela/sensor_data_20250203_154424.csv",
        "UniTac-NV Dataset/square_PLA/papillarray/sensor_data_20250204_144331.csv",
        "arbitrary_obj/papillarray/papil_arbitrary_3.csv",
        "arbitrary_obj/xela/xela_arbitrary_7.csv",
        "UniTac-NV Dataset Processed/Xela/oblong_TPU_xela.npz",
        "UniTac-NV Dataset Processed/PapillArray_arbitrary/arbitrary2_PLA_papillarray.npz",
        "UniTac-NV Dataset Processed/Xela/oblong_TPU_xela.csv",  # their flattened copy: not a session
        "README.md",
    ]
    for name in names:
        (tmp_path / name).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / name).write_text("x")
    found = discover(tmp_path, ImportConventions(), mode="raw")
    got = {(f.relative.split("/")[-1], f.object_id, f.sensor, f.rotation_deg) for f in found.files}
    assert got == {
        ("sensor_data_20250203_154424.csv", "hex_tpu", "uskin", 0.0),
        ("sensor_data_20250204_144331.csv", "square_pla", "papillarray", 0.0),
        ("papil_arbitrary_3.csv", "irregular_pla", "papillarray", 180.0),
        ("xela_arbitrary_7.csv", "irregular_pla", "uskin", None),  # no rotation known for n = 7
    }
    assert found.ignored == ["UniTac-NV Dataset Processed/Xela/oblong_TPU_xela.csv"]
    processed = discover(tmp_path, ImportConventions(), mode="processed").files
    assert {(f.object_id, f.sensor, f.rotation_deg) for f in processed} == {
        ("square_tpu", "uskin", 0.0),
        ("irregular_pla", "papillarray", 90.0),
    }


def test_conventions_file_overrides_only_what_it_names(tmp_path: Path) -> None:
    path = tmp_path / "conv.toml"
    path.write_text(
        "ft_rotation_deg = -45.0\n"
        "[arbitrary_rotation_deg]\n5 = 45.0\n"
        "[tactile_mapping.uskin]\nflip_cols = true\n"
        "[extraction]\ntolerance_n = 0.25\n"
    )
    conv = load_conventions(path)
    assert conv.ft_rotation_deg == -45.0
    assert conv.arbitrary_rotation_deg == {1: 0.0, 2: 90.0, 3: 180.0, 4: 270.0, 5: 45.0}
    assert conv.tactile_mapping["uskin"] == TactileMapping(flip_cols=True)
    assert conv.tactile_mapping["papillarray"] == TactileMapping()
    assert conv.extraction.tolerance_n == 0.25 and conv.extraction.smoothing_samples == 3
    assert conv.drop_first_rows == 10


def test_the_printed_conventions_read_back_unchanged(tmp_path: Path) -> None:
    rotations = {**ImportConventions().arbitrary_rotation_deg, 8: 315.0}
    conv = ImportConventions(arbitrary_rotation_deg=rotations, ramp_start_n=1.0, press_fz_band_n=(-25.0, -4.5))
    path = tmp_path / "printed.toml"
    path.write_text(conv.to_toml())
    assert load_conventions(path) == conv


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("ft_rotaton_deg = 45\n", "ft_rotaton_deg: unknown key"),
        ("press_fz_band_n = [-5.0, -20.0]\n", "low < high"),
        ("[tactile_mapping.uskin]\naxis_signs = [1, 2, 1]\n", "axis_signs"),
        ("[sensor_names]\nxela = 'digit'\n", "sensor_names.xela"),
        ("drop_first_rows = \n", "not valid TOML"),
        ("ft_rotation_deg = nan\n", "ft_rotation_deg: Input should be a finite number"),  # as the rig file refuses
    ],
)
def test_bad_conventions_files_are_refused_by_name(tmp_path: Path, text: str, message: str) -> None:
    path = tmp_path / "bad.toml"
    path.write_text(text)
    with pytest.raises(ConfigError, match=message):
        load_conventions(path)
