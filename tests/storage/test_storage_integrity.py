"""Data that cannot rot silently (issue 28): every press carries SHA-256 checksums from the moment it is recorded;
``inspect``, ``extract``, ``train`` and ``export`` verify them, repair a damaged press from its intact journal copy,
and otherwise refuse with one line naming the file and the press; export never certifies a damaged file."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import h5py
import numpy as np
import pytest

from lab.damage import dataset_location, flip_bits, flip_bits_in_dataset, press_ids
from tests.helpers import cli
from tests.robustness.robustness_helpers import one_error_line, tree_hashes
from unitac_rig.storage.manifest import sha256_file
from unitac_rig.storage.reader import session_digest, session_files
from unitac_rig.storage.recorder import journal_dir, press_dir, session_path

OBJ, SENSOR = "circle_pla", "uskin"
TRAIN_FAST = ("--no-report", "--no-baselines")


def _stored(group: h5py.Group) -> dict[str, bytes]:
    """Every dataset of a press group as bytes, and its attributes as text: what a reader would get."""
    out: dict[str, bytes] = {}

    def visit(name: str, obj: object) -> None:
        if isinstance(obj, h5py.Dataset):
            value = np.asarray(obj[()])
            out[name] = repr(value.tolist()).encode() if value.dtype.names else value.tobytes()

    group.visititems(visit)
    out["@attrs"] = repr(sorted((k, str(v)) for k, v in group.attrs.items())).encode()
    return out


def _matches_journal(data: Path, object_id: str = OBJ, sensor: str = SENSOR) -> bool:
    """True when every press of the session file holds exactly what its journal entry holds."""
    path = session_path(data, object_id, sensor)
    with h5py.File(path, "r") as f:
        for pid in f["presses"]:
            with h5py.File(journal_dir(data, object_id, sensor) / f"{pid}.h5", "r") as jf:
                if _stored(f["presses"][pid]) != _stored(jf["press"]):
                    return False
    return True


def _twenty_bits(path: Path) -> list[str]:
    """The review's damage: 20 flipped bits that change raw arrays in 3 presses and break tactile/values in 2."""
    pids = press_ids(path)
    targets = [(pids[0], "robot/t_s"), (pids[1], "robot/press_force_n"), (pids[2], "tactile/seq"),
               (pids[3], "tactile/values"), (pids[4], "tactile/values")]  # fmt: skip
    for seed, (pid, dataset) in enumerate(targets):
        flip_bits_in_dataset(path, f"presses/{pid}/{dataset}", 4, seed)
    return [pid for pid, _ in targets]


def _command(name: str, data: Path, tmp_path: Path) -> list[str]:
    return {
        "inspect": ["inspect", str(data)],
        "extract": ["extract", str(data), "--tolerance", "0.4"],
        "train": ["train", "--data", str(data), "--out", str(tmp_path / "run"), "--epochs", "1", *TRAIN_FAST],
        "export": ["export", str(data), "--out", str(tmp_path / "export")],
    }[name]


@pytest.mark.parametrize("command", ["inspect", "extract", "train", "export"])
def test_twenty_flipped_bits_are_repaired_from_the_journal_by_every_reader(
    command: str, data: Path, tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    path = session_path(data, OBJ, SENSOR)
    assert _matches_journal(data)
    damaged = _twenty_bits(path)
    assert not _matches_journal(data)
    assert cli(_command(command, data, tmp_path)) == 0
    assert _matches_journal(data), f"{command} left the damaged presses in place"
    warnings = " ".join(r.getMessage() for r in caplog.records if r.levelname == "WARNING")
    for pid in damaged:
        assert f"press {pid} (complete) damaged in the session file; replaced by the journal" in warnings
    if command == "export":  # the export holds (and its manifest certifies) the repaired file
        manifest = json.loads((tmp_path / "export" / "manifest.json").read_text())
        entry = next(s for s in manifest["sessions"] if s["object"] == OBJ and s["sensor"] == SENSOR)
        raw = tmp_path / "export" / "raw" / path.name
        assert entry["sha256"] == sha256_file(raw) and entry["integrity"] == "verified"
        assert session_digest(raw) == session_digest(path)  # the repaired presses, not the damaged ones
        assert cli(["verify", str(tmp_path / "export")]) == 0


@pytest.mark.parametrize("command", ["inspect", "extract", "train", "export"])
def test_a_press_damaged_in_the_file_and_its_journal_is_refused_with_one_line(
    command: str, data: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = session_path(data, OBJ, SENSOR)
    pid = press_ids(path)[2]
    flip_bits_in_dataset(path, f"presses/{pid}/robot/press_force_n", 4, 0)
    entry = journal_dir(data, OBJ, SENSOR) / f"{pid}.h5"
    flip_bits_in_dataset(entry, "press/robot/press_force_n", 4, 1)
    before = tree_hashes(data)
    assert cli(_command(command, data, tmp_path)) == 1
    line = one_error_line(capsys)
    assert str(path) in line and f"press {pid} is damaged" in line and "journal copy is damaged too" in line
    assert tree_hashes(data) == before  # nothing changed: not the file, not the journal
    assert not (tmp_path / "export").exists() and not (tmp_path / "run" / "checkpoint.pt").exists()


def test_damage_without_a_journal_is_refused_naming_file_and_press(
    data: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    alone = tmp_path / "copied_without_journal"
    alone.mkdir()
    for part in session_files(session_path(data, OBJ, SENSOR)):  # the session file and its press files
        (alone / part.relative_to(data)).parent.mkdir(exist_ok=True)
        shutil.copyfile(part, alone / part.relative_to(data))
    path = alone / session_path(data, OBJ, SENSOR).name
    pid = press_ids(path)[0]
    flip_bits_in_dataset(path, f"presses/{pid}/tactile/values", 4, 0)
    assert cli(["inspect", str(alone)]) == 1
    line = one_error_line(capsys)
    assert str(path) in line and f"press {pid}:" in line and "no journal to repair it from" in line


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_twenty_random_bits_anywhere_are_caught_or_repaired_never_passed_on(
    seed: int, data: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Bits flipped anywhere (data, B-trees, attributes, the superblock): inspect either repairs the session to
    exactly its recorded content or refuses with one line; it never reads damaged data as if it were good."""
    path = session_path(data, OBJ, SENSOR)
    flip_bits(path, 20, seed)
    code = cli(["inspect", str(data)])
    if code == 0:
        assert _matches_journal(data)
    else:
        assert code == 1 and OBJ in one_error_line(capsys)


def test_collect_drops_a_press_damaged_in_both_copies_keeps_them_aside_and_presses_it_again(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    data = tmp_path / "data"
    args = ["collect", "--object", "hex_tpu", "--sensor", "uskin", "--data", str(data), "--angles", "2", "--no-live"]
    assert cli(args) == 0
    path = session_path(data, "hex_tpu", "uskin")
    pid = press_ids(path)[0]
    press_file = dataset_location(path, f"presses/{pid}/robot/t_s")[0]  # the press's own file
    flip_bits_in_dataset(path, f"presses/{pid}/robot/t_s", 4, 0)
    entry = journal_dir(data, "hex_tpu", "uskin") / f"{pid}.h5"
    flip_bits_in_dataset(entry, "press/robot/t_s", 4, 1)
    damaged_file, damaged_entry = sha256_file(press_file), sha256_file(entry)
    capsys.readouterr()
    assert cli(args) == 0
    out = capsys.readouterr().out
    assert f"press {pid} was damaged" in out and "it will be pressed again" in out
    assert "2/2 presses finished (1 this run" in out
    (aside,) = press_dir(path).glob(f"{pid}-*.broken-*.h5")  # the damaged press file, kept aside
    (entry_aside,) = journal_dir(data, "hex_tpu", "uskin").glob(f"{pid}.broken-*.h5")
    assert sha256_file(aside) == damaged_file and sha256_file(entry_aside) == damaged_entry
    assert _matches_journal(data, "hex_tpu", "uskin")
    assert cli(["inspect", str(data)]) == 0


def test_a_torn_journal_entry_is_rewritten_from_the_intact_session_file(
    data: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from unitac_rig.storage.recorder import SessionWriter

    entry = journal_dir(data, OBJ, SENSOR) / f"{press_ids(session_path(data, OBJ, SENSOR))[1]}.h5"
    entry.write_bytes(entry.read_bytes()[:1500])  # torn, as by a crash of the disk's cache
    with pytest.raises(OSError):
        h5py.File(entry, "r")
    header = json.loads((journal_dir(data, OBJ, SENSOR) / "_session.json").read_text())
    with SessionWriter(data, OBJ, SENSOR, header) as writer:
        assert any("rewritten from the session file" in note for note in writer.recovery_notes)
    assert _matches_journal(data)


def test_verify_fails_on_a_file_the_manifest_does_not_list(
    data: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "export"
    assert cli(["export", str(data), "--out", str(out)]) == 0
    (out / "raw" / "extra.h5").write_bytes(b"added later")
    assert cli(["verify", str(out)]) == 1
    assert "raw/extra.h5: not in the manifest (added after export)" in one_error_line(capsys)


def test_a_deeply_nested_manifest_is_one_line(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    (tmp_path / "manifest.json").write_text("[" * 100_000 + "]" * 100_000)
    assert cli(["verify", str(tmp_path)]) == 1
    assert "nested too deeply" in one_error_line(capsys)
