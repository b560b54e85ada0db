"""The XELA uSkin uSPa46: rig-file tables for its two transports and the driver each one opens."""

from __future__ import annotations

from typing import Literal

from pydantic import Field

from drivers.clock import Clock
from drivers.layouts import USKIN
from drivers.sensor import TactileSensor
from unitac_rig.errors import UsageError
from unitac_rig.rig.sensors.base import SensorConfigBase, SensorSpec, SyntheticResponse


class UskinCanConfig(SensorConfigBase):
    type: Literal["uskin-can"] = "uskin-can"
    can_interface: str = Field("socketcan", description="python-can interface: socketcan, pcan, slcan, virtual, ...")
    can_channel: str = Field("can0", description="python-can channel, e.g. can0, PCAN_USBBUS1, /dev/ttyUSB0")
    bitrate: int = Field(1_000_000, description="CAN bit rate, bit/s (the XELA controller runs at 1 Mbit/s)")
    controller_id: int = Field(1, ge=0, le=15, description="XELA controller id (0..15)")


class UskinXelaServerConfig(SensorConfigBase):
    type: Literal["uskin-xela-server"] = "uskin-xela-server"
    url: str = Field(
        "ws://127.0.0.1:5000",
        description="Read through xela_server instead of CAN, e.g. ws://127.0.0.1:5000.",
        json_schema_extra={"cli": "--xela-server"},  # probe's option name
    )
    sensor_number: int = Field(1, ge=1, description="Sensor number in xela_server's data.")


def open_uskin(config: SensorConfigBase, clock: Clock) -> TactileSensor:
    """The uSkin driver for the configured transport (imported here: python-can and websockets load slowly)."""
    if isinstance(config, UskinCanConfig):
        from drivers.uskin import UskinCanDriver, open_can_bus

        bus = open_can_bus(config.can_interface, config.can_channel, config.bitrate)
        return UskinCanDriver(bus, controller_id=config.controller_id, clock=clock, owns_bus=True)
    if isinstance(config, UskinXelaServerConfig):
        from drivers.uskin import UskinXelaServerDriver

        return UskinXelaServerDriver(config.url, sensor_number=config.sensor_number, clock=clock)
    raise UsageError(f"unsupported uSkin configuration {config!r}")


SENSOR = SensorSpec(
    layout=USKIN,
    config_types=(UskinCanConfig, UskinXelaServerConfig),
    open_driver=open_uskin,
    simulated="unitac_rig.sim.fast_sensors:USKIN",
    pad="skin",
    geometry_dropout=0.2,
    # raw counts: ~110 counts/N normal, 60 counts/N shear, the skin spreading load to its neighbours, 3-count noise
    synthetic=SyntheticResponse(gain_normal=110.0, gain_shear=60.0, spread=(0.2, 0.6, 0.2), noise=3.0),
)
