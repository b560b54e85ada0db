"""The arm inside the controller twin: :class:`~unitac_rig.sim.arm.SimArm`'s physics stepped by the controller cycle.

The fast twin's :class:`SimArm` is driven by a host that advances a virtual clock. A controller runs the other way
round: every 2 ms cycle it executes whatever motion the program set up, whether or not anyone is listening.
:class:`TwinArm` gives the controller those motion primitives through SimArm's public interface and advances SimArm's
own virtual clock by one period per controller cycle, so the kinematics (trapezoidal lines, acceleration-limited
velocity ramps, force-mode admittance), the wrist F/T (latency, bias, noise, filter, zero) and the protective stop on
the true contact force are exactly the fast twin's. SimArm's own program model (its watchdog and its refusal of
commands after a protective stop) stays idle here: the controller twin runs the real program semantics itself, so
SimArm is built without a watchdog and its program is restarted whenever the controller's protective stop is unlocked.

Tool centre point: SimArm simulates the pad (the physical tool) with the pose the scene feels. The controller
reports and commands the *active* TCP set on the pendant or with ``set_tcp``; when that differs from the physical
tool offset, reported poses and move targets are transformed through the flange, as on a real arm (so a wrong TCP
on the pendant moves the pad somewhere else). Torques are still reported about the pad centre.
"""

from __future__ import annotations

import numpy as np

from drivers.clock import VirtualClock
from unitac_rig.rig.poses import matrix_to_rotvec, rotvec_to_matrix
from unitac_rig.sim.arm import SimArm, SimArmParams
from unitac_rig.sim.world import ContactWorld


def pose_matrix(pose: np.ndarray) -> np.ndarray:
    """4x4 homogeneous transform of a pose [x, y, z, rx, ry, rz] (m, rad rotation vector)."""
    matrix = np.eye(4)
    matrix[:3, :3] = rotvec_to_matrix(pose[3:6])
    matrix[:3, 3] = pose[:3]
    return matrix


def matrix_pose(matrix: np.ndarray) -> np.ndarray:
    return np.concatenate([matrix[:3, 3], matrix_to_rotvec(matrix[:3, :3])])


class TwinArm:
    """SimArm driven one controller cycle at a time (see the module docstring).

    ``tool_offset`` is the physical tool (pad centre) relative to the flange, (6,) m/rad; ``active_tcp`` starts equal
    to it. ``start_pose`` is the physical tool's pose.
    """

    def __init__(
        self,
        world: ContactWorld,
        *,
        rng: np.random.Generator,
        params: SimArmParams,
        start_pose: np.ndarray,
        tool_offset: np.ndarray,
    ) -> None:
        self.clock = VirtualClock()
        self.sim = SimArm(world, clock=self.clock, rng=rng, params=params, start_pose=start_pose, watchdog_hz=None)
        self.period_s = self.sim.control_period_s
        self.tool_offset = np.asarray(tool_offset, dtype=np.float64).copy()
        self.active_tcp = self.tool_offset.copy()

    # ---- frames ---------------------------------------------------------------------------------------------

    def _tcp_differs(self) -> bool:
        return not np.array_equal(self.active_tcp, self.tool_offset)

    def reported_pose(self) -> np.ndarray:
        """The active TCP's pose (what RTDE's actual_TCP_pose reports)."""
        pad = self.sim.true_tcp_pose()
        if not self._tcp_differs():
            return pad
        flange = pose_matrix(pad) @ np.linalg.inv(pose_matrix(self.tool_offset))
        return matrix_pose(flange @ pose_matrix(self.active_tcp))

    def pad_target(self, tcp_pose: np.ndarray) -> np.ndarray:
        """Where the physical tool goes when the active TCP is commanded to ``tcp_pose``."""
        if not self._tcp_differs():
            return np.asarray(tcp_pose, dtype=np.float64)
        flange = pose_matrix(tcp_pose) @ np.linalg.inv(pose_matrix(self.active_tcp))
        return matrix_pose(flange @ pose_matrix(self.tool_offset))

    # ---- state ----------------------------------------------------------------------------------------------

    @property
    def protective_stopped(self) -> bool:
        return self.sim.protective_stopped

    @property
    def path_active(self) -> bool:
        """A straight-line move is running."""
        return self.sim.move_running()

    def speed(self) -> np.ndarray:
        state = self.sim.latest_state()
        return np.zeros(6) if state.tcp_speed is None else np.asarray(state.tcp_speed)

    def at_rest(self, tolerance_m_s: float = 1e-9) -> bool:
        return bool(np.all(np.abs(self.speed()) <= tolerance_m_s)) and not self.sim.move_running()

    def measured_wrench(self) -> np.ndarray:
        """The wrist F/T as the controller reports it (latency, bias, noise, filter, minus the last zero)."""
        return np.asarray(self.sim.latest_state().tcp_force, dtype=np.float64)

    def true_wrench(self) -> np.ndarray:
        return self.sim.true_wrench()

    # ---- motions (one at a time, like URScript's) -----------------------------------------------------------

    def movel(self, tcp_goal: np.ndarray, speed_m_s: float, accel_m_s2: float) -> None:
        """Start a straight line to ``tcp_goal`` (the active TCP's pose); :attr:`path_active` until it arrives."""
        self.sim.start_move_linear(self.pad_target(np.asarray(tcp_goal, dtype=np.float64)), speed_m_s, accel_m_s2)

    def speedl(self, twist: np.ndarray, accel_m_s2: float) -> None:
        """Velocity command (base frame, m/s, rad/s) reached under ``accel_m_s2``; holds until the next motion."""
        self.sim.speed_linear(np.asarray(twist, dtype=np.float64), accel_m_s2)

    def stopl(self, decel_m_s2: float) -> None:
        """Decelerate to rest (ends a move, a speed command and force mode)."""
        self.sim.stop(decel_m_s2)

    def force_mode(self, task_frame: np.ndarray, selection: np.ndarray, wrench: np.ndarray, limits: np.ndarray) -> None:
        """Controller-side admittance toward ``wrench`` on the selected axes of ``task_frame`` (type 2)."""
        self.sim.force_mode(task_frame, selection, wrench, limits)

    def end_force_mode(self) -> None:
        """``end_force_mode()``: the force thread's velocity is no longer commanded (the arm then holds)."""
        self.sim.force_mode_stop()

    def zero_ft(self) -> None:
        self.sim.zero_ft()

    # ---- safety ---------------------------------------------------------------------------------------------

    def protective_stop(self) -> None:
        if not self.sim.protective_stopped:
            self.sim.trigger_protective_stop()

    def unlock(self) -> None:
        """The controller's protective stop is unlocked: SimArm may move again (its own program restarts)."""
        self.sim.unlock_protective_stop()
        self.sim.reupload_script()

    # ---- the cycle ------------------------------------------------------------------------------------------

    def step(self) -> None:
        """One control period: SimArm integrates the current motion, samples the F/T and trips if it must."""
        self.sim.wait_period()
