"""The read side of a UR controller over ur_rtde: :class:`UR5eReceiver` (RTDE receive, port 30004), and the connect
helpers both sides share (ur_rtde's C++ output routed to the log, its errors wrapped at this boundary).

:class:`drivers.ur5e.UR5eArm` reads its state through a receiver; ``probe ur5e`` uses one alone, read-only. A stalled
stream (no new controller timestamp for ``STALL_TIMEOUT_S`` of reads) is :class:`~drivers.errors.RobotStateLost`.
"""

from __future__ import annotations

import contextlib
import logging
import os
import sys
import tempfile
from collections.abc import Iterator, Sequence
from types import TracebackType
from typing import Any

import numpy as np

from drivers.arm import ArmState
from drivers.clock import Clock, MonotonicClock
from drivers.errors import DeviceError, DeviceNotFound, RobotStateLost

logger = logging.getLogger(__name__)

# What the receive side subscribes to: an explicit list (the default list depends on the controller version).
RECEIVE_VARIABLES = (
    "timestamp",
    "actual_TCP_pose",
    "actual_TCP_force",
    "robot_mode",
    "safety_mode",
    "safety_status_bits",
)
# Subscribed too where the controller offers them; one answered NOT_FOUND fails the whole recipe, so the receiver
# then connects with RECEIVE_VARIABLES alone.
SPEED_VARIABLE = "actual_TCP_speed"  # m/s, rad/s; without it the moves tell rest from the pose's change
PAYLOAD_VARIABLE = "payload"  # kg; subscribed only when the rig file gives a payload to check
STALL_TIMEOUT_S = 0.5  # no new controller timestamp for this long = the RTDE stream stalled
# A gap this long between two reads means the host was not reading (frozen, descheduled, SIGSTOP): the stall count
# starts again at the first read after it, so the receive thread that was frozen with the host can catch up.
HOST_GAP_S = 0.1

RECEIVE_HINT = (
    "check the cable/network (can you ping it?), that the robot is powered on, and that nothing blocks TCP port 30004"
)


@contextlib.contextmanager
def native_stderr_to_log(what: str) -> Iterator[None]:
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


def _connect_receive(host: str, frequency_hz: float, variables: Sequence[str]) -> Any:
    import rtde_receive

    try:
        with native_stderr_to_log("receive"):
            return rtde_receive.RTDEReceiveInterface(host, frequency_hz, list(variables))
    except (RuntimeError, ValueError) as exc:
        raise DeviceNotFound(f"no UR controller answers RTDE at {host}: {exc}", hint=RECEIVE_HINT) from exc


class UR5eReceiver:
    """Read-only view of a UR controller over RTDE; never moves the arm (used by ``probe ur5e``).

    ``receive``: an object with RTDEReceiveInterface's methods (injected in tests); connected to ``host`` if None.
    ``read_payload``: also subscribe to the payload (kg). The TCP speed is subscribed too; if the controller does not
    offer one of these (ur_rtde then refuses the whole recipe), the receiver connects with :data:`RECEIVE_VARIABLES`
    alone, ``tcp_speed`` reads None and :meth:`payload_kg` returns None. Raises DeviceNotFound when nothing answers
    at ``host``.
    """

    def __init__(
        self,
        host: str,
        *,
        frequency_hz: float = 500.0,
        receive: Any | None = None,
        clock: Clock | None = None,
        read_payload: bool = False,
    ) -> None:
        self.host = host
        self.clock: Clock = clock or MonotonicClock()
        self._has_payload = read_payload
        self._has_speed = True
        if receive is not None:
            self._receive = receive
        else:
            optional = (SPEED_VARIABLE, PAYLOAD_VARIABLE) if read_payload else (SPEED_VARIABLE,)
            try:
                self._receive = _connect_receive(host, frequency_hz, (*RECEIVE_VARIABLES, *optional))
            except DeviceNotFound as exc:  # e.g. an older controller has no "payload" output; connect without them
                logger.info("RTDE refused %s (%s); retrying without them", ", ".join(optional), exc)
                self._has_payload = self._has_speed = False
                self._receive = _connect_receive(host, frequency_hz, RECEIVE_VARIABLES)
        self._closed = False
        self._last_controller_t_s: float | None = None
        self._stale_since_ns: int | None = None  # host time of the first read that saw the timestamp unchanged
        self._last_read_ns: int | None = None

    def read_state(self) -> ArmState:
        """The latest state the RTDE client holds, stamped with the host clock (ns).

        Raises RobotStateLost (a DeviceTimeout) if the connection dropped or the controller timestamp has not moved
        for ``STALL_TIMEOUT_S``, DeviceError if the client fails.
        """
        if self._closed:
            raise DeviceError(f"the RTDE connection to {self.host} is closed")
        receive = self._receive
        try:
            if not receive.isConnected():
                raise RobotStateLost(f"lost the RTDE connection to {self.host}", hint=RECEIVE_HINT)
            controller_t_s = float(receive.getTimestamp())
            pose = np.asarray(receive.getActualTCPPose(), dtype=np.float64)
            force = np.asarray(receive.getActualTCPForce(), dtype=np.float64)
            speed = np.asarray(receive.getActualTCPSpeed(), dtype=np.float64) if self._has_speed else None
            robot_mode = int(receive.getRobotMode())
            safety_mode = int(receive.getSafetyMode())
            protective = bool(receive.isProtectiveStopped())
            emergency = bool(receive.isEmergencyStopped())
        except (RuntimeError, ValueError) as exc:
            raise DeviceError(f"reading the UR state from {self.host} failed: {exc}", hint=RECEIVE_HINT) from exc
        now_ns = self.clock.now_ns()
        # Stale = unchanged over STALL_TIMEOUT_S of *reads*, counted from the first read that saw it unchanged
        # after the host last read without a gap: a host that was itself frozen (SIGSTOP, a long GC) sees an old
        # timestamp after waking, and that says nothing about the controller (it would call a live controller lost,
        # send it no stop, and blame the cable for what the watchdog did).
        host_gap = self._last_read_ns is not None and now_ns - self._last_read_ns > HOST_GAP_S * 1e9
        self._last_read_ns = now_ns
        if controller_t_s != self._last_controller_t_s:
            self._last_controller_t_s = controller_t_s
            self._stale_since_ns = None
        elif self._stale_since_ns is None or host_gap:
            self._stale_since_ns = now_ns
        elif now_ns - self._stale_since_ns > STALL_TIMEOUT_S * 1e9:
            raise RobotStateLost(
                f"the UR at {self.host} sent no new state for {(now_ns - self._stale_since_ns) / 1e9:.2f} s",
                hint=RECEIVE_HINT,
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

    def payload_kg(self) -> float | None:
        """The payload mass the controller uses (kg), or None when the controller does not report it."""
        if not self._has_payload:
            return None
        try:
            return float(self._receive.getPayload())
        except (RuntimeError, ValueError) as exc:
            logger.info("the UR at %s does not report its payload: %s", self.host, exc)
            return None

    def wait_for_new_state(self, timeout_s: float = 1.0, poll_s: float = 0.0005) -> ArmState:
        """Block until the controller timestamp moves on, then return that state; RobotStateLost after ``timeout_s``."""
        previous = self._last_controller_t_s
        deadline_ns = self.clock.now_ns() + round(timeout_s * 1e9)
        while True:
            state = self.read_state()
            if state.controller_t_s != previous:
                return state
            if self.clock.now_ns() > deadline_ns:
                raise RobotStateLost(f"no new state from the UR at {self.host} within {timeout_s} s", hint=RECEIVE_HINT)
            self.clock.sleep(poll_s)

    def close(self) -> None:
        """Disconnect. Safe to call more than once."""
        if self._closed:
            return
        self._closed = True
        try:
            self._receive.disconnect()
        except (RuntimeError, ValueError) as exc:
            logger.warning("RTDE receive disconnect from %s failed: %s", self.host, exc)
        finally:
            self._receive = None  # its destructor blocks: let it run now, not during a later connection

    def __enter__(self) -> UR5eReceiver:
        return self

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.close()
