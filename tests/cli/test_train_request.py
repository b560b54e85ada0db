"""``unitac-rig train`` is a thin layer over :class:`TrainRequest`: every option lands in the request (a field of its
own or a TrainConfig key), so the configuration a command line asks for is the one that trains."""

from __future__ import annotations

import dataclasses
import inspect
from pathlib import Path

import pytest

from unitac_rig.cli.learn_train import TrainRequest, config_options, train_command
from unitac_rig.errors import UsageError
from unitac_rig.learning import config as learn_config
from unitac_rig.learning.train import TrainConfig


def test_every_train_option_reaches_the_request() -> None:
    options = set(inspect.signature(train_command).parameters) - {"ctx"}
    fields = {f.name for f in dataclasses.fields(TrainRequest)} - {"options"}
    generated = config_options()
    assert options == fields | set(generated)
    assert not fields & set(generated)
    flat = TrainConfig().to_dict()
    for option in generated.values():  # each names a real TrainConfig field
        key = learn_config.flat_key(option.section, option.key)
        assert (key.removeprefix("shape.") in flat["shape"]) if key.startswith("shape.") else key in flat


def test_the_request_builds_the_config_the_options_ask_for(tmp_path: Path) -> None:
    params = {name: None for name in config_options()} | {
        "data": [tmp_path],
        "out": tmp_path / "run",
        "resume": False,
        "config_file": None,
        "partial": False,
        "from_run": None,
        "new_sensor": None,
        "epochs": 7,
        "seed": 3,
        "n_seeds": 2,
        "device": "cpu",
        "threads": 0,
        "report": False,
        "latent_dim": 8,
        "encoder_hidden": "32,16",
        "nmae_normaliser": "sensor_range",
    }
    config = TrainRequest.from_params(params).train_config()
    assert (config.epochs, config.seeds, config.nmae_normaliser) == (7, (3, 4), "sensor_range")
    assert (config.shape.latent_dim, config.shape.encoder_hidden) == (8, (32, 16))
    resumed = TrainRequest.from_params(
        params | {"resume": True, "seed": None, "n_seeds": None, "latent_dim": None, "encoder_hidden": None}
    )
    with pytest.raises(UsageError, match="drop --nmae-normaliser"):
        resumed.train_config()
