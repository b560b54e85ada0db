"""Issue 31's findings, each through the installed ``unitac-rig`` console script as a newcomer runs it.

One small simulated dataset (3 approach angles; hex_tpu with both sensors, the irregular prism with both, circle_pla
with the uSkin only and cut short) and one 2-epoch run are built once for the module and shared. The tests that
collect or train are marked ``slow``: outside the default ``pytest -q``, run by ``.ci/run``
(``-m 'not network_fault'``).
"""

from __future__ import annotations

import json
import os
import re
import signal
import subprocess
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

from tests.helpers import run_console, start_console
from unitac_rig.storage.reader import snapshot_session

ANGLES = "3"


def ok(*args: str, cwd: Path | None = None) -> subprocess.CompletedProcess[str]:
    result = run_console(*args, cwd=cwd)
    assert result.returncode == 0, result.stdout + result.stderr
    return result


@pytest.fixture(scope="module")
def data(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """hex_tpu and irregular_pla with both sensors; circle_pla with the uSkin only, 1 of 3 presses."""
    root = tmp_path_factory.mktemp("newcomer") / "data"
    for obj in ("hex_tpu", "irregular_pla"):
        for sensor in ("uskin", "papillarray"):
            ok("collect", "--object", obj, "--sensor", sensor, "--angles", ANGLES, "--data", str(root))
    ok(
        "collect",
        "--object",
        "circle_pla",
        "--sensor",
        "uskin",
        "--angles",
        ANGLES,
        "--max-presses",
        "1",
        "--data",
        str(root),
    )
    return root


@pytest.fixture(scope="module")
def trained(data: Path) -> tuple[Path, subprocess.CompletedProcess[str]]:
    out = data.parent / "runs" / "demo"
    result = ok("train", "--data", str(data), "--out", str(out), "--epochs", "2", "--tsne-contacts", "12")
    return out, result


@pytest.fixture
def torch_unimportable(tmp_path: Path) -> Iterator[dict[str, str]]:
    """An environment where ``import torch`` fails: a command that reports its error under it checked before the
    heavy import (a bad argument answered in well under a second, not after torch's 5-8 s)."""
    fake = tmp_path / "no_torch" / "torch"
    fake.mkdir(parents=True)
    (fake / "__init__.py").write_text("raise ImportError('torch imported before the argument checks')\n")
    yield {"PYTHONPATH": os.pathsep.join([str(fake.parent), os.environ.get("PYTHONPATH", "")])}


# ---- 3, 4: silent data traps --------------------------------------------------------------------------------------


@pytest.mark.slow
def test_3_train_names_the_session_it_left_out_for_lack_of_a_partner_sensor(
    trained: tuple[Path, subprocess.CompletedProcess[str]],
) -> None:
    out = " ".join(trained[1].stdout.split())  # rich folds long lines at 80 columns
    assert re.search(r"left out: circle_pla/uskin .*no session of the same object with another sensor", out), out


@pytest.mark.slow
def test_3_export_notes_the_incomplete_session_in_its_output_and_manifest(data: Path) -> None:
    out = data.parent / "export"
    result = ok("export", str(data), "--out", str(out))
    assert "circle_pla/uskin 1/3" in " ".join(result.stdout.split())
    manifest = json.loads((out / "manifest.json").read_text())
    listed = manifest.get("incomplete_sessions") or manifest.get("document", {}).get("incomplete_sessions")
    if listed is None:  # the manifest may wrap the export's document
        listed = next(v for k, v in _walk(manifest) if k == "incomplete_sessions")
    assert [(e["object"], e["sensor"], e["finished"], e["planned"]) for e in listed] == [("circle_pla", "uskin", 1, 3)]


def _walk(tree: object) -> Iterator[tuple[str, object]]:
    if isinstance(tree, dict):
        for key, value in tree.items():
            yield key, value
            yield from _walk(value)


@pytest.mark.slow
def test_4_translate_writes_under_the_run_and_reads_the_sensor_from_the_session_file(
    data: Path, trained: tuple[Path, subprocess.CompletedProcess[str]]
) -> None:
    run_dir = trained[0]
    before = sorted(p.name for p in data.iterdir())
    ok("translate", str(run_dir), str(data / "hex_tpu__uskin.h5"), "--to", "papillarray")
    assert sorted(p.name for p in data.iterdir()) == before  # nothing written into the dataset
    written = run_dir / "translations" / "hex_tpu__uskin_to_papillarray.npz"
    with np.load(written) as archive:
        assert archive["frames"].shape[1:] == (9, 3)


@pytest.mark.slow
def test_4_and_12_geometry_predict_writes_under_the_run_and_reads_the_sensor_from_the_file(
    data: Path, trained: tuple[Path, subprocess.CompletedProcess[str]]
) -> None:
    run_dir = trained[0]
    geometry = ok("geometry", str(run_dir), "--epochs", "2")
    assert "training the profile MLPs on irregular_pla" in geometry.stdout
    before = sorted(p.name for p in data.iterdir())
    ok("geometry", str(run_dir), "--predict", str(data / "irregular_pla__papillarray.h5"))  # no --sensor
    assert sorted(p.name for p in data.iterdir()) == before
    with np.load(run_dir / "geometry" / "irregular_pla__papillarray_geometry.npz") as archive:
        assert str(archive["sensor"]) == "papillarray"


@pytest.mark.slow
def test_12_geometry_on_a_seen_object_shows_no_paper_number_beside_it(data: Path, tmp_path: Path) -> None:
    run_dir = tmp_path / "run"  # two thirds of hex_tpu's 3 directions held out: enough to fit and test the MLPs
    ok("train", "--data", str(data), "--out", str(run_dir), "--epochs", "1", "--test-fraction", "0.67", "--no-report")
    result = ok("geometry", str(run_dir), "--object", "hex_tpu", "--epochs", "2")
    text = " ".join(result.stdout.split())
    assert "seen in training" in text and "not comparable" in text
    rows = [
        line for line in result.stdout.splitlines() if re.search(r"(uskin|papillarray)\W+(uskin|papillarray)", line)
    ]
    assert len(rows) == 4 and all(line.strip(" │").endswith("–") for line in rows), result.stdout


@pytest.mark.slow
def test_12_geometry_refuses_a_run_without_an_unseen_object_before_training(
    data: Path, tmp_path: Path, trained: tuple[Path, subprocess.CompletedProcess[str]]
) -> None:
    seen_only = tmp_path / "seen_only"
    seen_only.mkdir()
    for name in ("hex_tpu__uskin.h5", "hex_tpu__papillarray.h5"):
        snapshot_session(data / name, seen_only / name)  # the session as one self-contained file
    run_dir = tmp_path / "run"
    ok("train", "--data", str(seen_only), "--out", str(run_dir), "--epochs", "1", "--no-report")
    result = run_console("geometry", str(run_dir))
    assert result.returncode == 1
    assert "no unseen object" in result.stderr
    assert "training the profile MLPs" not in result.stdout


# ---- 5-7: time you can plan ----------------------------------------------------------------------------------------


@pytest.mark.slow
def test_5_campaign_prints_an_overall_progress_line_with_time_left(tmp_path: Path) -> None:
    result = ok("campaign", "--data", str(tmp_path / "d"), "--angles", "2", "--objects", "hex_tpu,circle_pla")
    lines = [line for line in result.stdout.splitlines() if line.startswith("campaign: session")]
    assert [line.split(" (")[0] for line in lines] == [f"campaign: session {i}/4" for i in range(1, 5)]
    assert "time left known after the first session" in lines[0]
    assert all(re.search(r"\d+/8 presses done, about .+ left", line) for line in lines[1:]), lines


@pytest.mark.slow
def test_5_report_says_what_each_stage_is_doing(trained: tuple[Path, subprocess.CompletedProcess[str]]) -> None:
    result = ok("report", str(trained[0]), "--no-figures")
    stages = [line for line in result.stdout.splitlines() if line.startswith("report: ") and line.endswith("...")]
    assert any("scoring" in line for line in stages) and any("report.md" in line for line in stages), stages
    drawn = [line for line in trained[1].stdout.splitlines() if line.startswith("report: ")]  # train's report stage
    assert any("t-SNE" in line for line in drawn) and any("reconstructions" in line for line in drawn), drawn


@pytest.mark.slow
def test_6_collect_into_a_log_prints_progress_lines(tmp_path: Path) -> None:
    result = ok("collect", "--object", "hex_tpu", "--angles", "3", "--data", str(tmp_path))
    assert re.search(r"hex_tpu / uskin: press 1/3 complete", result.stdout), result.stdout
    assert re.search(r"hex_tpu / uskin: press 3/3 complete", result.stdout), result.stdout


@pytest.mark.slow
def test_7_ctrl_c_says_what_was_kept_and_that_the_same_command_resumes(tmp_path: Path) -> None:
    process = start_console("collect", "--object", "hex_tpu", "--angles", "91", "--data", str(tmp_path))
    try:
        assert process.stdout is not None
        for line in process.stdout:  # wait for the condition: the first press is recorded
            if "press 1/91" in line:
                break
        process.send_signal(signal.SIGINT)
        _, stderr = process.communicate(timeout=120)
    finally:
        if process.poll() is None:
            process.kill()
    assert process.returncode == 130, stderr
    kept = re.search(r"hex_tpu / uskin: kept (\d+)/91 presses in ", stderr)
    assert kept and int(kept.group(1)) >= 1, stderr
    assert "run the same command again to resume" in stderr
    assert stderr.strip().splitlines()[-1] == "interrupted"


# ---- 9-13: conventions ---------------------------------------------------------------------------------------------

COMMANDS = [
    [],
    ["collect"],
    ["campaign"],
    ["extract"],
    ["objects"],
    ["inspect"],
    ["export"],
    ["verify"],
    ["train"],
    ["report"],
    ["translate"],
    ["geometry"],
    ["export-model"],
    ["import-unitac-nv"],
    ["twin"],
    ["probe"],
    ["probe", "uskin"],
    ["probe", "papillarray"],
    ["probe", "ur5e"],
    ["bench"],
]


@pytest.mark.parametrize("command", COMMANDS, ids=lambda c: " ".join(c) or "root")
def test_9_help_fits_80_columns_with_one_placeholder_and_default_style(command: list[str]) -> None:
    result = ok(*command, "--help")
    text = result.stdout
    assert all(len(line) <= 80 for line in text.splitlines()), text
    assert "…" not in text and "<bool>" not in text and "<" not in re.sub(r"<->|<=|<-", "", text), text
    assert "(default" not in text and "(the paper:" not in text, text
    for line in text.splitlines():  # flags take no value; value options one UPPERCASE word
        match = re.match(r"\s+(--[a-z-]+)( [^ ].*?)?(\s{2,}|$)", line)
        if match and match.group(2) and not match.group(2).startswith(" / "):
            assert re.fullmatch(r" [A-Z][A-Z_,]*", match.group(2)), line


def test_9_train_help_is_grouped() -> None:
    text = ok("train", "--help").stdout
    for heading in ("Data and run:", "Training:", "Split, preprocessing and metrics:", "Evaluation and report:"):
        assert heading in text
    assert "--json" in ok("inspect", "--help").stdout
    assert re.search(r"^  --json  ", ok("inspect", "--help").stdout, re.M)


def test_10_version_and_debug_after_the_command() -> None:
    version = ok("--version")
    assert re.fullmatch(r"unitac-rig \d+\.\d+\.\d+\S*\n", version.stdout)
    after = run_console("collect", "--object", "no_such_object", "--debug")
    assert after.returncode != 0
    assert "Traceback" in after.stderr and "No such option" not in after.stderr


def test_11_an_option_error_names_the_option_typed_and_exits_2() -> None:
    result = run_console("collect", "--object", "hex_tpu", "--angles", "0", "--data", "/nonexistent/never")
    assert result.returncode == 2
    assert "--angles" in result.stderr and "got 0" in result.stderr and "press.angle_count" not in result.stderr


@pytest.mark.slow
def test_11_export_into_a_non_empty_folder_is_a_usage_error_like_export_model(tmp_path: Path, data: Path) -> None:
    (tmp_path / "kept.txt").write_text("mine")
    result = run_console("export", str(data), "--out", str(tmp_path))
    assert result.returncode == 2, result.stderr
    assert "--out" in result.stderr


def test_11_bad_train_arguments_are_refused_before_torch_is_imported(
    tmp_path: Path, torch_unimportable: dict[str, str]
) -> None:
    existing = tmp_path / "runs" / "demo"
    existing.mkdir(parents=True)
    (existing / "checkpoint.pt").write_bytes(b"a run")  # what makes a folder a run
    for args, expected in (
        (["--data", str(tmp_path / "missing"), "--out", str(tmp_path / "r")], "--data"),
        (["--data", str(tmp_path), "--out", str(tmp_path / "r"), "--device", "gpu"], "--device"),
        (["--data", str(tmp_path), "--out", str(tmp_path / "r"), "--preprocessing", "zscore"], "--preprocessing"),
        (["--data", str(tmp_path), "--out", str(existing)], "already holds a run"),
    ):
        result = run_console("train", *args, env=torch_unimportable)
        assert result.returncode == 2, result.stderr
        assert expected in result.stderr and "torch imported" not in result.stderr, result.stderr


def test_13_a_rig_file_type_error_names_the_field(tmp_path: Path) -> None:
    rig = tmp_path / "rig.toml"
    rig.write_text('[sensors.papillarray]\ntype = "papillarray"\nport = 5\n')
    result = run_console("objects", "--rig", str(rig))
    assert result.returncode != 0
    assert "sensors.papillarray.port:" in result.stderr
    assert "papillarray.papillarray" not in result.stderr


def test_13_papillarray_probe_gives_a_rate_and_distinct_sample_times() -> None:
    table = ok("probe", "papillarray", "--simulated", "--frames", "3")
    assert "n/a" not in table.stdout and re.search(r"about \d+ Hz", " ".join(table.stdout.split()))
    frames = [
        json.loads(line)
        for line in ok("probe", "papillarray", "--simulated", "--frames", "3", "--json").stdout.splitlines()
    ]
    times = [frame["device_t"] for frame in frames]
    assert len(set(times)) == 3 and times == sorted(times)


def test_13_probe_ur5e_lines_fit_80_columns() -> None:
    result = ok("probe", "ur5e", "--simulated", "--frames", "2")
    assert result.stdout.count("controller") == 2
    assert all(len(line) <= 80 for line in result.stdout.splitlines()), result.stdout


# ---- 14: figures --------------------------------------------------------------------------------------------------


def _png_size(path: Path) -> tuple[int, int]:
    header = path.read_bytes()[16:24]
    return int.from_bytes(header[:4], "big"), int.from_bytes(header[4:], "big")


@pytest.mark.slow
def test_14_figures_fit_a_page_and_show_several_contacts(
    trained: tuple[Path, subprocess.CompletedProcess[str]],
) -> None:
    figures = trained[0] / "figures"
    width, height = _png_size(figures / "curves.png")
    assert width <= 1000 and height / width > 0.5  # two panels a row, not a 2024 x 440 strip
    _, seen_h = _png_size(figures / "reconstructions_seen.png")
    assert seen_h > 600  # more than one contact (one row is about 300 px)
