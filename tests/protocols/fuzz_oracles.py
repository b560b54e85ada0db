"""The fuzz oracles the default suite's slice runs (tests/protocols/test_fuzz_slice.py): one target per wire codec,
each also driving its driver's decode path where there is one, and :func:`run_target`, which feeds a target seeded
inputs and counts crashes, wrong decodes and a long-lived decoder's memory growth.

These are the targets of the retired 100,000-input campaign (``git show b714727:benchmarks/fuzz.py``, whose table is
in docs/reliability.md); the draws are unchanged, so a slice with seed 28 is the first inputs of that campaign.
"""

from __future__ import annotations

import contextlib
import gc
import itertools
import json
import math
import struct
import tracemalloc
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import can
import numpy as np

from drivers.clock import VirtualClock
from drivers.papillarray import PapillArrayDriver
from drivers.uskin import UskinCanDriver, UskinXelaServerDriver
from protocols.errors import ProtocolError, UnitacError
from protocols.papillarray import (
    END_MARKER,
    MAX_PACKET_LEN,
    START_MARKER,
    PacketParser,
    PapillArrayPacket,
    PillarSensorData,
    checksum,
    encode_packet,
)
from protocols.papillarray_commands import VALID_RATES_HZ, Command, CommandParser, HubCommand, encode_command
from protocols.rtde import (
    FIELD_FORMATS,
    ControllerVersion,
    PackageType,
    RecipeReply,
    RtdePackage,
    RtdePackageParser,
    TextMessage,
    decode_accepted_reply,
    decode_controller_version_reply,
    decode_data_package,
    decode_protocol_version_reply,
    decode_recipe_reply,
    decode_request_protocol_version,
    decode_setup_inputs,
    decode_setup_outputs,
    decode_text_message,
    encode_accepted_reply,
    encode_controller_version_reply,
    encode_data_package,
    encode_protocol_version_reply,
    encode_recipe_reply,
    encode_setup_outputs,
    encode_text_message,
)
from protocols.xela_can import USPA46_ID_MAP, FrameAssembler
from protocols.xela_ws import MAX_COUNT, MAX_SERVER_TIME_S, XelaDataMessage, XelaSensorData, decode_message
from protocols.xela_ws import encode_data_message as encode_xela_message

Rng = np.random.Generator


@dataclass
class Case:
    """One fuzz input: its kind, the data, and what a correct decoder must give back (target-specific)."""

    kind: str
    data: Any
    expected: Any = None


class Target:
    """A codec under fuzz: ``draw`` builds one input, ``check`` runs it and returns (wrong decodes, valid placed,
    valid recovered), raising whatever the code under test raises; ``stream`` builds a long-lived consumer for the
    memory phase."""

    name = ""
    description = ""
    allowed: tuple[type[BaseException], ...] = (ProtocolError,)

    def draw(self, rng: Rng) -> Case:
        raise NotImplementedError

    def check(self, case: Case, rng: Rng) -> tuple[int, int, int]:
        raise NotImplementedError

    def stream(self) -> Callable[[Case], None]:
        raise NotImplementedError


# ---- shared generators ------------------------------------------------------------------------------------------


def random_bytes(rng: Rng, n: int) -> bytes:
    return rng.integers(0, 256, n, dtype=np.uint8).tobytes()


def random_chunks(rng: Rng, data: bytes) -> list[bytes]:
    """``data`` cut at random sizes: 1 byte, 7 bytes, USB packets, random, or whole."""
    mode = int(rng.integers(0, 5))
    if mode == 0 or len(data) < 2:
        return [data]
    if mode == 1:
        size = [1, 7, 64][int(rng.integers(0, 3))]
        return [data[i : i + size] for i in range(0, len(data), size)]
    cuts = np.sort(
        rng.choice(np.arange(1, len(data)), size=min(len(data) - 1, int(rng.integers(1, 40))), replace=False)
    )
    bounds = [0, *cuts.tolist(), len(data)]
    return [data[a:b] for a, b in itertools.pairwise(bounds)]


def flip_bits(rng: Rng, data: bytes, n: int) -> bytes:
    out = bytearray(data)
    for _ in range(n):
        if out:
            out[int(rng.integers(0, len(out)))] ^= 1 << int(rng.integers(0, 8))
    return bytes(out)


def mutate_bytes(rng: Rng, data: bytes) -> bytes:
    """A few random edits: bit flips, byte overwrites, cuts, duplications, insertions."""
    out = bytearray(data)
    for _ in range(int(rng.integers(1, 6))):
        op = int(rng.integers(0, 5))
        at = int(rng.integers(0, len(out) + 1))
        if op == 0 and out:
            out[min(at, len(out) - 1)] ^= 1 << int(rng.integers(0, 8))
        elif op == 1 and out:
            out[min(at, len(out) - 1)] = int(rng.integers(0, 256))
        elif op == 2:
            del out[at : at + int(rng.integers(1, 16))]
        elif op == 3:
            out[at:at] = out[at : at + int(rng.integers(1, 16))]
        else:
            out[at:at] = random_bytes(rng, int(rng.integers(1, 16)))
    return bytes(out)


def run_chunks(feed: Callable[[bytes], list[Any]], chunks: list[bytes]) -> list[Any]:
    out: list[Any] = []
    for chunk in chunks:
        out += feed(chunk)
    return out


def in_order(expected: list[Any], got: list[Any], same: Callable[[Any, Any], bool]) -> int:
    """How many of ``expected`` appear in ``got`` in order (extra items in ``got`` allowed)."""
    found = 0
    it = iter(got)
    for want in expected:
        for item in it:
            if same(want, item):
                found += 1
                break
        else:
            break
    return found


# ---- XELA uSkin CAN ---------------------------------------------------------------------------------------------

_IDS = USPA46_ID_MAP.ids
_N = len(_IDS)
_MS = 1_000_000


def _taxel_counts(cycle: int, index: int) -> tuple[int, int, int]:
    """Counts that name their cycle and taxel, so a frame shows which cycles it holds (x < 0xFA00: not a sentinel)."""
    return 1000 + cycle, 2000 + index, 30_000 + cycle


_TAXEL_PAYLOAD = struct.Struct(">BHHHB")  # what encode_taxel_message writes (tested there), packed directly for speed


def _taxel_payload(cycle: int, index: int) -> bytes:
    return _TAXEL_PAYLOAD.pack(0, 1000 + cycle, 2000 + index, 30_000 + cycle, 0)


class XelaCanTarget(Target):
    name = "xela_can"
    description = (
        "XELA uSkin CAN: FrameAssembler, and UskinCanDriver's pump over a fake bus (every 4th input); "
        "valid frames must hold exactly one cycle, except after a seamless splice (no wire can tell)"
    )

    def __init__(self) -> None:
        self._clock = VirtualClock()
        self._bus = _FakeCanBus(self._clock)
        self._driver = UskinCanDriver(self._bus, clock=self._clock)  # type: ignore[arg-type]
        self._driver_turn = 0

    def draw(self, rng: Rng) -> Case:
        kind = ["random", "mutated", "mutated", "embedded", "spliced", "spliced_any", "extreme"][
            int(rng.integers(0, 7))
        ]
        if kind == "random":
            return Case(kind, self._random_messages(rng))
        if kind == "extreme":
            return Case(kind, self._extreme_messages(rng))
        if kind == "embedded":
            messages, cycles = self._bursts(rng, int(rng.integers(13, 17)), loss=0.0, merge=0.0)
            for _ in range(int(rng.integers(1, 30))):  # garbage on ids the map does not have, anywhere
                at = int(rng.integers(0, len(messages) + 1))
                messages.insert(at, (int(rng.integers(0x000, 0x100)), random_bytes(rng, 8), -1))
            return Case(kind, self._timed(messages), expected=cycles)
        if kind in ("spliced", "spliced_any"):
            # "spliced": a controller that stops mid-cycle (power loss) and starts again at a cycle's start after a
            # silence. "spliced_any": any cut of one stream joined to any cut of another at any time; a seamless
            # join can itself be a whole cycle that no wire could tell from a real one, so only crashes and hangs
            # are judged there.
            a, _ = self._bursts(rng, int(rng.integers(2, 9)), loss=0.02, merge=0.1, joined=False)
            b, _ = self._bursts(rng, int(rng.integers(2, 9)), loss=0.02, merge=0.1, first_cycle=500, joined=False)
            head = self._timed(a[: int(rng.integers(0, len(a) + 1))])
            if kind == "spliced":
                tail = self._timed(b)
                gap = int(rng.integers(2, 50)) * _MS
            else:
                tail = self._timed(b[int(rng.integers(0, len(b))) :])
                gap = int(rng.integers(-50, 50)) * _MS
            if head and tail:
                shift = head[-1][2] - tail[0][2] + gap
                tail = [(i, d, t + shift) for i, d, t in tail]
            return Case(kind, head + tail)
        messages, _ = self._bursts(
            rng, int(rng.integers(3, 16)), loss=float(rng.choice([0.0, 0.01, 0.02, 0.1])), merge=float(rng.random()) / 3
        )
        for _ in range(int(rng.integers(0, 4))):  # damage the codec must see: sentinels, short payloads, repeats
            if not messages:
                break
            at = int(rng.integers(0, len(messages)))
            arbitration_id, data, t = messages[at]
            op = int(rng.integers(0, 3))
            if op == 0:
                messages[at] = (arbitration_id, b"\x00\xfa" + data[2:], t)
            elif op == 1:
                messages[at] = (arbitration_id, data[: int(rng.integers(0, 7))], t)
            else:
                messages.insert(at, messages[at])
        return Case(kind, self._timed(messages))

    @staticmethod
    def _timed(messages: list[tuple[int, bytes, int]]) -> list[tuple[int, bytes, int]]:
        """Give inserted garbage (time -1) the time of the message before it."""
        out: list[tuple[int, bytes, int]] = []
        last = 0
        for arbitration_id, data, t in messages:
            last = last if t < 0 else t
            out.append((arbitration_id, data, last))
        return out

    def _bursts(
        self, rng: Rng, n_cycles: int, *, loss: float, merge: float, first_cycle: int = 0, joined: bool = True
    ) -> tuple[list[tuple[int, bytes, int]], list[int]]:
        """Cycles as bursts (0.1 ms apart, 10 ms period) in id order, XELA's order or a new order each cycle; each
        message lost with ``loss``, each burst read straight after the previous one with ``merge``; with ``joined``,
        joined mid-cycle one time in four."""
        order_mode = int(rng.integers(0, 3))
        messages: list[tuple[int, bytes, int]] = []
        t_ns = 0
        for k in range(n_cycles):
            cycle = first_cycle + k
            if order_mode == 0:
                order = sorted(range(_N), key=lambda i: _IDS[i])
            elif order_mode == 1:
                order = list(range(_N))
            else:
                order = [int(i) for i in rng.permutation(_N)]
            t_ns = t_ns + 100_000 if k and rng.random() < merge else (k * 10 + int(rng.integers(0, 2))) * _MS
            kept = rng.random(_N) >= loss if loss else np.ones(_N, dtype=bool)
            for step, index in enumerate(order):
                if kept[step]:
                    messages.append((_IDS[index], _taxel_payload(cycle, index), t_ns + step * 100_000))
            t_ns += (_N - 1) * 100_000
        if joined and rng.random() < 0.25:
            messages = messages[int(rng.integers(1, _N)) :]
        return messages, list(range(first_cycle, first_cycle + n_cycles))

    @staticmethod
    def _random_messages(rng: Rng) -> list[tuple[int, bytes, int]]:
        n = int(rng.integers(1, 100))
        ids = np.where(rng.random(n) < 0.7, rng.choice(np.array(_IDS), n), rng.integers(0, 0x800, n))
        t = np.cumsum(rng.choice([0, 1, 100_000, 3 * _MS, -_MS], n))
        return [(int(i), random_bytes(rng, int(rng.integers(0, 9))), int(tt)) for i, tt in zip(ids, t, strict=True)]

    @staticmethod
    def _extreme_messages(rng: Rng) -> list[tuple[int, bytes, int]]:
        times = [0, 1, -1, 2**62, -(2**62), 2**63 - 1, -(2**63)]
        payloads = [b"", b"\x00", bytes(7), b"\xff" * 8, b"\x00\xf9\xff\xff\xff\xff\xff", bytes(64), b"\x07\x00"]
        out = []
        for _ in range(int(rng.integers(1, 80))):
            arbitration_id = int(rng.choice([0, 0x100, 0x135, 0x200, 0x201, 0x7FF, *_IDS]))
            out.append((arbitration_id, payloads[int(rng.integers(0, len(payloads)))], times[int(rng.integers(0, 7))]))
        return out

    def check(self, case: Case, rng: Rng) -> tuple[int, int, int]:
        assembler = FrameAssembler(USPA46_ID_MAP)
        frames = [f for m in case.data if (f := assembler.add(*m)) is not None]
        wrong = placed = recovered = 0
        for frame in frames:
            if frame.valid and not self._one_cycle(frame.values) and case.kind != "spliced_any":
                wrong += 1  # a frame flagged valid that is not exactly one cycle's counts
        if case.kind == "embedded":
            valid_cycles = [int(f.values[0, 0]) - 1000 for f in frames if f.valid]
            must = case.expected[10:-1]  # after the marks are learned; the last waits for its end mark
            placed = len(must)
            recovered = sum(1 for c in must if c in valid_cycles)
            wrong += placed - recovered
        self._driver_turn += 1
        if self._driver_turn % 4 == 0:
            wrong += self._through_driver(case)
        return wrong, placed, recovered

    @staticmethod
    def _one_cycle(values: np.ndarray) -> bool:
        cycle = int(values[0, 0]) - 1000
        return bool(np.array_equal(values, np.array([_taxel_counts(cycle, i) for i in range(_N)])))

    def _through_driver(self, case: Case) -> int:
        """The same messages through UskinCanDriver's pump (error, remote and extended frames mixed in); valid
        frames must still be exactly one cycle."""
        self._driver._open()  # a fresh assembler, as on connect
        self._bus.load(case.data)
        wrong = 0
        while self._bus.pending():
            for frame in self._driver._pump(0.0):
                wrong += frame.valid and not self._one_cycle(frame.values) and case.kind != "spliced_any"
        return wrong

    def stream(self) -> Callable[[Case], None]:
        assembler = FrameAssembler(USPA46_ID_MAP)

        def feed(case: Case) -> None:
            for message in case.data:
                assembler.add(*message)

        return feed


class _FakeCanBus:
    """Hands the driver python-can messages from a list, moving the virtual clock to each message's time."""

    channel_info = "fuzz"

    def __init__(self, clock: VirtualClock) -> None:
        self._clock = clock
        self._messages: list[can.Message] = []
        self._times: list[int] = []

    def load(self, messages: list[tuple[int, bytes, int]]) -> None:
        self._messages, self._times = [], []
        for n, (arbitration_id, data, t_ns) in enumerate(messages):
            kind = n % 17
            self._messages.append(
                can.Message(
                    arbitration_id=arbitration_id if kind != 5 else arbitration_id | 0x1000_0000,
                    data=data[:8],
                    is_extended_id=kind == 5,
                    is_error_frame=kind == 11,
                    is_remote_frame=kind == 13,
                    check=False,
                )
            )
            self._times.append(t_ns)
        self._messages.reverse()
        self._times.reverse()

    def pending(self) -> bool:
        return bool(self._messages)

    def recv(self, timeout: float | None = None) -> can.Message | None:
        if not self._messages:
            return None
        t_ns = self._times.pop()
        if t_ns > self._clock.now_ns():
            self._clock.advance_ns(min(t_ns - self._clock.now_ns(), 10**15))
        return self._messages.pop()

    def send(self, message: can.Message, timeout: float | None = None) -> None:
        pass


# ---- xela_server JSON -------------------------------------------------------------------------------------------

_EXTREME_JSON = [
    "1" + "0" * 400,
    "-1",
    "1e303",
    "-1e308",
    "1e400",
    "NaN",
    "Infinity",
    "-Infinity",
    "-0",
    "0.5",
    "true",
    "null",
    '""',
    "[]",
    "{}",
    str(2**63),
    str(2**64),
    '"-FFF"',
    '"0x1F"',
    '"F_FF"',
    '"\\u0661\\u0662\\u0663\\u0664"',
    '"FFFFF"',
    '" FFF"',
    '"' + "A" * 5000 + '"',
]
_HEX_TOKENS = ["-FFF", "0x1F", "F_FF", "\u0661\u0662\u0663\u0664", "+FFF", " FFF", "FFF", "FFFFF", "ffff", "0000"]


class XelaWsTarget(Target):
    name = "xela_ws"
    description = "xela_server JSON: decode_message, and UskinXelaServerDriver's frame path on what it accepts"
    allowed = (UnitacError,)

    def __init__(self) -> None:
        self._driver = UskinXelaServerDriver("ws://fuzz.invalid:5000", clock=VirtualClock())

    def draw(self, rng: Rng) -> Case:
        kind = ["random", "valid", "mutated", "fields", "hex", "deep", "non_utf8"][int(rng.integers(0, 7))]
        if kind == "random":
            data: str | bytes = random_bytes(rng, int(rng.integers(0, 400)))
            if rng.random() < 0.5:
                data = "".join(chr(int(c)) for c in rng.integers(32, 127, int(rng.integers(0, 300))))
            return Case(kind, data)
        if kind == "deep":
            depth = int(rng.choice([100, 1000, 10_000, 100_000]))
            opener, closer = ('{"a": ', "}") if rng.random() < 0.5 else ("[", "]")
            body = opener * depth + "1" + closer * depth * int(rng.integers(0, 2))
            return Case(kind, '{"message": 1, "time": 1.0, "1": ' + body + "}")
        text, sensors = self._valid(rng)
        if kind == "valid":
            return Case(kind, text, expected=sensors)
        if kind == "non_utf8":
            raw = bytearray(text.encode())
            at = int(rng.integers(0, len(raw)))
            raw[at:at] = bytes([0xFF, 0xC3, 0x28, 0x80][: int(rng.integers(1, 5))])
            return Case(kind, bytes(raw))
        if kind == "mutated":
            return Case(kind, mutate_bytes(rng, text.encode()))
        if kind == "hex":
            tokens = text.split('"data": "', 1)
            if len(tokens) == 2:
                items = tokens[1].split(",")
                items[int(rng.integers(0, min(len(items), 72)))] = _HEX_TOKENS[int(rng.integers(0, len(_HEX_TOKENS)))]
                return Case(kind, tokens[0] + '"data": "' + ",".join(items))
            return Case(kind, text)
        obj = json.loads(text)  # fields: one field set to an extreme JSON value
        paths = [
            ("message",),
            ("time",),
            ("sensors",),
            ("type",),
            ("1", "taxels"),
            ("1", "data"),
            ("1", "calibrated"),
            ("1", "sensor"),
            ("1", "model"),
        ]
        path = paths[int(rng.integers(0, len(paths)))]
        marker = "__FUZZ__"
        target = obj
        for key in path[:-1]:
            target = target[key]
        target[path[-1]] = marker
        value = _EXTREME_JSON[int(rng.integers(0, len(_EXTREME_JSON)))]
        if path == ("1", "calibrated") or (path == ("1", "data") and rng.random() < 0.5):
            value = "[" + ", ".join([value] + ["1"] * 71) + "]"
        return Case(kind, json.dumps(obj).replace(f'"{marker}"', value))

    @staticmethod
    def _valid(rng: Rng) -> tuple[str, list[XelaSensorData]]:
        sensors = []
        for number in range(1, int(rng.integers(1, 3)) + 1):
            counts = rng.integers(0, MAX_COUNT + 1, (24, 3))
            calibrated = rng.normal(0, 2, (24, 3)) if rng.random() < 0.3 else None
            sensors.append(XelaSensorData(number, "uSPa46", 24, counts, calibrated))
        seq = int(rng.integers(0, 2**40))
        text = encode_xela_message(seq, float(rng.uniform(0, 2e9)), sensors, as_hex=bool(rng.random() < 0.5))
        return text, sensors

    def check(self, case: Case, rng: Rng) -> tuple[int, int, int]:
        try:
            message = decode_message(case.data)
        except ProtocolError:
            return (1, 1, 0) if case.expected is not None else (0, 0, 0)
        wrong = 0
        if isinstance(message, XelaDataMessage):
            wrong += not (0 <= message.server_time_s <= MAX_SERVER_TIME_S and 0 <= message.seq < 2**63)
            for sensor in message.sensors.values():
                values = sensor.values
                wrong += not (
                    values.dtype.kind == "i" and values.min(initial=0) >= 0 and values.max(initial=0) <= MAX_COUNT
                )
                if sensor.calibrated is not None:
                    wrong += not bool(np.isfinite(sensor.calibrated).all())
            self._driver.sensor_number = next(iter(message.sensors), 1)
            with contextlib.suppress(UnitacError):  # a run of wrong-sized sensors: the driver's answer, with a hint
                self._driver._frame(message)  # the driver's own path: device time, flags, shape check
        if case.expected is None:
            return wrong, 0, 0
        placed = len(case.expected)
        got = message.sensors if isinstance(message, XelaDataMessage) else {}
        recovered = sum(
            1
            for s in case.expected
            if s.sensor_number in got
            and np.array_equal(got[s.sensor_number].values, s.values)
            and (s.calibrated is None) == (got[s.sensor_number].calibrated is None)
        )
        return wrong + placed - recovered, placed, recovered

    def stream(self) -> Callable[[Case], None]:
        def feed(case: Case) -> None:
            with contextlib.suppress(ProtocolError):
                decode_message(case.data)

        return feed


# ---- PapillArray packets ----------------------------------------------------------------------------------------

_SPECIAL_FLOATS = np.array([np.nan, np.inf, -np.inf, 3.4e38, -3.4e38, 1e-45, -0.0], dtype=np.float32)


def _papillarray_packet(rng: Rng, counter: int) -> PapillArrayPacket:
    n_sensors = int(rng.choice([2, 2, 2, 1, 3]))
    n_pillars = int(rng.choice([9, 9, 9, 1, 4, 16]))
    sensors = []
    for _ in range(n_sensors):
        sensor = PillarSensorData.unloaded(n_pillars)
        sensor.forces_n[:] = rng.normal(0, 3, (n_pillars, 3)).astype(np.float32)
        sensor.displacements_mm[:] = rng.normal(0, 0.5, (n_pillars, 3)).astype(np.float32)
        if rng.random() < 0.1:  # NaN, inf, huge: what a float32 on the wire can hold
            sensor.forces_n[int(rng.integers(0, n_pillars)), int(rng.integers(0, 3))] = rng.choice(_SPECIAL_FLOATS)
        sensor.slip_states[:] = rng.integers(-2, 3, n_pillars)
        sensors.append(sensor)
    if rng.random() < 0.1:
        return PapillArrayPacket(None, None, sensors)
    return PapillArrayPacket(counter, int(rng.integers(0, 2**63)), sensors)


def _encode_papillarray(rng: Rng, packet: PapillArrayPacket) -> bytes:
    """The packet framed with a random index size and optional blocks, at most the SDK's 2048 bytes (a longer one is
    not a valid packet: slots beyond the first two are dropped until it fits)."""
    index_size = int(rng.choice([2, 2, 2, 3, 4]))
    include_slip, include_global = bool(rng.random() < 0.7), bool(rng.random() < 0.9)
    while True:
        frame = encode_packet(packet, index_size=index_size, include_slip=include_slip, include_global=include_global)
        if len(frame) <= MAX_PACKET_LEN or len(packet.sensors) == 1:
            return frame
        packet.sensors = packet.sensors[:-1]


def _marker_dense(rng: Rng, n: int) -> bytes:
    pieces = [START_MARKER, END_MARKER, START_MARKER + bytes(3), b"\x00\x00" + END_MARKER, START_MARKER[:3]]
    out = bytearray()
    while len(out) < n:
        if rng.random() < 0.7:
            out += pieces[int(rng.integers(0, len(pieces)))]
        else:
            out += random_bytes(rng, int(rng.integers(1, 5)))
    return bytes(out)


def _garbage(rng: Rng, n: int) -> bytes:
    return _marker_dense(rng, n) if rng.random() < 0.5 else random_bytes(rng, n)


def _same_packet(a: PapillArrayPacket, b: PapillArrayPacket) -> bool:
    if (a.counter, a.timestamp_us, len(a.sensors)) != (b.counter, b.timestamp_us, len(b.sensors)):
        return False
    return all(
        np.array_equal(x.forces_n.astype(np.float32), y.forces_n.astype(np.float32), equal_nan=True)
        and np.array_equal(x.displacements_mm.astype(np.float32), y.displacements_mm.astype(np.float32), equal_nan=True)
        for x, y in zip(a.sensors, b.sensors, strict=True)
    )


class PapillArrayTarget(Target):
    name = "papillarray"
    description = "PapillArray packets: PacketParser on chunked streams, and PapillArrayDriver's pump (every 4th)"
    allowed = (UnitacError,)

    def __init__(self) -> None:
        self._driver = PapillArrayDriver("loop://", clock=VirtualClock(), rate_hz=1000)
        self._driver_turn = 0

    def draw(self, rng: Rng) -> Case:
        kind = ["random", "marker_dense", "embedded", "embedded", "mutated", "spliced", "extreme"][
            int(rng.integers(0, 7))
        ]
        if kind == "random":
            return Case(kind, random_chunks(rng, random_bytes(rng, int(rng.integers(0, 3000)))), expected=[])
        if kind == "marker_dense":
            return Case(kind, random_chunks(rng, _marker_dense(rng, int(rng.integers(100, 2500)))), expected=[])
        packets = [_papillarray_packet(rng, int(rng.integers(0, 2**32))) for _ in range(int(rng.integers(1, 5)))]
        frames = [_encode_papillarray(rng, p) for p in packets]
        if kind == "embedded":
            parts = []
            for frame in frames:
                parts += [_garbage(rng, int(rng.integers(0, 300))), frame]
            stream = b"".join(parts) + _garbage(rng, int(rng.integers(0, 100)))
            return Case(kind, random_chunks(rng, stream), expected=packets)
        if kind == "mutated":
            damaged = int(rng.integers(0, len(frames)))
            frames[damaged] = mutate_bytes(rng, frames[damaged])
            intact = [p for i, p in enumerate(packets) if i != damaged]
            return Case(kind, random_chunks(rng, b"".join(frames)), expected=intact)
        if kind == "spliced":
            stream = b"".join(frames)
            other = b"".join(_encode_papillarray(rng, _papillarray_packet(rng, 7)) for _ in range(2))
            cut, cut_other = int(rng.integers(0, len(stream))), int(rng.integers(0, len(other)))
            return Case(kind, random_chunks(rng, stream[:cut] + other[cut_other:]))
        # extreme: structure fields pushed to their limits, the checksum made right again so only structure is wrong
        body = bytearray(frames[0][4:-6])
        for _ in range(int(rng.integers(1, 4))):
            at = int(rng.integers(0, min(len(body), 64)))
            body[at] = int(rng.choice([0x00, 0x01, 0x04, 0x05, 0x7F, 0x80, 0xFF]))
        frame = START_MARKER + bytes(body) + (checksum(body) & 0xFFFF).to_bytes(2, "little") + END_MARKER
        return Case(kind, random_chunks(rng, frame + frames[-1]), expected=packets[-1:] if len(frames) > 1 else [])

    def check(self, case: Case, rng: Rng) -> tuple[int, int, int]:
        parser = PacketParser()
        got = run_chunks(parser.feed, case.data)
        placed = len(case.expected) if case.expected is not None else 0
        recovered = in_order(case.expected or [], got, _same_packet)
        self._driver_turn += 1
        if self._driver_turn % 4 == 0:
            self._through_driver(case.data)
        return placed - recovered, placed, recovered

    def _through_driver(self, chunks: list[bytes]) -> None:
        """The same bytes through PapillArrayDriver's pump: decode, counter gaps, slot and shape checks, physics."""
        driver = self._driver
        driver._parser.reset()
        driver._port = _FakePort(chunks)
        while driver._port.chunks:
            with contextlib.suppress(UnitacError):  # a run of packets with another pillar count: the answer
                driver._pump(0.0)

    def stream(self) -> Callable[[Case], None]:
        parser = PacketParser()

        def feed(case: Case) -> None:
            run_chunks(parser.feed, case.data)

        return feed


class _FakePort:
    """A serial port that hands over one chunk per read."""

    def __init__(self, chunks: list[bytes]) -> None:
        self.chunks = list(reversed(chunks))

    def read(self, size: int) -> bytes:
        return self.chunks.pop() if self.chunks else b""


# ---- PapillArray commands ---------------------------------------------------------------------------------------

_COMMANDS = [encode_command(Command.BIAS), encode_command(Command.START_SLIP), encode_command(Command.STOP_SLIP)] + [
    encode_command(Command.SET_RATE, rate) for rate in VALID_RATES_HZ
]


class PapillArrayCommandTarget(Target):
    name = "papillarray_commands"
    description = "PapillArray host commands: CommandParser on chunked streams, encode_command on any arguments"

    def draw(self, rng: Rng) -> Case:
        kind = ["random", "embedded", "mutated", "extreme_args"][int(rng.integers(0, 4))]
        if kind == "random":
            return Case(kind, random_chunks(rng, random_bytes(rng, int(rng.integers(0, 500)))), expected=[])
        if kind == "extreme_args":
            rate = rng.choice(np.array([None, 0, -1, 100, 1000, 999, 2**40, True, 250.0, math.nan], dtype=object))
            return Case(kind, (list(Command)[int(rng.integers(0, len(Command)))], rate))
        lines = [_COMMANDS[int(i)] for i in rng.integers(0, len(_COMMANDS), int(rng.integers(1, 8)))]
        if kind == "mutated":
            return Case(kind, random_chunks(rng, mutate_bytes(rng, b"".join(lines))))
        parts = []
        for line in lines:  # garbage lines (ending in a newline of their own) between real commands
            noise = random_bytes(rng, int(rng.integers(0, 60))).replace(b"\n", b"")
            parts += [noise + b"\n", line]
        return Case(kind, random_chunks(rng, b"".join(parts)), expected=lines)

    def check(self, case: Case, rng: Rng) -> tuple[int, int, int]:
        if case.kind == "extreme_args":
            command, rate = case.data
            encoded = encode_command(command, rate)  # ProtocolError for what a hub does not take
            return int(encoded not in _COMMANDS), 0, 0
        parser = CommandParser()
        got: list[HubCommand] = run_chunks(parser.feed, case.data)
        if not case.expected:
            return 0, 0, 0
        want = [CommandParser().feed(line)[0] for line in case.expected]
        recovered = in_order(want, got, lambda a, b: a == b)
        return len(want) - recovered, len(want), recovered

    def stream(self) -> Callable[[Case], None]:
        parser = CommandParser()

        def feed(case: Case) -> None:
            if case.kind != "extreme_args":
                run_chunks(parser.feed, case.data)

        return feed


# ---- RTDE -------------------------------------------------------------------------------------------------------

_DECODERS: dict[int, Callable[[bytes], Any]] = {
    PackageType.REQUEST_PROTOCOL_VERSION: decode_protocol_version_reply,
    PackageType.GET_URCONTROL_VERSION: decode_controller_version_reply,
    PackageType.CONTROL_PACKAGE_SETUP_OUTPUTS: decode_recipe_reply,
    PackageType.CONTROL_PACKAGE_SETUP_INPUTS: decode_recipe_reply,
    PackageType.CONTROL_PACKAGE_START: decode_accepted_reply,
    PackageType.CONTROL_PACKAGE_PAUSE: decode_accepted_reply,
    PackageType.TEXT_MESSAGE: decode_text_message,
}
_REQUEST_DECODERS: list[Callable[[bytes], Any]] = [
    decode_request_protocol_version,
    decode_setup_inputs,
    decode_setup_outputs,
]
_FIELD_TYPES = sorted(FIELD_FORMATS)


class RtdeTarget(Target):
    name = "rtde"
    description = "UR RTDE: RtdePackageParser on chunked streams, every package decoder on any payload"

    def draw(self, rng: Rng) -> Case:
        kind = ["random", "valid", "mutated", "payloads", "extreme"][int(rng.integers(0, 5))]
        if kind == "random":
            return Case(kind, random_chunks(rng, random_bytes(rng, int(rng.integers(0, 2000)))))
        if kind == "payloads":
            return Case(kind, random_bytes(rng, int(rng.integers(0, 300))))
        packages = [self._package(rng) for _ in range(int(rng.integers(1, 8)))]
        stream = b"".join(encoded for encoded, _ in packages)
        if kind == "valid":
            return Case(kind, random_chunks(rng, stream), expected=packages)
        if kind == "mutated":
            return Case(kind, random_chunks(rng, mutate_bytes(rng, stream)))
        # extreme length fields: a header claiming up to 65535 bytes, or fewer than its own 3
        header = int(rng.choice([0, 1, 2, 3, 0xFFFF, 0x8000])).to_bytes(2, "big") + bytes([int(rng.choice([85, 86]))])
        return Case(kind, random_chunks(rng, header + stream))

    @staticmethod
    def _package(rng: Rng) -> tuple[bytes, tuple[str, Any]]:
        choice = int(rng.integers(0, 7))
        if choice == 0:
            version = ControllerVersion(*(int(v) for v in rng.integers(0, 2**32, 4)))
            return encode_controller_version_reply(version), ("controller", version)
        if choice == 1:
            names = tuple(_FIELD_TYPES[int(i)] for i in rng.integers(0, len(_FIELD_TYPES), int(rng.integers(1, 6))))
            reply = RecipeReply(int(rng.integers(0, 256)), names)
            return encode_recipe_reply(PackageType.CONTROL_PACKAGE_SETUP_OUTPUTS, reply), ("recipe", reply)
        if choice == 2:
            types = [_FIELD_TYPES[int(i)] for i in rng.integers(0, len(_FIELD_TYPES), int(rng.integers(1, 6)))]
            values = [_field_value(rng, t) for t in types]
            return encode_data_package(int(rng.integers(0, 256)), types, values), ("data", (types, values))
        if choice == 3:
            text = TextMessage(
                "".join(chr(int(c)) for c in rng.integers(32, 127, int(rng.integers(0, 60)))),
                "fuzz",
                int(rng.integers(0, 256)),
            )
            return encode_text_message(text), ("text", text)
        if choice == 4:
            return encode_protocol_version_reply(bool(rng.random() < 0.5)), ("flag", None)
        if choice == 5:
            return encode_accepted_reply(PackageType.CONTROL_PACKAGE_START, True), ("flag", None)
        frequency = float(rng.choice([125.0, 500.0, math.nan, math.inf, -1.0, 1e308]))
        return encode_setup_outputs(frequency, ["timestamp", "actual_q"], trailing_comma=True), ("outputs", None)

    def check(self, case: Case, rng: Rng) -> tuple[int, int, int]:
        if case.kind == "payloads":
            for decoder in [*_DECODERS.values(), *_REQUEST_DECODERS]:
                with contextlib.suppress(ProtocolError):
                    decoder(case.data)
            types = [_FIELD_TYPES[int(i)] for i in rng.integers(0, len(_FIELD_TYPES), int(rng.integers(0, 6)))]
            with contextlib.suppress(ProtocolError):
                decode_data_package(case.data, types)
            return 0, 0, 0
        parser = RtdePackageParser()
        got: list[RtdePackage] = run_chunks(parser.feed, case.data)
        for package in got:
            decode = _DECODERS.get(package.type)
            if decode is not None:
                with contextlib.suppress(ProtocolError):
                    decode(package.payload)
        if case.expected is None:
            return 0, 0, 0
        recovered = 0
        for package, (encoded, (what, value)) in zip(got, case.expected, strict=False):
            same = package.encode() == encoded
            if same and what == "data":
                types, values = value
                _, decoded = decode_data_package(package.payload, types)
                same = _same_values(decoded, values)
            elif same and what in ("controller", "recipe", "text"):
                same = _DECODERS[package.type](package.payload) == value
            recovered += same
        return len(case.expected) - recovered, len(case.expected), recovered

    def stream(self) -> Callable[[Case], None]:
        parser = RtdePackageParser()

        def feed(case: Case) -> None:
            if case.kind != "payloads":
                run_chunks(parser.feed, case.data)

        return feed


def _field_value(rng: Rng, field_type: str) -> Any:
    code = FIELD_FORMATS[field_type]
    count = int(code[:-1]) if len(code) > 1 else 1
    kind = code[-1]

    def one() -> Any:
        if kind == "d":
            return float(rng.choice([0.0, 1.5, -2.25, math.nan, math.inf, 1e308, -1e-308]))
        if kind == "?":
            return bool(rng.random() < 0.5)
        bits = {"B": (0, 2**8), "i": (-(2**31), 2**31), "I": (0, 2**32), "Q": (0, 2**63)}[kind]
        return int(rng.integers(*bits))

    return tuple(one() for _ in range(count)) if count > 1 else one()


def _same_values(a: list[Any], b: list[Any]) -> bool:
    flat_a = np.array([x for v in a for x in (v if isinstance(v, tuple) else (v,))], dtype=np.float64)
    flat_b = np.array([x for v in b for x in (v if isinstance(v, tuple) else (v,))], dtype=np.float64)
    return bool(np.array_equal(flat_a, flat_b, equal_nan=True))


# ---- the runner -------------------------------------------------------------------------------------------------

TARGETS: dict[str, Callable[[], Target]] = {
    "xela_can": XelaCanTarget,
    "xela_ws": XelaWsTarget,
    "papillarray": PapillArrayTarget,
    "papillarray_commands": PapillArrayCommandTarget,
    "rtde": RtdeTarget,
}
MAX_MEMORY_GROWTH_BYTES = 256 * 1024  # a decoder that keeps more than this after hundreds of inputs is leaking


@dataclass
class Report:
    """What one target did with its inputs; ``examples`` names the first findings by input number."""

    inputs: int = 0
    kinds: Counter[str] = field(default_factory=Counter)
    crashes: int = 0
    wrong_decodes: int = 0
    valid_embedded: int = 0  # valid packets/messages placed among garbage and damage
    valid_recovered: int = 0
    memory_growth_bytes: int = 0
    examples: list[str] = field(default_factory=list)


def _rng(seed: int, target_name: str, index: int) -> Rng:
    """The input numbered ``index`` is drawn from ``(seed, target number, index)``, so any one can be rebuilt."""
    return np.random.default_rng((seed, list(TARGETS).index(target_name), index))


def run_target(name: str, n_inputs: int, seed: int, memory_inputs: int = 0) -> Report:
    """Feed ``n_inputs`` inputs to one target. A crash is any exception outside the target's ``allowed`` errors (the
    project's error tree); a valid input refused counts as wrong. Then ``memory_inputs`` more go back to back to one
    long-lived decoder under tracemalloc."""
    target = TARGETS[name]()
    report = Report()
    for index in range(n_inputs):
        rng = _rng(seed, name, index)
        case = target.draw(rng)
        report.inputs += 1
        report.kinds[case.kind] += 1
        try:
            wrong, placed, recovered = target.check(case, rng)
        except target.allowed:
            recovered = 0
            wrong = placed = (len(case.expected) if isinstance(case.expected, list) else 1) if case.expected else 0
        except Exception as exc:  # everything else is what the fuzzing looks for
            report.crashes += 1
            report.examples.append(f"input {index} ({case.kind}): {type(exc).__name__}: {exc}"[:300])
            continue
        report.valid_embedded += placed
        report.valid_recovered += recovered
        if wrong:
            report.wrong_decodes += wrong
            report.examples.append(f"input {index} ({case.kind}): {wrong} wrong of {placed} placed")
    if memory_inputs:
        report.memory_growth_bytes = memory_growth(target, seed + 1, memory_inputs)
    return report


def memory_growth(target: Target, seed: int, n: int) -> int:
    """Bytes one long-lived decoder gains between a fifth of ``n`` inputs and all of them."""
    feed = target.stream()
    cases = [target.draw(_rng(seed, target.name, index)) for index in range(n)]
    fifth = max(1, n // 5)
    gc.collect()
    tracemalloc.start()
    try:
        for case in cases[:fifth]:
            with contextlib.suppress(*target.allowed):
                feed(case)
        gc.collect()
        early = tracemalloc.get_traced_memory()[0]
        for case in cases[fifth:]:
            with contextlib.suppress(*target.allowed):
                feed(case)
        gc.collect()
        return tracemalloc.get_traced_memory()[0] - early
    finally:
        tracemalloc.stop()
