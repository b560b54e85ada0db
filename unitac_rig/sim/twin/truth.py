"""The controller twin's ground truth: a sequence-locked block of shared memory the controller writes every cycle.

Tests, benchmarks and the twin's own sensors read it without a round trip to the controller process (the sensors
need the pad pose up to 1000 times a second). Two slots, written in turn: snapshot g goes to slot g % 2 with its
sequence number set to 2g - 1 (odd) while the body is written and to 2g (even) after. A reader takes the slot with the
highest even number that did not change while it read, so a torn snapshot is never returned, and a writer descheduled
in the middle of a write (seen on a loaded 2-core box: half a second) leaves the previous snapshot readable.
"""

from __future__ import annotations

import mmap
import struct
import time
from dataclasses import dataclass

import numpy as np

_SEQ = struct.Struct("<Q")
# controller time, cycles, pad pose, reported TCP pose, true wrench, reported wrench, TCP speed, |F| true, |F| peak,
# robot mode, safety mode, safety bits, robot status bits, runtime state, program running, watchdog armed,
# watchdog trips, protective stops, emergency stops, program starts, script uploads, RTDE clients,
# last input write (controller s), worst lateness (s), late cycles, skipped cycles, achieved rate (Hz),
# commands completed by the script
_BODY = struct.Struct("<dQ6d6d6d6d6ddd iiIII BB IIIIII d d QQ d Q")
_SLOT = _SEQ.size + _BODY.size
_SIZE = 2 * _SLOT
_POSE = struct.Struct("<6d")
_POSE_AT = _SEQ.size + 16  # the pad pose within a slot: after controller time (d) and cycles (Q)


@dataclass(frozen=True)
class TwinTruth:
    """One snapshot of what really happens in the controller twin (SI units, base frame)."""

    controller_t_s: float
    cycles: int
    pad_pose: np.ndarray  # (6,) the physical tool (pad centre): what the scene and the sensors feel
    tcp_pose: np.ndarray  # (6,) the active TCP's pose, as RTDE reports it
    true_wrench: np.ndarray  # (6,) the object's wrench on the tool, no sensor effects
    reported_wrench: np.ndarray  # (6,) what actual_TCP_force reports (latency, bias, noise, filter, zero)
    tcp_speed: np.ndarray  # (6,)
    force_n: float  # |true contact force|
    peak_force_n: float  # highest |true contact force| since the last reset_peak
    robot_mode: int
    safety_mode: int
    safety_status_bits: int
    robot_status_bits: int
    runtime_state: int
    program_running: bool
    watchdog_armed: bool
    watchdog_trips: int
    protective_stops: int
    emergency_stops: int
    program_starts: int
    script_uploads: int
    rtde_clients: int
    last_input_t_s: float  # controller time of the last RTDE input write (any recipe)
    worst_lateness_s: float  # the latest a cycle started after its due time
    late_cycles: int  # cycles that started more than one period late
    skipped_cycles: int  # periods dropped because catching up would have taken too many cycles
    achieved_rate_hz: float  # cycles per second over the last second of wall time
    commands_done: int  # non-realtime commands the script completed (signalled done)

    @property
    def at_rest(self) -> bool:
        return bool(np.all(np.abs(self.tcp_speed) < 1e-9))

    @property
    def speed_m_s(self) -> float:
        return float(np.linalg.norm(self.tcp_speed[:3]))


def _pack(truth: TwinTruth) -> tuple[float | int | bool, ...]:
    return (
        truth.controller_t_s, truth.cycles, *truth.pad_pose, *truth.tcp_pose, *truth.true_wrench,
        *truth.reported_wrench, *truth.tcp_speed, truth.force_n, truth.peak_force_n, truth.robot_mode,
        truth.safety_mode, truth.safety_status_bits, truth.robot_status_bits, truth.runtime_state,
        truth.program_running, truth.watchdog_armed, truth.watchdog_trips, truth.protective_stops,
        truth.emergency_stops, truth.program_starts, truth.script_uploads, truth.rtde_clients, truth.last_input_t_s,
        truth.worst_lateness_s, truth.late_cycles, truth.skipped_cycles, truth.achieved_rate_hz, truth.commands_done,
    )  # fmt: skip


def _unpack(fields: tuple[float | int, ...]) -> TwinTruth:
    f = fields
    return TwinTruth(
        float(f[0]), int(f[1]), np.array(f[2:8]), np.array(f[8:14]), np.array(f[14:20]), np.array(f[20:26]),
        np.array(f[26:32]), float(f[32]), float(f[33]), int(f[34]), int(f[35]), int(f[36]), int(f[37]), int(f[38]),
        bool(f[39]), bool(f[40]), int(f[41]), int(f[42]), int(f[43]), int(f[44]), int(f[45]), int(f[46]),
        float(f[47]), float(f[48]), int(f[49]), int(f[50]), float(f[51]), int(f[52]),
    )  # fmt: skip


class TruthBlock:
    """The shared block, mapped from a file descriptor both processes hold (create it with :meth:`size`)."""

    size = _SIZE

    def __init__(self, fd: int) -> None:
        self._map = mmap.mmap(fd, _SIZE)
        self._generation = max(self._slot_seq(0), self._slot_seq(1)) // 2  # the writer's count so far

    def close(self) -> None:
        self._map.close()

    def _slot_seq(self, slot: int) -> int:
        (seq,) = _SEQ.unpack_from(self._map, slot * _SLOT)
        return int(seq)

    def write(self, truth: TwinTruth) -> None:
        self._generation += 1
        at = (self._generation % 2) * _SLOT
        _SEQ.pack_into(self._map, at, 2 * self._generation - 1)
        _BODY.pack_into(self._map, at + _SEQ.size, *_pack(truth))
        _SEQ.pack_into(self._map, at, 2 * self._generation)

    def _latest(self, fmt: struct.Struct, offset: int, timeout_s: float) -> tuple[float | int, ...] | None:
        """The raw fields ``fmt`` reads at ``offset`` within the slot of the newest complete snapshot; None before
        the first write, or when no slot holds a complete snapshot for ``timeout_s`` (the writer died in its first
        write). Only raw tuples are read here, so the caller builds one result, not one per slot."""
        deadline = time.monotonic() + timeout_s
        while True:
            best: tuple[int, tuple[float | int, ...]] | None = None
            for slot in (0, 1):
                at = slot * _SLOT
                before = self._slot_seq(slot)
                fields = fmt.unpack_from(self._map, at + offset)
                after = self._slot_seq(slot)
                if before == after and before % 2 == 0 and before > 0 and (best is None or before > best[0]):
                    best = (before, fields)
            if best is not None:
                return best[1]
            if self._slot_seq(0) == 0 and self._slot_seq(1) == 0:
                return None  # nothing written yet
            if time.monotonic() > deadline:
                return None
            time.sleep(0)

    def read(self, timeout_s: float = 0.5) -> TwinTruth | None:
        """The latest complete snapshot; None before the first write."""
        fields = self._latest(_BODY, _SEQ.size, timeout_s)
        return None if fields is None else _unpack(fields)

    def read_pad_pose(self, timeout_s: float = 0.5) -> np.ndarray | None:
        """Just the physical tool's pose (what the sensors sample), without building a whole snapshot; None before
        the first write."""
        fields = self._latest(_POSE, _POSE_AT, timeout_s)
        return None if fields is None else np.array(fields)
