"""Seeded, deterministic transport faults for the simulated devices.

Every simulated transport (virtual CAN controller, SLCAN adapter, PapillArray hub port, xela_server WebSocket) runs
its outgoing messages through one :class:`FaultInjector`, so tests can show that the drivers keep decoding the intact
data and count what they lost. A :class:`FaultPlan` says what goes wrong:

* ``split_max_bytes``: byte streams (serial ports) hand the host random chunks of 1..N bytes per read;
* ``drop_message_prob`` / ``drop_byte_prob``: whole messages (CAN frames, packets, WebSocket messages) or single
  bytes disappear;
* ``corrupt_prob``: a message gets one random bit flipped (on CAN this models a bad adapter, real CAN has a CRC);
* ``garbage_prob``: random bytes (1..16) are sent in front of a message (line noise, a half-sent packet);
* ``delay_s``: every message reaches the host this much later (device-clock seconds);
* ``stall_windows_s`` / ``disconnect_windows_s``: ``(start, duration)`` windows in seconds since the device started
  sending, during which nothing is sent, or the port / bus / socket is gone (reconnect possible afterwards).

Tests can also flip a stall or disconnect on and off by hand with :meth:`FaultInjector.force_stall` and
:meth:`FaultInjector.force_disconnect`. The random choices come from ``random.Random(seed)``, so one seed and one
call sequence give one outcome.
"""

from __future__ import annotations

import random
import threading
from dataclasses import dataclass, field


@dataclass(frozen=True)
class FaultPlan:
    """What a simulated transport does wrong; probabilities are per message (or per byte for ``drop_byte_prob``)."""

    seed: int = 0
    split_max_bytes: int | None = None
    drop_message_prob: float = 0.0
    drop_byte_prob: float = 0.0
    corrupt_prob: float = 0.0
    garbage_prob: float = 0.0
    delay_s: float = 0.0
    stall_windows_s: tuple[tuple[float, float], ...] = ()
    disconnect_windows_s: tuple[tuple[float, float], ...] = ()

    def __post_init__(self) -> None:
        for name in ("drop_message_prob", "drop_byte_prob", "corrupt_prob", "garbage_prob"):
            value = getattr(self, name)
            if not 0.0 <= value <= 1.0:
                raise ValueError(f"{name} must be within 0..1, got {value}")
        if self.split_max_bytes is not None and self.split_max_bytes < 1:
            raise ValueError("split_max_bytes must be at least 1")
        if self.delay_s < 0:
            raise ValueError("delay_s cannot be negative")


NO_FAULTS = FaultPlan()


@dataclass
class FaultCounts:
    """What the injector did so far (tests compare these with the driver's health counters)."""

    messages_seen: int = 0
    messages_dropped: int = 0
    messages_corrupted: int = 0
    bytes_dropped: int = 0
    garbage_bytes: int = 0
    messages_stalled: int = 0
    messages_disconnected: int = 0
    corrupted_indices: list[int] = field(default_factory=list)
    dropped_indices: list[int] = field(default_factory=list)


class FaultInjector:
    """Applies a :class:`FaultPlan` to one transport's outgoing messages. Thread-safe."""

    def __init__(self, plan: FaultPlan | None = None) -> None:
        self.plan = plan or NO_FAULTS
        self.counts = FaultCounts()
        self._rng = random.Random(self.plan.seed)
        self._lock = threading.Lock()
        self._origin_ns: int | None = None
        self._forced_stall = False
        self._forced_disconnect = False
        p = self.plan
        # False when no message is ever changed or dropped (mangle would hand every message back as it came)
        self.damages_messages = bool(p.drop_message_prob or p.drop_byte_prob or p.corrupt_prob or p.garbage_prob)

    # ---- time windows -----------------------------------------------------------------------------------------
    def start(self, t_ns: int) -> None:
        """Mark when the device started sending (the origin of the plan's windows). Only the first call counts."""
        with self._lock:
            if self._origin_ns is None:
                self._origin_ns = t_ns

    def _in_window(self, windows: tuple[tuple[float, float], ...], t_ns: int) -> bool:
        if self._origin_ns is None or not windows:
            return False
        t_s = (t_ns - self._origin_ns) / 1e9
        return any(start <= t_s < start + duration for start, duration in windows)

    def is_stalled(self, t_ns: int) -> bool:
        """True while the device must send nothing (forced, or inside a stall window)."""
        return self._forced_stall or self._in_window(self.plan.stall_windows_s, t_ns)

    def is_disconnected(self, t_ns: int) -> bool:
        """True while the port / bus / socket is gone (forced, or inside a disconnect window)."""
        return self._forced_disconnect or self._in_window(self.plan.disconnect_windows_s, t_ns)

    def force_stall(self, stalled: bool = True) -> None:
        self._forced_stall = stalled

    def force_disconnect(self, disconnected: bool = True) -> None:
        self._forced_disconnect = disconnected

    def release_t_ns(self, t_ns: int) -> int:
        """When a message produced at ``t_ns`` reaches the host (ns, device clock)."""
        return t_ns + round(self.plan.delay_s * 1e9)

    # ---- per-message damage -----------------------------------------------------------------------------------
    def mangle(self, message: bytes) -> bytes | None:
        """Return the bytes that really go out for ``message`` (None when the whole message is dropped)."""
        plan = self.plan
        with self._lock:
            index = self.counts.messages_seen
            self.counts.messages_seen += 1
            if plan.drop_message_prob and self._rng.random() < plan.drop_message_prob:
                self.counts.messages_dropped += 1
                self.counts.dropped_indices.append(index)
                return None
            data = bytearray(message)
            if plan.corrupt_prob and data and self._rng.random() < plan.corrupt_prob:
                bit = self._rng.randrange(len(data) * 8)
                data[bit // 8] ^= 1 << (bit % 8)
                self.counts.messages_corrupted += 1
                self.counts.corrupted_indices.append(index)
            if plan.drop_byte_prob and data:
                kept = bytearray(b for b in data if self._rng.random() >= plan.drop_byte_prob)
                self.counts.bytes_dropped += len(data) - len(kept)
                data = kept
            if plan.garbage_prob and self._rng.random() < plan.garbage_prob:
                garbage = bytes(self._rng.randrange(256) for _ in range(self._rng.randint(1, 16)))
                self.counts.garbage_bytes += len(garbage)
                data = bytearray(garbage) + data
            return bytes(data)

    def pass_messages(self, n: int) -> None:
        """Count ``n`` messages sent as they are: :meth:`mangle`'s bookkeeping, for a plan that damages none."""
        with self._lock:
            self.counts.messages_seen += n

    def chunk_size(self, available: int) -> int:
        """How many of ``available`` bytes one host read may take (random when splitting is planned)."""
        if available <= 0:
            return 0
        if self.plan.split_max_bytes is None:
            return available
        with self._lock:
            return min(available, self._rng.randint(1, self.plan.split_max_bytes))

    def note_stalled(self) -> None:
        with self._lock:
            self.counts.messages_stalled += 1

    def note_disconnected(self) -> None:
        with self._lock:
            self.counts.messages_disconnected += 1
