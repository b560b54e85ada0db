"""The controller twin: a simulated UR e-Series controller on one loopback address, in real time.

It runs in its own process (:mod:`unitac_rig.sim.twin.process`, started by
:class:`unitac_rig.sim.twin.ControllerTwin`: ur_rtde's constructors hold the GIL while they handshake, so a server
thread in the client's interpreter would never answer). It binds the dashboard (29999), script (30003) and RTDE
(30004) ports and runs until its owner's stdin closes; further stdin lines are test hooks (JSON, answered with one
JSON line on stdout).

One thread, one loop, a 2 ms cycle on the wall clock: sockets are served between cycles (RTDE inputs land in the
register bank at once, the dashboard answers at once, a complete uploaded program starts at the next cycle), then
each due cycle runs, in the order a controller does it: safety checks (force limit, reach, watchdog), the control
script's main loop and threads (:mod:`~unitac_rig.sim.twin.script`), the arm integrating one period
(:mod:`~unitac_rig.sim.twin.motion`). After the due cycles the output recipe goes out to every streaming RTDE client
and the ground truth is written. A cycle that starts late (the machine was busy) is caught up: the missed periods are
integrated back to back, so the arm's motion stays in wall time; the lateness is counted in the truth block. The
watchdog is not judged on those catch-up cycles (the host's writes of the missed periods are still in the sockets)
but on the next on-time cycle, after the writes are served.

Safety behaves like a controller's, not like a library's: a protective stop (|F| over ``protective_stop_n``, leaving
the reach, ``triggerProtectiveStop`` or a test hook) brakes the arm, pauses the program and raises safety bit 2; it
is unlocked only through the dashboard, not before ``unlock_delay_s``, and the program must then be uploaded again.
An emergency stop (test hook) brakes the arm, stops the program, raises bits 6, 7 and 10 and powers the arm off once
at rest; after its release the dashboard must power on and release the brakes. Nothing the clients do (or fail to do:
a dropped connection) changes what the program is executing, except through the watchdog the program armed.

One real-time loop emulating the control script command by command; the command table reads best in one place.
Sibling modules hold the rest: the dashboard, the arm's motion, the script text, the contact world and its
background table builds (:mod:`~unitac_rig.sim.twin.world`), the ground truth.
"""

from __future__ import annotations

import contextlib
import dataclasses
import json
import logging
import math
import os
import selectors
import socket
import sys
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from protocols import rtde
from protocols.rtde import ControllerVersion, PackageType
from unitac_rig.sim.arm import ROBOT_MODE_RUNNING, SAFETY_MODE_NORMAL, SAFETY_MODE_PROTECTIVE_STOP, SimArm, SimArmParams
from unitac_rig.sim.fast_rig import noise_seed
from unitac_rig.sim.twin import dashboard
from unitac_rig.sim.twin.motion import TwinArm, pose_matrix
from unitac_rig.sim.twin.params import DASHBOARD_PORT, RTDE_PORT, SCRIPT_PORT, TwinSettings
from unitac_rig.sim.twin.rtde_session import RtdeSession
from unitac_rig.sim.twin.script import (
    ControlScript,
    OutputRegisters,
    ScriptError,
    is_control_script,
    register_offset_from_script,
    take_program,
)
from unitac_rig.sim.twin.truth import TruthBlock, TwinTruth
from unitac_rig.sim.twin.world import SceneWorld

logger = logging.getLogger(__name__)

PERIOD_S = SimArm.control_period_s  # UR e-Series controller cycle, 500 Hz [S: hardware-facts 3.8]

# robot_mode values (RUNNING and the safety modes NORMAL and PROTECTIVE_STOP are the arm model's, sim/arm.py; the
# safety bits a client tests are protocols.rtde's)
ROBOT_MODE_POWER_OFF = 3
ROBOT_MODE_IDLE = 5
# safety_mode values
SAFETY_ROBOT_EMERGENCY_STOP = 7
# safety_status_bits
BIT_ROBOT_EMERGENCY = 1 << 6
BIT_STOPPED_BY_SAFETY = 1 << 10
# robot_status_bits
STATUS_POWER_ON = 1 << 0
STATUS_PROGRAM_RUNNING = 1 << 1
# runtime_state values
RUNTIME_STOPPED = 1
RUNTIME_PLAYING = 2
RUNTIME_PAUSED = 4

_OUTPUT_INT_NAMES = tuple(f"output_int_register_{i}" for i in range(48))
_OUTPUT_DOUBLE_NAMES = tuple(f"output_double_register_{i}" for i in range(48))
_MAX_PENDING_BYTES = 256 * 1024  # a client that stops reading gets no data packages until it catches up
_IDLE_SELECT_S = 0.05


@dataclass
class _Connection:
    sock: socket.socket
    kind: str  # "dashboard" | "script" | "rtde"
    peer: str
    inbox: bytearray = field(default_factory=bytearray)
    outbox: bytearray = field(default_factory=bytearray)
    session: RtdeSession | None = None
    parser: rtde.RtdePackageParser | None = None


class Controller:
    """The whole controller: servers, safety, program, arm. Single-threaded; :meth:`run` is the loop."""

    def __init__(self, settings: TwinSettings, truth: TruthBlock, hooks_in: int | None = None) -> None:
        self.settings = settings
        self.params = settings.params
        self._truth_block = truth
        self._hooks_in = hooks_in
        self._hook_buffer = bytearray()
        self.world = SceneWorld(settings.scene)
        arm_params = SimArmParams(protective_stop_n=self.params.protective_stop_n)
        self.arm = TwinArm(
            self.world,
            rng=np.random.default_rng([settings.seed, 1]),
            params=arm_params,
            start_pose=np.asarray(settings.start_pose, dtype=np.float64),
            tool_offset=np.asarray(self.params.tool_offset, dtype=np.float64),
        )
        scene = settings.scene
        if scene is not None and scene.sensor is not None:  # the session's own F/T noise, as on the fast twin
            session = (scene.object_id, scene.sensor, scene.rotation_deg)
            self.arm.use_noise_stream(np.random.default_rng(noise_seed(settings.seed, *session, "arm")))
        if self.params.pendant_tcp is not None:
            self.arm.active_tcp = np.asarray(self.params.pendant_tcp, dtype=np.float64)
        self.payload_kg = self.params.payload_kg
        self.payload_cog_m = tuple(self.params.payload_cog_m)
        self.remote_control = self.params.remote_control
        self.version = ControllerVersion(*self.params.controller_version)

        self.robot_mode = ROBOT_MODE_RUNNING
        self.protective = False
        self.protective_since_s = 0.0
        self.emergency = False
        self.program: ControlScript | None = None
        self.runtime_state = RUNTIME_STOPPED
        self.outputs = OutputRegisters()
        self.inputs: dict[str, Any] = {}
        self.last_write_s: dict[str, float] = {}
        self.watchdog: tuple[str, float, float] | None = None  # register, min frequency (Hz), armed at (s)
        self.cycles = 0
        self.peak_force_n = 0.0
        self.counts = {"watchdog": 0, "protective": 0, "emergency": 0, "starts": 0, "uploads": 0}
        self.last_error = ""
        self.last_input_s = 0.0
        self.worst_lateness_s = 0.0
        self.late_cycles = 0
        self.skipped_cycles = 0
        self._rate_window: tuple[float, int] = (time.monotonic(), 0)
        self.achieved_rate_hz = 0.0

        self.connections: list[_Connection] = []
        self.selector = selectors.DefaultSelector()
        self.listeners: dict[int, socket.socket] = {}
        self._stop = False
        self.scheduling = "normal"

    @property
    def now_s(self) -> float:
        """Controller time: cycles run times the period."""
        return self.cycles * PERIOD_S

    # ---- sockets --------------------------------------------------------------------------------------------

    def bind(self) -> None:
        """Bind the ports named in ``params.serve``; raises OSError (EADDRINUSE...) if one is taken."""
        ports = {"dashboard": DASHBOARD_PORT, "script": SCRIPT_PORT, "rtde": RTDE_PORT}
        for name in self.params.serve:
            listener = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
            try:
                listener.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
                listener.bind((self.settings.host, ports[name]))
                listener.listen(8)
            except OSError:
                listener.close()
                self.close_listeners()
                raise
            listener.setblocking(False)
            self.listeners[ports[name]] = listener
            self.selector.register(listener, selectors.EVENT_READ, name)

    def close_listeners(self) -> None:
        for listener in self.listeners.values():
            with contextlib.suppress(KeyError, ValueError):
                self.selector.unregister(listener)
            listener.close()
        self.listeners.clear()

    def _accept(self, listener: socket.socket, kind: str) -> None:
        try:
            sock, peer = listener.accept()
        except BlockingIOError:
            return
        sock.setblocking(False)
        sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        connection = _Connection(sock, kind, f"{peer[0]}:{peer[1]}")
        if kind == "rtde":
            connection.session = RtdeSession(
                connection.peer,
                controller_version=self.version,
                max_frequency_hz=500.0,
                registers_in_use=frozenset(self.params.rtde_registers_in_use),
                outputs_not_found=frozenset(self.params.rtde_outputs_not_found),
            )
            connection.parser = rtde.RtdePackageParser()
        self.connections.append(connection)
        self.selector.register(sock, selectors.EVENT_READ, connection)
        if kind == "dashboard":
            self._send(connection, (dashboard.WELCOME + "\n").encode())
        logger.debug("%s client %s connected", kind, connection.peer)

    def _drop(self, connection: _Connection, why: str) -> None:
        logger.debug("%s client %s dropped: %s", connection.kind, connection.peer, why)
        if connection in self.connections:
            self.connections.remove(connection)
        with contextlib.suppress(KeyError, ValueError):
            self.selector.unregister(connection.sock)
        connection.sock.close()

    def _send(self, connection: _Connection, data: bytes) -> None:
        connection.outbox += data
        self._flush(connection)

    def _flush(self, connection: _Connection) -> None:
        while connection.outbox:
            try:
                sent = connection.sock.send(connection.outbox)
            except BlockingIOError:
                return
            except OSError as exc:
                self._drop(connection, f"send failed: {exc}")
                return
            del connection.outbox[:sent]

    def _read(self, connection: _Connection) -> None:
        try:
            data = connection.sock.recv(65536)
        except BlockingIOError:
            return
        except OSError as exc:
            self._drop(connection, f"recv failed: {exc}")
            return
        if not data:
            if connection.kind == "script" and connection.inbox:
                self._script_bytes(connection, b"", closing=True)
            self._drop(connection, "closed by peer")
            return
        if connection.kind == "dashboard":
            self._dashboard_bytes(connection, data)
        elif connection.kind == "script":
            self._script_bytes(connection, data)
        else:
            self._rtde_bytes(connection, data)

    # ---- dashboard ------------------------------------------------------------------------------------------

    def _dashboard_bytes(self, connection: _Connection, data: bytes) -> None:
        connection.inbox += data
        while b"\n" in connection.inbox:
            raw, _, rest = bytes(connection.inbox).partition(b"\n")
            connection.inbox = bytearray(rest)
            line = raw.decode("utf-8", "replace").rstrip("\r")
            reply, close = dashboard.answer(self, line)
            logger.debug("dashboard %r -> %r", line, reply)
            self._send(connection, (reply + "\n").encode())
            if close:
                self._drop(connection, "quit")
                return

    def safety_mode(self) -> int:
        if self.emergency:
            return SAFETY_ROBOT_EMERGENCY_STOP
        if self.protective:
            return SAFETY_MODE_PROTECTIVE_STOP
        return SAFETY_MODE_NORMAL

    def program_state(self) -> str:
        name = "rtde_control" if self.program is not None else "<unnamed>"
        state = {RUNTIME_PLAYING: "PLAYING", RUNTIME_PAUSED: "PAUSED"}.get(self.runtime_state, "STOPPED")
        return f"{state} {name}"

    def program_running(self) -> bool:
        return self.runtime_state == RUNTIME_PLAYING

    def power_on(self) -> bool:
        if self.emergency:
            return False
        if self.robot_mode == ROBOT_MODE_POWER_OFF:
            self.robot_mode = ROBOT_MODE_IDLE
        return True

    def power_off(self) -> None:
        self.stop_program("power off")
        self.arm.stop(self.arm.params.protective_stop_decel_m_s2)
        self.robot_mode = ROBOT_MODE_POWER_OFF

    def brake_release(self) -> bool:
        if self.emergency or self.robot_mode == ROBOT_MODE_POWER_OFF:
            return False
        self.robot_mode = ROBOT_MODE_RUNNING
        return True

    def unlock_protective_stop(self) -> str:
        if not self.protective:
            return "Protective stop releasing"
        if self.now_s - self.protective_since_s < self.params.unlock_delay_s:
            return dashboard.UNLOCK_TOO_EARLY
        self.protective = False
        self.arm.unlock()  # trips again at once if the force is still over the limit
        logger.info("protective stop unlocked")
        return "Protective stop releasing"

    def pause_program(self) -> bool:
        if self.runtime_state != RUNTIME_PLAYING:
            return False
        self.runtime_state = RUNTIME_PAUSED
        self.arm.stop(self.arm.params.program_stop_decel_m_s2)
        return True

    def play_program(self) -> bool:
        if self.runtime_state != RUNTIME_PAUSED or self.program is None or not self._can_run():
            return False
        self.runtime_state = RUNTIME_PLAYING
        return True

    def restart_safety(self) -> None:
        """Reboot the safety system: stops clear, the arm is powered off (as PolyScope does)."""
        self.stop_program("restart safety")
        self.protective = False
        self.arm.unlock()
        self.robot_mode = ROBOT_MODE_POWER_OFF

    # ---- script port ----------------------------------------------------------------------------------------

    def _script_bytes(self, connection: _Connection, data: bytes, *, closing: bool = False) -> None:
        connection.inbox += data
        text = connection.inbox.decode("utf-8", "replace")
        while True:
            program, rest = take_program(text)
            if program is None:
                break
            text = rest
            self._on_program(program)
        connection.inbox = bytearray(text.encode("utf-8"))
        if closing and text.strip():
            logger.warning("script port: discarded an incomplete program (%d bytes)", len(text))

    def _can_run(self) -> bool:
        return self.robot_mode == ROBOT_MODE_RUNNING and not self.protective and not self.emergency

    def _on_program(self, text: str) -> None:
        self.counts["uploads"] += 1
        if not self.remote_control:
            self.last_error = "program refused: the robot is in local control"
            logger.warning(self.last_error)
            return
        if not self._can_run():
            self.last_error = (
                f"program refused: robot mode {dashboard.ROBOT_MODE_NAMES.get(self.robot_mode)}, "
                f"safety {dashboard.SAFETY_MODE_NAMES.get(self.safety_mode())}"
            )
            logger.warning(self.last_error)
            return
        if self.program is not None:
            self.stop_program("replaced by a new program")
        if not is_control_script(text):
            self.last_error = "uploaded program is not ur_rtde's control script; the twin cannot run it"
            logger.warning(self.last_error)
            return
        self.program = ControlScript(self, self.outputs, register_offset=register_offset_from_script(text))
        self.runtime_state = RUNTIME_PLAYING
        self.counts["starts"] += 1
        logger.info("control script started (register offset %d)", self.program.offset)

    # ---- ScriptHost -----------------------------------------------------------------------------------------

    def set_watchdog(self, register: str, min_frequency_hz: float) -> None:
        if not (math.isfinite(min_frequency_hz) and min_frequency_hz > 0):  # NaN would never fire
            raise ScriptError(f"rtde_set_watchdog: frequency must be > 0, got {min_frequency_hz}")
        self.watchdog = (register, min_frequency_hz, self.now_s)
        logger.info("watchdog armed on %s at %.1f Hz", register, min_frequency_hz)

    def trigger_protective_stop(self, why: str = "protective_stop() called") -> None:
        if self.protective:
            return
        self.protective = True
        self.protective_since_s = self.now_s
        self.counts["protective"] += 1
        self.last_error = f"protective stop: {why}"
        logger.warning(self.last_error)
        self.arm.trigger_protective_stop()
        if self.runtime_state == RUNTIME_PLAYING:
            self.runtime_state = RUNTIME_PAUSED

    def set_payload(self, mass_kg: float, cog_m: np.ndarray | None) -> None:
        self.payload_kg = float(mass_kg)
        if cog_m is not None:
            self.payload_cog_m = tuple(float(v) for v in cog_m)

    def prepare_move(self, tcp_pose: np.ndarray) -> None:
        """A move toward ``tcp_pose`` starts: have the contact table of its ray built meanwhile."""
        self.world.warm(self.arm.pad_target(np.asarray(tcp_pose, dtype=np.float64)))

    def reachable(self, tcp_pose: np.ndarray) -> bool:
        return self._flange_distance_m(self.arm.pad_target(np.asarray(tcp_pose, dtype=np.float64))) <= (
            self.params.reach_m
        )

    def _flange_distance_m(self, pad_pose: np.ndarray) -> float:
        flange = pose_matrix(pad_pose) @ np.linalg.inv(pose_matrix(self.arm.tool_offset))
        shoulder = np.array([0.0, 0.0, self.params.shoulder_height_m])
        return float(np.linalg.norm(flange[:3, 3] - shoulder))

    # ---- program and safety ---------------------------------------------------------------------------------

    def stop_program(self, why: str) -> bool:
        """Stop the program (if one is loaded): watchdog removed, the arm decelerates to rest."""
        if self.program is None and self.runtime_state == RUNTIME_STOPPED:
            return False
        logger.info("program stopped: %s", why)
        self.program = None
        self.runtime_state = RUNTIME_STOPPED
        self.watchdog = None
        if not self.arm.protective_stopped:
            self.arm.stop(self.arm.params.program_stop_decel_m_s2)
        return True

    def emergency_stop(self) -> None:
        if self.emergency:
            return
        self.emergency = True
        self.counts["emergency"] += 1
        self.last_error = "emergency stop"
        logger.warning("emergency stop")
        self.stop_program("emergency stop")
        if not self.arm.protective_stopped:
            self.arm.stop(self.arm.params.protective_stop_decel_m_s2)

    def release_emergency_stop(self) -> None:
        self.emergency = False

    def _cycle(self, check_watchdog: bool = True) -> None:
        arm = self.arm
        if arm.protective_stopped and not self.protective:
            force = float(np.linalg.norm(arm.true_wrench()[:3]))
            self.trigger_protective_stop(f"force {force:.1f} N over the {self.params.protective_stop_n:g} N limit")
        elif not self.protective and not arm.at_rest() and not self._inside_reach():
            self.trigger_protective_stop("the arm reached the end of its reach")
        if check_watchdog and self.runtime_state == RUNTIME_PLAYING and self.watchdog is not None:
            register, frequency, armed_s = self.watchdog
            last_s = max(armed_s, self.last_write_s.get(register, -math.inf))
            if self.now_s - last_s > 1.0 / frequency:
                self.counts["watchdog"] += 1
                self.last_error = f"watchdog: {register} not written for {self.now_s - last_s:.3f} s"
                logger.warning(self.last_error)
                self.stop_program("RTDE watchdog")
        if self.runtime_state == RUNTIME_PLAYING and self.program is not None:
            try:
                self.program.cycle(self.inputs)
            except ScriptError as exc:
                self.last_error = f"runtime error: {exc}"
                logger.error(self.last_error)
                self.stop_program("runtime error")
            else:
                if self.program is not None and self.program.finished:
                    self.stop_program("the script ended")
        arm.step()
        self.cycles += 1
        if self.emergency and self.robot_mode != ROBOT_MODE_POWER_OFF and arm.at_rest():
            self.robot_mode = ROBOT_MODE_POWER_OFF
        force = float(np.linalg.norm(arm.true_wrench()[:3]))
        if force > self.peak_force_n:
            self.peak_force_n = force

    def _safe_cycle(self, check_watchdog: bool = True) -> None:
        """One cycle; a bug in the twin stops the program (clients see False) instead of killing the controller,
        which would leave a connected control client waiting 300 s."""
        cycles = self.cycles
        try:
            self._cycle(check_watchdog)
        except Exception as exc:
            self.last_error = f"controller twin internal error: {type(exc).__name__}: {exc}"
            logger.exception("controller twin cycle failed")
            self.cycles = cycles + 1  # the period passed all the same
            with contextlib.suppress(Exception):
                self.stop_program("internal error")

    def _inside_reach(self) -> bool:
        pad = self.arm.true_tcp_pose()
        distance = self._flange_distance_m(pad)
        if distance <= self.params.reach_m:
            return True
        flange_velocity = self.arm.speed()[:3]  # moving outward is what the joints cannot do
        shoulder = np.array([0.0, 0.0, self.params.shoulder_height_m])
        return float(np.dot(flange_velocity, pad[:3] - shoulder)) <= 0.0

    # ---- outputs --------------------------------------------------------------------------------------------

    def safety_bits(self) -> int:
        if self.emergency:
            return BIT_ROBOT_EMERGENCY | rtde.SAFETY_BIT_EMERGENCY_STOP | BIT_STOPPED_BY_SAFETY
        if self.protective:
            return rtde.SAFETY_BIT_PROTECTIVE_STOP | BIT_STOPPED_BY_SAFETY
        return rtde.SAFETY_BIT_NORMAL_MODE

    def robot_status_bits(self) -> int:
        bits = STATUS_POWER_ON if self.robot_mode != ROBOT_MODE_POWER_OFF else 0
        return bits | (STATUS_PROGRAM_RUNNING if self.runtime_state == RUNTIME_PLAYING else 0)

    def _output_values(self) -> dict[str, Any]:
        arm = self.arm
        pose = tuple(float(v) for v in arm.reported_pose())
        force = tuple(float(v) for v in arm.measured_wrench())
        speed = tuple(float(v) for v in arm.speed())
        safety_mode = self.safety_mode()
        known: dict[str, Any] = {
            "timestamp": self.now_s,
            "actual_TCP_pose": pose,
            "target_TCP_pose": pose,
            "actual_TCP_force": force,
            "ft_raw_wrench": force,
            "actual_TCP_speed": speed,
            "target_TCP_speed": speed,
            "robot_mode": self.robot_mode,
            "safety_mode": safety_mode,
            "safety_status": safety_mode,
            "safety_status_bits": self.safety_bits(),
            "robot_status_bits": self.robot_status_bits(),
            "runtime_state": self.runtime_state,
            "speed_scaling": 1.0,
            "target_speed_fraction": 1.0,
            "payload": self.payload_kg,
            "payload_cog": self.payload_cog_m,
        }
        known.update(zip(_OUTPUT_INT_NAMES, self.outputs.ints, strict=True))
        known.update(zip(_OUTPUT_DOUBLE_NAMES, self.outputs.doubles, strict=True))
        return known

    def _publish(self) -> None:
        now = time.monotonic()
        known: dict[str, Any] | None = None
        for connection in list(self.connections):
            session = connection.session
            if session is None or not session.take_due(now):
                continue
            if connection.outbox and len(connection.outbox) > _MAX_PENDING_BYTES:
                continue  # the client stopped reading: skip its data until it catches up
            if known is None:
                known = self._output_values()
            self._send(connection, session.data_package(known))
        self._truth_block.write(self.truth())

    def truth(self) -> TwinTruth:
        arm = self.arm
        wrench = arm.true_wrench()
        return TwinTruth(
            controller_t_s=self.now_s,
            cycles=self.cycles,
            pad_pose=arm.true_tcp_pose(),
            tcp_pose=arm.reported_pose(),
            true_wrench=wrench,
            reported_wrench=arm.measured_wrench(),
            tcp_speed=arm.speed(),
            force_n=float(np.linalg.norm(wrench[:3])),
            peak_force_n=self.peak_force_n,
            robot_mode=self.robot_mode,
            safety_mode=self.safety_mode(),
            safety_status_bits=self.safety_bits(),
            robot_status_bits=self.robot_status_bits(),
            runtime_state=self.runtime_state,
            program_running=self.runtime_state == RUNTIME_PLAYING,
            watchdog_armed=self.watchdog is not None,
            watchdog_trips=self.counts["watchdog"],
            protective_stops=self.counts["protective"],
            emergency_stops=self.counts["emergency"],
            program_starts=self.counts["starts"],
            script_uploads=self.counts["uploads"],
            rtde_clients=sum(1 for c in self.connections if c.kind == "rtde"),
            last_input_t_s=self.last_input_s,
            worst_lateness_s=self.worst_lateness_s,
            late_cycles=self.late_cycles,
            skipped_cycles=self.skipped_cycles,
            achieved_rate_hz=self.achieved_rate_hz,
            commands_done=0 if self.program is None else self.program.commands_done,
        )

    # ---- RTDE -----------------------------------------------------------------------------------------------

    def _rtde_bytes(self, connection: _Connection, data: bytes) -> None:
        assert connection.parser is not None and connection.session is not None
        try:
            for package in connection.parser.feed(data):
                if package.type == PackageType.DATA_PACKAGE:
                    values = connection.session.input_values(package.payload)
                    if values:
                        self.inputs.update(values)
                        for name in values:
                            self.last_write_s[name] = self.now_s
                        self.last_input_s = self.now_s
                    continue
                reply = connection.session.handle(package)
                if reply:
                    self._send(connection, reply)
        except rtde.ProtocolError as exc:
            self._drop(connection, f"bad package: {exc}")

    # ---- hooks ----------------------------------------------------------------------------------------------

    def _hook_bytes(self, data: bytes) -> None:
        self._hook_buffer += data
        while b"\n" in self._hook_buffer:
            raw, _, rest = bytes(self._hook_buffer).partition(b"\n")
            self._hook_buffer = bytearray(rest)
            try:
                reply = self.hook(json.loads(raw))
            except Exception as exc:  # a bad hook must not kill the controller
                logger.exception("controller twin hook failed")
                reply = {"ok": False, "error": f"{type(exc).__name__}: {exc}"}
            sys.stdout.write(json.dumps(reply) + "\n")
            sys.stdout.flush()

    def hook(self, request: dict[str, Any]) -> dict[str, Any]:
        """Test hooks and queries (see :class:`unitac_rig.sim.twin.ControllerTwin`)."""
        op = request.get("op")
        if op == "reset_peak":
            self.peak_force_n = float(np.linalg.norm(self.arm.true_wrench()[:3]))
        elif op == "reset_timing":
            self.worst_lateness_s, self.late_cycles, self.skipped_cycles = 0.0, 0, 0
        elif op == "unlock_protective_stop":
            return {"ok": True, "reply": self.unlock_protective_stop()}
        elif op == "power_on":
            return {"ok": True, "reply": "Brake releasing" if self.power_on() and self.brake_release() else "Failed"}
        elif op == "emergency_stop":
            self.emergency_stop()
        elif op == "release_emergency_stop":
            self.release_emergency_stop()
        elif op == "protective_stop":
            self.trigger_protective_stop(str(request.get("why", "test hook")))
        elif op == "placement_error":
            spec = self.world.spec
            if spec is None:
                return {"ok": False, "error": "the twin has no scene"}
            dx, dy = (float(v) for v in request["error_m"])
            self.world.rebuild(dataclasses.replace(spec, placement_error_m=(dx, dy)))
            if self.world.disc is not None:  # the disc follows the object
                self.world.set_disc_pad(self.world.disc.pad_radius_m * 1000.0)
        elif op == "disc_pad":
            radius = request.get("radius_mm")
            self.world.set_disc_pad(None if radius is None else float(radius))
        elif op == "contact_scale":
            self.world.force_scale = float(request["scale"])
        elif op == "ft_sign":
            self.arm.set_ft_sign(float(request["sign"]))
        elif op == "remote_control":
            self.remote_control = bool(request["on"])
        elif op == "pendant_tcp":
            self.arm.active_tcp = np.asarray(request["pose"], dtype=np.float64)
        elif op == "status":
            return {
                "ok": True,
                "program_state": self.program_state(),
                "scheduling": self.scheduling,
                "contact_tables_built_ahead": self.world.warm_builds,
                "last_error": self.last_error,
                "active_tcp": [float(v) for v in self.arm.active_tcp],
                "payload_kg": self.payload_kg,
                "payload_cog_m": list(self.payload_cog_m),
                "motion_threads": [] if self.program is None else list(self.program.motion_threads),
                "inputs": {k: v for k, v in self.inputs.items() if not isinstance(v, tuple)},
            }
        else:
            return {"ok": False, "error": f"unknown hook {op!r}"}
        self._truth_block.write(self.truth())
        return {"ok": True}

    # ---- the loop -------------------------------------------------------------------------------------------

    def run(self) -> None:
        """Serve and cycle until the hooks pipe (stdin) closes."""
        if self._hooks_in is not None:
            self.selector.register(self._hooks_in, selectors.EVENT_READ, "hooks")
        self._truth_block.write(self.truth())
        due = time.monotonic()
        try:
            while not self._stop:
                timeout = min(_IDLE_SELECT_S, max(0.0, due - time.monotonic()))
                for key, _ in self.selector.select(timeout):
                    self._on_event(key)
                    if self._stop:
                        return
                now = time.monotonic()
                if now < due:
                    continue
                lateness = now - due
                if lateness > self.worst_lateness_s:
                    self.worst_lateness_s = lateness
                owed = 1 + int(lateness / PERIOD_S)
                if owed > 1:
                    self.late_cycles += 1
                if owed > self.params.max_catch_up_cycles:
                    self.skipped_cycles += owed - self.params.max_catch_up_cycles
                    owed = self.params.max_catch_up_cycles
                    due = now - PERIOD_S * (owed - 1)
                # Catching up, the host's writes of the missed periods still wait in the sockets: a real controller
                # would have read them on time, so the watchdog is judged on the next on-time cycle, after they are
                # served. Otherwise a twin descheduled for one watchdog window trips it on a live host.
                for _ in range(owed):
                    self._safe_cycle(check_watchdog=owed == 1)
                due += owed * PERIOD_S
                self._publish()
                self._measure_rate(now)
        finally:
            for connection in list(self.connections):
                self._drop(connection, "controller shutting down")
            self.close_listeners()
            self.selector.close()

    def _on_event(self, key: selectors.SelectorKey) -> None:
        if key.data == "hooks":
            data = os.read(self._hooks_in, 65536) if self._hooks_in is not None else b""
            if not data:
                self._stop = True
                return
            self._hook_bytes(data)
        elif isinstance(key.data, str):
            self._accept(key.fileobj, key.data)  # type: ignore[arg-type]
        else:
            connection: _Connection = key.data
            self._read(connection)
            if connection in self.connections:
                self._flush(connection)

    def _measure_rate(self, now: float) -> None:
        started, cycles = self._rate_window
        if now - started >= 1.0:
            self.achieved_rate_hz = (self.cycles - cycles) / (now - started)
            self._rate_window = (now, self.cycles)
