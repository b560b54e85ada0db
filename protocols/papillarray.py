"""Contactile PapillArray Controller v2.0 serial stream (PTS v2.0 protocol): data packets and ASCII commands.

Stream packets (controller -> host, binary, all multi-byte values little-endian)::

    55 66 77 88 | body ... | checksum (u16) | AA BB CC DD

``checksum`` is the sum of the body bytes (everything between the start marker and the checksum) truncated to 16
bits. Body byte 0 is the index size ISZ (bytes per offset). Then an index table of ``(type: u16, offset: ISZ bytes)``
entries; offsets count from body byte 0 and the table ends where the first block begins. Block types:

* 1 hub: ``u32`` packet counter, ``u64`` controller timestamp (us).
* 3 pillar data: ``u16`` n_sensors, sensor offset table (n_sensors x ISZ), then per sensor ``u16`` n_pillars, pillar
  offset table (n_pillars x ISZ), then per pillar ``u16`` entry type (= 2) and 6 x float32 Fx Fy Fz (N), Dx Dy Dz
  (mm) -- forces come before displacements on the wire.
* 4 global data: ``u16`` n_sensors, sensor offset table, per sensor ``u16`` type (= 2) and 6 x float32 Fx Fy Fz (N),
  Tx Ty Tz (N*mm, about the tip of the centre pillar).
* 5 per-pillar slip: ``u16`` n_sensors, sensor offset table, per sensor ``u16`` n_pillars, pillar offset table, per
  pillar ``u16`` type (= 1), ``int8`` slip state, float32 friction estimate.
* 6 per-sensor slip: ``u16`` n_sensors, sensor offset table, per sensor ``u16`` type (= 1), ``u8`` state (0 inactive,
  non-zero slip detection active, 2 reference pillar loaded), float32 friction estimate, float32 target grip
  force (N, -1 when none).
* 7 and others: not defined by the v2.0 SDK; kept as raw bytes.

Only the pillar block is required: no public source says the others always come. A packet without a hub block
decodes with ``counter`` and ``timestamp_us`` None, one without a global block with NaN global force and torque.

The controller always reports two sensor slots (SEN0/SEN1). The public sources do not say what the offsets inside
the sensor and pillar offset tables count from; this decoder reads every block sequentially (as the third-party
parser checked against the vendor SDK does), so it does not depend on them, and the encoder writes them relative to
body byte 0 like the index table [inference]. The last block must end exactly where the checksum begins. The SDK
caps a packet at 2048 bytes.

The host's ASCII commands (bias, slip detection, sampling rate) are in :mod:`protocols.papillarray_commands`.
Streaming starts when the port opens; there is no start command.

Sources: Contactile PTSCOM 2.0 spec (framing, checksum, endianness, commands), PTSDKParser.h (2048-byte maximum),
PTS 2.1 spec and PTS Python/ROS manuals, and the body layout of langxin11/contactile_pts_lab ``pts_protocol.py``
(third-party, said to match the SDK output), as summarised in the project's hardware facts (section 2).
Pure codec: no I/O, threads or clocks.

Why one module: it is one binary format. The encoder (for the simulated hub) and the decoder (for the
driver) read each data block's layout from one table (``_BLOCKS``) and are tested against each other (round trips,
fuzzing); the stream parser reuses the decoder's cached body layout (``_Layout``) to skip re-walking same-shaped
packets.
"""

from __future__ import annotations

import struct
from bisect import bisect_left, bisect_right, insort
from collections.abc import Iterable
from dataclasses import dataclass, field
from functools import cached_property

import numpy as np

from protocols.errors import ProtocolError

START_MARKER = b"\x55\x66\x77\x88"
END_MARKER = b"\xaa\xbb\xcc\xdd"
MAX_PACKET_LEN = 2048  # bytes, whole framed packet (vendor SDK limit)
N_SENSOR_SLOTS = 2  # the controller always reports SEN0 and SEN1
N_PILLARS = 9  # 3x3 PapillArray

BLOCK_HUB = 1
BLOCK_PILLAR = 3
BLOCK_GLOBAL = 4
BLOCK_PILLAR_SLIP = 5
BLOCK_SENSOR_SLIP = 6

NO_FRICTION_ESTIMATE = -1.0  # the device's "no estimate" value for friction and target grip force

_FRAMING_OVERHEAD = len(START_MARKER) + 2 + len(END_MARKER)
_U16 = struct.Struct("<H")
_HUB = struct.Struct("<IQ")
_HINT = "check the cable and the port; the decoder resynchronises on the next packet"
_FLOAT32_MAX = float(np.finfo(np.float32).max)


@dataclass(frozen=True)
class _Block:
    """One data block's layout, shared by the encoder and the decoder: a u16 sensor count and sensor offset table,
    then per sensor either one entry (``nested`` False) or a u16 pillar count, pillar offset table and one entry per
    pillar. An entry is a u16 ``entry_type``, an optional one-byte field (``byte``: numpy code) and ``n_floats``
    float32."""

    name: str
    nested: bool
    entry_type: int
    byte: str | None
    n_floats: int

    @cached_property
    def dtype(self) -> np.dtype:  # packed, as on the wire
        fields = [("type", "<u2"), ("byte", self.byte)] if self.byte else [("type", "<u2")]
        return np.dtype([*fields, ("floats", "<f4", (self.n_floats,))])


_BLOCKS = {
    BLOCK_PILLAR: _Block("pillar", nested=True, entry_type=2, byte=None, n_floats=6),  # Fx Fy Fz Dx Dy Dz
    BLOCK_GLOBAL: _Block("global", nested=False, entry_type=2, byte=None, n_floats=6),  # Fx Fy Fz Tx Ty Tz
    BLOCK_PILLAR_SLIP: _Block("pillar slip", nested=True, entry_type=1, byte="i1", n_floats=1),  # state, friction
    # slip detection state, friction estimate, target grip force
    BLOCK_SENSOR_SLIP: _Block("sensor slip", nested=False, entry_type=1, byte="u1", n_floats=2),
}


@dataclass(eq=False)
class PillarSensorData:
    """One sensor slot of one packet.

    Per pillar (row-major 3x3, pillar 4 is the centre): ``forces_n`` (n, 3) N, ``displacements_mm`` (n, 3) mm,
    ``slip_states`` (n,) int (-2 ineligible, -1 lost contact, 1 contact at start, 2 tangential loading, 3 slipped),
    ``pillar_friction`` (n,). Per sensor: ``global_force_n`` (3,) N, ``global_torque_nmm`` (3,) N*mm (NaN where the
    packet has no global block), ``slip_active`` (0 off, non-zero on, 2 reference pillar loaded),
    ``friction_estimate`` and ``target_grip_force_n`` (-1 = no estimate). Slip fields default to the device's
    "nothing" values, which is also what the decoder reports when a packet carries no slip blocks.
    """

    forces_n: np.ndarray
    displacements_mm: np.ndarray
    global_force_n: np.ndarray
    global_torque_nmm: np.ndarray
    slip_states: np.ndarray = field(default_factory=lambda: np.zeros(N_PILLARS, dtype=np.int64))
    pillar_friction: np.ndarray = field(default_factory=lambda: np.full(N_PILLARS, NO_FRICTION_ESTIMATE))
    slip_active: int = 0
    friction_estimate: float = NO_FRICTION_ESTIMATE
    target_grip_force_n: float = NO_FRICTION_ESTIMATE

    @property
    def n_pillars(self) -> int:
        return int(np.shape(self.forces_n)[0])

    @classmethod
    def unloaded(cls, n_pillars: int = N_PILLARS) -> PillarSensorData:
        """An all-zero reading (e.g. an empty sensor slot)."""
        zeros = np.zeros((n_pillars, 3))
        slip_states = np.zeros(n_pillars, dtype=np.int64)
        return cls(zeros, zeros.copy(), np.zeros(3), np.zeros(3), slip_states, np.full(n_pillars, NO_FRICTION_ESTIMATE))


@dataclass(eq=False)
class PapillArrayPacket:
    """One stream packet: controller packet counter, controller timestamp (us) and every sensor slot.

    ``counter`` and ``timestamp_us`` are None for a packet without a hub block (the encoder then writes none).
    ``unknown_blocks`` holds the raw bytes of block types the v2.0 SDK does not define (e.g. 7), by type.
    """

    counter: int | None
    timestamp_us: int | None
    sensors: list[PillarSensorData]
    unknown_blocks: dict[int, bytes] = field(default_factory=dict)


def checksum(body: bytes | bytearray | memoryview) -> int:
    """16-bit sum of the body bytes (between the start marker and the checksum)."""
    return int(np.frombuffer(body, dtype=np.uint8).sum(dtype=np.uint64)) & 0xFFFF


# ----------------------------------------------------------------------------------------------------- encoding


def _offsets(first: int, sizes: list[int], index_size: int) -> bytes:
    """Offset table (``index_size`` bytes each) of consecutive items of ``sizes`` bytes starting at ``first``."""
    positions = first + np.cumsum([0, *sizes], dtype=np.int64)[:-1]
    if len(positions) and positions[-1] >= 1 << (8 * index_size):
        raise ProtocolError(
            f"offset {positions[-1]} does not fit in index_size={index_size} bytes",
            hint="use index_size=2 for packets longer than 255 bytes",
        )
    return positions.astype("<u8").view(np.uint8).reshape(-1, 8)[:, :index_size].tobytes()


def _f32(values: object, shape: tuple[int, ...], what: str) -> np.ndarray:
    """``values`` as float64 of ``shape``; finite values float32 cannot hold are refused (NaN and inf pass)."""
    array = np.asarray(values, dtype=np.float64)
    if array.shape != shape:
        raise ProtocolError(f"{what} has shape {array.shape}, expected {shape}", hint="one row per pillar")
    finite = array[np.isfinite(array)]
    if finite.size and np.abs(finite).max() > _FLOAT32_MAX:
        raise ProtocolError(f"{what} exceeds the float32 range of the wire", hint="check the units (N, mm)")
    return array


def _entries(block_type: int, sensor: PillarSensorData) -> np.ndarray:
    """One sensor's entries of one block, checked against the wire's types."""
    n = sensor.n_pillars
    byte: object = None
    if block_type == BLOCK_PILLAR:
        floats = np.hstack(
            [_f32(sensor.forces_n, (n, 3), "forces_n"), _f32(sensor.displacements_mm, (n, 3), "displacements_mm")]
        )
    elif block_type == BLOCK_GLOBAL:
        force = _f32(sensor.global_force_n, (3,), "global_force_n")
        floats = np.concatenate([force, _f32(sensor.global_torque_nmm, (3,), "global_torque_nmm")])[None]
    elif block_type == BLOCK_PILLAR_SLIP:
        byte = np.asarray(sensor.slip_states).reshape(-1)
        friction = np.asarray(sensor.pillar_friction, dtype=np.float64).reshape(-1)
        if byte.shape != (n,) or friction.shape != (n,):
            raise ProtocolError(
                f"slip_states {byte.shape} / pillar_friction {friction.shape} do not match {n} pillars",
                hint="one slip state and one friction value per pillar",
            )
        if n and (byte.min() < -128 or byte.max() > 127):
            raise ProtocolError("slip state outside int8 range", hint="use the device's states -2..3")
        floats = _f32(friction, (n,), "pillar_friction")[:, None]
    else:
        if not 0 <= sensor.slip_active <= 0xFF:
            raise ProtocolError(f"slip_active {sensor.slip_active} is not a u8", hint="use 0, 1 or 2")
        byte = sensor.slip_active
        scalars = [sensor.friction_estimate, sensor.target_grip_force_n]
        floats = _f32(scalars, (2,), "friction/target grip")[None]
    spec = _BLOCKS[block_type]
    entries = np.empty(len(floats), dtype=spec.dtype)
    entries["type"] = spec.entry_type
    entries["floats"] = floats
    if spec.byte:
        entries["byte"] = byte
    return entries


def _encode_block(block_type: int, sensors: list[PillarSensorData], start: int, isz: int) -> bytes:
    """A data block beginning at body offset ``start``; every offset counts from body byte 0."""
    spec = _BLOCKS[block_type]
    rows = [_entries(block_type, sensor) for sensor in sensors]
    size = spec.dtype.itemsize
    parts = [_U16.pack(len(sensors))]
    position = start + 2 + len(sensors) * isz
    if not spec.nested:
        return b"".join([*parts, _offsets(position, [size] * len(rows), isz), *(r.tobytes() for r in rows)])
    parts.append(_offsets(position, [2 + len(r) * (isz + size) for r in rows], isz))
    for entries in rows:
        n = len(entries)
        parts += [_U16.pack(n), _offsets(position + 2 + n * isz, [size] * n, isz), entries.tobytes()]
        position += 2 + n * (isz + size)
    return b"".join(parts)


def encode_body(
    packet: PapillArrayPacket, index_size: int = 2, include_slip: bool = True, include_global: bool = True
) -> bytes:
    """The packet body (no markers, no checksum): ISZ, index table, then [hub,] pillar[, global][, slip] blocks.
    The hub block is left out when the packet's ``counter`` is None."""
    if not 1 <= index_size <= 4:
        raise ProtocolError(f"index_size {index_size} not in 1..4", hint="the controller uses small offsets; use 2")
    counter, timestamp_us = packet.counter, packet.timestamp_us
    if (counter is None) != (timestamp_us is None):
        raise ProtocolError("counter and timestamp_us come together in the hub block", hint="give both or neither")
    if counter is not None and not 0 <= counter < 1 << 32:
        raise ProtocolError(f"counter {counter} is not a u32", hint="wrap the counter modulo 2**32")
    if timestamp_us is not None and not 0 <= timestamp_us < 1 << 64:
        raise ProtocolError(f"timestamp_us {timestamp_us} is not a u64", hint="use a non-negative int")
    if not packet.sensors or len(packet.sensors) > 0xFFFF:
        raise ProtocolError("a packet needs at least one sensor slot", hint="the controller reports 2 slots")
    types = [BLOCK_PILLAR] if counter is None else [BLOCK_HUB, BLOCK_PILLAR]
    types += [BLOCK_GLOBAL] * include_global + [BLOCK_PILLAR_SLIP, BLOCK_SENSOR_SLIP] * include_slip
    extra = sorted(packet.unknown_blocks.items())
    for block_type, data in extra:
        if block_type in (BLOCK_HUB, *_BLOCKS) or not 0 < block_type <= 0xFFFF or not data:
            raise ProtocolError(f"cannot encode raw block type {block_type}", hint="use an undefined type, e.g. 7")
    index = [bytes((index_size,))]
    blocks: list[bytes] = []
    position = 1 + (len(types) + len(extra)) * (2 + index_size)
    pending: list[tuple[int, bytes | None]] = [(t, None) for t in types] + [(t, bytes(data)) for t, data in extra]
    for block_type, raw in pending:
        if block_type == BLOCK_HUB:
            raw = _HUB.pack(counter, timestamp_us)
        elif raw is None:
            raw = _encode_block(block_type, packet.sensors, position, index_size)
        index.append(_U16.pack(block_type) + _offsets(position, [0], index_size))
        blocks.append(raw)
        position += len(raw)
    return b"".join(index + blocks)


def frame_body(body: bytes) -> bytes:
    """Wrap a body in start marker, checksum and end marker."""
    return START_MARKER + body + _U16.pack(checksum(body)) + END_MARKER


def encode_packet(
    packet: PapillArrayPacket, index_size: int = 2, include_slip: bool = True, include_global: bool = True
) -> bytes:
    """One whole framed packet, as the controller sends it (blocks 1, 3, 4, 5, 6 and any unknown raw blocks)."""
    return frame_body(encode_body(packet, index_size, include_slip, include_global))


# ----------------------------------------------------------------------------------------------------- decoding


def _bad(reason: str) -> ProtocolError:
    return ProtocolError(f"bad PapillArray packet: {reason}", hint=_HINT)


def _read_index(body: bytes) -> tuple[int, list[tuple[int, int]], int]:
    """(ISZ, [(block type, offset)] sorted by offset, index table end)."""
    if len(body) < 1:
        raise _bad("empty body")
    isz = body[0]
    if not 1 <= isz <= 4:
        raise _bad(f"index size {isz} not in 1..4")
    entry_len = 2 + isz
    entries: list[tuple[int, int]] = []
    seen: set[int] = set()
    pos = 1
    first_block = len(body)
    while pos < first_block:
        if pos + entry_len > len(body):
            raise _bad("index table runs past the end of the body")
        block_type = _U16.unpack_from(body, pos)[0]
        offset = int.from_bytes(body[pos + 2 : pos + entry_len], "little")
        pos += entry_len
        if block_type in seen:
            raise _bad(f"block type {block_type} listed twice in the index")
        if not pos <= offset < len(body):
            raise _bad(f"block type {block_type} offset {offset} outside the body after the index")
        seen.add(block_type)
        entries.append((block_type, offset))
        first_block = min(first_block, offset)
    if pos != first_block:
        raise _bad(f"index table ends at body byte {pos} but the first block starts at {first_block}")
    entries.sort(key=lambda item: item[1])
    return isz, entries, pos


class _Layout:
    """Positions of every field of one body shape, found once by walking a body; reused while the shape holds.

    ``struct_pos``/``struct_val`` are the body bytes that fix the shape (index size, index table, counts, offset
    tables, entry types): a later body with the same length and the same bytes there has the same layout. The
    floats of every entry are gathered into one array, the one-byte fields into another; ``sensors[i][block type]``
    is ``(n entries, first float, first byte)`` of sensor slot i in that block.
    """

    def __init__(self, body: bytes) -> None:
        self.length = len(body)
        self._body = body
        struct_ranges: list[tuple[int, int]] = []
        float_ranges: list[tuple[int, int]] = []  # (body byte, n floats)
        n_floats = 0
        byte_pos: list[int] = []
        self.hub_pos = -1
        self.unknown: list[tuple[int, int, int]] = []  # (block type, start, end)
        self._isz, entries, index_end = _read_index(body)
        struct_ranges.append((0, index_end))
        if BLOCK_PILLAR not in (block_type for block_type, _ in entries):
            raise _bad(f"no block of type {BLOCK_PILLAR} (pillar data)")
        blocks: dict[int, list[tuple[int, int, int]]] = {}
        for position, (block_type, offset) in enumerate(entries):
            block_end = entries[position + 1][1] if position + 1 < len(entries) else len(body)
            self._pos = offset
            spec = _BLOCKS.get(block_type)
            if block_type == BLOCK_HUB:
                self.hub_pos = self._need(_HUB.size, "hub block")
            elif spec is None:
                self.unknown.append((block_type, offset, block_end))
                self._pos = block_end
            else:
                slots = blocks[block_type] = []
                for sensor in range(self._count(f"{spec.name} block sensor count", struct_ranges)):
                    n = self._count(f"sensor {sensor} {spec.name} pillar count", struct_ranges) if spec.nested else 1
                    slots.append((n, n_floats, len(byte_pos)))
                    for _ in range(n):
                        start = self._need(2, f"sensor {sensor} {spec.name} entry")
                        found = _U16.unpack_from(body, start)[0]
                        if found != spec.entry_type:
                            raise _bad(f"sensor {sensor} {spec.name} entry type {found}, expected {spec.entry_type}")
                        struct_ranges.append((start, 2))
                        if spec.byte:
                            byte_pos.append(self._need(1, f"sensor {sensor} {spec.name} state"))
                        float_ranges.append(
                            (self._need(4 * spec.n_floats, f"sensor {sensor} {spec.name} values"), spec.n_floats)
                        )
                        n_floats += spec.n_floats
            if self._pos > block_end:
                raise _bad(f"block type {block_type} overlaps the next block")
            if block_end == len(body) and self._pos != block_end:
                raise _bad(f"{block_end - self._pos} stray bytes after the last block")
        n_sensors = len(blocks[BLOCK_PILLAR])
        for block_type, slots in blocks.items():
            if len(slots) != n_sensors:
                raise _bad(
                    f"pillar block has {n_sensors} sensors but {_BLOCKS[block_type].name} block has {len(slots)}"
                )
        self.sensors = [{block_type: slots[i] for block_type, slots in blocks.items()} for i in range(n_sensors)]
        for index, sensor_blocks in enumerate(self.sensors):
            n_pillars, n_slip = sensor_blocks[BLOCK_PILLAR][0], sensor_blocks.get(BLOCK_PILLAR_SLIP, (None,))[0]
            if n_slip is not None and n_slip != n_pillars:
                raise _bad(f"sensor {index}: {n_pillars} pillars but {n_slip} slip entries")
        self.struct_pos = _ranges_to_positions(struct_ranges)
        self.struct_val = np.frombuffer(body, dtype=np.uint8)[self.struct_pos]
        self.float_bytes = _ranges_to_positions((start, 4 * n) for start, n in float_ranges)
        self.byte_pos = np.array(byte_pos, dtype=np.intp)
        del self._body

    def _need(self, n: int, what: str) -> int:
        """Claim ``n`` bytes at the walk's position; -> where they start."""
        start = self._pos
        if start + n > len(self._body):
            raise _bad(f"{what} at body byte {start} runs past the end ({len(self._body)} bytes)")
        self._pos = start + n
        return start

    def _count(self, what: str, struct_ranges: list[tuple[int, int]]) -> int:
        """A u16 count followed by its offset table (both fix the shape)."""
        start = self._need(2, what)
        n: int = _U16.unpack_from(self._body, start)[0]
        self._need(n * self._isz, f"{what} offset table")
        struct_ranges.append((start, self._pos - start))
        return n

    def matches(self, u8: np.ndarray) -> bool:
        """True when a body (as uint8 array) has exactly this shape."""
        return len(u8) == self.length and bool(np.array_equal(u8[self.struct_pos], self.struct_val))

    def extract(self, body: bytes, u8: np.ndarray) -> PapillArrayPacket:
        with np.errstate(invalid="ignore"):  # a signalling NaN on the wire stays NaN, without a warning
            floats = u8[self.float_bytes].view("<f4").astype(np.float64)
        one_byte = u8[self.byte_pos]
        states = one_byte.view(np.int8).astype(np.int64)
        counter, timestamp_us = _HUB.unpack_from(body, self.hub_pos) if self.hub_pos >= 0 else (None, None)
        sensors = []
        for blocks in self.sensors:
            n, at, _ = blocks[BLOCK_PILLAR]
            pillar_values = floats[at : at + 6 * n].reshape(n, 6)
            if BLOCK_GLOBAL in blocks:
                at = blocks[BLOCK_GLOBAL][1]
                global_values = floats[at : at + 6]
            else:
                global_values = np.full(6, np.nan)  # no global block in this packet
            if BLOCK_PILLAR_SLIP in blocks:
                _, at, state_at = blocks[BLOCK_PILLAR_SLIP]
                slip_states, pillar_friction = states[state_at : state_at + n], floats[at : at + n]
            else:
                slip_states, pillar_friction = np.zeros(n, dtype=np.int64), np.full(n, NO_FRICTION_ESTIMATE)
            sensor = PillarSensorData(
                forces_n=pillar_values[:, :3],
                displacements_mm=pillar_values[:, 3:],
                global_force_n=global_values[:3],
                global_torque_nmm=global_values[3:],
                slip_states=slip_states,
                pillar_friction=pillar_friction,
            )
            if BLOCK_SENSOR_SLIP in blocks:
                _, at, active_at = blocks[BLOCK_SENSOR_SLIP]
                sensor.slip_active = int(one_byte[active_at])
                sensor.friction_estimate, sensor.target_grip_force_n = float(floats[at]), float(floats[at + 1])
            sensors.append(sensor)
        unknown = {block_type: body[start:end] for block_type, start, end in self.unknown}
        return PapillArrayPacket(counter, timestamp_us, sensors, unknown)


def _ranges_to_positions(ranges: Iterable[tuple[int, int]]) -> np.ndarray:
    parts = [np.arange(start, start + length, dtype=np.intp) for start, length in ranges]
    return np.concatenate(parts) if parts else np.zeros(0, dtype=np.intp)


def decode_packet(frame: bytes | bytearray | memoryview) -> PapillArrayPacket:
    """Decode one whole framed packet (start marker to end marker); ProtocolError says what is wrong."""
    if len(frame) < _FRAMING_OVERHEAD + 1:
        raise _bad(f"{len(frame)} bytes is too short for a framed packet")
    if frame[:4] != START_MARKER:
        raise _bad(f"starts with {bytes(frame[:4]).hex(' ')}, not the start marker 55 66 77 88")
    if frame[-4:] != END_MARKER:
        raise _bad(f"ends with {bytes(frame[-4:]).hex(' ')}, not the end marker aa bb cc dd")
    body = bytes(frame[4:-6])
    sent, computed = _U16.unpack_from(frame, len(frame) - 6)[0], checksum(body)
    if sent != computed:
        raise _bad(f"checksum 0x{sent:04x} on the wire, 0x{computed:04x} computed")
    return _Layout(body).extract(body, np.frombuffer(body, dtype=np.uint8))


class PacketParser:
    """Incremental stream decoder: feed any chunks, get every intact packet back, in order.

    A start marker is accepted once some later end marker closes a body whose checksum matches and which decodes
    (end markers may also occur inside the float data, so every candidate up to ``max_packet_len`` is tried). A
    start marker is given up when ``max_packet_len`` bytes past it hold no such end, or as soon as a later start
    marker already opens an intact packet -- so a packet cut short never swallows the one after it. Counters:
    ``packets`` decoded, ``bytes_dropped`` skipped (garbage and broken packets), ``checksum_errors`` and
    ``framing_errors`` (no end marker, or a body that does not decode) per start marker given up. The body layout
    of the last packet is remembered, so a stream of same-shaped packets skips re-walking the body.

    Linear time, however the bytes come (marker-dense garbage, any chunk sizes): each marker is found once; each end
    marker is checked against every open start marker before it at once, from running byte sums (a checksum is a
    difference of two sums); only the rare (start, end) pairs whose checksum matches are decoded, each at most once.
    Work per byte is bounded by the markers within ``max_packet_len`` of it, never by how often it was fed.
    """

    def __init__(self, max_packet_len: int = MAX_PACKET_LEN) -> None:
        if max_packet_len < _FRAMING_OVERHEAD + 1:
            raise ProtocolError(f"max_packet_len {max_packet_len} too small", hint="the vendor SDK uses 2048")
        self.max_packet_len = max_packet_len
        self._layout: _Layout | None = None
        self.packets = 0
        self.bytes_dropped = 0
        self.checksum_errors = 0
        self.framing_errors = 0
        # work done, for benchmarks and tests: (start, end) marker pairs whose checksum was compared, bodies decoded
        self.pairs_checked = 0
        self.bodies_decoded = 0
        self.reset()

    def reset(self) -> None:
        """Forget buffered bytes (e.g. after reopening the port); counters are kept."""
        # Positions are absolute stream offsets; self._buf holds the stream from self._base on.
        self._buf = bytearray()
        self._base = 0
        self._waiting_for: int | None = None  # the open start marker the last read ended waiting on
        self._scanned = 0  # markers starting before this offset have been found
        self._starts: list[int] = []  # open start markers, ascending
        self._ends: list[int] = []  # end markers not yet consumed, ascending
        self._matches: dict[int, list[int]] = {}  # start -> ends whose checksum matches, ascending
        self._decoded: dict[tuple[int, int], PapillArrayPacket | None] = {}  # (start, end) -> packet, None: broken
        self._closed: dict[int, tuple[PapillArrayPacket, int]] = {}  # start -> (packet, end) of its first intact end
        self._closed_starts: list[int] = []  # the keys of _closed, ascending

    @property
    def pending_bytes(self) -> int:
        """Bytes held back waiting for the rest of a packet."""
        return len(self._buf)

    def counters(self) -> dict[str, int]:
        return {name: getattr(self, name) for name in ("packets", "bytes_dropped", "checksum_errors", "framing_errors")}

    def _decode(self, body: bytes, u8: np.ndarray) -> PapillArrayPacket:
        layout = self._layout
        if layout is None or not layout.matches(u8):
            layout = self._layout = _Layout(body)
        return layout.extract(body, u8)

    def _index_markers(self) -> None:
        """Find the markers the new bytes completed, and check each new end against the open starts before it."""
        buf, base = self._buf, self._base
        end_of_data = base + len(buf)
        new_starts: list[int] = []
        new_ends: list[int] = []
        for marker, found in ((START_MARKER, new_starts), (END_MARKER, new_ends)):
            at = buf.find(marker, max(0, self._scanned - base))
            while at >= 0:
                found.append(base + at)
                at = buf.find(marker, at + 1)
        self._scanned = max(self._scanned, end_of_data - (len(START_MARKER) - 1))
        self._starts += new_starts
        max_len = self.max_packet_len
        starts = self._starts
        sums: np.ndarray | None = None  # sums[i]: byte sum of _buf[:i], made once per read that brings an end marker
        for end in new_ends:
            self._ends.append(end)
            # starts whose packet could end here: a body of >= 1 byte and the checksum before it, within max_len
            low = bisect_left(starts, end + len(END_MARKER) - max_len)
            high = bisect_right(starts, end - len(START_MARKER) - 3)
            if low >= high:
                continue
            self.pairs_checked += high - low
            sent = buf[end - 2 - base] | buf[end - 1 - base] << 8
            if high - low == 1:  # the usual case, one packet start before its end: sum that body alone
                start = starts[low]
                body = np.frombuffer(buf, dtype=np.uint8, count=end - 2 - start - 4, offset=start + 4 - base)
                matched = int(body.sum(dtype=np.uint64)) & 0xFFFF == sent
                del body  # releases the buffer, so the bytearray can shrink again
                if matched:
                    self._match(start, end)
                continue
            if sums is None:
                sums = np.concatenate(([0], np.cumsum(np.frombuffer(buf, dtype=np.uint8), dtype=np.int64)))
            candidates = np.array(starts[low:high], dtype=np.int64)
            body_sums = sums[end - 2 - base] - sums[candidates + len(START_MARKER) - base]  # a checksum per start
            for start in candidates[(body_sums & 0xFFFF) == sent].tolist():
                self._match(start, end)

    def _match(self, start: int, end: int) -> None:
        """A body whose checksum matches: decode it now (once), and remember the first intact end of each start."""
        self._matches.setdefault(start, []).append(end)
        packet = self._packet(start, end)
        if packet is not None and start not in self._closed:
            self._closed[start] = (packet, end)
            insort(self._closed_starts, start)

    def _packet(self, start: int, end: int) -> PapillArrayPacket | None:
        """The packet from ``start`` to the end marker at ``end`` (checksum already matched), None if it is broken."""
        key = (start, end)
        if key not in self._decoded:
            body = bytes(self._buf[start + len(START_MARKER) - self._base : end - 2 - self._base])
            self.bodies_decoded += 1
            try:
                self._decoded[key] = self._decode(body, np.frombuffer(body, dtype=np.uint8))
            except ProtocolError:
                self._decoded[key] = None
        return self._decoded[key]

    def _give_up(self, start: int, stop: int) -> None:
        """Count a start marker with no intact packet ending by ``stop``: a framing error when a body with the right
        checksum did not decode or no end marker came; a checksum error when only checksums failed."""
        closed = [end for end in self._matches.get(start, ()) if end + len(END_MARKER) <= stop]
        decode_failed = any(self._decoded.get((start, end), 0) is None for end in closed)
        first_end = bisect_left(self._ends, start + len(START_MARKER) + 3)
        any_end = first_end < len(self._ends) and self._ends[first_end] + len(END_MARKER) <= stop
        if any_end and not decode_failed:
            self.checksum_errors += 1
        else:
            self.framing_errors += 1

    def _consume(self, upto: int) -> None:
        """Forget everything before stream offset ``upto``."""
        dropped = bisect_left(self._starts, upto)
        for start in self._starts[:dropped]:
            for end in self._matches.pop(start, ()):
                self._decoded.pop((start, end), None)
            self._closed.pop(start, None)
        del self._closed_starts[: bisect_left(self._closed_starts, upto)]
        del self._starts[:dropped]
        del self._ends[: bisect_left(self._ends, upto)]

    def feed(self, data: bytes | bytearray | memoryview) -> list[PapillArrayPacket]:
        """Append received bytes; return the packets completed by them (possibly none)."""
        if not data:
            return []
        old_len = len(self._buf)
        self._buf += data
        waiting = self._waiting_for
        if (
            waiting is not None
            and self._base + len(self._buf) < waiting + self.max_packet_len
            and self._buf.find(END_MARKER, max(0, old_len - (len(END_MARKER) - 1))) < 0
        ):
            return []  # still inside the packet the buffer waits on: nothing can close without a new end marker
        self._waiting_for = None
        self._index_markers()
        base = self._base
        end_of_data = base + len(self._buf)
        max_len = self.max_packet_len
        out: list[PapillArrayPacket] = []
        pos = base  # everything before pos is consumed
        while True:
            if not self._starts:
                keep_from = max(pos, end_of_data - (len(START_MARKER) - 1))  # a marker may be split across feeds
                self.bytes_dropped += keep_from - pos
                pos = keep_from
                break
            start = self._starts[0]
            self.bytes_dropped += start - pos
            pos = start
            intact = self._closed.get(start)  # (packet, end) of its first intact end, if one has arrived
            if intact is not None:
                out.append(intact[0])
                self.packets += 1
                pos = intact[1] + len(END_MARKER)
                self._consume(pos)
                continue
            if end_of_data >= start + max_len:  # every end it could have has arrived
                self._give_up(start, start + max_len)
                self.bytes_dropped += 1
                pos = start + 1
                self._consume(pos)
                continue
            # Not closed yet: wait for more bytes, unless a later start marker already opens an intact packet.
            at = bisect_right(self._closed_starts, start)
            if at == len(self._closed_starts):
                self._waiting_for = start
                break
            later = self._closed_starts[at]
            self._give_up(start, later)
            self.bytes_dropped += later - start
            pos = later
            self._consume(pos)
        if pos > base:
            del self._buf[: pos - base]
            self._base = pos
        return out
