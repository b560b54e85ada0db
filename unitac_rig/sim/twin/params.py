"""Settings of the controller twin: plain, JSON-able values (they cross into the controller's own process).

Numbers are tagged like the rest of the simulator: [S] stated by a source (hardware-facts.md), [I] assumed.
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass, field
from typing import Any

from drivers.layouts import SensorLayout

# Ports a UR controller serves; ur_rtde has no port arguments for them (hardware-facts 3.8) [S].
DASHBOARD_PORT = 29999
SCRIPT_PORT = 30003
RTDE_PORT = 30004
CONTROLLER_PORTS = (DASHBOARD_PORT, SCRIPT_PORT, RTDE_PORT)


@dataclass(frozen=True)
class ControllerParams:
    """What the controller twin answers and how its safety system acts."""

    # PolyScope 5.11 (e-Series): RTDE major 5 > 3 makes ur_rtde default to 500 Hz; 5.6+ makes it read the serial
    # number and check remote control [S: 3.4, 3.8].
    polyscope_version: str = "5.11.0.108249"
    serial_number: str = "20185500999"  # digits, as ur_rtde requires [S]
    robot_model: str = "UR5"
    remote_control: bool = True  # pendant in Remote Control mode; False = Local: connect and script uploads refused
    # A UR ships with a 150 N "Force" safety limit in normal mode [I, hardware-facts 3.6 / UR defaults]; the twin
    # trips a protective stop when the true contact force exceeds it.
    protective_stop_n: float = 150.0
    # "Cannot unlock protective stop until 5s after occurrence" (PolyScope dashboard) [I]; tests may shorten it.
    unlock_delay_s: float = 5.0
    # UR5e reach: 850 mm from the shoulder axis to the flange [I, UR5e datasheet as commonly quoted]; the shoulder is
    # 162.5 mm above the base (UR5e d1). A target out of reach is a runtime error; leaving reach in motion a
    # protective stop.
    reach_m: float = 0.85
    shoulder_height_m: float = 0.1625
    # The physical tool: pad centre relative to the flange (m, rad) [I]; the pendant's TCP starts equal to it
    # unless ``pendant_tcp`` says otherwise (a misconfigured pendant).
    tool_offset: tuple[float, ...] = (0.0, 0.0, 0.05, 0.0, 0.0, 0.0)
    pendant_tcp: tuple[float, ...] | None = None
    payload_kg: float = 0.3
    payload_cog_m: tuple[float, float, float] = (0.0, 0.0, 0.025)
    # A late cycle is caught up (integrated) up to this many periods at once; beyond, the twin's time skips [I].
    max_catch_up_cycles: int = 250
    # A controller runs its cycle at real-time priority. The twin asks the OS for SCHED_FIFO (or failing that a
    # higher nice level) and carries on without when it is not allowed (an ordinary user on Linux).
    realtime_priority: bool = True
    # Which servers to start (tests leave one out to see the client's error).
    serve: tuple[str, ...] = ("dashboard", "script", "rtde")
    # RTDE inputs held by something else (a running fieldbus adapter: ``IN_USE``) and outputs this controller does
    # not offer (``NOT_FOUND``), to show what the clients do then.
    rtde_registers_in_use: tuple[str, ...] = ()
    rtde_outputs_not_found: tuple[str, ...] = ()

    @property
    def controller_version(self) -> tuple[int, int, int, int]:
        """(major, minor, bugfix, build) as RTDE's ``v`` reply carries them."""
        parts = [int(p) for p in self.polyscope_version.split(".")] + [0, 0, 0, 0]
        return parts[0], parts[1], parts[2], parts[3]


@dataclass(frozen=True)
class SceneSpec:
    """The press scene inside the controller (and, built the same way, behind the twin's sensors).

    ``center_m`` is where the rig file says the object stands; ``placement_error_m`` is how far it really is from
    there (a test hook); ``sensor`` is the mounted pad, which shapes the contact the wrist feels (the sensor
    registry's first by default). Its ``layout`` and ``pad`` (what the scene presses: "skin" or "pillars") are
    filled in from the registry where the spec is made and travel with it, so the controller process builds the
    same scene without a registry of its own (a sensor registered at run time is unknown there).
    """

    object_id: str
    rotation_deg: float = 0.0
    sensor: str | None = None
    center_m: tuple[float, float] = (-0.15, 0.625)
    seed: int = 0
    objects_files: tuple[str, ...] = ()
    placement_error_m: tuple[float, float] = (0.0, 0.0)
    layout: SensorLayout | None = None
    pad: str | None = None

    def __post_init__(self) -> None:
        if self.sensor is None or self.layout is None or self.pad is None:
            from unitac_rig.rig.sensors import get_sensor, sensor_names

            spec = get_sensor(self.sensor if self.sensor is not None else sensor_names()[0])
            object.__setattr__(self, "sensor", spec.name)
            object.__setattr__(self, "layout", self.layout or spec.layout)
            object.__setattr__(self, "pad", self.pad or spec.pad)

    @property
    def true_center_m(self) -> tuple[float, float]:
        return (self.center_m[0] + self.placement_error_m[0], self.center_m[1] + self.placement_error_m[1])


@dataclass(frozen=True)
class TwinSettings:
    """Everything the controller process needs to start."""

    host: str
    start_pose: tuple[float, ...]
    params: ControllerParams = field(default_factory=ControllerParams)
    scene: SceneSpec | None = None
    seed: int = 0

    def to_json(self) -> str:
        return json.dumps(asdict(self))

    @classmethod
    def from_json(cls, text: str) -> TwinSettings:
        data: dict[str, Any] = json.loads(text)
        params: dict[str, Any] = {k: tuple(v) if isinstance(v, list) else v for k, v in data["params"].items()}
        scene: dict[str, Any] | None = data.get("scene")
        if scene is not None:
            scene = {k: tuple(v) if isinstance(v, list) else v for k, v in scene.items()}
            scene["layout"] = SensorLayout(**scene["layout"])
        spec = None if scene is None else SceneSpec(**scene)
        return cls(data["host"], tuple(data["start_pose"]), ControllerParams(**params), spec, data["seed"])
