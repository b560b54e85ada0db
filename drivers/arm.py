"""The robot-arm seam: an ``Arm`` protocol with state reads kept apart from commands.

It mirrors ur_rtde's split between ``RTDEReceiveInterface`` (state) and ``RTDEControlInterface`` (commands).
Implementations: :class:`drivers.ur5e.UR5eArm` (real arm over ur_rtde) and ``unitac_rig.sim.arm.SimArm``
(simulated arm on a virtual clock). Units: metres, seconds, newtons, rotation vectors in radians, base frame.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol, runtime_checkable

import numpy as np

from drivers.clock import Clock


@dataclass(frozen=True, slots=True)
class ArmState:
    """One state sample of the arm (500 Hz on a UR e-Series).

    ``tcp_pose``: (6,) [x, y, z, rx, ry, rz] in m and rad (rotation vector), base frame.
    ``tcp_force``: (6,) [Fx, Fy, Fz, Tx, Ty, Tz] in N and N*m, base-frame axes, reference point the TCP
    (what RTDE's ``actual_TCP_force`` reports), after the last ``zero_ft``.
    """

    host_t_ns: int
    controller_t_s: float
    tcp_pose: np.ndarray
    tcp_force: np.ndarray
    robot_mode: int
    safety_mode: int
    protective_stop: bool
    emergency_stop: bool = False
    tcp_speed: np.ndarray | None = None  # (6,) [vx, vy, vz (m/s), wx, wy, wz (rad/s)], base frame, if known


@runtime_checkable
class Arm(Protocol):
    """What the press routine needs from an arm. Every implementation stops the arm in ``close``."""

    clock: Clock
    control_period_s: float

    # ---- state (receive side) -------------------------------------------------------------------------------
    def read_state(self) -> ArmState: ...

    # ---- commands (control side) ----------------------------------------------------------------------------
    def move_linear(self, pose: np.ndarray, speed_m_s: float, accel_m_s2: float) -> None:
        """Blocking straight-line move to ``pose``; raises ProtectiveStop if the controller stops."""
        ...

    def speed_linear(self, twist: np.ndarray, accel_m_s2: float) -> None:
        """Start or update a Cartesian velocity command (m/s, rad/s) that lasts until the next command or stop."""
        ...

    def stop(self, decel_m_s2: float = 10.0) -> None:
        """Decelerate to rest (stopL / speedStop semantics)."""
        ...

    def zero_ft(self) -> None:
        """Zero the wrist force/torque sensor (only call when nothing touches the tool)."""
        ...

    def force_mode(
        self,
        task_frame: np.ndarray,
        selection: np.ndarray,
        wrench: np.ndarray,
        limits: np.ndarray,
    ) -> None:
        """Compliant control along selected axes (URScript force_mode type 2); call once per control period."""
        ...

    def force_mode_stop(self) -> None: ...

    def wait_period(self) -> None:
        """Block until the next control period (2 ms at 500 Hz). On the simulated arm this advances the clock."""
        ...

    def close(self) -> None:
        """Stop the arm and release the connection. Safe to call more than once."""
        ...
