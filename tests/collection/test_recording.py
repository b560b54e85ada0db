"""The session file keeps every finished press, survives broken writes, and reads back what was written."""

from pathlib import Path

import h5py
import numpy as np
import pytest

from unitac_rig.errors import DataError
from unitac_rig.storage.extraction import ExtractionSettings, extract_press
from unitac_rig.storage.press_record import PressRecord, press_id
from unitac_rig.storage.reader import list_sessions, load_matched_set, read_presses
from unitac_rig.storage.recorder import SessionWriter, session_path


def make_press(rotation: float, angle: float, status: str = "complete", n_taxels: int = 24) -> PressRecord:
    robot_t = np.arange(0, 1.2, 0.002)
    force = 10.0 * robot_t
    tactile_t = np.arange(0.0, 1.2, 0.01)
    values = np.full((tactile_t.size, n_taxels, 3), 32000.0, np.float32)
    values[:, :, 2] += (1000 * tactile_t)[:, None].astype(np.float32)  # z rises 1000 counts/s
    ex = extract_press(robot_t, force, tactile_t, settings=ExtractionSettings(ft_lag_s=0.0))  # the true force: no lag
    return PressRecord(
        press_id=press_id(rotation, angle),
        rotation_deg=rotation,
        angle_deg=angle,
        status=status,
        reason="force" if status == "complete" else "travel",
        robot_t_s=robot_t,
        robot_force=np.zeros((robot_t.size, 6)),
        robot_pose=np.zeros((robot_t.size, 6)),
        press_force_n=force,
        tactile_t_s=tactile_t,
        tactile_values=values,
        tactile_seq=np.arange(tactile_t.size),
        tactile_device_t_us=np.full(tactile_t.size, -1),
        tactile_valid=np.ones(tactile_t.size, bool),
        tare_baseline=np.full((n_taxels, 3), 32000.0),
        events=[(0.1, "contact", ""), (1.0, "stop", "force 10.0 N")],
        attrs={"strategy": "guarded", "speed_mm_s": 5.0, "ft_zero": [0.1, 0.2, 0.3, 0, 0, 0]},
        extraction=ex,
    )


ROOT = {"object": "hex_tpu", "sensor": "uskin", "simulated": True, "config": {"threshold_n": 10.0}}


def test_press_ids_are_stable_and_sortable():
    assert press_id(0, -45) == "rot000_ang-45"
    assert press_id(90, 7) == "rot090_ang+07"
    assert press_id(270.0, 0.0) == "rot270_ang+00"


def test_round_trip_and_matched_frames(tmp_path: Path):
    writer = SessionWriter(tmp_path, "hex_tpu", "uskin", ROOT)
    writer.write_press(make_press(0, -1))
    writer.write_press(make_press(0, 0, status="failed"))
    assert writer.finished_press_ids() == {"rot000_ang-01", "rot000_ang+00"}
    (info,) = list_sessions(tmp_path)
    assert (info.object_id, info.sensor, info.simulated) == ("hex_tpu", "uskin", True)
    presses = read_presses(info.path)
    assert [p.press_id for p in presses] == ["rot000_ang+00", "rot000_ang-01"]
    assert presses[1].events[1] == (1.0, "stop", "force 10.0 N")
    assert presses[1].attrs["ft_zero"] == [0.1, 0.2, 0.3, 0, 0, 0]
    matched = load_matched_set(info.path)
    assert len(matched) == 25  # the failed press contributes nothing
    assert np.all(matched.angle_deg == -1)
    # tared z at target 4 N (0.40 s) is 1000 counts/s * 0.40 s
    assert matched.values[0, 0, 2] == pytest.approx(400.0, abs=1e-3)
    assert matched.values[0, 0, 0] == pytest.approx(0.0)


def test_half_written_press_is_restored_from_the_journal(tmp_path: Path):
    writer = SessionWriter(tmp_path, "hex_tpu", "uskin", ROOT)
    writer.write_press(make_press(0, 3))
    path = session_path(tmp_path, "hex_tpu", "uskin")
    with h5py.File(path, "a") as f:  # simulate a kill in the middle of copying into the session file
        f["presses/rot000_ang+03"].attrs["write_complete"] = False
    reopened = SessionWriter(tmp_path, "hex_tpu", "uskin", ROOT)
    assert reopened.finished_press_ids() == {"rot000_ang+03"}
    assert any("restored" in note for note in reopened.recovery_notes)


def test_unreadable_session_file_is_set_aside_and_rebuilt(tmp_path: Path):
    writer = SessionWriter(tmp_path, "hex_tpu", "uskin", ROOT)
    for angle in (-2, -1, 0):
        writer.write_press(make_press(0, angle))
    path = session_path(tmp_path, "hex_tpu", "uskin")
    path.write_bytes(path.read_bytes()[:200])  # truncated by a crash
    rebuilt = SessionWriter(tmp_path, "hex_tpu", "uskin", ROOT)
    assert rebuilt.finished_press_ids() == {"rot000_ang-02", "rot000_ang-01", "rot000_ang+00"}
    assert list(tmp_path.glob("*.broken-*.h5"))
    assert [s.path.name for s in list_sessions(tmp_path)] == ["hex_tpu__uskin.h5"]


def test_press_missing_from_file_but_journalled_is_added(tmp_path: Path):
    writer = SessionWriter(tmp_path, "hex_tpu", "uskin", ROOT)
    writer.write_press(make_press(0, 5))
    with h5py.File(writer.path, "a") as f:
        del f["presses/rot000_ang+05"]
    assert SessionWriter(tmp_path, "hex_tpu", "uskin", ROOT).finished_press_ids() == {"rot000_ang+05"}


def test_other_schema_version_is_refused(tmp_path: Path):
    SessionWriter(tmp_path, "hex_tpu", "uskin", ROOT)
    with h5py.File(session_path(tmp_path, "hex_tpu", "uskin"), "a") as f:
        f.attrs["schema_version"] = 99
    with pytest.raises(DataError, match="schema version"):
        list_sessions(tmp_path)
