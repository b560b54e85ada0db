"""Beyond the paper: one contact-geometry head trained on both sensors' latents, scored on the same held-out
contacts as the paper's per-sensor heads."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from lab.pooled_geometry import pooled_geometry
from tests.learning.learning_helpers import small_sets
from unitac_rig.learning.contact_geometry import GeometryConfig, run_geometry
from unitac_rig.learning.data import build_paired_dataset, ray_deg
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
    # 10% of the rays held out: 4 of the 40 physical rays (44 (rotation, angle) keys, four rays with two keys each),
    # every key of a held-out ray with its 5 forces
    rays = {ray_deg(r, a) for r, a in zip(paper.rotation_deg, paper.angle_deg, strict=True)}
    assert len(rays) == 4
    assert len(paper.test_rows) % 5 == 0 and 4 * 5 <= len(paper.test_rows) <= 8 * 5
    assert pooled["seconds"] > 0
