"""The simple baselines Table I sets beside UniTac-NV (issue 38): what a model no bigger than the scene needs would do
on the same split, from the same training rows and scored by the same metrics.

* ``pca_<sensor>``: per-sensor PCA with k = the latent size, each test frame reconstructed from its own k
  components (the autoencoding columns' baseline: ``ae_<sensor>`` and ``<sensor>_to_<sensor>``);
* ``ridge_<src>_to_<dst>``: a frame-level linear map (with intercept) from one sensor's frame to the other's, the
  ridge alpha chosen by 5-fold cross-validation over the training rows' press directions (a direction's forces stay
  in one fold), never on validation or test rows;
* ``nn_<src>_to_<dst>``: 1-nearest-neighbour lookup: the training contact whose source frame is nearest
  (Euclidean, in the run's normalised units) gives its paired target frame.

All fit in the run's normalised space (:class:`unitac_rig.learning.data.Normaliser`) on the training rows only (the
complete ones: a pair needs both frames) and predict frames in sensor units. They are deterministic: one value per
split, paired with every model seed of that split in the comparisons.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
import torch

from unitac_rig.errors import DataError
from unitac_rig.learning.data import Normaliser, PairedDataset

RIDGE_ALPHAS: tuple[float, ...] = tuple(10.0**e for e in range(-4, 5))  # in normalised units, summed over rows
RIDGE_FOLDS = 5
NN_CHUNK = 2048  # test rows per distance block (2048 x 40k floats: 330 MB at most in float32)

DEFINITIONS: dict[str, str] = {
    "pca": "per-sensor PCA with k = the latent size, fitted on the training rows; each test frame reconstructed "
    "from its own k components",
    "ridge": "frame-level ridge map between sensors (with intercept); alpha chosen by 5-fold cross-validation over "
    "the training rows' press directions",
    "nn": "1-nearest-neighbour lookup: the training contact nearest in the source sensor's normalised frame space "
    "gives its paired target frame",
}


def baseline_columns(sensors: tuple[str, ...]) -> dict[str, str]:
    """{simple baseline column: the UniTac-NV column it is compared with}, in a fixed order: for each sensor its PCA
    against the same-sensor direction, then for each ordered pair the ridge map and the lookup against the
    cross-sensor direction. (The PCA also stands beside the per-sensor autoencoder ``ae_<sensor>``.)"""
    out = {f"pca_{s}": f"{s}_to_{s}" for s in sensors}
    for source in sensors:
        for target in sensors:
            if source != target:
                out[f"ridge_{source}_to_{target}"] = f"{source}_to_{target}"
                out[f"nn_{source}_to_{target}"] = f"{source}_to_{target}"
    return out


@dataclass
class SimplePredictions:
    """Each simple baseline's test frames: {column: (target sensor, (M, n_taxels, 3) sensor units)}, with what
    was chosen on the training rows (ridge alpha) and how many rows it was fitted on."""

    frames: dict[str, tuple[str, np.ndarray]]
    train_rows: int
    latent_dim: int
    ridge_alpha: dict[str, float] = field(default_factory=dict)

    def info(self) -> dict[str, Any]:
        return {
            "train_rows": self.train_rows,
            "pca_components": self.latent_dim,
            "ridge_alpha": self.ridge_alpha,
            "definition": DEFINITIONS,
        }


def predict_simple_baselines(
    train: PairedDataset, test: PairedDataset, normaliser: Normaliser, latent_dim: int
) -> SimplePredictions:
    """Fit every simple baseline on ``train`` (its complete rows) and predict ``test``'s frames."""
    train = train.subset(train.complete_rows())
    if len(train) < 2:
        raise DataError("the simple baselines need at least two complete training contacts")
    x = {s: normaliser.normalise(s, train.values[s]).astype(np.float64) for s in train.sensors}
    q = {s: normaliser.normalise(s, test.values[s]).astype(np.float64) for s in test.sensors}
    frames: dict[str, tuple[str, np.ndarray]] = {}
    alphas: dict[str, float] = {}
    groups = _direction_groups(train)
    for column, _ in baseline_columns(tuple(test.sensors)).items():
        kind, _, rest = column.partition("_")
        if kind == "pca":
            flat = pca_reconstruct(x[rest], q[rest], latent_dim)
            frames[column] = (rest, normaliser.denormalise(rest, flat))
            continue
        source, _, target = rest.partition("_to_")
        if kind == "ridge":
            alpha = choose_ridge_alpha(x[source], x[target], groups)
            alphas[column] = alpha
            flat = ridge_fit(x[source], x[target], alpha).predict(q[source])
        else:
            flat = x[target][nearest_rows(x[source], q[source])]
        frames[column] = (target, normaliser.denormalise(target, flat))
    return SimplePredictions(frames, len(train), latent_dim, alphas)


def pca_reconstruct(train: np.ndarray, query: np.ndarray, k: int) -> np.ndarray:
    """``query`` (M, F) projected on the first ``k`` principal components of ``train`` (N, F) and back."""
    mean = train.mean(axis=0)
    _, _, vt = np.linalg.svd(train - mean, full_matrices=False)
    basis = vt[: min(k, vt.shape[0])]
    return mean + (query - mean) @ basis.T @ basis


@dataclass(frozen=True)
class RidgeMap:
    """``y = (x - x_mean) @ weights + y_mean``."""

    x_mean: np.ndarray
    y_mean: np.ndarray
    weights: np.ndarray

    def predict(self, x: np.ndarray) -> np.ndarray:
        return (x - self.x_mean) @ self.weights + self.y_mean


def ridge_fit(x: np.ndarray, y: np.ndarray, alpha: float) -> RidgeMap:
    """Ridge regression with an unpenalised intercept: min ||Xc W - Yc||^2 + alpha ||W||^2."""
    x_mean, y_mean = x.mean(axis=0), y.mean(axis=0)
    xc, yc = x - x_mean, y - y_mean
    gram = xc.T @ xc + alpha * np.eye(x.shape[1])
    return RidgeMap(x_mean, y_mean, np.linalg.solve(gram, xc.T @ yc))


def choose_ridge_alpha(
    x: np.ndarray, y: np.ndarray, groups: np.ndarray, alphas: tuple[float, ...] = RIDGE_ALPHAS
) -> float:
    """The alpha of ``alphas`` with the lowest mean absolute error over ``RIDGE_FOLDS`` folds of ``groups`` (press
    directions: all forces of one press in one fold, so a fold does not score on near-copies of its training rows).
    Ties (and fewer than two groups) keep the smallest alpha."""
    unique = np.unique(groups)
    if unique.size < 2:
        return float(alphas[0])
    fold_of = {g: i % RIDGE_FOLDS for i, g in enumerate(np.random.default_rng(0).permutation(unique))}
    fold = np.array([fold_of[g] for g in groups])
    errors = []
    for alpha in alphas:
        total = 0.0
        for k in np.unique(fold):
            held = fold == k
            total += float(np.abs(ridge_fit(x[~held], y[~held], alpha).predict(x[held]) - y[held]).sum())
        errors.append(total)
    return float(alphas[int(np.argmin(errors))])


def nearest_rows(train: np.ndarray, query: np.ndarray) -> np.ndarray:
    """For each query row, the index of the nearest ``train`` row (Euclidean; the first on ties)."""
    reference = torch.from_numpy(np.ascontiguousarray(train))
    out = np.empty(len(query), dtype=np.int64)
    for start in range(0, len(query), NN_CHUNK):
        block = torch.from_numpy(np.ascontiguousarray(query[start : start + NN_CHUNK]))
        out[start : start + len(block)] = torch.cdist(block, reference).argmin(dim=1).numpy()
    return out


def _direction_groups(rows: PairedDataset) -> np.ndarray:
    """One label per row: its press direction (object, rotation, angle)."""
    keys = [
        f"{o}|{round(float(r))}|{round(float(a))}"
        for o, r, a in zip(rows.object_id.tolist(), rows.rotation_deg.tolist(), rows.angle_deg.tolist(), strict=True)
    ]
    return np.asarray(keys)
