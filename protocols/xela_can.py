"""XELA uSkin raw CAN wire format (old/2019 "version 1" firmware): stream commands, taxel messages, frame assembly.

Wire format (1 Mbit/s CAN, standard 11-bit arbitration ids, classic frames of up to 8 data bytes):

* Host -> controller stream command on arbitration id ``0x200 | controller_id`` (controller id 0..15, so the first
  board is 0x201): payload ``07 00`` starts streaming, ``07 01`` stops it. One vendor demo sends a single ``07`` to
  start; the decoder accepts that too.
* Controller -> host: **one CAN message per taxel**. Payload byte 0 is not used by any known host (meaning unknown);
  bytes 1-2 = X, 3-4 = Y, 5-6 = Z, each an unsigned 16-bit count, most significant byte first (big-endian).
  Byte 7, when present, is unused.
* Validity: a message whose X most significant byte (payload byte 1) is >= 0xFA is a "no data" sentinel (the vendor
  manual shows ``FA00,FA00,FA00`` placeholders); a message whose three axes are all 0 means "data unavailable".
  Either way the taxel is flagged, never used as a reading.
* Taxel ids: ``0x1RC`` with R = row 0..3 and C = column (chip) 0..3 on the 4x4 uSPa44 and 0..5 on the 4x6 uSPa46.
  XELA's own map file numbers the 4x6 taxels in *reverse*: s1 = 0x135, s2 = 0x134 ... s6 = 0x130, s7 = 0x125 ...
  s24 = 0x100, and xela_server lists taxels "from top left, line by line": so on the uSPa46 taxel 0 (top left) is
  s1 = 0x135 and taxel 23 is 0x100, the same frame through CAN as through xela_server (:data:`USPA46_ID_MAP`). No
  source states the order in which a controller sends a cycle's messages, so the assembler does not assume one.
  Other firmware uses other ids (one used 0x710 + taxel index), so id maps are plain data (:class:`TaxelIdMap`).
  This project's taxel index is row-major, ``index = row * cols + col`` (drivers/layouts.py).
* There is **no frame counter** on the wire: :class:`FrameAssembler` decides which messages make a frame, and
  flags every frame that nothing proves to hold one controller cycle.

Sources: XELA-Robotics/CAN-USB README and sensor-server/server.py, ROS/4x6.ini (reverse numbering), the XELA ROS
manual v0.0.9b and manual v1.4.0 (sentinel example), the AIST o2as_xela_sensor driver and demo (0xFA rule, 1-byte
start), aturganbayev/tactile_UR5 (``cansend can0 203#07.00``), as summarised in the project's hardware facts
(section 1.2). Pure codec: no I/O, threads or clocks; callers pass timestamps in.
"""

from __future__ import annotations

import math
import struct
from collections import deque
from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np

from protocols.errors import ProtocolError

START_STREAM_PAYLOAD = b"\x07\x00"
STOP_STREAM_PAYLOAD = b"\x07\x01"
START_STREAM_PAYLOAD_SHORT = b"\x07"  # the 1-byte start variant one vendor demo sends
COMMAND_BASE_ID = 0x200
MAX_CONTROLLER_ID = 15
MAX_STANDARD_ID = 0x7FF
MAX_COUNT = 0xFFFF  # counts are unsigned 16-bit
INVALID_X_MSB = 0xFA  # payload byte 1 (X MSB) at or above this marks a "no data" sentinel
MIN_TAXEL_PAYLOAD_LEN = 7  # byte 0 + three big-endian uint16 axes
# Learning where a cycle starts: one gap this many times any other in each of this many windows of one cycle's worth
# of messages in a row. A burst of 24 messages at 1 Mbit/s takes ~3 ms; at 100 frames/s the pause before the next
# burst is ~7 ms, ~60x the ~0.11 ms between messages. Lost messages leave gaps too (k lost in a row: k + 1 times the
# usual gap), so a pause must be 8 times every other gap: faking one takes 7 messages lost in a row (at 10 % loss,
# 1 in 10 million; at 3x, 2 lost in a row taught a host that reads bursts back to back a "pause" inside a cycle).
BURST_GAP_RATIO = 8
LEARN_CYCLES = 3
SHORT_PAUSE_CLOSES = 3  # frames in a row cut by a pause alone with under half the taxels: pauses mark no cycle
ORDER_LEARN_FRAMES = 3  # proven whole cycles in a row in one order make it the learned send order
FORGET_AFTER_FRAMES = 20  # frames in a row with none valid forget the learned order (at 2 % loss: p ~ 4e-9)

_AXES = struct.Struct(">HHH")  # X, Y, Z counts at payload offset 1


def _pause_around(gap_ns: int | None, max_inner_gap_ns: int) -> bool:
    """True when a gap next to a frame is a pause by that frame's own timing: longer than nothing, and
    :data:`BURST_GAP_RATIO` times every gap inside it. A frame that straddles a cycle boundary holds that boundary's
    pause inside, so the gaps next to it are no longer than the pause it holds."""
    return gap_ns is not None and gap_ns > 0 and gap_ns >= BURST_GAP_RATIO * max_inner_gap_ns


def command_arbitration_id(controller_id: int) -> int:
    """CAN id of the host -> controller stream command: ``0x200 | controller_id`` (id 0..15)."""
    if isinstance(controller_id, bool) or not isinstance(controller_id, int):
        raise ProtocolError(f"controller id must be an int, got {controller_id!r}", hint="use 0..15")
    if not 0 <= controller_id <= MAX_CONTROLLER_ID:
        raise ProtocolError(
            f"controller id {controller_id} out of range 0..{MAX_CONTROLLER_ID}",
            hint="use the 'id' from xServ.ini or the low nibble candump shows",
        )
    return COMMAND_BASE_ID | controller_id


def encode_stream_command(controller_id: int, start: bool) -> tuple[int, bytes]:
    """(arbitration id, payload) that starts (``07 00``) or stops (``07 01``) streaming on one controller."""
    return command_arbitration_id(controller_id), (START_STREAM_PAYLOAD if start else STOP_STREAM_PAYLOAD)


def decode_stream_command(arbitration_id: int, data: bytes) -> tuple[int, bool] | None:
    """(controller id, start?) if this CAN message is a stream command, else None.

    Accepts ``07 00`` (start), ``07 01`` (stop) and the 1-byte ``07`` start variant; zero padding after the two
    command bytes is tolerated (some adapters pad to 8 bytes).
    """
    if arbitration_id & ~MAX_CONTROLLER_ID != COMMAND_BASE_ID:
        return None
    controller_id = arbitration_id & MAX_CONTROLLER_ID
    payload = bytes(data)
    if payload == START_STREAM_PAYLOAD_SHORT:
        return controller_id, True
    if len(payload) < 2 or payload[0] != 0x07 or any(payload[2:]):
        return None
    if payload[1] == 0x00:
        return controller_id, True
    if payload[1] == 0x01:
        return controller_id, False
    return None


@dataclass(frozen=True)
class TaxelIdMap:
    """Which CAN arbitration id carries which taxel, in layout order (``index = row * cols + col``).

    ``ids[i]`` is the arbitration id of taxel ``i``. Firmware differs in its ids, so maps are data: give the ids in
    layout order (XELA's map file lists s1, s2, ... in that order, see the module docstring) or use
    :meth:`from_row_col_ids`.
    """

    ids: tuple[int, ...]
    name: str = field(default="", compare=False)
    _index: dict[int, int] = field(init=False, repr=False, compare=False, hash=False)

    def __post_init__(self) -> None:
        ids = tuple(self.ids)
        if not ids:
            raise ProtocolError("a taxel id map needs at least one id", hint="list one CAN id per taxel")
        for arbitration_id in ids:
            if isinstance(arbitration_id, bool) or not isinstance(arbitration_id, int):
                raise ProtocolError(f"taxel id {arbitration_id!r} is not an int", hint="use 11-bit CAN ids")
            if not 0 <= arbitration_id <= MAX_STANDARD_ID:
                raise ProtocolError(
                    f"taxel id 0x{arbitration_id:X} is not a standard 11-bit CAN id", hint="use 0x000..0x7FF"
                )
        duplicates = sorted({i for i in ids if ids.count(i) > 1})
        if duplicates:
            listed = ", ".join(f"0x{i:03X}" for i in duplicates)
            raise ProtocolError(f"taxel id map repeats ids {listed}", hint="each taxel needs its own CAN id")
        object.__setattr__(self, "ids", ids)
        object.__setattr__(self, "_index", {arbitration_id: i for i, arbitration_id in enumerate(ids)})

    @property
    def n_taxels(self) -> int:
        return len(self.ids)

    def index_of(self, arbitration_id: int) -> int | None:
        """Taxel index (layout order) carried by this CAN id, or None if the id is not a taxel of this map."""
        return self._index.get(arbitration_id)

    @classmethod
    def from_row_col_ids(cls, rows: int, cols: int, base: int = 0x100, name: str = "") -> TaxelIdMap:
        """The ``base + 0x10 * row + col`` scheme (0x1RC) of the uSPa44/uSPa46 boards."""
        if not (1 <= rows <= 16 and 1 <= cols <= 16):
            raise ProtocolError(f"grid {rows}x{cols} does not fit the 0x1RC id scheme", hint="rows, cols 1..16")
        return cls(tuple(base + 0x10 * row + col for row in range(rows) for col in range(cols)), name=name)


# uSPa46: XELA's 4x6 map, s1 = 0x135 first (0x1RC ids numbered in reverse); layout taxel 0 = s1 = 0x135.
USPA46_ID_MAP = TaxelIdMap(tuple(reversed(TaxelIdMap.from_row_col_ids(4, 6).ids)), "uSPa46 XELA map (s1 = 0x135 first)")
USPA44_ID_MAP = TaxelIdMap.from_row_col_ids(4, 4, name="uSPa44 0x1RC (4x4)")


def invalid_taxels(values: np.ndarray) -> np.ndarray:
    """(n_taxels,) bool: taxels whose (n_taxels, 3) counts are the "no data" sentinel (X >= 0xFA00) or all zero,
    the same rule as a CAN message; for frames that arrive whole (xela_server's ``data``)."""
    counts = np.asarray(values)
    return (counts[:, 0] >= INVALID_X_MSB << 8) | ~counts.any(axis=1)


@dataclass(frozen=True, slots=True)
class TaxelMessage:
    """One taxel's three raw counts from one CAN message; ``valid`` is False for the 0xFA sentinel or all-zero axes."""

    arbitration_id: int
    x: int
    y: int
    z: int
    valid: bool


def decode_taxel_message(arbitration_id: int, data: bytes) -> TaxelMessage:
    """Decode one taxel message (X, Y, Z big-endian uint16 at payload bytes 1-2, 3-4, 5-6).

    Raises ProtocolError when the payload is shorter than 7 bytes.
    """
    if len(data) < MIN_TAXEL_PAYLOAD_LEN:
        raise ProtocolError(
            f"taxel message 0x{arbitration_id:03X} has {len(data)} data bytes, needs at least {MIN_TAXEL_PAYLOAD_LEN}",
            hint="check the CAN bit rate (1 Mbit/s) and the sensor firmware version",
        )
    x, y, z = _AXES.unpack_from(data, 1)
    return TaxelMessage(arbitration_id, x, y, z, valid=_reading(data) is not None)


def _reading(data: bytes) -> tuple[int, int, int] | None:
    """X, Y, Z counts of a taxel payload; None when it is too short, the 0xFA sentinel or all zero (no reading)."""
    if len(data) < MIN_TAXEL_PAYLOAD_LEN or data[1] >= INVALID_X_MSB:
        return None
    counts: tuple[int, int, int] = _AXES.unpack_from(data, 1)
    return counts if any(counts) else None


def _clip_count(value: int, axis: str) -> int:
    if isinstance(value, bool) or not isinstance(value, int | np.integer):
        raise ProtocolError(f"{axis} count must be an int, got {value!r}", hint="round counts before encoding")
    return min(max(int(value), 0), MAX_COUNT)


def encode_taxel_message(arbitration_id: int, x: int, y: int, z: int, byte0: int = 0) -> bytes:
    """8-byte taxel payload; counts are clipped to 0..65535 like a saturating ADC.

    Note the wire's own rule: an X count >= 0xFA00 reads back as the invalid sentinel.
    ``arbitration_id`` is validated (11-bit) but not part of the payload; it travels in the CAN header.
    """
    if not 0 <= arbitration_id <= MAX_STANDARD_ID:
        raise ProtocolError(f"CAN id 0x{arbitration_id:X} is not 11-bit", hint="use 0x000..0x7FF")
    if not 0 <= byte0 <= 0xFF:
        raise ProtocolError(f"byte0 {byte0} does not fit in one byte", hint="use 0..255")
    return bytes((byte0,)) + _AXES.pack(_clip_count(x, "X"), _clip_count(y, "Y"), _clip_count(z, "Z")) + b"\x00"


def encode_invalid_taxel_message(byte0: int = 0) -> bytes:
    """8-byte "no data" payload ``FA00`` on every axis (the sentinel the vendor manual shows)."""
    sentinel = INVALID_X_MSB << 8
    return encode_taxel_message(0, sentinel, sentinel, sentinel, byte0=byte0)


@dataclass(frozen=True, slots=True)
class AssembledFrame:
    """One uSkin frame in layout order.

    ``values``: (n_taxels, 3) int64 raw counts; a flagged taxel holds its last good value (0 if never seen).
    ``t_ns``: caller's timestamp of the last message that went into the frame.
    ``one_cycle``: True only when every message of the frame provably came from one controller cycle (see
    :class:`FrameAssembler`); when False, no taxel can be trusted to belong to the frame's moment.
    ``stale_mask``: (n_taxels,) bool, True where the taxel was missing this cycle, sent the invalid sentinel, or its
    value is older than ``stale_after_ns``, and True everywhere when ``one_cycle`` is False. ``valid`` is True only
    when no taxel is flagged.
    """

    values: np.ndarray
    t_ns: int
    stale_mask: np.ndarray
    valid: bool
    one_cycle: bool = True


class _Snapshot(NamedTuple):
    """A closed frame's contents before its validity is decided."""

    values: np.ndarray
    t_ns: int
    flags: np.ndarray  # per taxel: missing, sentinel or too old
    arrival: tuple[int, ...]  # taxel indices in the order their messages came
    max_gap_ns: int  # longest gap between two of its messages


class FrameAssembler:
    """Turns the per-taxel CAN message stream into frames (there is no frame counter on the wire).

    A frame closes when every taxel has reported once since the previous frame, in whatever order they came, or
    early when a taxel reports a second time (its cycle lost a message) or a cycle mark (below) arrives; the taxels
    that did not report are flagged.

    **A frame is valid only when every taxel provably belongs to one cycle.** Completeness alone proves nothing: a
    cycle that lost its first message is completed by the next cycle's first message (23 taxels from cycle N, 1 from
    N + 1), and from then on every frame would straddle two cycles. What the wire and the receive times can prove is
    where a cycle *starts*; three marks do:

    * a **pause**: a controller that sends each cycle as a burst leaves one pause per cycle. A whole frame is
      bracketed by pauses by its own timing when the gaps before and after it are each :data:`BURST_GAP_RATIO`
      times every gap inside it (a frame straddling two cycles holds the pause between them). Once
      :data:`LEARN_CYCLES` windows of one cycle's worth of messages in a row each held one gap at least
      :data:`BURST_GAP_RATIO` times every other, a gap longer than the geometric mean of the pauses and the other
      gaps marks a cycle start. A lost message only lengthens the pause around it, so losses never switch this off;
      :data:`SHORT_PAUSE_CLOSES` frames in a row cut by a pause with under half the taxels (the messages became
      evenly spaced) do, and learning starts over.
    * a **learned send order**: once :data:`ORDER_LEARN_FRAMES` proven frames in a row came in the same order, a
      message whose place in that order is not after the previous message's closes the open frame. It closes frames
      only, it proves nothing: it was learned from receive times, and a host reading in offset bursts teaches a
      rotated order (6..23, 0..5) that would make every later frame of an evenly spaced backlog read mix two cycles.
      A frame is proven only by a pause the receive times show now, or by ``cycle_start_id``.
      :data:`FORGET_AFTER_FRAMES` frames in a row with none valid forget it.
    * ``cycle_start_id``: for firmware known to send a given id first.

    A complete frame is one cycle when a pause (or the first id) opened it and the message after it shows one too (a
    frame that began at a mark and holds every taxel with nothing marked inside could otherwise still end in the next
    cycle's first message); so without a learned order a frame comes out when the next message arrives, or at
    :meth:`flush` once the quiet after it is a pause. With a learned order a complete frame opened by a pause holds
    every place of the order once, in order, with no pause inside, so it comes out at once. Frames that cannot be
    proven (the first ones, before a pause is learned; every frame while the receive times show no pause, unless
    ``cycle_start_id`` is set) are flagged in every taxel and counted in ``unproven_frames``.

    What this cannot catch: a host whose receive times show the pause consistently in the wrong place, which no wire
    without a counter can reveal (it looks like a board sending in a rotated order); only ``cycle_start_id`` rules it
    out.

    Unknown ids are counted and ignored; payloads too short to decode or carrying the sentinel count as invalid
    reports and flag their taxel. ``stale_after_ns`` bounds how old a value in an emitted frame can be.
    """

    def __init__(
        self,
        id_map: TaxelIdMap = USPA46_ID_MAP,
        stale_after_ns: int = 250_000_000,
        cycle_start_id: int | None = None,
        *,
        learn_pauses: bool = True,
    ) -> None:
        if stale_after_ns <= 0:
            raise ProtocolError(f"stale_after_ns must be > 0, got {stale_after_ns}", hint="e.g. 250_000_000 (250 ms)")
        self.id_map = id_map
        self.stale_after_ns = stale_after_ns
        n = self._n = id_map.n_taxels
        self._index = id_map._index
        if cycle_start_id is not None and cycle_start_id not in self._index:
            raise ProtocolError(
                f"cycle_start_id 0x{cycle_start_id:X} is not a taxel id of the map", hint="use one of its ids, or None"
            )
        self._cycle_start_index = None if cycle_start_id is None else self._index[cycle_start_id]
        self._learn_pauses = learn_pauses
        self._prev_t_ns: int | None = None  # time of the previous known-id message
        self._prev_index: int | None = None  # its taxel
        self._window: list[int] = []  # gaps (ns) of the last < n messages
        self._pauses: deque[tuple[int, int]] = deque(maxlen=LEARN_CYCLES)  # (pause, next longest gap) per window
        self.pause_threshold_ns: int | None = None  # a gap this long starts a cycle (learned; None: not known)
        self._short_pause_closes = 0  # frames in a row cut by a pause alone with under half the taxels
        self.send_order: tuple[int, ...] | None = None  # learned: taxel indices in the order the board sends them
        self._position: list[int] | None = None  # taxel index -> its place in send_order
        self._proven_orders: deque[tuple[int, ...]] = deque(maxlen=ORDER_LEARN_FRAMES)
        self._frames_since_valid = 0
        self._values: list[tuple[int, int, int]] = [(0, 0, 0)] * n  # last good counts per taxel
        self._good_t_ns: list[int | None] = [None] * n  # time of each taxel's last good value
        self._bad_this_cycle: list[bool] = [False] * n  # reported, but invalid
        self._seen: list[bool] = [False] * n  # reported since the last closed frame
        self._n_seen = 0
        self._arrival: list[int] = []  # taxels of the open frame, in arrival order
        self._start_marked = False  # the open frame's first message carried a cycle mark
        self._gap_before: int | None = None  # gap (ns) before the open frame's first message
        self._max_gap_ns = 0  # longest gap between two messages of the open frame
        self._pending: _Snapshot | None = None  # a complete frame waiting for the next message to mark its end
        self._last_t_ns = 0
        # counters (monotonic)
        self.messages = 0
        self.unknown_ids = 0
        self.invalid_messages = 0
        self.frames = 0
        self.incomplete_frames = 0
        self.unproven_frames = 0

    @property
    def n_taxels(self) -> int:
        return self.id_map.n_taxels

    def add(self, arbitration_id: int, data: bytes, t_ns: int) -> AssembledFrame | None:
        """Feed one CAN message received at ``t_ns`` (caller's clock, ns); returns a frame when one closes."""
        self.messages += 1
        index = self._index.get(arbitration_id)
        if index is None:
            self.unknown_ids += 1
            return None
        gap = None if self._prev_t_ns is None else t_ns - self._prev_t_ns
        self._prev_t_ns = t_ns
        after_pause = gap is not None and self.pause_threshold_ns is not None and gap >= self.pause_threshold_ns
        position = self._position
        wrapped = (
            position is not None and self._prev_index is not None and position[index] <= position[self._prev_index]
        )
        self._prev_index = index
        # a cycle start the receive times show now (or the configured first id): what proves a boundary. The learned
        # order only closes frames: it was learned from receive times that may have lied (a host reading in offset
        # bursts teaches a rotated order), so a boundary the timing does not show now proves nothing.
        timed = after_pause or index == self._cycle_start_index
        marked = timed or wrapped
        emitted: AssembledFrame | None = None
        if self._pending is not None:  # the message after a complete frame decides whether it was one cycle
            pending, self._pending = self._pending, None
            ends = timed or _pause_around(gap, pending.max_gap_ns)
            emitted = self._finish(pending, one_cycle=ends, complete=True)
        elif self._n_seen > 0 and (self._seen[index] or marked):
            pause_alone = after_pause and not (self._seen[index] or wrapped or index == self._cycle_start_index)
            short = 2 * self._n_seen < self._n
            starts = self._start_marked or _pause_around(self._gap_before, self._max_gap_ns)
            ends = timed or _pause_around(gap, self._max_gap_ns)
            emitted = self._finish(self._close(), one_cycle=starts and ends, complete=False)
            self._short_pause_closes = self._short_pause_closes + 1 if pause_alone and short else 0
            if self._short_pause_closes >= SHORT_PAUSE_CLOSES:  # pauses no longer mark cycles: learn again
                self.pause_threshold_ns = None
                self._window = []
                self._pauses.clear()
                self._short_pause_closes = 0
        if gap is not None and self._learn_pauses and self.pause_threshold_ns is None:
            self._learn(gap)
        if self._n_seen == 0:
            self._start_marked = timed
            self._gap_before = gap
            self._max_gap_ns = 0
        elif gap is not None:
            self._max_gap_ns = max(self._max_gap_ns, abs(gap))  # time running backwards is no burst
        self._seen[index] = True
        self._n_seen += 1
        self._arrival.append(index)
        self._last_t_ns = t_ns
        reading = _reading(data)
        self._bad_this_cycle[index] = reading is None
        if reading is None:
            self.invalid_messages += 1
        else:
            self._values[index] = reading
            self._good_t_ns[index] = t_ns
        if self._n_seen < self._n:
            return emitted
        # Complete. Cannot coincide with an early close or a pending frame (either leaves one taxel seen) unless the
        # map has one taxel, where every message is a whole cycle.
        self._short_pause_closes = 0
        starts = self._start_marked or _pause_around(self._gap_before, self._max_gap_ns)
        snapshot = self._close()
        if self._n == 1 or (starts and self._position is not None):
            # the timing shows this frame's start, and it holds every place of the learned order once, in order, with
            # no pause inside (a pause would have closed it): its end is the order's last place
            return self._finish(snapshot, one_cycle=True, complete=True)
        if starts:
            self._pending = snapshot
            return emitted
        return self._finish(snapshot, one_cycle=False, complete=True)

    def flush(self, now_ns: int) -> AssembledFrame | None:
        """Call when the transport is drained (a receive found nothing) at ``now_ns``: a complete frame waiting for
        the next message to show the pause after it comes out now when the quiet since its last message is that
        pause (the learned pause, or :data:`BURST_GAP_RATIO` times its own gaps). A quiet seen on a drained
        transport is a real one on the bus, whatever the receive times of the messages before it were."""
        pending = self._pending
        if pending is None:
            return None
        quiet = now_ns - pending.t_ns
        needed = (
            self.pause_threshold_ns if self.pause_threshold_ns is not None else BURST_GAP_RATIO * pending.max_gap_ns
        )
        if quiet <= 0 or quiet < needed:
            return None
        self._pending = None
        self._prev_t_ns = now_ns  # the next message's gap counts from here: the quiet is already spent
        return self._finish(pending, one_cycle=True, complete=True)

    def _learn(self, gap: int) -> None:
        """Collect one cycle's worth of gaps; a window with one clear pause counts toward learning the threshold."""
        if self._n < 2:
            return  # one message per cycle: every gap is a pause
        self._window.append(gap)
        if len(self._window) < self._n:
            return
        longest, runner_up = sorted(self._window)[-1:-3:-1]
        self._window = []
        if longest <= 0 or longest < BURST_GAP_RATIO * runner_up:
            self._pauses.clear()
            return
        self._pauses.append((longest, runner_up))
        if len(self._pauses) == LEARN_CYCLES:
            shortest_pause = min(p for p, _ in self._pauses)
            longest_other = max(r for _, r in self._pauses)
            self.pause_threshold_ns = max(1, round(math.sqrt(shortest_pause * max(longest_other, 1))))

    def _close(self) -> _Snapshot:
        """The open frame's contents; the next message opens a new frame."""
        t_ns = self._last_t_ns
        oldest_ok = t_ns - self.stale_after_ns
        flags = [
            (not seen) or bad or good_t is None or good_t < oldest_ok
            for seen, bad, good_t in zip(self._seen, self._bad_this_cycle, self._good_t_ns, strict=True)
        ]
        snapshot = _Snapshot(
            np.array(self._values, dtype=np.int64),
            t_ns,
            np.array(flags, dtype=bool),
            tuple(self._arrival),
            self._max_gap_ns,
        )
        n = len(self._seen)
        self._seen = [False] * n
        self._bad_this_cycle = [False] * n
        self._n_seen = 0
        self._arrival = []
        return snapshot

    def _finish(self, snapshot: _Snapshot, *, one_cycle: bool, complete: bool) -> AssembledFrame:
        """Decide a closed frame's validity, count it, and learn the send order from proven whole cycles."""
        stale_mask = snapshot.flags if one_cycle else np.ones_like(snapshot.flags)
        valid = one_cycle and not snapshot.flags.any()
        self.frames += 1
        if not complete:
            self.incomplete_frames += 1
        elif not one_cycle:
            self.unproven_frames += 1
        self._frames_since_valid = 0 if valid else self._frames_since_valid + 1
        if self._position is not None and self._frames_since_valid >= FORGET_AFTER_FRAMES:
            self.send_order = None  # the board's order changed, or the bus loses too much to tell: learn again
            self._position = None
            self._proven_orders.clear()
        elif self._position is None and complete and one_cycle and self._n > 1:
            self._proven_orders.append(snapshot.arrival)
            if len(self._proven_orders) == ORDER_LEARN_FRAMES and len(set(self._proven_orders)) == 1:
                self.send_order = snapshot.arrival
                position = [0] * self._n
                for place, index in enumerate(snapshot.arrival):
                    position[index] = place
                self._position = position
                self._frames_since_valid = 0
        return AssembledFrame(
            values=snapshot.values, t_ns=snapshot.t_ns, stale_mask=stale_mask, valid=valid, one_cycle=one_cycle
        )

    def counters(self) -> dict[str, int]:
        """All counters as a dict (for health reports); ``unproven_frames`` are complete frames flagged because
        nothing proved they held one cycle."""
        names = ("messages", "unknown_ids", "invalid_messages", "frames", "incomplete_frames", "unproven_frames")
        return {name: getattr(self, name) for name in names}
