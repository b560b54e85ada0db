"""Training configuration files: every hyper-parameter of the model, the training, the split, the preprocessing and
the metrics in one TOML file, validated (unknown keys refused) and saved with each run as ``RUN/config.toml``.

The file has sections; every key is optional and a missing key keeps the default of
:class:`unitac_rig.learning.train.TrainConfig` (the paper's values where the paper gives one)::

    [model]                       # one encoder per sensor, one shared decoder (paper II-A)
    encoder_hidden = [64, 48]
    latent_dim = 16
    decoder_hidden = [64, 96]
    dropout = 0.007
    align_weight = 0.0            # beyond the paper: weight of a scale-free latent alignment term in the loss

    [training]
    epochs = 1000
    batch_size = 64
    learning_rate = 5e-4
    seeds = [0, 1, 2, 3, 4]       # model seeds (initialisation, shuffling, dropout), trained together
    baselines = true              # also train one autoencoder per sensor
    patience = 0                  # stop after this many epochs without a better validation NMAE (0: never)

    [split]
    seed = 0                      # which approach directions are test / validation data (apart from model seeds)
    test_fraction = 0.1
    val_fraction = 0.1
    unseen_objects = ["irregular_pla"]   # default: the object catalogue decides

    [evaluation]
    eval_every = 5                # epochs between validation evaluations (per-epoch curves)
    checkpoint_every = 50
    tsne_contacts = 600

    [preprocessing]
    scaling = "sensor_scale"      # channel_z | sensor_minmax | sensor_scale | raw

    [metrics]
    nmae_normaliser = "channel_range"  # channel_range | sensor_range | channel_std | frame_range
    ssim_range = "sensor_range"        # channel_range | sensor_range | z_range

This module only validates and translates between the sectioned file and the flat keyword arguments of
``TrainConfig``; the defaults live in ``TrainConfig`` alone.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from pathlib import Path
from typing import Any, Literal

from pydantic import BaseModel, ConfigDict, Field, ValidationError

from unitac_rig.errors import ConfigError
from unitac_rig.rig.config import describe_validation_error, read_toml

CONFIG_TOML = "config.toml"
_HINT = "see docs/learning.md (Training configuration) for every key"


class _Section(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)


class ModelSection(_Section):
    encoder_hidden: list[int] | None = Field(default=None, min_length=1)
    latent_dim: int | None = Field(default=None, ge=1)
    decoder_hidden: list[int] | None = Field(default=None, min_length=1)
    dropout: float | None = Field(default=None, ge=0.0, lt=1.0)
    align_weight: float | None = Field(default=None, ge=0.0)


class TrainingSection(_Section):
    epochs: int | None = Field(default=None, ge=1)
    batch_size: int | None = Field(default=None, ge=1)
    learning_rate: float | None = Field(default=None, gt=0.0)
    seeds: list[int] | None = Field(default=None, min_length=1)
    baselines: bool | None = None
    patience: int | None = Field(
        default=None,
        ge=0,
        description="early stopping: epochs without a better validation NMAE (mean over UniTac-NV's directions, "
        "seen validation contacts) before training stops; 0 never stops before `epochs`, which stays the maximum",
    )


class SplitSection(_Section):
    seed: int | None = None
    test_fraction: float | None = Field(default=None, gt=0.0, lt=1.0)
    val_fraction: float | None = Field(default=None, ge=0.0, lt=1.0)
    unseen_objects: list[str] | None = None
    mode: Literal["random", "blocked"] | None = None


class EvaluationSection(_Section):
    eval_every: int | None = Field(default=None, ge=1)
    checkpoint_every: int | None = Field(default=None, ge=1)
    tsne_contacts: int | None = Field(default=None, ge=0)


class PreprocessingSection(_Section):
    scaling: Literal["channel_z", "sensor_minmax", "sensor_scale", "raw"] | None = None


class MetricsSection(_Section):
    nmae_normaliser: Literal["channel_range", "sensor_range", "channel_std", "frame_range"] | None = None
    ssim_range: Literal["channel_range", "sensor_range", "z_range"] | None = None


class ConfigFile(_Section):
    """The sectioned file; every key optional, unknown keys and sections refused."""

    model: ModelSection = ModelSection()
    training: TrainingSection = TrainingSection()
    split: SplitSection = SplitSection()
    evaluation: EvaluationSection = EvaluationSection()
    preprocessing: PreprocessingSection = PreprocessingSection()
    metrics: MetricsSection = MetricsSection()


# (section, key in the file) -> TrainConfig field ("shape." for ModelShape fields)
_FIELDS: dict[tuple[str, str], str] = {
    ("model", "encoder_hidden"): "shape.encoder_hidden",
    ("model", "latent_dim"): "shape.latent_dim",
    ("model", "decoder_hidden"): "shape.decoder_hidden",
    ("model", "dropout"): "shape.dropout",
    ("model", "align_weight"): "shape.align_weight",
    ("training", "epochs"): "epochs",
    ("training", "batch_size"): "batch_size",
    ("training", "learning_rate"): "learning_rate",
    ("training", "seeds"): "seeds",
    ("training", "baselines"): "baselines",
    ("training", "patience"): "patience",
    ("split", "seed"): "split_seed",
    ("split", "test_fraction"): "test_fraction",
    ("split", "val_fraction"): "val_fraction",
    ("split", "unseen_objects"): "unseen_objects",
    ("split", "mode"): "split_mode",
    ("evaluation", "eval_every"): "eval_every",
    ("evaluation", "checkpoint_every"): "checkpoint_every",
    ("evaluation", "tsne_contacts"): "tsne_contacts",
    ("preprocessing", "scaling"): "preprocessing",
    ("metrics", "nmae_normaliser"): "nmae_normaliser",
    ("metrics", "ssim_range"): "ssim_range",
}


def parse_config(data: Mapping[str, Any], source: str = "config") -> dict[str, Any]:
    """Validate a sectioned config (a parsed TOML file) and return the keys it sets as flat ``TrainConfig`` field
    names (``shape.<field>`` for the model's widths, latent size and dropout). ConfigError names the first bad key."""
    try:
        parsed = ConfigFile.model_validate(dict(data))
    except ValidationError as exc:
        raise ConfigError(describe_validation_error(exc, source), hint=_HINT) from exc
    flat: dict[str, Any] = {}
    for (section, key), name in _FIELDS.items():
        value = getattr(getattr(parsed, section), key)
        if value is not None:
            flat[name] = tuple(value) if isinstance(value, list) else value
    return flat


def load_config(path: Path) -> dict[str, Any]:
    """The keys a TOML config file sets, as :func:`parse_config` returns them."""
    return parse_config(read_toml(Path(path), "config file"), source=str(path))


def sectioned(flat: Mapping[str, Any]) -> dict[str, dict[str, Any]]:
    """A complete flat ``TrainConfig.to_dict()`` (with its nested ``shape``) as the file's sections; ``None``
    values (e.g. unseen objects left to the catalogue) are left out, as TOML has no null."""
    values = dict(flat)
    shape = dict(values.pop("shape", {}))
    out: dict[str, dict[str, Any]] = {}
    for (section, key), name in _FIELDS.items():
        value = shape.get(name[6:]) if name.startswith("shape.") else values.get(name)
        if value is not None:
            out.setdefault(section, {})[key] = list(value) if isinstance(value, tuple) else value
    return out


def _toml_value(value: Any) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        if not math.isfinite(value):
            raise ConfigError(f"cannot write {value} to a TOML config")
        return repr(value)
    if isinstance(value, str):
        return '"' + value.replace("\\", "\\\\").replace('"', '\\"') + '"'
    if isinstance(value, list | tuple):
        return "[" + ", ".join(_toml_value(v) for v in value) + "]"
    raise ConfigError(f"cannot write a {type(value).__name__} to a TOML config")


def to_toml(flat: Mapping[str, Any]) -> str:
    """The TOML text of a complete flat config; :func:`parse_config` of it gives the same values back."""
    lines = ["# unitac-rig training configuration (written with the run; `unitac-rig train --config` reads it)"]
    for section, keys in sectioned(flat).items():
        lines += ["", f"[{section}]"]
        lines += [f"{key} = {_toml_value(value)}" for key, value in keys.items()]
    return "\n".join(lines) + "\n"
