"""The arm inside the controller twin: :class:`~unitac_rig.sim.arm.SimArm`'s physics stepped by the controller cycle.

The fast twin's :class:`SimArm` is driven by a host that advances a virtual clock (and its ``move_linear`` blocks
until the move is over). A controller runs the other way round: every 2 ms cycle it executes whatever motion the
program set up, whether or not anyone is listening. :class:`TwinArm` gives the controller those motion primitives,
each stepped one cycle at a time through SimArm's public interface, so the kinematics (acceleration-limited
velocity ramps), the wrist F/T (latency, bias, noise, filter, zero) and the protective stop on the true contact
force are exactly the fast twin's:

* ``movel`` (a straight line with a trapezoidal speed profile): each cycle commands the profile's velocity plus a
  position correction (gain 0.5 / period, which places the error's poles at |z| = 0.5) through ``speed_linear``;
  the move is over when the TCP is within 1 um / 10 urad of the goal and the profile has run out;
* ``speedl``, ``stopl``, force mode and its end, ``zero_ftsensor``: SimArm's own.

Tool centre point: SimArm simulates the pad (the physical tool) with the pose the scene feels. The controller
reports and commands the *active* TCP set on the pendant or with ``set_tcp``; when that differs from the physical
tool offset, reported poses and move targets are transformed through the flange, as on a real arm (so a wrong TCP
on the pendant moves the pad somewhere else). Torques are still reported about the pad centre.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from drivers.clock import VirtualClock
from unitac_rig.rig.poses import matrix_to_rotvec, rotvec_to_matrix
from unitac_rig.sim.arm import SimArm, SimArmParams
from unitac_rig.sim.world import ContactWorld

PATH_GAIN_PER_PERIOD = 0.5  # position feedback of path moves, x 1/period (error poles at |z| = 0.5)
PATH_DONE_M = 1e-6  # a move has arrived within 1 um ...
PATH_DONE_RAD = 1e-5  # ... and 10 urad of its goal
PATH_SETTLE_PERIODS = 50  # at most this many extra cycles to settle after the profile ends
TRACKING_ACCEL_M_S2 = 150.0  # velocity ramp used while tracking a profile (the profile limits acceleration)


def pose_matrix(pose: np.ndarray) -> np.ndarray:
    """4x4 homogeneous transform of a pose [x, y, z, rx, ry, rz] (m, rad rotation vector)."""
    matrix = np.eye(4)
    matrix[:3, :3] = rotvec_to_matrix(pose[3:6])
    matrix[:3, 3] = pose[:3]
    return matrix


def matrix_pose(matrix: np.ndarray) -> np.ndarray:
    return np.concatenate([matrix[:3, 3], matrix_to_rotvec(matrix[:3, :3])])


class _Trapezoid:
    """Trapezoidal progress along a distance (m or rad): fraction done and its rate at time t."""

    def __init__(self, distance: float, speed: float, accel: float) -> None:
        self.distance = distance
        if distance <= 0 or speed <= 0 or accel <= 0:
            self.ramp_s = self.cruise_s = self.peak = 0.0
        elif distance < speed * speed / accel:  # never reaches cruise speed
            self.ramp_s, self.cruise_s = math.sqrt(distance / accel), 0.0
            self.peak = accel * self.ramp_s
        else:
            self.ramp_s = speed / accel
            self.cruise_s = (distance - speed * self.ramp_s) / speed
            self.peak = speed
        self.accel = accel
        self.duration_s = 2 * self.ramp_s + self.cruise_s

    def at(self, t: float) -> tuple[float, float]:
        if self.distance <= 0 or self.duration_s <= 0:
            return 1.0, 0.0
        a, ramp, cruise = self.accel, self.ramp_s, self.cruise_s
        if t <= ramp:
            done, speed = 0.5 * a * t * t, a * t
        elif t <= ramp + cruise:
            done, speed = 0.5 * a * ramp * ramp + self.peak * (t - ramp), self.peak
        elif t < self.duration_s:
            left = self.duration_s - t
            done, speed = self.distance - 0.5 * a * left * left, a * left
        else:
            done, speed = self.distance, 0.0
        return min(1.0, done / self.distance), speed / self.distance


@dataclass
class _Path:
    start_position: np.ndarray
    start_rotation: np.ndarray
    delta_position: np.ndarray
    delta_rotvec: np.ndarray
    profile: _Trapezoid
    goal_position: np.ndarray
    goal_rotation: np.ndarray
    elapsed_s: float = 0.0
    settle_periods: int = 0

    @property
    def length_m(self) -> float:
        return float(np.linalg.norm(self.delta_position))


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
        self.sim = SimArm(world, clock=self.clock, rng=rng, params=params, start_pose=start_pose)
        self.period_s = self.sim.control_period_s
        self.tool_offset = np.asarray(tool_offset, dtype=np.float64).copy()
        self.active_tcp = self.tool_offset.copy()
        self._path: _Path | None = None
        self._force = False
        self.time_s = 0.0

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
    def in_force_mode(self) -> bool:
        return self._force

    @property
    def path_active(self) -> bool:
        return self._path is not None

    def speed(self) -> np.ndarray:
        state = self.sim.latest_state()
        return np.zeros(6) if state.tcp_speed is None else np.asarray(state.tcp_speed)

    def at_rest(self, tolerance_m_s: float = 1e-9) -> bool:
        return bool(np.all(np.abs(self.speed()) <= tolerance_m_s)) and self._path is None

    def measured_wrench(self) -> np.ndarray:
        """The wrist F/T as the controller reports it (latency, bias, noise, filter, minus the last zero)."""
        return np.asarray(self.sim.latest_state().tcp_force, dtype=np.float64)

    def true_wrench(self) -> np.ndarray:
        return self.sim.true_wrench()

    # ---- motions (one at a time, like URScript's) -----------------------------------------------------------

    def movel(self, tcp_goal: np.ndarray, speed_m_s: float, accel_m_s2: float) -> None:
        """Start a straight line to ``tcp_goal`` (the active TCP's pose); :attr:`path_active` until it arrives."""
        goal = self.pad_target(np.asarray(tcp_goal, dtype=np.float64))
        pad = self.sim.true_tcp_pose()
        start_rotation = rotvec_to_matrix(pad[3:])
        goal_rotation = rotvec_to_matrix(goal[3:])
        delta_position = goal[:3] - pad[:3]
        delta_rotvec = matrix_to_rotvec(goal_rotation @ start_rotation.T)
        distance = float(np.linalg.norm(delta_position))
        if distance < 1e-6:  # a pure rotation: the profile runs over the angle, same numbers in rad
            distance = float(np.linalg.norm(delta_rotvec))
        self._end_force()
        self._path = _Path(
            pad[:3].copy(), start_rotation, delta_position, delta_rotvec,
            _Trapezoid(distance, speed_m_s, accel_m_s2), goal[:3].copy(), goal_rotation,
        )  # fmt: skip

    def path_progress(self) -> float:
        """Fraction of the current path's profile done (0..1); 1 when none."""
        if self._path is None:
            return 1.0
        return self._path.profile.at(self._path.elapsed_s)[0]

    def speedl(self, twist: np.ndarray, accel_m_s2: float) -> None:
        """Velocity command (base frame, m/s, rad/s) reached under ``accel_m_s2``; holds until the next motion."""
        self._path = None
        self._end_force()
        self.sim.speed_linear(np.asarray(twist, dtype=np.float64), accel_m_s2)

    def stopl(self, decel_m_s2: float) -> None:
        """Decelerate to rest (ends a path, a speed command and force mode)."""
        self._path = None
        self._force = False
        self.sim.stop(decel_m_s2)

    def force_mode(self, task_frame: np.ndarray, selection: np.ndarray, wrench: np.ndarray, limits: np.ndarray) -> None:
        """Controller-side admittance toward ``wrench`` on the selected axes of ``task_frame`` (type 2)."""
        self._path = None
        self._force = True
        self.sim.force_mode(task_frame, selection, wrench, limits)

    def end_force_mode(self) -> None:
        """``end_force_mode()``: the force thread's velocity is no longer commanded (the arm then holds)."""
        self._end_force()

    def zero_ft(self) -> None:
        self.sim.zero_ft()

    def _end_force(self) -> None:
        if self._force:
            self._force = False
            self.sim.force_mode_stop()

    # ---- the cycle ------------------------------------------------------------------------------------------

    def step(self) -> None:
        """One control period: the current motion's command, then SimArm integrates (and trips if it must)."""
        if self.sim.protective_stopped:
            self._path, self._force = None, False
        elif self._path is not None:
            self._step_path(self._path)
        self.sim.wait_period()
        self.time_s += self.period_s

    def _step_path(self, path: _Path) -> None:
        path.elapsed_s += self.period_s
        fraction, rate = path.profile.at(path.elapsed_s)
        desired_position = path.start_position + fraction * path.delta_position
        desired_rotation = rotvec_to_matrix(fraction * path.delta_rotvec) @ path.start_rotation
        pad = self.sim.true_tcp_pose()
        rotation = rotvec_to_matrix(pad[3:])
        position_error = desired_position - pad[:3]
        rotation_error = matrix_to_rotvec(desired_rotation @ rotation.T)
        if fraction >= 1.0:
            goal_error = float(np.linalg.norm(path.goal_position - pad[:3]))
            turn_error = float(np.linalg.norm(matrix_to_rotvec(path.goal_rotation @ rotation.T)))
            path.settle_periods += 1
            if (goal_error < PATH_DONE_M and turn_error < PATH_DONE_RAD) or path.settle_periods > PATH_SETTLE_PERIODS:
                self._path = None
                self.sim.stop(TRACKING_ACCEL_M_S2)
                return
        gain = PATH_GAIN_PER_PERIOD / self.period_s
        twist = np.concatenate(
            [rate * path.delta_position + gain * position_error, rate * path.delta_rotvec + gain * rotation_error]
        )
        self.sim.speed_linear(twist, TRACKING_ACCEL_M_S2)
