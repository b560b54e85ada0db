"""Helpers for the controller-twin tests: the real ur_rtde clients on one twin, reused across a module.

ur_rtde's ``disconnect()`` sleeps 0.5 s and its constructor re-uploads the control script, so tests share one
connected set per module and put the controller back in a known state between tests (:meth:`TwinClients.recover`).
Every fixture disconnects the clients *before* it stops the twin: a control client whose controller vanished waits
300 s in its next blocking command. Loopback addresses 127.0.0.120-149 belong to these tests.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import dashboard_client
import numpy as np
import rtde_control
import rtde_receive

from unitac_rig.sim.scene import press_pose
from unitac_rig.sim.twin import ControllerParams, ControllerTwin, SceneSpec, start_twin_on_free_loopback

RECEIVE_VARIABLES = [
    "timestamp",
    "actual_TCP_pose",
    "actual_TCP_force",
    "actual_TCP_speed",
    "robot_mode",
    "safety_mode",
    "safety_status_bits",
    "runtime_state",
    "payload",
    "payload_cog",
]
CENTER_M = (-0.15, 0.625)
HEIGHT_M = 0.20
STANDOFF_MM = 40.0  # pad centre this far from the object's axis: 15 mm clear of circle_pla (radius 25 mm)
FIRST_OCTET, LAST_OCTET = 120, 149


def wait_until(condition: Callable[[], object], timeout_s: float = 3.0, poll_s: float = 0.002) -> bool:
    """Poll ``condition`` until it is truthy; generous timeouts keep a loaded 2-core box from failing tests."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if condition():
            return True
        time.sleep(poll_s)
    return bool(condition())


def start_pose() -> np.ndarray:
    """Pad facing the object's axis from approach angle 0, ``STANDOFF_MM`` from it, at the press height."""
    return press_pose(0.0, STANDOFF_MM, object_center_m=CENTER_M, height_m=HEIGHT_M)


def press_direction(pose: np.ndarray) -> np.ndarray:
    from unitac_rig.rig.poses import tool_z

    return tool_z(pose)


@dataclass
class TwinClients:
    """A controller twin and the real clients connected to it."""

    twin: ControllerTwin
    control: Any = None
    receive: Any = None
    dashboard: Any = None
    home: np.ndarray = field(default_factory=start_pose)

    def connect(self) -> None:
        self.control = rtde_control.RTDEControlInterface(self.twin.host, 500.0)
        self.receive = rtde_receive.RTDEReceiveInterface(self.twin.host, 500.0, RECEIVE_VARIABLES)
        self.dashboard = dashboard_client.DashboardClient(self.twin.host)
        self.dashboard.connect()

    def disconnect(self) -> None:
        for client in (self.control, self.receive, self.dashboard):
            if client is not None:
                client.disconnect()
        self.control = self.receive = self.dashboard = None

    def recover(self) -> None:
        """Back to a known state: no stop, arm powered, program running, arm at home, F/T zeroed there."""
        twin, control = self.twin, self.control
        truth = twin.truth()
        if truth.emergency_stops and truth.safety_status_bits & (1 << 7):
            twin.release_emergency_stop()
        if truth.robot_mode != 7:
            self.dashboard.powerOn()
            self.dashboard.brakeRelease()
        if twin.truth().safety_status_bits & (1 << 2):
            assert wait_until(lambda: twin.truth().at_rest)
            time.sleep(twin.params.unlock_delay_s)
            self.dashboard.unlockProtectiveStop()
        if not control.isProgramRunning():
            assert control.reuploadScript()
        assert wait_until(control.isProgramRunning), twin.status()
        control.speedStop(10.0)
        control.forceModeStop()
        assert control.moveL(list(self.home), 0.1, 1.0), twin.status()
        assert control.zeroFtSensor()
        twin.reset_peak()


def open_twin(params: ControllerParams, *, scene: SceneSpec | None = None) -> ControllerTwin:
    return start_twin_on_free_loopback(
        FIRST_OCTET, LAST_OCTET, scene=scene, start_pose=start_pose(), params=params, seed=7
    )
