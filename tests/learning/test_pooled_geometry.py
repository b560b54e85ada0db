"""Beyond the paper: one contact-geometry head trained on both sensors' latents, scored on the same held-out
contacts as the paper's per-sensor heads."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from tests.learning.learning_helpers import small_sets
from unitac_rig.learning.contact_geometry import GeometryConfig, run_geometry
from unitac_rig.learning.data import build_paired_dataset
from unitac_rig.learning.pooled_geometry import pooled_geometry
from unitac_rig.learning.train import TrainConfig, load_run, load_test_set, train


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("pooled") / "run"
    train(build_paired_dataset(small_sets()), out, TrainConfig(epochs=2, tsne_contacts=10), device="cpu")
    return out


def test_the_pooled_head_is_scored_on_each_sensor_over_the_paper_heads_test_contacts(run_dir: Path) -> None:
    run, test = load_run(run_dir), load_test_set(run_dir)
    config = GeometryConfig(epochs=3)
    pooled = pooled_geometry(run, test, config=config)
    paper = run_geometry(run, test, config=config)
    assert pooled["object"] == paper.object_id == "irregular_pla"
    assert set(pooled["scenarios"]) == {"pooled_to_uskin", "pooled_to_papillarray"}
    for scenario in pooled["scenarios"].values():
        assert np.isfinite(scenario["mae_mm"]) and len(scenario["per_point_mae_mm"]) == 11
    # the same 10% of directions held out: 4 of the 44 (rotation, angle) directions with their 5 forces
    assert len(paper.test_rows) == 4 * 5
    assert pooled["seconds"] > 0
