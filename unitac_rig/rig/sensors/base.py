"""What a registered sensor declares: :class:`SensorSpec`, and the base of every ``[sensors.<name>]`` table."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from pydantic import BaseModel, ConfigDict

from drivers.clock import Clock
from drivers.layouts import SensorLayout
from drivers.sensor import TactileSensor
from unitac_rig.errors import UsageError
from unitac_rig.rig.lazy import load


class SensorConfigBase(BaseModel):
    """One ``[sensors.<name>]`` table of the rig file; subclasses fix ``type`` to a literal that tells them apart.

    Unknown keys fail, as everywhere in the rig file: a typo in a port must not pass silently.
    """

    model_config = ConfigDict(extra="forbid", frozen=True)

    type: str


#: hardware driver factory: a validated config table and the rig's clock -> the driver, not yet connected
DriverFactory = Callable[[SensorConfigBase, Clock], TactileSensor]


@dataclass(frozen=True)
class SensorSpec:
    """Everything the application keys by a sensor's name, in one place.

    ``layout`` (drivers/layouts.py) gives the name, taxel grid, pitch and units. ``config_types`` are the rig-file
    tables this sensor accepts (one per transport), told apart by their ``type``. ``open_driver`` builds the real
    driver from one of them. ``simulated`` names the sensor's simulated device on the fast twin by import path
    (``"unitac_rig.sim.fast_sensors:USKIN"``), or is None when the twin cannot simulate it.
    """

    layout: SensorLayout
    config_types: tuple[type[SensorConfigBase], ...]
    open_driver: DriverFactory
    simulated: str | None = None

    @property
    def name(self) -> str:
        return self.layout.name

    def simulated_device(self) -> object:
        """The simulated device the fast twin mounts for this sensor (imported on first use)."""
        if self.simulated is None:
            raise UsageError(f"sensor {self.name!r} has no simulated device", hint="use it on a hardware rig")
        return load(self.simulated)
