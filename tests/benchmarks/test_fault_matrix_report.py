"""The fault matrix's judging and its table, on the committed run (docs/figures/fault_matrix.json): the criteria
judge every recorded row as they did when it ran, and ``--render`` regenerates docs/reliability.md's section from the
JSON alone. Running the rows themselves is ``pytest -m fault_matrix`` (about an hour)."""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Any

import pytest

import fault_matrix as matrix

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def committed() -> dict[str, Any]:
    doc: dict[str, Any] = json.loads((ROOT / "docs" / "figures" / "fault_matrix.json").read_text(encoding="utf-8"))
    return doc


def test_every_recorded_row_is_judged_as_when_it_ran(committed: dict[str, Any]) -> None:
    """The criteria the run recorded (a row recorded before a criterion existed is judged on the ones it has)."""
    for row in committed["rows"]:
        judged = matrix.criteria(row)
        assert {k: v for k, v in judged.items() if k in row["criteria"]} == row["criteria"], row["row"]


def test_the_planned_rows_are_the_recorded_ones(committed: dict[str, Any]) -> None:
    assert [s.row for s in matrix.scenarios()] == [r["row"] for r in committed["rows"]]
    for scenario, row in zip(matrix.scenarios(), committed["rows"], strict=True):
        assert scenario.host_can_act == row["host_can_act"], row["row"]


def test_render_regenerates_the_reliability_section(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    page = tmp_path / "reliability.md"
    page.write_text((ROOT / "docs" / "reliability.md").read_text(encoding="utf-8"), encoding="utf-8")
    out = ROOT / "docs" / "figures" / "fault_matrix.json"
    monkeypatch.setattr(sys, "argv", ["fault_matrix.py", "--render", "--out", str(out), "--docs", str(page)])
    matrix.main()
    assert page.read_text(encoding="utf-8") == (ROOT / "docs" / "reliability.md").read_text(encoding="utf-8")
