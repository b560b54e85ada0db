"""The geometry heads beyond the paper's (benchmarks/lab/geometry_heads.py). Strict cross-sensor geometry (issue 29):
the latent translators on hand-worked linear cases, and the study on a small trained run never reading the target
sensor's frames of the unseen object in training. The pooled head: scored on each sensor over the same held-out
contacts as the paper's per-sensor heads."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from lab import geometry_heads
from lab.geometry_heads import cca_projections, cross_sensor_geometry, pooled_geometry, ridge_map
from tests.learning.learning_helpers import small_sets
from unitac_rig.learning.contact_geometry import GeometryConfig, run_geometry
from unitac_rig.learning.data import build_paired_dataset, ray_deg
from unitac_rig.learning.train import TrainConfig, load_run, load_test_set, train


def linear_pair(seed: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """B's latents an invertible linear function of A's plus a shift: (za, zb, matrix, shift)."""
    rng = np.random.default_rng(seed)
    za = rng.normal(size=(400, 4))
    matrix = rng.normal(size=(4, 4)) + 2 * np.eye(4)
    shift = np.array([1.0, -2.0, 0.5, 3.0])
    return za, za @ matrix + shift, matrix, shift


def test_the_ridge_map_recovers_a_linear_relation_between_the_sensors_latents() -> None:
    za, zb, matrix, shift = linear_pair()
    mapped = ridge_map(za, zb, ridge=1e-9)(np.array([[1.0, 0.0, 0.0, 0.0]]))
    np.testing.assert_allclose(mapped[0], matrix[0] + shift, atol=1e-4)


def test_cca_puts_linearly_related_matched_contacts_on_the_same_coordinates() -> None:
    za, zb, _, _ = linear_pair(1)
    to_a, to_b = cca_projections(za, zb, ridge=1e-9)
    np.testing.assert_allclose(to_a(za), to_b(zb), atol=1e-3)
    np.testing.assert_allclose(np.cov(to_a(za).T), np.eye(4), atol=1e-2)  # whitened: unit variance, uncorrelated


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("cross") / "run"
    train(build_paired_dataset(small_sets()), out, TrainConfig(epochs=2, tsne_contacts=10), device="cpu")
    return out


def test_no_head_trains_on_the_target_sensors_frames_of_the_unseen_object(
    run_dir: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Every head's training inputs are computed from its train sensor's frames alone: with the target sensor's
    unseen-object frames replaced by noise, every cross-sensor head is fitted on identical inputs (only its test
    inputs change)."""
    run, test = load_run(run_dir), load_test_set(run_dir)
    fitted: list[list[np.ndarray]] = []
    original = geometry_heads.fit_single_thread

    def spy(inputs: list[np.ndarray], *args: object, **kwargs: object) -> object:
        fitted.append([np.array(x) for x in inputs])
        return original(inputs, *args, **kwargs)

    monkeypatch.setattr(geometry_heads, "fit_single_thread", spy)
    config = GeometryConfig(epochs=2)
    first = cross_sensor_geometry(run, test, member=0, split_seed=5, config=config, ceiling=False)
    noisy = {s: v.copy() for s, v in test.values.items()}
    unseen = test.object_id == "irregular_pla"
    noisy["papillarray"][unseen] = np.random.default_rng(0).normal(size=noisy["papillarray"][unseen].shape)
    changed = type(test)(**{**test.__dict__, "values": noisy})
    cross_sensor_geometry(run, changed, member=0, split_seed=5, config=config, ceiling=False)
    heads = [
        (m, a, b) for m in geometry_heads.METHODS for a in run.sensors for b in run.sensors if a != b or m == "paper"
    ]
    for k, (_, a, _) in enumerate(heads):
        if a == "uskin":  # trained on uSkin frames: the PapillArray's unseen frames must not reach it
            np.testing.assert_array_equal(fitted[0][k], fitted[1][k])
    assert set(first["methods"]) == set(geometry_heads.METHODS)
    assert set(first["methods"]["translated"]["cross"]) == {"uskin_to_papillarray", "papillarray_to_uskin"}
    assert first["no_latent_mm"] > 0


def test_the_ceiling_has_the_same_recipe_and_training_rays_as_every_other_head(run_dir: Path) -> None:
    """Issue 38: the ceiling was tuned apart (10x the learning rate, up to 1.5x the epochs, chosen dropout, 10 % of
    the rays held out): it measured its recipe. Now every head has the paper's recipe and the methods' rays."""
    run, test = load_run(run_dir), load_test_set(run_dir)
    config = GeometryConfig(epochs=10)
    result = cross_sensor_geometry(run, test, member=0, split_seed=2, config=config)
    ceiling = result["ceiling"]
    assert set(ceiling) == {"latent_uskin", "latent_papillarray", "raw_uskin", "raw_papillarray"}
    for key, entry in ceiling.items():
        sensor = key.split("_", 1)[1]
        assert (entry["learning_rate"], entry["epochs"]) == (config.learning_rate, config.epochs)
        assert entry["dropout"] == config.dropout_for(sensor)
        assert entry["contacts_train"] == result["contacts"]["train"] and entry["contacts_val"] == 0
        assert np.isfinite(entry["test_mm"])


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
