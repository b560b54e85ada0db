"""Where the learned representation fails: which outline feature a press hits (hand-worked on the irregular prism)
and the stability report of a tiny trained run (per-feature errors, PLA vs TPU, seed spread, figures)."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from stability import (
    CORNERS_PNG,
    MATERIALS_PNG,
    SEEDS_PNG,
    _direction_folds,
    feature_at_point,
    feature_of_press,
    outline_features,
    stability_report,
)
from tests.learning.learning_helpers import small_sets
from unitac_rig.errors import DataError, UsageError
from unitac_rig.learning.contact_geometry import GeometryConfig
from unitac_rig.learning.data import build_paired_dataset
from unitac_rig.learning.evaluate import evaluate_run, run_metrics
from unitac_rig.learning.paper import PAPER_TABLE1
from unitac_rig.learning.train import TrainConfig, load_run, load_test_set, train
from unitac_rig.rig.objects import get_object

IRREGULAR = get_object("irregular_pla")
V2 = np.array([0.0, 20.977491])  # 100 deg corner
V3 = np.array([-25.0, 0.0])  # 80 deg corner, pointing left


def test_a_press_aimed_at_the_80_degree_vertex_hits_corner_80() -> None:
    # rotation 90 turns V3 toward the pad at approach angle 0: the ray from the axis meets the outline at V3 itself
    hit = feature_of_press(IRREGULAR, 0.0, 90.0)
    assert hit.origin_mm.tolist() == pytest.approx(V3.tolist(), abs=1e-6)
    assert hit.corner_distance_mm == pytest.approx(0.0, abs=1e-6)
    assert hit.feature.kind == "corner"
    assert hit.feature.vertex_label == "V3"
    assert hit.feature.interior_angle_deg == pytest.approx(80.0, abs=1e-4)
    assert hit.feature.name == "corner 80 (V3)"


def test_a_press_aimed_at_the_middle_of_an_edge_hits_a_face() -> None:
    # midpoint of edge V2-V3 is (-12.5, 10.4887), at polar angle 140 deg; pad direction at rotation 90 and
    # angle -40 is -40 - 90 - 90 = -220 = 140 deg. It lies half the 32.635 mm edge (16.318 mm) from both corners.
    hit = feature_of_press(IRREGULAR, -40.0, 90.0)
    assert hit.origin_mm.tolist() == pytest.approx([-12.5, 10.488746], abs=1e-4)
    assert hit.corner_distance_mm == pytest.approx(16.318, abs=1e-3)
    assert hit.feature.kind == "face" and hit.feature.name == "face"


def test_the_corner_reaches_3_mm_along_the_edge_by_default() -> None:
    along = (V2 - V3) / np.linalg.norm(V2 - V3)
    assert feature_at_point(IRREGULAR, V3 + 2.9 * along).feature.name == "corner 80 (V3)"
    assert feature_at_point(IRREGULAR, V3 + 3.1 * along).feature.name == "face"
    assert feature_at_point(IRREGULAR, V3 + 3.1 * along, face_distance_mm=5.0).feature.name == "corner 80 (V3)"


def test_features_are_the_six_corners_sharpest_first_then_face() -> None:
    names = [f.name for f in outline_features(IRREGULAR)]
    assert names == [
        "corner 80 (V3)",
        "corner 100 (V2)",
        "corner 120 (V1)",
        "corner 120 (V4)",
        "corner 140 (V6)",
        "corner 160 (V5)",
        "face",
    ]
    assert [f.name for f in outline_features(get_object("circle_pla"))] == ["face"]
    assert feature_of_press(get_object("circle_pla"), 10.0, 0.0).feature.name == "face"


def test_geometry_folds_keep_every_force_of_a_direction_together_and_cover_each_direction_once() -> None:
    directions = [(r, a) for r in (0, 90) for a in range(-45, 46, 9) for _ in range(5)]  # 22 directions x 5 forces
    folds = _direction_folds(directions, 4, seed=0, object_id="irregular_pla")
    fold_of: dict[tuple[int, int], set[int]] = {}
    for direction, fold in zip(directions, folds.tolist(), strict=True):
        fold_of.setdefault(direction, set()).add(fold)
    assert all(len(f) == 1 for f in fold_of.values())
    sizes = np.bincount([next(iter(f)) for f in fold_of.values()], minlength=4)
    assert sorted(sizes.tolist()) == [5, 5, 6, 6]
    with pytest.raises(DataError, match="too few"):
        _direction_folds(directions[:10], 4, seed=0, object_id="irregular_pla")


# ---------------------------------------------------------------------------------------------------------------
# The report on a tiny run: 11 angles x 5 forces, circle in PLA and TPU, the irregular prism x 4 rotations
# ---------------------------------------------------------------------------------------------------------------

OBJECTS = ("circle_pla", "circle_tpu", "irregular_pla")


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("stability") / "run"
    pairs = build_paired_dataset(small_sets(objects=OBJECTS))
    train(pairs, out, TrainConfig(epochs=3, seeds=(0, 1), tsne_contacts=30, checkpoint_every=3), device="cpu")
    return out


@pytest.fixture(scope="module")
def report(run_dir: Path, tmp_path_factory: pytest.TempPathFactory) -> dict[str, Any]:
    figures = tmp_path_factory.mktemp("figures")
    return stability_report(
        run_dir, geometry_folds=2, geometry_config=GeometryConfig(epochs=2), figures_dir=figures
    ) | {"_figures_dir": str(figures)}


@pytest.fixture(scope="module")
def metrics(run_dir: Path) -> dict[str, Any]:
    return run_metrics(run_dir)


def test_report_is_json_and_names_the_object_seeds_and_paper_remark(report: dict[str, Any]) -> None:
    json.dumps(report, allow_nan=False)  # the benchmark script writes it as is: strict JSON
    assert report["object"] == "irregular_pla"
    assert report["seeds"] == [0, 1]
    assert report["paper_failing_corner_deg"] == 80.0
    assert "80 deg corner" in report["paper_remarks"]["geometry"]
    assert report["columns"] == list(PAPER_TABLE1["irregular_pla"])


def test_every_contact_of_the_object_falls_in_exactly_one_feature(
    report: dict[str, Any], metrics: dict[str, Any]
) -> None:
    features = {f["name"]: f for f in report["features"]}
    assert list(features) == [f.name for f in outline_features(IRREGULAR)]
    assert sum(f["test_contacts"] for f in features.values()) == metrics["test_rows"]["irregular_pla"] == 4 * 11 * 5
    # of the 44 directions (4 rotations x 11 angles, 9 deg apart) only rotation 90 / angle 0 comes within 3 mm of V3
    assert features["corner 80 (V3)"]["directions"] == 1
    assert features["corner 80 (V3)"]["test_contacts"] == 5
    assert features["corner 80 (V3)"]["vertex_mm"] == pytest.approx([-25.0, 0.0])
    assert features["face"]["max_corner_distance_mm"] > 3.0


def test_feature_errors_average_back_to_the_table_i_row_of_the_object(
    report: dict[str, Any], metrics: dict[str, Any]
) -> None:
    counts = {f["name"]: f["test_contacts"] for f in report["features"]}
    recon = report["reconstruction"]
    for name, count in counts.items():
        assert (recon[name] is None) == (count == 0)
    for column in report["columns"]:
        for metric in ("nmae", "ssim"):
            for member in range(2):
                weighted = sum(
                    counts[n] * recon[n][column][metric]["members"][member] for n in counts if counts[n] > 0
                ) / sum(counts.values())
                expected = metrics["table1_members"]["irregular_pla"][column][metric][member]
                assert weighted == pytest.approx(expected, rel=1e-5)
            whole = recon["whole object"][column][metric]
            assert whole["mean"] == pytest.approx(metrics["table1"]["irregular_pla"][column][metric], rel=1e-5)


def test_geometry_per_feature_covers_every_contact_once_with_the_true_corner_depth(report: dict[str, Any]) -> None:
    geometry = report["geometry"]
    assert geometry["folds"] == 2
    assert set(geometry["scenarios"]) == {
        "uskin_to_uskin",
        "uskin_to_papillarray",
        "papillarray_to_uskin",
        "papillarray_to_papillarray",
    }
    per_feature = geometry["per_feature"]
    tested = sum(entry["contacts"] for entry in per_feature.values() if entry is not None)
    assert tested == geometry["whole_object"]["contacts"] == 220 - geometry["left_out_contacts"]
    corner = per_feature["corner 80 (V3)"]
    # at V3 both walls leave the pad at 50 deg: depth |x| tan 50 deg at x = 0, +-1.4, ..., +-7 mm
    mean_abs_x = 2 * (1.4 + 2.8 + 4.2 + 5.6 + 7.0) / 11
    assert corner["mean_abs_depth_mm"] == pytest.approx(mean_abs_x * math.tan(math.radians(50)), rel=1e-4)
    for scenario in geometry["scenarios"]:
        cell = corner[scenario]
        assert len(cell["members"]) == 2
        assert 0.0 <= cell["min"] <= cell["mean"] <= cell["max"]
    assert geometry["paper_mae_mm"]["uskin_to_uskin"] == pytest.approx(0.353)


def test_pla_against_tpu_uses_the_table_i_rows_of_each_material(
    report: dict[str, Any], metrics: dict[str, Any]
) -> None:
    circle = report["materials"]["per_shape"]["circle"]
    assert circle["objects"] == {"PLA": "circle_pla", "TPU": "circle_tpu"}
    assert circle["contacts"] == {"PLA": 5, "TPU": 5}  # one held-out angle x 5 forces each
    cell = circle["uskin_to_papillarray"]["nmae"]
    assert cell["PLA"]["mean"] == pytest.approx(metrics["table1"]["circle_pla"]["uskin_to_papillarray"]["nmae"])
    assert cell["TPU"]["mean"] == pytest.approx(metrics["table1"]["circle_tpu"]["uskin_to_papillarray"]["nmae"])
    assert cell["tpu_minus_pla"]["mean"] == pytest.approx(cell["TPU"]["mean"] - cell["PLA"]["mean"])
    assert cell["paper"] == pytest.approx({"PLA": 0.020, "TPU": 0.021, "tpu_minus_pla": 0.001})
    pooled = report["materials"]["pooled"]
    assert pooled["objects"] == {"PLA": ["circle_pla"], "TPU": ["circle_tpu"]}
    assert pooled["uskin_to_papillarray"]["nmae"]["PLA"]["mean"] == pytest.approx(cell["PLA"]["mean"])


def test_seed_spread_is_mean_std_min_max_of_each_table_i_cell(report: dict[str, Any], metrics: dict[str, Any]) -> None:
    spread = report["seed_spread"]
    assert list(spread) == list(metrics["table1"])
    for row, cells in spread.items():
        for column, by_metric in cells.items():
            for metric, cell in by_metric.items():
                values = metrics["table1_members"][row][column][metric]
                assert cell["members"] == pytest.approx(values, rel=1e-5)
                assert cell["mean"] == pytest.approx(float(np.mean(values)), rel=1e-5)
                assert cell["std"] == pytest.approx(
                    float(np.std(values)), rel=1e-3, abs=1e-7
                )  # float32 vs float64 means
                assert cell["min"] == pytest.approx(min(values), rel=1e-5)
                assert cell["max"] == pytest.approx(max(values), rel=1e-5)
    assert spread["irregular_pla"]["papillarray_to_uskin"]["nmae"]["paper"] == pytest.approx(0.318)


def test_the_three_figures_are_drawn(report: dict[str, Any]) -> None:
    assert report["figures"] == {"corners": CORNERS_PNG, "materials": MATERIALS_PNG, "seeds": SEEDS_PNG}
    for name in report["figures"].values():
        png = Path(report["_figures_dir"]) / name
        assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_bad_requests_are_refused(run_dir: Path) -> None:
    with pytest.raises(UsageError, match="folds"):
        stability_report(run_dir, geometry_folds=1)
    with pytest.raises(DataError, match="no test contacts of object 'hex_pla'"):
        stability_report(run_dir, object_id="hex_pla", geometry_folds=0)


def test_an_object_without_corners_is_all_face(run_dir: Path) -> None:
    report = stability_report(run_dir, object_id="circle_pla", geometry_folds=0)
    assert [(f["name"], f["test_contacts"]) for f in report["features"]] == [("face", 5)]
    assert report["features"][0]["max_corner_distance_mm"] is None  # no corner to be near
    assert report["geometry"] is None
    json.dumps(report, allow_nan=False)


def test_other_metric_options_rescore_the_same_models_like_the_report_does(run_dir: Path) -> None:
    """``--nmae-normaliser`` on the benchmark gives the numbers ``unitac-rig report --nmae-normaliser`` puts in
    metrics.json: the whole-object row equals that re-scored Table I row, and differs from the run's own."""
    own = stability_report(run_dir, geometry_folds=0)
    other = stability_report(run_dir, geometry_folds=0, nmae_normaliser="channel_std")
    rescored = evaluate_run(load_run(run_dir).scored_under("channel_std"), load_test_set(run_dir))
    column = "uskin_to_uskin"
    whole_own = own["reconstruction"]["whole object"][column]
    whole_other = other["reconstruction"]["whole object"][column]
    assert whole_other["nmae"]["mean"] == pytest.approx(rescored["table1"]["irregular_pla"][column]["nmae"], rel=1e-5)
    assert whole_other["nmae"]["mean"] > whole_own["nmae"]["mean"]  # MAE / std > MAE / range
    assert whole_other["ssim"]["mean"] == pytest.approx(whole_own["ssim"]["mean"])  # SSIM range unchanged
