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
driver) mirror each other block by block and are tested against each other (round trips, fuzzing), and the stream
parser reuses the decoder's cached body layout (``_Layout``) to skip re-walking same-shaped packets; split apart,
each half would have to expose the other's internals.
"""

from __future__ import annotations

import struct
from bisect import bisect_left, bisect_right, insort
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field

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
_KNOWN_BLOCKS = (BLOCK_HUB, BLOCK_PILLAR, BLOCK_GLOBAL, BLOCK_PILLAR_SLIP, BLOCK_SENSOR_SLIP)
_PILLAR_ENTRY_TYPE = 2
_GLOBAL_ENTRY_TYPE = 2
_SLIP_ENTRY_TYPE = 1

NO_FRICTION_ESTIMATE = -1.0  # the device's "no estimate" value for friction and target grip force

_FRAMING_OVERHEAD = len(START_MARKER) + 2 + len(END_MARKER)
_U16 = struct.Struct("<H")
_HUB = struct.Struct("<IQ")
_GLOBAL_ENTRY = struct.Struct("<H6f")
_SENSOR_SLIP_ENTRY = struct.Struct("<HBff")
_PILLAR_DTYPE = np.dtype([("type", "<u2"), ("values", "<f4", (6,))])  # 26 bytes, packed
_PILLAR_SLIP_DTYPE = np.dtype([("type", "<u2"), ("state", "i1"), ("friction", "<f4")])  # 7 bytes, packed
_HINT = "check the cable and the port; the decoder resynchronises on the next packet"


def _zeros3x(n: int) -> np.ndarray:
    return np.zeros((n, 3), dtype=np.float64)


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
        return cls(
            forces_n=_zeros3x(n_pillars),
            displacements_mm=_zeros3x(n_pillars),
            global_force_n=np.zeros(3),
            global_torque_nmm=np.zeros(3),
            slip_states=np.zeros(n_pillars, dtype=np.int64),
            pillar_friction=np.full(n_pillars, NO_FRICTION_ESTIMATE),
        )


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


def _offset_bytes(offset: int, index_size: int) -> bytes:
    if offset >= 1 << (8 * index_size):
        raise ProtocolError(
            f"offset {offset} does not fit in index_size={index_size} bytes",
            hint="use index_size=2 for packets longer than 255 bytes",
        )
    return offset.to_bytes(index_size, "little")


_FLOAT32_MAX = float(np.finfo(np.float32).max)


def _check_f32(values: np.ndarray, what: str) -> None:
    """Reject finite values that float32 cannot hold (NaN and inf pass through as the wire can carry them)."""
    finite = values[np.isfinite(values)]
    if finite.size and np.abs(finite).max() > _FLOAT32_MAX:
        raise ProtocolError(f"{what} exceeds the float32 range of the wire", hint="check the units (N, mm)")


def _as_float_rows(array: np.ndarray, shape: tuple[int, ...], what: str) -> np.ndarray:
    values = np.asarray(array, dtype=np.float64)
    if values.shape != shape:
        raise ProtocolError(f"{what} has shape {values.shape}, expected {shape}", hint="one row per pillar")
    _check_f32(values, what)
    return values


class _BodyWriter:
    """Appends blocks to a body while tracking absolute offsets (from body byte 0)."""

    def __init__(self, start: int, index_size: int) -> None:
        self.parts: list[bytes] = []
        self.offset = start
        self.index_size = index_size

    def put(self, data: bytes) -> None:
        self.parts.append(data)
        self.offset += len(data)

    def offset_table(self, sizes: list[int], first: int) -> bytes:
        """Offsets of consecutive sub-blocks of the given sizes starting at absolute offset ``first``."""
        table = []
        position = first
        for size in sizes:
            table.append(_offset_bytes(position, self.index_size))
            position += size
        return b"".join(table)


def _encode_pillar_block(writer: _BodyWriter, sensors: list[PillarSensorData]) -> None:
    isz = writer.index_size
    entry = 2 + 24
    sensor_sizes = [2 + s.n_pillars * (isz + entry) for s in sensors]
    writer.put(_U16.pack(len(sensors)))
    writer.put(writer.offset_table(sensor_sizes, writer.offset + len(sensors) * isz))
    for sensor in sensors:
        n = sensor.n_pillars
        forces = _as_float_rows(sensor.forces_n, (n, 3), "forces_n")
        displacements = _as_float_rows(sensor.displacements_mm, (n, 3), "displacements_mm")
        writer.put(_U16.pack(n))
        writer.put(writer.offset_table([entry] * n, writer.offset + n * isz))
        entries = np.empty(n, dtype=_PILLAR_DTYPE)
        entries["type"] = _PILLAR_ENTRY_TYPE
        entries["values"] = np.concatenate([forces, displacements], axis=1)
        writer.put(entries.tobytes())


def _encode_global_block(writer: _BodyWriter, sensors: list[PillarSensorData]) -> None:
    isz = writer.index_size
    writer.put(_U16.pack(len(sensors)))
    writer.put(writer.offset_table([_GLOBAL_ENTRY.size] * len(sensors), writer.offset + len(sensors) * isz))
    for sensor in sensors:
        force = _as_float_rows(sensor.global_force_n, (3,), "global_force_n")
        torque = _as_float_rows(sensor.global_torque_nmm, (3,), "global_torque_nmm")
        writer.put(_GLOBAL_ENTRY.pack(_GLOBAL_ENTRY_TYPE, *force.tolist(), *torque.tolist()))


def _encode_pillar_slip_block(writer: _BodyWriter, sensors: list[PillarSensorData]) -> None:
    isz = writer.index_size
    entry = _PILLAR_SLIP_DTYPE.itemsize
    sensor_sizes = [2 + s.n_pillars * (isz + entry) for s in sensors]
    writer.put(_U16.pack(len(sensors)))
    writer.put(writer.offset_table(sensor_sizes, writer.offset + len(sensors) * isz))
    for sensor in sensors:
        n = sensor.n_pillars
        states = np.asarray(sensor.slip_states).reshape(-1)
        friction = np.asarray(sensor.pillar_friction, dtype=np.float64).reshape(-1)
        _check_f32(friction, "pillar_friction")
        if states.shape != (n,) or friction.shape != (n,):
            raise ProtocolError(
                f"slip_states {states.shape} / pillar_friction {friction.shape} do not match {n} pillars",
                hint="one slip state and one friction value per pillar",
            )
        if states.size and (states.min() < -128 or states.max() > 127):
            raise ProtocolError("slip state outside int8 range", hint="use the device's states -2..3")
        writer.put(_U16.pack(n))
        writer.put(writer.offset_table([entry] * n, writer.offset + n * isz))
        entries = np.empty(n, dtype=_PILLAR_SLIP_DTYPE)
        entries["type"] = _SLIP_ENTRY_TYPE
        entries["state"] = states
        entries["friction"] = friction
        writer.put(entries.tobytes())


def _encode_sensor_slip_block(writer: _BodyWriter, sensors: list[PillarSensorData]) -> None:
    isz = writer.index_size
    writer.put(_U16.pack(len(sensors)))
    writer.put(writer.offset_table([_SENSOR_SLIP_ENTRY.size] * len(sensors), writer.offset + len(sensors) * isz))
    for sensor in sensors:
        if not 0 <= sensor.slip_active <= 0xFF:
            raise ProtocolError(f"slip_active {sensor.slip_active} is not a u8", hint="use 0, 1 or 2")
        _check_f32(np.array([sensor.friction_estimate, sensor.target_grip_force_n]), "friction/target grip")
        writer.put(
            _SENSOR_SLIP_ENTRY.pack(
                _SLIP_ENTRY_TYPE, sensor.slip_active, sensor.friction_estimate, sensor.target_grip_force_n
            )
        )


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
    blocks: list[tuple[int, Callable[[_BodyWriter], None]]] = []
    if counter is not None:
        blocks.append((BLOCK_HUB, lambda w: w.put(_HUB.pack(counter, timestamp_us))))
    blocks.append((BLOCK_PILLAR, lambda w: _encode_pillar_block(w, packet.sensors)))
    if include_global:
        blocks.append((BLOCK_GLOBAL, lambda w: _encode_global_block(w, packet.sensors)))
    if include_slip:
        blocks.append((BLOCK_PILLAR_SLIP, lambda w: _encode_pillar_slip_block(w, packet.sensors)))
        blocks.append((BLOCK_SENSOR_SLIP, lambda w: _encode_sensor_slip_block(w, packet.sensors)))
    extra = sorted(packet.unknown_blocks.items())
    n_entries = len(blocks) + len(extra)
    writer = _BodyWriter(start=1 + n_entries * (2 + index_size), index_size=index_size)
    index = [bytes((index_size,))]
    for block_type, write in blocks:
        index.append(_U16.pack(block_type) + _offset_bytes(writer.offset, index_size))
        write(writer)
    for block_type, raw in extra:
        if block_type in _KNOWN_BLOCKS or not 0 < block_type <= 0xFFFF or not raw:
            raise ProtocolError(f"cannot encode raw block type {block_type}", hint="use an undefined type, e.g. 7")
        index.append(_U16.pack(block_type) + _offset_bytes(writer.offset, index_size))
        writer.put(bytes(raw))
    return b"".join(index + writer.parts)


def frame_body(body: bytes) -> bytes:
    """Wrap a body in start marker, checksum and end marker."""
    return START_MARKER + body + _U16.pack(checksum(body)) + END_MARKER


def encode_packet(
    packet: PapillArrayPacket, index_size: int = 2, include_slip: bool = True, include_global: bool = True
) -> bytes:
    """One whole framed packet, as the controller sends it (blocks 1, 3, 4, 5, 6 and any unknown raw blocks)."""
    return frame_body(
        encode_body(packet, index_size=index_size, include_slip=include_slip, include_global=include_global)
    )


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


@dataclass
class _SensorLayout:
    """Where one sensor slot's values sit in the gathered float array (-1 = block absent)."""

    n_pillars: int
    pillar_at: int = -1  # n_pillars x (Fx Fy Fz Dx Dy Dz)
    global_at: int = -1  # Fx Fy Fz Tx Ty Tz
    friction_at: int = -1  # n_pillars friction estimates
    state_at: int = -1  # index into the gathered int8 slip states
    scalars_at: int = -1  # friction estimate, target grip force
    active_pos: int = -1  # body byte of the u8 slip detection state


class _Layout:
    """Positions of every field of one body shape, found once by walking a body; reused while the shape holds.

    ``struct_pos``/``struct_val`` are the body bytes that fix the shape (index size, index table, counts, offset
    tables, entry types): a later body with the same length and the same bytes there has the same layout.
    """

    def __init__(self, body: bytes) -> None:
        self.length = len(body)
        self._body = body
        self._struct_ranges: list[tuple[int, int]] = []
        self._float_ranges: list[tuple[int, int]] = []  # (body byte, n floats)
        self._n_floats = 0
        self._state_pos: list[int] = []
        self.hub_pos = -1
        self.unknown: list[tuple[int, int, int]] = []  # (block type, start, end)
        isz, entries, index_end = _read_index(body)
        self._isz = isz
        self._struct_ranges.append((0, index_end))
        types = [block_type for block_type, _ in entries]
        if BLOCK_PILLAR not in types:
            raise _bad(f"no block of type {BLOCK_PILLAR} (pillar data)")
        pillar_counts: list[int] = []
        globals_at: list[int] = []
        pillar_slip: list[tuple[int, int, int]] | None = None  # (n_pillars, state_at, friction_at)
        sensor_slip: list[tuple[int, int]] | None = None  # (active_pos, scalars_at)
        pillar_at: list[int] = []
        for position, (block_type, offset) in enumerate(entries):
            block_end = entries[position + 1][1] if position + 1 < len(entries) else len(body)
            self._pos = offset
            if block_type == BLOCK_HUB:
                self.hub_pos = self._need(_HUB.size, "hub block")
            elif block_type == BLOCK_PILLAR:
                for sensor in range(self._count("pillar block sensor count")):
                    n_pillars = self._count(f"sensor {sensor} pillar count")
                    pillar_counts.append(n_pillars)
                    pillar_at.append(self._n_floats)
                    for _ in range(n_pillars):
                        self._entry_type(_PILLAR_ENTRY_TYPE, f"sensor {sensor} pillar entry")
                        self._floats(6, f"sensor {sensor} pillar values")
            elif block_type == BLOCK_GLOBAL:
                for sensor in range(self._count("global block sensor count")):
                    self._entry_type(_GLOBAL_ENTRY_TYPE, f"sensor {sensor} global entry")
                    globals_at.append(self._floats(6, f"sensor {sensor} global values"))
            elif block_type == BLOCK_PILLAR_SLIP:
                pillar_slip = []
                for sensor in range(self._count("slip block sensor count")):
                    n_pillars = self._count(f"sensor {sensor} slip pillar count")
                    state_at, friction_at = len(self._state_pos), self._n_floats
                    for _ in range(n_pillars):
                        self._entry_type(_SLIP_ENTRY_TYPE, f"sensor {sensor} slip entry")
                        self._state_pos.append(self._need(1, "slip state"))
                        self._floats(1, f"sensor {sensor} pillar friction")
                    pillar_slip.append((n_pillars, state_at, friction_at))
            elif block_type == BLOCK_SENSOR_SLIP:
                sensor_slip = []
                for sensor in range(self._count("sensor slip block sensor count")):
                    self._entry_type(_SLIP_ENTRY_TYPE, f"sensor {sensor} sensor slip entry")
                    active_pos = self._need(1, "slip detection state")
                    sensor_slip.append((active_pos, self._floats(2, "friction estimate, target grip force")))
            else:
                self.unknown.append((block_type, offset, block_end))
                self._pos = block_end
            if self._pos > block_end:
                raise _bad(f"block type {block_type} overlaps the next block")
            if block_end == len(body) and self._pos != block_end:
                raise _bad(f"{block_end - self._pos} stray bytes after the last block")
        n_sensors = len(pillar_counts)
        if BLOCK_GLOBAL in types and len(globals_at) != n_sensors:
            raise _bad(f"pillar block has {n_sensors} sensors but global block has {len(globals_at)}")
        if pillar_slip is not None and len(pillar_slip) != n_sensors:
            raise _bad(f"pillar block has {n_sensors} sensors but pillar slip block has {len(pillar_slip)}")
        if sensor_slip is not None and len(sensor_slip) != n_sensors:
            raise _bad(f"pillar block has {n_sensors} sensors but sensor slip block has {len(sensor_slip)}")
        self.sensors: list[_SensorLayout] = []
        for index, n_pillars in enumerate(pillar_counts):
            global_at = globals_at[index] if globals_at else -1
            slot = _SensorLayout(n_pillars, pillar_at=pillar_at[index], global_at=global_at)
            if pillar_slip is not None:
                slip_pillars, slot.state_at, slot.friction_at = pillar_slip[index]
                if slip_pillars != n_pillars:
                    raise _bad(f"sensor {index}: {n_pillars} pillars but {slip_pillars} slip entries")
            if sensor_slip is not None:
                slot.active_pos, slot.scalars_at = sensor_slip[index]
            self.sensors.append(slot)
        self.struct_pos = _ranges_to_positions((start, length) for start, length in self._struct_ranges)
        self.struct_val = np.frombuffer(body, dtype=np.uint8)[self.struct_pos]
        self.float_bytes = _ranges_to_positions((start, 4 * n) for start, n in self._float_ranges)
        self.state_pos = np.array(self._state_pos, dtype=np.intp)
        del self._body

    # walking helpers (only used while building the layout)
    def _need(self, n: int, what: str) -> int:
        start = self._pos
        if start + n > len(self._body):
            raise _bad(f"{what} at body byte {start} runs past the end ({len(self._body)} bytes)")
        self._pos = start + n
        return start

    def _count(self, what: str) -> int:
        """A u16 count followed by its offset table (both fix the shape)."""
        start = self._need(2, what)
        n: int = _U16.unpack_from(self._body, start)[0]
        self._need(n * self._isz, f"{what} offset table")
        self._struct_ranges.append((start, self._pos - start))
        return n

    def _entry_type(self, expected: int, what: str) -> None:
        start = self._need(2, what)
        found = _U16.unpack_from(self._body, start)[0]
        if found != expected:
            raise _bad(f"{what} type {found}, expected {expected}")
        self._struct_ranges.append((start, 2))

    def _floats(self, n: int, what: str) -> int:
        """Record n float32 at the current position; returns their index in the gathered float array."""
        start = self._need(4 * n, what)
        self._float_ranges.append((start, n))
        first = self._n_floats
        self._n_floats += n
        return first

    def matches(self, u8: np.ndarray) -> bool:
        """True when a body (as uint8 array) has exactly this shape."""
        return len(u8) == self.length and bool(np.array_equal(u8[self.struct_pos], self.struct_val))

    def extract(self, body: bytes, u8: np.ndarray) -> PapillArrayPacket:
        with np.errstate(invalid="ignore"):  # a signalling NaN on the wire stays NaN, without a warning
            floats = u8[self.float_bytes].view("<f4").astype(np.float64)
        states = u8[self.state_pos].view(np.int8).astype(np.int64)
        counter, timestamp_us = _HUB.unpack_from(body, self.hub_pos) if self.hub_pos >= 0 else (None, None)
        sensors = []
        for layout in self.sensors:
            n = layout.n_pillars
            pillar_values = floats[layout.pillar_at : layout.pillar_at + 6 * n].reshape(n, 6)
            if layout.friction_at >= 0:
                slip_states = states[layout.state_at : layout.state_at + n]
                pillar_friction = floats[layout.friction_at : layout.friction_at + n]
            else:
                slip_states = np.zeros(n, dtype=np.int64)
                pillar_friction = np.full(n, NO_FRICTION_ESTIMATE)
            if layout.global_at >= 0:
                global_values = floats[layout.global_at : layout.global_at + 6]
            else:
                global_values = np.full(6, np.nan)  # no global block in this packet
            sensor = PillarSensorData(
                forces_n=pillar_values[:, :3],
                displacements_mm=pillar_values[:, 3:],
                global_force_n=global_values[:3],
                global_torque_nmm=global_values[3:],
                slip_states=slip_states,
                pillar_friction=pillar_friction,
            )
            if layout.active_pos >= 0:
                sensor.slip_active = body[layout.active_pos]
                sensor.friction_estimate = float(floats[layout.scalars_at])
                sensor.target_grip_force_n = float(floats[layout.scalars_at + 1])
            sensors.append(sensor)
        unknown = {block_type: body[start:end] for block_type, start, end in self.unknown}
        return PapillArrayPacket(counter, timestamp_us, sensors, unknown)


def _ranges_to_positions(ranges: Iterable[tuple[int, int]]) -> np.ndarray:
    parts = [np.arange(start, start + length, dtype=np.intp) for start, length in ranges]
    return np.concatenate(parts) if parts else np.zeros(0, dtype=np.intp)


def decode_body(body: bytes) -> PapillArrayPacket:
    """Decode a body (between start marker and checksum) whose checksum was already verified."""
    body = bytes(body)
    return _Layout(body).extract(body, np.frombuffer(body, dtype=np.uint8))


def _verified_body(frame: bytes | bytearray | memoryview) -> bytes:
    if len(frame) < _FRAMING_OVERHEAD + 1:
        raise _bad(f"{len(frame)} bytes is too short for a framed packet")
    if frame[:4] != START_MARKER:
        raise _bad(f"starts with {bytes(frame[:4]).hex(' ')}, not the start marker 55 66 77 88")
    if frame[-4:] != END_MARKER:
        raise _bad(f"ends with {bytes(frame[-4:]).hex(' ')}, not the end marker aa bb cc dd")
    body = bytes(frame[4:-6])
    sent = _U16.unpack_from(frame, len(frame) - 6)[0]
    computed = checksum(body)
    if sent != computed:
        raise _bad(f"checksum 0x{sent:04x} on the wire, 0x{computed:04x} computed")
    return body


def decode_packet(frame: bytes | bytearray | memoryview) -> PapillArrayPacket:
    """Decode one whole framed packet (start marker to end marker); ProtocolError says what is wrong."""
    return decode_body(_verified_body(frame))


_CHECKSUM_FAIL = "checksum"
_FRAMING_FAIL = "framing"


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
        self._clear()

    def _clear(self) -> None:
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

    def reset(self) -> None:
        """Forget buffered bytes (e.g. after reopening the port); counters are kept."""
        self._clear()

    def counters(self) -> dict[str, int]:
        return {
            "packets": self.packets,
            "bytes_dropped": self.bytes_dropped,
            "checksum_errors": self.checksum_errors,
            "framing_errors": self.framing_errors,
        }

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

    def _intact(self, start: int) -> tuple[PapillArrayPacket, int] | None:
        """(packet, end) for the first end that closes an intact packet from ``start``, if one has arrived."""
        return self._closed.get(start)

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
            intact = self._intact(start)
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
