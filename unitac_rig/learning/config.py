"""Training options: every hyper-parameter of the model, the training, the split, the preprocessing and the metrics,
defined once here (default, description, bounds) and read three ways: a TOML file (``train --config``, saved with
each run as ``RUN/config.toml``), the options of ``unitac-rig train`` (generated from these fields by
:mod:`unitac_rig.cli.learn_train`: flag, help, default and range all come from the field), and the flat keyword
arguments of :class:`TrainConfig` (its defaults and its validation are these fields').

The file has the sections below; every key is optional and a missing key keeps the field's default (the paper's value
where the paper gives one)::

    [model]                       # one encoder per sensor, one shared decoder (paper II-A)
    encoder_hidden = [64, 48]
    latent_dim = 16
    [training]
    epochs = 1000
    seeds = [0, 1, 2, 3, 4]       # model seeds (initialisation, shuffling, dropout), trained together
    patience = 0                  # stop after this many epochs without a better validation NMAE (0: never)
    [split]
    test_fraction = 0.1
    unseen_objects = ["irregular_pla"]   # default: the object catalogue decides
    [evaluation]
    eval_every = 1
    [preprocessing]
    scaling = "sensor_scale"
    frame_baseline = "press"      # or "recording": the paper's one baseline per recorded file
    [metrics]
    nmae_normaliser = "channel_range"

A field's ``json_schema_extra`` says how the rest of the program names it: ``key`` (its flat ``TrainConfig`` key when
that is not the field's own name; ``shape.<field>`` for the model's), ``cli`` (its ``train`` option when that is not
``--<key>``; ``None``: no option), ``paper`` (the default is the paper's value).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import asdict, dataclass, field, replace
from dataclasses import fields as dataclass_fields
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any, Literal, get_args

from pydantic import BaseModel, BeforeValidator, ConfigDict, Field, ValidationError, ValidationInfo, field_validator
from pydantic.fields import FieldInfo

from unitac_rig.errors import ConfigError, ModelError, UsageError
from unitac_rig.rig.config import describe_validation_error, read_toml, toml_value

if TYPE_CHECKING:  # the model's module imports torch; the CLI reads these fields before it may
    from unitac_rig.learning.network import ModelShape

CONFIG_TOML = "config.toml"
# The readings offered for the preprocessing and the two metrics' open constants (docs/learning.md): named once here.
Preprocessing = Literal["channel_z", "sensor_minmax", "sensor_scale", "raw"]
NmaeNormaliser = Literal["channel_range", "sensor_range", "channel_std", "frame_range"]
SsimRange = Literal["channel_range", "sensor_range", "z_range"]
FrameBaseline = Literal["press", "recording"]  # storage.reader.FRAME_BASELINES
PREPROCESSING: tuple[str, ...] = get_args(Preprocessing)
NMAE_NORMALISERS: tuple[str, ...] = get_args(NmaeNormaliser)
SSIM_RANGES: tuple[str, ...] = get_args(SsimRange)
_HINT = "see docs/learning.md (Training configuration) for every key"


def _widths(value: Any) -> Any:
    """``"64,48"`` (as typed on the command line) -> [64, 48]; anything else is left to pydantic."""
    if isinstance(value, str):
        try:
            return [int(part) for part in value.replace(" ", "").split(",") if part]
        except ValueError:
            raise ValueError(f"takes comma-separated layer widths, e.g. 64,48; got {value!r}") from None
    return value


Widths = Annotated[tuple[Annotated[int, Field(ge=1)], ...], BeforeValidator(_widths), Field(min_length=1)]


def _field(default: Any, description: str, **extra: Any) -> Any:
    """A field with its description and how the rest of the program names it (``key``, ``cli``, ``paper``); the
    bounds (``ge``, ``gt``, ``lt``...) are pydantic's own keywords."""
    bounds = {k: extra.pop(k) for k in ("ge", "gt", "le", "lt", "min_length") if k in extra}
    return Field(default, description=description, json_schema_extra=extra or None, **bounds)


class _Section(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)


class ModelSection(_Section):
    encoder_hidden: Widths = _field((64, 48), "Encoder hidden widths.", key="shape.encoder_hidden", paper=True)
    latent_dim: int = _field(16, "Latent size.", key="shape.latent_dim", paper=True, ge=1)
    decoder_hidden: Widths = _field((64, 96), "Decoder hidden widths.", key="shape.decoder_hidden", paper=True)
    dropout: float = _field(0.007, "Dropout after every layer.", key="shape.dropout", paper=True, ge=0.0, lt=1.0)
    align_weight: float = _field(
        0.0, "Weight of a scale-free latent alignment term (beyond the paper).", key="shape.align_weight", ge=0.0
    )


class TrainingSection(_Section):
    epochs: int = _field(1000, "Training epochs; with --resume, the new total.", paper=True, ge=1)
    batch_size: int = _field(64, "Batch size.", paper=True, ge=1)
    learning_rate: float = _field(5e-4, "Adam learning rate.", cli="--lr", paper=True, gt=0.0)
    seeds: tuple[int, ...] = _field(
        (0,), "Model seeds (initialisation, shuffling, dropout), trained together.", cli=None, min_length=1
    )
    baselines: bool = _field(True, "Also train per-sensor autoencoders.", cli="--baselines/--no-baselines")
    patience: int = _field(
        0,
        "Stop after this many epochs without a better validation NMAE (0: never); --epochs stays the maximum.",
        ge=0,
    )

    @field_validator("seeds")
    @classmethod
    def _distinct(cls, seeds: tuple[int, ...]) -> tuple[int, ...]:
        if len(set(seeds)) != len(seeds):
            raise ValueError(f"seeds must differ, got {list(seeds)}")
        return seeds


class SplitSection(_Section):
    seed: int = _field(0, "Seed of the test/validation split.", key="split_seed")
    mode: Literal["random", "blocked"] = _field(
        "random", "Test directions: the paper's random ones, or blocked rays.", key="split_mode"
    )
    test_fraction: float = _field(0.1, "Share of directions held out for test.", gt=0.0, lt=1.0)
    val_fraction: float = _field(0.1, "Share of directions for validation.", ge=0.0, lt=1.0)
    unseen_objects: tuple[str, ...] | None = _field(
        None, "Objects held out of training entirely (default: the object catalogue decides).", cli=None
    )

    @field_validator("val_fraction")
    @classmethod
    def _room_for_training(cls, value: float, info: ValidationInfo) -> float:
        test = info.data.get("test_fraction")  # absent when it failed its own check
        if test is not None and not value < 1.0 - test:
            raise ValueError(f"must be below 1 - test fraction = {1.0 - test:g} (training needs directions)")
        return value


class EvaluationSection(_Section):
    eval_every: int = _field(1, "Epochs between validation evaluations.", ge=1)
    checkpoint_every: int = _field(50, "Epochs between checkpoints.", ge=1)
    tsne_contacts: int = _field(600, "Test contacts kept for the t-SNE.", ge=0)


class PreprocessingSection(_Section):
    scaling: Preprocessing = _field(
        "sensor_scale", "How frames are scaled for the network.", key="preprocessing", cli="--preprocessing"
    )
    frame_baseline: FrameBaseline = _field(
        "press",
        "What frames are referenced to: each press's own tare, or the tare at the start of the recording (the "
        "paper's preprocessing; the sensor's drift stays in).",
    )


class MetricsSection(_Section):
    nmae_normaliser: NmaeNormaliser = _field("channel_range", "What the NMAE divides by.")
    ssim_range: SsimRange = _field("sensor_range", "SSIM data range.")


class ConfigFile(_Section):
    """The sectioned file; every key optional, unknown keys and sections refused."""

    model: ModelSection = ModelSection()
    training: TrainingSection = TrainingSection()
    split: SplitSection = SplitSection()
    evaluation: EvaluationSection = EvaluationSection()
    preprocessing: PreprocessingSection = PreprocessingSection()
    metrics: MetricsSection = MetricsSection()


def fields() -> dict[tuple[str, str], FieldInfo]:
    """Every option, by (section, key in the file), in the file's order."""
    return {
        (section, key): info
        for section, holder in ConfigFile.model_fields.items()
        for key, info in holder.annotation.model_fields.items()  # type: ignore[union-attr]
    }


def flat_key(section: str, key: str) -> str:
    """The ``TrainConfig`` key of a field of the file (``shape.<field>`` for the model's)."""
    extra = fields()[section, key].json_schema_extra
    return str(extra.get("key", key)) if isinstance(extra, dict) else key


def defaults() -> dict[str, Any]:
    """Every field's default as flat ``TrainConfig`` keys: what a run trains with when nothing is set."""
    return {flat_key(*where): info.default for where, info in fields().items()}


def validate(sections: Mapping[str, Mapping[str, Any]]) -> ConfigFile:
    """The complete configuration of sectioned values (missing keys: the defaults); pydantic's ValidationError
    names the first bad (section, key)."""
    return ConfigFile.model_validate({name: dict(values) for name, values in sections.items()})


def parse_config(data: Mapping[str, Any], source: str = "config") -> dict[str, Any]:
    """Validate a sectioned config (a parsed TOML file) and return the keys it sets as flat ``TrainConfig`` keys.
    ConfigError names the first bad key."""
    try:
        parsed = ConfigFile.model_validate(dict(data))
    except ValidationError as exc:
        raise ConfigError(describe_validation_error(exc, source), hint=_HINT) from exc
    flat: dict[str, Any] = {}
    for section in parsed.model_fields_set:
        values = getattr(parsed, section)
        for key in values.model_fields_set:
            flat[flat_key(section, key)] = getattr(values, key)
    return flat


def load_config(path: Path) -> dict[str, Any]:
    """The keys a TOML config file sets, as :func:`parse_config` returns them."""
    return parse_config(read_toml(Path(path), "config file"), source=str(path))


def sectioned(flat: Mapping[str, Any]) -> dict[str, dict[str, Any]]:
    """Flat ``TrainConfig`` keys (or a ``TrainConfig.to_dict()`` with its nested ``shape``) as the file's sections;
    ``None`` values (e.g. unseen objects left to the catalogue) are left out, as TOML has no null."""
    values = dict(flat)
    values.update({f"shape.{k}": v for k, v in dict(values.pop("shape", None) or {}).items()})
    out: dict[str, dict[str, Any]] = {}
    for section, key in fields():
        value = values.get(flat_key(section, key))
        if value is not None:
            out.setdefault(section, {})[key] = list(value) if isinstance(value, tuple) else value
    return out


def to_toml(flat: Mapping[str, Any]) -> str:
    """The TOML text of a complete flat config; :func:`parse_config` of it gives the same values back."""
    lines = ["# unitac-rig training configuration (written with the run; `unitac-rig train --config` reads it)"]
    for section, keys in sectioned(flat).items():
        lines += ["", f"[{section}]"]
        lines += [f"{key} = {toml_value(value)}" for key, value in keys.items()]
    return "\n".join(lines) + "\n"


_DEFAULTS = defaults()
# keys added after runs were stored, with what those runs did: a run from before frame_baseline trained on each
# press's own tare
_ADDED_SINCE = {"frame_baseline": "press"}


def _default_shape() -> ModelShape:
    from unitac_rig.learning.network import ModelShape

    return ModelShape(**{k.removeprefix("shape."): v for k, v in _DEFAULTS.items() if k.startswith("shape.")})


@dataclass(frozen=True)
class TrainConfig:
    """What a run trains, as flat keyword arguments (``shape`` the model's): the fields above, their defaults (the
    paper's where it gives one; the other choices and their reasons are in docs/learning.md) and their bounds, so a
    ``TrainConfig`` built in Python is checked as a config file or the command line is."""

    epochs: int = _DEFAULTS["epochs"]
    batch_size: int = _DEFAULTS["batch_size"]
    learning_rate: float = _DEFAULTS["learning_rate"]
    seeds: tuple[int, ...] = _DEFAULTS["seeds"]
    split_seed: int = _DEFAULTS["split_seed"]  # which directions are test / validation data; apart from the seeds
    split_mode: str = _DEFAULTS["split_mode"]
    test_fraction: float = _DEFAULTS["test_fraction"]
    val_fraction: float = _DEFAULTS["val_fraction"]
    baselines: bool = _DEFAULTS["baselines"]
    shape: ModelShape = field(default_factory=_default_shape)
    eval_every: int = _DEFAULTS["eval_every"]  # epoch 1 and the last epoch are always evaluated
    checkpoint_every: int = _DEFAULTS["checkpoint_every"]  # the last epoch is always saved
    unseen_objects: tuple[str, ...] | None = _DEFAULTS["unseen_objects"]  # None: the object catalogue decides
    tsne_contacts: int = _DEFAULTS["tsne_contacts"]
    preprocessing: str = _DEFAULTS["preprocessing"]
    frame_baseline: str = _DEFAULTS["frame_baseline"]
    nmae_normaliser: str = _DEFAULTS["nmae_normaliser"]
    ssim_range: str = _DEFAULTS["ssim_range"]
    patience: int = _DEFAULTS["patience"]  # epochs without a better validation NMAE before stopping; 0: never

    def __post_init__(self) -> None:
        try:
            validate(sectioned(self.to_dict()))
        except ValidationError as exc:
            raise UsageError(describe_validation_error(exc, "training options"), hint=_HINT) from exc

    def to_dict(self) -> dict[str, Any]:
        d = asdict(self)
        d["seeds"] = list(self.seeds)
        d["shape"] = self.shape.to_dict()
        d["unseen_objects"] = None if self.unseen_objects is None else list(self.unseen_objects)
        return d

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> TrainConfig:
        """The config a checkpoint stored (every key: a run's config is written whole); ModelError when one is
        missing or unknown."""
        names = {f.name for f in dataclass_fields(cls)}
        d = {**_ADDED_SINCE, **d}
        if set(d) != names:
            odd = sorted(names.symmetric_difference(d))
            raise ModelError(f"the stored training config does not match this unitac-rig's ({', '.join(odd)})")
        flat = {k: v for k, v in d.items() if k != "shape"}
        return cls().updated(flat | {f"shape.{k}": v for k, v in d["shape"].items()})

    def updated(self, flat: Mapping[str, Any]) -> TrainConfig:
        """A copy with ``flat`` applied: ``TrainConfig`` field names, ``shape.<field>`` for the model's (what
        :func:`parse_config` returns, or CLI options)."""
        shape = {k[6:]: v for k, v in flat.items() if k.startswith("shape.")}
        top = {k: v for k, v in flat.items() if not k.startswith("shape.")}
        unknown = set(top) - set(self.to_dict()) | set(shape) - set(self.shape.to_dict())
        if unknown:
            raise UsageError(f"unknown training option(s) {', '.join(sorted(unknown))}")
        if "seeds" in top:
            top["seeds"] = tuple(int(s) for s in top["seeds"])
        if top.get("unseen_objects") is not None:
            top["unseen_objects"] = tuple(top["unseen_objects"])
        for key in ("encoder_hidden", "decoder_hidden"):
            if key in shape:
                shape[key] = tuple(int(w) for w in shape[key])
        return replace(self, **top, shape=replace(self.shape, **shape))
