"""Adding a sensor scores the new directions under the base run's own metric reading (issue 29: it used each
channel's range whatever the run's SSIM option, so its numbers did not read like the run's report)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch

from tests.learning.learning_helpers import small_sets
from unitac_rig.learning.data import build_paired_dataset
from unitac_rig.learning.engine import UNITAC_GROUP
from unitac_rig.learning.extend import evaluate_new_sensor
from unitac_rig.learning.metrics import ssim_per_frame
from unitac_rig.learning.train import TrainConfig, load_run, load_test_set, train


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("extend") / "run"
    train(build_paired_dataset(small_sets()), out, TrainConfig(epochs=2, tsne_contacts=10), device="cpu")
    return out


def test_the_new_directions_ssim_uses_the_runs_ssim_range(run_dir: Path) -> None:
    run, test = load_run(run_dir), load_test_set(run_dir)
    engine, normaliser = run.engine.member(0, groups=[UNITAC_GROUP]), run.normaliser
    by_sensor = evaluate_new_sensor(engine, normaliser, test, "papillarray", "channel_range", "sensor_range")
    by_channel = evaluate_new_sensor(engine, normaliser, test, "papillarray", "channel_range", "channel_range")
    x = torch.from_numpy(normaliser.normalise("uskin", test.values["uskin"]))
    decoded = engine.decode(UNITAC_GROUP, engine.encode(UNITAC_GROUP, "uskin", x))["papillarray"]
    estimate = torch.from_numpy(normaliser.denormalise("papillarray", decoded.numpy()))
    truth = torch.from_numpy(test.values["papillarray"]).to(torch.float32)
    whole = torch.full((3,), float(normaliser.sensor_range["papillarray"]))
    expected = float(ssim_per_frame(truth, estimate, whole).mean())
    assert by_sensor["uskin_to_papillarray"]["ssim"][0] == pytest.approx(expected, rel=1e-5)
    assert not np.isclose(by_sensor["uskin_to_papillarray"]["ssim"][0], by_channel["uskin_to_papillarray"]["ssim"][0])
