"""The UniTac-NV authors' conventions, made explicit: every constant their offline scripts hard-code is a field here
(defaults: what their preprocessing does to a raw session), and what this project adds on top says so (name mapping,
press windows, completeness, grid mapping, the arbitrary files' rotations: a guess). docs/import.md has every field.

A TOML file can override any field (``--conventions FILE``); the effective conventions are stored in every imported
session's root attributes.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from pydantic import Field, ValidationError, field_validator, model_validator

from unitac_rig.errors import ConfigError
from unitac_rig.rig.config import describe_validation_error, read_toml, toml_text
from unitac_rig.rig.sensors.base import StrictTable
from unitac_rig.storage.extraction import ExtractionSettings, default_targets_n

# What the authors' script (0_data_preprocessing.py) already applied to every processed .npz file.
AUTHORS_PROCESSED_STEPS: dict[str, Any] = {
    "drop_first_rows": 10,
    "baseline_samples": 100,
    "ft_rotation_deg": 45.0,
    "papillarray_flip_xy": True,
    "time_zeroed_at_first_kept_row": True,
}


class TactileMapping(StrictTable):
    """How one of their matrices (rows x cols x 3, after their own sign harmonisation) lands in our frame.

    Identity by default: their matrix row r, column c becomes our taxel ``r * cols + c`` and their x, y, z our x, y, z.
    That is an assumption (the authors publish no drawing of either sensor's axes); flip here if a figure shows
    otherwise.
    """

    flip_rows: bool = Field(default=False, description="reverse their row order (our row 0 is the top row)")
    flip_cols: bool = Field(default=False, description="reverse their column order (our columns grow along +x)")
    axis_signs: tuple[int, int, int] = Field(default=(1, 1, 1), description="sign applied to their x, y, z")

    @field_validator("axis_signs")
    @classmethod
    def _unit_signs(cls, value: tuple[int, int, int]) -> tuple[int, int, int]:
        if any(s not in (-1, 1) for s in value):
            raise ValueError("axis_signs entries must be +1 or -1")
        return value


class ExtractionConventions(StrictTable):
    """Settings of the force-matched extraction for 100 Hz imported data (the project defaults assume 500 Hz)."""

    targets_n: tuple[float, ...] = tuple(float(x) for x in default_targets_n())
    tolerance_n: float = Field(default=0.5, gt=0, description="largest |force at frame - target| that still counts, N")
    smoothing_samples: int = Field(
        default=3, ge=1, description="centred moving average of the press force, samples (30 ms)"
    )
    max_frame_gap_s: float = Field(default=0.05, gt=0, description="largest gap between crossing and nearest frame, s")
    tactile_latency_s: float = Field(default=0.0, description="tactile delay relative to the F/T, s (same CSV row: 0)")

    def to_settings(self) -> ExtractionSettings:
        # the moving average, as before the fit: the authors' wrist lag and noise are not known, and their rows pair
        # the tactile frame with the wrist reading as recorded (`unitac-rig extract` can re-run with the fit)
        return ExtractionSettings(**self.model_dump(), method="moving-average")


def _default_object_shapes() -> dict[str, str]:
    # Their folder names (circular/square/hexagonal) and their processed names (cylinder/oblong/hexagon) -> our
    # shape prefix; our object id is "<prefix>_<material>" (e.g. hexagonal_TPU -> hex_tpu).
    return {
        "circular": "circle",
        "cylinder": "circle",
        "square": "square",
        "oblong": "square",
        "hexagonal": "hex",
        "hexagon": "hex",
        "arbitrary": "irregular",
    }


class ImportConventions(StrictTable):
    """Every assumption the import makes about the UniTac-NV files (see the module docstring)."""

    # --- names -------------------------------------------------------------------------------------------------
    object_shapes: dict[str, str] = Field(
        default_factory=_default_object_shapes,
        description="their shape name (lower case) -> our object-id prefix; the id is '<prefix>_<material>'",
    )
    sensor_names: dict[str, str] = Field(
        default_factory=lambda: {"xela": "uskin", "papil": "papillarray", "papillarray": "papillarray"},
        description="their sensor folder/file name (lower case) -> our sensor id",
    )
    arbitrary_material: str = Field(
        default="pla", description="material of the arbitrary object (their raw names omit it)"
    )
    arbitrary_rotation_deg: dict[int, float] = Field(
        default_factory=lambda: {1: 0.0, 2: 90.0, 3: 180.0, 4: 270.0},
        description="GUESS: object rotation of arbitrary file n; files whose n is missing here are not imported",
    )

    # --- their preprocessing -----------------------------------------------------------------------------------
    drop_first_rows: int = Field(default=10, ge=0, description="data rows dropped at the start of every raw file")
    baseline_samples: int = Field(default=100, ge=1, description="tare = mean of this many first kept samples")
    ft_rotation_deg: float = Field(default=45.0, description="F/T x, y (and Mx, My) rotated by this about z, degrees")
    papillarray_flip_xy: bool = Field(default=True, description="negate PapillArray x and y (force and displacement)")
    press_fz_band_n: tuple[float, float] = Field(
        default=(-20.0, -5.0), description="a sample is 'pressing' when low < Fz < high (strict), N, after rotation"
    )
    min_press_samples: dict[str, int] = Field(
        default_factory=lambda: {"uskin": 30, "papillarray": 5},
        description="shortest run that counts as a press, samples, per our sensor id",
    )
    object_centre_m: tuple[float, float] = Field(
        default=(-0.15, 0.625), description="object axis in the robot base frame (x, y), m"
    )
    angle_offset_deg: float = Field(default=90.0, description="angle = atan2(y - cy, x - cx) in degrees + this")

    # --- what this project adds --------------------------------------------------------------------------------
    tactile_mapping: dict[str, TactileMapping] = Field(
        default_factory=lambda: {"uskin": TactileMapping(), "papillarray": TactileMapping()},
        description="their harmonised matrix -> our (n_taxels, 3) frame, per our sensor id",
    )
    ramp_start_n: float = Field(
        default=0.5,
        ge=0,
        description="press window starts at the last sample before the run with press force <= this, N",
    )
    max_pre_margin_s: float = Field(
        default=5.0, gt=0, description="furthest the window may reach back before the run, s"
    )
    post_margin_s: float = Field(default=0.5, ge=0, description="samples kept after the run (unloading), s")
    complete_peak_n: float = Field(
        default=10.0, gt=0, description="a press whose peak press force reaches this is complete"
    )
    extraction: ExtractionConventions = ExtractionConventions()

    @model_validator(mode="after")
    def _consistent(self) -> ImportConventions:
        low, high = self.press_fz_band_n
        if not low < high:
            raise ValueError("press_fz_band_n must be (low, high) with low < high")
        for sensor in ("uskin", "papillarray"):
            if sensor not in self.tactile_mapping:
                raise ValueError(f"tactile_mapping.{sensor} is missing")
            if sensor not in self.min_press_samples:
                raise ValueError(f"min_press_samples.{sensor} is missing")
        if any(n < 1 for n in self.min_press_samples.values()):
            raise ValueError("min_press_samples must be at least 1")
        for name, sensor in self.sensor_names.items():
            if sensor not in ("uskin", "papillarray"):
                raise ValueError(f"sensor_names.{name}: {sensor!r} is not a sensor id (use uskin or papillarray)")
        return self

    # -- helpers ------------------------------------------------------------------------------------------------
    def object_id(self, shape: str, material: str) -> str:
        """Our object id for their shape name and material (``hexagonal``, ``TPU`` -> ``hex_tpu``)."""
        prefix = self.object_shapes.get(shape.lower())
        if prefix is None:
            known = ", ".join(sorted(self.object_shapes))
            raise ConfigError(
                f"unknown UniTac-NV shape name {shape!r}",
                hint=f"known: {known}; add it under [object_shapes] in a --conventions file",
            )
        return f"{prefix}_{material.lower()}"

    def to_toml(self) -> str:
        """The effective conventions as a TOML document that ``load_conventions`` reads back unchanged."""
        return toml_text(self.model_dump(mode="json"))


def _merge(base: dict[str, Any], override: dict[str, Any]) -> dict[str, Any]:
    """Deep-merge ``override`` into ``base``: tables are merged key by key, everything else replaced."""
    out = dict(base)
    for key, value in override.items():
        if isinstance(value, dict) and isinstance(out.get(key), dict):
            out[key] = _merge(out[key], value)
        else:
            out[key] = value
    return out


def conventions_from_dict(data: dict[str, Any], source: str = "conventions") -> ImportConventions:
    """Defaults overridden by ``data`` (tables merge with the defaults, so a file only lists what it changes)."""
    merged = _merge(ImportConventions().model_dump(mode="json"), data)
    try:
        return ImportConventions.model_validate(merged)
    except ValidationError as exc:
        raise ConfigError(describe_validation_error(exc, source), hint="see docs/import.md for every field") from exc


def load_conventions(path: Path | None) -> ImportConventions:
    """The default conventions, or the defaults overridden by a TOML file."""
    if path is None:
        return ImportConventions()
    path = Path(path)
    return conventions_from_dict(read_toml(path, "conventions file"), source=str(path))
