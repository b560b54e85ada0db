"""The Contactile PapillArray (3x3) on its serial hub: the rig-file table and the driver it opens."""

from __future__ import annotations

from typing import Literal

from pydantic import Field

from drivers.clock import Clock
from drivers.layouts import PAPILLARRAY
from drivers.sensor import TactileSensor
from unitac_rig.errors import UsageError
from unitac_rig.rig.sensors.base import SensorConfigBase, SensorSpec, SyntheticResponse


class PapillArrayConfig(SensorConfigBase):
    type: Literal["papillarray"] = "papillarray"
    port: str = Field(description="Serial port or pyserial URL of the hub, e.g. /dev/ttyACM0.")
    slot: int = Field(0, ge=0, le=1, description="Sensor port on the hub (0 or 1).")
    rate_hz: Literal[100, 250, 500, 1000] = Field(100, description="Sampling rate to set: 100, 250, 500 or 1000 Hz.")


def open_papillarray(config: SensorConfigBase, clock: Clock) -> TactileSensor:
    """The PapillArray driver on the configured serial port (imported here: pyserial is only needed on hardware)."""
    if not isinstance(config, PapillArrayConfig):
        raise UsageError(f"unsupported PapillArray configuration {config!r}")
    from drivers.papillarray import PapillArrayDriver

    return PapillArrayDriver(config.port, slot=config.slot, rate_hz=config.rate_hz, clock=clock)


SENSOR = SensorSpec(
    layout=PAPILLARRAY,
    config_types=(PapillArrayConfig,),
    open_driver=open_papillarray,
    simulated="unitac_rig.sim.fast_sensors:PAPILLARRAY",
    pad="pillars",
    geometry_dropout=0.3,
    synthetic=SyntheticResponse(noise=0.01, proud_centre_mm=0.3),  # newtons; the centre pillar stands 0.3 mm proud
)
