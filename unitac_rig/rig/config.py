"""The rig file: a TOML document validated by pydantic. No rig file means the simulated rig.

Every model forbids unknown keys: a typo in a safety limit must fail loudly, never pass silently. Validation errors
become one :class:`ConfigError` line naming the field. docs/rig-file.md says what every field means and why.
"""

from __future__ import annotations

import json
import math
import tomllib
from pathlib import Path
from typing import Annotated, Any

from pydantic import (
    AfterValidator,
    BaseModel,
    BeforeValidator,
    Field,
    SerializeAsAny,
    ValidationError,
    model_validator,
)

from drivers.arm import DEFAULT_WATCHDOG_HZ
from unitac_rig.errors import ConfigError
from unitac_rig.rig.sensors import SENSORS, SensorConfigBase, parse_sensor_config
from unitac_rig.rig.sensors.base import StrictTable
from unitac_rig.rig.strategies import known_strategy

# Physical ceilings of the limits (docs/real-rig.md, "Limits with physical ceilings"): a limit above what the hardware
# can measure or survive is refused, naming the field. The figures are public (hardware-facts 2.6, 3.6).
WRIST_FORCE_RANGE_N = 50.0  # UR5e built-in F/T force range +-50 N: a force limit above it can never trip
WRIST_TORQUE_RANGE_NM = 10.0  # ... torque range +-10 N*m
REDUCED_SPEED_MM_S = 250.0  # ISO 10218-1 reduced speed (teach mode, collaborative work): no tool speed above it
NEAR_STIFFNESS_N_PER_MM = 10.0  # the contact stiffness the near speed is sized for (a printed prism with a pad)
DOUBLE_FAULT_BOUND_N = 25.0  # what a host frozen at an unexpected contact may reach there: the default hard limit,
# and the trueness of a UR's own TCP-force safety limit (hardware-facts 3.6), below which the controller cannot help
MIN_STANDOFF_FLOOR_MM = 2.0  # no position move may end closer to the object than this, mm


class ArmConfig(StrictTable):
    host: str = Field(description="IP address or host name of the UR controller")
    frequency_hz: float = Field(500.0, gt=0, le=500, description="RTDE control/receive frequency")
    watchdog_hz: float = Field(
        DEFAULT_WATCHDOG_HZ,
        gt=5,
        le=100,
        description="RTDE watchdog: the controller stops the program when the host sends nothing for 1/this s",
    )
    tcp_offset: tuple[float, float, float, float, float, float] | None = None  # the pendant's TCP, m and rad
    payload_kg: float | None = Field(None, ge=0, le=5, description="payload mass set on the pendant, kg")
    unchecked_tool: bool = False  # run without tcp_offset / payload_kg (each session then warns)


#: one ``[sensors.<name>]`` table: any registered sensor's config type (unitac_rig/rig/sensors), told apart by ``type``;
#: dumped with its own fields, not just the base's
SensorConfig = Annotated[SerializeAsAny[SensorConfigBase], BeforeValidator(parse_sensor_config)]


class ObjectPlacement(StrictTable):
    center_m: tuple[float, float] = Field((-0.15, 0.625), description="object axis in the base frame (x, y), m")
    press_height_m: float = Field(0.20, description="height of the press plane (TCP z) in the base frame, m")
    standoff_mm: float = Field(8.0, gt=0, le=50, description="pad-object gap where position moves end, mm")
    clearance_mm: float = Field(90.0, gt=0, description="moves between rays go this far from the axis, mm")
    objects_files: tuple[Path, ...] = ()  # extra object files (TOML/JSON) added to the catalogue


class PressConfig(StrictTable):
    threshold_n: float = Field(10.0, gt=0, description="stop force along the press, N")
    # two-phase 15/2 mm/s: chosen from the press chart (docs/benchmarks.md, "Press strategy")
    strategy: Annotated[str, AfterValidator(known_strategy)] = "two-phase"  # a name in rig/strategies.py
    speed_mm_s: float = Field(2.0, gt=0, description="press speed (guarded) / slow speed (two-phase), mm/s")
    fast_speed_mm_s: float = Field(15.0, gt=0, description="approach speed before contact (two-phase, force-ramp)")
    contact_force_n: float = Field(1.0, gt=0, description="force that counts as first contact, N")
    ramp_rate_n_s: float = Field(8.0, gt=0, description="force-ramp strategy: force rise rate after contact, N/s")
    dwell_s: float = Field(0.2, ge=0, description="hold at the stop before retracting, s")
    # the paper's presses came every 6-12 s (its sessions ran 563-1145 s for 91 presses), ours every 1.5-3 s: a rest
    # lets the elastomer recover from the last press (creep, hysteresis) and reproduces the paper's pace
    rest_s: float = Field(0.0, ge=0, le=60, description="rest in free air at the stand-off before each press, s")
    transit_speed_mm_s: float = Field(50.0, gt=0, description="speed between presses, mm/s")
    retract_speed_mm_s: float = Field(20.0, gt=0, description="back off the object after the dwell, mm/s")
    confirmed_standoff_mm: float = Field(5.0, gt=0, description="the stand-off once the placement is confirmed, mm")
    # the controller's set-point in contact is threshold + this, N: what a stalled host leaves it holding, so small
    setpoint_margin_n: float = Field(0.2, gt=0)
    setpoint_ceiling_margin_n: float = Field(2.0, gt=0, description="a settled force raises the set-point to this, N")
    force_mode_damping: float = Field(0.025, ge=0, le=1, description="URScript force_mode_set_damping (UR: 0.005)")
    force_mode_gain_scaling: float = Field(1.0, gt=0, le=2, description="URScript force_mode_set_gain_scaling")
    # the press stops when the mean of this many wrist readings reaches the threshold (50 at 500 Hz: the mean's noise
    # is ~0.16 N, so the true force reaches the threshold instead of a noise peak ending the press ~0.3 N short)
    stop_samples: int = Field(50, ge=1, le=50)
    angle_min_deg: float = Field(-45.0, ge=-90, le=90, description="first approach angle from the object's normal")
    angle_max_deg: float = Field(45.0, ge=-90, le=90, description="last approach angle, deg")
    angle_count: int = Field(91, ge=1, description="approach angles from angle_min_deg to angle_max_deg")

    def max_angle_count(self) -> int:
        """The most approach angles the arc can hold: press ids name angles in whole degrees, so two angles less
        than a degree apart would be the same press."""
        return math.floor(self.angle_max_deg - self.angle_min_deg) + 1

    @model_validator(mode="after")
    def _whole_degrees(self) -> PressConfig:
        too_many = self.angle_count > 1 and self.angle_count > self.max_angle_count()  # checked first: no huge array
        if too_many or len({round(a) for a in _arc(self)}) < self.angle_count:
            raise ValueError(
                f"angle_count = {self.angle_count} gives two approach angles the same whole degree between "
                f"angle_min_deg = {self.angle_min_deg:g} and angle_max_deg = {self.angle_max_deg:g} (press ids are "
                f"whole degrees; at most {self.max_angle_count()} angles there)"
            )
        return self


def _arc(press: PressConfig) -> list[float]:
    """The approach angles of a press config, deg (rounded to 1e-6 so they print and compare cleanly)."""
    import numpy as np

    values = np.linspace(press.angle_min_deg, press.angle_max_deg, press.angle_count)
    return [float(a) for a in np.round(values, 6)]


class LimitsConfig(StrictTable):
    hard_force_n: float = Field(25.0, gt=0, description="abort a press when |F| (all force axes) passes this, N")
    hard_torque_nm: float = Field(2.0, gt=0, description="abort a press when |T| at the TCP passes this, N*m")
    move_force_n: float = Field(5.0, gt=0, description="stop a transit move when the wrist force grows this much, N")
    min_standoff_mm: float = Field(5.0, gt=0, description="no position move ends closer to the object, mm")
    max_failed_in_a_row: int = Field(3, ge=1, description="stop after this many presses in a row do not complete")
    max_reach_m: float = Field(0.85, gt=0, description="no waypoint farther from the shoulder (0, 0, 0.1625 m), m")
    max_travel_after_contact_mm: float = Field(8.0, gt=0, description="fail a press that travels further, mm")
    max_speed_mm_s: float = Field(100.0, gt=0, description="no press or transit speed may exceed this, mm/s")
    # moves toward the object inside the near zone go no faster, mm/s: what bounds the force on the controller when
    # the host freezes at an unexpected contact (docs/real-rig.md, "The bounds")
    near_speed_mm_s: float = Field(10.0, gt=0)
    near_zone_mm: float = Field(50.0, ge=0, description="how far the object may stand from where expected, mm")
    near_zone_confirmed_mm: float = Field(10.0, ge=0, description="the near zone once the placement is confirmed, mm")
    workspace_min_m: tuple[float, float, float] = (-0.6, 0.2, 0.0)
    workspace_max_m: tuple[float, float, float] = (0.4, 1.0, 0.6)

    @model_validator(mode="after")
    def _physical_ceilings(self) -> LimitsConfig:
        """Refuse limits past what the hardware can read or survive (the module's ceilings)."""
        ceilings = (
            ("hard_force_n", self.hard_force_n, WRIST_FORCE_RANGE_N, "N, the UR5e wrist F/T's force range"),
            ("hard_torque_nm", self.hard_torque_nm, WRIST_TORQUE_RANGE_NM, "N*m, the UR5e wrist F/T's torque range"),
            ("max_speed_mm_s", self.max_speed_mm_s, REDUCED_SPEED_MM_S, "mm/s, the ISO 10218-1 reduced speed"),
            ("move_force_n", self.move_force_n, self.hard_force_n, "N, limits.hard_force_n"),
        )
        for name, value, ceiling, what in ceilings:
            if value > ceiling:
                raise ValueError(f"{name} = {value:g} is above {ceiling:g} {what}")
        if self.min_standoff_mm < MIN_STANDOFF_FLOOR_MM:
            raise ValueError(
                f"min_standoff_mm = {self.min_standoff_mm:g} is below {MIN_STANDOFF_FLOOR_MM:g} mm: the wrist "
                "is zeroed at the stand-off, which must stay clear of the object"
            )
        return self


class RigConfig(StrictTable):
    """A whole rig. ``arm`` absent and no sensors means the simulated rig."""

    name: str = "rig"
    arm: ArmConfig | None = None
    sensors: dict[str, SensorConfig] = Field(default_factory=dict)
    object: ObjectPlacement = ObjectPlacement()
    press: PressConfig = PressConfig()
    limits: LimitsConfig = LimitsConfig()

    @property
    def simulated(self) -> bool:
        return self.arm is None

    @model_validator(mode="after")
    def _consistent(self) -> RigConfig:
        speeds = {
            "press.speed_mm_s": self.press.speed_mm_s,
            "press.fast_speed_mm_s": self.press.fast_speed_mm_s,
            "press.transit_speed_mm_s": self.press.transit_speed_mm_s,
            "press.retract_speed_mm_s": self.press.retract_speed_mm_s,
            "limits.near_speed_mm_s": self.limits.near_speed_mm_s,
        }
        for name, value in speeds.items():
            if value > self.limits.max_speed_mm_s:
                raise ValueError(f"{name} = {value} exceeds limits.max_speed_mm_s = {self.limits.max_speed_mm_s}")
        if self.limits.hard_force_n <= self.press.threshold_n:
            raise ValueError(
                f"limits.hard_force_n = {self.limits.hard_force_n} must be above press.threshold_n = "
                f"{self.press.threshold_n}"
            )
        if self.object.standoff_mm < self.limits.min_standoff_mm:
            raise ValueError(
                f"object.standoff_mm = {self.object.standoff_mm} is below limits.min_standoff_mm = "
                f"{self.limits.min_standoff_mm}: position moves would end that close to the object"
            )
        if self.press.threshold_n + self.press.setpoint_margin_n >= self.limits.hard_force_n:
            raise ValueError("press.threshold_n + press.setpoint_margin_n must stay below limits.hard_force_n")
        if self.press.setpoint_ceiling_margin_n < self.press.setpoint_margin_n:
            raise ValueError("press.setpoint_ceiling_margin_n must be at least press.setpoint_margin_n")
        if self.press.angle_min_deg > self.press.angle_max_deg:
            raise ValueError("press.angle_min_deg is above press.angle_max_deg")
        lo, hi = self.limits.workspace_min_m, self.limits.workspace_max_m
        if any(a >= b for a, b in zip(lo, hi, strict=True)):
            raise ValueError("limits.workspace_min_m must be below limits.workspace_max_m on every axis")
        for name, sensor in self.sensors.items():
            if name not in SENSORS:
                raise ValueError(f"sensors.{name}: unknown sensor id (use {spoken([repr(n) for n in SENSORS])})")
            if not isinstance(sensor, SENSORS[name].config_types):
                raise ValueError(f"sensors.{name}: type {sensor.type!r} does not fit sensor {name!r}")
        if self.arm is not None and not self.sensors:
            raise ValueError("an [arm] is configured but no [sensors.*]: a real rig needs at least one sensor")
        if self.arm is not None and not self.arm.unchecked_tool:
            missing = [n for n in ("tcp_offset", "payload_kg") if getattr(self.arm, n) is None]
            if missing:
                raise ValueError(
                    f"arm.{' and arm.'.join(missing)} must be set for a real arm (what the teach pendant says; "
                    "they are read back and checked at connect), or set arm.unchecked_tool = true to run unchecked"
                )
        watchdog_hz = DEFAULT_WATCHDOG_HZ if self.arm is None else self.arm.watchdog_hz
        # The fastest near speed whose double fault (a host frozen at an unexpected contact: the move runs on for one
        # watchdog period) stays under DOUBLE_FAULT_BOUND_N on a NEAR_STIFFNESS_N_PER_MM contact (12 mm/s by default)
        near_ceiling = max(DOUBLE_FAULT_BOUND_N - self.limits.move_force_n, 0.0) * watchdog_hz / NEAR_STIFFNESS_N_PER_MM
        if self.limits.near_speed_mm_s > near_ceiling:
            raise ValueError(
                f"limits.near_speed_mm_s = {self.limits.near_speed_mm_s:g} is above {near_ceiling:.1f} mm/s: a host "
                f"frozen at an unexpected contact runs on for 1/{watchdog_hz:g} s, past {DOUBLE_FAULT_BOUND_N:g} N "
                f"on a {NEAR_STIFFNESS_N_PER_MM:g} N/mm object (docs/real-rig.md)"
            )
        return self

    def angles_deg(self) -> list[float]:
        return _arc(self.press)


def spoken(names: list[str]) -> str:
    """``a, b or c``: registered names in a message or a help line (the registries name them, not the text)."""
    return f"{', '.join(names[:-1])} or {names[-1]}" if len(names) > 1 else names[0]


def describe_validation_error(err: ValidationError, source: str, model: type[BaseModel] | None = None) -> str:
    """The first pydantic error as one line naming the field: ``rig.toml: press.speed_mm_s: ...``; an unknown key
    of ``model`` (the model validated) names the known key it most resembles."""
    first = err.errors()[0]
    where = ".".join(str(p) for p in first["loc"])
    message = str(first["msg"]).removeprefix("Value error, ")
    if first["type"] == "extra_forbidden":
        message = "unknown key (a typo?)"
        near = _nearest_key(model, first["loc"]) if model is not None else None
        if near is not None:
            message = f"unknown key (did you mean {near}?)"
    return f"{source}: {where}: {message}" if where else f"{source}: {message}"


def _nearest_key(model: type[BaseModel], loc: tuple[int | str, ...]) -> str | None:
    """The field of ``model`` at ``loc[:-1]`` whose name is closest to the unknown ``loc[-1]`` (difflib), if any."""
    import difflib
    import typing

    for part in loc[:-1]:
        field = model.model_fields.get(str(part))
        if field is None:
            return None
        nested = [a for a in (field.annotation, *typing.get_args(field.annotation)) if isinstance(a, type)]
        models = [a for a in nested if issubclass(a, BaseModel)]
        if not models:
            return None
        model = models[0]
    close = difflib.get_close_matches(str(loc[-1]), list(model.model_fields), n=1, cutoff=0.6)
    return close[0] if close else None


MAX_TOML_BYTES = 1 << 20  # a rig or object file is a few kB; a bigger one is the wrong file


def read_toml(path: Path, what: str) -> dict[str, Any]:
    """Parse a TOML file; a missing file, a directory, non-UTF-8 text or bad syntax becomes one ConfigError line
    naming ``what`` and the path."""
    path = Path(path)
    try:
        if path.is_dir():
            raise ConfigError(f"{what} {path} is a directory, not a TOML file")
        with path.open("rb") as fh:
            raw = fh.read(MAX_TOML_BYTES + 1)
        if len(raw) > MAX_TOML_BYTES:
            raise ConfigError(f"{path}: over {MAX_TOML_BYTES >> 20} MB, not a {what}")
        return tomllib.loads(raw.decode("utf-8"))
    except FileNotFoundError:
        raise ConfigError(f"{what} {path} does not exist") from None
    except UnicodeDecodeError as exc:
        raise ConfigError(f"{path}: not UTF-8 text (byte {exc.start}), so not TOML") from None
    except RecursionError:
        raise ConfigError(f"{path}: not valid TOML (nested too deeply)") from None
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"{path}: not valid TOML ({exc})") from exc
    except OSError as exc:
        raise ConfigError(f"{what} {path} cannot be read ({exc.strerror or exc})") from exc


def _toml_key(key: str) -> str:
    return key if key.replace("_", "").replace("-", "").isalnum() else json.dumps(key)


def toml_value(value: Any) -> str:
    """One TOML value: a string, bool, int, float or a list of them (what the project's files hold). TOML has
    ``inf`` and ``nan``, so a non-finite number is written as such and refused by whoever reads it as a limit."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        if math.isnan(value):
            return "nan"
        if math.isinf(value):
            return "inf" if value > 0 else "-inf"
        return repr(value)
    if isinstance(value, str):
        return json.dumps(value)  # JSON's string escapes are TOML's
    if isinstance(value, list | tuple):
        return "[" + ", ".join(toml_value(v) for v in value) + "]"
    raise ConfigError(f"cannot write a {type(value).__name__} to TOML")


def toml_text(data: dict[str, Any], prefix: str = "") -> str:
    """A TOML document of ``data`` (nested dicts are tables) that :func:`read_toml` reads back unchanged."""
    lines = [f"[{prefix}]"] if prefix else []
    lines.extend(f"{_toml_key(k)} = {toml_value(v)}" for k, v in data.items() if not isinstance(v, dict))
    text = "\n".join(lines)
    for key, value in data.items():
        if isinstance(value, dict):
            sub = toml_text(value, f"{prefix}.{_toml_key(key)}" if prefix else _toml_key(key))
            text = f"{text}\n\n{sub}" if text else sub
    return text + ("\n" if not prefix else "")


def load_rig_config(path: Path | None) -> RigConfig:
    """Read and validate a rig file; ``None`` gives the simulated rig's defaults."""
    if path is None:
        return RigConfig()
    path = Path(path)
    config = parse_rig_config(read_toml(path, "rig file"), source=str(path))
    files = tuple(f if f.is_absolute() else (path.parent / f) for f in config.object.objects_files)
    return config.model_copy(update={"object": config.object.model_copy(update={"objects_files": files})})


def parse_rig_config(data: dict[str, object], source: str = "rig file") -> RigConfig:
    try:
        return RigConfig.model_validate(data)
    except ValidationError as exc:
        raise ConfigError(
            describe_validation_error(exc, source, RigConfig), hint="see docs/rig-file.md for every field"
        ) from exc
