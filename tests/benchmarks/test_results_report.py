"""docs/results.md is rendered from the committed per-split JSON alone (issue 29): a tiny run through every stage,
its run folder deleted, then the page drawn from the JSON; each number on the page traces to the JSON."""

from __future__ import annotations

import json
import shutil
import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "benchmarks"))

from tests.learning.learning_helpers import small_sets  # noqa: E402
from unitac_rig.learning.data import build_paired_dataset  # noqa: E402
from unitac_rig.learning.train import TrainConfig  # noqa: E402


@pytest.fixture(scope="module")
def json_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    from results_full import export_split, geometry_member, split_config, train_split

    root = tmp_path_factory.mktemp("results")
    dataset = build_paired_dataset(small_sets())
    base = TrainConfig().updated({"epochs": 2, "eval_every": 1, "tsne_contacts": 10})
    for protocol in ("random", "blocked"):
        run_dir = root / "runs" / protocol / "split-1"
        if protocol == "blocked":  # as results_full does: a 1-epoch probe, then resumed to the full run
            probe = split_config(base.updated({"epochs": 1}), protocol, 1, 2)
            train_split(dataset, run_dir, probe, log=lambda message: None)
        train_split(dataset, run_dir, split_config(base, protocol, 1, 2), log=lambda message: None)
        for member in range(2):
            geometry_member(run_dir, protocol, member, ceiling=member == 0, epochs=3)
        export_split(run_dir, protocol, root / "json" / protocol / "split-1.json", figures=False)
    shutil.rmtree(root / "runs")  # the page must need nothing but the JSON
    return root / "json"


def test_the_page_is_drawn_from_the_json_alone_with_both_protocols(json_dir: Path, tmp_path: Path) -> None:
    import run_results

    results = run_results.load_results(json_dir)
    assert set(results) == {"random", "blocked"}
    page = run_results.render(results, run_results.draw_figures(results, tmp_path / "figures", None))
    for heading in ("## Random split", "## Blocked split", "Strict cross-sensor geometry", "no latent", "**default**"):
        assert heading in page
    assert (tmp_path / "figures" / "results_blocked_cross_sensor.png").exists()


def test_each_split_keeps_its_own_model_seeds_and_every_members_geometry(json_dir: Path) -> None:
    doc = json.loads((json_dir / "blocked" / "split-1.json").read_text(encoding="utf-8"))
    assert doc["config"]["seeds"] == [2, 3] and doc["config"]["split_mode"] == "blocked"
    members = doc["geometry"]["members"]
    assert [m["model_seed"] for m in members] == [2, 3]
    assert len({m["geometry_split_seed"] for m in members}) == 2
    assert "ceiling" in members[0]["cross_sensor"] and "ceiling" not in members[1]["cross_sensor"]
    assert set(doc["readings"]) == {f"{n}|{s}" for n, s in __import__("results_full").READINGS}


def test_the_pages_no_latent_number_is_the_mean_over_the_json_members(json_dir: Path, tmp_path: Path) -> None:
    import run_results

    results = run_results.load_results(json_dir)
    page = run_results.render(results, {})
    doc = json.loads((json_dir / "random" / "split-1.json").read_text(encoding="utf-8"))
    values = np.array([m["cross_sensor"]["no_latent_mm"] for m in doc["geometry"]["members"]])
    assert f"| no latent (the training rays' mean profile) | {values.mean():.3f} ± {values.std():.3f} | – |" in page


def test_the_blocked_json_records_its_mode_and_gap_after_the_resumed_run(json_dir: Path) -> None:
    """Issue 38: results_full resumes every run after its probe, and the resumed run recorded random, 0."""
    doc = json.loads((json_dir / "blocked" / "split-1.json").read_text(encoding="utf-8"))
    assert doc["history"][-1]["epoch"] == 2
    assert (doc["split"]["mode"], doc["split"]["gap_deg"]) == ("blocked", 3.0)
    assert doc["split"]["not_held_out"] == ["circle_pla"]
    assert "circle_pla" not in doc["metrics"]["table1"]  # a circle cannot be held out by angle


def test_table_one_carries_the_simple_baselines_and_the_paired_comparison(json_dir: Path) -> None:
    import run_results

    results = run_results.load_results(json_dir)
    page = run_results.render(results, {})
    doc = json.loads((json_dir / "random" / "split-1.json").read_text(encoding="utf-8"))
    simple = doc["metrics"]["simple_baselines"]["table1"]["all_seen"]
    assert set(simple) == {
        "pca_uskin",
        "pca_papillarray",
        "ridge_uskin_to_papillarray",
        "nn_uskin_to_papillarray",
        "ridge_papillarray_to_uskin",
        "nn_papillarray_to_uskin",
    }
    for reading in doc["readings"].values():  # under every metric reading too
        assert set(reading["simple_baselines"]["all_seen"]) == set(simple)
    assert "### Simple baselines (random split)" in page and "### Simple baselines (blocked split)" in page
    # the paired row of p -> u against the ridge map: the mean over the two members of (baseline - ours)
    ours = np.array(doc["metrics"]["table1_members"]["all_seen"]["papillarray_to_uskin"]["nmae"])
    difference = simple["ridge_papillarray_to_uskin"]["nmae"] - ours
    wins = int((difference > 0).sum())
    assert (
        f"| all_seen | papillarray → uskin | ridge papillarray → uskin | {difference.mean():+.4f} | {wins} of 2 |"
        in page
    )
    assert "matched / unmatched L1" in page and "so it is not the claim" in page


def test_the_collection_line_comes_from_its_json_or_says_there_is_none(json_dir: Path) -> None:
    import run_results

    results = run_results.load_results(json_dir)
    assert "no `docs/results/collection.json`" in run_results.render(results, {}, None)
    session = {
        "presses_planned": 130,
        "presses_complete": 130,
        "targets_matched": 3249,
        "targets_missed": 1,
        "match_error_n": {"median": 0.013, "p95": 0.027, "max": 0.05},
        "peak_force_n": {"median": 11.0, "max": 11.7},
    }
    other = {**session, "targets_missed": 0, "match_error_n": {"median": 0.082, "p95": 0.256, "max": 0.3}}
    page = run_results.render(results, {}, {"sessions": [session, other], "pairs": {"hex_pla": 2275}})
    assert (
        "2 sessions, 260 of 260 presses complete, 6498 of 6499 force targets matched; force-matching error per "
        "session median 13-82 mN, p95 27-256 mN; press peak force median 11.0-11.0 N, max 11.7-11.7 N; joined pairs "
        "per object: hex_pla 2275." in page
    )


def test_the_halving_verdict_does_not_call_a_ceiling_a_bound_when_a_strict_method_beats_it() -> None:
    import run_results

    summary = {
        "ceiling": {"raw_uskin": {"test_mm": 0.55}, "raw_papillarray": {"test_mm": 0.2}},
        "methods": {"cca": {"uskin_to_papillarray": 0.4, "papillarray_to_uskin": 0.276}},
    }
    verdict = run_results.halving_verdict(summary)
    assert "For papillarray → uskin a strict cross-sensor method reads below the ceiling" in verdict
    assert "leaves room to halve the paper's error for uskin → papillarray" in verdict
    assert "rules out" not in verdict


def test_the_committed_page_is_what_the_committed_json_renders(tmp_path: Path) -> None:
    """``run_results.py`` regenerates docs/results.md byte for byte from docs/results/*.json (the JSON
    keeps the training config of the code that wrote it: the page reads it as stored, not through TrainConfig)."""
    import run_results

    (tmp_path / "figures").mkdir()
    for figure in (ROOT / "docs" / "figures").glob("results_*.png"):  # the per-run figures are copied, not drawn
        shutil.copyfile(figure, tmp_path / "figures" / figure.name)
    page = tmp_path / "results.md"
    shutil.copyfile(ROOT / "docs" / "results.md", page)
    assert run_results.write_page(ROOT / "docs" / "results", page, None)
    assert page.read_text(encoding="utf-8") == (ROOT / "docs" / "results.md").read_text(encoding="utf-8")


def test_the_unseen_to_seen_ratio_is_the_ratio_of_member_means_beside_the_papers() -> None:
    import run_results

    columns = list(run_results.PAPER_TABLE1["all_seen"])
    paper = {
        c: run_results.PAPER_TABLE1["irregular_pla"][c][0] / run_results.PAPER_TABLE1["all_seen"][c][0] for c in columns
    }
    # members 0.01 and 0.03 on the seen row (mean 0.02); the unseen row's mean is the paper's ratio times 0.02,
    # except the first column (twice the paper's: out) and the second (1.4 times: within 1.5)
    factor = {c: 1.0 for c in columns} | {columns[0]: 2.0, columns[1]: 1.4}
    table = {
        "all_seen": {c: {"nmae": 0.02} for c in columns},
        "irregular_pla": {c: {"nmae": 0.02 * paper[c] * factor[c]} for c in columns},
    }
    members = {
        "all_seen": {c: {"nmae": [0.01, 0.03]} for c in columns},
        "irregular_pla": {c: {"nmae": [0.02 * paper[c] * factor[c]] * 2} for c in columns},
    }
    splits = [{"metrics": {"table1": table, "table1_members": members}}]
    (line,) = [x for x in run_results.unseen_ratio_lines("random", splits, columns) if x]
    assert f"{len(columns) - 1} of {len(columns)} within a factor 1.5" in line
    assert line.count("**out**") == 1
    assert f"{2 * paper[columns[0]]:.2f} (paper {paper[columns[0]]:.2f}) **out**" in line
    assert "random split, where" not in line
    assert "random split, where" in run_results.unseen_ratio_lines("blocked", splits, columns)[1]
