"""The real UR5e over ur_rtde: :class:`UR5eArm` (implements :class:`drivers.arm.Arm`) and :class:`UR5eReceiver`.

State comes from ``rtde_receive.RTDEReceiveInterface`` (RTDE port 30004, 500 Hz on e-Series), commands go through
``rtde_control.RTDEControlInterface`` (which uploads a URScript program and needs the robot in Remote Control mode).
Both objects can be injected, so tests run the real receive client against
:class:`unitac_rig.sim.rtde_server.SimURController` and a small fake in place of the control interface.

Safety: ``close`` (and leaving a ``with`` block, whatever the reason) always tries forceModeStop, speedStop,
stopScript and disconnect, each on its own, so one failing step does not skip the others. A blocking command that
returns False becomes :class:`~drivers.errors.ProtectiveStop` when the receive side reports a protective or emergency
stop, else :class:`~drivers.errors.ArmError`. ur_rtde's own ``RuntimeError`` is wrapped at this boundary.

Gotchas: ur_rtde's Python constructors hold the GIL until the handshake finishes (a Python RTDE server in the same
process would deadlock, hence the simulator's server process); the C++ library prints to file descriptor 2 itself
(e.g. ``connect: Connection refused``), so the constructors run with fd 2 routed to the log.
"""

from __future__ import annotations

import contextlib
import logging
import os
import sys
import tempfile
from collections.abc import Callable, Iterator
from types import TracebackType
from typing import Any

import numpy as np

from drivers.arm import ArmState
from drivers.clock import Clock, MonotonicClock
from drivers.errors import ArmError, DeviceError, DeviceNotFound, DeviceTimeout, ProtectiveStop

logger = logging.getLogger(__name__)

# What the receive side subscribes to: an explicit list (the default list depends on the controller version).
RECEIVE_VARIABLES = (
    "timestamp",
    "actual_TCP_pose",
    "actual_TCP_force",
    "actual_TCP_speed",
    "robot_mode",
    "safety_mode",
    "safety_status_bits",
)
FORCE_MODE_TYPE = 2  # URScript force_mode type 2: the task frame is used as given
STALL_TIMEOUT_S = 0.5  # no new controller timestamp for this long = the RTDE stream stalled

_RECEIVE_HINT = (
    "check the cable/network (can you ping it?), that the robot is powered on, and that nothing blocks TCP port 30004"
)
_CONTROL_HINT = (
    "put the teach pendant in Remote Control mode, turn off EtherNet/IP, PROFINET and MODBUS (they hold the RTDE "
    "input registers), and check the network"
)
_STOPPED_HINT = "clear the stop on the teach pendant, move the arm clear, then run again"


@contextlib.contextmanager
def _native_stderr_to_log(what: str) -> Iterator[None]:
    """Route what ur_rtde's C++ code prints on file descriptor 2 to the log while it connects.

    Otherwise a failed connection leaves a stray "connect: Connection refused" line above the CLI's one-line error.
    Anything else written to fd 2 by other threads in that window lands in the log too.
    """
    sys.stderr.flush()
    saved_fd = os.dup(2)
    with tempfile.TemporaryFile() as capture:
        os.dup2(capture.fileno(), 2)
        try:
            yield
        finally:
            os.dup2(saved_fd, 2)
            os.close(saved_fd)
            capture.seek(0)
            text = capture.read().decode("utf-8", "replace").strip()
            if text:
                logger.info("ur_rtde (%s) printed: %s", what, text)


def _connect_receive(host: str, frequency_hz: float) -> Any:
    import rtde_receive

    try:
        with _native_stderr_to_log("receive"):
            return rtde_receive.RTDEReceiveInterface(host, frequency_hz, list(RECEIVE_VARIABLES))
    except RuntimeError as exc:
        raise DeviceNotFound(f"no UR controller answers RTDE at {host}: {exc}", hint=_RECEIVE_HINT) from exc


def _connect_control(host: str, frequency_hz: float) -> Any:
    import rtde_control

    try:
        with _native_stderr_to_log("control"):
            return rtde_control.RTDEControlInterface(host, frequency_hz)
    except RuntimeError as exc:
        raise DeviceNotFound(f"cannot take control of the UR at {host}: {exc}", hint=_CONTROL_HINT) from exc


class UR5eReceiver:
    """Read-only view of a UR controller over RTDE; never moves the arm (used by ``probe ur5e``).

    ``receive``: an object with RTDEReceiveInterface's methods (injected in tests); connected to ``host`` if None.
    Raises DeviceNotFound when nothing answers at ``host``.
    """

    def __init__(
        self,
        host: str,
        *,
        frequency_hz: float = 500.0,
        receive: Any | None = None,
        clock: Clock | None = None,
    ) -> None:
        self.host = host
        self.clock: Clock = clock or MonotonicClock()
        self._receive = receive if receive is not None else _connect_receive(host, frequency_hz)
        self._closed = False
        self._last_controller_t_s: float | None = None
        self._last_change_ns = self.clock.now_ns()

    def read_state(self) -> ArmState:
        """The latest state the RTDE client holds, stamped with the host clock (ns).

        Raises DeviceTimeout if the connection dropped or the controller timestamp has not moved for
        ``STALL_TIMEOUT_S``, DeviceError if the client fails.
        """
        if self._closed:
            raise DeviceError(f"the RTDE connection to {self.host} is closed")
        receive = self._receive
        try:
            if not receive.isConnected():
                raise DeviceTimeout(f"lost the RTDE connection to {self.host}", hint=_RECEIVE_HINT)
            controller_t_s = float(receive.getTimestamp())
            pose = np.asarray(receive.getActualTCPPose(), dtype=np.float64)
            force = np.asarray(receive.getActualTCPForce(), dtype=np.float64)
            speed = np.asarray(receive.getActualTCPSpeed(), dtype=np.float64)
            robot_mode = int(receive.getRobotMode())
            safety_mode = int(receive.getSafetyMode())
            protective = bool(receive.isProtectiveStopped())
            emergency = bool(receive.isEmergencyStopped())
        except RuntimeError as exc:
            raise DeviceError(f"reading the UR state from {self.host} failed: {exc}", hint=_RECEIVE_HINT) from exc
        now_ns = self.clock.now_ns()
        if controller_t_s != self._last_controller_t_s:
            self._last_controller_t_s = controller_t_s
            self._last_change_ns = now_ns
        elif now_ns - self._last_change_ns > STALL_TIMEOUT_S * 1e9:
            raise DeviceTimeout(
                f"the UR at {self.host} sent no new state for {(now_ns - self._last_change_ns) / 1e9:.2f} s",
                hint=_RECEIVE_HINT,
            )
        return ArmState(
            host_t_ns=now_ns,
            controller_t_s=controller_t_s,
            tcp_pose=pose,
            tcp_force=force,
            robot_mode=robot_mode,
            safety_mode=safety_mode,
            protective_stop=protective,
            emergency_stop=emergency,
            tcp_speed=speed,
        )

    def wait_for_new_state(self, timeout_s: float = 1.0, poll_s: float = 0.0005) -> ArmState:
        """Block until the controller timestamp moves on, then return that state; DeviceTimeout after ``timeout_s``."""
        previous = self._last_controller_t_s
        deadline_ns = self.clock.now_ns() + round(timeout_s * 1e9)
        while True:
            state = self.read_state()
            if state.controller_t_s != previous:
                return state
            if self.clock.now_ns() > deadline_ns:
                raise DeviceTimeout(f"no new state from the UR at {self.host} within {timeout_s} s", hint=_RECEIVE_HINT)
            self.clock.sleep(poll_s)

    def close(self) -> None:
        """Disconnect. Safe to call more than once."""
        if self._closed:
            return
        self._closed = True
        try:
            self._receive.disconnect()
        except RuntimeError as exc:
            logger.warning("RTDE receive disconnect from %s failed: %s", self.host, exc)

    def __enter__(self) -> UR5eReceiver:
        return self

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.close()


class UR5eArm:
    """A UR5e (any e-Series arm) over ur_rtde, implementing :class:`drivers.arm.Arm`.

    ``control`` / ``receive``: objects with RTDEControlInterface / RTDEReceiveInterface's methods (injected in
    tests); connected to ``host`` if None. ``control_period_s`` = 1 / ``frequency_hz`` (2 ms at 500 Hz).
    Raises DeviceNotFound with what to check when either interface cannot connect.
    """

    def __init__(
        self,
        host: str,
        *,
        frequency_hz: float = 500.0,
        control: Any | None = None,
        receive: Any | None = None,
        clock: Clock | None = None,
    ) -> None:
        if frequency_hz <= 0:
            raise ArmError(f"RTDE frequency must be > 0 Hz, got {frequency_hz}")
        self.host = host
        self.control_period_s = 1.0 / frequency_hz
        self._receiver = UR5eReceiver(host, frequency_hz=frequency_hz, receive=receive, clock=clock)
        self.clock: Clock = self._receiver.clock
        try:
            self._control = control if control is not None else _connect_control(host, frequency_hz)
        except BaseException:
            self._receiver.close()
            raise
        self._closed = False
        self._in_force_mode = False
        self._period_start: Any = None

    # ---- state ----------------------------------------------------------------------------------------------

    def read_state(self) -> ArmState:
        return self._receiver.read_state()

    # ---- commands -------------------------------------------------------------------------------------------

    def move_linear(self, pose: np.ndarray, speed_m_s: float, accel_m_s2: float) -> None:
        """Blocking moveL; raises ProtectiveStop if the controller stops the move, ArmError if it refuses it."""
        target = _as_list(pose, 6, "pose")
        self._require_ready("moveL")
        ok = self._call("moveL", self._control.moveL, target, float(speed_m_s), float(accel_m_s2), False)
        self._expect_ok("moveL", ok)

    def speed_linear(self, twist: np.ndarray, accel_m_s2: float) -> None:
        """speedL with no time limit: the velocity holds until the next command or a stop."""
        xd = _as_list(twist, 6, "twist")
        self._require_ready("speedL")
        ok = self._call("speedL", self._control.speedL, xd, float(accel_m_s2), 0.0)
        self._expect_ok("speedL", ok)

    def stop(self, decel_m_s2: float = 10.0) -> None:
        """Leave force mode if in it, then speedStop at ``decel_m_s2``; a stopped controller counts as stopped.

        A no-op after ``close`` (which already stopped the arm).
        """
        if self._closed:
            return
        if self._in_force_mode:
            self.force_mode_stop()
        ok = self._call("speedStop", self._control.speedStop, float(decel_m_s2))
        if ok is False and not self._stopped_by_safety():
            raise ArmError(f"the UR at {self.host} refused speedStop", hint=_STOPPED_HINT)

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
        ok = self._call("forceMode", self._control.forceMode, frame, chosen, target, FORCE_MODE_TYPE, speed_limits)
        self._in_force_mode = True
        self._expect_ok("forceMode", ok)

    def force_mode_stop(self) -> None:
        self._check_open()
        ok = self._call("forceModeStop", self._control.forceModeStop)
        self._in_force_mode = False
        if ok is False and not self._stopped_by_safety():
            raise ArmError(f"the UR at {self.host} refused forceModeStop", hint=_STOPPED_HINT)

    def wait_period(self) -> None:
        """Pace the loop at the RTDE frequency with ur_rtde's initPeriod/waitPeriod."""
        self._check_open()
        if self._period_start is None:
            self._period_start = self._control.initPeriod()
        self._control.waitPeriod(self._period_start)
        self._period_start = self._control.initPeriod()

    def close(self) -> None:
        """Stop force mode and motion, stop the control script, disconnect both interfaces. Idempotent."""
        if self._closed:
            return
        self._closed = True
        steps: list[tuple[str, Callable[[], object]]] = []
        if self._in_force_mode:
            steps.append(("forceModeStop", self._control.forceModeStop))
        steps += [
            ("speedStop", lambda: self._control.speedStop(10.0)),
            ("stopScript", self._control.stopScript),
            ("disconnect", self._control.disconnect),
        ]
        for name, step in steps:
            try:
                step()
            except Exception as exc:  # keep going: the remaining steps still matter
                logger.warning("UR close: %s failed: %s", name, exc)
        self._in_force_mode = False
        self._receiver.close()

    def __enter__(self) -> UR5eArm:
        return self

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.close()

    # ---- internals ------------------------------------------------------------------------------------------

    def _check_open(self) -> None:
        if self._closed:
            raise ArmError(f"the connection to the UR at {self.host} is closed")

    def _stopped_by_safety(self) -> bool:
        try:
            state = self._receiver.read_state()
        except DeviceError:
            return False
        return state.protective_stop or state.emergency_stop

    def _require_ready(self, what: str) -> None:
        """Refuse a motion command up front while the controller is in a protective or emergency stop."""
        self._check_open()
        state = self._receiver.read_state()
        if state.protective_stop or state.emergency_stop:
            kind = "an emergency" if state.emergency_stop else "a protective"
            raise ProtectiveStop(f"{what}: the UR at {self.host} is in {kind} stop", hint=_STOPPED_HINT)

    def _call(self, what: str, method: Callable[..., Any], *args: Any) -> Any:
        try:
            return method(*args)
        except RuntimeError as exc:
            raise ArmError(f"{what} on the UR at {self.host} failed: {exc}", hint=_CONTROL_HINT) from exc

    def _expect_ok(self, what: str, ok: object) -> None:
        if ok is False:
            if self._stopped_by_safety():
                raise ProtectiveStop(f"{what}: the UR at {self.host} stopped (protective/emergency stop)",
                                     hint=_STOPPED_HINT)  # fmt: skip
            raise ArmError(
                f"{what} was not completed by the UR at {self.host}",
                hint="look at the teach pendant's log; the rtde_control script may have stopped",
            )


def _as_list(values: np.ndarray, size: int, what: str) -> list[float]:
    vector = np.asarray(values, dtype=np.float64).reshape(-1)
    if vector.shape != (size,) or not np.all(np.isfinite(vector)):
        raise ArmError(f"{what} must be {size} finite numbers, got {values!r}")
    return [float(v) for v in vector]
