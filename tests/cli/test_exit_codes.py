"""Issues 40 and 41: the README's exit codes through the installed console script, as a user's script sees them
(0 done, 1 failure, 2 usage, 130 Ctrl-C), each refusal one line and before any work.

The interruption messages (what was kept, the command that goes on) are in test_interruptions.py.
"""

from __future__ import annotations

import subprocess
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from tests.helpers import cli, run_console


def _one_error_line(result: subprocess.CompletedProcess[str]) -> str:
    lines = [line for line in result.stderr.splitlines() if line.strip()]
    assert len(lines) == 1, result.stderr
    assert lines[0].startswith("error: ") and "unexpected" not in lines[0], lines[0]
    assert "Traceback" not in result.stderr
    return lines[0]


def test_no_command_prints_the_help_as_help_and_exits_2() -> None:
    result = run_console()
    assert result.returncode == 2
    assert result.stdout.startswith("Usage: unitac-rig"), result.stdout
    assert "Collect data:" in result.stdout and "\n  collect" in result.stdout  # laid out, not squashed in one line
    assert "error" not in result.stderr


def test_a_command_that_works_exits_0() -> None:
    result = run_console("objects")
    assert result.returncode == 0, result.stderr
    assert "hex_tpu" in result.stdout


def test_a_runtime_failure_exits_1(tmp_path: Path) -> None:
    (tmp_path / "not-an-export").mkdir()
    result = run_console("verify", str(tmp_path / "not-an-export"))
    assert result.returncode == 1
    assert "manifest.json does not exist" in _one_error_line(result)


@pytest.fixture
def places(tmp_path: Path) -> Path:
    """A working folder with an empty data folder ``data`` and a plain file ``afile.txt``."""
    (tmp_path / "data").mkdir()
    (tmp_path / "afile.txt").write_text("not a folder\n")
    return tmp_path


@pytest.mark.parametrize(
    ("args", "expected"),
    [
        (["inspect", "nodir"], "DATA nodir does not exist"),
        (["inspect", "afile.txt"], "DATA afile.txt is a file, not a folder"),
        (["extract", "afile.txt"], "DATA afile.txt is a file, not a folder"),
        (["export", "nodir", "--out", "new"], "DATA nodir does not exist"),
        (["verify", "nodir"], "DIR nodir does not exist"),
        (["verify", "afile.txt"], "DIR afile.txt is a file, not a folder"),
        (["collect", "--object", "hex_tpu", "--data", "afile.txt"], "--data afile.txt is a file, not a folder"),
        (["collect", "--object", "hex_tpu", "--data", ""], "Invalid value for '--data': an empty path"),
        (["campaign", "--data", "afile.txt/sub"], "afile.txt is a file, not a folder"),
        (["inspect", "data", "--watch", "--interval", "nan"], "--interval must be a positive number of seconds"),
        (["export", "data", "--out", "/proc/x"], "--out /proc/x cannot be created in /proc"),
        (["export", "data", "--out", "afile.txt/sub"], "afile.txt is a file, not a folder"),
        (["export-model", "runs/nope", "--out", "m"], "runs/nope does not exist"),
        (["train", "--data", "data", "--out", "/proc/x"], "--out /proc/x cannot be created in /proc"),
        (["train", "--data", "data", "--out", "afile.txt/run"], "afile.txt is a file, not a folder"),
        (["train", "--data", "data", "--out", "new", "--test-fraction", "1.5"], "--test-fraction 1.5"),
    ],
)
def test_path_and_value_errors_exit_2_in_one_line_and_write_nothing(
    places: Path, args: list[str], expected: str
) -> None:
    before = sorted(p.name for p in places.rglob("*"))
    result = run_console(*args, cwd=places)
    assert result.returncode == 2, result.stdout + result.stderr
    assert expected in _one_error_line(result)
    assert sorted(p.name for p in places.rglob("*")) == before  # nothing collected, exported or probed left behind


def test_debug_shows_the_traceback_with_the_same_exit_code(places: Path) -> None:
    plain = run_console("export-model", "runs/nope", cwd=places)
    debug = run_console("export-model", "runs/nope", "--debug", cwd=places)
    assert plain.returncode == debug.returncode == 2
    assert "Traceback" in debug.stderr and "Traceback" not in plain.stderr
    inspect = run_console("--debug", "inspect", "nodir", cwd=places)
    assert inspect.returncode == 2 and "Traceback" in inspect.stderr


def test_a_typo_in_a_rig_file_is_a_usage_error_that_names_the_key_meant(tmp_path: Path) -> None:
    rig = tmp_path / "labb.toml"
    rig.write_text("[press]\nthreshhold_n = 3.0\n")
    result = run_console("collect", "--object", "hex_tpu", "--rig", str(rig), "--data", str(tmp_path / "data"))
    assert result.returncode == 2
    line = _one_error_line(result)
    assert "press.threshhold_n: unknown key (did you mean threshold_n?)" in line
    assert not (tmp_path / "data").exists()


def test_a_rig_file_without_an_arm_says_so_instead_of_no_rig_file(tmp_path: Path) -> None:
    rig = tmp_path / "labb.toml"
    rig.write_text('name = "labb"\n')
    result = run_console(
        "collect",
        "--object",
        "hex_tpu",
        "--rig",
        str(rig),
        "--data",
        str(tmp_path / "data"),
        "--angles",
        "3",
        "--max-presses",
        "1",
        "--no-live",
    )
    assert result.returncode == 0, result.stderr
    text = " ".join(result.stdout.split())
    assert f"SIMULATED RIG (rig file {rig} has no [arm])" in text
    assert "no rig file given" not in text


def test_a_collect_that_pressed_nothing_is_a_runtime_failure(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Issue 37: the object is not where the rig file says (1 m away): no press completes, and `collect` exits 1
    (a runtime failure, resumable), never 0, with one line saying why."""
    from unitac_rig.sim.fast_rig import SimRig

    mount = SimRig.mount

    def misplaced(self: SimRig, obj: Any, rotation_deg: float, sensor_name: str) -> None:
        mount(self, obj, rotation_deg, sensor_name)
        self.world.scene.center_mm = self.world.scene.center_mm + np.array([0.0, 1000.0])

    monkeypatch.setattr(SimRig, "mount", misplaced)
    code = cli(["collect", "--object", "circle_pla", "--data", str(tmp_path / "data"), "--angles", "2"])
    assert code == 1
