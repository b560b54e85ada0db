"""Data that knows what it is (issue 41): a press's seal binds it to its object, sensor, session, press id and place,
so a press intact but in the wrong place is damage; the journal is checked like the data it protects; a vanished
session is rebuilt, never omitted. Every case: repaired to exactly what was recorded, or refused in one line."""

from __future__ import annotations

import json
import os
from pathlib import Path

import h5py
import pytest

from lab.damage import (
    copy_press_over,
    delete_press_file,
    flip_bits_in_dataset,
    flip_seal_name,
    press_ids,
    raw_contents,
    swap_journal_entries,
    swap_press_files,
)
from tests.helpers import cli
from tests.robustness.robustness_helpers import one_error_line
from unitac_rig.storage import reextract
from unitac_rig.storage.extraction import ExtractionSettings
from unitac_rig.storage.integrity import check_session
from unitac_rig.storage.recorder import journal_dir, journal_entry_check, session_path

OBJ, OTHER, SENSOR = "circle_pla", "irregular_pla", "uskin"


def _recorded(data: Path) -> dict[str, dict[str, str]]:
    """Session file name -> press id -> digest of what was recorded (raw streams, tare, events, status)."""
    return {p.name: raw_contents(p) for p in sorted(data.glob("*__*.h5"))}


def _journal_intact(data: Path, object_id: str = OBJ, sensor: str = SENSOR) -> bool:
    journal = journal_dir(data, object_id, sensor)
    with h5py.File(session_path(data, object_id, sensor), "r") as f:
        identity = {k: str(f.attrs[k]) for k in ("object", "sensor", "session_id")}
    pids = press_ids(session_path(data, object_id, sensor))
    return all(journal_entry_check(journal / f"{pid}.h5", identity).state == "ok" for pid in pids)


def _warnings(caplog: pytest.LogCaptureFixture) -> str:
    return " ".join(r.getMessage() for r in caplog.records if r.levelname == "WARNING")


CASES = {
    "other_object_press": lambda d: copy_press_over(d, (OTHER, SENSOR), (OBJ, SENSOR)),
    "other_sensor_press": lambda d: copy_press_over(d, (OBJ, SENSOR), (OBJ, "papillarray")),
    "two_press_files_swapped": lambda d: swap_press_files(d, OBJ, SENSOR),
    "journal_swapped_then_press_deleted": lambda d: (swap_journal_entries(d, OBJ, SENSOR),
                                                     delete_press_file(d, OBJ, SENSOR, 0)),
    "seal_name_flipped": lambda d: flip_seal_name(session_path(d, OBJ, SENSOR)),
    "session_file_deleted": lambda d: session_path(d, OBJ, SENSOR).unlink(),
}  # fmt: skip


@pytest.mark.parametrize("case", sorted(CASES))
def test_a_press_in_the_wrong_place_or_a_vanished_session_is_repaired_to_what_was_recorded(
    case: str, data: Path, caplog: pytest.LogCaptureFixture
) -> None:
    recorded = _recorded(data)
    CASES[case](data)
    damaged = _recorded(data) != recorded or any(check_session(p).needs_repair for p in data.glob("*__*.h5"))
    assert damaged  # the damage is real: some press reads otherwise, is gone, or the file's seal is broken
    assert cli(["inspect", str(data)]) == 0
    assert _recorded(data) == recorded, f"{case}: a press was lost, dropped or left in the wrong place"
    assert all(not check_session(p).needs_repair for p in data.glob("*__*.h5"))
    assert "unsealed" not in _warnings(caplog) and _warnings(caplog)  # said what it repaired


def test_a_wrong_press_without_a_journal_is_refused_in_one_line_naming_it(
    data: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    pid = copy_press_over(data, (OTHER, SENSOR), (OBJ, SENSOR))
    (journal_dir(data, OBJ, SENSOR) / f"{pid}.h5").unlink()
    assert cli(["inspect", str(data)]) == 1
    line = one_error_line(capsys)
    assert f"press {pid}" in line and "in the wrong place" in line and f"{OBJ}__{SENSOR}" in line


@pytest.mark.parametrize("damage", ["flipped", "truncated", "deleted", "header_deleted"])
def test_a_press_that_lost_its_repair_copy_is_reported_and_the_copy_recreated(
    damage: str, data: Path, caplog: pytest.LogCaptureFixture
) -> None:
    journal = journal_dir(data, OBJ, SENSOR)
    entry = journal / f"{press_ids(session_path(data, OBJ, SENSOR))[1]}.h5"
    if damage == "flipped":
        flip_bits_in_dataset(entry, "press/robot/press_force_n", 3, 0)
    elif damage == "truncated":
        entry.write_bytes(entry.read_bytes()[:2000])
    elif damage == "deleted":
        entry.unlink()
    else:
        (journal / "_session.json").unlink()
    assert not _journal_intact(data) or damage == "header_deleted"
    assert cli(["inspect", str(data)]) == 0
    said = _warnings(caplog)
    assert ("_session.json" in said) if damage == "header_deleted" else ("journal entry" in said and entry.name in said)
    assert _journal_intact(data) and (journal / "_session.json").is_file()


@pytest.mark.parametrize("renames", [5, 11, 12, 17, 23])
def test_extract_killed_between_renames_never_restores_an_older_extraction(
    renames: int, data: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A kill after the k-th of extract's 24 renames (11 press files, the session file, 11 journal entries, the
    header), then a press file deleted: the repair gives every press, journal entry and the header the extraction
    the session file's settings say (the newer side), never the journal's older one."""
    real_replace = os.replace
    done = [0]

    def killed(src: str, dst: str) -> None:
        if done[0] >= renames:
            raise KeyboardInterrupt  # what kill -9 leaves: the renames made so far, nothing after
        done[0] += 1
        real_replace(src, dst)

    path = session_path(data, OBJ, SENSOR)
    monkeypatch.setattr(reextract.os, "replace", killed)
    with pytest.raises(KeyboardInterrupt):
        reextract.reextract_sessions([path], ExtractionSettings(tolerance_n=0.45))
    monkeypatch.setattr(reextract.os, "replace", real_replace)
    delete_press_file(data, OBJ, SENSOR, 0)
    assert cli(["inspect", str(data)]) == 0
    with h5py.File(path, "r") as f:
        root = f.attrs.get("extraction_settings")
        pressed = [json.loads(g["extraction"].attrs["settings"]) for g in f["presses"].values()]
    if root is not None:  # the session file was renamed: it says NEW, and so does every copy now
        new = json.loads(root)
        assert all(settings == new for settings in pressed)
        for entry in journal_dir(data, OBJ, SENSOR).glob("*.h5"):
            with h5py.File(entry, "r") as jf:
                assert json.loads(jf["press"]["extraction"].attrs["settings"]) == new, entry.name
        header = json.loads((journal_dir(data, OBJ, SENSOR) / "_session.json").read_text())
        assert header["extraction_settings"] == new
    assert _journal_intact(data)


def test_pairs_join_only_within_one_rig_and_say_why_not() -> None:
    """Two rigs' sessions in one folder (another rig's uSkin beside this rig's PapillArray): no pair is joined
    across them; the refusal names both sessions and their rigs."""
    import dataclasses

    from drivers.layouts import PAPILLARRAY, USKIN
    from unitac_rig.errors import DataError
    from unitac_rig.learning.synthetic_data import synthetic_matched_sets
    from unitac_rig.storage.paired import build_paired_dataset

    sets = synthetic_matched_sets(("circle_pla",), (USKIN, PAPILLARRAY), angles_deg=(0.0, 9.0), targets_n=(4.0, 6.0))
    same = [dataclasses.replace(s, rig="simulated rig 'lab-a'") for s in sets]
    assert len(build_paired_dataset(same)) > 0
    mixed = [dataclasses.replace(s, rig=f"hardware rig 'lab-{'a' if s.sensor == 'uskin' else 'b'}'") for s in sets]
    with pytest.raises(DataError, match="pairs join only within one rig") as refused:
        build_paired_dataset(mixed)
    assert "hardware rig 'lab-a'" in str(refused.value) and "hardware rig 'lab-b'" in str(refused.value)


def test_temporary_files_of_killed_processes_are_removed_by_the_next_run(data: Path, tmp_path: Path) -> None:
    """What kill -9 leaves (a journal header's private copy, a press file's, a half-built export) is gone after the
    next extract or export; a live export's staging folder is left alone."""
    from unitac_rig.storage.manifest import remove_dead_staging

    journal = journal_dir(data, OBJ, SENSOR)
    leftovers = [journal / "._session.json.4194305.tmp", journal / "._verified.json.4194305.tmp"]
    for leftover in leftovers:
        leftover.write_text("{}")
    assert cli(["extract", str(data), "--tolerance", "0.45"]) == 0
    assert not any(p.exists() for p in leftovers)
    dead = tmp_path / ".export.partial-4194305"  # above any pid_max: no such process
    live = tmp_path / f".other.partial-{os.getpid()}"
    for folder in (dead, live):
        (folder / "raw").mkdir(parents=True)
    assert remove_dead_staging(tmp_path) == [dead]
    assert not dead.exists() and live.is_dir()
