"""The controller twin's ground truth: a sequence-locked block of shared memory the controller writes every cycle.

Tests, benchmarks and the twin's own sensors read it without a round trip to the controller process (the sensors
need the pad pose up to 1000 times a second). Two slots, written in turn: snapshot g goes to slot g % 2 with its
sequence number set to 2g - 1 (odd) while the body is written and to 2g (even) after. A reader takes the slot with the
highest even number that did not change while it read, so a torn snapshot is never returned, and a writer descheduled
in the middle of a write (seen on a loaded 2-core box: half a second) leaves the previous snapshot readable.
"""

from __future__ import annotations

import dataclasses
import mmap
import struct
import time
from dataclasses import dataclass

import numpy as np

_SEQ = struct.Struct("<Q")


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


# The body of a slot: the fields of TwinTruth in order, an array as its 6 numbers.
_FORMATS = {"float": "d", "int": "q", "bool": "?", "np.ndarray": "6d"}
_FIELDS = tuple((f.name, str(f.type)) for f in dataclasses.fields(TwinTruth))
_BODY = struct.Struct("<" + "".join(_FORMATS[kind] for _, kind in _FIELDS))
_SLOT = _SEQ.size + _BODY.size
_SIZE = 2 * _SLOT
_POSE = struct.Struct("<6d")
_POSE_AT = _SEQ.size + struct.calcsize("<dq")  # the pad pose within a slot: after controller time and cycles
assert _FIELDS[:3] == (("controller_t_s", "float"), ("cycles", "int"), ("pad_pose", "np.ndarray"))


def _pack(truth: TwinTruth) -> list[float | int | bool]:
    values: list[float | int | bool] = []
    for name, kind in _FIELDS:
        value = getattr(truth, name)
        if kind == "np.ndarray":
            values.extend(float(v) for v in value)
        else:
            values.append(value)
    return values


def _unpack(values: tuple[float | int, ...]) -> TwinTruth:
    cast = {"float": float, "int": int, "bool": bool}
    read: dict[str, object] = {}
    at = 0
    for name, kind in _FIELDS:
        if kind == "np.ndarray":
            read[name], at = np.array(values[at : at + 6]), at + 6
        else:
            read[name], at = cast[kind](values[at]), at + 1
    return TwinTruth(**read)  # type: ignore[arg-type]


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
