"""A simulated UR controller's RTDE server on a loopback address, so the REAL ur_rtde receive client can read it.

:class:`SimURController` listens on ``host:30004`` and speaks RTDE v2 (:mod:`protocols.rtde`): it answers the
protocol version (``V``), the controller version (``v``, 5.11.0 by default), output and input recipes (``O``/``I``),
start and pause (``S``/``P``), and once started streams data packages (``U``) in real time at the rate the client
asked for (at most ``frequency_hz``), filled from a ``state_provider`` (:class:`drivers.arm.ArmState`): TCP pose,
TCP force, TCP speed, robot mode, safety mode, ``safety_status_bits`` (bit 2 protective stop, bit 7 emergency
stop) and the controller timestamp. Variables the sim has no model for (joint values, currents, registers...) are
sent as zeros so a client may still subscribe to them; names it does not know get ``NOT_FOUND``.

The protocol runs in a child process (``python -m unitac_rig.sim.rtde_server``); a thread named ``sim-rtde`` in the
caller's process polls the state provider and hands each snapshot over through a small shared memory block (a
sequence lock, so a writer that stalls mid-update never blocks the server). Why not a thread:

Gotchas found by running ``rtde_receive.RTDEReceiveInterface`` (ur-rtde 1.6.5) against this server:

* **Its Python constructor holds the GIL** until the handshake is over and the first data package has arrived, so
  a server thread in the same interpreter never gets to answer: the constructor hangs. Hence the child process.
  (``multiprocessing`` with "spawn" re-imports the caller's ``__main__`` and breaks scripts without a
  ``__main__`` guard; "fork" is unsafe with threads running. A plain subprocess has neither problem.)
* The client has no port argument: it always dials 30004. Run several servers side by side on different loopback
  addresses (Linux routes all of 127.0.0.0/8 to ``lo``; macOS only has 127.0.0.1 unless aliased).
* Pass an explicit ``variables`` list. An empty list subscribes to ur_rtde's long default list (whose content
  depends on the controller version, per its source); this server answers that too, but an explicit list keeps the
  contract small.
* The client parses ``U`` packages with its own type table, not with the types named in the ``O`` reply; it only
  looks for ``NOT_FOUND``/``IN_USE`` there and fails the constructor if it finds one. So the server's type table
  must agree with ur_rtde's for every variable it serves.
* A getter for a variable that was not subscribed raises ``RuntimeError("unable to get state data for specified
  key: ...")``; ``isProtectiveStopped``/``isEmergencyStopped`` need ``safety_status_bits``.
* ``disconnect()`` takes about 0.5 s; on a failed connection the C++ library prints ``connect: Connection refused``
  to stderr itself before raising ``RuntimeError``.

Why one module: the RTDE session state machine, the variable type table that must agree with
ur_rtde's, and the child-process server with its seqlocked shared state are one contract with the real client.
"""

from __future__ import annotations

import argparse
import contextlib
import errno
import logging
import math
import mmap
import os
import select
import selectors
import socket
import struct
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from types import TracebackType
from typing import NamedTuple

import numpy as np

from drivers.arm import ArmState
from drivers.errors import DeviceError
from protocols import rtde
from protocols.rtde import ControllerVersion, PackageType, RecipeReply
from unitac_rig.sim.child import stop_child

logger = logging.getLogger(__name__)

ROBOT_MODE_RUNNING = 7  # RTDE robot_mode: 7 = RUNNING (powered, brakes released)
SAFETY_MODE_NORMAL = 1
SAFETY_MODE_PROTECTIVE_STOP = 3
ROBOT_STATUS_POWER_ON = 1 << 0  # robot_status_bits bit 0
RUNTIME_STATE_STOPPED = 1  # no program running (a receive-only client never starts one)

# A still arm in front of the prism (m, rad): used when no state provider is given.
DEFAULT_STILL_POSE = np.array([-0.15, 0.52, 0.25, 0.0, 2.2214, -2.2214])

_SEND_TIMEOUT_S = 1.0  # a client that stops reading for this long is dropped
_MAX_IDLE_WAIT_S = 0.05  # selector timeout when nothing is due
_START_TIMEOUT_S = 10.0  # a fresh interpreter that imports numpy; allow for a slow CI box


class Snapshot(NamedTuple):
    """What the server streams: one arm state in plain numbers (no numpy, it crosses a process boundary)."""

    controller_t_s: float
    tcp_pose: tuple[float, ...]  # m, rad
    tcp_force: tuple[float, ...]  # N, N*m
    tcp_speed: tuple[float, ...]  # m/s, rad/s
    robot_mode: int
    safety_mode: int
    protective_stop: bool
    emergency_stop: bool

    @classmethod
    def from_state(cls, state: ArmState) -> Snapshot:
        return cls(
            float(state.controller_t_s),
            _vector6(state.tcp_pose),
            _vector6(state.tcp_force),
            _vector6(state.tcp_speed),
            int(state.robot_mode),
            int(state.safety_mode),
            bool(state.protective_stop),
            bool(state.emergency_stop),
        )


def _vector6(values: np.ndarray | None) -> tuple[float, ...]:
    if values is None:
        return (0.0,) * 6
    return tuple(float(v) for v in np.asarray(values, dtype=np.float64).reshape(6))


def safety_status_bits(state: Snapshot) -> int:
    """The ``safety_status_bits`` word: bit 0 normal mode, bit 2 protective stop, bit 7 emergency stop."""
    bits = 0
    if state.protective_stop:
        bits |= rtde.SAFETY_BIT_PROTECTIVE_STOP
    if state.emergency_stop:
        bits |= rtde.SAFETY_BIT_EMERGENCY_STOP
    return bits or rtde.SAFETY_BIT_NORMAL_MODE


def _zero_value(field_type: str) -> rtde.FieldValue:
    if field_type == "VECTOR3D":
        return (0.0, 0.0, 0.0)
    if field_type == "VECTOR6D":
        return (0.0,) * 6
    if field_type in ("VECTOR6INT32", "VECTOR6UINT32"):
        return (0,) * 6
    if field_type == "DOUBLE":
        return 0.0
    if field_type == "BOOL":
        return False
    return 0


def snapshot_values(state: Snapshot) -> dict[str, rtde.FieldValue]:
    """The output variables a :class:`Snapshot` determines, by RTDE name (see :func:`values_for`)."""
    return {
        "timestamp": state.controller_t_s,
        "actual_TCP_pose": state.tcp_pose,
        "target_TCP_pose": state.tcp_pose,
        "actual_TCP_force": state.tcp_force,
        "ft_raw_wrench": state.tcp_force,
        "actual_TCP_speed": state.tcp_speed,
        "target_TCP_speed": state.tcp_speed,
        "robot_mode": state.robot_mode,
        "safety_mode": state.safety_mode,
        "safety_status": state.safety_mode,
        "safety_status_bits": safety_status_bits(state),
        "robot_status_bits": ROBOT_STATUS_POWER_ON,
        "runtime_state": RUNTIME_STATE_STOPPED,
        "speed_scaling": 1.0,
        "target_speed_fraction": 1.0,
    }


def values_for(
    names: Sequence[str], types: Sequence[str], known: Mapping[str, rtde.FieldValue]
) -> list[rtde.FieldValue]:
    """Values of an output recipe: from ``known`` by name, zeros for variables the simulation does not model."""
    return [known[name] if name in known else _zero_value(t) for name, t in zip(names, types, strict=True)]


def state_values(state: Snapshot, names: Sequence[str], types: Sequence[str]) -> list[rtde.FieldValue]:
    """Values of an output recipe for one state (zeros for variables the simulation does not model)."""
    return values_for(names, types, snapshot_values(state))


# ---- the shared block between the caller (writer) and the server process (reader) -----------------------------

# uint64 sequence (odd while a write is in progress), then the snapshot, then two counters the server writes.
_SEQ = struct.Struct("<Q")
_STATE = struct.Struct("<d6d6d6diiBB")
_STATS = struct.Struct("<QQ")  # connected clients, data packages sent
_STATE_AT = _SEQ.size
_STATS_AT = _STATE_AT + _STATE.size
_SHARED_SIZE = _STATS_AT + _STATS.size


class _SharedState:
    """A sequence-locked snapshot in a memory-mapped temporary file that both processes map."""

    def __init__(self, fd: int) -> None:
        self._map = mmap.mmap(fd, _SHARED_SIZE)

    def close(self) -> None:
        self._map.close()

    def write_state(self, state: Snapshot) -> None:
        (seq,) = _SEQ.unpack_from(self._map, 0)
        _SEQ.pack_into(self._map, 0, seq + 1)
        _STATE.pack_into(
            self._map,
            _STATE_AT,
            state.controller_t_s,
            *state.tcp_pose,
            *state.tcp_force,
            *state.tcp_speed,
            state.robot_mode,
            state.safety_mode,
            state.protective_stop,
            state.emergency_stop,
        )
        _SEQ.pack_into(self._map, 0, seq + 2)

    def read_state(self) -> Snapshot | None:
        """The snapshot, or None while a write is in progress (the caller keeps its previous one)."""
        (before,) = _SEQ.unpack_from(self._map, 0)
        fields = _STATE.unpack_from(self._map, _STATE_AT)
        (after,) = _SEQ.unpack_from(self._map, 0)
        if before % 2 or before != after or before == 0:
            return None
        return Snapshot(
            fields[0],
            fields[1:7],
            fields[7:13],
            fields[13:19],
            fields[19],
            fields[20],
            bool(fields[21]),
            bool(fields[22]),
        )

    def set_client_count(self, count: int) -> None:
        _, sent = _STATS.unpack_from(self._map, _STATS_AT)
        _STATS.pack_into(self._map, _STATS_AT, count, sent)

    def count_sent(self) -> None:
        clients, sent = _STATS.unpack_from(self._map, _STATS_AT)
        _STATS.pack_into(self._map, _STATS_AT, clients, sent + 1)

    def stats(self) -> tuple[int, int]:
        clients, sent = _STATS.unpack_from(self._map, _STATS_AT)
        return int(clients), int(sent)


# ---- the server process ---------------------------------------------------------------------------------------


# Input-only variables a controller accepts besides the registers (ur_rtde's setExternalForceTorque recipe).
INPUT_VARIABLE_TYPES: dict[str, str] = {"external_force_torque": "VECTOR6D"}


def input_variable_type(name: str) -> str:
    """RTDE type of an input (client -> controller) variable, or ``NOT_FOUND``."""
    if name in INPUT_VARIABLE_TYPES:
        return INPUT_VARIABLE_TYPES[name]
    known = rtde.variable_type(name) if name.startswith("input_") else None
    return known or rtde.NOT_FOUND


class RtdeSession:
    """The server side of one RTDE connection, without the socket: recipes, start/pause and the stream schedule.

    Shared by this module's receive-only server and the controller twin (:mod:`unitac_rig.sim.twin`). Output and
    input recipes are numbered 1, 2, 3... on **separate counters**: ur_rtde's control client hard-codes its input
    recipe ids 1..23 in setup order and ignores the ids in the replies, so one shared counter (output recipe = 1,
    inputs from 2) breaks it silently. Every input recipe request gets an id, even one with ``NOT_FOUND`` in it
    (the client ignores that reply and counts on the next id); one with ``IN_USE`` gets 0, as a controller refuses it.
    """

    def __init__(
        self,
        peer: str,
        *,
        controller_version: ControllerVersion,
        max_frequency_hz: float,
        registers_in_use: frozenset[str] = frozenset(),
        outputs_not_found: frozenset[str] = frozenset(),
    ) -> None:
        self.peer = peer
        self.controller_version = controller_version
        self.max_frequency_hz = max_frequency_hz
        self.registers_in_use = registers_in_use
        self.outputs_not_found = outputs_not_found  # output names answered NOT_FOUND (a controller without them)
        self.output_names: tuple[str, ...] = ()
        self.output_types: tuple[str, ...] = ()
        self.output_recipe_id = 0
        self.input_recipes: dict[int, tuple[tuple[str, ...], tuple[str, ...]]] = {}
        self._next_output_id = 1
        self._next_input_id = 1
        self.period_s = 1.0 / max_frequency_hz
        self.streaming = False
        self.next_due_s = 0.0

    @property
    def wants_data(self) -> bool:
        """Started and subscribed to something: data packages are due every ``period_s``."""
        return self.streaming and bool(self.output_types)

    def handle(self, package: rtde.RtdePackage) -> bytes | None:
        """The reply to a request package (None for data packages and text messages, which get none)."""
        kind = package.type
        if kind == PackageType.REQUEST_PROTOCOL_VERSION:
            version = rtde.decode_request_protocol_version(package.payload)
            return rtde.encode_protocol_version_reply(version == rtde.PROTOCOL_VERSION)
        if kind == PackageType.GET_URCONTROL_VERSION:
            return rtde.encode_controller_version_reply(self.controller_version)
        if kind == PackageType.CONTROL_PACKAGE_SETUP_OUTPUTS:
            return self._setup_outputs(package.payload)
        if kind == PackageType.CONTROL_PACKAGE_SETUP_INPUTS:
            return self._setup_inputs(package.payload)
        if kind == PackageType.CONTROL_PACKAGE_START:
            self.streaming = True
            self.next_due_s = time.monotonic()
            return rtde.encode_accepted_reply(kind, True)
        if kind == PackageType.CONTROL_PACKAGE_PAUSE:
            self.streaming = False
            return rtde.encode_accepted_reply(kind, True)
        if kind == PackageType.TEXT_MESSAGE:
            message = rtde.decode_text_message(package.payload)
            logger.info("RTDE client %s says [%s] %s", self.peer, message.source, message.message)
        return None

    def input_values(self, payload: bytes) -> dict[str, rtde.FieldValue] | None:
        """The variables a data package from the client writes, by name; None for an unknown recipe id."""
        recipe_id = payload[0] if payload else -1
        recipe = self.input_recipes.get(recipe_id)
        if recipe is None:
            logger.debug("RTDE client %s sent data for unknown input recipe %d", self.peer, recipe_id)
            return None
        names, types = recipe
        _, values = rtde.decode_data_package(payload, types)
        return dict(zip(names, values, strict=True))

    def take_due(self, now_s: float) -> bool:
        """True (and the schedule moves on) when a data package is due at ``now_s``; never bursts to catch up."""
        if not self.wants_data or self.next_due_s > now_s:
            return False
        self.next_due_s += self.period_s
        if self.next_due_s < now_s - self.period_s:  # fell behind: skip, do not burst
            self.next_due_s = now_s + self.period_s
        return True

    def data_package(self, known: Mapping[str, rtde.FieldValue]) -> bytes:
        """One output data package, values by name from ``known`` (zeros for the rest)."""
        values = values_for(self.output_names, self.output_types, known)
        return rtde.encode_data_package(self.output_recipe_id, self.output_types, values)

    def _setup_outputs(self, payload: bytes) -> bytes:
        frequency_hz, names = rtde.decode_setup_outputs(payload)
        types = tuple(
            rtde.NOT_FOUND if name in self.outputs_not_found else rtde.variable_type(name) or rtde.NOT_FOUND
            for name in names
        )
        recipe_id = 0
        if names and rtde.NOT_FOUND not in types:
            limit_hz = self.max_frequency_hz
            if not 0 < frequency_hz <= limit_hz:  # NaN and inf too: never a stream period of NaN or 0 s
                logger.info("RTDE client %s asked for %.1f Hz; streaming at %.1f Hz", self.peer, frequency_hz, limit_hz)
                frequency_hz = limit_hz
            recipe_id = self._next_output_id
            self._next_output_id += 1
            self.output_names, self.output_types = names, types
            self.output_recipe_id = recipe_id
            self.period_s = 1.0 / frequency_hz
        return rtde.encode_recipe_reply(PackageType.CONTROL_PACKAGE_SETUP_OUTPUTS, RecipeReply(recipe_id, types))

    def _setup_inputs(self, payload: bytes) -> bytes:
        names = rtde.decode_setup_inputs(payload)
        types = tuple(rtde.IN_USE if n in self.registers_in_use else input_variable_type(n) for n in names)
        recipe_id = 0
        if names and rtde.IN_USE not in types:
            recipe_id = self._next_input_id
            self._next_input_id += 1
            if rtde.NOT_FOUND not in types:
                self.input_recipes[recipe_id] = (names, types)
        return rtde.encode_recipe_reply(PackageType.CONTROL_PACKAGE_SETUP_INPUTS, RecipeReply(recipe_id, types))


@dataclass
class _Client:
    sock: socket.socket
    session: RtdeSession
    parser: rtde.RtdePackageParser = field(default_factory=rtde.RtdePackageParser)

    @property
    def peer(self) -> str:
        return self.session.peer


@dataclass(frozen=True)
class _ServerSettings:
    host: str
    port: int
    max_frequency_hz: float
    controller_version: ControllerVersion
    registers_in_use: frozenset[str]
    outputs_not_found: frozenset[str]


class _RtdeServerLoop:
    """The RTDE protocol server; runs in its own process (see :class:`SimURController` for why)."""

    def __init__(self, settings: _ServerSettings, listener: socket.socket, shared: _SharedState) -> None:
        self.settings = settings
        self._listener = listener
        self._shared = shared
        self._clients: list[_Client] = []
        self._selector = selectors.DefaultSelector()
        self._selector.register(listener, selectors.EVENT_READ, None)
        self._last_state = shared.read_state() or Snapshot(
            0.0, tuple(DEFAULT_STILL_POSE), (0.0,) * 6, (0.0,) * 6, ROBOT_MODE_RUNNING, SAFETY_MODE_NORMAL, False, False
        )

    def run(self, control_fd: int) -> None:
        """Serve until ``control_fd`` (the parent's pipe) closes: the parent asked to stop, or it died."""
        self._selector.register(control_fd, selectors.EVENT_READ, None)
        try:
            while True:
                self._send_due_packages()
                for key, _ in self._selector.select(self._wait_time_s()):
                    if key.fileobj is self._listener:
                        self._accept()
                    elif key.fileobj == control_fd:
                        if not os.read(control_fd, 64):
                            return
                    else:
                        self._read(key.data)
        finally:
            for client in list(self._clients):
                self._drop(client, "server closing")
            self._selector.close()

    def _wait_time_s(self) -> float:
        due = [c.session.next_due_s for c in self._clients if c.session.wants_data]
        if not due:
            return _MAX_IDLE_WAIT_S
        return min(max(0.0, min(due) - time.monotonic()), _MAX_IDLE_WAIT_S)

    def _accept(self) -> None:
        try:
            sock, peer = self._listener.accept()
        except BlockingIOError:
            return
        sock.settimeout(_SEND_TIMEOUT_S)
        sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        session = RtdeSession(
            f"{peer[0]}:{peer[1]}",
            controller_version=self.settings.controller_version,
            max_frequency_hz=self.settings.max_frequency_hz,
            registers_in_use=self.settings.registers_in_use,
            outputs_not_found=self.settings.outputs_not_found,
        )
        client = _Client(sock=sock, session=session)
        self._clients.append(client)
        self._shared.set_client_count(len(self._clients))
        self._selector.register(sock, selectors.EVENT_READ, client)
        logger.debug("RTDE client %s connected", client.peer)

    def _drop(self, client: _Client, why: str) -> None:
        logger.debug("RTDE client %s dropped: %s", client.peer, why)
        if client in self._clients:
            self._clients.remove(client)
        self._shared.set_client_count(len(self._clients))
        with contextlib.suppress(KeyError, ValueError):
            self._selector.unregister(client.sock)
        client.sock.close()

    def _read(self, client: _Client) -> None:
        try:
            data = client.sock.recv(65536)
        except (BlockingIOError, TimeoutError):
            return
        except OSError as exc:
            self._drop(client, f"recv failed: {exc}")
            return
        if not data:
            self._drop(client, "closed by peer")
            return
        try:
            for package in client.parser.feed(data):
                if package.type == PackageType.DATA_PACKAGE:
                    client.session.input_values(package.payload)  # accepted and ignored: nothing is driven here
                    continue
                reply = client.session.handle(package)
                if reply:
                    client.sock.sendall(reply)
        except OSError as exc:
            self._drop(client, f"send failed: {exc}")
        except rtde.ProtocolError as exc:
            self._drop(client, f"bad package: {exc}")

    def _send_due_packages(self) -> None:
        now_s = time.monotonic()
        due = [c for c in self._clients if c.session.take_due(now_s)]
        if not due:
            return
        state = self._shared.read_state() or self._last_state
        self._last_state = state
        known = snapshot_values(state)
        for client in due:
            try:
                client.sock.sendall(client.session.data_package(known))
            except OSError as exc:
                self._drop(client, f"send failed: {exc}")
                continue
            self._shared.count_sent()


def _server_main(argv: Sequence[str]) -> int:
    """Entry point of the server process: bind, print ``ready PORT`` (or ``error TEXT``), serve until stdin closes."""
    parser = argparse.ArgumentParser(prog="python -m unitac_rig.sim.rtde_server")
    parser.add_argument("--host", required=True)
    parser.add_argument("--port", type=int, required=True)
    parser.add_argument("--max-frequency-hz", type=float, required=True)
    parser.add_argument("--controller-version", required=True, help="major.minor.bugfix.build")
    parser.add_argument("--registers-in-use", default="", help="comma-joined input names to answer IN_USE")
    parser.add_argument("--outputs-not-found", default="", help="comma-joined output names to answer NOT_FOUND")
    parser.add_argument("--shared-fd", type=int, required=True)
    args = parser.parse_args(argv)
    version = ControllerVersion(*(int(part) for part in args.controller_version.split(".")))
    settings = _ServerSettings(
        args.host,
        args.port,
        args.max_frequency_hz,
        version,
        frozenset(filter(None, args.registers_in_use.split(","))),
        frozenset(filter(None, args.outputs_not_found.split(","))),
    )
    listener = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    try:
        listener.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        listener.bind((settings.host, settings.port))
        listener.listen(4)
    except OSError as exc:
        listener.close()
        print(f"error {exc.errno or 0} {exc.strerror or exc}", flush=True)  # noqa: T201 - the parent reads this line
        return 1
    listener.setblocking(False)
    shared = _SharedState(args.shared_fd)
    print(f"ready {listener.getsockname()[1]}", flush=True)  # noqa: T201 - the parent reads this line
    try:
        _RtdeServerLoop(settings, listener, shared).run(sys.stdin.fileno())
    finally:
        listener.close()
        shared.close()
    return 0


# ---- the object users hold ------------------------------------------------------------------------------------


class _AddressTaken(DeviceError):
    """The server process could not bind: something already listens there."""


_PACKAGE_ROOT = str(Path(__file__).resolve().parents[2])  # the directory that holds unitac_rig/


class SimURController:
    """RTDE server of a simulated UR controller on ``host``:``port`` (30004 by default, what ur_rtde dials).

    ``state_provider`` is polled ``frequency_hz`` times a second by a thread named ``sim-rtde`` and must be thread
    safe (return an immutable snapshot: ``SimArm.latest_state`` only while nothing advances that arm's clock, since
    it forms the snapshot on first read; the twin publishes its own through shared memory); without one the arm
    stands still at :data:`DEFAULT_STILL_POSE` with zero force and the timestamp counts seconds since the server
    started.
    ``frequency_hz`` is also the highest stream rate (500 Hz on e-Series); a client asking for more gets this rate.
    Names in ``registers_in_use`` are answered ``IN_USE`` in input recipes (like a running fieldbus adapter), names
    in ``outputs_not_found`` ``NOT_FOUND`` in output recipes (a controller, or a fake, that does not offer them).
    Raises DeviceError if the address is taken. POSIX only (the shared block is passed as a file descriptor).
    """

    def __init__(
        self,
        host: str = "127.0.0.1",
        *,
        state_provider: Callable[[], ArmState] | None = None,
        frequency_hz: float = 500.0,
        port: int = rtde.RTDE_PORT,
        controller_version: ControllerVersion = ControllerVersion(5, 11, 0, 0),
        registers_in_use: frozenset[str] = frozenset(),
        outputs_not_found: frozenset[str] = frozenset(),
    ) -> None:
        if not (math.isfinite(frequency_hz) and frequency_hz > 0):
            raise ValueError(f"frequency_hz must be a positive number, got {frequency_hz}")
        self.host = host
        self.frequency_hz = frequency_hz
        self._state_provider = state_provider or self._still_state
        self._started_at_s = time.monotonic()
        self._closed = False
        self._stop = threading.Event()
        self._file = tempfile.TemporaryFile()  # noqa: SIM115 - lives as long as the server; closed in close()
        self._file.truncate(_SHARED_SIZE)
        self._shared = _SharedState(self._file.fileno())
        self._shared.write_state(Snapshot.from_state(self._state_provider()))
        v = controller_version
        command = [
            sys.executable, "-m", "unitac_rig.sim.rtde_server",
            "--host", host, "--port", str(port), "--max-frequency-hz", repr(frequency_hz),
            "--controller-version", f"{v.major}.{v.minor}.{v.bugfix}.{v.build}",
            "--registers-in-use", ",".join(sorted(registers_in_use)),
            "--outputs-not-found", ",".join(sorted(outputs_not_found)),
            "--shared-fd", str(self._file.fileno()),
        ]  # fmt: skip
        environment = dict(os.environ)  # the child imports this very package, wherever the caller found it
        environment["PYTHONPATH"] = os.pathsep.join(filter(None, [_PACKAGE_ROOT, environment.get("PYTHONPATH")]))
        self._process = subprocess.Popen(
            command, stdin=subprocess.PIPE, stdout=subprocess.PIPE, pass_fds=(self._file.fileno(),), env=environment
        )
        try:
            self.port = self._await_ready(port)
        except BaseException:
            self._shut_down_process()
            raise
        self._shared.write_state(Snapshot.from_state(self._state_provider()))  # fresh: start-up took a while
        self._pump = threading.Thread(target=self._pump_states, name="sim-rtde", daemon=True)
        self._pump.start()
        logger.debug("simulated UR controller listening on %s:%d (pid %d)", host, self.port, self._process.pid)

    def _await_ready(self, port: int) -> int:
        assert self._process.stdout is not None
        line = b""
        ready, _, _ = select.select([self._process.stdout], [], [], _START_TIMEOUT_S)
        if ready:
            line = self._process.stdout.readline()
        word, _, rest = line.decode("utf-8", "replace").strip().partition(" ")
        if word == "ready":
            return int(rest)
        if word == "error":
            code, _, why = rest.partition(" ")
            message = f"simulated UR controller cannot listen on {self.host}:{port}: {why}"
            if int(code or 0) == errno.EADDRINUSE:
                raise _AddressTaken(
                    message, hint="another controller (or URSim) uses this address; try another 127.0.0.x"
                )
            raise DeviceError(message, hint="use a loopback address such as 127.0.0.2")
        exit_code = self._process.poll()
        why = f"it exited with status {exit_code}" if exit_code is not None else f"no answer in {_START_TIMEOUT_S} s"
        raise DeviceError(
            f"the simulated UR controller's server process did not start ({why})",
            hint="see its error output above; is unitac-rig installed in this Python environment?",
        )

    # ---- public ---------------------------------------------------------------------------------------------

    @property
    def address(self) -> tuple[str, int]:
        return (self.host, self.port)

    @property
    def client_count(self) -> int:
        """RTDE clients connected right now."""
        return self._shared.stats()[0]

    @property
    def sent_packages(self) -> int:
        """Data packages streamed so far (all clients)."""
        return self._shared.stats()[1]

    def close(self) -> None:
        """Stop serving, drop clients, end the server process and the ``sim-rtde`` thread. Idempotent."""
        if self._closed:
            return
        self._closed = True
        self._stop.set()
        self._pump.join(timeout=5.0)
        self._shut_down_process()

    def __enter__(self) -> SimURController:
        return self

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.close()

    # ---- internals ------------------------------------------------------------------------------------------

    def _shut_down_process(self) -> None:
        stop_child(self._process, "simulated UR controller")
        self._shared.close()
        self._file.close()

    def _still_state(self) -> ArmState:
        return ArmState(
            host_t_ns=time.monotonic_ns(),
            controller_t_s=time.monotonic() - self._started_at_s,
            tcp_pose=DEFAULT_STILL_POSE.copy(),
            tcp_force=np.zeros(6),
            robot_mode=ROBOT_MODE_RUNNING,
            safety_mode=SAFETY_MODE_NORMAL,
            protective_stop=False,
            tcp_speed=np.zeros(6),
        )

    def _pump_states(self) -> None:
        period_s = 1.0 / self.frequency_hz
        while not self._stop.wait(period_s):
            try:
                state = self._state_provider()
            except Exception:
                logger.exception("simulated UR controller: the state provider failed; streaming the last state")
                continue
            self._shared.write_state(Snapshot.from_state(state))


def start_on_free_loopback(
    state_provider: Callable[[], ArmState] | None = None,
    *,
    frequency_hz: float = 500.0,
    first: int = 2,
    outputs_not_found: frozenset[str] = frozenset(),
) -> SimURController:
    """A :class:`SimURController` on the first 127.0.0.x (x >= ``first``) whose port 30004 is free (Linux loopback)."""
    for last_octet in range(first, 255):
        host = f"127.0.0.{last_octet}"
        probe = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        probe.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)  # as the server does: TIME_WAIT is no obstacle
        try:
            probe.bind((host, rtde.RTDE_PORT))
        except OSError:
            continue
        finally:
            probe.close()
        try:
            return SimURController(
                host, state_provider=state_provider, frequency_hz=frequency_hz, outputs_not_found=outputs_not_found
            )
        except _AddressTaken:
            continue  # taken between the check and the start
    raise DeviceError(
        "no free loopback address for a simulated UR controller (127.0.0.2-254 all have port 30004 in use)",
        hint="close other simulated controllers or URSim instances",
    )


if __name__ == "__main__":
    sys.exit(_server_main(sys.argv[1:]))
