"""The Rig seam: the arm, the clock and the sensors, real or simulated, behind one small interface.

Collection code only sees :class:`Rig`. Backends (the hardware rig, the simulated rigs) implement it;
:mod:`unitac_rig.rig.backends` picks one from the rig file.
"""

from __future__ import annotations

import logging
from abc import ABC, abstractmethod
from typing import TYPE_CHECKING

from drivers.arm import Arm
from drivers.clock import Clock
from drivers.errors import DeviceError, DeviceNotFound, DeviceTimeout
from drivers.frames import TactileFrame
from drivers.sensor import TactileSensor
from unitac_rig.errors import UsageError
from unitac_rig.rig.config import RigConfig

if TYPE_CHECKING:
    from unitac_rig.rig.objects import ObjectSpec

log = logging.getLogger(__name__)


class Rig(ABC):
    config: RigConfig
    clock: Clock
    simulated: bool

    @property
    @abstractmethod
    def arm(self) -> Arm: ...

    @abstractmethod
    def sensor_names(self) -> list[str]:
        """Sensors this rig can mount (configured ones on hardware; every simulated model on the simulated rig)."""

    @abstractmethod
    def open_sensor(self, name: str) -> TactileSensor:
        """Connect the named sensor and return its driver, streaming."""

    def mount(self, obj: ObjectSpec, rotation_deg: float, sensor_name: str) -> None:  # noqa: B027 - optional hook
        """Tell the rig which object (and rotation) and sensor are mounted. Hardware: nothing to do."""

    @abstractmethod
    def close(self) -> None: ...

    def __enter__(self) -> Rig:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def sensor_answers(self, name: str, probe_s: float = 1.0) -> bool:
        """True when the named sensor sends a frame within ``probe_s`` (rig clock); it is closed again afterwards.

        Raises what ``open_sensor`` raises (DeviceNotFound: the port or channel is not there).
        """
        sensor = self.open_sensor(name)
        try:
            frames: list[TactileFrame] = []
            deadline = self.clock.now_ns() + int(probe_s * 1e9)
            while not frames and self.clock.now_ns() < deadline:
                self.clock.sleep(0.02)
                frames = sensor.poll()
            return bool(frames)
        finally:
            sensor.disconnect()

    def _answering(self, names: list[str], probe_s: float) -> list[str]:
        """Those of ``names`` whose sensor sends a frame within ``probe_s`` (one that cannot be opened does not)."""
        answering = []
        for name in names:
            try:
                if self.sensor_answers(name, probe_s):
                    answering.append(name)
            except DeviceError as exc:
                log.info("sensor %s does not answer: %s", name, exc)
        return answering

    def detect_sensor(self, probe_s: float = 1.0) -> str:
        """The one configured sensor that answers; an error if none or more than one does."""
        answering = self._answering(self.sensor_names(), probe_s)
        if not answering:
            raise DeviceNotFound(
                "no configured sensor answers",
                hint="check cables and power, or name the mounted sensor with --sensor",
            )
        if len(answering) > 1:
            raise UsageError(
                f"more than one sensor answers ({', '.join(answering)}); cannot tell which is mounted",
                hint="unplug the one that is not on the arm, or name the mounted sensor with --sensor",
            )
        return answering[0]

    def check_sensor(self, name: str, probe_s: float = 1.0) -> None:
        """Make sure the sensor the operator named is the one streaming; a clear error naming the one that is."""
        if self.sensor_answers(name, probe_s):
            return
        others = self._answering([n for n in self.sensor_names() if n != name], probe_s)
        instead = f"; {', '.join(others)} answers instead" if others else ""
        raise DeviceTimeout(
            f"sensor {name!r} is connected but sent no frame within {probe_s:g} s{instead}",
            hint="mount and power the sensor you named, or omit --sensor to use the one that answers"
            if others
            else "check the sensor's power, cable and rig-file settings (CAN channel/bitrate, controller id)",
        )
