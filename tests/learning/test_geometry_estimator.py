"""The contact-geometry estimator is kept in the run (tensors + JSON, weights_only-loadable) and applied to new frames
by `unitac-rig geometry RUN --predict FRAMES --sensor S`, giving what it gave on its own test contacts."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import torch

from tests.helpers import cli
from tests.learning.learning_helpers import small_sets, write_sessions
from unitac_rig.errors import ModelError
from unitac_rig.learning.contact_geometry import (
    ESTIMATOR_JSON,
    ESTIMATOR_PT,
    GeometryConfig,
    geometry_for_run,
    predict_geometry,
)
from unitac_rig.learning.data import PairedDataset, build_paired_dataset
from unitac_rig.learning.run import load_test_set
from unitac_rig.learning.train import TrainConfig, train


@pytest.fixture(scope="module")
def pairs() -> PairedDataset:
    return build_paired_dataset(small_sets())


@pytest.fixture(scope="module")
def fitted(pairs: PairedDataset, tmp_path_factory: pytest.TempPathFactory):  # type: ignore[no-untyped-def]
    run = tmp_path_factory.mktemp("geometry") / "run"
    train(pairs, run, TrainConfig(epochs=3, seeds=(0, 1), tsne_contacts=30), device="cpu")
    result, _, _ = geometry_for_run(run, member=1, config=GeometryConfig(epochs=5))
    return run, result


def test_the_estimator_is_saved_as_tensors_and_json(fitted) -> None:  # type: ignore[no-untyped-def]
    run, result = fitted
    payload = torch.load(run / ESTIMATOR_PT, weights_only=True)
    shapes = [tuple(w.shape) for w in payload["weights"]]  # one MLP per training sensor, 16 -> ... -> 11
    assert shapes == [(2, 16, 64), (2, 64, 128), (2, 128, 64), (2, 64, 32), (2, 32, 11)]
    meta = json.loads((run / ESTIMATOR_JSON).read_text())
    assert meta["train_sensors"] == ["uskin", "papillarray"] and meta["member"] == 1
    assert meta["object"] == "irregular_pla"
    assert meta["test_mae_mm"]["uskin_to_papillarray"] == result.scenarios["uskin_to_papillarray"]["mae_mm"]


def test_predict_gives_the_estimators_own_test_predictions(  # type: ignore[no-untyped-def]
    fitted, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    run, result = fitted
    test = load_test_set(run)
    frames = test.values["uskin"][result.test_rows]
    np.save(tmp_path / "frames.npy", frames)
    assert cli(["geometry", str(run), "--predict", str(tmp_path / "frames.npy"), "--sensor", "uskin"]) == 0
    printed = capsys.readouterr().out
    assert "MLP trained on uskin latents" in printed and f"{len(frames)} profiles" in printed
    written = np.load(run / "geometry" / "frames_geometry.npz")  # with the run, not beside the frames
    assert written["profiles_mm"].shape == (len(frames), 11)
    np.testing.assert_allclose(written["offsets_mm"], result.offsets_mm)
    np.testing.assert_allclose(written["profiles_mm"], result.predictions["uskin_to_uskin"], rtol=1e-5, atol=1e-5)

    # the MLP trained on the other sensor's latents, applied to uSkin frames: the cross scenario
    cross = predict_geometry(run, frames, "uskin", trained_on="papillarray")
    np.testing.assert_allclose(cross.profiles_mm, result.predictions["papillarray_to_uskin"], rtol=1e-5, atol=1e-5)


def test_predict_reads_a_session_file_and_keeps_its_keys(fitted, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    run, _ = fitted
    data = tmp_path / "data"
    papill = [s for s in small_sets(objects=("hex_tpu",)) if s.sensor == "papillarray"]
    write_sessions(data, papill)
    out = tmp_path / "p.npz"
    session = data / "hex_tpu__papillarray.h5"
    assert cli(["geometry", str(run), "--predict", str(session), "--sensor", "papillarray", "--out", str(out)]) == 0
    written = np.load(out)
    assert written["profiles_mm"].shape == (55, 11) and sorted(set(written["angle_deg"].tolist()))[0] == -45.0
    assert str(written["trained_on"]) == "papillarray"


def test_a_stale_or_missing_estimator_is_refused(pairs: PairedDataset, tmp_path: Path, capsys) -> None:  # type: ignore[no-untyped-def]
    run = tmp_path / "run"
    train(pairs, run, TrainConfig(epochs=2, tsne_contacts=30, checkpoint_every=1), device="cpu")
    np.save(tmp_path / "f.npy", pairs.values["uskin"][:2])
    assert cli(["geometry", str(run), "--predict", str(tmp_path / "f.npy"), "--sensor", "uskin"]) == 2
    assert "no saved geometry estimator" in capsys.readouterr().err

    geometry_for_run(run, config=GeometryConfig(epochs=2))
    train(pairs, run, resume=True, epochs=3, device="cpu")  # the encoders move on: old latents no longer hold
    with pytest.raises(ModelError, match="fitted to other encoder weights"):
        predict_geometry(run, pairs.values["uskin"][:2], "uskin")
    assert cli(["geometry", str(run), "--predict", str(tmp_path / "f.npy")]) == 2  # which sensor recorded them?
