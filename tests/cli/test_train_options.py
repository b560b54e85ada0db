"""``unitac-rig train``'s hyper-parameter options are generated from the training configuration's fields: each
option's help, default and range come from its field, and a bad value (on the command line or in --config) is a
usage error (exit 2) naming the option as typed, before any data is read or torch imported."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest
import typer
from typer.testing import CliRunner

from tests.helpers import cli
from unitac_rig.cli import learn_train
from unitac_rig.cli.help import use_plain_help
from unitac_rig.learning import config as train_config
from unitac_rig.learning.train import TrainConfig


def _help(command: Any) -> str:
    app = typer.Typer()
    app.command("train")(command)
    app.command("other")(lambda: None)  # two commands: `train` stays a subcommand
    use_plain_help(app)
    result = CliRunner().invoke(app, ["train", "--help"], env={"COLUMNS": "200"})
    assert result.exit_code == 0, result.output
    return " ".join(result.output.split())


def test_every_option_shows_its_fields_description_and_default() -> None:
    text = _help(learn_train.train_command)
    for option in learn_train.config_options().values():
        description = option.info.description
        assert description and description.rstrip(".") in text, option.flag
        default = option.info.default
        shown = ",".join(map(str, default)) if isinstance(default, tuple) else option.typed(default).split()[-1]
        assert f"{option.flag.replace('/', ' / ')}" in text
        assert f"[default: {shown if not isinstance(default, float) else f'{default:g}'}" in text, option.flag


def test_changing_a_fields_default_and_description_changes_the_help(monkeypatch: pytest.MonkeyPatch) -> None:
    info = train_config.TrainingSection.model_fields["batch_size"]
    monkeypatch.setattr(info, "default", 32)
    monkeypatch.setattr(info, "description", "Contacts per optimiser step.")
    text = _help(learn_train.build_train_command())
    assert "--batch-size N Contacts per optimiser step. [default: 32, as in the paper; at least 1]" in text


def test_the_configs_defaults_are_the_trainers() -> None:
    """TrainConfig takes its defaults from the config's fields: one list of training options."""
    flat = TrainConfig().to_dict()
    flat.update({f"shape.{k}": v for k, v in flat.pop("shape").items()})
    assert {k: list(v) if isinstance(v, tuple) else v for k, v in train_config.defaults().items()} == {
        k: list(v) if isinstance(v, tuple) else v for k, v in flat.items()
    }


def test_the_config_choices_are_the_librarys_tables() -> None:
    from typing import get_args

    from unitac_rig.learning.data import PREPROCESSING, SPLIT_MODES
    from unitac_rig.learning.metrics import NMAE_NORMALISERS, SSIM_RANGES

    fields = train_config.fields()
    for (section, key), table in {
        ("preprocessing", "scaling"): PREPROCESSING,
        ("metrics", "nmae_normaliser"): NMAE_NORMALISERS,
        ("metrics", "ssim_range"): SSIM_RANGES,
        ("split", "mode"): SPLIT_MODES,
    }.items():
        assert set(get_args(fields[section, key].annotation)) == set(table), key


@pytest.fixture
def started(monkeypatch: pytest.MonkeyPatch) -> list[Any]:
    """The requests that got past the checks to the work (reading data, importing torch)."""
    calls: list[Any] = []
    monkeypatch.setattr(learn_train, "run_train", calls.append)
    return calls


def _train(tmp_path: Path, *args: str, out: str = "run") -> int:
    (tmp_path / "data").mkdir(exist_ok=True)
    return cli(["train", "--data", str(tmp_path / "data"), "--out", str(tmp_path / out), *args])


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--test-fraction", "1.5"], "--test-fraction 1.5: should be less than 1"),
        (["--test-fraction", "0.5", "--val-fraction", "0.6"], "--val-fraction 0.6: must be below 1 - test fraction"),
        (["--lr", "0"], "--lr 0.0: should be greater than 0"),
        (["--encoder-hidden", "64,x"], "--encoder-hidden 64,x: takes comma-separated layer widths"),
        (["--decoder-hidden", "64,0"], "--decoder-hidden 64,0: should be greater than or equal to 1"),
        (["--preprocessing", "zscore"], "--preprocessing zscore: should be 'channel_z'"),
        (["--dropout", "1"], "--dropout 1.0: should be less than 1"),
        (["--epochs", "0"], "'--epochs'"),
    ],
)
def test_a_bad_value_exits_2_naming_the_option_before_any_work(
    tmp_path: Path, started: list[Any], capsys: pytest.CaptureFixture[str], args: list[str], message: str
) -> None:
    assert _train(tmp_path, *args) == 2
    assert message in capsys.readouterr().err
    assert not started


def test_a_bad_value_in_the_config_file_names_the_files_key(
    tmp_path: Path, started: list[Any], capsys: pytest.CaptureFixture[str]
) -> None:
    config = tmp_path / "tuning.toml"
    config.write_text("[split]\nval_fraction = 0.5\n")
    assert _train(tmp_path, "--config", str(config), "--test-fraction", "0.6") == 2
    assert f"{config}: split.val_fraction: must be below 1 - test fraction = 0.4" in capsys.readouterr().err
    assert not started


def test_good_values_reach_the_run_with_the_file_under_the_options(tmp_path: Path, started: list[Any]) -> None:
    config = tmp_path / "tuning.toml"
    config.write_text("[model]\nlatent_dim = 8\n[split]\ntest_fraction = 0.2\n")
    assert _train(tmp_path, "--config", str(config), "--test-fraction", "0.3", "--encoder-hidden", "32,16") == 0
    trained = started[0].train_config()
    assert (trained.shape.latent_dim, trained.test_fraction, trained.shape.encoder_hidden) == (8, 0.3, (32, 16))
    assert trained.epochs == train_config.defaults()["epochs"]


def test_out_must_be_new_or_empty_unless_it_holds_a_run(
    tmp_path: Path, started: list[Any], capsys: pytest.CaptureFixture[str]
) -> None:
    (tmp_path / "photos").mkdir()
    (tmp_path / "photos" / "holiday.jpg").write_bytes(b"")
    assert _train(tmp_path, out="photos") == 2
    assert "is not empty and holds no run" in capsys.readouterr().err
    (tmp_path / "empty").mkdir()
    assert _train(tmp_path, out="empty") == 0
    assert len(started) == 1
