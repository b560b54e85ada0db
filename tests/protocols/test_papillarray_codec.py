"""PapillArray stream codec: packets written out byte by byte, round trips, and streams cut, corrupted and buried."""

from __future__ import annotations

import itertools
import random

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from protocols.errors import ProtocolError
from protocols.papillarray import (
    END_MARKER,
    START_MARKER,
    PacketParser,
    PapillArrayPacket,
    PillarSensorData,
    decode_packet,
    encode_body,
    encode_packet,
)
from protocols.papillarray_commands import VALID_RATES_HZ, Command, CommandParser, HubCommand, encode_command

# ------------------------------------------------------------------------------------------ golden vector no. 1
# One sensor slot, one pillar, index size 1, blocks hub (1), pillar (3), global (4). Offsets count from body byte 0.
# float32 little-endian: 0.5 = 00 00 00 3f, -1.0 = 00 00 80 bf, 2.0 = 00 00 00 40, 1.0 = 00 00 80 3f, 4.0 = 00 00 80 40
GOLDEN_1 = bytes.fromhex(
    "55 66 77 88"  # start marker
    "01"  # body byte 0: index size 1
    "01 00 0a"  # hub block at body byte 10
    "03 00 16"  # pillar block at 22
    "04 00 36"  # global block at 54
    "04 03 02 01"  # (10) hub: counter 0x01020304
    "40 42 0f 00 00 00 00 00"  # timestamp 1_000_000 us
    "01 00 19"  # (22) pillar block: 1 sensor, sensor 0 at 25
    "01 00 1c"  # (25) sensor 0: 1 pillar, pillar 0 at 28
    "02 00"  # (28) entry type 2
    "00 00 00 3f 00 00 80 bf 00 00 00 40"  # Fx 0.5, Fy -1, Fz 2 (N)
    "00 00 00 00 00 00 00 00 00 00 80 3f"  # Dx 0, Dy 0, Dz 1 (mm)
    "01 00 39"  # (54) global block: 1 sensor at 57
    "02 00"  # (57) entry type 2
    "00 00 00 3f 00 00 80 bf 00 00 00 40"  # Fx 0.5, Fy -1, Fz 2 (N)
    "00 00 00 00 00 00 00 00 00 00 80 40"  # Tx 0, Ty 0, Tz 4 (N*mm)
    # checksum = 1 + (1+10 + 3+22 + 4+54) + (10 + 145) + (26 + 29 + 2 + 637) + (58 + 2 + 638) = 1642 = 0x066a
    "6a 06"
    "aa bb cc dd"  # end marker
)

# ------------------------------------------------------------------------------------------ golden vector no. 2
# The same reading with the slip blocks 5 and 6 too (so every offset moves).
GOLDEN_2 = bytes.fromhex(
    "55 66 77 88 01"
    "01 00 10  03 00 1c  04 00 3c  05 00 59  06 00 66"  # index: hub 16, pillar 28, global 60, 5 at 89, 6 at 102
    "04 03 02 01 40 42 0f 00 00 00 00 00"  # (16) hub
    "01 00 1f  01 00 22  02 00"  # (28) pillar block, sensor 0 at 31, pillar 0 at 34
    "00 00 00 3f 00 00 80 bf 00 00 00 40 00 00 00 00 00 00 00 00 00 00 80 3f"
    "01 00 3f  02 00"  # (60) global block, sensor 0 at 63
    "00 00 00 3f 00 00 80 bf 00 00 00 40 00 00 00 00 00 00 00 00 00 00 80 40"
    "01 00 5c  01 00 5f  01 00"  # (89) pillar slip block, sensor 0 at 92, pillar 0 at 95, entry type 1
    "ff  00 00 80 bf"  # slip state -1 (lost contact), friction -1 (no estimate)
    "01 00 69  01 00"  # (102) sensor slip block, sensor 0 at 105, entry type 1
    "02  00 00 00 3f  00 00 80 40"  # state 2 (reference pillar loaded), friction 0.5, target grip 4 N
    # checksum = 1 + 314 + 155 + 706 + 704 + 764 + 364 = 3008 = 0x0bc0
    "c0 0b aa bb cc dd"
)


def _golden_packet() -> PapillArrayPacket:
    sensor = PillarSensorData(
        forces_n=np.array([[0.5, -1.0, 2.0]]),
        displacements_mm=np.array([[0.0, 0.0, 1.0]]),
        global_force_n=np.array([0.5, -1.0, 2.0]),
        global_torque_nmm=np.array([0.0, 0.0, 4.0]),
        slip_states=np.array([-1]),
        pillar_friction=np.array([-1.0]),
        slip_active=2,
        friction_estimate=0.5,
        target_grip_force_n=4.0,
    )
    return PapillArrayPacket(counter=0x01020304, timestamp_us=1_000_000, sensors=[sensor])


def test_golden_packet_without_slip_blocks_decodes() -> None:
    packet = decode_packet(GOLDEN_1)
    assert packet.counter == 0x01020304
    assert packet.timestamp_us == 1_000_000
    (sensor,) = packet.sensors
    assert sensor.forces_n.tolist() == [[0.5, -1.0, 2.0]]
    assert sensor.displacements_mm.tolist() == [[0.0, 0.0, 1.0]]
    assert sensor.global_force_n.tolist() == [0.5, -1.0, 2.0]
    assert sensor.global_torque_nmm.tolist() == [0.0, 0.0, 4.0]
    # No slip blocks on the wire: the device's own "nothing" values, not guesses.
    assert sensor.slip_states.tolist() == [0]
    assert sensor.pillar_friction.tolist() == [-1.0]
    assert (sensor.slip_active, sensor.friction_estimate, sensor.target_grip_force_n) == (0, -1.0, -1.0)


def test_golden_packet_with_slip_blocks_decodes() -> None:
    (sensor,) = decode_packet(GOLDEN_2).sensors
    assert sensor.forces_n.tolist() == [[0.5, -1.0, 2.0]]
    assert sensor.slip_states.tolist() == [-1]
    assert sensor.pillar_friction.tolist() == [-1.0]
    assert (sensor.slip_active, sensor.friction_estimate, sensor.target_grip_force_n) == (2, 0.5, 4.0)


def test_encoder_writes_the_golden_bytes() -> None:
    assert encode_packet(_golden_packet(), index_size=1, include_slip=False) == GOLDEN_1
    assert encode_packet(_golden_packet(), index_size=1) == GOLDEN_2


def _f32(rng: np.random.Generator, shape: tuple[int, ...], scale: float = 3.0) -> np.ndarray:
    """Random values that float32 holds exactly, so round trips compare equal."""
    return (rng.normal(size=shape) * scale).astype(np.float32).astype(np.float64)


def random_sensor(rng: np.random.Generator, n_pillars: int = 9) -> PillarSensorData:
    return PillarSensorData(
        forces_n=_f32(rng, (n_pillars, 3)),
        displacements_mm=_f32(rng, (n_pillars, 3), 0.5),
        global_force_n=_f32(rng, (3,)),
        global_torque_nmm=_f32(rng, (3,), 20.0),
        slip_states=rng.integers(-2, 4, size=n_pillars),
        pillar_friction=_f32(rng, (n_pillars,), 0.3),
        slip_active=int(rng.integers(0, 3)),
        friction_estimate=float(_f32(rng, (1,))[0]),
        target_grip_force_n=float(_f32(rng, (1,))[0]),
    )


def random_packet(rng: np.random.Generator, counter: int, n_sensors: int = 2, n_pillars: int = 9) -> PapillArrayPacket:
    sensors = [random_sensor(rng, n_pillars) for _ in range(n_sensors)]
    return PapillArrayPacket(counter=counter, timestamp_us=1000 * counter + 17, sensors=sensors)


def assert_same_packet(a: PapillArrayPacket, b: PapillArrayPacket) -> None:
    assert (a.counter, a.timestamp_us, len(a.sensors)) == (b.counter, b.timestamp_us, len(b.sensors))
    for sa, sb in zip(a.sensors, b.sensors, strict=True):
        for name in ("forces_n", "displacements_mm", "global_force_n", "global_torque_nmm", "pillar_friction"):
            np.testing.assert_array_equal(getattr(sa, name), getattr(sb, name), err_msg=name)
        np.testing.assert_array_equal(sa.slip_states, sb.slip_states)
        assert (sa.slip_active, sa.friction_estimate, sa.target_grip_force_n) == (
            sb.slip_active,
            sb.friction_estimate,
            sb.target_grip_force_n,
        )


@pytest.mark.parametrize("index_size", [2, 3, 4])
def test_round_trip_two_slots_of_nine_pillars(index_size: int) -> None:
    packet = random_packet(np.random.default_rng(index_size), counter=123_456)
    frame = encode_packet(packet, index_size=index_size)
    assert frame.startswith(START_MARKER) and frame.endswith(END_MARKER)
    decoded = decode_packet(frame)
    assert_same_packet(decoded, packet)
    assert decoded.sensors[0].forces_n.shape == (9, 3)


def test_unknown_block_type_7_is_kept_as_raw_bytes() -> None:
    packet = random_packet(np.random.default_rng(1), counter=5)
    packet.unknown_blocks = {7: b"\x01\x02\x03"}
    decoded = decode_packet(encode_packet(packet))
    assert decoded.unknown_blocks == {7: b"\x01\x02\x03"}
    assert_same_packet(decoded, packet)


def test_a_packet_without_a_hub_block_decodes_without_counter_or_time() -> None:
    """No public source says the hub block always comes; the golden packet with its hub entry retyped as an undefined
    block still gives its pillar values, and the 12 hub bytes are kept raw."""
    packet = decode_packet(_with_body_byte(GOLDEN_1, 1, 7))
    assert (packet.counter, packet.timestamp_us) == (None, None)
    assert packet.sensors[0].forces_n.tolist() == [[0.5, -1.0, 2.0]]
    assert packet.unknown_blocks[7] == (0x01020304).to_bytes(4, "little") + (1_000_000).to_bytes(8, "little")


@pytest.mark.parametrize("index_size", [1, 2])
def test_pillar_data_alone_round_trips_with_nan_globals(index_size: int) -> None:
    rng = np.random.default_rng(7)
    sensors = [random_sensor(rng, n_pillars=2) for _ in range(2)]
    packet = PapillArrayPacket(counter=None, timestamp_us=None, sensors=sensors)
    body = encode_body(packet, index_size=index_size, include_slip=False, include_global=False)
    assert body[0] == index_size and body[1:3] == (3).to_bytes(2, "little")  # one index entry: pillar data
    decoded = decode_packet(encode_packet(packet, index_size=index_size, include_slip=False, include_global=False))
    assert (decoded.counter, decoded.timestamp_us) == (None, None)
    for sent, got in zip(sensors, decoded.sensors, strict=True):
        np.testing.assert_array_equal(got.forces_n, sent.forces_n)
        np.testing.assert_array_equal(got.displacements_mm, sent.displacements_mm)
        assert np.isnan(got.global_force_n).all() and np.isnan(got.global_torque_nmm).all()


def test_a_counter_without_a_time_is_refused_by_the_encoder() -> None:
    packet = PapillArrayPacket(counter=1, timestamp_us=None, sensors=[PillarSensorData.unloaded()])
    with pytest.raises(ProtocolError, match="come together"):
        encode_body(packet)


def test_index_size_1_cannot_address_a_full_packet() -> None:
    with pytest.raises(ProtocolError, match="does not fit in index_size=1"):
        encode_packet(random_packet(np.random.default_rng(0), counter=1), index_size=1)


def _with_body_byte(frame: bytes, index: int, value: int) -> bytes:
    """Change body byte ``index`` and fix the checksum, so only the structure is wrong."""
    body = bytearray(frame[4:-6])
    body[index] = value
    checksum = sum(body) & 0xFFFF
    return START_MARKER + bytes(body) + checksum.to_bytes(2, "little") + END_MARKER


@pytest.mark.parametrize(
    ("frame", "reason"),
    [
        (GOLDEN_1[:-1] + b"\x00", "end marker"),
        (b"\x00" + GOLDEN_1[1:], "start marker"),
        (GOLDEN_1[:-6] + b"\x6b\x06" + END_MARKER, "checksum 0x066b on the wire, 0x066a computed"),
        (GOLDEN_1[:8], "too short"),
        (_with_body_byte(GOLDEN_1, 0, 0), "index size 0"),
        (_with_body_byte(GOLDEN_1, 28, 3), "type 3, expected 2"),  # pillar entry type
        (_with_body_byte(GOLDEN_1, 25, 0x40), "runs past"),  # sensor 0 claims 64 pillars
        (_with_body_byte(GOLDEN_1, 4, 4), "listed twice"),  # pillar entry retyped as global
        (_with_body_byte(GOLDEN_1, 4, 7), "no block of type 3"),  # pillar entry retyped as 7: no pillar data
        (START_MARKER + GOLDEN_1[4:-6] + b"\x00" + (0x066A).to_bytes(2, "little") + END_MARKER, "stray bytes"),
    ],
)
def test_broken_packets_say_what_is_wrong(frame: bytes, reason: str) -> None:
    with pytest.raises(ProtocolError) as info:
        decode_packet(frame)
    assert reason in str(info.value)
    assert info.value.hint


# -------------------------------------------------------------------------------------------------- the stream


def _three_packets() -> list[bytes]:
    rng = np.random.default_rng(3)
    return [encode_packet(random_packet(rng, counter=c)) for c in (10, 11, 12)]


def _feed_all(parser: PacketParser, chunks: list[bytes]) -> list[PapillArrayPacket]:
    out: list[PapillArrayPacket] = []
    for chunk in chunks:
        out += parser.feed(chunk)
    return out


def test_stream_fed_whole_byte_by_byte_and_in_random_pieces() -> None:
    frames = _three_packets()
    stream = b"".join(frames)
    rng = random.Random(11)
    cuts = sorted(rng.sample(range(1, len(stream)), 40))
    pieces = [stream[a:b] for a, b in zip([0, *cuts], [*cuts, len(stream)], strict=True)]
    for chunks in ([stream], [stream[i : i + 1] for i in range(len(stream))], pieces):
        parser = PacketParser()
        out = _feed_all(parser, chunks)
        assert [p.counter for p in out] == [10, 11, 12]
        assert [encode_packet(p) for p in out] == frames
        assert parser.counters() == {"packets": 3, "bytes_dropped": 0, "checksum_errors": 0, "framing_errors": 0}
        assert parser.pending_bytes == 0


def test_garbage_between_packets_is_counted_and_skipped() -> None:
    a, b, c = _three_packets()
    junk = [b"\x00\x01\x02", b"\x55\x66\x77", b"\xaa\xbb\xcc\xdd", b"\x55\x66\x77\x88\x01\x02"]
    stream = junk[0] + a + junk[1] + b + junk[2] + junk[3] + c
    parser = PacketParser()
    out = _feed_all(parser, [stream[i : i + 7] for i in range(0, len(stream), 7)])
    assert [p.counter for p in out] == [10, 11, 12]
    assert parser.bytes_dropped == sum(len(j) for j in junk)
    assert parser.framing_errors == 1  # the fake start marker in junk[3]


def test_bad_checksum_drops_one_packet_and_keeps_its_neighbours() -> None:
    a, b, c = _three_packets()
    broken = bytearray(b)
    broken[100] ^= 0x40
    parser = PacketParser()
    out = parser.feed(a + bytes(broken) + c)
    assert [p.counter for p in out] == [10, 12]
    assert parser.checksum_errors == 1 and parser.framing_errors == 0
    assert parser.bytes_dropped == len(b)


def test_packet_cut_short_does_not_swallow_the_next_one() -> None:
    a, b, c = _three_packets()
    parser = PacketParser()
    # The cut packet's length is unknown; the parser must not wait for 2048 bytes or eat b.
    assert [p.counter for p in parser.feed(a[:400] + b)] == [11]
    assert parser.framing_errors == 1 and parser.bytes_dropped == 400
    assert [p.counter for p in parser.feed(c)] == [12]


def test_markers_inside_float_data_do_not_split_a_packet() -> None:
    # Bytes aa bb cc dd and 55 66 77 88 read as little-endian float32 are ordinary finite numbers.
    end_in_data = float(np.frombuffer(END_MARKER, dtype="<f4")[0])
    start_in_data = float(np.frombuffer(START_MARKER, dtype="<f4")[0])
    rng = np.random.default_rng(5)
    packet = random_packet(rng, counter=77)
    packet.sensors[0].forces_n[2] = [start_in_data, end_in_data, 1.0]
    packet.sensors[1].displacements_mm[0] = [end_in_data, end_in_data, start_in_data]
    frame = encode_packet(packet)
    assert frame.count(END_MARKER) == 4 and frame.count(START_MARKER) == 3
    after = encode_packet(random_packet(rng, counter=78))
    parser = PacketParser()
    out = _feed_all(parser, [bytes([x]) for x in frame + after])
    assert [p.counter for p in out] == [77, 78]
    assert_same_packet(out[0], packet)
    assert parser.bytes_dropped == 0


def test_start_marker_without_end_is_given_up_after_max_packet_len() -> None:
    a, _, _ = _three_packets()
    parser = PacketParser(max_packet_len=2048)
    assert parser.feed(START_MARKER + bytes(3000)) == []
    assert parser.framing_errors == 1
    assert parser.pending_bytes <= 3  # the rest was dropped, not hoarded
    assert [p.counter for p in parser.feed(a)] == [10]


def _marker_dense_garbage(seed: int, n_bytes: int) -> bytes:
    """Garbage made mostly of start and end markers: the input that took the old parser 15.8 s CPU for 2.4 KB."""
    rng = random.Random(seed)
    pieces = [START_MARKER, END_MARKER, START_MARKER + bytes(3), b"\x00\x00" + END_MARKER, bytes([rng.randrange(256)])]
    out = bytearray()
    while len(out) < n_bytes:
        out += rng.choice(pieces)
    return bytes(out)


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_marker_dense_garbage_costs_the_same_work_in_any_chunking_and_keeps_the_packets(seed: int) -> None:
    """Issue 28: resynchronising re-tried every marker pair on every read, so 2 KB fed in 7-byte chunks took 9.3 s of
    CPU. Each (start, end) pair is now compared once however the bytes come, bounded by the pairs max_packet_len
    allows, and the packets inside the garbage still come out."""
    a, b, c = _three_packets()
    garbage = _marker_dense_garbage(seed, 2400)
    stream = garbage[:800] + a + garbage[800:1600] + b + garbage[1600:] + c
    starts = [i for i in range(len(stream)) if stream.startswith(START_MARKER, i)]
    ends = [i for i in range(len(stream)) if stream.startswith(END_MARKER, i)]
    pairs = sum(1 for e in ends for st_ in starts if st_ + 7 <= e and e + 4 - st_ <= 2048)  # each could be a packet
    for chunk in (len(stream), 7, 1):
        parser = PacketParser(max_packet_len=2048)
        out = _feed_all(parser, [stream[i : i + chunk] for i in range(0, len(stream), chunk)])
        assert [p.counter for p in out] == [10, 11, 12]
        assert parser.pairs_checked <= pairs  # no pair compared twice, however often the bytes were fed
        assert parser.bodies_decoded <= parser.pairs_checked  # only pairs whose checksum matched, once each


# ----------------------------------------------------------------------------------------------------- commands


def test_command_bytes() -> None:
    assert encode_command(Command.BIAS) == b"z\n"
    assert encode_command(Command.START_SLIP) == b"S\n"
    assert encode_command(Command.STOP_SLIP) == b"s\n"
    assert [encode_command(Command.SET_RATE, rate) for rate in VALID_RATES_HZ] == [
        b"f100\n",
        b"f250\n",
        b"f500\n",
        b"f1000\n",
    ]
    assert encode_command(HubCommand(Command.SET_RATE, 250)) == b"f250\n"


@pytest.mark.parametrize(
    ("command", "rate"),
    [
        (Command.SET_RATE, 200),
        (Command.SET_RATE, None),
        (Command.BIAS, 100),
        (Command.SET_RATE, 250.0),  # found by benchmarks/fuzz.py: went out as "f250.0", which no hub reads
        (Command.SET_RATE, True),
    ],
)
def test_bad_command_arguments_are_refused(command: Command, rate: int | None) -> None:
    with pytest.raises(ProtocolError) as info:
        encode_command(command, rate)
    assert info.value.hint


def test_command_parser_splits_lines_and_counts_unknown_ones() -> None:
    parser = CommandParser()
    assert parser.feed(b"z\nf5") == [HubCommand(Command.BIAS)]
    assert parser.feed(b"00\r\nS\nhello\nf123\n\ns\n") == [
        HubCommand(Command.SET_RATE, 500),
        HubCommand(Command.START_SLIP),
        HubCommand(Command.STOP_SLIP),
    ]
    assert parser.unknown_lines == 2 and parser.commands == 4


def test_command_parser_drops_an_endless_line() -> None:
    parser = CommandParser(max_line_len=32)
    assert parser.feed(b"x" * 100) == []
    assert parser.feed(b"y" * 100 + b"\nz\n") == [HubCommand(Command.BIAS)]
    assert parser.unknown_lines == 1


_commands = st.sampled_from(
    [HubCommand(Command.BIAS), HubCommand(Command.START_SLIP), HubCommand(Command.STOP_SLIP)]
    + [HubCommand(Command.SET_RATE, rate) for rate in VALID_RATES_HZ]
)


@settings(max_examples=100, deadline=None)
@given(st.lists(_commands, max_size=12), st.lists(st.integers(0, 200), max_size=8))
def test_commands_survive_any_chunking(commands: list[HubCommand], cuts: list[int]) -> None:
    stream = b"".join(encode_command(command) for command in commands)
    points = sorted({c % (len(stream) + 1) for c in cuts} | {0, len(stream)})
    parser = CommandParser()
    parsed: list[HubCommand] = []
    for a, b in itertools.pairwise(points):
        parsed += parser.feed(stream[a:b])
    assert parsed == commands
    assert parser.unknown_lines == 0


@settings(max_examples=100, deadline=None)
@given(st.binary(max_size=200))
def test_command_parser_never_raises_on_garbage(data: bytes) -> None:
    parser = CommandParser()
    parser.feed(data)
    assert parser.commands + parser.unknown_lines <= data.count(b"\n") + 1
