"""The simulated UR5e: a kinematic arm on a virtual clock with the wrist force/torque sensor a real UR gives you.

It implements :class:`drivers.arm.Arm`, so the press routine cannot tell it from :class:`drivers.ur5e.UR5eArm`.

What is modelled (numbers and sources in :class:`SimArmParams`):

* kinematics only: the TCP follows commanded velocities under an acceleration limit (``speed_linear``), decelerates
  over ``v^2 / 2a`` when stopped (``stop``), follows a trapezoidal straight line (``start_move_linear``, asynchronous
  and stoppable like ``moveL(..., asynchronous=True)``; ``move_linear`` blocks until it ends), or obeys an admittance
  law in force mode (``force_mode``: velocity along a compliant axis = gain x force error, clipped to the axis' speed
  limit and reached under an acceleration limit; non-compliant axes hold still);
* the wrist F/T: the world's wrench (:class:`unitac_rig.sim.world.ContactWorld`) delayed by a few ms, plus a bias
  that starts random and drifts slowly (so ``zero_ft`` matters), plus white noise, through a first-order low-pass
  filter, minus the offset captured by the last ``zero_ft``;
* the control program a real controller runs for ur_rtde, with the behaviour that matters for safety
  (``hardware-facts`` 3.8 and ur_rtde's ``rtde_control.script``):

  - the controller keeps executing the last command on its own: whenever the clock advances, by the host's
    ``wait_period`` or by anyone else (a stalled host), the arm moves on. ``speed_linear`` keeps going even with a
    time limit, because ur_rtde's speed thread repeats ``speedl(xd, a, t)`` in a loop; force mode keeps
    regulating toward its last set-point;
  - the RTDE watchdog (``watchdog_hz``, armed by the first motion command): if the host writes nothing (a command
    or ``wait_period``; time inside ``keep_alive`` counts as written) for longer than 1 / frequency, the program
    stops and the arm brakes to rest;
  - a protective stop when the true contact force exceeds ``protective_stop_n`` (or on
    :meth:`SimArm.trigger_protective_stop`): the arm brakes to rest, the program stops, and every command raises
    (:class:`~drivers.errors.ProtectiveStop` while the stop lasts, then
    :class:`~drivers.errors.ControlScriptStopped`) until the stop is unlocked *and* the program re-uploaded
    (:meth:`unlock_protective_stop`, :meth:`reupload_script`), as with ``reuploadScript()`` on a real arm.

Not modelled: joint space, singularities, reach, arm dynamics or compliance, the 5 s wait before a protective stop
may be unlocked, payload/gravity compensation of the F/T, emergency and safeguard stops.

Time only moves when someone advances the virtual clock: ``wait_period`` integrates one 2 ms control period and then
advances the clock (which makes simulated sensors emit the samples that fall due, reading :meth:`true_tcp_pose`).
If other code advances the clock directly (a host stall injected by a test or benchmark), the arm integrates those
periods too (it listens to the clock), exactly as a controller goes on while its host is frozen.

Why one module: the kinematics, the F/T model and the controller-program model (watchdog, protective
stop) all act on one state per control period.
"""

from __future__ import annotations

import contextlib
import math
from collections import deque
from collections.abc import Iterator
from dataclasses import dataclass
from typing import Literal

import numpy as np

from drivers.arm import DEFAULT_WATCHDOG_HZ, ArmState, checked_force_mode_parameters
from drivers.clock import Clock, VirtualClock
from drivers.errors import ArmError, ControlScriptStopped, ProtectiveStop
from unitac_rig.rig.poses import matrix_to_rotvec, rotvec_to_matrix
from unitac_rig.sim.ft_noise import FtNoise, NormalBlocks
from unitac_rig.sim.world import ContactWorld

ROBOT_MODE_RUNNING = 7
SAFETY_MODE_NORMAL = 1
SAFETY_MODE_PROTECTIVE_STOP = 3

DEFAULT_START_POSE = np.array([-0.15, 0.52, 0.25, 0.0, 2.2214, -2.2214])  # m, rad: pad facing base +y

_UNLOCK_HINT = "unlock the protective stop, then re-upload the control program"
# rad/s: the angular velocity of an arm that is not turning (most periods: checking this identity replaces a
# reduction); read only.
_NO_TURN = np.zeros(3)
_NO_TURN.flags.writeable = False


@dataclass(frozen=True)
class SimArmParams:
    """Simulated-arm parameters. [S] sourced, [D] derived, [I] assumed (see ``scene-facts.md`` section 3)."""

    # Wrist F/T. UR5e datasheet: precision +-3.5 N, accuracy +-4.0 N [S]; the scene notes suggest sigma ~1-2 N per
    # 500 Hz sample for the simulated stop decision [I]. 1.15 N [fitted]: 1.5 N gave ~1.3x the recorded sessions'
    # wrist noise (scene-facts section 8), and a session's peak force is the noise's extreme on top of the stop,
    # so TPU sessions peaked at 11.2-11.8 N against the recorded 10.6-11.0 (docs/simulator.md, fidelity). After the
    # 20 Hz filter below, 1.15 N becomes ~0.4 N.
    ft_noise_sigma_n: float = 1.15
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
    # Deceleration during a protective stop (a category-2 stop along the path; the real-time twin's emergency stop
    # and power off brake the same) [I]: the stopL default, 10 m/s^2.
    protective_stop_decel_m_s2: float = 10.0
    # Deceleration when the program stops (watchdog, stopScript, the dashboard's stop) [I]: 10 m/s^2.
    program_stop_decel_m_s2: float = 10.0
    # Argument checks ur_rtde applies (tool speed <= 3 m/s, tool accel <= 150 m/s^2) [S, hardware-facts 3.4].
    max_tool_speed_m_s: float = 3.0
    max_tool_accel_m_s2: float = 150.0
    # Force-mode admittance gains [I]: 2 mm/s per N keeps the loop stable (gain x stiffness x 2 ms < 1) for
    # contact stiffnesses up to ~250 N/mm; torque axes 0.05 rad/s per N*m.
    force_mode_gain_m_s_per_n: float = 0.002
    force_mode_gain_rad_s_per_nm: float = 0.05
    # Force mode reaches the admittance velocity under an acceleration limit, not instantly [I]: a controller
    # brakes a fast approach over a few ms when the contact force rises, which adds to the overshoot. 1 m/s^2
    # (1 rad/s^2) brakes 15 mm/s in 15 ms over 0.11 mm.
    force_mode_accel_m_s2: float = 1.0


_Mode = Literal["idle", "speed", "stop", "force", "path"]


@dataclass
class _Path:
    """An asynchronous straight-line move in progress (trapezoidal profile over the distance)."""

    start_position: np.ndarray
    start_rotation: np.ndarray
    delta_position: np.ndarray
    delta_rotvec: np.ndarray
    goal: np.ndarray
    profile: _Trapezoid
    elapsed_s: float = 0.0
    # a move that does not turn has the same orientation every period: (matrix, rotation vector), formed once
    held_rotation: tuple[np.ndarray, np.ndarray] | None = None


class SimArm:
    """A simulated UR5e implementing :class:`drivers.arm.Arm` on a :class:`~drivers.clock.VirtualClock`.

    ``world`` gives the wrench on the tool at a pose; ``rng`` drives the F/T noise and bias (seed it for a
    deterministic run); ``start_pose`` is (6,) [x, y, z (m), rx, ry, rz (rad)]. ``watchdog_hz``: the RTDE watchdog
    frequency, armed with the first motion command (the fast twin's arm exists before the host first uses it, and
    sensor detection advances the clock meanwhile); None leaves it off.
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
        watchdog_hz: float | None = DEFAULT_WATCHDOG_HZ,
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
        initial = np.concatenate([self._position, self._rotvec])
        initial.flags.writeable = False
        self._pose_of: tuple[np.ndarray, np.ndarray, np.ndarray] = (self._position, self._rotvec, initial)
        self._velocity = np.zeros(3)  # m/s, base frame
        self._speed_of: tuple[np.ndarray | None, np.ndarray | None, np.ndarray] = (None, None, _NO_TURN)
        self._angular_velocity = _NO_TURN  # rad/s, base frame
        self._mode: _Mode = "idle"
        self._target_twist = np.zeros(6)
        self._accel_m_s2 = 0.0
        # (task frame rotation, selected axes, target wrench, speed limits) of the force mode in force
        self._force_command: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None = None
        self._force_key: tuple[bytes, ...] = ()  # its arguments' float64 bytes
        self._path: _Path | None = None
        self._protective_stop = False
        self._program_running = True
        self._program_stop_reason: str | None = None
        self._closed = False

        self._period_ns = round(self.control_period_s * 1e9)
        self._integrated_ns = clock.now_ns()
        if watchdog_hz is not None and not watchdog_hz > 0:
            raise ArmError(f"watchdog frequency must be > 0 Hz, got {watchdog_hz}")
        self._watchdog_hz = watchdog_hz  # what every start of the control program arms at its first motion
        self._watchdog_ns: int | None = None  # armed: longest allowed gap between host writes
        self._last_write_ns = self._integrated_ns
        self._kept_alive = False

        self._true_wrench = np.array(world.wrench_on_tool(self.true_tcp_pose()), dtype=np.float64)
        delay_periods = max(0, round(self.params.ft_latency_s / self.control_period_s))
        # Holds the last ``delay_periods`` true wrenches: append the new one, pop the one that is now due.
        self._delay_line: deque[np.ndarray] = deque([self._true_wrench.copy()] * delay_periods)
        self._axis_scale = np.array([1.0, 1.0, 1.0] + [self.params.ft_torque_scale_m] * 3)
        self._bias = rng.normal(0.0, self.params.ft_bias_sigma_n, 6) * self._axis_scale
        self._ft_noise = self._ft_noise_from(rng)
        self._filtered = self._true_wrench + self._bias
        self._zero_offset = np.zeros(6)
        self._gains = np.array(
            [self.params.force_mode_gain_m_s_per_n] * 3 + [self.params.force_mode_gain_rad_s_per_nm] * 3
        )
        self.force_mode_damping, self.force_mode_gain_scaling = 0.005, 1.0  # the URScript defaults
        self._ft_sign = 1.0
        cutoff = self.params.ft_filter_cutoff_hz
        self._filter_alpha = 1.0 if cutoff is None else 1.0 - math.exp(-2 * math.pi * cutoff * self.control_period_s)
        self._latest: ArmState | None = self._snapshot()
        clock.on_advance(self._on_clock_advance)

    def _ft_noise_from(self, rng: np.random.Generator) -> FtNoise:
        return FtNoise(
            NormalBlocks(rng),
            self.params.ft_bias_drift_n_per_sqrt_s * math.sqrt(self.control_period_s),
            self.params.ft_noise_sigma_n,
            self._axis_scale,
        )

    def use_noise_stream(self, rng: np.random.Generator) -> None:
        """Draw the F/T's bias drift steps and white noise from ``rng`` from now on (the bias keeps its value): the
        simulated rig keys a stream per session, as it does the sensors' (fast_rig.noise_seed)."""
        self._ft_noise = self._ft_noise_from(rng)

    # ---- truth (for simulated sensors and tests) ------------------------------------------------------------

    def true_tcp_pose(self) -> np.ndarray:
        """Noise-free TCP pose (6,) [m, rad rotation vector], base frame: what simulated sensors feel. Read only
        (the arm's own array, asked for every control period by the state and the sensors): copy it to change it."""
        return self._pose()

    def _pose(self) -> np.ndarray:
        """The pose array itself, read only: formed once for each (position, rotation vector) pair. Both are
        replaced, never changed in place, so their identity says whether the pose moved (the world, the F/T
        snapshot and the sensors read it every control period)."""
        position, rotvec, pose = self._pose_of
        if position is not self._position or rotvec is not self._rotvec:
            pose = np.concatenate([self._position, self._rotvec])
            pose.flags.writeable = False
            self._pose_of = (self._position, self._rotvec, pose)
        return pose

    def true_wrench(self) -> np.ndarray:
        """The world's wrench on the tool now (6,) [N, N*m], base axes; no latency, noise, bias or filter."""
        return self._true_wrench.copy()

    def latest_state(self) -> ArmState:
        """The state after the last control period: an immutable snapshot. Formed when first read after the clock
        moved (the host reads it in some periods, not all: forming it every period was a tenth of the simulator's
        cost), so read it from the thread that drives the clock, or between advances."""
        latest = self._latest
        if latest is None:
            latest = self._latest = self._snapshot()
        return latest

    # ---- Arm: state -----------------------------------------------------------------------------------------

    def read_state(self) -> ArmState:
        return self.latest_state()

    # ---- Arm: commands --------------------------------------------------------------------------------------

    def start_move_linear(self, pose: np.ndarray, speed_m_s: float, accel_m_s2: float) -> None:
        """Start a straight line with a trapezoidal speed profile and return at once (``moveL`` asynchronous).

        The orientation turns in proportion to the distance covered. The move runs as the clock advances;
        :meth:`move_running` says when it is over, :meth:`stop` ends it early.
        """
        self._command()
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
        self._path = _Path(start_position, start_rotation, delta_position, delta_rotvec, goal, profile)

    def move_running(self) -> bool:
        """True while the move started by :meth:`start_move_linear` runs (``getAsyncOperationProgress() >= 0``)."""
        return self._mode == "path"

    def move_linear(self, pose: np.ndarray, speed_m_s: float, accel_m_s2: float) -> None:
        """Blocking straight line: :meth:`start_move_linear`, then the clock advances (host-driven) until it ends.

        Raises ProtectiveStop (arm at rest) if a protective stop trips on the way.
        """
        self.start_move_linear(pose, speed_m_s, accel_m_s2)
        assert self._path is not None
        if self._path.profile.duration_s <= 0:  # nothing to do: land exactly, spend no time
            self._finish_path(self._path)
            return
        while self._mode == "path":
            self.wait_period()
        if self._protective_stop:
            self._settle_after_protective_stop()
            raise ProtectiveStop("protective stop during a linear move", hint=_UNLOCK_HINT)
        if not self._program_running:
            reason = self._program_stop_reason
            raise ControlScriptStopped(f"the control program stopped during a linear move ({reason})")

    def speed_linear(self, twist: np.ndarray, accel_m_s2: float, time_s: float = 0.0) -> None:
        """Velocity command (m/s, rad/s, base frame) reached under ``accel_m_s2``; lasts until the next command.

        ``time_s`` is accepted like ur_rtde's ``speedL(xd, a, t)`` and, as on a controller running ur_rtde's script,
        does not end the motion: the script's speed thread calls ``speedl(xd, a, t)`` again and again.
        """
        self._command()
        target = _as_vector(twist, 6, "twist")
        self._check_speed(float(np.linalg.norm(target[:3])), accel_m_s2)
        if not time_s >= 0:
            raise ArmError(f"speedL time must be >= 0 s, got {time_s}")
        self._mode, self._force_command, self._path = "speed", None, None
        self._target_twist = target
        self._accel_m_s2 = accel_m_s2

    def stop(self, decel_m_s2: float = 10.0) -> None:
        """Decelerate to rest at ``decel_m_s2`` (stopping distance v^2 / 2a), ending a move, a speed command or force
        mode. Never raises on a stopped arm (closed, protective stop, program not running)."""
        if decel_m_s2 <= 0:
            raise ArmError(f"deceleration must be > 0 m/s^2, got {decel_m_s2}")
        if self._closed or self._protective_stop or not self._program_running:
            return  # already braking (protective stop, program stop) or at rest
        self._note_write()
        self._begin_stop(min(decel_m_s2, self.params.max_tool_accel_m_s2))

    def zero_ft(self) -> None:
        """Take the current (filtered) F/T reading as the new zero, like ``zeroFtSensor``."""
        self._command()
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
        self._command()
        # The host re-sends an unchanged command every period (a ur_rtde loop does): validating it and building its
        # frame again was half the cost of a force-mode period, so the one in force is kept.
        key = tuple(np.asarray(v, dtype=np.float64).tobytes() for v in (task_frame, selection, wrench, limits))
        if self._mode == "force" and self._force_command is not None and key == self._force_key:
            return
        frame = _as_vector(task_frame, 6, "task_frame")
        chosen = _as_vector(selection, 6, "selection") != 0
        target = _as_vector(wrench, 6, "wrench")
        speed_limits = np.abs(_as_vector(limits, 6, "limits"))
        self._mode, self._path = "force", None
        self._force_command = (rotvec_to_matrix(frame[3:]), chosen, target, speed_limits)
        self._force_key = key

    def set_ft_sign(self, sign: float) -> None:
        """A fault hook: -1 reports the negated F/T (a flipped sensor frame); force mode regulates on the same
        reading, as a controller does."""
        self._ft_sign = float(sign)
        self._latest = self._snapshot()

    def set_force_mode_parameters(self, damping: float, gain_scaling: float) -> None:
        """``force_mode_set_damping`` / ``force_mode_set_gain_scaling``: the gain scaling multiplies the admittance
        gains (as on a UR, where above 1 the loop may go unstable on hard contacts); damping is stored, not modelled
        (the admittance here has no free-air coasting for it to brake)."""
        self.force_mode_damping, self.force_mode_gain_scaling = checked_force_mode_parameters(damping, gain_scaling)

    def force_mode_stop(self) -> None:
        """Leave force mode and stop (the ur_rtde script does ``end_force_mode(); stopl(10)``)."""
        if self._mode == "force":
            self._note_write()
            self._force_command = None
            if not self._protective_stop:
                self._begin_stop(10.0)

    @contextlib.contextmanager
    def keep_alive(self) -> Iterator[None]:
        """Feed the watchdog while the host does non-motion work with the arm at rest (UR5eArm runs a kicker
        thread); time advanced inside counts as kicked. A motion still commanded is stopped first."""
        if self._mode not in ("idle", "stop"):
            self.stop()
        self._kept_alive = True
        try:
            yield
        finally:
            self._kept_alive = False
            self._note_write()

    def wait_period(self) -> None:
        """Integrate one control period, then advance the virtual clock by it (simulated sensors sample then).

        Counts as a host write for the watchdog (``UR5eArm.wait_period`` kicks it).
        """
        if self._closed:
            raise ArmError("the simulated arm is closed", hint="open a new rig")
        self._note_write()
        self._advance_one_period(integrate=True)

    def close(self) -> None:
        """Stop the arm (at once: nothing drives the clock afterwards) and detach from the clock. Idempotent."""
        if self._closed:
            return
        self._closed = True
        self._mode, self._force_command, self._path = "idle", None, None
        self._velocity, self._angular_velocity = np.zeros(3), _NO_TURN
        self._latest = self._snapshot()
        self.virtual_clock.remove_listener(self._on_clock_advance)

    # ---- faults and recovery --------------------------------------------------------------------------------

    def trigger_protective_stop(self) -> None:
        """Fault hook: the controller enters a protective stop now (as if a safety limit tripped)."""
        self._enter_protective_stop()
        self._latest = self._snapshot()

    def unlock_protective_stop(self) -> None:
        """Clear a protective stop (the dashboard's ``unlock protective stop``). It trips again if the force is still
        high. The program stays stopped: commands are refused until :meth:`reupload_script`."""
        self._protective_stop = False
        self._latest = self._snapshot()

    def reupload_script(self) -> None:
        """Start the control program again (``reuploadScript()``). The watchdog is armed again by the next motion
        command, as :class:`drivers.ur5e.UR5eArm` arms it at each motion start: a resumed session keeps its bound.

        Raises ProtectiveStop while a protective stop is not yet unlocked.
        """
        if self._closed:
            raise ArmError("the simulated arm is closed", hint="open a new rig")
        if self._protective_stop:
            raise ProtectiveStop("cannot start the control program during a protective stop", hint=_UNLOCK_HINT)
        self.latest_state()  # the state of the last period keeps the stopped program until the next period
        self._program_running, self._program_stop_reason = True, None
        self._watchdog_ns = None
        self._note_write()

    def stop_program(self, reason: str = "stopped by the host") -> None:
        """Stop the control program (``stopScript``, or the pendant's stop button): the arm brakes to rest."""
        self._stop_program(reason)
        self._latest = self._snapshot()

    @property
    def protective_stopped(self) -> bool:
        return self._protective_stop

    @property
    def program_running(self) -> bool:
        return self._program_running

    @property
    def program_stop_reason(self) -> str | None:
        """Why the program last stopped ("watchdog", "protective stop", ...), None while it runs."""
        return self._program_stop_reason

    # ---- internals ------------------------------------------------------------------------------------------

    def _set_rotation(self, rotation: np.ndarray, rotvec: np.ndarray | None = None) -> None:
        """Keep the matrix and its rotation vector together (the vector is read every period).

        Pass ``rotvec`` when it is known exactly: converting back loses ~1e-7 rad near a half turn.
        """
        self._rotation = rotation
        self._rotvec = matrix_to_rotvec(rotation) if rotvec is None else np.array(rotvec, dtype=np.float64)

    def _command(self) -> None:
        """Gate of every motion command: refuse it unless the program runs, count the write, arm the watchdog."""
        if self._closed:
            raise ArmError("the simulated arm is closed", hint="open a new rig")
        if self._protective_stop:
            raise ProtectiveStop("the simulated arm is in a protective stop", hint=_UNLOCK_HINT)
        if not self._program_running:
            raise ControlScriptStopped(
                f"the control program is not running ({self._program_stop_reason})",
                hint="re-upload the control program (a new connection does it)",
            )
        self._note_write()
        if self._watchdog_ns is None and self._watchdog_hz is not None:
            self._watchdog_ns = round(1e9 / self._watchdog_hz)

    def _note_write(self) -> None:
        self._last_write_ns = max(self._last_write_ns, self.virtual_clock.now_ns())

    def _check_speed(self, speed_m_s: float, accel_m_s2: float) -> None:
        if not 0 <= speed_m_s <= self.params.max_tool_speed_m_s:
            raise ArmError(f"tool speed {speed_m_s} m/s is outside 0..{self.params.max_tool_speed_m_s} m/s")
        if not 0 < accel_m_s2 <= self.params.max_tool_accel_m_s2:
            raise ArmError(f"tool acceleration {accel_m_s2} m/s^2 is outside (0, {self.params.max_tool_accel_m_s2}]")

    def _begin_stop(self, decel_m_s2: float) -> None:
        self._mode, self._force_command, self._path = "stop", None, None
        self._target_twist = np.zeros(6)
        self._accel_m_s2 = decel_m_s2

    def _enter_protective_stop(self) -> None:
        if not self._protective_stop:
            self._protective_stop = True
            self._stop_program("protective stop", decel_m_s2=self.params.protective_stop_decel_m_s2)

    def _stop_program(self, reason: str, decel_m_s2: float | None = None) -> None:
        if self._program_running:
            self._program_running, self._program_stop_reason = False, reason
            self._watchdog_ns = None
        if self._mode != "idle" or np.any(self._velocity) or np.any(self._angular_velocity):
            self._begin_stop(self.params.program_stop_decel_m_s2 if decel_m_s2 is None else decel_m_s2)

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
        self._latest = None  # formed when read (latest_state)

    def _advance_one_period(self, *, integrate: bool) -> None:
        if integrate:
            self._integrate_motion()
        self._update_sensor()
        self._integrated_ns += self._period_ns
        self.virtual_clock.advance_ns(self._period_ns)  # our listener takes the new snapshot

    def _check_watchdog(self) -> None:
        """Controller side, once per period: stop the program when the host has not written in time."""
        if self._watchdog_ns is None or not self._program_running:
            return
        if self._kept_alive:
            self._last_write_ns = self._integrated_ns
        elif self._integrated_ns + self._period_ns - self._last_write_ns > self._watchdog_ns:
            self._stop_program("watchdog: the host wrote nothing in time")

    def _force_twist(self) -> tuple[np.ndarray, np.ndarray]:
        """Velocity the force-mode admittance law asks for this period (base frame): (linear, angular).

        On each selected task axis: gain x (target - applied), clipped to the axis' speed limit, where the wrench
        applied to the environment is minus the measured one in task axes; unselected axes hold still."""
        assert self._force_command is not None
        rotation, chosen, target, speed_limits = self._force_command
        measured = self._measured_ft()
        applied = -np.concatenate([np.dot(rotation.T, measured[:3]), np.dot(rotation.T, measured[3:])])
        gains = self.force_mode_gain_scaling * self._gains
        twist = np.where(chosen, np.minimum(np.maximum(gains * (target - applied), -speed_limits), speed_limits), 0.0)
        return np.dot(rotation, twist[:3]), np.dot(rotation, twist[3:])

    def _integrate_motion(self) -> None:
        self._check_watchdog()
        dt = self.control_period_s
        if self._mode == "path" and self._path is not None:
            self._step_path(self._path, dt)
            return
        if self._mode == "idle":
            if not _moving(self._velocity) and not _moving(self._angular_velocity):
                return  # at rest: nothing moves (the steps below would all be zero)
            step = 0.5 * self._velocity * dt
            turn = 0.5 * self._angular_velocity * dt
            self._velocity, self._angular_velocity = np.zeros(3), _NO_TURN
        else:
            if self._mode == "force" and self._force_command is not None:
                (linear, angular), accel = self._force_twist(), self.params.force_mode_accel_m_s2
            else:
                linear, angular, accel = self._target_twist[:3], self._target_twist[3:], self._accel_m_s2
            self._velocity, step = _ramp(self._velocity, linear, accel, dt)
            turning = self._angular_velocity is not _NO_TURN and _moving(self._angular_velocity)
            if turning or (angular is not _NO_TURN and _moving(angular)):
                self._angular_velocity, turn = _ramp(self._angular_velocity, angular, accel, dt)
            else:
                turn = _NO_TURN
            if self._mode == "stop" and not _moving(self._velocity) and not _moving(self._angular_velocity):
                self._mode = "idle"
        self._position = self._position + step
        if turn is not _NO_TURN and _moving(turn):
            self._set_rotation(rotvec_to_matrix(turn) @ self._rotation)

    def _step_path(self, path: _Path, dt: float) -> None:
        path.elapsed_s = min(path.elapsed_s + dt, path.profile.duration_s)
        fraction, rate = path.profile.at(path.elapsed_s)
        if fraction >= 1.0:  # land exactly on the commanded pose
            self._finish_path(path)
            return
        self._position = path.start_position + fraction * path.delta_position
        if path.held_rotation is not None:
            self._rotation, self._rotvec = path.held_rotation
        else:
            self._set_rotation(rotvec_to_matrix(fraction * path.delta_rotvec) @ path.start_rotation)
            if not _moving(path.delta_rotvec):  # fraction x 0: the same matrix every period
                path.held_rotation = (self._rotation, self._rotvec)
        self._velocity = rate * path.delta_position
        self._angular_velocity = rate * path.delta_rotvec

    def _finish_path(self, path: _Path) -> None:
        self._position = path.goal[:3].copy()
        self._set_rotation(rotvec_to_matrix(path.goal[3:]), path.goal[3:])
        self._velocity, self._angular_velocity = np.zeros(3), _NO_TURN
        self._mode, self._path = "idle", None
        self._latest = self._snapshot()

    def _update_sensor(self) -> None:
        """One F/T sample: true wrench -> latency -> + bias (drifting) + noise -> low-pass; and the protective-stop
        check on the true force."""
        # a new array every period, never changed in place: the delay line holds the earlier ones
        self._true_wrench = np.array(self.world.wrench_on_tool(self._pose()), dtype=np.float64)
        self._delay_line.append(self._true_wrench)
        self._bias, noise = self._ft_noise.next(self._bias)
        raw = self._delay_line.popleft() + self._bias
        if noise is not None:
            raw = raw + noise
        self._filtered = self._filtered + self._filter_alpha * (raw - self._filtered)
        if float(np.linalg.norm(self._true_wrench[:3])) > self.params.protective_stop_n:
            self._enter_protective_stop()

    def _measured_ft(self) -> np.ndarray:
        """The F/T reading the controller reports and regulates on: sign x (filtered - zero offset); read only."""
        reading = self._ft_sign * (self._filtered - self._zero_offset)
        reading.flags.writeable = False
        return reading

    def _snapshot(self) -> ArmState:
        now_ns = self.clock.now_ns()
        return ArmState(
            host_t_ns=now_ns,
            controller_t_s=now_ns / 1e9,
            tcp_pose=self.true_tcp_pose(),
            tcp_force=self._measured_ft(),
            robot_mode=ROBOT_MODE_RUNNING,
            safety_mode=SAFETY_MODE_PROTECTIVE_STOP if self._protective_stop else SAFETY_MODE_NORMAL,
            protective_stop=self._protective_stop,
            tcp_speed=self._speed(),
            program_running=self._program_running,
        )

    def _speed(self) -> np.ndarray:
        """The TCP speed (6,) [m/s, rad/s], read only; formed once for each (velocity, angular velocity) pair."""
        velocity, angular, speed = self._speed_of
        if velocity is not self._velocity or angular is not self._angular_velocity:
            speed = np.concatenate([self._velocity, self._angular_velocity])
            speed.flags.writeable = False
            self._speed_of = (self._velocity, self._angular_velocity, speed)
        return speed


def _moving(values: np.ndarray) -> bool:
    """``values.any()`` for a short vector (a -0.0 is no motion either, NaN is), at a fraction of the cost of numpy's
    reduction wrapper."""
    return any(values.tolist())


def _as_vector(values: np.ndarray, size: int, what: str) -> np.ndarray:
    vector = np.asarray(values, dtype=np.float64).reshape(-1)
    if vector.shape != (size,) or not np.all(np.isfinite(vector)):
        raise ArmError(f"{what} must be {size} finite numbers, got {values!r}")
    return vector.copy()


def _ramp(current: np.ndarray, target: np.ndarray, accel: float, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """Move a velocity toward ``target`` at ``accel`` for ``dt``: -> (new velocity, exact distance covered)."""
    delta = target - current
    change = math.sqrt(float(delta.dot(delta)))
    if change == 0.0:  # already there (most force-mode periods, at the speed limit)
        return target.copy(), target * dt
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
