"""The simulated rig: a virtual clock, the simulated arm, the press scene, and simulated sensors on real transports.

The collection code cannot tell it from hardware: the arm implements :class:`drivers.arm.Arm`, and each sensor is the
*real* driver (:class:`drivers.uskin.UskinCanDriver` on a python-can bus, a
:class:`~unitac_rig.sim.devices.lockstep_can.LockstepCanBus`, or
:class:`drivers.papillarray.PapillArrayDriver` on a ``simpapill://`` pyserial URL) reading the bytes a simulated
device encodes from what the scene says the pad feels. Everything runs on one thread in lockstep with the virtual
clock: the arm's ``wait_period`` advances the clock by 2 ms, due sensor samples are emitted into the transport, and
the press loop polls the driver. A run is therefore deterministic for a given seed and far faster than real time.
"""

from __future__ import annotations

import itertools
import logging
import zlib
from collections.abc import Mapping
from dataclasses import replace
from typing import Any, Protocol, TypeVar, runtime_checkable

import numpy as np

from drivers.arm import Arm
from drivers.clock import VirtualClock
from drivers.layouts import SensorLayout
from drivers.sensor import TactileSensor
from unitac_rig.errors import UsageError
from unitac_rig.rig.base import Rig
from unitac_rig.rig.config import ObjectPlacement, RigConfig
from unitac_rig.rig.objects import DEFAULT_OBJECT_CENTER_M, ObjectSpec
from unitac_rig.rig.poses import approach_direction, pose_from, press_rotation
from unitac_rig.rig.sensors import SENSORS, SensorSpec, sensor_layout
from unitac_rig.sim.fast_sensors import configured_sensors
from unitac_rig.sim.faults import FaultInjector, FaultPlan
from unitac_rig.sim.imperfections import (
    CLEAN,
    SKIN_FLANK_FRICTION,
    Imperfections,
    as_imperfections,
    mount_offset_mm,
    mount_seed,
    print_seed,
    printed_object,
)
from unitac_rig.sim.scene import PressScene, SceneParams, TaxelLoads
from unitac_rig.sim.sensor_signals import SensorSample, SignalSource
from unitac_rig.sim.world import NO_WRENCH

log = logging.getLogger(__name__)

_instance_ids = itertools.count()
_Device = TypeVar("_Device")


class SensorOutputModel(Protocol):
    """What a taxel feels (N) -> what the sensor reports, in its layout's units (sim/sensor_models.py)."""

    layout: SensorLayout

    def sample(self, loads: TaxelLoads, t_ns: int) -> SensorSample:
        """The reading for ``loads`` at device time ``t_ns`` (ns: the elastomer's creep and the drift need it)."""
        ...


@runtime_checkable
class SimulatedSensor(Protocol):
    """A registered sensor's simulated side (the registry's ``simulated`` entry names one; see sim/fast_sensors.py).

    ``rng_stream`` keys the sensor's own random stream under the rig seed (``default_rng([seed, rng_stream])``), so
    adding a sensor leaves the others' noise as it was. It must be unique: the arm draws from stream 1, the
    scenes from 4, the uSkin 2 and the PapillArray 3. A model with ``use_noise_stream(rng)`` draws its per-sample
    noise from a stream of each session's own from the session's mount on (:func:`noise_seed`).
    """

    rng_stream: int

    def model(self, rng: np.random.Generator) -> SensorOutputModel:
        """The sensor's output model, its static parts (baselines, gains, offsets) drawn from ``rng``."""
        ...

    def open(self, rig: SimRig, feed: SignalSource) -> TactileSensor:
        """Serve the sensor's simulated device(s) (``rig.serve``) and return its real driver on them, unconnected."""
        ...


def _simulated_sensor(spec: SensorSpec, device: object) -> SimulatedSensor:
    """``device`` (the spec's simulated side), checked to be one the fast twin can mount."""
    if not isinstance(device, SimulatedSensor):
        raise UsageError(
            f"sensor {spec.name!r}: {spec.simulated} is not a simulated sensor",
            hint="name an object with rng_stream, model() and open() (see unitac_rig/sim/fast_sensors.py)",
        )
    return device


HOME_DISTANCE_M = 0.08  # both twins' arms start this far from the object's axis, facing it from approach angle 0


def home_pose(placement: ObjectPlacement) -> np.ndarray:
    """Where a twin's arm starts: the pad at the press height, facing the object from approach angle 0."""
    u = approach_direction(0.0)
    position = np.array([*placement.center_m, placement.press_height_m]) + u * HOME_DISTANCE_M
    return pose_from(position, press_rotation(-u))


def scene_seed(seed: int, object_id: str, sensor: str, rotation_deg: float) -> list[int]:
    """Seed of the sensor mount's errors (pad pitch) in one session: what is mounted, not how many rigs ran before."""
    return [seed, 4, zlib.crc32(object_id.encode()), zlib.crc32(sensor.encode()), round(rotation_deg * 1000) % 2**32]


def noise_seed(seed: int, object_id: str, sensor: str, rotation_deg: float, device: str) -> list[int]:
    """Seed of ``device``'s per-sample draws (white noise, drift steps) in one session (``object_id`` at
    ``rotation_deg`` pressed with ``sensor``); ``device`` is the sensor's name or ``"arm"`` (the wrist F/T). A real
    sensor never reads the same noise twice; keyed by the unit's stream alone, every ``collect`` process with the
    same seed read one noise and drift path in every session (issue 38: the seen sessions and the unseen prism's
    first rotation drifted alike). The units' static draws (baselines, gains, offsets, the F/T's first bias) stay
    per unit."""
    return [
        seed,
        8,
        zlib.crc32(device.encode()),
        zlib.crc32(object_id.encode()),
        zlib.crc32(sensor.encode()),
        round(rotation_deg * 1000) % 2**32,
    ]


def placement_seed(seed: int, object_id: str, rotation_deg: float) -> list[int]:
    """Seed of the object's centring error: one per placement of the object, whichever sensor presses it. The paper
    fixes each object at a known position through a mounting adapter on the breadboard and swaps the sensor, not the
    adapter, so both sensors' sessions of an object press it where the adapter puts it (even if the object is taken
    out between them, as `unitac-rig campaign` asks); drawing it per session made the sensors' lateral readings
    disagree."""
    return [seed, 5, zlib.crc32(object_id.encode()), round(rotation_deg * 1000) % 2**32]


def seeded_scene(
    obj: ObjectSpec,
    rotation_deg: float,
    sensor: str,
    *,
    seed: int,
    params: SceneParams | None = None,
    object_center_m: tuple[float, float] = DEFAULT_OBJECT_CENTER_M,
    shared_placement: bool = True,
    imperfections: Imperfections = CLEAN,
) -> PressScene:
    """The scene the simulated rig presses for this object, rotation and sensor, its errors seeded as
    :func:`placement_seed` and :func:`scene_seed` say. ``shared_placement`` False draws the centring error from the
    session's own generator (the rig before the placement was shared; benchmarks compare the two).
    ``imperfections``: with ``print_tolerance`` the object is one print of it (seeded per object,
    sim/imperfections.py), with ``mount_offset`` the pad sits off the tool axis by a seeded amount per session."""
    placement = np.random.default_rng(placement_seed(seed, obj.id, rotation_deg)) if shared_placement else None
    if imperfections.print_tolerance:
        obj = printed_object(obj, np.random.default_rng(print_seed(seed, obj.id)))
    if imperfections.flank_friction:
        params = replace(params or SceneParams(), skin_flank_friction=SKIN_FLANK_FRICTION)
    if imperfections.mount_offset:
        params = params or SceneParams()
        extra_mm = mount_offset_mm(np.random.default_rng(mount_seed(seed, obj.id, sensor, rotation_deg)))
        params = replace(
            params,
            skin_pad_offset_mm=params.skin_pad_offset_mm + extra_mm,
            pillar_pad_offset_mm=params.pillar_pad_offset_mm + extra_mm,
        )
    return PressScene(
        obj,
        rotation_deg,
        sensor_layout(sensor),
        object_center_m=object_center_m,
        params=params,
        rng=np.random.default_rng(scene_seed(seed, obj.id, sensor, rotation_deg)),
        placement_rng=placement,
    )


class _SceneSwitch:
    """The world the simulated arm presses into; swapped when the object, rotation or sensor changes."""

    def __init__(self) -> None:
        self.scene: Any = None

    def wrench_on_tool(self, tcp_pose: np.ndarray) -> np.ndarray:
        if self.scene is None:
            return NO_WRENCH
        result: np.ndarray = self.scene.wrench_on_tool(tcp_pose)
        return result


class _SensorFeed:
    """SignalSource for one simulated sensor: the scene's loads through that sensor's (persistent) output model."""

    def __init__(self, rig: SimRig, sensor: str, model: SensorOutputModel) -> None:
        self.rig = rig
        self.sensor = sensor
        self.model = model

    def sample(self, t_ns: int) -> SensorSample:
        scene = self.rig.world.scene
        if scene is None or self.rig.mounted_sensor != self.sensor:
            shape = self.model.layout.frame_shape
            loads = TaxelLoads(np.zeros(shape), np.zeros(shape) if self.model.layout.has_displacement else None)
        else:
            loads = scene.taxel_loads(self.rig.sim_arm.true_tcp_pose())
        return self.model.sample(loads, t_ns)


class SimRig(Rig):
    """Every registered sensor with a simulated device is available; one is mounted at a time, as on the real arm."""

    simulated = True

    def __init__(
        self,
        config: RigConfig,
        *,
        seed: int = 0,
        faults: FaultPlan | None = None,
        sensor_options: Mapping[str, Mapping[str, Any]] | None = None,
        imperfections: Imperfections | str | None = None,
    ) -> None:
        """``faults`` damages every simulated sensor transport. ``sensor_options`` sets each sensor's simulation
        options by name (its simulated side's fields, sim/fast_sensors.py): e.g. ``{"uskin": {"transport": "slcan"}}``
        (python-can's own slcan client on a ``simslcan://`` serial URL instead of the in-process CAN bus),
        ``{"papillarray": {"rate_hz": 1000}}``. ``imperfections`` (sim/imperfections.py): which of the real
        sensors' and rig's imperfections the twin has, every one by default; ``"none"`` is the clean twin. A
        sensor's own ``imperfections`` option, where given, wins for its output model."""
        from unitac_rig.sim.arm import SimArm

        self.config = config
        self.seed = seed
        self.clock = VirtualClock()
        self._rng = np.random.default_rng(seed)
        self.world = _SceneSwitch()
        self.mounted_sensor: str | None = None
        self._instance = next(_instance_ids)
        home = home_pose(config.object)
        self.sim_arm = SimArm(self.world, clock=self.clock, rng=np.random.default_rng([seed, 1]), start_pose=home)
        self.imperfections = as_imperfections(imperfections)
        self._simulated: dict[str, SimulatedSensor] = {
            name: _simulated_sensor(SENSORS[name], device)
            for name, device in configured_sensors(sensor_options, self.imperfections.text).items()
        }
        self._models = {
            name: device.model(np.random.default_rng([seed, device.rng_stream]))
            for name, device in self._simulated.items()
        }
        self._noise_session: tuple[str, float, str] | None = None  # the session the noise streams are keyed to
        self.faults = faults
        self._devices: list[Any] = []
        self._object: ObjectSpec | None = None
        self._rotation = 0.0

    @property
    def arm(self) -> Arm:
        return self.sim_arm

    def sensor_names(self) -> list[str]:
        return list(self._simulated)

    def mount(self, obj: ObjectSpec, rotation_deg: float, sensor_name: str) -> None:
        self._object, self._rotation = obj, rotation_deg
        self.mounted_sensor = sensor_name
        self.world.scene = seeded_scene(
            obj,
            rotation_deg,
            sensor_name,
            seed=self.seed,
            object_center_m=self.config.object.center_m,
            imperfections=self.imperfections,
        )
        self._key_noise_stream(obj.id, rotation_deg, sensor_name)

    def _key_noise_stream(self, object_id: str, rotation_deg: float, sensor_name: str) -> None:
        """Give the mounted sensor and the wrist F/T noise streams of this session's own when the session changes
        (not when the same one is mounted again, which would replay its noise). A registered model without
        ``use_noise_stream`` keeps its unit stream."""
        session = (object_id, rotation_deg, sensor_name)
        if self._noise_session == session:
            return
        self._noise_session = session

        def stream(device: str) -> np.random.Generator:
            return np.random.default_rng(noise_seed(self.seed, object_id, sensor_name, rotation_deg, device))

        self.sim_arm.use_noise_stream(stream("arm"))
        use_stream = getattr(self._models.get(sensor_name), "use_noise_stream", None)
        if use_stream is not None:
            use_stream(stream(sensor_name))

    def open_sensor(self, name: str) -> TactileSensor:
        if name not in self._simulated:
            names = ", ".join(self._simulated)
            raise UsageError(f"the simulated rig has no sensor {name!r}", hint=f"use one of: {names}")
        self._close_devices()
        self.mounted_sensor = name
        if self._object is not None:
            self.mount(self._object, self._rotation, name)
        sensor = self._simulated[name].open(self, _SensorFeed(self, name, self._models[name]))
        sensor.connect()
        return sensor

    def new_channel(self) -> str:
        """A name no other simulated transport of this process uses (virtual CAN channel, serial URL stem)."""
        return f"unitac-sim-{self._instance}-{len(self._devices)}"

    def serve(self, device: _Device) -> _Device:
        """Keep a simulated device running until the sensor is swapped or the rig closes; returns it."""
        self._devices.append(device)
        return device

    def sensor_fault_injectors(self) -> list[FaultInjector]:
        """The fault injectors of the open sensor's simulated devices (tests force stalls and unplugs by hand)."""
        return [device.faults for device in self._devices if isinstance(getattr(device, "faults", None), FaultInjector)]

    def _close_devices(self) -> None:
        for device in self._devices:
            device.close()
        self._devices.clear()

    def close(self) -> None:
        try:
            self.sim_arm.close()
        finally:
            self._close_devices()
