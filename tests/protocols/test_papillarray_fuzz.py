"""Hypothesis on the PapillArray stream: garbage never crashes it; every intact packet in a damaged stream comes out.

Run with ``-s`` to see how many fuzzed streams ran and how many packets were recovered.
"""

from __future__ import annotations

import contextlib
import itertools
from collections import Counter

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from protocols.errors import ProtocolError
from protocols.papillarray import (
    END_MARKER,
    START_MARKER,
    PacketParser,
    decode_packet,
    encode_packet,
    frame_body,
)
from tests.protocols.test_papillarray_codec import GOLDEN_2, random_packet

_START_IN_DATA = float(np.frombuffer(START_MARKER, dtype="<f4")[0])
_END_IN_DATA = float(np.frombuffer(END_MARKER, dtype="<f4")[0])

_garbage = st.lists(
    st.sampled_from([START_MARKER, END_MARKER, START_MARKER[:3], END_MARKER[:2]]) | st.binary(max_size=24),
    max_size=4,
).map(b"".join)

_packet_specs = st.fixed_dictionaries(
    {
        "damage": st.sampled_from(["none", "none", "none", "flip", "truncate", "end", "start"]),
        "seed": st.integers(0, 2**32 - 1),
        "n_sensors": st.sampled_from([2, 2, 1]),
        "n_pillars": st.sampled_from([9, 9, 1, 3]),
        "index_size": st.sampled_from([2, 2, 1, 4]),
        "include_slip": st.booleans(),
        "markers_in_data": st.booleans(),
        "garbage_after": _garbage,
    }
)


def _make_frame(spec: dict, counter: int) -> tuple[bytes, bytes, int]:
    """(intact frame, frame as sent after the spec's damage, index size used)."""
    rng = np.random.default_rng(spec["seed"])
    packet = random_packet(rng, counter, n_sensors=spec["n_sensors"], n_pillars=spec["n_pillars"])
    if spec["markers_in_data"]:
        packet.sensors[0].forces_n[0] = [_START_IN_DATA, _END_IN_DATA, _END_IN_DATA]
    index_size = spec["index_size"]
    try:
        frame = encode_packet(packet, index_size=index_size, include_slip=spec["include_slip"])
    except ProtocolError:  # index size 1 cannot address a big packet
        index_size = 2
        frame = encode_packet(packet, index_size=index_size, include_slip=spec["include_slip"])
    sent = bytearray(frame)
    flip = int(rng.integers(1, 256))
    if spec["damage"] == "flip":
        sent[int(rng.integers(0, len(sent)))] ^= flip
    elif spec["damage"] == "truncate":
        del sent[int(rng.integers(1, len(sent))) :]
    elif spec["damage"] == "end":
        sent[-1 - int(rng.integers(0, 4))] ^= flip
    elif spec["damage"] == "start":
        sent[int(rng.integers(0, 4))] ^= flip
    return frame, bytes(sent), index_size


FUZZ_STATS: Counter[str] = Counter()


@settings(max_examples=200, deadline=None)
@given(
    lead=_garbage,
    specs=st.lists(_packet_specs, min_size=1, max_size=6),
    cuts=st.lists(st.integers(0, 10_000), max_size=12),
)
def _check_recovery(lead: bytes, specs: list[dict], cuts: list[int]) -> None:
    stream = bytearray(lead)
    placed: list[tuple[int, bytes, int]] = []  # (position, intact frame, counter)
    encoding: list[tuple[int, bool]] = []  # (index size, include_slip) per counter
    for counter, spec in enumerate(specs):
        frame, sent, index_size = _make_frame(spec, counter)
        placed.append((len(stream), frame, counter))
        encoding.append((index_size, spec["include_slip"]))
        stream += sent + spec["garbage_after"]
    # A packet is intact when its exact bytes are in the stream where it was put (damage can be undone by chance,
    # e.g. a cut packet followed by garbage that happens to restore its tail).
    expected = [(frame, counter) for pos, frame, counter in placed if stream[pos : pos + len(frame)] == frame]
    points = sorted({c % (len(stream) + 1) for c in cuts} | {0, len(stream)})
    parser = PacketParser()
    out = []
    for a, b in itertools.pairwise(points):
        out += parser.feed(bytes(stream[a:b]))
    assert [p.counter for p in out] == [counter for _, counter in expected]
    for packet, (frame, counter) in zip(out, expected, strict=True):
        index_size, include_slip = encoding[counter]
        assert encode_packet(packet, index_size=index_size, include_slip=include_slip) == frame
    recovered_bytes = sum(len(frame) for frame, _ in expected)
    assert parser.bytes_dropped + recovered_bytes + parser.pending_bytes == len(stream)
    FUZZ_STATS["streams"] += 1
    FUZZ_STATS["packets_sent"] += len(specs)
    FUZZ_STATS["packets_damaged"] += len(specs) - len(expected)
    FUZZ_STATS["packets_recovered"] += len(out)
    FUZZ_STATS["stream_bytes"] += len(stream)


def test_every_intact_packet_in_a_damaged_stream_is_recovered() -> None:
    FUZZ_STATS.clear()
    _check_recovery()
    print(f"\npapillarray stream fuzz: {dict(FUZZ_STATS)}")
    assert FUZZ_STATS["packets_damaged"] > 0 and FUZZ_STATS["packets_recovered"] > 0


@settings(max_examples=100, deadline=None)
@given(st.binary(max_size=64), st.integers(0, 40))
def test_any_garbage_before_a_packet_never_hides_it(garbage: bytes, seed: int) -> None:
    frame = encode_packet(random_packet(np.random.default_rng(seed), counter=seed))
    parser = PacketParser()
    out = parser.feed(garbage) + parser.feed(frame)
    assert [p.counter for p in out] == [seed]


@settings(max_examples=200, deadline=None)
@given(st.binary(max_size=300))
def test_arbitrary_bytes_never_crash_the_parser(data: bytes) -> None:
    parser = PacketParser()
    parser.feed(data)
    parser.feed(START_MARKER + data + END_MARKER)
    assert parser.bytes_dropped + parser.pending_bytes <= 2 * len(data) + 8


@settings(max_examples=300, deadline=None)
@given(st.lists(st.tuples(st.integers(0, len(GOLDEN_2) - 11), st.integers(0, 255)), min_size=1, max_size=4))
def test_mutated_bodies_with_a_valid_checksum_decode_or_raise_protocol_error(
    mutations: list[tuple[int, int]],
) -> None:
    body = bytearray(GOLDEN_2[4:-6])
    for index, value in mutations:
        body[index] = value
    try:
        packet = decode_packet(frame_body(bytes(body)))
    except ProtocolError:
        return
    for sensor in packet.sensors:
        assert sensor.forces_n.shape == sensor.displacements_mm.shape == (sensor.n_pillars, 3)


@settings(max_examples=200, deadline=None)
@given(st.binary(max_size=200))
def test_arbitrary_bodies_decode_or_raise_protocol_error(body: bytes) -> None:
    with contextlib.suppress(ProtocolError):
        decode_packet(frame_body(body))
