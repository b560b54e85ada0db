"""What a registered sensor declares: :class:`SensorSpec`, and the base of every ``[sensors.<name>]`` table."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Literal

from pydantic import BaseModel, ConfigDict

from drivers.clock import Clock
from drivers.layouts import SensorLayout
from drivers.sensor import TactileSensor
from unitac_rig.errors import UsageError
from unitac_rig.rig.lazy import load


class StrictTable(BaseModel):
    """The base of every table a user writes (rig file, sensor tables, import conventions): an unknown key fails (a
    typo in a safety limit or a port must not pass silently), and every number is finite (a NaN or inf limit would
    switch its check off silently: every comparison with NaN is False; nothing passes inf). Defined here, the lowest
    module the rig file's tables share."""

    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)


class SensorConfigBase(StrictTable):
    """One ``[sensors.<name>]`` table of the rig file; subclasses fix ``type`` to a literal that tells them apart."""

    type: str


#: hardware driver factory: a validated config table and the rig's clock -> the driver, not yet connected
DriverFactory = Callable[[SensorConfigBase, Clock], TactileSensor]


@dataclass(frozen=True)
class SyntheticResponse:
    """How the closed-form synthetic contacts (:mod:`unitac_rig.learning.synthetic_data`, for smoke tests and
    benchmarks; not the simulator) turn a taxel's load in N into this sensor's reading.

    ``gain_normal`` / ``gain_shear``: sensor units per N (1.0 for a sensor that reads newtons). ``spread``: the
    kernel a continuous skin spreads the normal load over neighbouring taxels with, along rows and columns (empty:
    separate taxels). ``noise``: standard deviation of the reading, sensor units. ``proud_centre_mm``: how far the
    centre taxel stands out of the pad (the PapillArray's centre pillar), so it touches first.
    """

    gain_normal: float = 1.0
    gain_shear: float = 1.0
    spread: tuple[float, ...] = ()
    noise: float = 0.01
    proud_centre_mm: float = 0.0


@dataclass(frozen=True)
class SensorSpec:
    """Everything the application keys by a sensor's name, in one place.

    ``layout`` (drivers/layouts.py) gives the name, taxel grid, pitch and units. ``config_types`` are the rig-file
    tables this sensor accepts (one per transport), told apart by their ``type``; their fields are also the options
    of ``unitac-rig probe <name>``. ``open_driver`` builds the real driver from one of them. ``simulated`` names the
    sensor's simulated side by import path (``"unitac_rig.sim.fast_sensors:USKIN"``: its output model, and its
    devices on the fast twin, the real-time twin and ``probe --simulated``), or is None when it cannot be simulated.

    ``pad`` is what the simulated scene presses: a continuous ``"skin"`` (the load spreads, the skin drags) or
    separate ``"pillars"``. ``geometry_dropout`` is the dropout of the contact-geometry head trained on this
    sensor's latent (the paper's downstream task). ``synthetic`` renders its frames in the synthetic contacts.
    """

    layout: SensorLayout
    config_types: tuple[type[SensorConfigBase], ...]
    open_driver: DriverFactory
    simulated: str | None = None
    pad: Literal["skin", "pillars"] = "skin"
    geometry_dropout: float = 0.2
    synthetic: SyntheticResponse = field(default_factory=SyntheticResponse)

    @property
    def name(self) -> str:
        return self.layout.name

    def simulated_device(self) -> object:
        """The simulated device the fast twin mounts for this sensor (imported on first use)."""
        if self.simulated is None:
            raise UsageError(f"sensor {self.name!r} has no simulated device", hint="use it on a hardware rig")
        return load(self.simulated)
