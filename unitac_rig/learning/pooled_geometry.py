"""Beyond the paper: a contact-geometry head trained on *both* sensors' latents.

The paper trains the profile MLP on one sensor's latents and applies it to the other's (Section IV); its
cross-sensor error (0.637 / 0.666 mm) is what is left of the latents' misalignment. Here one MLP of the paper's
architecture and training (:class:`unitac_rig.learning.contact_geometry.GeometryConfig`) is trained on the training
contacts' latents of every sensor at once (each contact once per sensor, the same profile target), then tested on
each sensor's latents of the held-out contacts. Same split, same targets and same epochs as the paper's heads, so
the errors are comparable; it costs one MLP trained on N times the rows instead of N MLPs.
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np
import torch

from unitac_rig.errors import DataError
from unitac_rig.learning.contact_geometry import GeometryConfig, contact_profiles, fit_profile_mlps
from unitac_rig.learning.data import PairedDataset, held_out_directions
from unitac_rig.learning.engine import UNITAC_GROUP
from unitac_rig.learning.train import LoadedRun

POOLED = "pooled"


def pooled_geometry(
    run: LoadedRun,
    test_set: PairedDataset,
    object_id: str | None = None,
    *,
    member: int = 0,
    config: GeometryConfig | None = None,
) -> dict[str, Any]:
    """``{"scenarios": {"pooled_to_<sensor>": {"mae_mm", "per_point_mae_mm"}}, "seconds": ...}`` for one member,
    split and seeded exactly as :func:`unitac_rig.learning.contact_geometry.run_geometry` does it. The dropout is
    the mean of the sensors' paper values (0.25 for uSkin and PapillArray)."""
    config = config or GeometryConfig()
    if object_id is None:
        unseen = [o for o in run.unseen_objects if o in set(test_set.object_id.tolist())]
        if not unseen:
            raise DataError("the run's test data holds no unseen object to estimate geometry on")
        object_id = unseen[0]
    rows = np.flatnonzero(test_set.object_id == object_id)
    if rows.size == 0:
        raise DataError(f"no test contacts of object {object_id!r} in this run")
    seed = run.engine.seeds[member]
    subset, truth, valid, directions = contact_profiles(test_set, rows, object_id, config)
    held = set(held_out_directions(directions, object_id, seed, config.test_fraction))
    in_held = np.array([d in held for d in directions])
    is_test, is_train = in_held & valid, ~in_held & valid
    engine = run.engine.member(member, groups=[UNITAC_GROUP])
    latents = {
        s: engine.encode(UNITAC_GROUP, s, torch.from_numpy(run.normaliser.normalise(s, subset.values[s])))[0].numpy()
        for s in run.sensors
    }
    began = time.perf_counter()
    previous_threads = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        model = fit_profile_mlps(
            [np.concatenate([latents[s][is_train] for s in run.sensors])],
            np.concatenate([truth[is_train]] * len(run.sensors)),
            config,
            [float(np.mean([config.dropout_for(s) for s in run.sensors]))],
            seed,
        )
    finally:
        torch.set_num_threads(previous_threads)
    seconds = time.perf_counter() - began
    scenarios = {}
    for sensor in run.sensors:
        with torch.no_grad():
            predicted = model(torch.from_numpy(latents[sensor][is_test][None]))[0].numpy()
        errors = np.abs(predicted - truth[is_test])
        scenarios[f"{POOLED}_to_{sensor}"] = {
            "train_sensor": POOLED,
            "test_sensor": sensor,
            "mae_mm": float(errors.mean()),
            "per_point_mae_mm": errors.mean(axis=0).tolist(),
        }
    return {"object": object_id, "member": member, "seed": seed, "scenarios": scenarios, "seconds": seconds}
