"""The inputs a review found answered with "unexpected X", a MemoryError, a silent wrong run or advice to switch a
safety off (issue 28, item 7): each now gets one line from the project's own error tree (usage errors exit 2) and
changes nothing on disk."""

from __future__ import annotations

import datetime
import math
import types
from pathlib import Path

import numpy as np
import pytest
import torch

from protocols import rtde
from protocols.rtde import ControllerVersion
from tests.helpers import cli
from tests.robustness.robustness_helpers import one_error_line, tree_hashes
from unitac_rig.learning.run import CHECKPOINT_FORMAT, CHECKPOINT_VERSION, checkpoint_path
from unitac_rig.rig.config import load_rig_config

COLLECT = ["collect", "--object", "hex_tpu", "--no-live"]


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        ("[press]\nangle_min_deg = nan\n", "press.angle_min_deg: Input should be a finite number"),
        ("[press]\nangle_max_deg = inf\n", "press.angle_max_deg: Input should be a finite number"),
        ("[press]\nangle_max_deg = 1e30\n", "press.angle_max_deg: Input should be less than or equal to 90"),
        ("[press]\nangle_count = 1000000000\n", "gives two approach angles the same whole degree"),
        ("[object]\ncenter_m = [nan, 0.6]\n", "object.center_m.0: Input should be a finite number"),
        ("[press]\ndwell_s = nan\n", "press.dwell_s: Input should be a finite number"),
        ("a = " + "[" * 10_000 + "]" * 10_000 + "\n", "not valid TOML (nested too deeply)"),
    ],
)
def test_a_rig_file_value_that_is_not_a_number_or_not_possible_is_one_line(
    text: str, expected: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    rig = tmp_path / "rig.toml"
    rig.write_text(text)
    assert cli([*COLLECT, "--rig", str(rig), "--data", str(tmp_path / "data")]) == 2
    assert expected in one_error_line(capsys)
    assert not (tmp_path / "data").exists()


def test_a_rig_file_that_is_not_utf8_text_or_is_a_directory_is_one_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    binary = tmp_path / "rig.toml"
    binary.write_bytes(b"\xff\xfename = 'x'\n")
    assert cli([*COLLECT, "--rig", str(binary), "--data", str(tmp_path / "data")]) == 2
    assert "not UTF-8 text" in one_error_line(capsys)
    folder = tmp_path / "folder.toml"
    folder.mkdir()
    assert cli([*COLLECT, "--rig", str(folder), "--data", str(tmp_path / "data")]) == 2
    assert "is a directory, not a TOML file" in one_error_line(capsys)
    assert not (tmp_path / "data").exists()


def test_angles_with_the_same_whole_degree_are_refused_before_any_array_is_built() -> None:
    rig = {"press": {"angle_min_deg": -44.5, "angle_max_deg": 44.5, "angle_count": 90}}  # .5 steps round together
    from unitac_rig.errors import ConfigError
    from unitac_rig.rig.config import parse_rig_config

    with pytest.raises(ConfigError, match="same whole degree"):
        parse_rig_config(rig)
    assert len(load_rig_config(None).angles_deg()) == 91


@pytest.mark.parametrize(
    ("args", "expected"),
    [
        (["--seed", "-1"], "--seed must be 0 or more, got -1"),
        (["--max-presses", "-1"], "--max-presses must be 1 or more, got -1"),
        (["--max-presses", "0"], "--max-presses must be 1 or more, got 0"),
        (["--angles", "1000000000"], "--angles must be 1 to 91, got 1000000000"),
        (["--angles", "0"], "--angles must be 1 to 91, got 0"),
        (["--angles", "1e30"], "Invalid value for '--angles'"),  # not a whole number: the parser's one line
    ],
)
def test_collect_counts_and_seeds_are_usage_errors_naming_the_option(
    args: list[str], expected: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert cli([*COLLECT, "--data", str(tmp_path / "data"), *args]) == 2
    assert expected in one_error_line(capsys)
    assert not (tmp_path / "data").exists()


def test_campaign_refuses_a_negative_seed(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert cli(["campaign", "--data", str(tmp_path / "data"), "--seed", "-3", "--no-live"]) == 2
    assert "--seed must be 0 or more, got -3" in one_error_line(capsys)


def test_max_presses_one_runs_exactly_one_press(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    data = tmp_path / "data"
    assert cli([*COLLECT, "--sensor", "uskin", "--data", str(data), "--angles", "3", "--max-presses", "1"]) == 0
    assert "1/3 presses finished (1 this run" in " ".join(capsys.readouterr().out.split())
    before = tree_hashes(data)
    assert cli([*COLLECT, "--sensor", "uskin", "--data", str(data), "--angles", "3", "--max-presses", "-1"]) == 2
    assert tree_hashes(data) == before


# -- checkpoints -----------------------------------------------------------------------------------------------------


def _frames(tmp_path: Path) -> Path:
    frames = tmp_path / "frames.npy"
    np.save(frames, np.zeros((2, 24, 3), dtype=np.float32))
    return frames


def test_a_checkpoint_with_nan_weights_is_refused_not_translated_to_nan(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    run = tmp_path / "run"
    run.mkdir()
    weights = torch.zeros(4, 72)
    weights[1, 3] = math.nan
    payload = {
        "format": CHECKPOINT_FORMAT,
        "version": CHECKPOINT_VERSION,
        "engine": {"state_dict": {"uskin.enc.0.weight": weights, "uskin.enc.0.bias": torch.zeros(4)}},
    }
    torch.save(payload, checkpoint_path(run))
    out = tmp_path / "out.npy"
    assert (
        cli(
            ["translate", str(run), str(_frames(tmp_path)), "--from", "uskin", "--to", "papillarray", "--out", str(out)]
        )
        == 1
    )
    line = one_error_line(capsys)
    assert "NaN or infinite values in engine.uskin.enc.0.weight" in line and "retrain" in line
    assert not out.exists()


def test_a_refused_checkpoint_never_advises_loading_it_with_the_safety_off(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    run = tmp_path / "run"
    run.mkdir()
    # torch's legacy (non-zip) format: torch cannot list its globals, only its own error text says what it holds
    torch.save(
        {"format": CHECKPOINT_FORMAT, "made": datetime.date(2025, 1, 1)},
        checkpoint_path(run),
        _use_new_zipfile_serialization=False,
    )
    assert cli(["translate", str(run), str(_frames(tmp_path)), "--from", "uskin", "--to", "papillarray"]) == 1
    line = one_error_line(capsys)
    assert "datetime.date" in line and "could run code" in line
    assert "weights_only" not in line and "trust" not in line and "\x1b[" not in line


# -- the simulated controller ----------------------------------------------------------------------------------------


@pytest.mark.parametrize("frequency", [math.nan, math.inf, -1.0, 0.0, 1e9])
def test_the_simulated_controller_never_streams_at_a_frequency_it_could_not_run(frequency: float) -> None:
    from unitac_rig.sim.twin.rtde_session import RtdeSession

    session = RtdeSession("test", controller_version=ControllerVersion(5, 11, 0, 0), max_frequency_hz=500.0)
    (package,) = rtde.RtdePackageParser().feed(rtde.encode_setup_outputs(frequency, ["timestamp"]))
    assert session.handle(package) is not None
    assert session.period_s == pytest.approx(1 / 500.0)  # what it does for any rate it cannot stream: the limit


@pytest.mark.parametrize("frequency", [math.nan, math.inf, 0.0])
def test_a_watchdog_frequency_that_is_not_a_positive_number_stops_the_script(frequency: float) -> None:
    from unitac_rig.sim.twin.controller import Controller
    from unitac_rig.sim.twin.script import ScriptError

    with pytest.raises(ScriptError, match="frequency must be > 0"):
        Controller.set_watchdog(types.SimpleNamespace(), "input_int_register_0", frequency)  # type: ignore[arg-type]
