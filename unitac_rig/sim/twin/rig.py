"""The real-time twin of the whole rig: the controller twin and the mounted sensor, on loopback network transports.

:class:`RigTwin` starts a :class:`~unitac_rig.sim.twin.ControllerTwin` with an object in front of the arm and serves
the mounted sensor from the same scene, on the transports a lab uses. What those are is the sensor's own business
(its simulated side, named by the sensor registry: ``serve_twin`` and ``twin_table`` in sim/fast_sensors.py):

* **PapillArray**: the simulated hub (:class:`~unitac_rig.sim.devices.SimPapillArrayHub`, the PTS v2.0 packets and
  ASCII commands) behind a TCP server, reached with the pyserial URL ``socket://HOST:PORT``;
* **uSkin**: the simulated XELA controller board on a CAN channel, reached two ways at once: through a simulated
  SLCAN adapter (:class:`~unitac_rig.sim.devices.SimSlcanAdapter`) behind a TCP server, which python-can's own
  ``slcan`` interface opens with ``channel = "socket://HOST:PORT"``, and through a simulated xela_server
  (:class:`~unitac_rig.sim.devices.SimXelaServer`, WebSocket ``ws://HOST:PORT``).

Only the mounted sensor is served (the others are "unplugged"), so ``collect`` without ``--sensor`` detects it as on
the real rig. :meth:`RigTwin.rig_file` is the rig file that points the unchanged hardware code path
(:class:`~unitac_rig.rig.hardware.HardwareRig`, :class:`drivers.ur5e.UR5eArm`, the real drivers) at all of it.

Where the sensors run: in this process (threads), while the controller runs in its own. The sensors read the pad
pose from the controller's shared ground-truth block at every sample (a sequence-locked read, no round trip) and
feel it through their own copy of the scene, built from the same :class:`~unitac_rig.sim.twin.SceneSpec` (object,
rotation, pad, placement, seed) as the controller's. Two processes keep the 500 Hz controller loop off the GIL the
sensor threads (and a uSkin at 2,400 CAN frames a second) need; the price is two identical scene tables.
"""

from __future__ import annotations

import dataclasses
import logging
from collections.abc import Callable, Mapping
from types import TracebackType
from typing import Any, Protocol, runtime_checkable

import numpy as np

from unitac_rig.errors import UsageError
from unitac_rig.rig.config import ObjectPlacement, toml_value
from unitac_rig.rig.objects import get_object
from unitac_rig.rig.sensors import sensor_layout, sensor_names
from unitac_rig.sim.fast_rig import home_pose, noise_seed
from unitac_rig.sim.fast_sensors import configured_sensors
from unitac_rig.sim.sensor_signals import SignalSource
from unitac_rig.sim.twin.handle import ControllerTwin
from unitac_rig.sim.twin.params import ControllerParams, SceneSpec
from unitac_rig.sim.twin.world import build_scene

logger = logging.getLogger(__name__)

DEFAULT_HOST = "127.0.0.210"  # examples/twin.toml points here
SensorOptions = Mapping[str, Mapping[str, Any]]  # sensor name -> its simulation options (sim/fast_sensors.py)


@runtime_checkable
class TwinSensor(Protocol):
    """A registered sensor's simulated side, as the real-time twin serves it (see sim/fast_sensors.py)."""

    rng_stream: int  # its noise stream under the twin's seed: the fast twin's, so both twins draw alike

    def model(self, rng: Any) -> Any:
        """What a taxel feels (N) -> what the sensor reports (sim/sensor_models.py)."""
        ...

    def serve_twin(self, host: str, source: SignalSource, serve: Callable[[Any], Any]) -> None:
        """Serve the sensor's devices on ``host`` (fixed ports), feeding them ``source``; ``serve`` keeps each one
        until the twin closes."""
        ...

    def twin_table(self, host: str) -> str:
        """The body of its ``[sensors.<name>]`` rig-file table, pointing the real driver at what it serves."""
        ...


def twin_sensors(options: SensorOptions | None = None) -> dict[str, TwinSensor]:
    """Every registered sensor the real-time twin can serve (registry order), with ``options`` set."""
    return {name: s for name, s in configured_sensors(options).items() if isinstance(s, TwinSensor)}


class RigTwin:
    """The controller twin with ``object_id`` in front of the arm, and the mounted ``sensor`` served on loopback.

    ``placement`` is where the printed rig file says the object stands (the rig file's defaults if None); ``params``
    configures the controller. Raises :class:`~unitac_rig.sim.twin.AddressTaken` (a DeviceError) when the address or a
    port is in use.
    """

    def __init__(
        self,
        object_id: str,
        *,
        rotation_deg: float | None = None,
        sensor: str | None = None,
        host: str = DEFAULT_HOST,
        seed: int = 0,
        placement: ObjectPlacement | None = None,
        params: ControllerParams | None = None,
        sensor_options: SensorOptions | None = None,
    ) -> None:
        """``sensor``: the mounted one (the registry's first by default). ``sensor_options``: each sensor's
        simulation options by name (its ports, the uSkin's ``transport`` in the rig file, the PapillArray's
        ``rate_hz``), checked before anything starts."""
        obj = get_object(object_id)
        self._sensors = twin_sensors(sensor_options)
        sensor = sensor_names()[0] if sensor is None else sensor
        sensor_layout(sensor)  # an unknown sensor is a usage error before anything starts
        if sensor not in self._sensors:
            raise UsageError(
                f"the real-time twin cannot serve sensor {sensor!r}", hint=f"it serves: {', '.join(self._sensors)}"
            )
        for device in self._sensors.values():
            device.twin_table(host)  # an option the rig file cannot say is a usage error before anything starts
        self.sensor_options = dict(sensor_options or {})
        self.object_id = object_id
        self.rotation_deg = float(obj.rotations_deg[0] if rotation_deg is None else rotation_deg)
        self.sensor = sensor
        self.host = host
        self.seed = seed
        self.placement = placement or ObjectPlacement()
        self.spec = SceneSpec(
            object_id, rotation_deg=self.rotation_deg, sensor=sensor, center_m=self.placement.center_m, seed=seed
        )
        self._devices: list[Any] = []
        self._source: Any = None
        self.controller = ControllerTwin(
            host, scene=self.spec, start_pose=home_pose(self.placement), params=params, seed=seed
        )
        try:
            self._start_sensor()
        except BaseException:
            self.close()
            raise

    # ---- sensors --------------------------------------------------------------------------------------------

    def _start_sensor(self) -> None:
        from unitac_rig.sim.source import SceneSensorSource

        device = self._sensors[self.sensor]
        model = device.model(np.random.default_rng([self.seed, device.rng_stream]))
        use_stream = getattr(model, "use_noise_stream", None)
        if use_stream is not None:  # the session's own noise, as on the fast twin
            session = (self.object_id, self.sensor, self.rotation_deg)
            use_stream(np.random.default_rng(noise_seed(self.seed, *session, self.sensor)))
        self._source = SceneSensorSource(build_scene(self.spec), model, self.controller.true_pad_pose)
        device.serve_twin(self.host, self._source, self._serve)

    def _serve(self, device: Any) -> Any:
        self._devices.append(device)
        return device

    # ---- hooks ----------------------------------------------------------------------------------------------

    def set_placement_error(self, dx_m: float, dy_m: float) -> None:
        """Move the object (dx, dy) m from where the rig file says it stands: the arm and the sensor feel it."""
        self.controller.set_placement_error(dx_m, dy_m)
        self.spec = dataclasses.replace(self.spec, placement_error_m=(dx_m, dy_m))
        if self._source is not None:
            self._source.scene = build_scene(self.spec)

    # ---- the rig file ---------------------------------------------------------------------------------------

    def rig_file(
        self, tables: dict[str, dict[str, Any]] | None = None, sensor_options: SensorOptions | None = None
    ) -> str:
        """The rig file (TOML) that points the hardware code path at this twin (``tables``: see rig_file_text).
        ``sensor_options`` change what the file says over the twin's own (e.g. ``{"uskin": {"transport": "slcan"}}``:
        the uSkin's other transport, which the twin serves too)."""
        options = {
            name: {**self.sensor_options.get(name, {}), **extra} for name, extra in (sensor_options or {}).items()
        }
        return rig_file_text(
            self.host, self.placement, self.controller.params, tables, {**self.sensor_options, **options}
        )

    # ---- lifetime -------------------------------------------------------------------------------------------

    def close(self) -> None:
        """Unplug the sensors, then stop the controller. Disconnect the hosts' clients first (see ControllerTwin)."""
        for device in reversed(self._devices):
            try:
                device.close()
            except Exception:
                logger.exception("closing %r failed", device)
        self._devices.clear()
        controller = getattr(self, "controller", None)
        if controller is not None:
            controller.close()

    def __enter__(self) -> RigTwin:
        return self

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.close()


def rig_file_text(
    host: str,
    placement: ObjectPlacement,
    params: ControllerParams | None = None,
    tables: dict[str, dict[str, Any]] | None = None,
    sensor_options: SensorOptions | None = None,
) -> str:
    """The rig file for a rig twin on ``host``: every sensor it can serve is listed (it serves only the mounted one),
    each table as its simulated side writes it with ``sensor_options`` (e.g. the uSkin through xela_server, its
    SLCAN route as a comment). The arm's TCP offset and payload are what the twin's pendant is set to, so the driver's
    read-back check at connect passes. ``tables`` (e.g. the ``press`` and ``limits`` of a rig file being rehearsed)
    are written after ``[object]``.
    """
    params = params or ControllerParams()
    tcp = params.tool_offset if params.pendant_tcp is None else params.pendant_tcp
    tcp_text = ", ".join(repr(float(v)) for v in tcp)
    sensors = "".join(
        f"[sensors.{name}]\n{device.twin_table(host)}\n" for name, device in twin_sensors(sensor_options).items()
    )
    center = ", ".join(repr(float(v)) for v in placement.center_m)
    return (
        "# Rig file of the real-time twin (`unitac-rig twin`): the hardware code path, pointed at loopback.\n"
        "# Start it with `unitac-rig twin --object OBJECT [--sensor papillarray]`, then run\n"
        "# `unitac-rig collect --rig <this file> --object OBJECT` exactly as on the robot. The twin serves only the\n"
        "# mounted sensor; `collect` without --sensor detects it, as on the real rig.\n"
        'name = "twin"\n'
        "\n"
        "[arm]\n"
        f'host = "{host}"  # the controller twin: dashboard 29999, script 30003, RTDE 30004\n'
        "frequency_hz = 500.0\n"
        f"tcp_offset = [{tcp_text}]  # as set on the (twin's) pendant: m, rad from the flange\n"
        f"payload_kg = {float(params.payload_kg)!r}\n"
        "\n"
        f"{sensors}"
        "[object]  # where the twin's scene puts the object\n"
        f"center_m = [{center}]\n"
        f"press_height_m = {float(placement.press_height_m)!r}\n"
        + _toml_values(placement.model_dump(mode="json", exclude={"center_m", "press_height_m"}))
        + "".join(f"\n[{name}]\n{_toml_values(values)}" for name, values in (tables or {}).items())
    )


def _toml_values(values: dict[str, Any]) -> str:
    """``key = value`` lines of one flat table (numbers, strings, booleans and lists of them)."""
    return "".join(f"{key} = {toml_value(value)}\n" for key, value in values.items())
