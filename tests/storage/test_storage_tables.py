"""Tables that fit: ``inspect`` and the training report's terminal table in an 80-column terminal, every cell whole
(no line over 80 characters, no ellipsis, every value findable as printed in full)."""

from __future__ import annotations

import io
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest
from rich.console import Console

from tests.robustness.robustness_helpers import write_synthetic_sessions
from unitac_rig.cli.learn import _print_table
from unitac_rig.learning.paper import PAPER_TABLE1
from unitac_rig.learning.report import baseline_name, direction_name, table_columns


def _run(*args: str, columns: int) -> str:
    env = {**os.environ, "COLUMNS": str(columns)}
    done = subprocess.run([sys.executable, "-m", "unitac_rig", *args], capture_output=True, text=True, env=env)
    assert done.returncode == 0, done.stderr
    return done.stdout


def _assert_fits(text: str, width: int) -> None:
    lines = text.splitlines()
    too_long = [line for line in lines if len(line) > width]
    assert not too_long, too_long
    assert "…" not in text and "..." not in text


def test_inspect_fits_80_columns_with_every_cell_whole(tmp_path: Path) -> None:
    write_synthetic_sessions(tmp_path, ("circle_pla", "irregular_pla"))
    text = _run("inspect", str(tmp_path), columns=80)
    _assert_fits(text, 80)
    report = json.loads(_run("inspect", str(tmp_path), "--json", columns=80))  # the full numbers, in N
    assert len(report["sessions"]) == 4
    for s in report["sessions"]:
        (row,) = [line for line in text.splitlines() if line.split()[:2] == [s["object"], s["sensor"] + "*"]]
        e, p = s["match_error_n"], s["peak_force_n"]
        cells = [
            f"{s['presses_complete']}/{s['presses_failed']}/{s['presses_planned']}",
            f"{s['targets_matched']}/{s['targets_missed']}",
            "/".join("-" if e[k] is None else f"{e[k] * 1000:.0f}" for k in ("median", "p95", "max")),
            "/".join("-" if p[k] is None else f"{p[k]:.1f}" for k in ("median", "max")),
        ]
        assert row.split()[2:6] == cells, row
    assert "irregular_pla" in text and "* simulated rig" in text


def _metrics(run: Path, sensors: tuple[str, ...]) -> dict[str, str]:
    """A run's metrics.json with the real row and column names and a distinct value per cell; returns every cell as
    it must be printed."""
    trained = {baseline_name(s) for s in sensors} | {direction_name(a, b) for a in sensors for b in sensors}
    columns = table_columns(sensors, trained)
    rows = [*PAPER_TABLE1, "all_seen"]
    table = {
        row: {c: {"nmae": 0.001 * (i + 1), "ssim": 0.5 + 0.001 * j} for j, c in enumerate(columns)}
        for i, row in enumerate(rows)
    }
    run.mkdir()
    (run / "metrics.json").write_text(
        json.dumps(
            {
                "sensors": list(sensors),
                "table1": table,
                "alignment": {"per_subset": {"all": {"latent_l1": {"first_epoch": [2.5], "final": [0.25]}}}},
            }
        )
    )
    cells = {f"{row}/{c}": f"{v['nmae']:.3f}/{v['ssim']:.3f}" for row, cs in table.items() for c, v in cs.items()}
    cells.update(
        {f"paper {row}/{c}": f"{n:.3f}/{s:.3f}" for row, cs in PAPER_TABLE1.items() for c, (n, s) in cs.items()}
    )
    return cells


@pytest.mark.parametrize("sensors", [("uskin", "papillarray"), ("uskin", "papillarray", "digit")])
def test_training_table_fits_80_columns_and_keeps_every_cell(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, sensors: tuple[str, ...]
) -> None:
    cells = _metrics(tmp_path / "run", sensors)
    monkeypatch.setenv("COLUMNS", "80")
    out = io.StringIO()
    console = Console(file=out)
    assert console.width == 80
    _print_table(console, tmp_path / "run")
    text = out.getvalue()
    _assert_fits(text, 80)
    printed = text.split()
    missing = {key: value for key, value in cells.items() if value not in printed}
    assert not missing, missing
    assert "u = uskin" in text and "p = papillarray" in text
    assert "latent L1 between matched contacts: 2.500 -> 0.250" in text


def test_training_table_uses_the_width_it_has(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    _metrics(tmp_path / "run", ("uskin", "papillarray"))
    tables = {}
    for columns in (80, 200):
        monkeypatch.setenv("COLUMNS", str(columns))
        out = io.StringIO()
        _print_table(Console(file=out), tmp_path / "run")
        tables[columns] = sum(line.split()[:1] == ["row"] for line in out.getvalue().splitlines())
    assert tables == {80: 2, 200: 1}  # two side-by-side chunks at 80 columns, one table when there is room
