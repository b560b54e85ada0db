"""Each benchmark's quick mode runs through the CLI and writes a sane JSON and a PNG (structure, never timings)."""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest

from unitac_rig.bench.press_benchmark import CAMPAIGN_PRESSES, nearest_rank, pareto_front, transit_time_s
from unitac_rig.cli import main

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


def _outputs(out: Path, name: str) -> dict:  # type: ignore[type-arg]
    png = out / f"bench_{name}.png"
    assert png.read_bytes()[:8] == PNG_MAGIC
    doc: dict = json.loads((out / f"bench_{name}.json").read_text())  # type: ignore[type-arg]
    assert doc["benchmark"] == name and doc["machine"]["cpus"] >= 1
    return doc


def test_pareto_front_keeps_only_points_nothing_beats_on_both_axes() -> None:
    # (time, error): (3, 0.1) is beaten by (2, 0.05); (1, 0.3) and (4, 0.01) and (2, 0.05) are the front
    points = [(3.0, 0.1), (1.0, 0.3), (2.0, 0.05), (4.0, 0.01), (5.0, 0.01), (1.0, math.inf)]
    assert pareto_front(points) == [1, 2, 3]


def test_nearest_rank_keeps_misses_infinite() -> None:
    errors = [0.1, 0.2, 0.3, math.inf]
    import numpy as np

    assert nearest_rank(np.array(errors), 0.5) == 0.2
    assert nearest_rank(np.array(errors), 0.95) == math.inf
    assert math.isnan(nearest_rank(np.array([]), 0.5))


def test_transit_time_of_trapezoid_and_triangle() -> None:
    # 50 mm at 50 mm/s, 0.5 m/s^2: 0.1 s ramps (2.5 mm each) + 45 mm cruise (0.9 s) = 1.1 s
    assert transit_time_s(0.05, 0.05, 0.5) == pytest.approx(1.1)
    # 2 mm never reaches cruise: 2 * sqrt(0.002 / 0.5) = 0.1265 s
    assert transit_time_s(0.002, 0.05, 0.5) == pytest.approx(2 * math.sqrt(0.004))


def test_press_quick(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    main(["bench", "press", "--quick", "--jobs", "1", "--out", str(tmp_path)])
    assert "goal:" in capsys.readouterr().out
    doc = _outputs(tmp_path, "press")
    assert doc["presses_run"] == 4 * 2 * 2  # settings x sensors x angles
    for variant in doc["variants"]:
        rows = variant["rows"]
        assert len(rows) == 4 and variant["pareto_front"]
        for row in rows:
            assert row["statuses"] == {"complete": 4}
            assert row["campaign_h"] == pytest.approx(row["per_press_s"] * CAMPAIGN_PRESSES / 3600)
            assert 0.5 < row["per_press_s"] < 10.0  # simulated seconds: settle, approach, press, dwell, retract
            assert 0.0 <= row["miss_rate"] <= 1.0
            assert 0.0 < row["matched_median_abs_error_n"] < 0.5  # within the extraction's tolerance
            assert -3.0 < row["true_overshoot_median_n"] < 3.0
            assert set(row["by_sensor"]) == {"uskin", "papillarray"}
        ramp = next(r for r in rows if r["strategy"] == "force-ramp")
        assert 4.0 < ramp["rise_rate_median_n_s"] < 16.0  # 8 N/s asked
        guarded = sorted((r for r in rows if r["strategy"] == "guarded"), key=lambda r: r["speed_mm_s"])
        assert guarded[0]["campaign_h"] > guarded[1]["campaign_h"]  # 2 mm/s takes longer than 8 mm/s
    # the same presses scored with the old moving average: the fit's matched frames are nearer their targets in
    # TRUTH (the simulator's own force) for every setting, and the measured error no longer hides the noise
    fit, old = doc["variants"][0], doc["variants"][1]
    assert (fit["method"], old["method"]) == ("fit", "moving-average")
    for f, o in zip(fit["rows"], old["rows"], strict=True):
        assert f["true_median_abs_error_n"] < o["true_median_abs_error_n"], f["setting"]


def test_recorder_quick_loses_no_frame(tmp_path: Path) -> None:
    main(["bench", "recorder", "--quick", "--out", str(tmp_path), "--work-dir", str(tmp_path / "work")])
    doc = _outputs(tmp_path, "recorder")
    recorder = doc["recorder"]
    assert recorder["frames_lost"] == 0 and recorder["presses_not_identical"] == 0
    for row in recorder["rows"]:
        pap, usk = row["by_sensor"]["papillarray"], row["by_sensor"]["uskin"]
        assert pap["frames_written"] == pap["frames_read_back"] == 2 * round(1000 * row["press_length_s"])
        assert usk["frames_written"] == usk["frames_read_back"] == 2 * round(100 * row["press_length_s"])
        assert row["combined_headroom"] > 0
    live = doc["live_papillarray"]
    assert live["frames_delivered"] > 0 and live["in_order"]
    assert live["counter_gaps"] == 0 and live["checksum_errors"] == 0
    assert live["frames_delivered"] == live["counter_last"] - live["counter_first"] + 1


def test_inference_quick(tmp_path: Path) -> None:
    main(["bench", "inference", "--quick", "--out", str(tmp_path)])
    doc = _outputs(tmp_path, "inference")
    assert doc["sensors"] == ["uskin", "papillarray"]
    ops = doc["by_threads"]["1"]
    assert set(ops) == {
        "encode uskin",
        "encode papillarray",
        "decode to uskin",
        "decode to papillarray",
        "translate uskin -> papillarray",
        "translate papillarray -> uskin",
    }
    for rows in ops.values():
        assert [r["batch"] for r in rows] == [1, 64, 1024]
        assert all(r["median_ms"] > 0 and r["p99_ms"] >= r["median_ms"] for r in rows)
    assert doc["within_budget"] == (doc["worst_single_frame_ms"] < 1.0)


def test_inference_refuses_a_run_without_checkpoint(tmp_path: Path) -> None:
    with pytest.raises(SystemExit) as exit_info:
        main(["bench", "inference", "--run", str(tmp_path), "--out", str(tmp_path)])
    assert exit_info.value.code == 2
