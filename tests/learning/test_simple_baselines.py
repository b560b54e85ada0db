"""The simple baselines of Table I (issue 38), each on a case worked by hand: a ridge map recovers an exact linear
map, PCA with k = the full rank reconstructs exactly, 1-NN returns the paired frame of an identical source; and a
run's metrics.json carries them, fitted on its own training rows."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from tests.learning.learning_helpers import small_sets
from unitac_rig.learning.data import Normaliser, PairedDataset, build_paired_dataset
from unitac_rig.learning.simple_baselines import (
    RIDGE_ALPHAS,
    baseline_columns,
    choose_ridge_alpha,
    nearest_rows,
    pca_reconstruct,
    predict_simple_baselines,
    ridge_fit,
)


def test_ridge_recovers_an_exact_linear_map() -> None:
    rng = np.random.default_rng(0)
    x = rng.normal(size=(300, 6))
    a, b = rng.normal(size=(6, 4)), rng.normal(size=4)
    y = x @ a + b
    groups = np.repeat(np.arange(60), 5)
    alpha = choose_ridge_alpha(x, y, groups)
    assert alpha == RIDGE_ALPHAS[0]  # no noise: the least shrinkage fits best
    fitted = ridge_fit(x, y, alpha)
    assert np.allclose(fitted.weights, a, atol=1e-4)
    assert np.allclose(fitted.predict(x[:7] + 1.0), (x[:7] + 1.0) @ a + b, atol=1e-3)


def test_ridge_shrinks_all_the_way_when_the_target_is_noise() -> None:
    rng = np.random.default_rng(1)
    x, y = rng.normal(size=(200, 8)), rng.normal(size=(200, 3))
    assert choose_ridge_alpha(x, y, np.repeat(np.arange(40), 5)) >= 100.0  # heavy shrinkage, not the least


def test_pca_with_the_full_rank_reconstructs_exactly_and_fewer_components_do_not() -> None:
    rng = np.random.default_rng(2)
    train, query = rng.normal(size=(50, 5)), rng.normal(size=(9, 5))
    assert np.allclose(pca_reconstruct(train, query, 5), query)
    assert not np.allclose(pca_reconstruct(train, query, 2), query, atol=1e-2)
    # data on a 2-d affine plane: two components are enough
    plane = rng.normal(size=(40, 2)) @ rng.normal(size=(2, 5)) + 3.0
    assert np.allclose(pca_reconstruct(plane, plane[:4], 2), plane[:4])


def test_nearest_neighbour_finds_the_identical_source() -> None:
    rng = np.random.default_rng(3)
    train = rng.normal(size=(100, 4))
    picks = np.array([17, 3, 99, 0])
    assert nearest_rows(train, train[picks]).tolist() == picks.tolist()
    assert nearest_rows(train, train[picks] + 1e-6).tolist() == picks.tolist()


@pytest.fixture(scope="module")
def pairs() -> PairedDataset:
    return build_paired_dataset(small_sets())


def test_the_lookup_returns_the_paired_frame_and_full_rank_pca_the_frame_itself(pairs: PairedDataset) -> None:
    normaliser = Normaliser.fit(pairs, np.ones(len(pairs), dtype=bool), "sensor_scale")
    query = pairs.subset(np.arange(len(pairs)) % 7 == 0)  # contacts the baselines also trained on
    predicted = predict_simple_baselines(pairs, query, normaliser, latent_dim=pairs.n_taxels("uskin") * 3)
    assert set(predicted.frames) == set(baseline_columns(pairs.sensors))
    target, frames = predicted.frames["nn_papillarray_to_uskin"]
    assert target == "uskin" and np.allclose(frames, query.values["uskin"], atol=1e-3)
    assert np.allclose(predicted.frames["pca_uskin"][1], query.values["uskin"], rtol=1e-4, atol=1e-2)
    assert set(predicted.ridge_alpha) == {"ridge_uskin_to_papillarray", "ridge_papillarray_to_uskin"}


def test_a_runs_metrics_carry_the_simple_baselines_fitted_on_its_training_rows(
    pairs: PairedDataset, tmp_path: Path
) -> None:
    from unitac_rig.learning.evaluate import run_metrics
    from unitac_rig.learning.run import load_training_pairs
    from unitac_rig.learning.train import TrainConfig, train

    outcome = train(pairs, tmp_path / "run", TrainConfig(epochs=1, seeds=(0,), tsne_contacts=30), device="cpu")
    kept = load_training_pairs(tmp_path / "run")
    assert kept is not None and len(kept) == int((outcome.split.train_mask & pairs.complete_rows()).sum())
    metrics = run_metrics(tmp_path / "run")
    simple = metrics["simple_baselines"]
    assert simple["train_rows"] == len(kept) and simple["pca_components"] == 16
    assert set(simple["table1"]) == set(metrics["table1"])  # the same rows as UniTac-NV's
    cell = simple["table1"]["all_seen"]["ridge_papillarray_to_uskin"]
    assert 0.0 < cell["nmae"] < 1.0 and -1.0 <= cell["ssim"] <= 1.0
    assert simple["compared_with"]["nn_uskin_to_papillarray"] == "uskin_to_papillarray"
