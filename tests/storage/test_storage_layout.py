"""The press-file layout (issue 27): each press is written a constant number of times (journal entry, press file)
instead of the whole session once per press; an export's self-contained copy reads and re-extracts like its
session; a reader keeps its version while presses are added, redone or repaired; a kill between the writes loses
nothing."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import h5py
import numpy as np
import pytest

from lab.damage import flip_bits
from tests.helpers import cli
from tests.robustness.robustness_helpers import one_error_line, tree_hashes
from unitac_rig.bench.recorder import synthetic_press
from unitac_rig.errors import DataError
from unitac_rig.storage import recorder, reextract
from unitac_rig.storage.pooling import pool_sessions
from unitac_rig.storage.press_record import PressRecord
from unitac_rig.storage.reader import (
    load_matched_set,
    read_presses,
    read_session_info,
    session_digest,
    session_files,
    snapshot_session,
)
from unitac_rig.storage.recorder import (
    SessionWriter,
    journal_dir,
    press_dir,
    session_bytes,
    session_layout,
    session_path,
)

OBJ, SENSOR = "hex_tpu", "uskin"
ATTRS = {"object": OBJ, "sensor": SENSOR, "simulated": True, "rig": "rig", "config": {"threshold_n": 10.0}}


def _presses(count: int, length_s: float = 1.5) -> list[PressRecord]:
    """uSkin presses at the hardware's rates (robot 500 Hz, tactile 100 Hz), seeded."""
    rng = np.random.default_rng(27)
    return [synthetic_press(SENSOR, length_s, index, rng) for index in range(count)]


def write_session(data: Path, records: list[PressRecord]) -> Path:
    with SessionWriter(data, OBJ, SENSOR, ATTRS) as writer:
        for rec in records:
            writer.write_press(rec)
        return writer.path


def _same_presses(a: list[PressRecord], b: list[PressRecord]) -> bool:
    if [p.press_id for p in a] != [p.press_id for p in b]:
        return False
    for x, y in zip(a, b, strict=True):
        for name in ("robot_t_s", "robot_force", "press_force_n", "tactile_t_s", "tactile_values", "tactile_seq"):
            if not np.array_equal(getattr(x, name), getattr(y, name)):
                return False
        attrs_x, attrs_y = ({k: v for k, v in p.attrs.items() if k != "checksums"} for p in (x, y))
        if (x.status, attrs_x, x.events) != (y.status, attrs_y, y.events):
            return False
    return True


def _reference(tmp_path: Path, records: list[PressRecord]) -> list[PressRecord]:
    """``records`` as read back from a session of their own (stored dtypes and attributes), for comparisons."""
    return read_presses(write_session(tmp_path / "reference", records))


def _written_bytes() -> int:
    """Bytes this process has caused to be written to storage so far (Linux /proc/self/io ``write_bytes``)."""
    for line in Path("/proc/self/io").read_text().splitlines():
        if line.startswith("write_bytes:"):
            return int(line.split()[1])
    raise AssertionError("no write_bytes in /proc/self/io")


# -- bytes written -------------------------------------------------------------------------------------------------


@pytest.mark.skipif(not Path("/proc/self/io").exists(), reason="needs Linux's per-process I/O accounting")
def test_each_press_is_written_a_constant_number_of_times_not_the_whole_session(tmp_path: Path) -> None:
    records = _presses(24)
    before = _written_bytes()
    new = write_session(tmp_path / "new", records)
    new_written = _written_bytes() - before
    # journal entry + press file + the small session file: about twice the session's size, whatever its length (a
    # writer that rewrote the whole session per press wrote over 8 times its size for 24 presses)
    assert new_written <= 3 * session_bytes(new), (new_written, session_bytes(new))
    # the measure sees the writes: at least the fsynced journal entries reached the disk
    assert new_written >= sum(p.stat().st_size for p in journal_dir(tmp_path / "new", OBJ, SENSOR).glob("*.h5"))


def test_the_session_file_holds_links_and_each_press_file_is_never_rewritten(tmp_path: Path) -> None:
    records = _presses(6)
    with SessionWriter(tmp_path, OBJ, SENSOR, ATTRS) as writer:
        writer.write_press(records[0])
        (first,) = session_files(writer.path)[1:]
        identity = (first.stat().st_ino, first.stat().st_mtime_ns)
        for rec in records[1:]:
            writer.write_press(rec)
        assert (first.stat().st_ino, first.stat().st_mtime_ns) == identity
        path = writer.path
    with h5py.File(path, "r") as f:
        links, groups = session_layout(f)
    assert groups == [] and sorted(links) == sorted(r.press_id for r in records)
    assert all(target.startswith(f"{press_dir(path).name}/") for target in links.values())
    assert path.stat().st_size < 32_000  # attributes and six links; the presses are elsewhere
    assert len(session_files(path)) == 7 and len(list(press_dir(path).glob("*.h5"))) == 6


# -- an export's self-contained copy ----------------------------------------------------------------------------------


def test_a_snapshot_reads_and_pools_as_its_session_and_no_writer_continues_it(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    records = _presses(5)
    new = write_session(tmp_path / "new", records)
    (tmp_path / "snap").mkdir()
    snap = tmp_path / "snap" / new.name
    snapshot_session(new, snap)  # one self-contained file: the same content
    assert session_files(snap) == [snap] and len(session_files(new)) == 6
    assert _same_presses(read_presses(snap), read_presses(new)) and session_digest(snap) == session_digest(new)
    assert np.array_equal(load_matched_set(snap).values, load_matched_set(new).values)
    assert read_session_info(snap).integrity == "verified"
    (pooled,) = pool_sessions([tmp_path / "new", tmp_path / "snap"])
    assert pooled.also_in == (tmp_path / "snap",)
    before = tree_hashes(tmp_path / "snap")
    with pytest.raises(DataError, match="holds its presses inside it: an export's read-only copy"):
        SessionWriter(tmp_path / "snap", OBJ, SENSOR, ATTRS)
    assert tree_hashes(tmp_path / "snap") == before


def test_extract_on_a_snapshot_rewrites_it_into_press_files(tmp_path: Path) -> None:
    records = _presses(4)
    (tmp_path / "snap").mkdir()
    snap = tmp_path / "snap" / f"{OBJ}__{SENSOR}.h5"
    snapshot_session(write_session(tmp_path / "new", records), snap)
    before = session_digest(snap)
    assert cli(["extract", str(tmp_path / "snap"), "--tolerance", "0.3"]) == 0
    with h5py.File(snap, "r") as f:
        assert json.loads(f.attrs["extraction_settings"])["tolerance_n"] == 0.3
        links, groups = session_layout(f)
    assert groups == [] and len(links) == 4
    assert session_digest(snap) != before and read_session_info(snap).integrity == "verified"
    assert _same_presses(read_presses(snap), _reference(tmp_path / "ref", records))


def test_extract_failing_on_a_snapshot_leaves_it_exactly_as_it_was(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    (tmp_path / "snap").mkdir()
    snap = tmp_path / "snap" / f"{OBJ}__{SENSOR}.h5"
    snapshot_session(write_session(tmp_path / "new", _presses(4)), snap)
    real, calls = reextract._reextract_copy, []

    def failing(path: Path, *args: object, **kwargs: object) -> object:
        calls.append(path)
        if len(calls) == 3:
            raise OSError(28, "No space left on device")
        return real(path, *args, **kwargs)  # type: ignore[arg-type]

    monkeypatch.setattr(reextract, "_reextract_copy", failing)
    before = tree_hashes(tmp_path / "snap")
    assert cli(["extract", str(tmp_path / "snap"), "--tolerance", "0.3"]) == 1
    assert "nothing was changed" in one_error_line(capsys)
    assert tree_hashes(tmp_path / "snap") == before and not press_dir(snap).exists()


# -- readers keep their version --------------------------------------------------------------------------------------


def test_a_reader_keeps_its_version_of_a_redone_press_until_a_later_command(tmp_path: Path) -> None:
    aborted, redone = _presses(2)[0], _presses(2)[0]
    aborted.status, aborted.reason = "aborted", "interrupted"
    writer = SessionWriter(tmp_path, OBJ, SENSOR, ATTRS)
    writer.write_press(aborted)
    held = h5py.File(writer.path, "r")
    try:
        writer.write_press(redone)  # the same press id, pressed again
        assert held["presses"][aborted.press_id].attrs["status"] == "aborted"  # the version it opened
        assert read_presses(writer.path)[0].status == "complete"
        writer.close()
        reopened = SessionWriter(tmp_path, OBJ, SENSOR, ATTRS)  # a later command removes the superseded file
        reopened.close()
        assert len(list(press_dir(writer.path).glob("*.h5"))) == 1
        assert read_presses(writer.path)[0].status == "complete"
    finally:
        held.close()


# -- kills and damage ------------------------------------------------------------------------------------------------


def test_a_kill_after_the_press_file_before_the_session_file_loses_nothing(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    records = _presses(3)
    writer = SessionWriter(tmp_path, OBJ, SENSOR, ATTRS)
    writer.write_press(records[0])

    def killed(*args: object, **kwargs: object) -> Path:
        raise OSError(5, "Input/output error")  # stands for the process dying before the rename

    monkeypatch.setattr(recorder, "write_session_file", killed)
    with pytest.raises(DataError, match=f"could not record press {records[1].press_id}"):
        writer.write_press(records[1])
    monkeypatch.undo()
    writer.close()
    assert [p.press_id for p in read_presses(writer.path)] == [records[0].press_id]  # whole presses only
    assert len(list(press_dir(writer.path).glob("*.h5"))) == 2  # the unpublished press file is there
    resumed = SessionWriter(tmp_path, OBJ, SENSOR, ATTRS)
    assert resumed.finished_press_ids() == {records[0].press_id, records[1].press_id}
    resumed.write_press(records[2])
    resumed.close()
    assert len(list(press_dir(writer.path).glob("*.h5"))) == 3 and not list(tmp_path.rglob("*.tmp"))
    assert _same_presses(read_presses(writer.path), _reference(tmp_path / "ref", records))


def test_a_missing_press_file_is_restored_from_the_journal_or_refused_naming_it(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = write_session(tmp_path / "data", _presses(3))
    victim = session_files(path)[2]
    victim.unlink()
    assert cli(["inspect", str(tmp_path / "data")]) == 0  # repaired from the journal
    assert len(session_files(path)) == 4 and all(p.exists() for p in session_files(path))
    # the session file copied without its press folder: every press is missing, and said so in one line
    alone = tmp_path / "alone"
    alone.mkdir()
    shutil.copyfile(path, alone / path.name)
    assert cli(["inspect", str(alone)]) == 1
    line = one_error_line(capsys)
    assert str(alone / path.name) in line and f"its press file {press_dir(path).name}/" in line and "is missing" in line


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_bits_flipped_in_press_files_are_repaired_or_refused_never_passed_on(
    seed: int, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    records = _presses(4)
    path = write_session(tmp_path, records)
    for index, part in enumerate(session_files(path)[1:]):
        flip_bits(part, 5, seed * 10 + index)
    code = cli(["inspect", str(tmp_path)])
    if code == 0:
        assert _same_presses(read_presses(path), _reference(tmp_path / "ref", records))
    else:
        assert code == 1 and OBJ in one_error_line(capsys)


def test_random_bits_in_a_session_file_with_real_attributes_are_repaired_or_refused_never_a_crash(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """The session file is small, so random bits mostly hit its attribute heap and link table (seeds 4 and 10 broke
    the heap's strings and a link's name): the session file is rebuilt from the journal, never a crash."""
    from unitac_rig.rig.config import RigConfig

    attrs = {**ATTRS, "config": RigConfig().model_dump(mode="json"), "planned_presses": [f"p{i}" for i in range(91)]}
    records = _presses(4)
    pristine = tmp_path / "pristine"
    with SessionWriter(pristine, OBJ, SENSOR, attrs) as writer:
        for rec in records:
            writer.write_press(rec)
    expected = _reference(tmp_path / "ref", records)
    for seed in range(12):
        data = tmp_path / f"seed{seed}"
        shutil.copytree(pristine, data)
        flip_bits(session_path(data, OBJ, SENSOR), 20, seed)
        code = cli(["inspect", str(data)])
        if code == 0:
            assert _same_presses(read_presses(session_path(data, OBJ, SENSOR)), expected), seed
        else:
            line = one_error_line(capsys)
            assert code == 1 and OBJ in line and "unexpected" not in line, (seed, line)
        capsys.readouterr()
