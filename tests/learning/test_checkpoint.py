"""A run's checkpoint holds only tensors and plain Python values, in one format: a checkpoint of any other version is
refused in one line that says what to do (unreleased versions owe no readers)."""

from __future__ import annotations

from pathlib import Path

import pytest
import torch

from tests.learning.learning_helpers import small_sets
from unitac_rig.errors import ModelError
from unitac_rig.learning.data import PairedDataset, build_paired_dataset
from unitac_rig.learning.run import CHECKPOINT_VERSION, checkpoint_path, load_checkpoint
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


def test_a_checkpoint_of_another_version_is_refused_in_one_line(pairs: PairedDataset, tmp_path: Path) -> None:
    run_dir = tmp_path / "run"
    train(pairs, run_dir, TINY, device="cpu")
    payload = load_checkpoint(run_dir)
    for version, hint in ((2, "retrain"), (CHECKPOINT_VERSION + 1, "upgrade unitac-rig")):
        torch.save({**payload, "version": version}, checkpoint_path(run_dir))
        for opening in (lambda: load_run(run_dir), lambda: train(pairs, run_dir, resume=True, epochs=3, device="cpu")):
            with pytest.raises(ModelError) as caught:
                opening()
            line = caught.value.one_line()
            assert f"checkpoint of version {version}; this unitac-rig reads version 3 only" in line, line
            assert hint in line and "\n" not in line
