"""Contact-geometry heads beyond the paper's: strict cross-sensor transfer, the ceiling beside it, what a 16-d latent
allows to close the gap, and a head pooled over both sensors.

"Cross-sensor" here means what the paper's Section IV means: the profile head is trained on sensor A's latents of the
unseen object's training rays and tested on sensor B's latents of its held-out rays; sensor B's frames of the unseen
object are never used in training (the seen objects' paired frames, the autoencoder's own training data, may be).
Every head has the paper's architecture (:class:`unitac_rig.learning.contact_geometry.GeometryConfig`); they differ
only in what they are fed:

* ``paper``: A's latents; tested on B's latents.
* ``translated``: A's frames encoded, decoded to B's frame by the shared decoder, encoded by B's encoder
  (``enc_B(dec_B(enc_A(x_A)))``): A's contacts as B's encoder would see them; tested on B's latents.
* ``linear_map``: A's latents mapped by a ridge regression ``z_A -> z_B`` fitted on seen-object pairs; tested on B's.
* ``cca``: both sensors' latents projected on the canonical directions of a CCA fitted on seen-object pairs
  (whitened, so matched contacts share coordinates); trained on A's projection, tested on B's.

Beside them, on the same split and test rays: the same-sensor heads (A's latents, tested on A's), the no-latent
baseline (the training rays' mean profile, whatever the contact) and the ceiling: per-sensor heads on the sensor's
own latents and on its raw (normalised) frames. Every head, the ceiling's included, has one recipe (the paper's
learning rate, epochs and per-sensor dropout, :class:`GeometryConfig`) and the same training rays (issue 38: a
ceiling tuned apart measured its recipe, not its input). Costs are process CPU seconds of each head's fit (heads
fitted together are charged equal shares) plus its method's own preparation (the CCA or ridge fit, the translation).

And a head the paper lacks (:func:`pooled_geometry`): one MLP of the paper's architecture and training trained on
the training contacts' latents of every sensor at once (each contact once per sensor, the same profile target), then
tested on each sensor's latents of the held-out contacts. It has seen the test sensor's latents of the unseen
object in training, so its errors answer "one head that serves every sensor a lab has geometry labels for" and
compare with the *same-sensor* heads, never with the cross-sensor transfer above. Same split, targets and epochs as
the paper's heads.
"""

from __future__ import annotations

import itertools
import time
from collections.abc import Sequence
from typing import Any

import numpy as np
import torch

from unitac_rig.learning.contact_geometry import (
    GeometryConfig,
    OutlineGeometry,
    StackedProfileMLP,
    contact_profiles,
    fit_single_thread,
    geometry_object,
    geometry_split,
    member_latents,
)
from unitac_rig.learning.data import PairedDataset
from unitac_rig.learning.engine import UNITAC_GROUP
from unitac_rig.learning.train import LoadedRun

METHODS = ("paper", "translated", "linear_map", "cca")
RIDGE = 1e-3  # ridge / CCA regulariser, relative to the latents' mean variance
SEEN_PAIRS_MAX = 4000  # seen-object pairs the linear map and the CCA are fitted on (a seeded subsample)


def cca_projections(za: np.ndarray, zb: np.ndarray, ridge: float = RIDGE) -> tuple[Any, Any]:
    """Two functions mapping A's and B's latents (M, d) onto the shared canonical coordinates (M, d) of a
    regularised CCA of the pairs ``(za[i], zb[i])``: whitened, so that a matched pair lands on equal coordinates
    where the two sensors are linearly related."""
    mean_a, mean_b = za.mean(axis=0), zb.mean(axis=0)
    a, b = za - mean_a, zb - mean_b
    n = len(a)
    scale_a, scale_b = ridge * np.trace(a.T @ a) / n / a.shape[1], ridge * np.trace(b.T @ b) / n / b.shape[1]
    caa = a.T @ a / n + scale_a * np.eye(a.shape[1])
    cbb = b.T @ b / n + scale_b * np.eye(b.shape[1])
    cab = a.T @ b / n
    wa, wb = _inverse_sqrt(caa), _inverse_sqrt(cbb)
    u, _, vt = np.linalg.svd(wa @ cab @ wb)
    pa, pb = wa @ u, wb @ vt.T
    return (lambda z: ((z - mean_a) @ pa).astype(np.float32)), (lambda z: ((z - mean_b) @ pb).astype(np.float32))


def _inverse_sqrt(c: np.ndarray) -> np.ndarray:
    values, vectors = np.linalg.eigh(c)
    return vectors @ np.diag(1.0 / np.sqrt(np.maximum(values, 1e-12))) @ vectors.T


def ridge_map(za: np.ndarray, zb: np.ndarray, ridge: float = RIDGE) -> Any:
    """``z_A -> z_B`` by ridge regression (with intercept) on the pairs: a linear translator between latent sets."""
    mean_a, mean_b = za.mean(axis=0), zb.mean(axis=0)
    a, b = za - mean_a, zb - mean_b
    lam = ridge * np.trace(a.T @ a) / a.shape[1]
    w = np.linalg.solve(a.T @ a + lam * np.eye(a.shape[1]), a.T @ b)
    return lambda z: ((z - mean_a) @ w + mean_b).astype(np.float32)


def translated_latents(run: LoadedRun, member: int, frames: np.ndarray, source: str, target: str) -> np.ndarray:
    """``enc_target(dec_target(enc_source(frames)))`` (M, latent): the source's contacts as the target's encoder
    sees them, through the shared decoder (normalised frames throughout)."""
    engine = run.engine.member(member, groups=[UNITAC_GROUP])
    z = engine.encode(UNITAC_GROUP, source, torch.from_numpy(run.normaliser.normalise(source, frames)))
    decoded = engine.decode(UNITAC_GROUP, z)[target]
    return engine.encode(UNITAC_GROUP, target, decoded)[0].numpy()


def _predict(model: StackedProfileMLP, inputs: Sequence[np.ndarray] | np.ndarray) -> np.ndarray:
    """(members, M, inputs) -> (members, M, points) with each member's head."""
    with torch.no_grad():
        stacked = inputs if isinstance(inputs, np.ndarray) else np.stack(list(inputs))
        return model(torch.from_numpy(stacked.astype(np.float32))).numpy()


def _mae(predicted: np.ndarray, truth: np.ndarray) -> float:
    return float(np.abs(predicted - truth).mean())


def _seen_pairs(run: LoadedRun, member: int, seen: PairedDataset, seed: int) -> dict[str, np.ndarray]:
    """One member's latents of (a seeded subsample of) the seen-object pairs every sensor has."""
    rows = np.flatnonzero(seen.complete_rows() & ~np.isin(seen.object_id, list(run.unseen_objects)))
    if len(rows) > SEEN_PAIRS_MAX:
        rows = np.sort(np.random.default_rng([seed, 29]).choice(rows, SEEN_PAIRS_MAX, replace=False))
    subset = seen.subset(rows)
    return member_latents(run, member, {s: subset.values[s] for s in run.sensors})


def cross_sensor_geometry(
    run: LoadedRun,
    test_set: PairedDataset,
    *,
    member: int,
    split_seed: int,
    seen: PairedDataset | None = None,
    config: GeometryConfig | None = None,
    ceiling: bool = True,
    object_id: str | None = None,
) -> dict[str, Any]:
    """Every cross-sensor method, the same-sensor heads, the no-latent baseline and (with ``ceiling``) the
    per-sensor ceiling, for one member on one geometry split (``split_seed``). Every head, the ceiling's included,
    has one recipe (``config``: the paper's) and trains on the split's training rays (the paper's heads among them:
        the same heads as :func:`run_geometry` on that split); the test rays are the same for all. ``seen``: paired
    frames of the seen objects for the linear map and
    the CCA (default: the seen objects' test contacts in ``test_set``). Returns JSON-ready numbers (mm, seconds)."""
    config = config or GeometryConfig()
    object_id, rows = geometry_object(run, test_set, object_id)
    outline = OutlineGeometry.from_catalogue(object_id)
    subset, truth, valid, _ = contact_profiles(test_set, rows, object_id, config, outline)
    split = geometry_split(subset, valid, object_id, split_seed, config, outline)
    sensors = run.sensors
    seed = run.engine.seeds[member]
    latents = member_latents(run, member, subset.values)
    pairs = _seen_pairs(run, member, seen if seen is not None else test_set, seed)
    inputs, prep = _method_inputs(run, member, subset, latents, pairs, sensors)
    train, test = split.train, split.test
    heads = [(m, a, b) for m in METHODS for a in sensors for b in sensors if a != b or m == "paper"]
    began = time.process_time()
    model = fit_single_thread(
        [inputs[(m, a, b)][0][train] for m, a, b in heads],
        truth[train],
        config,
        [config.dropout_for(a) for _, a, _ in heads],
        seed,
    )
    share = (time.process_time() - began) / len(heads)
    predicted = _predict(model, [inputs[(m, a, b)][1][test] for m, a, b in heads])
    methods: dict[str, Any] = {m: {"cross": {}, "same": {}, "seconds": share + prep.get(m, 0.0)} for m in METHODS}
    for k, (m, a, b) in enumerate(heads):
        methods[m]["same" if a == b else "cross"][f"{a}_to_{b}"] = _mae(predicted[k], truth[test])
    result: dict[str, Any] = {
        "object": object_id,
        "member": member,
        "model_seed": seed,
        "split_seed": split_seed,
        "split_mode": config.split_mode,
        "contacts": {"train": int(train.sum()), "val": int(split.val.sum()), "test": int(test.sum())},
        "no_latent_mm": _mae(np.broadcast_to(truth[train].mean(axis=0), truth[test].shape), truth[test]),
        "methods": methods,
    }
    if ceiling:
        result["ceiling"] = _ceiling(run, subset, latents, truth, split, config, seed)
    return result


def _method_inputs(
    run: LoadedRun,
    member: int,
    subset: PairedDataset,
    latents: dict[str, np.ndarray],
    pairs: dict[str, np.ndarray],
    sensors: Sequence[str],
) -> tuple[dict[tuple[str, str, str], tuple[np.ndarray, np.ndarray]], dict[str, float]]:
    """(method, train sensor, test sensor) -> (training inputs from the train sensor's frames, test inputs from the
    test sensor's frames), both over all of the object's contacts; and each method's preparation CPU seconds."""
    out: dict[tuple[str, str, str], tuple[np.ndarray, np.ndarray]] = {
        ("paper", a, a): (latents[a], latents[a]) for a in sensors
    }
    prep = dict.fromkeys(("translated", "linear_map", "cca"), 0.0)
    for a, b in itertools.permutations(sensors, 2):
        out[("paper", a, b)] = (latents[a], latents[b])
        clock = time.process_time()
        out[("translated", a, b)] = (translated_latents(run, member, subset.values[a], a, b), latents[b])
        prep["translated"] += time.process_time() - clock
        clock = time.process_time()
        out[("linear_map", a, b)] = (ridge_map(pairs[a], pairs[b])(latents[a]), latents[b])
        prep["linear_map"] += time.process_time() - clock
        clock = time.process_time()
        project_a, project_b = cca_projections(pairs[a], pairs[b])
        out[("cca", a, b)] = (project_a(latents[a]), project_b(latents[b]))
        prep["cca"] += time.process_time() - clock
    return out, prep


def _ceiling(
    run: LoadedRun,
    subset: PairedDataset,
    latents: dict[str, np.ndarray],
    truth: np.ndarray,
    split: Any,
    config: GeometryConfig,
    seed: int,
) -> dict[str, Any]:
    """Per sensor, a same-sensor head on its latents and one on its raw (normalised) frames, trained with the one
    recipe every head here has (``config``: the paper's learning rate, epochs and the sensor's dropout) on the same
    training rays as the methods, scored on the same test rays. All heads train in one stacked fit, inputs
    zero-padded to the widest (a zero input feeds nothing forward and gets no gradient)."""
    inputs = {f"latent_{s}": latents[s] for s in run.sensors}
    inputs |= {f"raw_{s}": run.normaliser.normalise(s, subset.values[s]) for s in run.sensors}
    width = max(x.shape[1] for x in inputs.values())
    padded = {k: np.pad(x, ((0, 0), (0, width - x.shape[1]))).astype(np.float32) for k, x in inputs.items()}
    keys = list(padded)
    dropouts = [config.dropout_for(k.split("_", 1)[1]) for k in keys]
    began = time.process_time()
    model = fit_single_thread([padded[k][split.train] for k in keys], truth[split.train], config, dropouts, seed)
    seconds = (time.process_time() - began) / len(keys)
    predicted = _predict(model, np.stack([padded[k][split.test] for k in keys]))
    return {
        key: {
            "test_mm": _mae(predicted[h], truth[split.test]),
            "learning_rate": config.learning_rate,
            "dropout": dropouts[h],
            "epochs": config.epochs,
            "seconds": seconds,
            "contacts_train": int(split.train.sum()),
            "contacts_val": 0,
        }
        for h, key in enumerate(keys)
    }


POOLED = "pooled"


def pooled_geometry(
    run: LoadedRun,
    test_set: PairedDataset,
    object_id: str | None = None,
    *,
    member: int = 0,
    config: GeometryConfig | None = None,
    split_seed: int | None = None,
) -> dict[str, Any]:
    """``{"scenarios": {"pooled_to_<sensor>": {"mae_mm", "per_point_mae_mm"}}, "seconds": ...}`` for one member,
    split as :func:`unitac_rig.learning.contact_geometry.run_geometry` splits it for the same ``split_seed``
    (default: the member's model seed). The dropout is the mean of the sensors' paper values (0.25)."""
    config = config or GeometryConfig()
    object_id, rows = geometry_object(run, test_set, object_id)
    seed = run.engine.seeds[member]
    outline = OutlineGeometry.from_catalogue(object_id)
    subset, truth, valid, _ = contact_profiles(test_set, rows, object_id, config, outline)
    split = geometry_split(subset, valid, object_id, seed if split_seed is None else split_seed, config, outline)
    latents = member_latents(run, member, subset.values)
    began = time.perf_counter()
    model = fit_single_thread(
        [np.concatenate([latents[s][split.train] for s in run.sensors])],
        np.concatenate([truth[split.train]] * len(run.sensors)),
        config,
        [float(np.mean([config.dropout_for(s) for s in run.sensors]))],
        seed,
    )
    seconds = time.perf_counter() - began
    scenarios = {}
    for sensor in run.sensors:
        with torch.no_grad():
            predicted = model(torch.from_numpy(latents[sensor][split.test][None]))[0].numpy()
        errors = np.abs(predicted - truth[split.test])
        scenarios[f"{POOLED}_to_{sensor}"] = {
            "train_sensor": POOLED,
            "test_sensor": sensor,
            "mae_mm": float(errors.mean()),
            "per_point_mae_mm": errors.mean(axis=0).tolist(),
            "same_sensor": True,
        }
    return {"object": object_id, "member": member, "seed": seed, "scenarios": scenarios, "seconds": seconds}
