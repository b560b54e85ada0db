"""Adding a metric is one new module and one line in the metric table: the worked example of docs/learning.md ("Add a
metric") run for real. A root-mean-square error written in its own module and put in ``METRICS`` shows up in the
training history, ``metrics.json`` (with the right value), ``report.md`` and the terminal's table, with nothing else
changed."""

from __future__ import annotations

import importlib
import json
from pathlib import Path

import numpy as np
import pytest
import torch

from tests.helpers import cli
from tests.learning.learning_helpers import small_sets, write_sessions
from unitac_rig.learning.engine import UNITAC_GROUP
from unitac_rig.learning.metric_table import METRICS
from unitac_rig.learning.train import load_run, load_test_set

# the new module, as docs/learning.md writes it (unitac_rig/learning/metric_rmse.py there)
METRIC_MODULE = '''"""Root-mean-square error of a reconstructed frame, in the sensor's units."""

import torch

from unitac_rig.learning.metrics import FrameScoring, Metric


def rmse(estimate: torch.Tensor, scoring: FrameScoring, variant: str | None = None) -> torch.Tensor:
    """(members, M, n, 3) frames against the true (M, n, 3) ones -> (members, M)."""
    return (estimate - scoring.target).pow(2).mean(dim=(-2, -1)).sqrt()


RMSE = Metric("rmse", "RMSE", "lower", "sensor units", "frame", rmse, "root-mean-square error over taxels and axes")
'''


def test_a_new_metric_module_and_one_table_line_reach_train_evaluate_report_and_the_terminal(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    (tmp_path / "metric_rmse.py").write_text(METRIC_MODULE, encoding="utf-8")
    monkeypatch.syspath_prepend(str(tmp_path))
    module = importlib.import_module("metric_rmse")
    monkeypatch.setitem(METRICS, "rmse", module.RMSE)  # the one line in metric_table.METRICS

    data, run = tmp_path / "data", tmp_path / "run"
    write_sessions(data, small_sets(objects=("circle_pla", "irregular_pla")))
    assert cli(["train", "--data", str(data), "--out", str(run), "--epochs", "2", "--no-baselines",
                "--tsne-contacts", "0"]) == 0  # fmt: skip
    terminal = capsys.readouterr().out
    assert "Test NMAE/SSIM/RMSE" in terminal  # train's own table, printed after the report

    history = load_run(run).history
    assert "rmse" in history[-1]["val"]["seen"]["uskin_to_papillarray"]  # recorded while training
    metrics = json.loads((run / "metrics.json").read_text(encoding="utf-8"))
    assert metrics["metric_table"]["rmse"] == {"label": "RMSE", "direction": "lower", "units": "sensor units",
                                               "scope": "frame"}  # fmt: skip
    cell = metrics["table1"]["all_seen"]["uskin_to_papillarray"]
    assert set(cell) == {"nmae", "ssim", "rmse"}

    # the value is the RMSE of the model's translations of the seen test contacts, computed here from scratch
    loaded, test = load_run(run), load_test_set(run)
    seen = ~np.isin(test.object_id, list(loaded.unseen_objects))
    x = torch.from_numpy(loaded.normaliser.normalise("uskin", test.values["uskin"][seen]))
    decoded = loaded.engine.decode(UNITAC_GROUP, loaded.engine.encode(UNITAC_GROUP, "uskin", x))["papillarray"][0]
    frames = decoded.reshape(len(x), -1, 3).numpy() * loaded.normaliser.std["papillarray"]
    frames = frames + loaded.normaliser.mean["papillarray"]
    expected = np.sqrt(((frames - test.values["papillarray"][seen]) ** 2).mean(axis=(1, 2))).mean()
    assert cell["rmse"] == pytest.approx(expected, rel=1e-4)

    report = (run / "report.md").read_text(encoding="utf-8")
    assert "## Table I: NMAE / SSIM / RMSE on the test set" in report
    assert f"{cell['nmae']:.3f} / {cell['ssim']:.3f} / {cell['rmse']:.3f}" in report
    assert "RMSE: root-mean-square error over taxels and axes (sensor units)." in report

    assert cli(["report", str(run), "--no-figures"]) == 0  # `report` reads the same table
    assert f"{cell['rmse']:.3f}" in capsys.readouterr().out


def test_the_table_says_which_way_each_metric_is_better() -> None:
    assert METRICS["nmae"].better(0.1, 0.2) and METRICS["ssim"].better(0.9, 0.8)
    assert [m.scope for m in METRICS.values()].count("frame") == 2  # NMAE and SSIM, the paper's
    assert all(m.units and m.description for m in METRICS.values())
