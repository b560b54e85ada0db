"""A run's checkpoint holds only tensors and plain Python values, and runs saved before the autograd engine (one flat
parameter vector, numpy arrays) still load and resume."""

from __future__ import annotations

from pathlib import Path

import pytest
import torch

from tests.learning.learning_helpers import small_sets
from unitac_rig.learning.data import PairedDataset, build_paired_dataset
from unitac_rig.learning.run import checkpoint_path, load_checkpoint, safe_torch_load, save_checkpoint
from unitac_rig.learning.train import TrainConfig, load_run, train

TINY = TrainConfig(epochs=2, seeds=(0, 1), tsne_contacts=30, checkpoint_every=1)


@pytest.fixture(scope="module")
def pairs() -> PairedDataset:
    return build_paired_dataset(small_sets())


def test_checkpoint_loads_with_weights_only(pairs: PairedDataset, tmp_path: Path) -> None:
    train(pairs, tmp_path / "run", TINY, device="cpu")
    payload = torch.load(checkpoint_path(tmp_path / "run"), weights_only=True)
    assert payload["epoch"] == 2
    assert {"layers.unitac/dec/2.weight", "layers.ae_uskin/dec/2.bias"} <= set(payload["engine"]["state_dict"])


def test_a_version_1_checkpoint_loads_and_resumes(pairs: PairedDataset, tmp_path: Path) -> None:
    run_dir = tmp_path / "run"
    train(pairs, run_dir, TINY, device="cpu")
    current = load_run(run_dir)
    payload = load_checkpoint(run_dir)
    # rewrite it as version 1 stored it: flat parameters and Adam moments, numpy dropout streams and arrays
    engine = current.engine
    moments = payload["optimizer"]["state"]
    flat_moments = {
        name: torch.cat([moments[i][name].reshape(-1) for i in range(len(moments))])
        for name in ("exp_avg", "exp_avg_sq")
    }
    flat_state = {
        "state": {0: {**flat_moments, "step": moments[0]["step"]}},
        "param_groups": [dict(payload["optimizer"]["param_groups"][0], params=[0])],
    }
    converted = engine.optimizer_state_from_flat(flat_state)["state"]
    assert all(torch.equal(converted[i]["exp_avg_sq"], moments[i]["exp_avg_sq"]) for i in range(len(moments)))
    old_engine = {k: v for k, v in payload["engine"].items() if k != "state_dict"}
    old_engine["theta"] = engine.theta
    old_engine["dropout_rng"] = [{"bit_generator": "PCG64", "state": {"state": 1, "inc": 1}}] * 2
    payload.update(
        engine=old_engine,
        optimizer=flat_state,
        test_mask=payload["test_mask"].numpy(),
        tsne_rows=payload["tsne_rows"].numpy(),
        latents_first_epoch={s: z.numpy() for s, z in payload["latents_first_epoch"].items()},
    )
    del payload["format"], payload["version"]
    save_checkpoint(run_dir, payload)
    raw = safe_torch_load(checkpoint_path(run_dir), what="checkpoint")  # numpy arrays: allowed, nothing else
    raw["version"] = 1
    torch.save(raw, checkpoint_path(run_dir))

    old = load_run(run_dir)
    assert torch.equal(old.engine.theta, engine.theta)
    assert old.payload["tsne_rows"].tolist() == current.payload["tsne_rows"].tolist()
    resumed = train(pairs, run_dir, resume=True, epochs=3, device="cpu")
    assert [h["epoch"] for h in resumed.history] == [1, 2, 3]
    assert not torch.equal(resumed.engine.theta, engine.theta)  # it trained on from the stored state
