"""The simulated UR5e: a kinematic arm on a virtual clock with the wrist force/torque sensor a real UR gives you.

It implements :class:`drivers.arm.Arm`, so the press routine cannot tell it from :class:`drivers.ur5e.UR5eArm`.

What is modelled (numbers and sources in :class:`SimArmParams`):

* kinematics only: the TCP follows commanded velocities under an acceleration limit (``speed_linear``), decelerates
  over ``v^2 / 2a`` when stopped (``stop``), follows a trapezoidal straight line (``move_linear``, blocking), or obeys
  an admittance law in force mode (``force_mode``: velocity along a compliant axis = gain x force error, clipped to
  the axis' speed limit; non-compliant axes hold still);
* the wrist F/T: the world's wrench (:class:`unitac_rig.sim.world.ContactWorld`) delayed by a few ms, plus a bias
  that starts random and drifts slowly (so ``zero_ft`` matters), plus white noise, through a first-order low-pass
  filter, minus the offset captured by the last ``zero_ft``;
* a protective stop when the true contact force exceeds ``protective_stop_n`` (or on
  :meth:`SimArm.trigger_protective_stop`): the arm decelerates to rest and every command raises
  :class:`~drivers.errors.ProtectiveStop` until :meth:`SimArm.unlock_protective_stop`.

Not modelled: joint space, singularities, reach, arm dynamics or compliance, the 5 s wait before a protective stop
may be unlocked, payload/gravity compensation of the F/T.

Time only moves when someone advances the virtual clock: ``wait_period`` integrates one 2 ms control period and then
advances the clock (which makes simulated sensors emit the samples that fall due, reading :meth:`true_tcp_pose`).
If other code advances the clock directly, the arm integrates those periods too (it listens to the clock).
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass
from typing import Literal

import numpy as np

from drivers.arm import ArmState
from drivers.clock import Clock, VirtualClock
from drivers.errors import ArmError, ProtectiveStop
from unitac_rig.rig.poses import matrix_to_rotvec, rotvec_to_matrix
from unitac_rig.sim.world import ContactWorld

ROBOT_MODE_RUNNING = 7
SAFETY_MODE_NORMAL = 1
SAFETY_MODE_PROTECTIVE_STOP = 3

DEFAULT_START_POSE = np.array([-0.15, 0.52, 0.25, 0.0, 2.2214, -2.2214])  # m, rad: pad facing base +y


@dataclass(frozen=True)
class SimArmParams:
    """Simulated-arm parameters. [S] sourced, [D] derived, [I] assumed (see ``scene-facts.md`` section 3)."""

    # Wrist F/T. UR5e datasheet: precision +-3.5 N, accuracy +-4.0 N [S]; the scene notes suggest sigma ~1-2 N per
    # 500 Hz sample for the simulated stop decision [I]. After the 20 Hz filter below, 1.5 N becomes ~0.5 N.
    ft_noise_sigma_n: float = 1.5
    # Torque channels scale like the datasheet's precision ratio: 0.2 N*m / 3.5 N = 0.057 m [D].
    ft_torque_scale_m: float = 0.057
    # First-order low-pass on the controller side [I]; time constant 1/(2*pi*20 Hz) = 8 ms, so with the latency
    # below the effective delay is ~12 ms, inside the 4-20 ms the scene notes give for cycle + filtering [I].
    # None = no filter.
    ft_filter_cutoff_hz: float | None = 20.0
    # Transport/processing latency of the F/T reading [I]: 2 ms control cycle + 2 ms (scene notes: 4-20 ms total).
    ft_latency_s: float = 0.004
    # Offset before the first zero_ft, per force axis [I]: a few N, within the +-4 N accuracy [S].
    ft_bias_sigma_n: float = 2.0
    # Random-walk drift of that offset [I]: ~0.3 N over a 4-minute session, so a per-press zero still matters.
    ft_bias_drift_n_per_sqrt_s: float = 0.02
    # Protective stop on the true contact force. A UR e-Series ships with a 150 N "Force" safety limit in normal mode
    # [I, UR safety settings default]; the press routine's own hard limit (tens of N) must act long before this.
    protective_stop_n: float = 150.0
    # Deceleration during a protective stop (a category-2 stop along the path) [I]: the stopL default, 10 m/s^2.
    protective_stop_decel_m_s2: float = 10.0
    # Argument checks ur_rtde applies (tool speed <= 3 m/s, tool accel <= 150 m/s^2) [S, hardware-facts 3.4].
    max_tool_speed_m_s: float = 3.0
    max_tool_accel_m_s2: float = 150.0
    # Force-mode admittance gains [I]: 2 mm/s per N keeps the loop stable (gain x stiffness x 2 ms < 1) for
    # contact stiffnesses up to ~250 N/mm; torque axes 0.05 rad/s per N*m.
    force_mode_gain_m_s_per_n: float = 0.002
    force_mode_gain_rad_s_per_nm: float = 0.05


_Mode = Literal["idle", "speed", "stop", "force", "path"]


class SimArm:
    """A simulated UR5e implementing :class:`drivers.arm.Arm` on a :class:`~drivers.clock.VirtualClock`.

    ``world`` gives the wrench on the tool at a pose; ``rng`` drives the F/T noise and bias (seed it for a
    deterministic run); ``start_pose`` is (6,) [x, y, z (m), rx, ry, rz (rad)].
    """

    control_period_s: float = 0.002  # 500 Hz, a UR e-Series controller cycle [S]

    def __init__(
        self,
        world: ContactWorld,
        *,
        clock: VirtualClock,
        rng: np.random.Generator,
        params: SimArmParams | None = None,
        start_pose: np.ndarray | None = None,
    ) -> None:
        self.world = world
        self.clock: Clock = clock  # typed as the Arm protocol's Clock; the arm itself drives the virtual one
        self.virtual_clock = clock
        self.params = params or SimArmParams()
        self._rng = rng
        pose = DEFAULT_START_POSE if start_pose is None else np.asarray(start_pose, dtype=np.float64)
        if pose.shape != (6,) or not np.all(np.isfinite(pose)):
            raise ArmError(f"start pose must be 6 finite numbers, got {start_pose!r}")
        self._position = pose[:3].copy()
        self._set_rotation(rotvec_to_matrix(pose[3:]), pose[3:])
        self._velocity = np.zeros(3)  # m/s, base frame
        self._angular_velocity = np.zeros(3)  # rad/s, base frame
        self._mode: _Mode = "idle"
        self._target_twist = np.zeros(6)
        self._accel_m_s2 = 0.0
        self._force_command: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None = None
        self._protective_stop = False
        self._closed = False

        self._period_ns = round(self.control_period_s * 1e9)
        self._integrated_ns = clock.now_ns()
        self._true_wrench = np.asarray(world.wrench_on_tool(self.true_tcp_pose()), dtype=np.float64)
        delay_periods = max(0, round(self.params.ft_latency_s / self.control_period_s))
        # Holds the last ``delay_periods`` true wrenches: append the new one, pop the one that is now due.
        self._delay_line: deque[np.ndarray] = deque([self._true_wrench.copy()] * delay_periods)
        self._axis_scale = np.array([1.0, 1.0, 1.0] + [self.params.ft_torque_scale_m] * 3)
        self._bias = rng.normal(0.0, self.params.ft_bias_sigma_n, 6) * self._axis_scale
        self._filtered = self._true_wrench + self._bias
        self._zero_offset = np.zeros(6)
        cutoff = self.params.ft_filter_cutoff_hz
        self._filter_alpha = 1.0 if cutoff is None else 1.0 - math.exp(-2 * math.pi * cutoff * self.control_period_s)
        self._latest = self._snapshot()
        clock.on_advance(self._on_clock_advance)

    # ---- truth (for simulated sensors and tests) ------------------------------------------------------------

    def true_tcp_pose(self) -> np.ndarray:
        """Noise-free TCP pose (6,) [m, rad rotation vector], base frame: what simulated sensors feel."""
        return np.concatenate([self._position, self._rotvec])

    def true_wrench(self) -> np.ndarray:
        """The world's wrench on the tool now (6,) [N, N*m], base axes; no latency, noise, bias or filter."""
        return self._true_wrench.copy()

    def latest_state(self) -> ArmState:
        """The state after the last control period; an immutable snapshot, safe to read from another thread."""
        return self._latest

    # ---- Arm: state -----------------------------------------------------------------------------------------

    def read_state(self) -> ArmState:
        return self._latest

    # ---- Arm: commands --------------------------------------------------------------------------------------

    def move_linear(self, pose: np.ndarray, speed_m_s: float, accel_m_s2: float) -> None:
        """Blocking straight line with a trapezoidal speed profile; the clock advances through the move.

        The orientation turns in proportion to the distance covered. Raises ProtectiveStop (arm at rest) if a
        protective stop trips on the way.
        """
        self._check_command()
        goal = _as_vector(pose, 6, "pose")
        self._check_speed(speed_m_s, accel_m_s2)
        start_position, start_rotation = self._position.copy(), self._rotation.copy()
        delta_position = goal[:3] - start_position
        delta_rotvec = matrix_to_rotvec(rotvec_to_matrix(goal[3:]) @ start_rotation.T)
        # The profile runs over the translation (m); a pure rotation uses the angle with the same numbers in rad.
        distance = float(np.linalg.norm(delta_position))
        if distance < 1e-6:
            distance = float(np.linalg.norm(delta_rotvec))
        profile = _Trapezoid(distance, speed_m_s, accel_m_s2)
        self._mode, self._force_command = "path", None
        elapsed_s = 0.0
        try:
            while elapsed_s < profile.duration_s:
                elapsed_s = min(elapsed_s + self.control_period_s, profile.duration_s)
                fraction, rate = profile.at(elapsed_s)
                if fraction >= 1.0:  # land exactly on the commanded pose
                    self._position = goal[:3].copy()
                    self._set_rotation(rotvec_to_matrix(goal[3:]), goal[3:])
                else:
                    self._position = start_position + fraction * delta_position
                    self._set_rotation(rotvec_to_matrix(fraction * delta_rotvec) @ start_rotation)
                self._velocity = rate * delta_position
                self._angular_velocity = rate * delta_rotvec
                self._advance_one_period(integrate=False)
                if self._protective_stop:
                    self._settle_after_protective_stop()
                    raise ProtectiveStop(
                        "protective stop during a linear move",
                        hint="move the arm clear, then unlock the protective stop",
                    )
        finally:
            if self._mode == "path":
                self._mode = "idle"
                self._velocity[:] = 0.0
                self._angular_velocity[:] = 0.0

    def speed_linear(self, twist: np.ndarray, accel_m_s2: float) -> None:
        """Velocity command (m/s, rad/s, base frame) reached under ``accel_m_s2``; lasts until the next command."""
        self._check_command()
        target = _as_vector(twist, 6, "twist")
        self._check_speed(float(np.linalg.norm(target[:3])), accel_m_s2)
        self._mode, self._force_command = "speed", None
        self._target_twist = target
        self._accel_m_s2 = accel_m_s2

    def stop(self, decel_m_s2: float = 10.0) -> None:
        """Decelerate to rest at ``decel_m_s2`` (stopping distance v^2 / 2a). Never raises on a stopped arm."""
        if decel_m_s2 <= 0:
            raise ArmError(f"deceleration must be > 0 m/s^2, got {decel_m_s2}")
        if self._closed:
            return
        if self._protective_stop:
            return  # already braking at the protective-stop deceleration
        self._begin_stop(min(decel_m_s2, self.params.max_tool_accel_m_s2))

    def zero_ft(self) -> None:
        """Take the current (filtered) F/T reading as the new zero, like ``zeroFtSensor``."""
        self._check_command()
        self._zero_offset = self._filtered.copy()
        self._latest = self._snapshot()

    def force_mode(
        self,
        task_frame: np.ndarray,
        selection: np.ndarray,
        wrench: np.ndarray,
        limits: np.ndarray,
    ) -> None:
        """Admittance control (URScript force_mode type 2): compliant axes move at gain x (target - applied).

        ``wrench`` is what the robot should apply to the environment (N, N*m) in ``task_frame`` axes; ``limits``
        are the speed limits of compliant axes (m/s, rad/s). Non-compliant axes hold still.
        """
        self._check_command()
        frame = _as_vector(task_frame, 6, "task_frame")
        chosen = _as_vector(selection, 6, "selection") != 0
        target = _as_vector(wrench, 6, "wrench")
        speed_limits = np.abs(_as_vector(limits, 6, "limits"))
        self._mode = "force"
        self._force_command = (rotvec_to_matrix(frame[3:]), chosen, target, speed_limits)

    def force_mode_stop(self) -> None:
        """Leave force mode and stop (the ur_rtde script does ``end_force_mode(); stopl(10)``)."""
        if self._mode == "force":
            self._force_command = None
            if not self._protective_stop:
                self._begin_stop(10.0)

    def wait_period(self) -> None:
        """Integrate one control period, then advance the virtual clock by it (simulated sensors sample then)."""
        if self._closed:
            raise ArmError("the simulated arm is closed", hint="open a new rig")
        self._advance_one_period(integrate=True)

    def close(self) -> None:
        """Stop the arm (at once: nothing drives the clock afterwards) and detach from the clock. Idempotent."""
        if self._closed:
            return
        self._closed = True
        self._mode, self._force_command = "idle", None
        self._velocity[:] = 0.0
        self._angular_velocity[:] = 0.0
        self._latest = self._snapshot()
        self.virtual_clock.remove_listener(self._on_clock_advance)

    # ---- faults ---------------------------------------------------------------------------------------------

    def trigger_protective_stop(self) -> None:
        """Fault hook: the controller enters a protective stop now (as if a safety limit tripped)."""
        self._enter_protective_stop()
        self._latest = self._snapshot()

    def unlock_protective_stop(self) -> None:
        """Clear a protective stop (the dashboard's unlockProtectiveStop). It trips again if the force is still high."""
        self._protective_stop = False
        self._latest = self._snapshot()

    @property
    def protective_stopped(self) -> bool:
        return self._protective_stop

    # ---- internals ------------------------------------------------------------------------------------------

    def _set_rotation(self, rotation: np.ndarray, rotvec: np.ndarray | None = None) -> None:
        """Keep the matrix and its rotation vector together (the vector is read every period).

        Pass ``rotvec`` when it is known exactly: converting back loses ~1e-7 rad near a half turn.
        """
        self._rotation = rotation
        self._rotvec = matrix_to_rotvec(rotation) if rotvec is None else np.array(rotvec, dtype=np.float64)

    def _check_command(self) -> None:
        if self._closed:
            raise ArmError("the simulated arm is closed", hint="open a new rig")
        if self._protective_stop:
            raise ProtectiveStop(
                "the simulated arm is in a protective stop",
                hint="move the arm clear, then unlock the protective stop",
            )

    def _check_speed(self, speed_m_s: float, accel_m_s2: float) -> None:
        if not 0 <= speed_m_s <= self.params.max_tool_speed_m_s:
            raise ArmError(f"tool speed {speed_m_s} m/s is outside 0..{self.params.max_tool_speed_m_s} m/s")
        if not 0 < accel_m_s2 <= self.params.max_tool_accel_m_s2:
            raise ArmError(f"tool acceleration {accel_m_s2} m/s^2 is outside (0, {self.params.max_tool_accel_m_s2}]")

    def _begin_stop(self, decel_m_s2: float) -> None:
        self._mode, self._force_command = "stop", None
        self._target_twist = np.zeros(6)
        self._accel_m_s2 = decel_m_s2

    def _enter_protective_stop(self) -> None:
        if not self._protective_stop:
            self._protective_stop = True
            self._begin_stop(self.params.protective_stop_decel_m_s2)

    def _settle_after_protective_stop(self) -> None:
        """Inside a blocking move: brake to rest before reporting the stop (moveL returns False after stopping)."""
        while np.any(self._velocity) or np.any(self._angular_velocity):
            self._advance_one_period(integrate=True)

    def _on_clock_advance(self, now_ns: int) -> None:
        """Someone else advanced the clock: integrate the periods that passed (no clock advance from here)."""
        while self._integrated_ns + self._period_ns <= now_ns:
            self._integrate_motion()
            self._update_sensor()
            self._integrated_ns += self._period_ns
        self._latest = self._snapshot()

    def _advance_one_period(self, *, integrate: bool) -> None:
        if integrate:
            self._integrate_motion()
        self._update_sensor()
        self._integrated_ns += self._period_ns
        self.virtual_clock.advance_ns(self._period_ns)  # our listener takes the new snapshot

    def _command_twist(self) -> np.ndarray | None:
        """Velocity the controller wants this period, or None in speed/stop mode (accel-limited target)."""
        if self._mode == "force" and self._force_command is not None:
            rotation, chosen, target, speed_limits = self._force_command
            measured = self._filtered - self._zero_offset
            applied_task = -np.concatenate([rotation.T @ measured[:3], rotation.T @ measured[3:]])
            gains = np.array(
                [self.params.force_mode_gain_m_s_per_n] * 3 + [self.params.force_mode_gain_rad_s_per_nm] * 3
            )
            twist_task = np.where(chosen, np.clip(gains * (target - applied_task), -speed_limits, speed_limits), 0.0)
            return np.concatenate([rotation @ twist_task[:3], rotation @ twist_task[3:]])
        if self._mode == "idle":
            return np.zeros(6)
        return None

    def _integrate_motion(self) -> None:
        dt = self.control_period_s
        commanded = self._command_twist()
        if commanded is not None:  # idle or force mode: the velocity is set, not ramped
            step = 0.5 * (self._velocity + commanded[:3]) * dt
            turn = 0.5 * (self._angular_velocity + commanded[3:]) * dt
            self._velocity, self._angular_velocity = commanded[:3].copy(), commanded[3:].copy()
        else:
            self._velocity, step = _ramp(self._velocity, self._target_twist[:3], self._accel_m_s2, dt)
            if np.any(self._angular_velocity) or np.any(self._target_twist[3:]):
                self._angular_velocity, turn = _ramp(
                    self._angular_velocity, self._target_twist[3:], self._accel_m_s2, dt
                )
            else:
                turn = np.zeros(3)
            if self._mode == "stop" and not np.any(self._velocity) and not np.any(self._angular_velocity):
                self._mode = "idle"
        self._position = self._position + step
        if np.any(turn):
            self._set_rotation(rotvec_to_matrix(turn) @ self._rotation)

    def _update_sensor(self) -> None:
        """One F/T sample: true wrench -> latency -> + bias + noise -> low-pass; and the protective-stop check."""
        dt = self.control_period_s
        self._true_wrench = np.asarray(self.world.wrench_on_tool(self.true_tcp_pose()), dtype=np.float64)
        self._delay_line.append(self._true_wrench.copy())
        delayed = self._delay_line.popleft()
        p = self.params
        if p.ft_bias_drift_n_per_sqrt_s > 0:
            self._bias = self._bias + self._rng.normal(0.0, p.ft_bias_drift_n_per_sqrt_s * math.sqrt(dt), 6) * (
                self._axis_scale
            )
        raw = delayed + self._bias
        if p.ft_noise_sigma_n > 0:
            raw = raw + self._rng.normal(0.0, p.ft_noise_sigma_n, 6) * self._axis_scale
        self._filtered = self._filtered + self._filter_alpha * (raw - self._filtered)
        if float(np.linalg.norm(self._true_wrench[:3])) > p.protective_stop_n:
            self._enter_protective_stop()

    def _snapshot(self) -> ArmState:
        now_ns = self.clock.now_ns()
        return ArmState(
            host_t_ns=now_ns,
            controller_t_s=now_ns / 1e9,
            tcp_pose=self.true_tcp_pose(),
            tcp_force=self._filtered - self._zero_offset,
            robot_mode=ROBOT_MODE_RUNNING,
            safety_mode=SAFETY_MODE_PROTECTIVE_STOP if self._protective_stop else SAFETY_MODE_NORMAL,
            protective_stop=self._protective_stop,
            tcp_speed=np.concatenate([self._velocity, self._angular_velocity]),
        )


def _as_vector(values: np.ndarray, size: int, what: str) -> np.ndarray:
    vector = np.asarray(values, dtype=np.float64).reshape(-1)
    if vector.shape != (size,) or not np.all(np.isfinite(vector)):
        raise ArmError(f"{what} must be {size} finite numbers, got {values!r}")
    return vector.copy()


def _ramp(current: np.ndarray, target: np.ndarray, accel: float, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """Move a velocity toward ``target`` at ``accel`` for ``dt``: -> (new velocity, exact distance covered)."""
    delta = target - current
    change = float(np.linalg.norm(delta))
    if change <= accel * dt:
        reach_s = change / accel if accel > 0 else 0.0
        distance = 0.5 * (current + target) * reach_s + target * (dt - reach_s)
        return target.copy(), distance
    new = current + delta / change * accel * dt
    return new, 0.5 * (current + new) * dt


class _Trapezoid:
    """Trapezoidal progress over ``distance`` (m or rad) with peak speed and acceleration; fraction 0..1 in time."""

    def __init__(self, distance: float, speed: float, accel: float) -> None:
        self.distance = distance
        if distance <= 0 or speed <= 0:
            self.ramp_s, self.cruise_s, self.peak = 0.0, 0.0, 0.0
        elif distance < speed * speed / accel:  # never reaches cruise speed
            self.ramp_s = math.sqrt(distance / accel)
            self.cruise_s = 0.0
            self.peak = accel * self.ramp_s
        else:
            self.ramp_s = speed / accel
            self.cruise_s = (distance - speed * self.ramp_s) / speed
            self.peak = speed
        self.accel = accel
        self.duration_s = 2 * self.ramp_s + self.cruise_s

    def at(self, t: float) -> tuple[float, float]:
        """-> (fraction of the distance done, rate of that fraction per second) at time ``t``."""
        if self.distance <= 0 or self.duration_s <= 0:
            return 1.0, 0.0
        a, ramp, cruise = self.accel, self.ramp_s, self.cruise_s
        if t <= ramp:
            done, speed = 0.5 * a * t * t, a * t
        elif t <= ramp + cruise:
            done, speed = 0.5 * a * ramp * ramp + self.peak * (t - ramp), self.peak
        else:
            left = max(0.0, self.duration_s - t)
            done, speed = self.distance - 0.5 * a * left * left, a * left
        return min(1.0, done / self.distance), speed / self.distance
