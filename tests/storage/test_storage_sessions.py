"""Commands that change sessions: ``extract`` checks its settings first and is all or nothing; a session knows the
rig it was recorded on and refuses presses from another one; foreign or broken files are set aside, never lost."""

from __future__ import annotations

import json
from pathlib import Path

import h5py
import pytest

from lab.damage import flip_bits_in_dataset, press_ids
from tests.helpers import cli
from tests.robustness.robustness_helpers import one_error_line, tree_hashes
from unitac_rig.errors import DataError
from unitac_rig.storage import reextract
from unitac_rig.storage.recorder import SessionWriter, journal_dir, keep_aside, session_path


@pytest.mark.parametrize(
    ("args", "option"),
    [
        (["--tolerance", "-1"], "--tolerance"),
        (["--tolerance", "0"], "--tolerance"),
        (["--tolerance", "nan"], "--tolerance"),
        (["--tolerance", "inf"], "--tolerance"),
        (["--latency", "nan"], "--latency"),
        (["--latency", "-inf"], "--latency"),
        (["--latency", "5"], "--latency"),
        (["--smoothing", "0"], "--smoothing"),
        (["--smoothing", "-3"], "--smoothing"),
        (["--smoothing", "10000000"], "--smoothing"),
    ],
)
def test_extract_settings_are_usage_errors_naming_the_option_and_nothing_is_written(
    args: list[str], option: str, data: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    before = tree_hashes(data)
    assert cli(["extract", str(data), *args]) == 2
    assert one_error_line(capsys).startswith(f"error: {option} must be")
    assert tree_hashes(data) == before


def test_extract_that_cannot_finish_changes_no_session(data: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """The last session (sorted) has a press damaged in both copies: no other session may be re-extracted first."""
    path = session_path(data, "irregular_pla", "uskin")
    pid = press_ids(path)[0]
    flip_bits_in_dataset(path, f"presses/{pid}/robot/t_s", 4, 0)
    flip_bits_in_dataset(journal_dir(data, "irregular_pla", "uskin") / f"{pid}.h5", "press/robot/t_s", 4, 1)
    before = tree_hashes(data)
    assert cli(["extract", str(data), "--tolerance", "0.3"]) == 1
    assert f"press {pid} is damaged" in one_error_line(capsys)
    assert tree_hashes(data) == before


def test_extract_failing_while_writing_its_copies_leaves_every_file_as_it_was(
    data: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    real = reextract._reextract_copy
    calls = []

    def failing(path: Path, *args: object, **kwargs: object) -> object:
        calls.append(path)
        if len(calls) == 30:  # well into the second session
            raise OSError(28, "No space left on device")
        return real(path, *args, **kwargs)  # type: ignore[arg-type]

    monkeypatch.setattr(reextract, "_reextract_copy", failing)
    before = tree_hashes(data)
    assert cli(["extract", str(data), "--tolerance", "0.3"]) == 1
    line = one_error_line(capsys)
    assert "extract could not finish" in line and "nothing was changed" in line
    assert tree_hashes(data) == before
    assert not [p for p in data.rglob("*.tmp")]


def test_extract_with_a_broken_journal_header_is_one_line_and_changes_nothing(
    data: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    (journal_dir(data, "irregular_pla", "uskin") / "_session.json").write_text('{"object": "irregular_pla", "se')
    before = tree_hashes(data)
    assert cli(["extract", str(data)]) == 1
    assert "_session.json is unreadable" in one_error_line(capsys)
    assert tree_hashes(data) == before


def test_extract_rewrites_every_session_and_keeps_them_verified(data: Path) -> None:
    assert cli(["extract", str(data), "--tolerance", "0.3"]) == 0
    for path in data.glob("*__*.h5"):
        with h5py.File(path, "r") as f:
            assert json.loads(f.attrs["extraction_settings"])["tolerance_n"] == 0.3
    assert cli(["inspect", str(data)]) == 0  # every checksum, the new extraction's included, still matches


# -- which rig recorded a session ------------------------------------------------------------------------------------


def test_collecting_into_a_session_from_another_rig_is_refused_naming_both(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    data = tmp_path / "data"
    base = ["collect", "--object", "circle_pla", "--sensor", "uskin", "--data", str(data), "--angles", "2"]
    assert cli([*base, "--no-live"]) == 0
    other = tmp_path / "lab_b.toml"
    other.write_text('name = "lab-b"\n')  # another rig (the simulated one here, with its own name)
    before = tree_hashes(data)
    capsys.readouterr()
    assert cli([*base, "--rig", str(other), "--no-live"]) == 1
    line = one_error_line(capsys)
    assert "was recorded on the simulated rig 'rig', not on the simulated rig 'lab-b'" in line
    assert "collect into another --data directory" in line
    assert tree_hashes(data) == before


def test_a_hardware_rig_never_continues_a_simulated_session(tmp_path: Path) -> None:
    sim = {"object": "hex_tpu", "sensor": "uskin", "simulated": True, "rig": "rig"}
    SessionWriter(tmp_path, "hex_tpu", "uskin", sim).close()
    with pytest.raises(DataError, match=r"recorded on the simulated rig 'rig', not on a hardware rig 'ur5e-lab-a'"):
        SessionWriter(tmp_path, "hex_tpu", "uskin", {**sim, "simulated": False, "rig": "ur5e-lab-a"})
    imported = {"object": "hex_tpu", "sensor": "uskin", "simulated": False, "source": "unitac-nv"}
    with pytest.raises(DataError, match=r"recorded on the simulated rig 'rig', not on imported data"):
        SessionWriter(tmp_path, "hex_tpu", "uskin", imported)


def test_another_sensor_serial_is_refused_when_both_are_known(tmp_path: Path) -> None:
    attrs = {"object": "hex_tpu", "sensor": "uskin", "simulated": False, "rig": "lab"}
    with SessionWriter(tmp_path, "hex_tpu", "uskin", attrs) as writer:
        writer.update_root_attrs({"sensor_identity": {"model": "uSPa46", "serial": "A17"}})
        writer.update_root_attrs({"sensor_identity": {"model": "uSPa46"}})  # a driver that cannot tell: accepted
        with pytest.raises(DataError, match="recorded with uskin serial A17, not with serial B02"):
            writer.update_root_attrs({"sensor_identity": {"model": "uSPa46", "serial": "B02"}})


def test_a_session_a_script_started_without_a_rig_is_continued_with_a_note(tmp_path: Path) -> None:
    SessionWriter(tmp_path, "hex_tpu", "uskin", {"object": "hex_tpu", "sensor": "uskin"}).close()
    attrs = {"object": "hex_tpu", "sensor": "uskin", "simulated": True, "rig": "rig"}
    with SessionWriter(tmp_path, "hex_tpu", "uskin", attrs) as writer:
        assert any("does not record which rig it was recorded on" in n for n in writer.recovery_notes)


# -- files set aside -------------------------------------------------------------------------------------------------


def test_set_aside_copies_never_overwrite_each_other_within_one_second(tmp_path: Path) -> None:
    path = tmp_path / "s.h5"
    names = []
    for content in (b"first", b"second", b"third"):
        path.write_bytes(content)
        names.append(keep_aside(path))
    assert len(set(names)) == 3
    assert [n.read_bytes() for n in names] == [b"first", b"second", b"third"]


def test_a_foreign_hdf5_file_is_set_aside_and_the_session_rebuilt_from_its_journal(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    data = tmp_path / "data"
    args = ["collect", "--object", "hex_tpu", "--sensor", "uskin", "--data", str(data), "--angles", "2", "--no-live"]
    assert cli(args) == 0
    path = session_path(data, "hex_tpu", "uskin")
    path.unlink()
    with h5py.File(path, "w") as f:  # e.g. someone's own export saved under the session's name
        f["x"] = [1, 2, 3]
    foreign = path.read_bytes()
    capsys.readouterr()
    assert cli(args) == 0
    out = " ".join(capsys.readouterr().out.split())
    assert "is not a unitac-rig session file" in out and "moved aside" in out
    assert "2/2 presses finished (0 this run" in out
    (aside,) = data.glob("hex_tpu__uskin.broken-*.h5")
    assert aside.read_bytes() == foreign
    assert cli(["inspect", str(data)]) == 0
