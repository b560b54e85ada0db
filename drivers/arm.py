"""The robot-arm seam: an ``Arm`` protocol with state reads kept apart from commands.

It mirrors ur_rtde's split between ``RTDEReceiveInterface`` (state) and ``RTDEControlInterface`` (commands).
Implementations: :class:`drivers.ur5e.UR5eArm` (real arm over ur_rtde) and ``unitac_rig.sim.arm.SimArm``
(simulated arm on a virtual clock). Units: metres, seconds, newtons, rotation vectors in radians, base frame.

The protocol has no blocking move on purpose. A controller executes what it was told whether or not the host is
still there, so every motion is started and then watched one control period at a time (``wait_period`` feeds the
controller's RTDE watchdog, which stops the program when the host stops writing): a straight-line move is started
asynchronously (``start_move_linear``) and polled (``move_running``), so the host can stop it (``stop``) the
moment something is wrong, Ctrl-C included. The application's ``collection/guarded_motion.py`` is that loop.
"""

from __future__ import annotations

from contextlib import AbstractContextManager
from typing import NamedTuple, Protocol, runtime_checkable

import numpy as np

from drivers.clock import Clock
from drivers.errors import ArmError

# RTDE watchdog frequency (Hz): the control program stops when the host writes nothing for 1 / 6 Hz = 167 ms. High
# enough that the arm is at rest within 0.2 s of a dead host's last write (167 ms + braking: ~5 ms from transit speed
# at 10 m/s^2, nothing at press speed); low enough that a 100 ms host stall (GC, a slow disk) and a loaded PC's
# scheduling gaps do not stop the program mid-session (8 Hz tripped on a 2-core box at load 8 on the real-time twin).
DEFAULT_WATCHDOG_HZ = 6.0


class ArmState(NamedTuple):
    """One state sample of the arm (500 Hz on a UR e-Series); immutable (``state._replace(...)`` for a changed copy).

    ``tcp_pose``: (6,) [x, y, z, rx, ry, rz] in m and rad (rotation vector), base frame.
    ``tcp_force``: (6,) [Fx, Fy, Fz, Tx, Ty, Tz] in N and N*m, base-frame axes, reference point the TCP
    (what RTDE's ``actual_TCP_force`` reports), after the last ``zero_ft``.
    A named tuple, not a frozen dataclass: the host forms two every control period and reads them, and a frozen
    dataclass's checked attribute stores made that a tenth of the simulated arm's cost. Treat its arrays as read
    only (the simulated arm hands out read-only ones).
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
    program_running: bool = True  # the controller's control program runs (it refuses every command otherwise)


def checked_force_mode_parameters(damping: float, gain_scaling: float) -> tuple[float, float]:
    """(damping, gain scaling) as floats after checking URScript's ranges (0..1, 0..2); ArmError otherwise."""
    if not (0.0 <= damping <= 1.0 and 0.0 <= gain_scaling <= 2.0):
        raise ArmError(
            f"force mode damping must be in [0, 1] and gain scaling in [0, 2], got {damping}, {gain_scaling}"
        )
    return float(damping), float(gain_scaling)


@runtime_checkable
class Arm(Protocol):
    """What the press routine needs from an arm. Every implementation stops the arm in ``close``."""

    clock: Clock
    control_period_s: float

    # ---- state (receive side) -------------------------------------------------------------------------------
    def read_state(self) -> ArmState: ...

    # ---- commands (control side) ----------------------------------------------------------------------------
    def start_move_linear(self, pose: np.ndarray, speed_m_s: float, accel_m_s2: float) -> None:
        """Start a straight-line move to ``pose`` and return at once (``moveL(..., asynchronous=True)``).

        Poll :meth:`move_running` once per control period; :meth:`stop` ends it early.
        """
        ...

    def move_running(self) -> bool:
        """True while the move started by :meth:`start_move_linear` runs."""
        ...

    def speed_linear(self, twist: np.ndarray, accel_m_s2: float) -> None:
        """Cartesian velocity command (m/s, rad/s); send it every control period. It holds until the next command
        or a stop, on the controller too: only the watchdog stops it when the host dies."""
        ...

    def stop(self, decel_m_s2: float = 10.0) -> None:
        """Decelerate to rest, whatever runs: force mode, a speed command, an asynchronous move."""
        ...

    def zero_ft(self) -> None:
        """Zero the wrist force/torque sensor (only call at rest, when nothing touches the tool)."""
        ...

    def force_mode(
        self,
        task_frame: np.ndarray,
        selection: np.ndarray,
        wrench: np.ndarray,
        limits: np.ndarray,
    ) -> None:
        """Compliant control along selected axes (URScript force_mode type 2); call once per control period.

        The controller regulates toward ``wrench`` at most at the speed ``limits`` of the compliant axes and goes on
        doing so while the host is stalled: this bounds the contact force on the controller.
        """
        ...

    def force_mode_stop(self) -> None: ...

    def set_force_mode_parameters(self, damping: float, gain_scaling: float) -> None:
        """Force mode's damping (0..1) and gain scaling (0..2) (URScript ``force_mode_set_damping`` /
        ``force_mode_set_gain_scaling``), applied from the next entry into force mode on; set explicitly, so no
        earlier program's or installation's values carry over into a press."""
        ...

    def wait_period(self) -> None:
        """Block until the next control period (2 ms at 500 Hz) and feed the watchdog.

        On the simulated arm this advances the clock.
        """
        ...

    def keep_alive(self) -> AbstractContextManager[None]:
        """Feed the watchdog while the host does non-motion work (writing a press, waiting for the operator) with
        the arm at rest; motion commands must not be sent inside."""
        ...

    def close(self) -> None:
        """Stop the arm and release the connection. Safe to call more than once."""
        ...
