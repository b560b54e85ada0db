"""Tuning: every hyper-parameter from a TOML file or the command line, saved with the run; a validation split that
never touches test data; the split seed apart from the model seeds; preprocessing as an explicit option."""

from __future__ import annotations

import tomllib
from pathlib import Path

import numpy as np
import pytest

from tests.helpers import cli
from tests.learning.learning_helpers import small_sets, write_sessions
from unitac_rig.errors import ConfigError, UsageError
from unitac_rig.learning.config import parse_config, to_toml
from unitac_rig.learning.data import Normaliser, build_paired_dataset, split_by_direction
from unitac_rig.learning.engine import ModelShape
from unitac_rig.learning.train import TrainConfig, load_run, train


@pytest.fixture(scope="module")
def pairs():  # type: ignore[no-untyped-def]
    return build_paired_dataset(small_sets())


TUNED = TrainConfig(
    epochs=7,
    batch_size=32,
    learning_rate=1e-3,
    seeds=(4, 5),
    split_seed=2,
    test_fraction=0.2,
    val_fraction=0.15,
    baselines=False,
    shape=ModelShape(encoder_hidden=(32,), latent_dim=4, decoder_hidden=(16, 24), dropout=0.1, align_weight=0.5),
    eval_every=3,
    checkpoint_every=9,
    unseen_objects=("hex_tpu",),
    tsne_contacts=12,
    preprocessing="raw",
    nmae_normaliser="frame_range",
    ssim_range="z_range",
)


def test_a_config_round_trips_through_its_toml_file() -> None:
    text = to_toml(TUNED.to_dict())
    assert TrainConfig().updated(parse_config(tomllib.loads(text))) == TUNED
    assert 'scaling = "raw"' in text and "[metrics]" in text


def test_a_partial_file_keeps_the_defaults_for_everything_else() -> None:
    config = TrainConfig().updated(parse_config({"training": {"learning_rate": 1e-3}, "model": {"latent_dim": 8}}))
    assert config.learning_rate == 1e-3 and config.shape.latent_dim == 8
    assert config.epochs == 1000 and config.batch_size == 64 and config.shape.encoder_hidden == (64, 48)


@pytest.mark.parametrize(
    ("data", "where"),
    [
        ({"training": {"lr": 1e-3}}, "training.lr: unknown key"),
        ({"optimiser": {"name": "sgd"}}, "optimiser: unknown key"),
        ({"metrics": {"ssim_range": "x_range"}}, "metrics.ssim_range"),
        ({"training": {"epochs": 0}}, "training.epochs"),
        ({"model": {"dropout": 1.5}}, "model.dropout"),
    ],
)
def test_unknown_or_invalid_keys_are_refused_naming_the_key(data: dict, where: str) -> None:
    with pytest.raises(ConfigError, match=where.replace(".", r"\.")):
        parse_config(data, source="tuning.toml")


def test_the_validation_split_never_overlaps_test_and_leaves_test_as_it_was(pairs) -> None:  # type: ignore[no-untyped-def]
    with_val = split_by_direction(pairs, seed=3, val_fraction=0.1)
    without = split_by_direction(pairs, seed=3)
    assert np.array_equal(with_val.test_mask, without.test_mask)  # validation comes out of the training side
    val, test, train_ = with_val.validation_mask, with_val.test_mask, with_val.train_mask
    assert val.any() and not (val & test).any() and not (val & train_).any() and (val | test | train_).all()

    def directions(mask):  # type: ignore[no-untyped-def]
        return set(zip(pairs.object_id[mask], pairs.rotation_deg[mask], pairs.angle_deg[mask], strict=True))

    assert not directions(val) & directions(test) and not directions(val) & directions(train_)
    assert not (val & (pairs.object_id == "irregular_pla")).any()  # the unseen object is all test data
    for object_id, held in with_val.val_directions.items():
        assert len(held) == 1  # round(10% of 11 angles), with all 5 forces
        assert ((pairs.object_id == object_id) & val).sum() == 5


def test_the_split_seed_is_apart_from_the_model_seeds(pairs, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    a = train(pairs, tmp_path / "a", TrainConfig(epochs=1, seeds=(0,), split_seed=1, tsne_contacts=10), device="cpu")
    b = train(pairs, tmp_path / "b", TrainConfig(epochs=1, seeds=(7,), split_seed=1, tsne_contacts=10), device="cpu")
    c = train(pairs, tmp_path / "c", TrainConfig(epochs=1, seeds=(0,), split_seed=2, tsne_contacts=10), device="cpu")
    assert np.array_equal(a.split.test_mask, b.split.test_mask)
    assert np.array_equal(a.split.validation_mask, b.split.validation_mask)
    assert not np.array_equal(a.split.test_mask, c.split.test_mask)
    # per-epoch curves are validation scores; the test rows are scored only after epoch 1 and at the end


def test_curves_use_validation_rows_and_test_is_scored_only_at_the_ends(pairs, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    outcome = train(pairs, tmp_path / "run", TrainConfig(epochs=4, eval_every=2, tsne_contacts=10), device="cpu")
    assert [("val" in h, "test" in h) for h in outcome.history] == [
        (True, True),
        (True, False),
        (False, False),
        (True, True),
    ]
    val_rows = int(outcome.split.validation_mask.sum())
    assert val_rows == 2 * 5  # one validation angle of each of the two seen objects
    seen = outcome.history[1]["val"]["seen"]
    assert {"latent_l1", "latent_ratio", "mixing", "mixing_expected"} <= set(seen)
    assert "unseen" not in outcome.history[1]["val"]  # validation holds seen objects only
    assert set(outcome.history[-1]["val_metric_variants"]["nmae"]) == {
        "channel_range",
        "sensor_range",
        "channel_std",
        "frame_range",
    }


@pytest.mark.parametrize("mode", ["channel_z", "sensor_minmax", "sensor_scale", "raw"])
def test_each_preprocessing_inverts_exactly(pairs, mode: str) -> None:  # type: ignore[no-untyped-def]
    norm = Normaliser.fit(pairs, np.ones(len(pairs), dtype=bool), mode)
    frames = pairs.values["uskin"][:20]
    assert np.allclose(norm.denormalise("uskin", norm.normalise("uskin", frames)), frames, rtol=1e-5, atol=1e-2)
    assert Normaliser.from_dict(norm.to_dict()).to_dict() == norm.to_dict()


def test_per_sensor_scalings_keep_the_channels_proportions_and_channel_z_does_not(pairs) -> None:  # type: ignore[no-untyped-def]
    rows = np.ones(len(pairs), dtype=bool)
    values = pairs.values["papillarray"].reshape(-1, 3).astype(np.float64)
    recorded = values.std(axis=0)
    for mode, proportional in (("sensor_minmax", True), ("sensor_scale", True), ("raw", True), ("channel_z", False)):
        seen = Normaliser.fit(pairs, rows, mode).normalise("papillarray", pairs.values["papillarray"])
        spread = seen.reshape(-1, 3).std(axis=0)
        assert np.allclose(spread / spread[2], recorded / recorded[2], rtol=1e-4) is proportional, mode
    minmax = Normaliser.fit(pairs, rows, "sensor_minmax").normalise("papillarray", pairs.values["papillarray"])
    assert minmax.min() == pytest.approx(0.0, abs=1e-6) and minmax.max() == pytest.approx(1.0, abs=1e-6)
    whole = float(values.max() - values.min())
    assert Normaliser.fit(pairs, rows, "raw").sensor_range["papillarray"] == pytest.approx(whole)


def test_cli_takes_a_config_file_and_options_over_it_and_saves_both_with_the_run(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    data = tmp_path / "data"
    write_sessions(data, small_sets(objects=("circle_pla", "irregular_pla")))
    config = tmp_path / "tuning.toml"
    config.write_text(
        "[training]\nepochs = 2\nlearning_rate = 0.002\nbatch_size = 16\n[model]\nlatent_dim = 8\n"
        '[preprocessing]\nscaling = "channel_z"\n',
        encoding="utf-8",
    )
    run = tmp_path / "run"
    args = ["train", "--data", str(data), "--out", str(run), "--config", str(config), "--no-report"]
    assert cli([*args, "--lr", "0.001", "--seed", "3", "--encoder-hidden", "32,16", "--ssim-range", "z_range"]) == 0
    saved = tomllib.loads((run / "config.toml").read_text())
    assert saved["training"]["learning_rate"] == 0.001  # the command line wins over the file
    assert saved["training"]["batch_size"] == 16 and saved["training"]["epochs"] == 2  # the file over defaults
    assert saved["training"]["seeds"] == [3] and saved["split"]["seed"] == 0  # model seed apart from split seed
    assert saved["model"]["latent_dim"] == 8 and saved["model"]["encoder_hidden"] == [32, 16]
    assert saved["preprocessing"]["scaling"] == "channel_z" and saved["metrics"]["ssim_range"] == "z_range"
    loaded = load_run(run).config
    assert loaded.learning_rate == 0.001 and loaded.shape.encoder_hidden == (32, 16)
    assert load_run(run).normaliser.mode == "channel_z"

    # a resumed run keeps its stored configuration: only --epochs may change
    assert cli(["train", "--data", str(data), "--out", str(run), "--resume", "--lr", "0.1", "--no-report"]) == 2
    assert "drop --lr" in capsys.readouterr().err
    assert cli(["train", "--data", str(data), "--out", str(run), "--resume", "--epochs", "3", "--no-report"]) == 0
    assert load_run(run).payload["epoch"] == 3

    bad = tmp_path / "bad.toml"
    bad.write_text("[training]\nlearnig_rate = 0.1\n", encoding="utf-8")
    assert cli(["train", "--data", str(data), "--out", str(tmp_path / "r2"), "--config", str(bad)]) == 2
    assert "training.learnig_rate: unknown key" in capsys.readouterr().err


def test_invalid_options_are_usage_errors() -> None:
    # checked by the config's own fields, named as in a config file
    with pytest.raises(UsageError, match=r"preprocessing\.scaling: Input should be 'channel_z'"):
        TrainConfig(preprocessing="zscore")
    with pytest.raises(UsageError, match=r"split\.val_fraction: must be below 1 - test fraction = 0\.5"):
        TrainConfig(test_fraction=0.5, val_fraction=0.5)
    with pytest.raises(UsageError, match=r"model\.latent_dim: Input should be greater than or equal to 1"):
        TrainConfig().updated({"shape.latent_dim": 0})
    with pytest.raises(UsageError, match="unknown training option"):
        TrainConfig().updated({"shape.width": 3})


def test_the_alignment_term_brings_matched_latents_closer_than_reconstruction_alone(pairs, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    ratios = {}
    for weight in (0.0, 1.0):
        config = TrainConfig(epochs=20, eval_every=20, tsne_contacts=10, baselines=False)
        config = config.updated({"shape.align_weight": weight})
        outcome = train(pairs, tmp_path / f"w{weight}", config, device="cpu")
        ratios[weight] = outcome.history[-1]["test"]["all"]["latent_ratio"][0]
    # scale-free, so shrinking the latents cannot fake it: matched / unmatched L1 itself falls
    assert ratios[1.0] < ratios[0.0] - 0.15


def test_report_rescores_a_run_under_other_metric_options(pairs, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    import json

    run = tmp_path / "run"
    train(pairs, run, TrainConfig(epochs=1, tsne_contacts=10), device="cpu")
    assert cli(["report", str(run), "--no-figures"]) == 0
    own = json.loads((run / "metrics.json").read_text())
    assert own["metrics"]["nmae_normaliser"] == "channel_range" and own["preprocessing"]["scaling"] == "sensor_scale"
    assert cli(["report", str(run), "--no-figures", "--nmae-normaliser", "channel_std"]) == 0
    other = json.loads((run / "metrics.json").read_text())
    assert other["metrics"]["nmae_normaliser"] == "channel_std" and other["metrics"]["ssim_range"] == "sensor_range"
    # MAE in z-score units is larger than MAE over each channel's range (std < range), for the same reconstructions
    cell, before = other["table1"]["all_seen"]["uskin_to_uskin"], own["table1"]["all_seen"]["uskin_to_uskin"]
    assert cell["nmae"] > before["nmae"] and cell["ssim"] == before["ssim"]
    assert "channel_std" in (run / "report.md").read_text()
