"""How the simulators present each registered sensor: its output model, and its real driver on simulated devices.

The sensor registry (:mod:`unitac_rig.rig.sensors`) names these objects by import path (``SensorSpec.simulated``).
Each one serves three places, so none of them names a sensor:

* the fast twin (:class:`~unitac_rig.sim.fast_rig.SimRig`) builds every ``model`` when it starts and calls ``open``
  when a sensor is mounted (devices in lockstep with the virtual clock);
* the real-time twin (:class:`~unitac_rig.sim.twin.rig.RigTwin`) calls ``serve_twin`` for the mounted sensor
  (devices on loopback network transports, in real time) and ``twin_table`` for every sensor's rig-file table;
* ``unitac-rig probe <sensor> --simulated`` calls ``probe`` for a device streaming a synthetic press.

An object's dataclass fields other than ``rng_stream`` are its simulation options (``SimRig(sensor_options=...)``,
``RigTwin(sensor_options=...)``; :func:`with_options`). Both sensors' ``imperfections``
option says which of the real sensor's imperfections its output model has (sim/imperfections.py: ``"all"``, the
default, ``"none"`` for the clean twin, ``"all,-creep"``, ...; ``SimRig(imperfections=...)`` sets it for every
sensor at once). A new sensor's simulated side can
live anywhere under ``unitac_rig.sim`` (or in a test): it has to fit :class:`~unitac_rig.sim.fast_rig.SimulatedSensor`,
and :class:`~unitac_rig.sim.twin.rig.TwinSensor` / ``probe`` where it is to be served there.
"""

from __future__ import annotations

import contextlib
import dataclasses
import itertools
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any, Protocol, TypeVar

import numpy as np

from drivers import layouts
from drivers.clock import VirtualClock
from drivers.sensor import TactileSensor
from unitac_rig.errors import UsageError
from unitac_rig.rig.sensors import SENSORS, get_sensor
from unitac_rig.sim.faults import FaultPlan
from unitac_rig.sim.imperfections import Imperfections
from unitac_rig.sim.sensor_models import PapillArrayModel, UskinModel
from unitac_rig.sim.sensor_signals import SignalSource

_Device = TypeVar("_Device")
Serve = Callable[[_Device], _Device]  # keeps a simulated device running until the twin closes; returns it


class LockstepHost(Protocol):
    """What a simulated sensor's ``open`` uses of the fast twin (:class:`~unitac_rig.sim.fast_rig.SimRig`): its
    virtual clock, its fault injector, a fresh bus channel, and ``serve`` (run a device in lockstep, return it)."""

    clock: VirtualClock
    faults: FaultPlan | None

    def new_channel(self) -> str: ...

    def serve(self, device: _Device) -> _Device: ...


def _option_names(device: object) -> list[str]:
    """A simulated side's options: its dataclass fields other than ``rng_stream``."""
    if not dataclasses.is_dataclass(device) or isinstance(device, type):
        return []
    return sorted(f.name for f in dataclasses.fields(device) if f.name != "rng_stream")


def with_options(device: _Device, sensor: str, options: Mapping[str, Any] | None) -> _Device:
    """``device`` (a sensor's simulated side) with ``options`` set: its dataclass fields other than ``rng_stream``
    (e.g. ``{"transport": "slcan"}`` for the uSkin, ``{"rate_hz": 1000}`` for the PapillArray). A usage error names
    the options the sensor has when one is not among them."""
    if not options:
        return device
    names = _option_names(device)
    unknown = sorted(set(options) - set(names))
    if unknown:
        raise UsageError(
            f"the simulated {sensor} has no option {unknown[0]!r}", hint=f"its options: {', '.join(names) or 'none'}"
        )
    result: _Device = dataclasses.replace(device, **options)  # type: ignore[type-var]
    return result


def configured_sensors(
    options: Mapping[str, Mapping[str, Any]] | None, imperfections: str | None = None
) -> dict[str, Any]:
    """Every registered sensor's simulated side (registry order), each with its ``options[name]`` set; options for
    a sensor the registry does not know, or that cannot be simulated, are a usage error. ``imperfections``
    (sim/imperfections.py's text) goes to every sensor that has that option and whose own options do not set it."""
    for name in options or {}:
        if get_sensor(name).simulated is None:
            raise UsageError(f"sensor {name!r} has no simulated device", hint="its options need a simulated sensor")
    sensors = {}
    for name, spec in SENSORS.items():
        if spec.simulated is None:
            continue
        device = spec.simulated_device()
        own = dict((options or {}).get(name) or {})
        if imperfections is not None and "imperfections" in _option_names(device):
            own.setdefault("imperfections", imperfections)
        sensors[name] = with_options(device, name, own)
    return sensors


_twin_channels = itertools.count(1)
_probe_channels = itertools.count(1)
USKIN_TRANSPORTS = ("can", "slcan", "xela-server")


@dataclass(frozen=True)
class SimulatedUskin:
    """The uSkin's XELA controller board on a CAN channel.

    On the fast twin, ``transport`` ``"can"`` (the default) puts it on a
    :class:`~unitac_rig.sim.devices.lockstep_can.LockstepCanBus` (python-can's bus interface without the ``virtual``
    bus's per-message deep copy), ``"slcan"`` behind a simulated SLCAN adapter that python-can's own ``slcan``
    client opens (slower). The real-time twin serves both of its lab transports at once, the SLCAN adapter on TCP
    ``slcan_port`` and a simulated xela_server on ``xela_server_port``; ``transport`` picks the one its rig file uses
    (``"xela-server"`` by default, or ``"slcan"``), the other is written as a comment.
    """

    rng_stream: int = 2
    transport: str | None = None
    slcan_port: int = 30101  # the socket:// serial URL of the SLCAN adapter on the real-time twin
    xela_server_port: int = 5000  # xela_server's own default port
    imperfections: str = "all"  # which of the real sensor's imperfections the model has (sim/imperfections.py)

    def __post_init__(self) -> None:
        if self.transport is not None and self.transport not in USKIN_TRANSPORTS:
            raise UsageError(
                f"unknown uSkin transport {self.transport!r}", hint=f"use one of: {', '.join(USKIN_TRANSPORTS)}"
            )
        Imperfections.parse(self.imperfections)  # an unknown name is a usage error before anything starts

    def model(self, rng: np.random.Generator) -> UskinModel:
        return UskinModel(rng=rng, imperfections=Imperfections.parse(self.imperfections))

    def open(self, rig: LockstepHost, feed: SignalSource) -> TactileSensor:
        import can

        from drivers.uskin import UskinCanDriver
        from unitac_rig.sim.devices import SimXelaController
        from unitac_rig.sim.devices.lockstep_can import LockstepCanBus

        transport = self.transport or "can"
        if transport not in ("can", "slcan"):
            raise UsageError(f"the fast twin runs the uSkin on can or slcan, not {transport!r}")
        channel = rig.new_channel()
        if transport == "slcan":
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

    def serve_twin(self, host: str, source: SignalSource, serve: Serve[Any]) -> None:
        from unitac_rig.sim.devices import SimSlcanAdapter, SimXelaController, SimXelaServer
        from unitac_rig.sim.twin.bridge import TcpSerialBridge

        channel = f"unitac-twin-{host}-{next(_twin_channels)}"
        adapter = serve(SimSlcanAdapter(channel))
        serve(SimXelaController(channel, source=source, rate_hz=100.0))
        serve(TcpSerialBridge(adapter.url, host, self.slcan_port))
        serve(SimXelaServer(host, self.xela_server_port, source=source, rate_hz=100))

    def twin_table(self, host: str) -> str:
        transport = self.transport or "xela-server"
        if transport not in ("slcan", "xela-server"):
            raise UsageError(f"the real-time twin serves the uSkin through slcan or xela-server, not {transport!r}")
        slcan = (
            f'type = "uskin-can"\ncan_interface = "slcan"\ncan_channel = "socket://{host}:{self.slcan_port}"\n'
            "bitrate = 1000000\n"
        )
        xela = f'type = "uskin-xela-server"\nurl = "ws://{host}:{self.xela_server_port}"\n'
        chosen, other = (slcan, xela) if transport == "slcan" else (xela, slcan)
        other_commented = "".join(f"# {line}\n" for line in other.splitlines())
        return f"{chosen}# the same uSkin through the other transport the twin serves:\n{other_commented}"

    def probe(self, options: Mapping[str, Any], stack: contextlib.ExitStack) -> TactileSensor:
        """The driver on a simulated controller streaming a synthetic press: through xela_server when ``options``
        name its URL, else on CAN (``can_interface`` ``"slcan"``: through a simulated SLCAN adapter)."""
        from drivers.uskin import UskinCanDriver, UskinXelaServerDriver, open_can_bus
        from unitac_rig.sim.devices import SimSlcanAdapter, SimXelaController, SimXelaServer
        from unitac_rig.sim.synthetic_sources import PressSource

        source = PressSource(layouts.USKIN)
        if "url" in options:
            sensor_number = int(options.get("sensor_number", 1))
            server = stack.enter_context(SimXelaServer(source=source, sensor_number=sensor_number))
            return UskinXelaServerDriver(server.url, sensor_number=sensor_number)
        controller_id = int(options.get("controller_id", 1))
        channel = f"unitac-probe-sim-{next(_probe_channels)}"
        stack.enter_context(SimXelaController(channel, controller_id=controller_id, source=source))
        if options.get("can_interface") == "slcan":
            adapter = stack.enter_context(SimSlcanAdapter(channel))
            bus = open_can_bus("slcan", adapter.url, sleep_after_open=0)
        else:
            bus = open_can_bus("virtual", channel)
        driver = UskinCanDriver(bus, controller_id=controller_id, owns_bus=True)
        stack.callback(driver.disconnect)  # shuts the bus down even if connect() fails
        return driver


@dataclass(frozen=True)
class SimulatedPapillArray:
    """The PapillArray hub: behind a ``simpapill://`` pyserial URL on the fast twin, behind a TCP server reached as
    ``socket://HOST:twin_port`` on the real-time twin. ``rate_hz`` is the rate its driver (fast twin) or rig file
    (real-time twin) asks for."""

    rng_stream: int = 3
    rate_hz: int = 100
    twin_port: int = 30100
    imperfections: str = "all"  # which of the real sensor's imperfections the model has (sim/imperfections.py)

    def __post_init__(self) -> None:
        from protocols.papillarray_commands import VALID_RATES_HZ

        if self.rate_hz not in VALID_RATES_HZ:
            raise UsageError(
                f"the PapillArray samples at {', '.join(map(str, sorted(VALID_RATES_HZ)))} Hz, not {self.rate_hz}"
            )
        Imperfections.parse(self.imperfections)

    def model(self, rng: np.random.Generator) -> PapillArrayModel:
        return PapillArrayModel(rng=rng, imperfections=Imperfections.parse(self.imperfections))

    def open(self, rig: LockstepHost, feed: SignalSource) -> TactileSensor:
        from drivers.papillarray import PapillArrayDriver
        from unitac_rig.sim.devices.papillarray import SimPapillArrayHub

        hub = rig.serve(SimPapillArrayHub(source=feed, clock=rig.clock, faults=rig.faults))
        return PapillArrayDriver(hub.url, rate_hz=self.rate_hz, clock=rig.clock)

    def serve_twin(self, host: str, source: SignalSource, serve: Serve[Any]) -> None:
        from unitac_rig.sim.devices import SimPapillArrayHub
        from unitac_rig.sim.twin.bridge import TcpSerialBridge

        hub = serve(SimPapillArrayHub(source=source))
        serve(TcpSerialBridge(hub.url, host, self.twin_port))

    def twin_table(self, host: str) -> str:
        return f'type = "papillarray"\nport = "socket://{host}:{self.twin_port}"\nrate_hz = {self.rate_hz}\n'

    def probe(self, options: Mapping[str, Any], stack: contextlib.ExitStack) -> TactileSensor:
        """The driver on a simulated hub streaming a synthetic press in ``options``' slot, at its rate."""
        from drivers.papillarray import PapillArrayDriver
        from unitac_rig.sim.devices import SimPapillArrayHub
        from unitac_rig.sim.synthetic_sources import PressSource

        slot = int(options.get("slot", 0))
        hub = stack.enter_context(SimPapillArrayHub(source=PressSource(layouts.PAPILLARRAY), slot=slot))
        return PapillArrayDriver(hub.url, slot=slot, rate_hz=int(options.get("rate_hz", 100)))


USKIN = SimulatedUskin()
PAPILLARRAY = SimulatedPapillArray()
