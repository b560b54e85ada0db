"""The arm inside the controller twin: :class:`~unitac_rig.sim.arm.SimArm`'s physics stepped by the controller cycle.

The fast twin's :class:`SimArm` is driven by a host that advances a virtual clock. A controller runs the other way
round: every 2 ms cycle it executes whatever motion the program set up, whether or not anyone is listening.
:class:`TwinArm` is a SimArm on its own virtual clock that the controller advances by one period per cycle
(:meth:`TwinArm.step`); the emulated script commands it through SimArm's own motion methods, so the kinematics
(trapezoidal lines, acceleration-limited velocity ramps, force-mode admittance), the wrist F/T (latency, bias, noise,
filter, zero) and the protective stop on the true contact force are exactly the fast twin's. SimArm's own program
model (its watchdog and its refusal of commands after a protective stop) stays idle here: the controller twin runs
the real program semantics itself, so SimArm is built without a watchdog and its program is restarted whenever the
controller's protective stop is unlocked.

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


class TwinArm(SimArm):
    """SimArm driven one controller cycle at a time (see the module docstring); the script commands it through
    SimArm's own motion methods (``start_move_linear`` through :meth:`movel`, ``speed_linear``, ``stop``,
    ``force_mode``, ``force_mode_stop``, ``zero_ft``).

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
        super().__init__(world, clock=VirtualClock(), rng=rng, params=params, start_pose=start_pose, watchdog_hz=None)
        self.tool_offset = np.asarray(tool_offset, dtype=np.float64).copy()
        self.active_tcp = self.tool_offset.copy()

    # ---- frames ---------------------------------------------------------------------------------------------

    def _tcp_differs(self) -> bool:
        return not np.array_equal(self.active_tcp, self.tool_offset)

    def reported_pose(self) -> np.ndarray:
        """The active TCP's pose (what RTDE's actual_TCP_pose reports)."""
        pad = self.true_tcp_pose()
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

    def speed(self) -> np.ndarray:
        state = self.latest_state()
        return np.zeros(6) if state.tcp_speed is None else np.asarray(state.tcp_speed)

    def at_rest(self, tolerance_m_s: float = 1e-9) -> bool:
        return bool(np.all(np.abs(self.speed()) <= tolerance_m_s)) and not self.move_running()

    def measured_wrench(self) -> np.ndarray:
        """The wrist F/T as the controller reports it (latency, bias, noise, filter, minus the last zero)."""
        return np.asarray(self.latest_state().tcp_force, dtype=np.float64)

    # ---- commands and the cycle -----------------------------------------------------------------------------

    def movel(self, tcp_goal: np.ndarray, speed_m_s: float, accel_m_s2: float) -> None:
        """Start a straight line to ``tcp_goal`` (the active TCP's pose); :meth:`move_running` until it arrives."""
        self.start_move_linear(self.pad_target(np.asarray(tcp_goal, dtype=np.float64)), speed_m_s, accel_m_s2)

    def unlock(self) -> None:
        """The controller's protective stop is unlocked: SimArm may move again (its own program restarts)."""
        self.unlock_protective_stop()
        self.reupload_script()

    def step(self) -> None:
        """One control period: SimArm integrates the current motion, samples the F/T and trips if it must."""
        self.wait_period()
