"""Bad input: every case gives ONE line on stderr starting with ``error:``, a non-zero exit, no traceback (without
``--debug``), and leaves every file already recorded byte for byte as it was (sha256 before and after)."""

from __future__ import annotations

import hashlib
import shutil
from collections.abc import Iterator
from pathlib import Path

import h5py
import numpy as np
import pytest

from drivers.layouts import PAPILLARRAY
from tests.helpers import cli
from tests.robustness.robustness_helpers import few_angles, one_error_line, tree_hashes, write_synthetic_sessions
from unitac_rig.collection.session import collect_session
from unitac_rig.rig.config import parse_rig_config
from unitac_rig.rig.hardware import HardwareRig
from unitac_rig.rig.objects import get_object
from unitac_rig.sim.devices import SimPapillArrayHub
from unitac_rig.sim.fast_rig import SimRig
from unitac_rig.sim.synthetic_sources import PressSource
from unitac_rig.storage.reader import read_presses
from unitac_rig.storage.recorder import session_path


@pytest.fixture(scope="module")
def recorded(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A small real dataset: hex_tpu with the uSkin over 2 angles (one sensor only: no cross-sensor pairs)."""
    data = tmp_path_factory.mktemp("recorded") / "data"
    with SimRig(few_angles(2), seed=0) as rig:
        collect_session(rig, get_object("hex_tpu"), "uskin", data)
    return data


@pytest.fixture
def data(recorded: Path, tmp_path: Path) -> Iterator[Path]:
    """A private copy of the recorded dataset; asserts after the test that nothing in it changed."""
    copy = tmp_path / "data"
    shutil.copytree(recorded, copy)
    before = tree_hashes(copy)
    yield copy
    assert tree_hashes(copy) == before, "a failed command changed recorded files"


def _collect(data: Path, *extra: str) -> list[str]:
    return ["collect", "--object", "hex_tpu", "--data", str(data), "--no-live", *extra]


def test_unknown_object_and_sensor(data: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert cli(["collect", "--object", "cube_wood", "--data", str(data), "--no-live"]) == 2
    assert "unknown object 'cube_wood'" in one_error_line(capsys)
    assert cli(_collect(data, "--sensor", "gelsight")) == 2
    assert "unknown sensor 'gelsight'" in one_error_line(capsys)


def test_debug_shows_the_traceback_instead(data: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert cli(["--debug", "collect", "--object", "cube_wood", "--data", str(data), "--no-live"]) == 2  # as without
    err = capsys.readouterr().err
    assert "Traceback" in err and "UsageError" in err and "unknown object" in err


@pytest.mark.parametrize(
    ("rig_text", "expected"),
    [
        ("[press\nthreshold_n = 3\n", "not valid TOML"),
        ("[press]\nthreshhold_n = 3.0\n", "press.threshhold_n: unknown key"),
        ("[press]\nthreshold_n = 30.0\n", "limits.hard_force_n = 25.0 must be above press.threshold_n = 30.0"),
        ("[press]\nspeed_mm_s = -1\n", "press.speed_mm_s: Input should be greater than 0"),
        ("[press]\nspeed_mm_s = 120.0\n", "press.speed_mm_s = 120.0 exceeds limits.max_speed_mm_s"),
        ("[arm]\nhost = '10.0.0.2'\n", "an [arm] is configured but no [sensors.*]"),
        ("[arm]\nhost = 'h'\n[sensors.uskin]\ntype = 'papillarray'\nport = '/dev/x'\n", "does not fit sensor 'uskin'"),
    ],
)
def test_a_malformed_or_contradictory_rig_file_names_the_field(
    data: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str], rig_text: str, expected: str
) -> None:
    rig_file = tmp_path / "rig.toml"
    rig_file.write_text(rig_text)
    assert cli(_collect(data, "--rig", str(rig_file))) == 2  # the user's file: a usage error
    line = one_error_line(capsys)
    assert str(rig_file) in line and expected in line


def test_a_missing_rig_file(data: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert cli(_collect(data, "--rig", str(tmp_path / "nope.toml"))) == 2
    assert "does not exist" in one_error_line(capsys)


@pytest.mark.parametrize(
    ("sensor", "section", "expected"),
    [
        ("papillarray", "type = 'papillarray'\nport = '/dev/ttyUNITAC_NONE'", "cannot open PapillArray port"),
        ("uskin", "type = 'uskin-can'\ncan_interface = 'socketcan'\ncan_channel = 'unitacnone0'", "cannot open CAN"),
        ("uskin", "type = 'uskin-can'\ncan_interface = 'nosuchcan'\ncan_channel = 'x'", "'nosuchcan' is not available"),
    ],
)
def test_a_port_or_can_channel_that_is_not_there(
    data: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str], sensor: str, section: str, expected: str
) -> None:
    rig_file = tmp_path / "rig.toml"
    rig_file.write_text(f"[arm]\nhost = '127.0.0.1'\nunchecked_tool = true\n[sensors.{sensor}]\n{section}\n")
    assert cli(_collect(data, "--rig", str(rig_file), "--sensor", sensor)) == 1
    assert expected in one_error_line(capsys)  # and no new file: the fixture compares the whole tree


def test_a_failed_start_leaves_no_empty_session_in_a_fresh_directory(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    rig_file = tmp_path / "rig.toml"
    rig_file.write_text(
        "[arm]\nhost = '127.0.0.1'\nunchecked_tool = true\n"
        "[sensors.papillarray]\ntype = 'papillarray'\nport = '/dev/nope'\n"
    )
    fresh = tmp_path / "fresh"
    assert (
        cli(
            [
                "collect",
                "--object",
                "hex_tpu",
                "--sensor",
                "papillarray",
                "--rig",
                str(rig_file),
                "--data",
                str(fresh),
                "--no-live",
            ]
        )
        == 1
    )
    one_error_line(capsys)
    assert not fresh.exists() or not any(fresh.rglob("*.h5"))


@pytest.fixture
def wrong_sensor_rig(tmp_path: Path) -> Iterator[Path]:
    """A hardware rig file whose uSkin CAN channel is silent while a (simulated) PapillArray hub answers on its port.

    The arm is never contacted: sensor detection and checks happen before the arm moves.
    """
    hub = SimPapillArrayHub(source=PressSource(PAPILLARRAY, seed=0))  # streams on the host clock, like hardware
    rig_file = tmp_path / "rig.toml"
    rig_file.write_text(
        "[arm]\nhost = '127.0.0.1'\nunchecked_tool = true\n"
        f"[sensors.uskin]\ntype = 'uskin-can'\ncan_interface = 'virtual'\ncan_channel = 'silent-{tmp_path.name}'\n"
        f"[sensors.papillarray]\ntype = 'papillarray'\nport = '{hub.url}'\n"
    )
    try:
        yield rig_file
    finally:
        hub.close()


def test_detection_picks_the_sensor_that_answers(wrong_sensor_rig: Path) -> None:
    from unitac_rig.rig.config import load_rig_config

    rig = HardwareRig(load_rig_config(wrong_sensor_rig))
    try:
        assert rig.detect_sensor(probe_s=0.5) == "papillarray"
    finally:
        rig.close()


def test_naming_the_wrong_sensor_is_one_clear_line(
    wrong_sensor_rig: Path, data: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert cli(_collect(data, "--rig", str(wrong_sensor_rig), "--sensor", "uskin")) == 1
    line = one_error_line(capsys)
    assert "sensor 'uskin' is connected but sent no frame" in line
    assert "papillarray answers instead" in line


def _set_schema_version(path: Path, version: int) -> None:
    with h5py.File(path, "a") as f:
        f.attrs["schema_version"] = version


def test_a_dataset_from_another_version(recorded: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    data = tmp_path / "old"
    shutil.copytree(recorded, data)
    _set_schema_version(session_path(data, "hex_tpu", "uskin"), 0)
    before = tree_hashes(data)
    assert cli(["inspect", str(data)]) == 1
    assert "schema version 0" in one_error_line(capsys)
    assert cli(_collect(data, "--sensor", "uskin", "--angles", "3")) == 1
    assert "schema version 0" in one_error_line(capsys)
    assert cli(["train", "--data", str(data), "--out", str(tmp_path / "run"), "--epochs", "1"]) == 1
    assert "schema version 0" in one_error_line(capsys)
    assert cli(["extract", str(data)]) == 1
    assert "schema version 0" in one_error_line(capsys)
    assert tree_hashes(data) == before


def test_a_broken_session_file_is_set_aside_and_rebuilt_from_the_journal_by_any_reader_or_collect(
    recorded: Path, tmp_path: Path, caplog: pytest.LogCaptureFixture, capsys: pytest.CaptureFixture[str]
) -> None:
    data = tmp_path / "broken"
    shutil.copytree(recorded, data)
    path = session_path(data, "hex_tpu", "uskin")
    path.write_bytes(path.read_bytes()[:3000])  # truncated, as by a failing disk
    before = tree_hashes(data)
    # a reader (inspect) sets the broken file aside untouched and rebuilds the session from its journal, and says so
    assert cli(["inspect", str(data)]) == 0
    assert any("moved aside" in r.getMessage() and r.levelname == "WARNING" for r in caplog.records)
    (aside,) = data.glob("hex_tpu__uskin.broken-*.h5")
    assert tree_hashes(data)[aside.name] == before[path.name]
    assert [p.status for p in read_presses(path)] == ["complete", "complete"]
    # so does collect, and a second broken copy never overwrites the first one (even within the same second)
    path.write_bytes(path.read_bytes()[:2000])
    second = hashlib.sha256(path.read_bytes()).hexdigest()
    assert cli(_collect(data, "--sensor", "uskin", "--angles", "2")) == 0
    assert "moved aside" in capsys.readouterr().out
    asides = {tree_hashes(data)[p.name] for p in data.glob("hex_tpu__uskin.broken-*.h5")}
    assert asides == {before[path.name], second}
    assert [p.status for p in read_presses(path)] == ["complete", "complete"]


def test_a_broken_journal_header(recorded: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    data = tmp_path / "badjournal"
    shutil.copytree(recorded, data)
    (data / ".journal" / "hex_tpu__uskin" / "_session.json").write_text('{"object": "hex_tpu", "sens')
    before = tree_hashes(data)
    assert cli(_collect(data, "--sensor", "uskin", "--angles", "3")) == 1
    assert "_session.json is unreadable" in one_error_line(capsys)
    assert tree_hashes(data) == before


def test_training_on_data_with_no_joined_pairs(
    recorded: Path, data: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    run = tmp_path / "run"
    assert cli(["train", "--data", str(data), "--out", str(run), "--epochs", "1"]) == 1
    assert "only one sensor in the data (uskin)" in one_error_line(capsys)
    # two sensors, but on different objects: nothing joins across them
    mixed = tmp_path / "mixed"
    shutil.copytree(recorded, mixed)
    with SimRig(few_angles(2), seed=0) as rig:
        collect_session(rig, get_object("circle_pla"), "papillarray", mixed)
    before = tree_hashes(mixed)
    assert cli(["train", "--data", str(mixed), "--out", str(run), "--epochs", "1"]) == 1
    assert "no joined pairs" in one_error_line(capsys)
    assert tree_hashes(mixed) == before
    assert not run.exists() or not any(run.iterdir())


def test_extract_on_an_empty_directory(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert cli(["extract", str(tmp_path)]) == 2
    assert "no session files" in one_error_line(capsys)


def test_translate_with_a_sensor_the_model_does_not_know(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    data = tmp_path / "pairs"
    write_synthetic_sessions(data)
    run = tmp_path / "run"
    assert cli(["train", "--data", str(data), "--out", str(run), "--epochs", "1", "--no-report", "--no-baselines"]) == 0
    capsys.readouterr()
    frames = tmp_path / "frames.npy"
    np.save(frames, np.zeros((2, 16, 3), np.float32))
    before = tree_hashes(tmp_path)
    assert cli(["translate", str(run), str(frames), "--from", "gelsight", "--to", "uskin"]) == 1
    assert "this model knows no sensor 'gelsight'" in one_error_line(capsys)
    assert cli(["translate", str(run), str(frames), "--from", "papillarray", "--to", "uskin"]) == 1
    assert "papillarray frames must be (..., 9, 3)" in one_error_line(capsys)
    assert tree_hashes(tmp_path) == before


def test_an_unknown_key_in_a_rig_dict_is_an_error_too() -> None:
    from unitac_rig.errors import ConfigError

    with pytest.raises(ConfigError, match=r"limits\.hard_force: unknown key"):
        parse_rig_config({"limits": {"hard_force": 30.0}})
