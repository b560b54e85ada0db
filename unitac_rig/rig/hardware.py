"""The hardware rig: a real UR5e and real sensors, addressed only through the rig file."""

from __future__ import annotations

from drivers.arm import Arm
from drivers.clock import MonotonicClock
from drivers.sensor import TactileSensor
from unitac_rig.errors import UsageError
from unitac_rig.rig.base import Rig
from unitac_rig.rig.config import PapillArrayConfig, RigConfig, UskinCanConfig, UskinXelaServerConfig


class HardwareRig(Rig):
    """A real UR5e and real sensors, addressed only through the rig file."""

    simulated = False

    def __init__(self, config: RigConfig) -> None:
        if config.arm is None:
            raise UsageError("this rig file has no [arm] section; without one the simulated rig is used")
        self.config = config
        self.clock = MonotonicClock()
        self._arm: Arm | None = None

    @property
    def arm(self) -> Arm:
        if self._arm is None:
            from drivers.ur5e import UR5eArm

            assert self.config.arm is not None
            self._arm = UR5eArm(self.config.arm.host, frequency_hz=self.config.arm.frequency_hz, clock=self.clock)
        return self._arm

    def sensor_names(self) -> list[str]:
        return list(self.config.sensors)

    def open_sensor(self, name: str) -> TactileSensor:
        cfg = self.config.sensors.get(name)
        if cfg is None:
            raise UsageError(
                f"sensor {name!r} is not in the rig file",
                hint=f"configured: {', '.join(self.config.sensors) or 'none'}",
            )
        sensor: TactileSensor
        if isinstance(cfg, UskinCanConfig):
            from drivers.uskin import UskinCanDriver, open_can_bus

            bus = open_can_bus(cfg.can_interface, cfg.can_channel, cfg.bitrate)
            sensor = UskinCanDriver(bus, controller_id=cfg.controller_id, clock=self.clock, owns_bus=True)
        elif isinstance(cfg, UskinXelaServerConfig):
            from drivers.uskin import UskinXelaServerDriver

            sensor = UskinXelaServerDriver(cfg.url, sensor_number=cfg.sensor_number, clock=self.clock)
        elif isinstance(cfg, PapillArrayConfig):
            from drivers.papillarray import PapillArrayDriver

            sensor = PapillArrayDriver(cfg.port, slot=cfg.slot, rate_hz=cfg.rate_hz, clock=self.clock)
        else:  # pragma: no cover - pydantic's discriminator makes this unreachable
            raise UsageError(f"unsupported sensor configuration {cfg!r}")
        sensor.connect()
        sensor.start_reader()
        return sensor

    def close(self) -> None:
        if self._arm is not None:
            self._arm.close()
            self._arm = None
