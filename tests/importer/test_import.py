"""End to end: small files in their exact formats become session files whose force-matched frames we worked by hand."""

from __future__ import annotations

import math
from pathlib import Path

import h5py
import numpy as np
import pytest

from tests.helpers import cli
from tests.importer.unitac_nv_fixtures import QUIET, Press, write_processed_npz, write_raw_csv
from unitac_rig.errors import ConfigError, DataError
from unitac_rig.importer.conventions import ImportConventions, conventions_from_dict
from unitac_rig.importer.pipeline import import_unitac_nv
from unitac_rig.storage.press_record import PressRecord
from unitac_rig.storage.reader import list_sessions, load_matched_set, load_matched_sets, read_presses
from unitac_rig.storage.recorder import SessionWriter, journal_dir

RAW_XELA = "UniTac-NV Dataset/hexagonal_TPU/xela/sensor_data_20250203_154424.csv"
RAW_PAPIL = "UniTac-NV Dataset/hexagonal_TPU/papillarray/sensor_data_20250202_174333.csv"
PROCESSED_XELA = "UniTac-NV Dataset Processed/Xela/hexagon_TPU_xela.npz"
H = math.sqrt(0.5)


def _presses(path: Path) -> dict[str, PressRecord]:
    return {p.press_id: p for p in read_presses(path)}


def test_raw_uskin_session_becomes_presses_with_hand_worked_frames(tmp_path: Path) -> None:
    write_raw_csv(tmp_path / "src" / RAW_XELA, "uskin", [Press(-1.0), Press(0.0), Press(1.0, peak_n=9.0)])
    report = import_unitac_nv(tmp_path / "src", tmp_path / "data")

    (session,) = report.sessions
    assert (session.object_id, session.sensor) == ("hex_tpu", "uskin")
    assert (session.presses, session.complete, session.targets_matched, session.targets_total) == (3, 2, 50, 50)
    (info,) = list_sessions(tmp_path / "data")
    assert info.attrs["source"] == "unitac-nv-import"
    assert info.attrs["simulated"] is False
    assert info.attrs["conventions"]["ft_rotation_deg"] == 45.0
    assert isinstance(info.attrs["config"], dict)
    (entry,) = info.attrs["source_files"].values()
    assert entry["path"] == RAW_XELA and entry["presses_found"] == 3

    presses = read_presses(info.path)
    by_id = {p.press_id: p for p in presses}
    assert sorted(by_id) == ["rot000_ang+00", "rot000_ang+01", "rot000_ang-01"]
    assert (by_id["rot000_ang+01"].status, by_id["rot000_ang+01"].reason) == ("failed", "peak_below_threshold")
    first = by_id["rot000_ang-01"]
    assert first.status == "complete"
    # tare: rows 10..109 only (rows 0..9 carry +500 junk, later rows +7 drift): 32000 + 100 r + 10 c + k
    np.testing.assert_allclose(first.tare_baseline[0], [32000, 32001, 32002])
    np.testing.assert_allclose(first.tare_baseline[23], [32350, 32351, 32352])
    # the window starts at the last sample <= 0.5 N: press sample 5, data row QUIET + 5, 1.15 s after row 10
    assert first.press_force_n[0] == pytest.approx(0.5)
    assert first.attrs["source_rows"][0] == QUIET + 5
    assert first.robot_t_s[0] == pytest.approx((QUIET + 5 - 10) * 0.01)
    assert first.attrs["peak_row"] == QUIET + 105
    np.testing.assert_array_equal(first.robot_t_s, first.tactile_t_s)
    # F/T stored after the 45 deg rotation: raw [0.1 f, 0, -f, 0, 0.02 f, 0] at the 10.5 N peak
    peak = int(np.argmax(first.press_force_n))
    np.testing.assert_allclose(
        first.robot_force[peak], [1.05 * H, 1.05 * H, -10.5, -0.21 * H, 0.21 * H, 0.0], rtol=1e-6, atol=1e-6
    )

    matched = load_matched_set(info.path)
    assert len(matched) == 50
    at = {(a, t): i for i, (a, t) in enumerate(zip(matched.angle_deg, matched.target_n, strict=True))}
    four, ten = at[(-1.0, 4.0)], at[(0.0, 10.0)]
    # tared counts = drift 7 + gain * f: x 5 f, y -5 f, z (100 + 10 taxel) f
    np.testing.assert_allclose(matched.values[four, 0], [27.0, -13.0, 407.0], atol=1e-3)
    np.testing.assert_allclose(matched.values[four, 23], [27.0, -13.0, 7 + 330 * 4.0], atol=1e-3)
    np.testing.assert_allclose(matched.values[ten, 0], [57.0, -43.0, 1007.0], atol=1e-3)
    assert matched.force_n[four] == pytest.approx(4.0) and matched.force_n[ten] == pytest.approx(10.0)


def test_papillarray_is_flipped_into_the_shared_axes_and_keeps_displacement(tmp_path: Path) -> None:
    write_raw_csv(tmp_path / "src" / RAW_PAPIL, "papillarray", [Press(3.0)])
    import_unitac_nv(tmp_path / "src", tmp_path / "data")
    (info,) = list_sessions(tmp_path / "data")
    assert info.sensor == "papillarray"
    matched = load_matched_set(info.path)
    four = int(np.nonzero(matched.target_n == 4.0)[0][0])
    # pillar 0 at 4 N: their (0.02 f, 0.01 f, f / 9) -> ours (-0.08, -0.04, 0.444)
    np.testing.assert_allclose(matched.values[four, 0], [-0.08, -0.04, 4 / 9], atol=1e-6)
    (press,) = read_presses(info.path)
    assert press.tactile_displacement_mm is not None
    assert press.extraction is not None
    frame = int(press.extraction.frame_index[0])
    # displacement is kept raw (force / 6, flipped), its tare in the press attributes
    np.testing.assert_allclose(press.tactile_displacement_mm[frame, 0], [-0.08 / 6, -0.04 / 6, (4 / 9) / 6], atol=1e-6)
    np.testing.assert_allclose(press.attrs["displacement_tare_mm"][4], [-0.04 / 6, -0.04 / 6, 0.04 / 6], atol=1e-9)


def test_duplicate_angles_keep_the_press_closest_to_the_nominal_pattern(tmp_path: Path) -> None:
    presses = [Press(0.0, peak_n=9.0), Press(0.3), Press(5.3), Press(5.1)]
    write_raw_csv(tmp_path / "src" / RAW_XELA, "uskin", presses)
    report = import_unitac_nv(tmp_path / "src", tmp_path / "data")
    (file_report,) = report.files
    assert file_report.presses_found == 4 and file_report.written == 2
    assert len(file_report.duplicates) == 2
    assert "rot000_ang+00" in file_report.duplicates[0] and "failed" in file_report.duplicates[0]
    assert "rot000_ang+05" in file_report.duplicates[1] and "+5.30" in file_report.duplicates[1]
    kept = _presses(report.sessions[0].path)
    # a complete press beats a failed one; among complete ones the angle nearer the whole degree wins
    assert kept["rot000_ang+00"].attrs["raw_angle_deg"] == pytest.approx(0.3)
    assert kept["rot000_ang+05"].attrs["raw_angle_deg"] == pytest.approx(5.1)


def test_rerun_skips_imported_files_and_resumes_an_interrupted_one(tmp_path: Path) -> None:
    src, data = tmp_path / "src", tmp_path / "data"
    write_raw_csv(src / RAW_XELA, "uskin", [Press(-1.0), Press(0.0), Press(1.0)])
    first = import_unitac_nv(src, data)
    assert first.files[0].written == 3

    again = import_unitac_nv(src, data)
    assert again.files[0].outcome == "already-imported"
    assert again.sessions[0].presses == 3

    # a kill after two presses: the third press and the file's entry never made it
    path = first.sessions[0].path
    SessionWriter(data, "hex_tpu", "uskin", {"object": "hex_tpu", "sensor": "uskin"}).update_root_attrs(
        {"source_files": {}}
    )
    with h5py.File(path, "a") as f:
        del f["presses/rot000_ang+01"]
    (journal_dir(data, "hex_tpu", "uskin") / "rot000_ang+01.h5").unlink()
    resumed = import_unitac_nv(src, data)
    assert (resumed.files[0].outcome, resumed.files[0].written, resumed.files[0].already_written) == ("imported", 1, 2)
    assert resumed.sessions[0].presses == 3 and resumed.sessions[0].targets_matched == 75


def test_other_conventions_into_an_existing_session_are_refused(tmp_path: Path) -> None:
    write_raw_csv(tmp_path / "src" / RAW_XELA, "uskin", [Press(0.0)])
    import_unitac_nv(tmp_path / "src", tmp_path / "data")
    with pytest.raises(DataError, match="other conventions"):
        import_unitac_nv(tmp_path / "src", tmp_path / "data", ImportConventions(ramp_start_n=1.0))


def test_processed_file_gives_the_same_frames_as_its_raw_file(tmp_path: Path) -> None:
    presses = [Press(-1.0), Press(0.0)]
    write_raw_csv(tmp_path / "raw" / RAW_XELA, "uskin", presses)
    write_processed_npz(tmp_path / "processed" / PROCESSED_XELA, "uskin", presses)
    import_unitac_nv(tmp_path / "raw", tmp_path / "from_raw")
    report = import_unitac_nv(tmp_path / "processed", tmp_path / "from_npz", mode="processed")
    (file_report,) = report.files
    assert file_report.outcome == "imported" and file_report.kind == "processed"
    assert not any("differs" in note for note in file_report.notes)  # our presses = their 'selected'
    (from_raw,) = load_matched_sets(tmp_path / "from_raw")
    (from_npz,) = load_matched_sets(tmp_path / "from_npz")
    assert len(from_npz) == len(from_raw) == 50
    np.testing.assert_array_equal(from_npz.target_n, from_raw.target_n)
    # targets like 4.25 N fall exactly between two 0.1 N samples: either frame is right, so compare the others
    clear = np.isclose(from_raw.target_n * 10, np.round(from_raw.target_n * 10))
    assert clear.sum() == 26
    np.testing.assert_allclose(from_npz.values[clear], from_raw.values[clear], atol=1e-3)
    np.testing.assert_allclose(from_npz.force_n[clear], from_raw.force_n[clear], atol=1e-9)
    (press, _) = read_presses(list_sessions(tmp_path / "from_npz")[0].path)
    np.testing.assert_array_equal(press.tare_baseline, 0.0)


def _write_peaks_only_npz(path: Path) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    np.savez(
        path,
        times=np.array([0.0, 9.0]),
        sensor_matrices_force=np.zeros((2, 3, 3, 3)),
        sensor_matrices_displacement=np.zeros((2, 3, 3, 3)),
        ft_values=np.zeros((2, 6)),
        end_effector_poses=np.zeros((2, 6)),
        selected=np.array([0, 1]),
        angle=np.array([-45, -44]),
    )


def test_auto_mode_prefers_raw_and_peak_only_files_are_refused(tmp_path: Path) -> None:
    src = tmp_path / "src"
    write_raw_csv(src / RAW_XELA, "uskin", [Press(0.0)])
    write_processed_npz(src / PROCESSED_XELA, "uskin", [Press(0.0)])
    _write_peaks_only_npz(src / "UniTac-NV Dataset Processed" / "PapillArray" / "oblong_PLA_papillarray.npz")
    report = import_unitac_nv(src, tmp_path / "data")
    assert report.superseded == [PROCESSED_XELA]
    outcomes = {(f.object_id, f.sensor, f.kind): f for f in report.files}
    assert outcomes[("hex_tpu", "uskin", "raw")].outcome == "imported"
    refused = outcomes[("square_pla", "papillarray", "processed")]
    assert refused.outcome == "failed" and "only the 2 peak samples" in refused.message


def test_arbitrary_files_land_in_one_session_at_their_assumed_rotations(tmp_path: Path) -> None:
    src = tmp_path / "src" / "arbitrary_obj" / "xela"
    write_raw_csv(src / "xela_arbitrary_1.csv", "uskin", [Press(-1.0), Press(0.0)])
    write_raw_csv(src / "xela_arbitrary_2.csv", "uskin", [Press(-1.0, peak_n=10.6), Press(0.0)])
    write_raw_csv(src / "xela_arbitrary_5.csv", "uskin", [Press(0.0)])
    report = import_unitac_nv(tmp_path / "src", tmp_path / "data")
    (session,) = report.sessions
    assert (session.object_id, session.presses) == ("irregular_pla", 4)
    assert sorted(_presses(session.path)) == ["rot000_ang+00", "rot000_ang-01", "rot090_ang+00", "rot090_ang-01"]
    skipped = [f for f in report.files if f.outcome == "skipped"]
    assert [f.relative for f in skipped] == ["arbitrary_obj/xela/xela_arbitrary_5.csv"]
    assert "arbitrary_rotation_deg" in skipped[0].message


def test_cli_prints_a_summary_per_session_and_a_total(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    write_raw_csv(tmp_path / "src" / RAW_XELA, "uskin", [Press(-1.0), Press(0.0)])
    assert not cli(["import-unitac-nv", str(tmp_path / "src"), "--data", str(tmp_path / "data")])
    out = capsys.readouterr().out
    assert "2 presses found, 2 complete, 50 targets matched" in out
    assert "hex_tpu__uskin: 2 presses, 2 complete, 50/50 targets matched" in out
    assert "total: 1 sessions, 2 presses, 2 complete, 50/50 targets matched; files: 1 imported" in out
    assert not cli(["import-unitac-nv", str(tmp_path / "src"), "--data", str(tmp_path / "data")])
    assert "already-imported" in capsys.readouterr().out


def test_cli_exits_1_when_a_file_could_not_be_used(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    _write_peaks_only_npz(tmp_path / "src" / "oblong_PLA_papillarray.npz")
    assert cli(["import-unitac-nv", str(tmp_path / "src"), "--data", str(tmp_path / "data")]) == 1
    captured = capsys.readouterr()
    assert "oblong_PLA_papillarray.npz -> square_pla__papillarray: failed:" in captured.out
    assert "import the raw session CSVs" in captured.out
    assert "error: 1 of 1 files could not be imported" in captured.err
    assert not list(tmp_path.glob("data/*.h5"))  # no empty session left behind


def test_cli_missing_source_is_one_usage_line(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert cli(["import-unitac-nv", str(tmp_path / "nowhere"), "--data", str(tmp_path / "data")]) == 2
    err = capsys.readouterr().err.strip()
    assert "nowhere does not exist" in err and len(err.splitlines()) == 1
    assert not (tmp_path / "data").exists()


def test_cli_show_conventions_prints_toml_that_reads_back(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert not cli(["import-unitac-nv", str(tmp_path), "--data", str(tmp_path / "data"), "--show-conventions"])
    text = capsys.readouterr().out
    assert "ft_rotation_deg = 45.0" in text
    path = tmp_path / "conv.toml"
    path.write_text(text)
    assert not cli(
        [
            "import-unitac-nv",
            str(tmp_path),
            "--data",
            str(tmp_path / "d"),
            "--conventions",
            str(path),
            "--show-conventions",
        ]
    )
    assert capsys.readouterr().out == text


def test_names_mapped_outside_the_object_catalogue_are_refused(tmp_path: Path) -> None:
    write_raw_csv(tmp_path / "src" / RAW_XELA, "uskin", [Press(0.0)])
    conv = conventions_from_dict({"object_shapes": {"hexagonal": "hexagonish"}})
    with pytest.raises(ConfigError, match=r"hexagonish_tpu.*not in the object catalogue"):
        import_unitac_nv(tmp_path / "src", tmp_path / "data", conv)
    assert not (tmp_path / "data").exists()


def test_disagreement_with_their_selected_peaks_is_reported(tmp_path: Path) -> None:
    path = tmp_path / "src" / PROCESSED_XELA
    write_processed_npz(path, "uskin", [Press(-1.0), Press(0.0)])
    with np.load(path) as npz:
        arrays = dict(npz)
    arrays["selected"] = arrays["selected"] + np.array([0, 3])  # their second peak 3 samples off ours
    arrays["angle"] = np.array([-2, 0])  # and their first angle another degree
    np.savez(path, **arrays)
    (file_report,) = import_unitac_nv(tmp_path / "src", tmp_path / "data").files
    assert file_report.outcome == "imported" and file_report.written == 2
    assert "1 of their peaks not found, 1 extra, 1 with another angle" in " ".join(file_report.notes)
