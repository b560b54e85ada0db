"""Beyond the paper: a contact-geometry head trained on *both* sensors' latents, a same-sensor option.

The paper trains the profile MLP on one sensor's latents and applies it to the other's (Section IV). Here one MLP of
the paper's architecture and training (:class:`unitac_rig.learning.contact_geometry.GeometryConfig`) is trained on
the training contacts' latents of every sensor at once (each contact once per sensor, the same profile target), then
tested on each sensor's latents of the held-out contacts. It has seen the test sensor's latents of the unseen object
in training, so its errors answer "one head that serves every sensor a lab has geometry labels for" and compare with
the *same-sensor* heads, never with the paper's cross-sensor transfer (that is
:mod:`lab.cross_geometry`). Same split, targets and epochs as the paper's heads.
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np
import torch

from unitac_rig.learning.contact_geometry import (
    GeometryConfig,
    OutlineGeometry,
    contact_profiles,
    fit_single_thread,
    geometry_object,
    geometry_split,
    member_latents,
)
from unitac_rig.learning.data import PairedDataset
from unitac_rig.learning.train import LoadedRun

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
