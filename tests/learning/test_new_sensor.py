"""A third sensor added to a trained two-sensor model (`train --from RUN --new-sensor NAME`): only its encoder and
output layer train, against the frozen model, on contacts it shares with any trained sensor; it then translates to
and from the trained sensors far better than its untrained layers, and the trained sensors' weights do not change by
a single bit."""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

import numpy as np
import pytest
import torch

from drivers.layouts import PAPILLARRAY, USKIN, SensorLayout
from tests.helpers import cli
from tests.learning.learning_helpers import SMALL_TARGETS, write_sessions
from unitac_rig.learning.data import PairedDataset, build_paired_dataset
from unitac_rig.learning.engine import UNITAC_GROUP
from unitac_rig.learning.extend import ExtendConfig, add_sensor
from unitac_rig.learning.run import checkpoint_path, load_test_set
from unitac_rig.learning.synthetic_data import synthetic_matched_sets
from unitac_rig.learning.train import TrainConfig, load_run, train
from unitac_rig.learning.translate import Translator

FAKE = SensorLayout("fakepad", "test-only pad", 2, 2, 6.0, "N", False, "a 2x2 pad that exists only in tests")
OBJECTS = ("circle_pla", "hex_tpu", "irregular_pla")
ANGLES = tuple(float(a) for a in range(-45, 46, 5))  # 19 approach angles: enough contacts for a model worth extending
FAST = 2e-3  # a higher learning rate than the paper's, so a test-sized run learns in a few hundred epochs


def contacts(layouts: tuple[SensorLayout, ...]) -> list:
    return synthetic_matched_sets(OBJECTS, layouts, angles_deg=ANGLES, targets_n=SMALL_TARGETS, seed=0)


def _sha(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


@pytest.fixture(scope="module")
def base_run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """UniTac-NV on the uSkin and the PapillArray, two seeds, with baselines; every object seen (a tenth of each
    one's approach directions held out), so the test contacts measure the model, not the transfer to a new shape."""
    out = tmp_path_factory.mktemp("base") / "run"
    pairs = build_paired_dataset(contacts((USKIN, PAPILLARRAY)))
    config = TrainConfig(
        epochs=250, learning_rate=FAST, seeds=(0, 1), unseen_objects=(), tsne_contacts=30, eval_every=250
    )
    train(pairs, out, config, device="cpu")
    return out


@pytest.fixture(scope="module")
def new_sets() -> list:
    """The three sensors on the same contacts; the fake pad's hex_tpu contacts have no PapillArray partner (that
    session is left out), so part of its training rests on the uSkin alone (the masked loss)."""
    return [s for s in contacts((USKIN, PAPILLARRAY, FAKE)) if (s.object_id, s.sensor) != ("hex_tpu", "papillarray")]


def _errors(translator: Translator, test: PairedDataset, source: str, target: str) -> tuple[float, float]:
    """Mean absolute error of the translated frames' total normal force and of their per-taxel normal force
    (target sensor units)."""
    estimate, truth = translator.translate(test.values[source], source, target)[..., 2], test.values[target][..., 2]
    return float(np.abs(estimate.sum(-1) - truth.sum(-1)).mean()), float(np.abs(estimate - truth).mean())


def test_a_third_sensor_learns_to_translate_both_ways_and_the_trained_model_stays_bit_identical(
    base_run: Path, new_sets: list, tmp_path: Path
) -> None:
    base_checkpoint = _sha(checkpoint_path(base_run))
    base = load_run(base_run)
    out = tmp_path / "with_fake"
    outcome = add_sensor(base_run, new_sets, "fakepad", out, ExtendConfig(epochs=300, learning_rate=FAST), device="cpu")

    # the trained run is untouched, and every one of its layers is bit-identical in the extended run
    assert _sha(checkpoint_path(base_run)) == base_checkpoint
    extended = load_run(out)
    assert extended.sensors == ("uskin", "papillarray", "fakepad")
    for key, weight in base.engine.weights.items():
        assert torch.equal(extended.engine.weights[key], weight), key
        assert torch.equal(extended.engine.biases[key], base.engine.biases[key]), key
    trained = {k for k in extended.engine.weights if k not in extended.engine.frozen}
    assert trained == {"unitac/enc_fakepad/0", "unitac/enc_fakepad/1", "unitac/enc_fakepad/2", "unitac/head_fakepad/2"}

    # hex_tpu's fake-pad contacts trained with the uSkin alone
    contacts = outcome.summary["contacts"]
    assert contacts["train_shared_with"]["uskin"] > contacts["train_shared_with"]["papillarray"] > 0

    # translations to and from the new sensor, on test contacts, against its untrained layers
    test = load_test_set(out)
    assert len(test) > 0 and test.sensors == ("uskin", "papillarray", "fakepad")
    trained_translator = Translator.load(out)
    untrained = Translator(
        base.engine.with_new_sensor("fakepad", FAKE.n_taxels * 3).member(0, groups=[UNITAC_GROUP]),
        trained_translator.normaliser,
    )
    for source, target in [
        ("fakepad", "uskin"),
        ("fakepad", "papillarray"),
        ("uskin", "fakepad"),
        ("papillarray", "fakepad"),
    ]:
        total_after, taxel_after = _errors(trained_translator, test, source, target)
        total_before, taxel_before = _errors(untrained, test, source, target)
        assert total_after < 0.5 * total_before, (source, target, total_after, total_before)  # measured 0.04-0.3
        # measured: the 2x2 pad places the 3x3 PapillArray's load no better than its mean frame does (its total is
        # right to a 0.99 correlation), so that direction is held to the total only; the others' per-taxel error
        # measured 0.1-0.63 of the untrained one (the ratio depends on the preprocessing: an untrained head's
        # output is near the mean frame under a per-channel z-score)
        if (source, target) != ("fakepad", "papillarray"):
            assert taxel_after < 0.75 * taxel_before, (source, target, taxel_after, taxel_before)
    for name in ("uskin_to_fakepad", "papillarray_to_fakepad", "fakepad_to_fakepad"):
        nmae = outcome.summary["trained"][name]["nmae"]
        assert np.mean(nmae) < 0.75 * np.mean(outcome.summary["untrained"][name]["nmae"]), name

    # what the model did for its own sensors it still does exactly
    np.testing.assert_array_equal(
        trained_translator.translate(test.values["uskin"], "uskin", "papillarray"),
        Translator.load(base_run).translate(test.values["uskin"], "uskin", "papillarray"),
    )
    summary = json.loads((out / "extension.json").read_text())
    assert summary["new_sensor"] == "fakepad" and summary["from_epoch"] == 250


def test_cli_adds_a_sensor_and_refuses_what_does_not_fit(
    base_run: Path, new_sets: list, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    data = tmp_path / "data"
    write_sessions(data, [s for s in new_sets if s.sensor == "fakepad" or s.object_id != "irregular_pla"])
    out = tmp_path / "ext"
    args = ["train", "--from", str(base_run), "--new-sensor", "fakepad", "--data", str(data), "--out", str(out)]
    assert cli([*args, "--epochs", "3", "--no-report"]) == 0
    printed = capsys.readouterr().out
    assert "fakepad→uskin" in printed and "untrained" in printed
    assert load_run(out).sensors == ("uskin", "papillarray", "fakepad")

    assert cli([*args[:3], "--data", str(data), "--out", str(tmp_path / "x")]) == 2  # --from without --new-sensor
    assert "go together" in capsys.readouterr().err
    assert cli([*args[:-1], str(tmp_path / "y"), "--seed", "3"]) == 2
    assert "drop --seed" in capsys.readouterr().err
    assert cli([*args[:4], "uskin", *args[5:-1], str(tmp_path / "z")]) == 1
    assert "already has sensor 'uskin'" in capsys.readouterr().err
    assert cli([*args[:-1], str(base_run)]) == 2  # never into the trained run
