"""Emulation of ur_rtde's uploaded control script (``rtde_control.script``, as the 1.6.5 wheel uploads it).

The real client talks to its script only through RTDE registers, so the twin runs the script's logic here instead of
a URScript interpreter. What follows is that script's behaviour, read from the program the 1.6.5 client uploads
(captured by the twin's script port) and cross-checked against ur_rtde's release 1.6.0 source:

* **main loop**, once per controller cycle (``sync()``): ``cmd = input_int_register_0``. *Realtime* commands (speedL
  10, speedJ 9, servoJ 11, servoL 24, servoC 12, forceMode 6, toolContact 25, getStepTime 26, joint history 27,
  joint torques 38, flange pose 58, the torque commands 66-71) are processed every cycle the register holds them,
  then ``output_int_register_0`` = 1 (ready). For every other command: 0 clears (``executing = False``, ready); a
  non-zero id runs once (``process_cmd``), ends with ``output_int_register_0`` = 2 (done) and is not run again until
  the client writes 0. ``process_cmd`` runs motions inline: a blocking ``movel``, ``stopl`` or the ``stopl`` after
  speedStop/forceModeStop keep the main loop busy (it reads no register) until the arm is at rest or there.
* **threads**: ``speedL`` starts a speed thread that repeats ``speedl(target, a)`` -- or ``speedl(target, a, t)``
  when a time was given, *in the same endless loop*, so in this script a time limit does **not** end the motion --
  until speedStop (15) kills it and runs ``stopl(a)``. ``forceMode`` starts a force thread re-applying
  ``force_mode(...)`` every cycle until forceModeStop (7: ``end_force_mode(); stopl(10)``). ``moveL(async=True)``
  starts a move thread and signals done at once; stopL/stopJ (33/34) kill it (and only it) and stop, synchronously or
  in a stop thread. ``output_int_register_2`` is the async progress word: bits 24-30 an operation id incremented at
  each start, bits 16-22 a write counter, bit 15 running, bits 0-14 progress.
* **set_watchdog** (35) arms ``rtde_set_watchdog("input_int_register_0", f, "stop")``: the controller stops the
  program when that register is not written at least at f Hz (the controller side lives in
  :mod:`unitac_rig.sim.twin.controller`).
* **stopScript** (255) ends the main loop: the program stops. **protective_stop** (31) triggers a protective stop.

Not emulated (the program stops with a runtime error, so a client sees False rather than a silent success): joint
moves and joint-space commands, servo*, path moves (``moveL(path)`` re-uploads the script with injected ``movel``
lines), moveUntilContact and contact detection, teach/freedrive, jogging, kinematics queries other than the TCP.
"""

from __future__ import annotations

import logging
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np

from unitac_rig.sim.twin.motion import TwinArm

logger = logging.getLogger(__name__)

# Command ids of the 1.6.5 script (process_cmd).
CMD_NONE = 0
CMD_MOVEL = 3
CMD_FORCE_MODE = 6
CMD_FORCE_MODE_STOP = 7
CMD_ZERO_FT = 8
CMD_SPEEDJ = 9
CMD_SPEEDL = 10
CMD_SPEED_STOP = 15
CMD_SET_PAYLOAD = 17
CMD_FORCE_MODE_SET_DAMPING = 20
CMD_FORCE_MODE_SET_GAIN_SCALING = 21
CMD_GET_STEPTIME = 26
CMD_SET_TCP = 29
CMD_PROTECTIVE_STOP = 31
CMD_STOPL = 33
CMD_STOPJ = 34
CMD_SET_WATCHDOG = 35
CMD_IS_POSE_WITHIN_SAFETY_LIMITS = 36
CMD_POSE_TRANS = 39
CMD_GET_TCP_OFFSET = 40
CMD_GET_FORWARD_KINEMATICS_DEFAULT = 43
CMD_IS_STEADY = 47
CMD_GET_FLANGE_POSE = 58
CMD_SET_GRAVITY = 59
CMD_SET_TARGET_PAYLOAD = 65
CMD_STOP_SCRIPT = 255

# The main loop's test for "realtime" commands, copied from the script.
REALTIME_COMMANDS = frozenset({24, 11, 9, 10, 6, 25, 26, 27, 38, 58, 66, 67, 68, 69, 70, 71})

READY = 1  # output_int_register_0
DONE = 2

FORCE_STOP_DECEL_M_S2 = 10.0  # forceModeStop: end_force_mode(); stopl(10)
AT_REST_M_S = 1e-9  # speed below which a stopl/movel has finished


class ScriptHost(Protocol):
    """What the script needs from the controller around it."""

    arm: TwinArm

    def set_watchdog(self, register: str, min_frequency_hz: float) -> None: ...

    def trigger_protective_stop(self) -> None: ...

    def set_payload(self, mass_kg: float, cog_m: np.ndarray | None) -> None: ...

    def reachable(self, tcp_pose: np.ndarray) -> bool: ...

    def prepare_move(self, tcp_pose: np.ndarray) -> None: ...


class ScriptError(Exception):
    """A URScript runtime error: the controller stops the program (and says why in its log)."""


@dataclass
class OutputRegisters:
    """Output registers the script writes (ints 0..47, doubles 0..47)."""

    ints: list[int] = field(default_factory=lambda: [0] * 48)
    doubles: list[float] = field(default_factory=lambda: [0.0] * 48)


class ControlScript:
    """One running instance of the uploaded control script; :meth:`cycle` is one pass of its main loop + threads.

    ``register_offset`` is 0, or 24 with ur_rtde's UPPER_RANGE flag (read from the uploaded text). Output registers
    live in ``outputs`` (shared with the controller, which streams them); inputs are read from the mapping passed to
    :meth:`cycle`. :attr:`finished` turns True when the script ends (stopScript); :class:`ScriptError` from
    :meth:`cycle` means a runtime error.
    """

    def __init__(self, host: ScriptHost, outputs: OutputRegisters, *, register_offset: int = 0) -> None:
        self.host = host
        self.out = outputs
        self.offset = register_offset
        self.finished = False
        self._executing = False
        self._blocking: str | None = None  # "movel" | "stop": the main loop waits in a motion
        self._speed_thread = False
        self._speed_args: tuple[tuple[float, ...], float] | None = None
        self._force_thread = False
        self._force_args: tuple[np.ndarray, np.ndarray, np.ndarray, int, np.ndarray] | None = None
        self._move_thread = False
        self._stop_thread = False
        self._async_writes = 0
        self._async_op_id = 0
        self._inputs: Mapping[str, float | int] = {}
        self.commands_done = 0
        # script start: reset_async_progress(); signal_ready()
        self._write_async_progress(-1)
        self._out_int(0, READY)

    # ---- registers -----------------------------------------------------------------------------------------

    def _in_int(self, index: int) -> int:
        return int(self._inputs.get(f"input_int_register_{index + self.offset}", 0))

    def _in_double(self, index: int) -> float:
        return float(self._inputs.get(f"input_double_register_{index + self.offset}", 0.0))

    def _in_vector(self, first: int) -> np.ndarray:
        return np.array([self._in_double(first + i) for i in range(6)])

    def _out_int(self, index: int, value: int) -> None:
        self.out.ints[index + self.offset] = int(value)

    def _out_pose(self, first: int, pose: np.ndarray) -> None:
        for i, value in enumerate(np.asarray(pose, dtype=np.float64)):
            self.out.doubles[first + i + self.offset] = float(value)

    def _write_async_progress(self, value: int) -> None:
        """write_async_progress_register: 0 starts an operation, >= 0 running with progress, < 0 finished."""
        self._async_writes = 0 if self._async_writes >= 127 else self._async_writes + 1
        if value == 0:
            self._async_op_id = 0 if self._async_op_id >= 127 else self._async_op_id + 1
        word = self._async_writes * 65536 + self._async_op_id * 16777216
        if value >= 0:
            word += min(value, 32767) + 32768
        self._out_int(2, word)

    # ---- the cycle -----------------------------------------------------------------------------------------

    @property
    def motion_threads(self) -> tuple[str, ...]:
        """Which of the script's motion threads run now (for the twin's ground truth)."""
        names = ("speed", "force", "move", "stop")
        flags = (self._speed_thread, self._force_thread, self._move_thread, self._stop_thread)
        return tuple(n for n, f in zip(names, flags, strict=True) if f)

    def cycle(self, inputs: Mapping[str, float | int]) -> None:
        """One controller cycle of the script (before the arm integrates the period). Raises ScriptError."""
        if self.finished:
            return
        self._inputs = inputs
        self._run_threads()
        if self._blocking is not None:
            if not self._blocking_done():
                return
            self._blocking = None
            self._finish_command()
            return
        cmd = self._in_int(0)
        if cmd in REALTIME_COMMANDS:
            self._process(cmd)
            self._out_int(0, READY)
        elif cmd == CMD_NONE:
            self._executing = False
            self._out_int(0, READY)
        else:
            if not self._executing:
                self._process(cmd)
            self._executing = True

    def _finish_command(self) -> None:
        self.commands_done += 1
        self._out_int(0, DONE)

    def _blocking_done(self) -> bool:
        arm = self.host.arm
        return not arm.move_running() and arm.at_rest(AT_REST_M_S)

    def _run_threads(self) -> None:
        arm = self.host.arm
        if self._move_thread and not arm.move_running():
            self._move_thread = False  # move_thread finished
            self._write_async_progress(-1)
        if self._stop_thread and arm.at_rest(AT_REST_M_S):
            self._stop_thread = False
            self._write_async_progress(-1)
        if self._speed_thread and self._speed_args is not None:
            target, accel = self._speed_args
            arm.speed_linear(np.array(target), accel)  # the thread's speedl(...) runs again every cycle
        if self._force_thread and self._force_args is not None:
            frame, selection, wrench, _kind, limits = self._force_args
            arm.force_mode(frame, selection, wrench, limits)

    # ---- process_cmd ---------------------------------------------------------------------------------------

    def _process(self, cmd: int) -> None:
        handler = _HANDLERS.get(cmd)
        if handler is None:
            raise ScriptError(f"the controller twin does not emulate rtde_control command {cmd}")
        handler(self)
        if self._blocking is None and cmd != CMD_STOP_SCRIPT:
            self._finish_command()

    def _movel(self) -> None:
        pose = self._in_vector(0)
        speed, accel = self._in_double(6), self._in_double(7)
        asynchronous = self._in_int(1) == 1
        if not self.host.reachable(pose):
            raise ScriptError(f"movel: target {np.round(pose, 4).tolist()} is not reachable")
        self._stop_async_move()
        if self._speed_thread or self._force_thread:
            logger.warning("movel while a speed or force thread runs: the twin ends the thread's motion")
            self._speed_thread = self._force_thread = False
        self.host.prepare_move(pose)
        self.host.arm.movel(pose, speed, accel)
        if asynchronous:
            self._move_thread = True
            self._write_async_progress(0)
        else:
            self._blocking = "movel"

    def _stop_async_move(self) -> None:
        if self._move_thread:
            self._move_thread = False
            self._write_async_progress(-1)  # the killed thread cannot signal it, so stop_async_move does

    def _stopl(self) -> None:
        """exec_stopl_stopj: kill a running stop thread or the async move, then stop (inline or in a thread)."""
        decel = self._in_double(0)
        asynchronous = self._in_int(1) == 1
        stop_move = True
        if self._stop_thread:
            stop_move = False
            self._stop_thread = False
            self._write_async_progress(-1)
        if stop_move:
            self._stop_async_move()
        if self._speed_thread or self._force_thread:
            # URScript would have two threads fighting over the arm; the twin lets the running thread keep it
            logger.warning("stopl/stopj while a speed or force thread runs: the thread keeps moving the arm")
            return
        self.host.arm.stop(max(decel, 1e-3))
        if asynchronous:
            self._stop_thread = True
            self._write_async_progress(0)
        else:
            self._blocking = "stop"

    def _force_mode(self) -> None:
        kind = self._in_int(1)
        selection = np.array([self._in_int(2 + i) for i in range(6)], dtype=np.float64)
        frame = self._in_vector(0)
        wrench = self._in_vector(6)
        limits = self._in_vector(12)
        if kind != 2:
            logger.warning("force mode type %d is emulated as type 2 (task frame used as given)", kind)
        self._force_args = (frame, selection, wrench, kind, limits)
        if not self._force_thread:
            self._force_thread = True
            self._speed_thread = False
        self.host.arm.force_mode(frame, selection, wrench, limits)

    def _force_mode_stop(self) -> None:
        self._force_thread = False
        self._force_args = None
        self.host.arm.force_mode_stop()
        self.host.arm.stop(FORCE_STOP_DECEL_M_S2)
        self._blocking = "stop"

    def _speedl(self) -> None:
        xd = tuple(float(v) for v in self._in_vector(0))
        accel = self._in_double(6)
        if accel <= 0:
            raise ScriptError(f"speedl: acceleration must be > 0, got {accel}")
        self._speed_args = (xd, accel)  # speed_time (register 7) only sets how often speedl returns: see module doc
        if not self._speed_thread:
            self._speed_thread = True
            self._force_thread = False
        self.host.arm.speed_linear(np.array(xd), accel)

    def _speed_stop(self) -> None:
        decel = self._in_double(0)
        self._speed_thread = False
        self._speed_args = None
        self.host.arm.stop(max(decel, 1e-3))
        self._blocking = "stop"

    def _zero_ft(self) -> None:
        self.host.arm.zero_ft()

    def _set_payload(self) -> None:
        mass = self._in_double(0)
        cog = np.array([self._in_double(1), self._in_double(2), self._in_double(3)])
        self.host.set_payload(mass, None if not np.any(cog) else cog)

    def _set_tcp(self) -> None:
        self.host.arm.active_tcp = self._in_vector(0)

    def _get_tcp_offset(self) -> None:
        self._out_pose(0, self.host.arm.active_tcp)

    def _get_flange_pose(self) -> None:
        arm = self.host.arm
        saved = arm.active_tcp
        arm.active_tcp = np.zeros(6)
        try:
            self._out_pose(0, arm.reported_pose())
        finally:
            arm.active_tcp = saved

    def _forward_kinematics_default(self) -> None:
        self._out_pose(0, self.host.arm.reported_pose())

    def _is_steady(self) -> None:
        self._out_int(1, 1 if self.host.arm.at_rest(1e-4) else 0)

    def _is_pose_within_safety_limits(self) -> None:
        self._out_int(1, 1 if self.host.reachable(self._in_vector(0)) else 0)

    def _protective_stop(self) -> None:
        self.host.trigger_protective_stop()
        self._blocking = "protective"  # never completes: the program pauses

    def _set_watchdog(self) -> None:
        frequency = self._in_double(0)
        self.host.set_watchdog(f"input_int_register_{0 if self.offset not in (0, 24) else self.offset}", frequency)

    def _get_steptime(self) -> None:
        self.out.doubles[self.offset] = self.host.arm.control_period_s

    def _force_mode_set_damping(self) -> None:
        """``force_mode_set_damping(d0)``: clamped to [0, 1] as URScript does."""
        arm = self.host.arm
        arm.set_force_mode_parameters(min(max(self._in_double(0), 0.0), 1.0), arm.force_mode_gain_scaling)

    def _force_mode_set_gain_scaling(self) -> None:
        """``force_mode_set_gain_scaling(d0)``: clamped to [0, 2] as URScript does."""
        arm = self.host.arm
        arm.set_force_mode_parameters(arm.force_mode_damping, min(max(self._in_double(0), 0.0), 2.0))

    def _accepted(self) -> None:
        """Commands whose effect the twin does not model but which a real controller accepts (logged)."""
        logger.info("control script: command %d accepted without effect in the twin", self._in_int(0))

    def _stop_script(self) -> None:
        self.finished = True


_HANDLERS = {
    CMD_MOVEL: ControlScript._movel,
    CMD_FORCE_MODE: ControlScript._force_mode,
    CMD_FORCE_MODE_STOP: ControlScript._force_mode_stop,
    CMD_ZERO_FT: ControlScript._zero_ft,
    CMD_SPEEDL: ControlScript._speedl,
    CMD_SPEED_STOP: ControlScript._speed_stop,
    CMD_SET_PAYLOAD: ControlScript._set_payload,
    CMD_SET_TARGET_PAYLOAD: ControlScript._set_payload,
    CMD_FORCE_MODE_SET_DAMPING: ControlScript._force_mode_set_damping,
    CMD_FORCE_MODE_SET_GAIN_SCALING: ControlScript._force_mode_set_gain_scaling,
    CMD_SET_GRAVITY: ControlScript._accepted,
    CMD_GET_STEPTIME: ControlScript._get_steptime,
    CMD_SET_TCP: ControlScript._set_tcp,
    CMD_PROTECTIVE_STOP: ControlScript._protective_stop,
    CMD_STOPL: ControlScript._stopl,
    CMD_STOPJ: ControlScript._stopl,
    CMD_SET_WATCHDOG: ControlScript._set_watchdog,
    CMD_IS_POSE_WITHIN_SAFETY_LIMITS: ControlScript._is_pose_within_safety_limits,
    CMD_GET_TCP_OFFSET: ControlScript._get_tcp_offset,
    CMD_GET_FORWARD_KINEMATICS_DEFAULT: ControlScript._forward_kinematics_default,
    CMD_IS_STEADY: ControlScript._is_steady,
    CMD_GET_FLANGE_POSE: ControlScript._get_flange_pose,
    CMD_STOP_SCRIPT: ControlScript._stop_script,
}


def register_offset_from_script(text: str) -> int:
    """The register offset ur_rtde injected after ``# int register offset`` (0, or 24 with UPPER_RANGE)."""
    marker = "# int register offset"
    at = text.find(marker)
    if at < 0:
        return 0
    rest = text[at + len(marker) :].lstrip("\r\n")
    digits = ""
    for char in rest.lstrip():
        if not char.isdigit():
            break
        digits += char
    return int(digits) if digits else 0


def is_control_script(text: str) -> bool:
    """Whether an upload is ur_rtde's control script (its main-loop markers), not some other program."""
    return "def rtde_control():" in text and "NODE_CONTROL_LOOP_BEGINS" in text


def take_program(text: str) -> tuple[str | None, str]:
    """Split the first complete top-level program (``def``/``sec`` ... ``end`` at column 0) off ``text``."""
    lines = text.splitlines(keepends=True)
    start = None
    for index, line in enumerate(lines):
        if start is None:
            if line.startswith(("def ", "sec ")):
                start = index
            continue
        if line.rstrip("\r\n") == "end":
            return "".join(lines[start : index + 1]), "".join(lines[index + 1 :])
    if start is None and text.strip() and text.endswith("\n"):
        logger.warning("script port: ignored text outside a program: %r", text[:80])
        return None, ""
    return None, text
