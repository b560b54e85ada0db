"""XELA uSkin CAN codec: golden payloads worked by hand, id maps, and frame assembly with lost/sentinel taxels."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from drivers.uskin import STALE_AFTER_S
from protocols.errors import ProtocolError
from protocols.xela_can import (
    LEARN_CYCLES,
    ORDER_LEARN_FRAMES,
    START_STREAM_PAYLOAD,
    STOP_STREAM_PAYLOAD,
    USPA44_ID_MAP,
    USPA46_ID_MAP,
    FrameAssembler,
    TaxelIdMap,
    command_arbitration_id,
    decode_stream_command,
    decode_taxel_message,
    encode_invalid_taxel_message,
    encode_stream_command,
    encode_taxel_message,
    invalid_taxels,
)

MS = 1_000_000  # ns
# bursts before the pause and then the send order are known: the first burst has no pause before it, and a frame is
# proven by the pause after it
WARM_UP = LEARN_CYCLES + ORDER_LEARN_FRAMES + 2


# --------------------------------------------------------------------------------------------- stream commands


def test_start_command_for_controller_3_is_cansend_203_07_00() -> None:
    # tactile_UR5 starts an old board with `cansend can0 203#07.00` and stops it with `203#07.01`.
    assert encode_stream_command(3, start=True) == (0x203, b"\x07\x00")
    assert encode_stream_command(3, start=False) == (0x203, b"\x07\x01")
    assert (START_STREAM_PAYLOAD, STOP_STREAM_PAYLOAD) == (b"\x07\x00", b"\x07\x01")
    assert command_arbitration_id(1) == 0x201


@pytest.mark.parametrize(
    ("arbitration_id", "data", "expected"),
    [
        (0x203, b"\x07\x00", (3, True)),
        (0x20F, b"\x07\x01", (15, False)),
        (0x201, b"\x07", (1, True)),  # the AIST demo's 1-byte start
        (0x200, b"\x07\x00\x00\x00\x00\x00\x00\x00", (0, True)),  # zero-padded by an adapter
        (0x203, b"\x07\x02", None),
        (0x203, b"\x08\x00", None),
        (0x203, b"", None),
        (0x203, b"\x07\x00\x01", None),
        (0x135, b"\x07\x00", None),  # a taxel id, not a command
        (0x210, b"\x07\x00", None),  # outside 0x200..0x20F
    ],
)
def test_decode_stream_command(arbitration_id: int, data: bytes, expected: tuple[int, bool] | None) -> None:
    assert decode_stream_command(arbitration_id, data) == expected


@pytest.mark.parametrize("controller_id", [-1, 16, 0x200])
def test_controller_id_out_of_range_is_refused_with_a_hint(controller_id: int) -> None:
    with pytest.raises(ProtocolError) as info:
        command_arbitration_id(controller_id)
    assert info.value.hint


# ------------------------------------------------------------------------------------------------ taxel messages


def test_taxel_payload_is_big_endian_xyz_after_an_unused_byte() -> None:
    # X = 0x4010 = 16400, Y = 0x8020 = 32800, Z = 0x9030 = 36912 (resting uSkin counts look like this).
    payload = bytes([0x5A, 0x40, 0x10, 0x80, 0x20, 0x90, 0x30, 0x00])
    message = decode_taxel_message(0x123, payload)
    assert (message.x, message.y, message.z) == (16400, 32800, 36912)
    assert message.valid
    assert message.arbitration_id == 0x123
    assert encode_taxel_message(0x123, 16400, 32800, 36912, byte0=0x5A) == payload


def test_encoder_clips_counts_to_16_bits() -> None:
    assert encode_taxel_message(0x100, -5, 70_000, 1) == bytes([0, 0x00, 0x00, 0xFF, 0xFF, 0x00, 0x01, 0])


def test_sentinel_and_all_zero_messages_are_invalid() -> None:
    sentinel = encode_invalid_taxel_message()
    assert sentinel == bytes([0, 0xFA, 0x00, 0xFA, 0x00, 0xFA, 0x00, 0])
    assert not decode_taxel_message(0x100, sentinel).valid
    assert not decode_taxel_message(0x100, bytes(8)).valid
    # The sentinel rule looks at the X most significant byte only: 0xF9FF is a (very large) reading.
    assert decode_taxel_message(0x100, encode_taxel_message(0x100, 0xF9FF, 0, 0)).valid
    assert not decode_taxel_message(0x100, encode_taxel_message(0x100, 0xFA00, 1, 1)).valid
    # One non-zero axis is enough to be a reading.
    assert decode_taxel_message(0x100, encode_taxel_message(0x100, 0, 0, 1)).valid


def test_seven_byte_payload_decodes_and_six_byte_payload_raises() -> None:
    assert decode_taxel_message(0x100, bytes([0, 0, 1, 0, 2, 0, 3])).z == 3
    with pytest.raises(ProtocolError, match="6 data bytes"):
        decode_taxel_message(0x100, bytes(6))


@settings(max_examples=200, deadline=None)
@given(st.integers(0, 0x7FF), st.binary(max_size=8))
def test_any_payload_decodes_or_raises_protocol_error(arbitration_id: int, data: bytes) -> None:
    try:
        message = decode_taxel_message(arbitration_id, data)
    except ProtocolError:
        assert len(data) < 7
    else:
        assert 0 <= message.x <= 0xFFFF and 0 <= message.y <= 0xFFFF and 0 <= message.z <= 0xFFFF


# ------------------------------------------------------------------------------------------------------ id maps


def test_uspa46_ids_follow_row_and_column() -> None:
    assert USPA46_ID_MAP.n_taxels == 24
    # XELA's 4x6 map: s1 = 0x135 ... s6 = 0x130, s7 = 0x125 ... s24 = 0x100, s1 the top-left taxel (row 0, col 0)
    assert USPA46_ID_MAP.index_of(0x135) == 0  # s1: row 0, col 0
    assert USPA46_ID_MAP.index_of(0x130) == 5  # s6: row 0, col 5
    assert USPA46_ID_MAP.index_of(0x125) == 6  # s7: row 1, col 0
    assert USPA46_ID_MAP.index_of(0x100) == 23  # s24: row 3, col 5
    assert USPA46_ID_MAP.index_of(0x106) is None
    assert USPA46_ID_MAP.index_of(0x201) is None


def test_xela_map_file_order_is_the_layout_order() -> None:
    # XELA's 4x6 map file lists s1 = 0x135, s2 = 0x134 ... s6 = 0x130, s7 = 0x125 ... s24 = 0x100.
    ini = [0x135, 0x134, 0x133, 0x132, 0x131, 0x130, 0x125, 0x124, 0x123, 0x122, 0x121, 0x120]
    ini += [0x115, 0x114, 0x113, 0x112, 0x111, 0x110, 0x105, 0x104, 0x103, 0x102, 0x101, 0x100]
    assert TaxelIdMap(tuple(ini)) == USPA46_ID_MAP


def test_uspa44_map_and_other_firmware_maps_are_data() -> None:
    assert USPA44_ID_MAP.n_taxels == 16
    assert USPA44_ID_MAP.index_of(0x133) == 15
    assert USPA44_ID_MAP.index_of(0x134) is None
    aist = TaxelIdMap(tuple(range(0x710, 0x720)))  # one firmware used 0x710 + taxel index
    assert aist.index_of(0x71F) == 15


@pytest.mark.parametrize("ids", [[0x100, 0x100], [0x800], [], [-1]])
def test_bad_id_maps_are_refused(ids: list[int]) -> None:
    with pytest.raises(ProtocolError):
        TaxelIdMap(tuple(ids))


# ----------------------------------------------------------------------------------------------- frame assembly


def _counts(cycle: int, index: int) -> tuple[int, int, int]:
    """Distinct, recognisable counts per (cycle, taxel)."""
    return 10_000 + 100 * cycle + index, 20_000 + index, 30_000 + cycle


# The assembler's tests feed taxels in id order by index: a 4x6 map listed in id order (0x100 first) makes index
# and send position the same. USPA46_ID_MAP lists the same ids in XELA's order (0x135 first); see the test below.
ID_ORDER_46 = TaxelIdMap.from_row_col_ids(4, 6)


def _send_cycle(
    assembler: FrameAssembler,
    cycle: int,
    t0_ns: int,
    order: list[int] | None = None,
    skip: frozenset[int] = frozenset(),
    sentinel: frozenset[int] = frozenset(),
) -> list:
    """Feed one cycle as a burst (taxels in ``order``, 0.1 ms apart); return the frames that came out."""
    frames = []
    for step, index in enumerate(order if order is not None else range(assembler.n_taxels)):
        if index in skip:
            continue
        arbitration_id = assembler.id_map.ids[index]
        payload = (
            encode_invalid_taxel_message()
            if index in sentinel
            else encode_taxel_message(arbitration_id, *_counts(cycle, index))
        )
        frame = assembler.add(arbitration_id, payload, t0_ns + step * 100_000)
        if frame is not None:
            frames.append(frame)
    return frames


def _warmed_up(id_map: TaxelIdMap = ID_ORDER_46, order: list[int] | None = None) -> FrameAssembler:
    """An assembler that has seen WARM_UP whole bursts, 10 ms apart: pause and send order learned, nothing pending."""
    assembler = FrameAssembler(id_map)
    for cycle in range(WARM_UP):
        _send_cycle(assembler, cycle=cycle, t0_ns=cycle * 10 * MS, order=order)
    assert assembler.pause_threshold_ns is not None and assembler.send_order is not None
    return assembler


def _cycles_in(frame) -> set[int]:  # type: ignore[no-untyped-def]
    """Which cycles a frame's values came from (the x count carries the cycle)."""
    return {int((x - 10_000) // 100) for x in frame.values[:, 0]}


def test_frame_closes_when_every_taxel_has_reported_in_any_order() -> None:
    """Bursts in a new order every cycle teach no order, only the pause: a whole cycle is one valid frame, decided
    when the next burst's first message shows the pause that ends it."""
    rng = np.random.default_rng(3)
    assembler = FrameAssembler(ID_ORDER_46)
    for cycle in range(WARM_UP):
        _send_cycle(assembler, cycle=cycle, t0_ns=cycle * 10 * MS, order=list(rng.permutation(24)))
    assert assembler.pause_threshold_ns is not None and assembler.send_order is None
    c = WARM_UP
    order = [23, 0, 5, 12, *[i for i in range(24) if i not in (23, 0, 5, 12)]]
    (previous,) = _send_cycle(assembler, cycle=c, t0_ns=c * 10 * MS, order=order)  # the pause ends cycle c - 1
    assert previous.valid and _cycles_in(previous) == {c - 1}
    assert assembler.frames == c  # cycle c is complete, but waits for the pause after it
    (frame,) = _send_cycle(assembler, cycle=c + 1, t0_ns=(c + 1) * 10 * MS, order=order)
    assert frame.valid and frame.one_cycle and not frame.stale_mask.any()
    assert frame.t_ns == c * 10 * MS + 23 * 100_000  # time of the 24th (last) message
    assert frame.values.shape == (24, 3)
    assert tuple(frame.values[0]) == _counts(c, 0) and tuple(frame.values[23]) == _counts(c, 23)


def test_lost_message_closes_the_frame_early_and_flags_only_that_taxel() -> None:
    assembler = _warmed_up()
    c = WARM_UP
    before = (assembler.frames, assembler.incomplete_frames)
    assert _send_cycle(assembler, cycle=c, t0_ns=c * 10 * MS, skip=frozenset({7})) == []  # cannot know yet
    frames = _send_cycle(assembler, cycle=c + 1, t0_ns=(c + 1) * 10 * MS)
    assert len(frames) == 2  # cycle c closed by cycle c+1's first message, then cycle c+1 itself
    lossy, complete = frames
    assert list(np.flatnonzero(lossy.stale_mask)) == [7]
    assert not lossy.valid and lossy.one_cycle
    assert tuple(lossy.values[7]) == _counts(c - 1, 7)  # last known value, not a fabricated one
    assert tuple(lossy.values[8]) == _counts(c, 8)
    assert lossy.t_ns == c * 10 * MS + 23 * 100_000  # last message of cycle c
    assert complete.valid and tuple(complete.values[7]) == _counts(c + 1, 7)
    assert (assembler.frames, assembler.incomplete_frames) == (before[0] + 2, before[1] + 1)


def test_taxel_never_seen_reads_zero_and_is_flagged() -> None:
    assembler = FrameAssembler(ID_ORDER_46, cycle_start_id=0x100)
    _send_cycle(assembler, cycle=0, t0_ns=0, skip=frozenset({22, 23}))
    first = _send_cycle(assembler, cycle=1, t0_ns=10 * MS)[0]
    assert list(np.flatnonzero(first.stale_mask)) == [22, 23]
    assert tuple(first.values[23]) == (0, 0, 0)


def test_lost_leading_taxel_is_flagged_and_the_next_cycle_stays_whole() -> None:
    """Once the cycle marks are known, losing a cycle's first message flags one frame instead of shifting every later
    one."""
    assembler = _warmed_up()
    c = WARM_UP
    assert _send_cycle(assembler, cycle=c, t0_ns=c * 10 * MS, skip=frozenset({0})) == []
    lossy, whole = _send_cycle(assembler, cycle=c + 1, t0_ns=(c + 1) * 10 * MS)
    assert list(np.flatnonzero(lossy.stale_mask)) == [0]
    assert tuple(lossy.values[1]) == _counts(c, 1)
    assert whole.valid
    assert tuple(whole.values[0]) == _counts(c + 1, 0) and tuple(whole.values[23]) == _counts(c + 1, 23)
    (after,) = _send_cycle(assembler, cycle=c + 2, t0_ns=(c + 2) * 10 * MS)
    assert after.valid and tuple(after.values[0]) == _counts(c + 2, 0)


def test_lossy_cycles_closed_by_a_repeat_keep_the_learned_pause() -> None:
    """A cycle that lost a middle message is closed by the next cycle's first message: a message lost is no evidence
    against the pause, so lossy cycles in a row do not switch pause-learning off."""
    assembler = _warmed_up()
    threshold = assembler.pause_threshold_ns
    for cycle in range(WARM_UP, WARM_UP + 6):
        _send_cycle(assembler, cycle=cycle, t0_ns=cycle * 10 * MS, skip=frozenset({5}))
    assert assembler.pause_threshold_ns == threshold


def test_a_fixed_cycle_start_needs_no_learning() -> None:
    assembler = FrameAssembler(ID_ORDER_46, cycle_start_id=0x100, learn_pauses=False)
    frames = _send_cycle(assembler, cycle=0, t0_ns=0)
    frames += _send_cycle(assembler, cycle=1, t0_ns=10 * MS)
    frames += _send_cycle(assembler, cycle=2, t0_ns=20 * MS, skip=frozenset({5}))
    frames += _send_cycle(assembler, cycle=3, t0_ns=30 * MS)
    whole0, whole1, lossy = frames  # cycle 3 waits for the next 0x100 to show where it ends
    assert whole0.valid and _cycles_in(whole0) == {0} and whole1.valid and _cycles_in(whole1) == {1}
    assert list(np.flatnonzero(lossy.stale_mask)) == [5] and lossy.one_cycle


def test_a_cycle_start_outside_the_map_is_refused() -> None:
    with pytest.raises(ProtocolError, match="not a taxel id"):
        FrameAssembler(USPA46_ID_MAP, cycle_start_id=0x700)


def _send_ids(assembler: FrameAssembler, cycle: int, ids: list[int], t0_ns: int) -> list:
    """Feed one burst of ``ids`` (0.1 ms apart), counts marked with ``cycle``; return the frames that came out."""
    frames = []
    for step, arbitration_id in enumerate(ids):
        index = assembler.id_map.ids.index(arbitration_id)
        frame = assembler.add(arbitration_id, encode_taxel_message(arbitration_id, *_counts(cycle, index)),
                              t0_ns + step * 100_000)  # fmt: skip
        if frame is not None:
            frames.append(frame)
    return frames


XELA_ORDER = list(USPA46_ID_MAP.ids)  # s1 = 0x135 first, the order of XELA's own map


def test_one_cycle_with_nothing_to_mark_its_start_is_flagged_not_trusted() -> None:
    """A lone cycle could be the tail of one cycle and the head of the next: nothing on the wire says otherwise."""
    assembler = FrameAssembler(USPA46_ID_MAP)
    (frame,) = _send_ids(assembler, 0, XELA_ORDER, t0_ns=0)
    assert not frame.valid and not frame.one_cycle and frame.stale_mask.all()
    assert assembler.counters()["unproven_frames"] == 1
    assert tuple(frame.values[0]) == _counts(0, 0)  # taxel 0 = s1 = 0x135, sent first


def test_bursts_in_xelas_order_learn_the_pause_and_a_lost_first_message_flags_one_frame() -> None:
    assembler = FrameAssembler(USPA46_ID_MAP)
    frames = []
    for cycle in range(WARM_UP):
        frames += _send_ids(assembler, cycle, XELA_ORDER, t0_ns=cycle * 10 * MS)
    assert assembler.pause_threshold_ns is not None and assembler.send_order is not None
    c = WARM_UP
    frames += _send_ids(assembler, c, XELA_ORDER[1:], t0_ns=c * 10 * MS)  # 0x135 lost
    for cycle in range(c + 1, c + 4):
        frames += _send_ids(assembler, cycle, XELA_ORDER, t0_ns=cycle * 10 * MS)
    assert all(_cycles_in(frame) == {cycle} for cycle, frame in enumerate(frames[: c - 1]) if frame.valid)
    lossy = frames[c]
    assert list(np.flatnonzero(lossy.stale_mask)) == [0] and _cycles_in(lossy) == {c - 1, c}  # 0: its last good value
    for cycle, frame in enumerate(frames[c + 1 :], start=c + 1):
        assert frame.valid and _cycles_in(frame) == {cycle}  # every later frame is exactly one cycle


def test_the_reviews_four_lost_messages_never_give_a_frame_of_two_cycles() -> None:
    """Issue 28: cycle 5 lost s1, cycle 6 s6, cycle 7 s1, cycle 10 s1 (4 of 480 messages). The old assembler took
    that for 'pauses mark nothing' after the second lossy cycle in a row and from cycle 10 on every frame held 23
    taxels of one cycle and 1 of the next, flagged valid."""
    assembler = FrameAssembler(USPA46_ID_MAP)
    lost = {5: {0x135}, 6: {0x130}, 7: {0x135}, 10: {0x135}}
    frames = []
    for cycle in range(20):
        ids = [i for i in XELA_ORDER if i not in lost.get(cycle, set())]
        frames += _send_ids(assembler, cycle, ids, t0_ns=cycle * 10 * MS)
    assert all(len(_cycles_in(frame)) == 1 for frame in frames if frame.valid)
    valid_cycles = {min(_cycles_in(frame)) for frame in frames if frame.valid}
    assert valid_cycles >= set(range(11, 19))  # every whole cycle after the losses (19 waits for its end mark)


def _lossy_stream(seed: int, n_cycles: int, loss: float, shuffled: bool, merge: float = 0.0) -> tuple[int, int, int]:
    """Bursts (0.1 ms apart, 10 ms period) in XELA's order or a new order per cycle, each message lost with
    probability ``loss``; with ``merge`` a burst is read straight after the previous one (a host that fell behind:
    no pause shows). Returns (valid frames, valid frames mixing two cycles, whole cycles sent)."""
    rng = np.random.default_rng(seed)
    assembler = FrameAssembler(USPA46_ID_MAP)
    valid = mixed = whole = 0
    t_ns = 0
    for cycle in range(n_cycles):
        order = [XELA_ORDER[i] for i in rng.permutation(24)] if shuffled else XELA_ORDER
        t_ns = t_ns + 100_000 if rng.random() < merge else cycle * 10 * MS
        kept = [i for i in order if rng.random() >= loss]
        whole += len(kept) == 24
        for step, arbitration_id in enumerate(order):
            if arbitration_id not in kept:
                continue
            index = USPA46_ID_MAP.ids.index(arbitration_id)
            payload = encode_taxel_message(arbitration_id, *_counts(cycle % 400, index))
            frame = assembler.add(arbitration_id, payload, t_ns + step * 100_000)
            if frame is not None and frame.valid:
                valid += 1
                mixed += len(_cycles_in(frame)) > 1
        t_ns += 23 * 100_000
    return valid, mixed, whole


@pytest.mark.parametrize("shuffled", [False, True], ids=["xela-order", "new-order-each-cycle"])
def test_two_percent_message_loss_over_5000_cycles_flags_no_mixed_frame_valid(shuffled: bool) -> None:
    """Issue 28's measure: at 2 % loss over 5,000 cycles the old assembler flagged 12,262 mixed frames valid."""
    valid, mixed, whole = _lossy_stream(seed=28, n_cycles=5000, loss=0.02, shuffled=shuffled)
    assert mixed == 0
    assert valid >= whole - 2 * WARM_UP  # every whole cycle is kept, but those before the marks were learned


def test_bursts_the_host_reads_back_to_back_do_not_make_mixed_frames_valid() -> None:
    """A host that falls behind sees no pause between two bursts; a cycle that lost a message could then end in the
    next cycle's first message. With no learned order only a pause after the frame proves its end."""
    valid, mixed, _ = _lossy_stream(seed=5, n_cycles=2000, loss=0.02, shuffled=True, merge=0.2)
    assert mixed == 0 and valid > 0


@settings(max_examples=25, deadline=None)
@given(st.randoms(use_true_random=False))
def test_any_send_orders_give_one_cycle_per_frame(rnd) -> None:  # type: ignore[no-untyped-def]
    """Whatever orders the cycles come in (the same for a while, then another), no frame takes two cycles."""
    assembler = FrameAssembler(USPA46_ID_MAP)
    frames = []
    for cycle in range(14):
        order = list(XELA_ORDER)
        rnd.shuffle(order)
        frames += _send_ids(assembler, cycle, order, t0_ns=cycle * 10 * MS)
    assert all(len(_cycles_in(frame)) == 1 for frame in frames if frame.valid)


def test_a_stream_joined_mid_cycle_in_a_new_order_every_cycle_is_one_cycle_per_frame_once_learned() -> None:
    assembler = FrameAssembler(USPA46_ID_MAP)
    rng = np.random.default_rng(7)
    frames = []
    for cycle in range(21):
        order = [XELA_ORDER[i] for i in rng.permutation(24)]
        frames += _send_ids(assembler, cycle, order[9:] if cycle == 0 else order, t0_ns=cycle * 10 * MS)
    assert assembler.pause_threshold_ns is not None
    assert 0.1 * MS < assembler.pause_threshold_ns < 7.7 * MS  # between the gaps in a burst and the pause
    assert all(len(_cycles_in(frame)) == 1 for frame in frames if frame.valid)
    last = frames[-10:]
    assert all(frame.valid and _cycles_in(frame) == {cycle} for cycle, frame in zip(range(10, 20), last, strict=True))


def test_a_learned_order_alone_proves_nothing_when_the_host_shows_no_pauses() -> None:
    """Bursts read back to back (every gap the same): the learned order still closes frames, but it was learned from
    receive times, so without a pause the timing shows now no frame is proven: every one is flagged, none valid."""
    assembler = _warmed_up(USPA46_ID_MAP, order=list(range(24)))
    frames = []
    t_ns = WARM_UP * 10 * MS
    for cycle in range(WARM_UP, WARM_UP + 6):
        for arbitration_id in XELA_ORDER[1:] if cycle == WARM_UP + 2 else XELA_ORDER:
            index = USPA46_ID_MAP.ids.index(arbitration_id)
            frame = assembler.add(arbitration_id, encode_taxel_message(arbitration_id, *_counts(cycle, index)), t_ns)
            t_ns += 100_000
            if frame is not None:
                frames.append(frame)
    first, *rest = frames  # the first still follows the warm-up's pause: a whole cycle
    assert first.valid and len(_cycles_in(first)) == 1
    assert rest and not any(frame.valid for frame in rest)


def test_evenly_spaced_messages_drop_the_learned_pause_and_prove_no_frame() -> None:
    """A controller that stops sending bursts (every message 4 ms apart, each gap longer than the learned pause
    threshold): pause learning starts over, and nothing proves a frame meanwhile (none valid, none mixed)."""
    assembler = _warmed_up(USPA46_ID_MAP, order=list(range(24)))
    frames = []
    t_ns = WARM_UP * 10 * MS
    for cycle in range(WARM_UP, WARM_UP + 6):
        for arbitration_id in XELA_ORDER:
            index = assembler.id_map.ids.index(arbitration_id)
            frame = assembler.add(arbitration_id, encode_taxel_message(arbitration_id, *_counts(cycle, index)), t_ns)
            t_ns += 4 * MS
            if frame is not None:
                frames.append(frame)
    assert assembler.pause_threshold_ns is None
    assert frames and not any(frame.valid for frame in frames)


def _feed(assembler: FrameAssembler, messages: list[tuple[int, int, int]]) -> list:
    """Feed (cycle, taxel index, receive time ns) messages; return the frames that came out."""
    out = []
    for cycle, index, t_ns in messages:
        arbitration_id = assembler.id_map.ids[index]
        frame = assembler.add(arbitration_id, encode_taxel_message(arbitration_id, *_counts(cycle, index)), t_ns)
        if frame is not None:
            out.append(frame)
    return out


def test_offset_bursts_then_a_backlog_read_never_give_a_valid_mixed_frame() -> None:
    """The review's reproducer: the board sends 0..23 every 10 ms; for 7 cycles the host reads in bursts that end 6
    taxels late (receive-time pauses before taxel 6), so it learns the order (6..23, 0..5); then it reads a backlog
    (every message 0.1 ms apart). Before, 188 of 188 later frames were valid while mixing two cycles. Now none is
    valid until the receive times show real pauses again, and then every valid frame is one cycle."""
    assembler = FrameAssembler(ID_ORDER_46)
    stream = [(cycle, index) for cycle in range(200) for index in range(24)]
    t_ns, messages = 0, []
    for n, (cycle, index) in enumerate(stream):
        if n < 7 * 24 + 6:  # 7 offset bursts (6..23 of one cycle, 0..5 of the next): the pause falls before taxel 6
            t_ns += 7 * MS if index == 6 else 100_000
        elif n < 7 * 24 + 6 + 100 * 24:  # the backlog: evenly spaced
            t_ns += 100_000
        else:  # the host keeps up again: the pause is before taxel 0, where the cycle starts
            t_ns += 7 * MS if index == 0 else 100_000
        messages.append((cycle, index, t_ns))
    lying = _feed(assembler, messages[: 7 * 24 + 6])
    assert assembler.send_order is not None and assembler.send_order[0] == 6  # it learned the rotated order
    later = _feed(assembler, messages[7 * 24 + 6 :])
    assert len(later) >= 188
    mixed_valid = [f for f in later if f.valid and len(_cycles_in(f)) > 1]
    assert mixed_valid == []
    assert sum(f.valid for f in later[-20:]) >= 18  # recovered: the true order, frames valid again
    assert all(len(_cycles_in(f)) == 1 for f in later[-20:] if f.valid)
    assert lying  # (the offset bursts themselves cannot be told from a board sending 6..23, 0..5: docs/real-rig.md)


@settings(max_examples=60, deadline=None)
@given(
    order=st.permutations(list(range(24))),
    regimes=st.lists(st.sampled_from(["burst", "even", "jitter"]), min_size=8, max_size=30),
    lost=st.sets(st.integers(0, 30 * 24 - 1), max_size=40),
    seed=st.integers(0, 2**16),
)
def test_property_no_valid_frame_mixes_cycles_whatever_receive_timing_hides(
    order: list[int], regimes: list[str], lost: set[int], seed: int
) -> None:
    """Whatever the board's order, lost messages, and whether the host's receive times show the pauses (bursts),
    hide them (an even backlog read) or jitter: a frame flagged valid holds one cycle, in every taxel."""
    rng = np.random.default_rng(seed)
    assembler = FrameAssembler(ID_ORDER_46)
    t_ns, messages, n = 0, [], 0
    for cycle, regime in enumerate(regimes):
        for place, index in enumerate(order):
            n += 1
            if regime == "burst":
                t_ns += 7 * MS if place == 0 else 100_000
            elif regime == "even":
                t_ns += 100_000
            else:
                t_ns += int(rng.integers(20_000, 600_000))
            if n - 1 not in lost:
                messages.append((cycle, index, t_ns))
    frames = _feed(assembler, messages)
    assert all(len(_cycles_in(f)) == 1 for f in frames if f.valid)


def test_sentinel_flags_the_taxel_and_keeps_its_last_good_value() -> None:
    assembler = _warmed_up()
    c = WARM_UP
    invalid_before = assembler.invalid_messages
    (frame,) = _send_cycle(assembler, cycle=c, t0_ns=c * 10 * MS, sentinel=frozenset({4}))
    assert list(np.flatnonzero(frame.stale_mask)) == [4]
    assert tuple(frame.values[4]) == _counts(c - 1, 4)
    assert assembler.invalid_messages == invalid_before + 1
    (recovered,) = _send_cycle(assembler, cycle=c + 1, t0_ns=(c + 1) * 10 * MS)
    assert recovered.valid


def test_value_older_than_stale_after_is_flagged_even_in_a_complete_frame() -> None:
    assembler = FrameAssembler(ID_ORDER_46, stale_after_ns=50 * MS, cycle_start_id=0x100)
    ids = assembler.id_map.ids
    assembler.add(ids[0], encode_taxel_message(ids[0], 1, 2, 3), 0)
    for index in range(1, 24):  # the bus stalls 60 ms after taxel 0
        assert assembler.add(ids[index], encode_taxel_message(ids[index], 1, 2, 3), 60 * MS + index) is None
    frame = assembler.add(ids[0], encode_taxel_message(ids[0], 1, 2, 3), 70 * MS)  # the next cycle marks its end
    assert frame is not None and frame.one_cycle
    assert list(np.flatnonzero(frame.stale_mask)) == [0]
    assert not frame.valid


def test_evenly_spaced_cycles_need_a_known_first_id_and_are_valid_with_the_drivers_stale_limit() -> None:
    """Only ~2.5 ms per read is published: a controller sending one message per read spreads a cycle over 60 ms. No
    pause shows where a cycle starts, so only a known first id proves the frames."""
    for start_id, expect_valid in ((None, False), (0x100, True)):
        assembler = FrameAssembler(ID_ORDER_46, stale_after_ns=round(STALE_AFTER_S * 1e9), cycle_start_id=start_id)
        ids = assembler.id_map.ids
        frames = []
        for cycle in range(6):
            for index in range(24):
                t_ns = (cycle * 24 + index) * 2_500_000
                frame = assembler.add(ids[index], encode_taxel_message(ids[index], 1, 2, 3), t_ns)
                if frame is not None:
                    frames.append(frame)
        assert assembler.pause_threshold_ns is None  # evenly spaced messages show no pause to learn from
        assert len(frames) >= 5 and all(frame.valid == expect_valid for frame in frames)


def test_uspa46_cycle_in_id_order_puts_s1_0x135_at_the_top_left_taxel() -> None:
    """A controller sending 0x100 first; the frame is in XELA's numbering (s1 = 0x135 = taxel 0, s24 = 0x100 = 23)."""
    assembler = FrameAssembler(USPA46_ID_MAP, cycle_start_id=0x100)
    frames = []
    for cycle in range(3):
        for step, arbitration_id in enumerate(sorted(USPA46_ID_MAP.ids)):
            payload = encode_taxel_message(arbitration_id, 1000 + arbitration_id, 2000 + cycle, 3000)
            frame = assembler.add(arbitration_id, payload, cycle * 10 * MS + step * 100_000)
            if frame is not None:
                frames.append(frame)
    assert len(frames) == 2 and all(frame.valid for frame in frames)
    assert tuple(frames[1].values[0]) == (1000 + 0x135, 2001, 3000)
    assert tuple(frames[1].values[6]) == (1000 + 0x125, 2001, 3000)  # s7: row 1, col 0
    assert tuple(frames[1].values[23]) == (1000 + 0x100, 2001, 3000)


def test_unknown_ids_and_short_payloads_are_counted_not_raised() -> None:
    assembler = FrameAssembler(ID_ORDER_46, cycle_start_id=0x100)
    assert assembler.add(0x700, bytes(8), 0) is None
    assert assembler.add(0x100, b"\x00\x01", 1) is None  # known id, too short: an invalid report
    assert (assembler.messages, assembler.unknown_ids, assembler.invalid_messages) == (2, 1, 1)
    frames = _send_cycle(assembler, cycle=0, t0_ns=10, order=list(range(1, 24)))
    frames += _send_cycle(assembler, cycle=1, t0_ns=10 * MS, order=[0])
    assert len(frames) == 1 and list(np.flatnonzero(frames[0].stale_mask)) == [0]


@settings(max_examples=60, deadline=None)
@given(
    st.lists(st.frozensets(st.integers(1, 23), max_size=6), min_size=1, max_size=8),
    st.booleans(),
)
def test_each_frame_flags_exactly_the_taxels_its_cycle_lost(drops: list[frozenset[int]], uspa44: bool) -> None:
    """Model check on a bus that sends taxels in id order (taxel 0, the known first id, never lost): frame k ==
    cycle k."""
    id_map = USPA44_ID_MAP if uspa44 else ID_ORDER_46
    assembler = FrameAssembler(id_map, cycle_start_id=id_map.ids[0])
    n = id_map.n_taxels
    frames = []
    for cycle, lost in enumerate(drops):
        frames += _send_cycle(assembler, cycle, t0_ns=cycle * 10 * MS, skip=frozenset(i for i in lost if i < n))
    frames += _send_cycle(assembler, len(drops), t0_ns=len(drops) * 10 * MS)  # closes the last lossy cycle
    frames += _send_cycle(assembler, len(drops) + 1, t0_ns=(len(drops) + 1) * 10 * MS, order=[0])  # marks its end
    assert len(frames) == len(drops) + 1
    last_good = {index: (0, 0, 0) for index in range(n)}
    for cycle, frame in enumerate(frames):
        dropped: set[int] = {i for i in drops[cycle] if i < n} if cycle < len(drops) else set()
        assert frame.one_cycle and set(np.flatnonzero(frame.stale_mask)) == dropped
        for index in range(n):
            if index not in dropped:
                last_good[index] = _counts(cycle, index)
            assert tuple(frame.values[index]) == last_good[index]
    assert assembler.incomplete_frames == sum(1 for d in drops if any(i < n for i in d))


@settings(max_examples=100, deadline=None)
@given(st.lists(st.tuples(st.integers(0x0FF, 0x136), st.binary(max_size=8)), max_size=80))
def test_arbitrary_messages_never_crash_the_assembler(messages: list[tuple[int, bytes]]) -> None:
    assembler = FrameAssembler()
    for t_ns, (arbitration_id, data) in enumerate(messages):
        frame = assembler.add(arbitration_id, data, t_ns)
        if frame is not None:
            assert frame.values.shape == (24, 3) and frame.stale_mask.shape == (24,)
            assert frame.valid == (frame.one_cycle and not frame.stale_mask.any())
    assert assembler.messages == len(messages)
    assert assembler.frames <= assembler.messages


@settings(max_examples=200, deadline=None)
@given(st.integers(0, 0xFFFF), st.integers(0, 0xFFFF), st.integers(0, 0xFFFF), st.integers(0, 255))
def test_taxel_message_round_trip(x: int, y: int, z: int, byte0: int) -> None:
    message = decode_taxel_message(0x100, encode_taxel_message(0x100, x, y, z, byte0=byte0))
    assert (message.x, message.y, message.z) == (x, y, z)
    assert message.valid == (x < 0xFA00 and (x, y, z) != (0, 0, 0))


def test_invalid_taxels_of_a_whole_frame_follow_the_message_rule() -> None:
    values = np.array([[0xF9FF, 0, 0], [0xFA00, 5, 5], [0, 0, 0], [0, 0, 1], [0xFFFF, 0xFFFF, 0xFFFF]])
    assert invalid_taxels(values).tolist() == [False, True, True, False, True]


def test_a_drained_transports_quiet_ends_a_waiting_frame_only_once_it_is_a_pause() -> None:
    """Without a learned order a whole cycle waits for the next message to show the pause after it; a receive that
    finds nothing (``flush``) lets it out as soon as the quiet since its last message is a pause, never earlier."""
    rng = np.random.default_rng(4)
    assembler = FrameAssembler(ID_ORDER_46)
    for cycle in range(WARM_UP):
        _send_cycle(assembler, cycle=cycle, t0_ns=cycle * 10 * MS, order=list(rng.permutation(24)))
    assert assembler.send_order is None and assembler.pause_threshold_ns is not None
    c = WARM_UP
    (_previous,) = _send_cycle(assembler, cycle=c, t0_ns=c * 10 * MS, order=list(rng.permutation(24)))
    last_ns = c * 10 * MS + 23 * 100_000
    assert assembler.flush(last_ns + 200_000) is None  # 0.2 ms of quiet: could be a gap inside a cycle
    frame = assembler.flush(last_ns + assembler.pause_threshold_ns)
    assert frame is not None and frame.valid and _cycles_in(frame) == {c}
    assert assembler.flush(last_ns + 20 * MS) is None  # nothing waits any more
