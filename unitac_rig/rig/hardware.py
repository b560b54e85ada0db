"""The hardware rig: a real UR5e and real sensors, addressed only through the rig file."""

from __future__ import annotations

import logging

from drivers.arm import Arm
from drivers.clock import MonotonicClock
from drivers.sensor import TactileSensor
from unitac_rig.errors import UsageError
from unitac_rig.rig.base import Rig
from unitac_rig.rig.config import RigConfig
from unitac_rig.rig.sensors import get_sensor

log = logging.getLogger(__name__)


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

            arm = self.config.arm
            assert arm is not None
            if arm.unchecked_tool and (arm.tcp_offset is None or arm.payload_kg is None):
                log.warning(
                    "arm.unchecked_tool = true: the TCP and payload on the pendant are not checked; a wrong TCP moves "
                    "every pose and a wrong payload shifts the wrist force the press stops on"
                )
            self._arm = UR5eArm(
                arm.host,
                frequency_hz=arm.frequency_hz,
                clock=self.clock,
                watchdog_hz=arm.watchdog_hz,
                expected_tcp_offset=arm.tcp_offset,
                expected_payload_kg=arm.payload_kg,
            )
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
        sensor = get_sensor(name).open_driver(cfg, self.clock)
        sensor.connect()
        sensor.start_reader()
        return sensor

    def close(self) -> None:
        if self._arm is not None:
            self._arm.close()
            self._arm = None
