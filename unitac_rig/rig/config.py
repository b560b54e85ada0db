"""The rig file: a TOML document validated by pydantic. No rig file means the simulated rig.

Every model forbids unknown keys: a typo in a safety limit must fail loudly, never pass silently. Validation errors
become one :class:`ConfigError` line naming the field. See docs/rig-file.md for every field.
"""

from __future__ import annotations

import tomllib
from pathlib import Path
from typing import Annotated, Any, Literal

from pydantic import BaseModel, ConfigDict, Field, ValidationError, model_validator

from unitac_rig.errors import ConfigError

STRATEGIES = ("guarded", "two-phase", "force-ramp")


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)


class ArmConfig(_Strict):
    host: str = Field(description="IP address or host name of the UR controller")
    frequency_hz: float = Field(500.0, gt=0, le=500, description="RTDE control/receive frequency")


class UskinCanConfig(_Strict):
    type: Literal["uskin-can"] = "uskin-can"
    can_interface: str = Field("socketcan", description="python-can interface: socketcan, pcan, slcan, virtual, ...")
    can_channel: str = Field("can0", description="python-can channel, e.g. can0, PCAN_USBBUS1, /dev/ttyUSB0")
    bitrate: int = 1_000_000
    controller_id: int = Field(1, ge=0, le=15)


class UskinXelaServerConfig(_Strict):
    type: Literal["uskin-xela-server"] = "uskin-xela-server"
    url: str = Field("ws://127.0.0.1:5000", description="xela_server WebSocket address")
    sensor_number: int = Field(1, ge=1)


class PapillArrayConfig(_Strict):
    type: Literal["papillarray"] = "papillarray"
    port: str = Field(description="pyserial URL of the hub, e.g. /dev/ttyACM0")
    slot: int = Field(0, ge=0, le=1, description="the hub's sensor slot")
    rate_hz: Literal[100, 250, 500, 1000] = 100


SensorConfig = Annotated[UskinCanConfig | UskinXelaServerConfig | PapillArrayConfig, Field(discriminator="type")]


class ObjectPlacement(_Strict):
    center_m: tuple[float, float] = Field((-0.15, 0.625), description="object axis in the base frame (x, y), m")
    press_height_m: float = Field(0.20, description="height of the press plane (TCP z) in the base frame, m")
    standoff_mm: float = Field(3.0, gt=0, le=50, description="gap between pad and object at the start pose, mm")
    clearance_mm: float = Field(
        90.0, gt=0, description="moves between press rays go out to this distance from the object axis, mm"
    )
    objects_files: tuple[Path, ...] = Field((), description="extra object files (TOML/JSON) to add to the catalogue")


class PressConfig(_Strict):
    threshold_n: float = Field(10.0, gt=0, description="stop force along the press, N")
    strategy: Literal["guarded", "two-phase", "force-ramp"] = "guarded"
    speed_mm_s: float = Field(2.0, gt=0, description="press speed (guarded) / slow speed (two-phase), mm/s")
    fast_speed_mm_s: float = Field(15.0, gt=0, description="approach speed before contact (two-phase, force-ramp)")
    contact_force_n: float = Field(1.0, gt=0, description="force that counts as first contact, N")
    ramp_rate_n_s: float = Field(8.0, gt=0, description="force-ramp strategy: force rise rate after contact, N/s")
    dwell_s: float = Field(0.2, ge=0, description="hold at the stop before retracting, s")
    transit_speed_mm_s: float = Field(50.0, gt=0, description="speed between presses, mm/s")
    angle_min_deg: float = -45.0
    angle_max_deg: float = 45.0
    angle_count: int = Field(91, ge=1)


class LimitsConfig(_Strict):
    hard_force_n: float = Field(25.0, gt=0, description="abort a press when the press force passes this, N")
    max_travel_after_contact_mm: float = Field(8.0, gt=0, description="fail a press that travels further, mm")
    max_speed_mm_s: float = Field(100.0, gt=0, description="no press or transit speed may exceed this, mm/s")
    workspace_min_m: tuple[float, float, float] = (-0.6, 0.2, 0.0)
    workspace_max_m: tuple[float, float, float] = (0.4, 1.0, 0.6)


class RigConfig(_Strict):
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
        }
        for name, value in speeds.items():
            if value > self.limits.max_speed_mm_s:
                raise ValueError(f"{name} = {value} exceeds limits.max_speed_mm_s = {self.limits.max_speed_mm_s}")
        if self.limits.hard_force_n <= self.press.threshold_n:
            raise ValueError(
                f"limits.hard_force_n = {self.limits.hard_force_n} must be above press.threshold_n = "
                f"{self.press.threshold_n}"
            )
        if self.press.angle_min_deg > self.press.angle_max_deg:
            raise ValueError("press.angle_min_deg is above press.angle_max_deg")
        lo, hi = self.limits.workspace_min_m, self.limits.workspace_max_m
        if any(a >= b for a, b in zip(lo, hi, strict=True)):
            raise ValueError("limits.workspace_min_m must be below limits.workspace_max_m on every axis")
        for name in self.sensors:
            if name not in ("uskin", "papillarray"):
                raise ValueError(f"sensors.{name}: unknown sensor id (use 'uskin' or 'papillarray')")
            expected = "papillarray" if name == "papillarray" else "uskin"
            if not self.sensors[name].type.startswith(expected):
                raise ValueError(f"sensors.{name}: type {self.sensors[name].type!r} does not fit sensor {name!r}")
        if self.arm is not None and not self.sensors:
            raise ValueError("an [arm] is configured but no [sensors.*]: a real rig needs at least one sensor")
        return self

    def angles_deg(self) -> list[float]:
        import numpy as np

        p = self.press
        return [float(a) for a in np.round(np.linspace(p.angle_min_deg, p.angle_max_deg, p.angle_count), 6)]


def describe_validation_error(err: ValidationError, source: str) -> str:
    """The first pydantic error as one line naming the field: ``rig.toml: press.speed_mm_s: ...``."""
    first = err.errors()[0]
    where = ".".join(str(p) for p in first["loc"])
    message = str(first["msg"]).removeprefix("Value error, ")
    if first["type"] == "extra_forbidden":
        message = "unknown key (a typo?)"
    return f"{source}: {where}: {message}" if where else f"{source}: {message}"


def read_toml(path: Path, what: str) -> dict[str, Any]:
    """Parse a TOML file; a missing file or bad syntax becomes one ConfigError line naming ``what`` and the path."""
    try:
        return tomllib.loads(Path(path).read_text())
    except FileNotFoundError:
        raise ConfigError(f"{what} {path} does not exist") from None
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"{path}: not valid TOML ({exc})") from exc


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
        raise ConfigError(describe_validation_error(exc, source), hint="see docs/rig-file.md for every field") from exc
