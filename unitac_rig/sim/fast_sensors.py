"""How the fast twin simulates each registered sensor: its output model, and its real driver on a simulated device.

The sensor registry (:mod:`unitac_rig.rig.sensors`) names these objects by import path; :class:`SimRig
<unitac_rig.sim.fast_rig.SimRig>` builds every model when it starts and calls ``open`` when a sensor is mounted. A
new sensor's simulated device can live anywhere under ``unitac_rig.sim``: it only has to fit
:class:`~unitac_rig.sim.fast_rig.SimulatedSensor`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from drivers.sensor import TactileSensor
from unitac_rig.sim.sensor_models import PapillArrayModel, UskinModel
from unitac_rig.sim.signals import SignalSource

if TYPE_CHECKING:
    from unitac_rig.sim.fast_rig import SimRig


@dataclass(frozen=True)
class SimulatedUskin:
    """The uSkin's XELA controller on a :class:`~unitac_rig.sim.devices.lockstep_can.LockstepCanBus` (python-can's
    bus interface without the ``virtual`` bus's per-message deep copy), or behind a simulated SLCAN adapter."""

    rng_stream: int = 2

    def model(self, rng: np.random.Generator) -> UskinModel:
        return UskinModel(rng=rng)

    def open(self, rig: SimRig, feed: SignalSource) -> TactileSensor:
        import can

        from drivers.uskin import UskinCanDriver
        from unitac_rig.sim.devices import SimXelaController
        from unitac_rig.sim.devices.lockstep_can import LockstepCanBus

        channel = rig.new_channel()
        if rig.uskin_transport == "slcan":
            from unitac_rig.sim.devices import SimSlcanAdapter

            adapter = rig.serve(SimSlcanAdapter(channel, clock=rig.clock, faults=rig.faults))
            controller_faults, controller_bus = None, None  # the adapter bridges to a python-can virtual channel
            bus = can.Bus(interface="slcan", channel=adapter.url, bitrate=1_000_000)
        else:
            controller_faults = rig.faults
            bus = LockstepCanBus(channel, clock=rig.clock)
            controller_bus = LockstepCanBus(channel, clock=rig.clock)
        rig.serve(
            SimXelaController(
                channel, source=feed, clock=rig.clock, rate_hz=100.0, faults=controller_faults, bus=controller_bus
            )
        )
        return UskinCanDriver(bus, clock=rig.clock, owns_bus=True)


@dataclass(frozen=True)
class SimulatedPapillArray:
    """The PapillArray hub behind a ``simpapill://`` pyserial URL."""

    rng_stream: int = 3

    def model(self, rng: np.random.Generator) -> PapillArrayModel:
        return PapillArrayModel(rng=rng)

    def open(self, rig: SimRig, feed: SignalSource) -> TactileSensor:
        from drivers.papillarray import PapillArrayDriver
        from unitac_rig.sim.devices.papillarray import SimPapillArrayHub

        hub = rig.serve(SimPapillArrayHub(source=feed, clock=rig.clock, faults=rig.faults))
        return PapillArrayDriver(hub.url, rate_hz=rig.papillarray_rate_hz, clock=rig.clock)


USKIN = SimulatedUskin()
PAPILLARRAY = SimulatedPapillArray()
