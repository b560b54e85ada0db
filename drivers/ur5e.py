"""The real UR5e over ur_rtde: :class:`UR5eArm` (implements :class:`drivers.arm.Arm`); its read side,
:class:`~drivers.ur5e_receive.UR5eReceiver`, is in ``drivers/ur5e_receive.py``.

State comes from ``rtde_receive.RTDEReceiveInterface`` (RTDE port 30004, 500 Hz on e-Series), commands go through
``rtde_control.RTDEControlInterface`` (which uploads a URScript program and needs the robot in Remote Control mode).
Both objects can be injected (tests use the real clients against the controller twin, and a recording fake where
the twin cannot reach).

Safety (``hardware-facts`` 3.8; the reasons and measurements are in docs/real-rig.md, "Safety"): the controller
executes the last command until told otherwise, even after the host dies, so

* the **RTDE watchdog** (``setWatchdog``) is held at ``watchdog_hz`` only while a motion is commanded (a speedL,
  force mode or asynchronous moveL not yet seen to end or stopped), armed again as each motion starts (ur_rtde's
  reconnect uploads a script without one), and fed only by the loop that decides the motion (``wait_period``, or
  the motion command itself): a host that freezes or dies mid-motion stops the arm 1 / ``watchdog_hz`` after its
  last decision. At connect and as the arm comes to rest it is set to ``REST_WATCHDOG_HZ`` (a watchdog can only be
  replaced, not removed), so set-up and saving can take seconds; :meth:`UR5eArm.keep_alive` kicks from a thread
  for the operator's waits;
* a period that sent speedL or forceMode is **not** also kicked: ``kickWatchdog`` writes 0 to the same command
  register, and landing in the same 2 ms script cycle it would erase the command unread;
* ``speedL`` carries a time limit of a few control periods (it bounds each call; the watchdog stops the arm);
  moveL is asynchronous and polled, so ``stop`` (``stopL``) can end it and the watchdog stays fed;
* ``stop`` and ``close`` run every step (forceModeStop, stopL, speedStop; then stopScript and disconnect) however
  the others fare, holding a second Ctrl-C until done; with the receive stream lost (no new state for
  ``STALL_TIMEOUT_S``) they send none (each would block ~301 s; the watchdog stops the program);
* in a protective or emergency stop commands are refused up front with :class:`~drivers.errors.ProtectiveStop`
  (what to do on the pendant in the hint); a stopped program gives :class:`~drivers.errors.ControlScriptStopped`;
* at connect the TCP offset and payload are read back and compared with the rig file's, when it names them.

ur_rtde's ``RuntimeError`` and ``ValueError`` are wrapped at this boundary. Its Python constructors hold the GIL
until the handshake finishes (hence the twins' server processes), and its C++ code prints to file descriptor 2,
so the constructors run with fd 2 routed to the log.
"""

from __future__ import annotations

import contextlib
import logging
import math
import threading
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from types import TracebackType
from typing import Any, NoReturn

import numpy as np

from drivers.arm import DEFAULT_WATCHDOG_HZ, ArmState, checked_force_mode_parameters
from drivers.clock import Clock
from drivers.errors import (
    ArmError,
    ControlScriptStopped,
    DeviceError,
    DeviceNotFound,
    ProtectiveStop,
    RobotStateLost,
)
from drivers.rotations import angle_between
from drivers.ur5e_receive import UR5eReceiver, native_stderr_to_log

logger = logging.getLogger(__name__)

FORCE_MODE_TYPE = 2  # URScript force_mode type 2: the task frame is used as given
SPEED_TIME_LIMIT_PERIODS = 4  # speedL's t: a few control periods (see the module docstring for what it does not do)
KEEP_ALIVE_KICK_S = 0.02  # keep_alive's kicker thread writes at 50 Hz, far above any sensible watchdog frequency
# The watchdog's frequency while no motion is commanded (Hz): 10 s. At rest it guards nothing that moves; it only
# ends a program whose host went away. Long enough that no set-up or save step on a loaded PC reaches it.
REST_WATCHDOG_HZ = 0.1
MAX_TOOL_SPEED_M_S = 3.0  # ur_rtde refuses faster tool speeds (hardware-facts 3.4)
MAX_TOOL_ACCEL_M_S2 = 150.0  # ... and larger tool accelerations
TCP_TOLERANCE_M = 0.001  # read-back TCP offset must match the rig file within 1 mm ...
TCP_TOLERANCE_RAD = 0.01  # ... and 0.01 rad
PAYLOAD_TOLERANCE_KG = 0.05  # read-back payload must match within 50 g
SAFETY_CATCH_UP_STATES = 5  # a stopped program: read up to this many new states (~10 ms) for the safety bits

_CONTROL_HINT = (
    "put the teach pendant in Remote Control mode, turn off EtherNet/IP, PROFINET and MODBUS (they hold the RTDE "
    "input registers), and check the network"
)
STOPPED_HINT = (
    "on the teach pendant: unlock the protective stop (if the pad is still pressing on something, move the arm clear "
    "in freedrive first), then run the same command again to resume"
)


def _program_stopped_hint(watchdog_hz: float | None) -> str:
    why = (
        f"the RTDE watchdog stops it when this computer sends nothing for {1000.0 / watchdog_hz:.0f} ms, e.g. an "
        "overloaded or stalled host"
        if watchdog_hz
        else "it may have been stopped on the teach pendant"
    )
    return f"{why}; check the pendant's log, then run the same command again to resume"


def _connect_control(host: str, frequency_hz: float) -> Any:
    import rtde_control

    try:
        with native_stderr_to_log("control"):
            return rtde_control.RTDEControlInterface(host, frequency_hz)
    except (RuntimeError, ValueError) as exc:
        raise DeviceNotFound(f"cannot take control of the UR at {host}: {exc}", hint=_CONTROL_HINT) from exc


@dataclass
class _AsyncMove:
    """An asynchronous moveL in flight: the async operation id before it started (bits 24-30 of the progress word,
    incremented by the script at every start; None where the client's status object has no ``operationId``), and
    whether this move has been seen running (what ends it when there is no id to tell moves apart)."""

    operation_before: int | None
    seen_running: bool = False


class UR5eArm:
    """A UR5e (any e-Series arm) over ur_rtde, implementing :class:`drivers.arm.Arm` (see the module docstring).

    ``control`` / ``receive``: objects with RTDEControlInterface / RTDEReceiveInterface's methods (injected in
    tests); connected to ``host`` if None. ``control_period_s`` = 1 / ``frequency_hz`` (2 ms at 500 Hz).
    ``watchdog_hz``: the RTDE watchdog while a motion is commanded (None: none, for read-mostly tools only).
    ``expected_tcp_offset`` ((6,) m, rad, from the flange) and ``expected_payload_kg``: what the rig file says is set
    on the pendant; the connection is refused with ArmError when the controller reports something else.
    Raises DeviceNotFound with what to check when either interface cannot connect, ProtectiveStop when the arm is in
    a protective or emergency stop.
    """

    def __init__(
        self,
        host: str,
        *,
        frequency_hz: float = 500.0,
        control: Any | None = None,
        receive: Any | None = None,
        clock: Clock | None = None,
        watchdog_hz: float | None = DEFAULT_WATCHDOG_HZ,
        expected_tcp_offset: Sequence[float] | None = None,
        expected_payload_kg: float | None = None,
    ) -> None:
        if frequency_hz <= 0:
            raise ArmError(f"RTDE frequency must be > 0 Hz, got {frequency_hz}")
        if watchdog_hz is not None and not 0 < watchdog_hz <= frequency_hz:
            raise ArmError(f"watchdog frequency must be within (0, {frequency_hz}] Hz, got {watchdog_hz}")
        self.host = host
        self.control_period_s = 1.0 / frequency_hz
        self._watchdog_hz = watchdog_hz
        self._watchdog_set_hz: float | None = None  # the frequency last set on the controller
        self._closed = False
        self._in_force_mode = False
        self._speeding = False
        self._command_this_period = False  # speedL/forceMode wrote the command register since the last wait_period
        self._move: _AsyncMove | None = None
        self._period_start: Any = None
        self._kicker: tuple[threading.Thread, threading.Event] | None = None
        self._force_mode_parameters: tuple[float, float] | None = None  # (damping, gain scaling), set on entry
        self.tcp_offset: np.ndarray | None = None  # as read back at connect
        self.payload_kg: float | None = None
        self._receiver = UR5eReceiver(
            host, frequency_hz=frequency_hz, receive=receive, clock=clock, read_payload=expected_payload_kg is not None
        )
        self.clock: Clock = self._receiver.clock
        try:
            self._refuse_safety_stop(self._receiver.read_state(), "connect")
            self._control = control if control is not None else _connect_control(host, frequency_hz)
        except BaseException:
            self._receiver.close()
            raise
        try:
            self._check_setup(expected_tcp_offset, expected_payload_kg)
            self._rest_watchdog(always=True)
        except BaseException:
            self.close()
            raise

    # ---- state ----------------------------------------------------------------------------------------------

    def read_state(self) -> ArmState:
        """The receive side's latest state, with ``program_running`` from the control side.

        A receive stream that went stale while the control side says the program stopped is a stopped program
        (ControlScriptStopped, what to do in its hint), not a lost controller: after a host freeze longer than the
        watchdog period the receive stream may take a while to show new states, and calling that "lost" sent the
        operator to the network cable instead of telling them the same command resumes."""
        try:
            state = self._receiver.read_state()
        except RobotStateLost:
            if not self._closed and self._program_stopped():
                self._raise_stopped("reading the state", "is not running")
            raise
        if self._closed:
            return state
        running = bool(self._call("isProgramRunning", self._control.isProgramRunning))
        return state if running else state._replace(program_running=False)

    # ---- commands -------------------------------------------------------------------------------------------

    def start_move_linear(self, pose: np.ndarray, speed_m_s: float, accel_m_s2: float) -> None:
        """moveL with ``asynchronous=True``: returns once the controller started the move; poll ``move_running``."""
        target = _as_list(pose, 6, "pose")
        _check_motion(speed_m_s, accel_m_s2)
        self._require_ready("moveL")
        self._rearm_watchdog()
        before, _ = self._async_status()
        ok = self._call("moveL", self._control.moveL, target, float(speed_m_s), float(accel_m_s2), True)
        self._expect_ok("moveL", ok)
        self._move = _AsyncMove(before)

    def move_running(self) -> bool:
        """True while the asynchronous move runs, from ur_rtde's async progress word
        (``getAsyncOperationProgressEx``): the move is this one once the operation id differs from the one before
        it started, and over once that operation no longer runs. A finish signalled by an *earlier* move (its
        thread ending just as this one starts) has the old id and cannot end this one.

        A status object without ``operationId`` (hardware-facts names only ``isAsyncOperationRunning`` and
        ``progress``) is read by the running flag alone: the move is over once it has been seen running and then
        not. Until the controller shows the move as started it counts as running: callers bound the wait.
        """
        move = self._move
        if move is None:
            return False
        operation, running = self._async_status()
        if operation is None:
            move.seen_running = move.seen_running or running
            if running or not move.seen_running:
                return True
        elif operation == move.operation_before or running:
            return True
        self._move = None
        self._rest_watchdog()
        return False

    def speed_linear(self, twist: np.ndarray, accel_m_s2: float) -> None:
        """speedL with a time limit of ``SPEED_TIME_LIMIT_PERIODS`` control periods; send it every period."""
        xd = _as_list(twist, 6, "twist")
        _check_motion(float(np.linalg.norm(xd[:3])), accel_m_s2, allow_zero_speed=True)
        self._require_ready("speedL")
        if not self._speeding:
            self._rearm_watchdog()
        time_s = SPEED_TIME_LIMIT_PERIODS * self.control_period_s
        ok = self._call("speedL", self._control.speedL, xd, float(accel_m_s2), time_s)
        self._speeding = self._command_this_period = True
        self._expect_ok("speedL", ok)

    def stop(self, decel_m_s2: float = 10.0) -> None:
        """Stop whatever runs (:meth:`_stop_steps`, every step run); a controller that stopped on its own (protective
        stop, program not running) counts as stopped. A no-op after ``close``."""
        if self._closed:
            return
        if not decel_m_s2 > 0:
            raise ArmError(f"deceleration must be > 0 m/s^2, got {decel_m_s2}")
        self._end_keep_alive()  # stopping always wins; the kicker must not share the client with us
        if self._controller_lost():
            self._forget_motion()
            if self._program_stopped():
                return  # the controller stopped the program (and the arm) itself: nothing to stop, nothing to wait for
            raise RobotStateLost(
                f"the RTDE stream from the UR at {self.host} is lost: no stop command was sent (each would wait "
                "ur_rtde's 300 s for an answer)",
                hint=self._lost_hint(),
            )
        steps = self._stop_steps(self._control, float(min(decel_m_s2, MAX_TOOL_ACCEL_M_S2)))
        try:
            refused = _run_all(steps, on_error=lambda name, exc: logger.warning("UR stop: %s failed: %s", name, exc))
        finally:
            self._forget_motion()
        if refused:
            if not self._stopped_anyway():
                raise ArmError(f"the UR at {self.host} refused {', '.join(refused)}", hint=STOPPED_HINT)
            return  # stopped by the controller: its program is not running, nothing to relax
        self._rest_watchdog()

    def zero_ft(self) -> None:
        self._require_ready("zeroFtSensor")
        self._expect_ok("zeroFtSensor", self._call("zeroFtSensor", self._control.zeroFtSensor))

    def force_mode(
        self,
        task_frame: np.ndarray,
        selection: np.ndarray,
        wrench: np.ndarray,
        limits: np.ndarray,
    ) -> None:
        """forceMode type 2 (task frame as given); call once per control period."""
        frame = _as_list(task_frame, 6, "task_frame")
        chosen = [int(v != 0) for v in _as_list(selection, 6, "selection")]
        target = _as_list(wrench, 6, "wrench")
        speed_limits = _as_list(limits, 6, "limits")
        self._require_ready("forceMode")
        if not self._in_force_mode:
            self._rearm_watchdog()
            self._apply_force_mode_parameters()
        ok = self._call("forceMode", self._control.forceMode, frame, chosen, target, FORCE_MODE_TYPE, speed_limits)
        self._in_force_mode = self._command_this_period = True
        self._expect_ok("forceMode", ok)

    def set_force_mode_parameters(self, damping: float, gain_scaling: float) -> None:
        """Damping (0..1) and gain scaling (0..2), sent before each entry into force mode (ur_rtde: "call before
        entering force mode"; a script uploaded again after a reconnect starts from its defaults)."""
        self._force_mode_parameters = checked_force_mode_parameters(damping, gain_scaling)

    def _apply_force_mode_parameters(self) -> None:
        if self._force_mode_parameters is None:
            return
        damping, scaling = self._force_mode_parameters
        control = self._control
        self._expect_ok("forceModeSetDamping", self._call("forceModeSetDamping", control.forceModeSetDamping, damping))
        ok = self._call("forceModeSetGainScaling", control.forceModeSetGainScaling, scaling)
        self._expect_ok("forceModeSetGainScaling", ok)

    def force_mode_stop(self) -> None:
        self._check_open()
        ok = self._call("forceModeStop", self._control.forceModeStop)
        self._in_force_mode = False
        if ok is False:
            if not self._stopped_anyway():
                raise ArmError(f"the UR at {self.host} refused forceModeStop", hint=STOPPED_HINT)
            return
        self._rest_watchdog()

    def wait_period(self) -> None:
        """Feed the watchdog, then pace the loop at the RTDE frequency with ur_rtde's initPeriod/waitPeriod. No kick
        after a speedL or forceMode this period: the command fed the watchdog, and a kick would erase it unread."""
        self._check_open()
        self._refuse_while_kept_alive("wait_period")
        if self._watchdog_hz is not None and not self._command_this_period:
            self._call("kickWatchdog", self._control.kickWatchdog)
        self._command_this_period = False
        if self._period_start is None:
            self._period_start = self._control.initPeriod()
        self._control.waitPeriod(self._period_start)
        self._period_start = self._control.initPeriod()

    @contextlib.contextmanager
    def keep_alive(self) -> Iterator[None]:
        """Kick the watchdog from a thread at 50 Hz while the host does non-motion work with the arm at rest.

        A motion still commanded is stopped first, and the watchdog is at its rest window inside (a kick starved of
        the GIL by this process's own work cannot trip it). Inside, this object refuses every command (ur_rtde's
        client must not be used from two threads). If the process dies, the thread dies with it and the watchdog
        stops the program as usual.
        """
        self._check_open()
        if self._in_force_mode or self._speeding or self._move is not None:
            self.stop()  # which sets the rest window
        elif self._kicker is None:
            self._rest_watchdog()
        if self._watchdog_hz is None or self._kicker is not None:
            yield
            return
        done = threading.Event()
        thread = threading.Thread(target=self._kick_until, args=(done,), name="ur5e-watchdog-kick", daemon=True)
        self._kicker = (thread, done)
        thread.start()
        try:
            yield
        finally:
            self._end_keep_alive()

    def close(self) -> None:
        """Stop force mode and motion, stop the control script, disconnect both interfaces (every step run).
        Idempotent."""
        if self._closed:
            return
        self._closed = True
        control = getattr(self, "_control", None)
        steps: list[tuple[str, Callable[[], object]]] = [("keep_alive", self._end_keep_alive)]
        if control is not None and self._controller_lost():
            # nothing would answer: stop commands would each block ~300 s; the watchdog stops the program
            logger.warning(
                "UR close: the RTDE stream from %s is lost; sending no stop commands. %s",
                self.host,
                self._lost_hint(),
            )
            steps.append(("disconnect", control.disconnect))
        elif control is not None:
            steps += [*self._stop_steps(control, 10.0), ("stopScript", control.stopScript)]
            steps.append(("disconnect", control.disconnect))
        steps.append(("receive disconnect", self._receiver.close))
        try:
            _run_all(steps, on_error=lambda name, exc: logger.warning("UR close: %s failed: %s", name, exc))
        finally:
            self._forget_motion()
            # Let ur_rtde's objects go now: their destructors block (a 0.5 s sleep each) holding the GIL, and run
            # later, when garbage collection gets to them, they freeze whatever this process does then (a second
            # connection's watchdog tripped that way on the twin).
            self._control = None

    def __enter__(self) -> UR5eArm:
        return self

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.close()

    # ---- internals ------------------------------------------------------------------------------------------

    def _check_setup(self, expected_tcp: Sequence[float] | None, expected_payload_kg: float | None) -> None:
        """Read the TCP offset and payload back and refuse to go on if the rig file expects something else.

        ``getTCPOffset`` is a script command (40) that waits for the script's answer, so it is only sent when there
        is a TCP to check it against.
        """
        if expected_tcp is None:
            logger.warning(
                "arm.tcp_offset is not set in the rig file: the UR at %s runs with an unchecked TCP", self.host
            )
        else:
            actual = np.asarray(self._call("getTCPOffset", self._control.getTCPOffset), dtype=np.float64).reshape(-1)
            self.tcp_offset = actual
            expected = np.asarray(_as_list(np.asarray(expected_tcp), 6, "expected TCP offset"))
            off_m = float(np.linalg.norm(actual[:3] - expected[:3])) if actual.shape == (6,) else math.inf
            off_rad = angle_between(actual[3:], expected[3:]) if actual.shape == (6,) else math.inf
            if off_m > TCP_TOLERANCE_M or off_rad > TCP_TOLERANCE_RAD:
                raise ArmError(
                    f"the UR at {self.host} has TCP offset {_fmt(actual)} but the rig file's arm.tcp_offset is "
                    f"{_fmt(expected)} (m, rad)",
                    hint="set the TCP on the teach pendant (Installation > General > TCP) or correct arm.tcp_offset",
                )
        self.payload_kg = self._receiver.payload_kg() if expected_payload_kg is not None else None
        if expected_payload_kg is not None:
            if self.payload_kg is None:
                logger.warning("the UR at %s does not report its payload; check it on the pendant", self.host)
            elif abs(self.payload_kg - expected_payload_kg) > PAYLOAD_TOLERANCE_KG:
                raise ArmError(
                    f"the UR at {self.host} has a payload of {self.payload_kg:.3f} kg but the rig file's "
                    f"arm.payload_kg is {expected_payload_kg:.3f} kg",
                    hint="set the payload on the teach pendant (Installation > General > Payload) or correct "
                    "arm.payload_kg (a wrong payload shifts the wrist force and weakens the robot's collision check)",
                )

    def _kick_until(self, done: threading.Event) -> None:
        while not done.wait(KEEP_ALIVE_KICK_S):
            try:
                self._control.kickWatchdog()
            except Exception as exc:  # the connection went away: the watchdog will stop the program, as it should
                logger.warning("keep_alive: kickWatchdog failed (%s); stopping the kicker", exc)
                return

    def _end_keep_alive(self) -> None:
        kicker, self._kicker = self._kicker, None
        if kicker is not None:
            thread, done = kicker
            done.set()
            thread.join()

    def _check_open(self) -> None:
        if self._closed:
            raise ArmError(f"the connection to the UR at {self.host} is closed")

    def _refuse_while_kept_alive(self, what: str) -> None:
        if self._kicker is not None:
            raise ArmError(f"{what} inside keep_alive: the arm must stay at rest there")

    def _stop_steps(self, control: Any, decel_m_s2: float) -> list[tuple[str, Callable[[], object]]]:
        """What ends whatever runs: forceModeStop (in force mode), stopL (an asynchronous move), speedStop."""
        steps: list[tuple[str, Callable[[], object]]] = []
        if self._in_force_mode:
            steps.append(("forceModeStop", control.forceModeStop))
        if self._move is not None:
            steps.append(("stopL", lambda: control.stopL(decel_m_s2, False)))
        return [*steps, ("speedStop", lambda: control.speedStop(decel_m_s2))]

    def _forget_motion(self) -> None:
        self._in_force_mode = self._speeding = False
        self._move = None

    def _state_or_none(self) -> ArmState | None:
        try:
            return self._receiver.read_state()
        except DeviceError:
            return None

    def _refuse_safety_stop(self, state: ArmState | None, what: str) -> None:
        """ProtectiveStop (what to do on the pendant in its hint) when ``state`` shows a protective or emergency
        stop."""
        if state is not None and (state.protective_stop or state.emergency_stop):
            kind = "an emergency" if state.emergency_stop else "a protective"
            raise ProtectiveStop(f"{what}: the UR at {self.host} is in {kind} stop", hint=STOPPED_HINT)

    def _stopped_anyway(self) -> bool:
        """A refused stop is fine when the controller stopped on its own (safety stop, program not running)."""
        state = self._state_or_none()
        return state is not None and (state.protective_stop or state.emergency_stop or self._program_stopped())

    def _require_ready(self, what: str) -> None:
        """Refuse a motion command up front while the controller is stopped (safety stop, program not running)."""
        self._check_open()
        self._refuse_while_kept_alive(what)
        self._refuse_safety_stop(self._receiver.read_state(), what)
        if not self._call("isProgramRunning", self._control.isProgramRunning):
            self._raise_stopped(what, "is not running")

    def _raise_stopped(self, what: str, how: str) -> NoReturn:
        """The program is not running: say why. A protective or emergency stop stops the program too, and the
        control client may see the program stop a few periods before the receive stream shows the safety bits,
        so wait briefly for fresher state before calling it a plain program stop."""
        try:
            state = self._receiver.read_state()
            for _ in range(SAFETY_CATCH_UP_STATES):
                if state.protective_stop or state.emergency_stop:
                    break
                state = self._receiver.wait_for_new_state(timeout_s=0.05)
        except DeviceError:
            state = None
        self._refuse_safety_stop(state, what)
        raise ControlScriptStopped(
            f"{what}: the control program on the UR at {self.host} {how}",
            hint=_program_stopped_hint(self._watchdog_hz),
        )

    def _program_stopped(self) -> bool:
        """Whether the control side says the program is not running (False when it cannot tell)."""
        try:
            return not bool(self._control.isProgramRunning())
        except (RuntimeError, ValueError, AttributeError):
            return False

    def _rearm_watchdog(self) -> None:
        """Arm the watchdog at ``watchdog_hz`` as every motion starts (one ~5 ms round trip): the script ur_rtde
        uploads again after reconnecting by itself has none."""
        if self._watchdog_hz is not None:
            self._set_watchdog(self._watchdog_hz)

    def _rest_watchdog(self, *, always: bool = False) -> None:
        """Set the watchdog to the rest window once nothing is commanded (see the module docstring); a no-op while
        any motion is still commanded, and when it is at the rest window already (unless ``always``)."""
        if self._watchdog_hz is None or self._in_force_mode or self._speeding or self._move is not None:
            return
        if self._controller_lost():
            return  # setWatchdog would wait ur_rtde's 300 s for an answer; the armed watchdog stops the program
        rest_hz = min(REST_WATCHDOG_HZ, self._watchdog_hz)
        if always or self._watchdog_set_hz != rest_hz:
            try:
                self._set_watchdog(rest_hz)
            except (ControlScriptStopped, ProtectiveStop):
                # a stopped program has no watchdog left to relax and moves nothing: the caller's next state check
                # reports the stop in its own words (which stop, and that the same command resumes)
                if always:
                    raise

    def _set_watchdog(self, frequency_hz: float) -> None:
        self._watchdog_set_hz = None  # unknown until the controller confirmed it
        ok = self._call("setWatchdog", self._control.setWatchdog, float(frequency_hz))
        self._expect_ok("setWatchdog", ok)
        self._watchdog_set_hz = frequency_hz

    def _lost_hint(self) -> str:
        if self._watchdog_hz is None:
            return "no RTDE watchdog is armed: stop the arm on the teach pendant now, then check the network cable"
        return (
            f"the controller's RTDE watchdog ({self._watchdog_hz:g} Hz) stops the program once this host's writes "
            "stop; check the network cable and the teach pendant, and that the arm is at rest, before connecting again"
        )

    def _controller_lost(self) -> bool:
        """Whether the receive side says the controller is gone (connection dropped, or no new state for
        ``STALL_TIMEOUT_S``). Blocking commands to a vanished controller return False only after ~301 s."""
        try:
            self._receiver.read_state()
        except RobotStateLost:
            return True
        except DeviceError:
            return False
        return False

    def _async_status(self) -> tuple[int | None, bool]:
        """(operation id, running) from the async progress word (output_int_register_2); the id is None where the
        status object has no ``operationId`` (a control client written from the documented API only)."""
        status = self._call("getAsyncOperationProgressEx", self._control.getAsyncOperationProgressEx)
        running = bool(status.isAsyncOperationRunning())
        operation_id = getattr(status, "operationId", None)
        return (None if operation_id is None else int(operation_id())), running

    def _call(self, what: str, method: Callable[..., Any], *args: Any) -> Any:
        try:
            return method(*args)
        except ValueError as exc:  # ur_rtde checks arguments (tool speed, acceleration) and raises ValueError
            raise ArmError(f"{what}: the UR client refused the arguments {args!r}: {exc}") from exc
        except RuntimeError as exc:
            raise ArmError(f"{what} on the UR at {self.host} failed: {exc}", hint=_CONTROL_HINT) from exc

    def _expect_ok(self, what: str, ok: object) -> None:
        if ok is not False:
            return
        self._refuse_safety_stop(self._state_or_none(), what)
        if self._program_stopped():
            self._raise_stopped(what, "stopped")
        raise ArmError(
            f"{what} was not completed by the UR at {self.host}",
            hint="look at the teach pendant's log; the rtde_control script may have stopped",
        )


def _run_all(
    steps: Sequence[tuple[str, Callable[[], object]]], on_error: Callable[[str, Exception], None]
) -> list[str]:
    """Run every step whatever the earlier ones did; -> the names of steps that returned False.

    An exception is reported to ``on_error``; a KeyboardInterrupt (a second Ctrl-C) or SystemExit is held and
    re-raised after the last step, so an impatient operator cannot skip stopping the arm.
    """
    refused: list[str] = []
    held: BaseException | None = None
    for name, step in steps:
        try:
            if step() is False:
                refused.append(name)
        except Exception as exc:
            on_error(name, exc)
            refused.append(name)
        except BaseException as exc:  # Ctrl-C again, SIGTERM turned into an interrupt: finish stopping first
            logger.warning("interrupted during %s; finishing the stop sequence first", name)
            held = held or exc
    if held is not None:
        raise held
    return refused


def _check_motion(speed_m_s: float, accel_m_s2: float, *, allow_zero_speed: bool = False) -> None:
    """The limits ur_rtde checks, checked here first so they fail as ArmError naming the value."""
    low_ok = speed_m_s >= 0 if allow_zero_speed else speed_m_s > 0
    if not (low_ok and speed_m_s <= MAX_TOOL_SPEED_M_S):
        raise ArmError(f"tool speed {speed_m_s} m/s is outside the UR's range (0, {MAX_TOOL_SPEED_M_S}] m/s")
    if not 0 < accel_m_s2 <= MAX_TOOL_ACCEL_M_S2:
        raise ArmError(f"tool acceleration {accel_m_s2} m/s^2 is outside (0, {MAX_TOOL_ACCEL_M_S2}] m/s^2")


def _fmt(values: np.ndarray) -> str:
    return "[" + ", ".join(f"{v:.4f}" for v in np.asarray(values).ravel()) + "]"


def _as_list(values: np.ndarray, size: int, what: str) -> list[float]:
    vector = np.asarray(values, dtype=np.float64).reshape(-1)
    if vector.shape != (size,) or not np.all(np.isfinite(vector)):
        raise ArmError(f"{what} must be {size} finite numbers, got {values!r}")
    return [float(v) for v in vector]
