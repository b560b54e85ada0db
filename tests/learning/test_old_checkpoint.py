"""A run written before the model became one ``nn.Module`` (checkpoint version 2: one ``{"weight", "bias"}`` entry per
layer and the dropout streams beside them) still loads, predicts bit for bit what it predicted when it was written,
continues its dropout streams and resumes training.

The fixture ``fixtures/v2_run`` was written by commit 6641b69's code (its README says how): a two-seed run
with the baselines and a tiny shape, trained 2 epochs on ``small_sets()``, and what that code's model computed for
fixed inputs (latents, reconstructions, the next dropout masks)."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest
import torch

from tests.learning.learning_helpers import small_sets
from unitac_rig.learning.data import build_paired_dataset
from unitac_rig.learning.run import checkpoint_path, load_checkpoint
from unitac_rig.learning.train import load_run, train

FIXTURE = Path(__file__).parent / "fixtures" / "v2_run"


@pytest.fixture()
def old_run(tmp_path: Path) -> Path:
    run = tmp_path / "run"
    run.mkdir()
    shutil.copy(FIXTURE / "checkpoint.pt", checkpoint_path(run))
    return run


def test_a_version_2_run_predicts_what_it_predicted_when_written(old_run: Path) -> None:
    expected = torch.load(FIXTURE / "expected.pt", weights_only=True)
    assert load_checkpoint(old_run)["version"] == 2 and "parameters" in load_checkpoint(old_run)["engine"]
    model = load_run(old_run).engine
    assert torch.equal(model.theta, expected["theta"])
    for group in model.groups:
        for sensor in group.sensors:
            latents = model.encode(group.name, sensor, expected["inputs"][sensor])
            assert torch.equal(latents, expected["latents"][f"{group.name}/{sensor}"])
            for target, frames in model.decode(group.name, latents).items():
                assert torch.equal(frames, expected["decoded"][f"{group.name}/{sensor}/{target}"])
    masks = model.draw_masks(6)  # each member's dropout stream goes on where the old run left it
    assert masks is not None and masks.keys() == expected["next_masks"].keys()
    assert all(torch.equal(masks[k], expected["next_masks"][k]) for k in masks)
    # and its state now is the standard one: a state_dict that loads into a fresh model of the same shape
    assert set(model.state()["state_dict"]) == set(model.state_dict())


def test_a_version_2_run_resumes_and_then_saves_the_current_layout(old_run: Path) -> None:
    before = load_run(old_run).engine.theta
    resumed = train(build_paired_dataset(small_sets()), old_run, resume=True, epochs=3, device="cpu")
    assert [h["epoch"] for h in resumed.history] == [1, 2, 3]
    assert not torch.equal(resumed.engine.theta, before)
    payload = load_checkpoint(old_run)
    assert payload["version"] == 3 and "state_dict" in payload["engine"] and "parameters" not in payload["engine"]
    assert torch.equal(load_run(old_run).engine.theta, resumed.engine.theta)
