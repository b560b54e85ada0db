"""UskinCanDriver over the simulated controller on python-can's virtual bus and through SLCAN (python-can slcan)."""

from __future__ import annotations

import contextlib
import itertools
import time
from collections.abc import Iterator
from typing import Literal

import numpy as np
import pytest

from drivers.clock import VirtualClock
from drivers.errors import DeviceError, DeviceNotFound
from drivers.frames import TactileFrame
from drivers.layouts import USKIN
from drivers.uskin import UskinCanDriver, open_can_bus
from tests.drivers.driver_helpers import PERIOD_NS, collect, run_mode, step
from unitac_rig.sim.devices import SimSlcanAdapter, SimXelaController, counts_from_sample
from unitac_rig.sim.faults import FaultPlan
from unitac_rig.sim.sensor_signals import SensorSample, SignalSource
from unitac_rig.sim.synthetic_sources import PressSource, RecordingSource

_channels = itertools.count()


@contextlib.contextmanager
def can_rig(
    transport: str,
    clock: VirtualClock,
    source: SignalSource,
    *,
    can_faults: FaultPlan | None = None,
    serial_faults: FaultPlan | None = None,
    missing_taxels: tuple[int, ...] = (),
    send_order: Literal["id", "map", "shuffled"] = "id",
) -> Iterator[tuple[UskinCanDriver, SimXelaController, SimSlcanAdapter | None]]:
    channel = f"uskin-driver-test-{next(_channels)}"
    controller = SimXelaController(
        channel, source=source, clock=clock, faults=can_faults, missing_taxels=missing_taxels, send_order=send_order
    )
    adapter = None
    driver = None
    try:
        if transport == "virtual":
            bus = open_can_bus("virtual", channel)
        else:
            adapter = SimSlcanAdapter(channel, clock=clock, faults=serial_faults)
            bus = open_can_bus("slcan", adapter.url, sleep_after_open=0)
        driver = UskinCanDriver(bus, clock=clock, owns_bus=True)
        driver.connect()
        yield driver, controller, adapter
    finally:
        if driver is not None:
            driver.disconnect()
        if adapter is not None:
            adapter.close()
        controller.close()


def sent_counts(source: RecordingSource) -> list[np.ndarray]:
    return [counts_from_sample(sample.values) for _, sample in source.samples]


def assert_every_row_was_sent(frames: list[TactileFrame], sent: list[np.ndarray]) -> None:
    """No invented counts: each taxel of each valid frame carries that taxel's counts from one of the samples.

    (The wire has no frame counter, so after a lost message the assembler may pair a taxel with the neighbouring
    sample; it never makes values up.)
    """
    history = np.stack(sent)  # (samples, taxels, 3)
    for frame in frames:
        if frame.valid:
            assert np.all(np.any(np.all(history == frame.values[None], axis=2), axis=0))


@pytest.mark.parametrize("transport", ["virtual", "slcan"])
@pytest.mark.parametrize("mode", ["poll", "reader"])
def test_frames_carry_exactly_the_counts_the_controller_sent(transport: str, mode: str) -> None:
    clock = VirtualClock()
    source = RecordingSource(PressSource(USKIN, seed=5))
    with can_rig(transport, clock, source) as (driver, _, _):
        frames = run_mode(mode, clock, driver, 40)
        assert len(frames) == 40
        # nothing on the wire shows that the stream began at a cycle's start: the first frame is flagged, unproven
        assert not frames[0].valid and frames[0].stale_mask is not None and frames[0].stale_mask.all()
        assert all(f.valid and f.seq is None and f.sensor == "uskin" for f in frames[1:])
        for frame, counts in zip(frames, sent_counts(source), strict=True):
            np.testing.assert_array_equal(frame.values, counts)
        assert [f.host_t_ns for f in frames] == sorted(f.host_t_ns for f in frames)
        health = driver.health()
        assert (health.frames, health.invalid_frames, health.stalls) == (40, 1, 0)
        assert driver.link_counters()["unproven_frames"] == 1


@pytest.mark.parametrize("order", ["map", "shuffled"])
def test_a_board_sending_in_another_order_gives_the_same_frames(order: Literal["map", "shuffled"]) -> None:
    """No source states the order a board sends a cycle in: XELA's map order (0x135 first) or a new order every
    cycle give every frame whole, each with exactly one sample's counts, and a lost message flags one frame."""
    clock = VirtualClock()
    source = RecordingSource(PressSource(USKIN, seed=5))
    plan = FaultPlan(seed=4, drop_message_prob=0.004)
    with can_rig("virtual", clock, source, can_faults=plan, send_order=order) as (driver, controller, _):
        frames = step(clock, driver, 60)
        damaged = {i // 24 for i in controller.faults.counts.dropped_indices}
    sent = sent_counts(source)
    assert damaged and len(frames) >= 59
    for frame in frames:
        if frame.valid:
            assert any(np.array_equal(frame.values, counts) for counts in sent)  # one sample, never a mix
    assert sum(not f.valid for f in frames) <= len(damaged) + 1  # + the first frame, which nothing proves


def test_a_silent_taxel_flags_every_frame_and_names_the_taxel() -> None:
    clock = VirtualClock()
    with can_rig("virtual", clock, PressSource(USKIN), missing_taxels=(7,)) as (driver, _, _):
        frames = step(clock, driver, 20)
    # each cycle closes when taxel 0 reports again, so the frame of the last sample is still open
    assert len(frames) == 19
    assert not any(f.valid for f in frames)
    assert frames[0].stale_mask is not None and frames[0].stale_mask.all()  # where the stream began is unknown
    for frame in frames[1:]:
        assert frame.stale_mask is not None
        assert np.flatnonzero(frame.stale_mask).tolist() == [7]
    assert driver.health().invalid_frames == 19


def test_dropped_can_messages_flag_frames_and_never_invent_counts() -> None:
    clock = VirtualClock()
    source = RecordingSource(PressSource(USKIN))
    plan = FaultPlan(seed=11, drop_message_prob=0.005)
    with can_rig("virtual", clock, source, can_faults=plan) as (driver, controller, _):
        frames = step(clock, driver, 100)
        damaged = {i // 24 for i in controller.faults.counts.dropped_indices}
    assert len(damaged) >= 3, "the seed should drop a few messages"
    health = driver.health()
    assert 1 <= health.invalid_frames <= len(damaged) + 1  # + the first frame, which nothing proves
    assert health.frames >= 100 - len(damaged) - 1
    assert_every_row_was_sent(frames, sent_counts(source))


def test_stall_is_detected_by_the_clock_and_clears_when_frames_return() -> None:
    clock = VirtualClock()
    with can_rig("virtual", clock, PressSource(USKIN)) as (driver, controller, _):
        assert len(step(clock, driver, 5)) == 5
        controller.faults.force_stall()
        assert step(clock, driver, 60) == []  # 0.6 s > 0.5 s stall timeout
        assert driver.stalled and driver.health().stalls == 1
        controller.faults.force_stall(False)
        assert len(step(clock, driver, 5)) == 5
        assert not driver.stalled and driver.health().stalls == 1


def test_controller_power_loss_needs_a_reconnect_to_stream_again() -> None:
    clock = VirtualClock()
    with can_rig("virtual", clock, PressSource(USKIN)) as (driver, controller, _):
        step(clock, driver, 3)
        controller.faults.force_disconnect()
        step(clock, driver, 5)
        controller.faults.force_disconnect(False)
        assert step(clock, driver, 60) == []  # powered again but waiting for a start command
        assert driver.health().stalls == 1
        driver.reconnect()
        assert len(step(clock, driver, 5)) == 5
        assert driver.health().reconnects == 1


@pytest.mark.parametrize("mode", ["poll", "reader"])
def test_unplugged_slcan_adapter_raises_and_a_new_bus_works_after_replug(mode: str) -> None:
    clock = VirtualClock()
    with can_rig("slcan", clock, PressSource(USKIN)) as (driver, _, adapter):
        assert adapter is not None
        if mode == "reader":
            driver.start_reader()
        adapter.faults.force_disconnect()
        clock.advance_ns(PERIOD_NS)
        with pytest.raises(DeviceError, match="CAN bus failed"):
            for _ in range(500):
                driver.poll()
                if mode == "reader":
                    time.sleep(0.002)
        driver.stop_reader()
        with pytest.raises(DeviceNotFound):
            open_can_bus("slcan", adapter.url, sleep_after_open=0)
        adapter.faults.force_disconnect(False)
        replugged = UskinCanDriver(open_can_bus("slcan", adapter.url, sleep_after_open=0), clock=clock, owns_bus=True)
        try:
            replugged.connect()
            assert len(step(clock, replugged, 5)) == 5
        finally:
            replugged.disconnect()


def test_split_reads_and_lost_slcan_lines_keep_intact_frames_exact() -> None:
    clock = VirtualClock()
    source = RecordingSource(PressSource(USKIN))
    plan = FaultPlan(seed=3, split_max_bytes=7, drop_message_prob=0.003)
    with can_rig("slcan", clock, source, serial_faults=plan) as (driver, _, adapter):
        frames = step(clock, driver, 60)
        assert adapter is not None
        damaged = {i // 24 for i in adapter.faults.counts.dropped_indices}
    assert damaged
    assert 1 <= driver.health().invalid_frames <= len(damaged) + 1  # + the first frame, which nothing proves
    assert len(frames) >= 60 - len(damaged) - 1
    assert_every_row_was_sent(frames, sent_counts(source))
    # before the first lost line every frame is exactly its sample
    first_damaged = min(damaged)
    for frame, counts in zip(frames[:first_damaged], sent_counts(source), strict=False):
        np.testing.assert_array_equal(frame.values, counts)


def test_garbage_on_the_slcan_line_is_skipped_and_counted() -> None:
    clock = VirtualClock()
    source = RecordingSource(PressSource(USKIN))
    plan = FaultPlan(seed=4, garbage_prob=0.01)
    with can_rig("slcan", clock, source, serial_faults=plan) as (driver, _, _):
        frames = step(clock, driver, 60)
        frames += step(clock, driver, 60)
    valid = [f for f in frames if f.valid]
    assert len(valid) > 60  # the stream survives
    assert driver.health().invalid_frames > 0 and driver.health().checksum_errors > 0
    assert_every_row_was_sent(frames, sent_counts(source))


class _Idle:
    """Counts that sit still except for small noise, with one dead (frozen) and one saturated taxel."""

    def __init__(self) -> None:
        self.rng = np.random.default_rng(0)

    def sample(self, t_ns: int) -> SensorSample:
        values = 30_000.0 + self.rng.normal(0, 5, size=(24, 3))
        values[3] = [20_000, 20_000, 20_000]
        values[9, 2] = 65_300
        return SensorSample(values=values)


def test_health_names_saturated_and_dead_taxels() -> None:
    clock = VirtualClock()
    with can_rig("virtual", clock, _Idle()) as (driver, _, _):
        step(clock, driver, 50)
        assert driver.health().saturated_taxels == [9]
        assert driver.health().dead_taxels == []  # not enough frames to judge yet
        step(clock, driver, 60)
        assert driver.health().dead_taxels == [3]  # taxel 9 is pinned on z only; x and y still move


def test_tare_takes_the_unloaded_median_and_refuses_during_a_press() -> None:
    clock = VirtualClock()
    source = RecordingSource(PressSource(USKIN, period_s=2.0, rest_fraction=0.5))
    with can_rig("virtual", clock, source) as (driver, _, _):
        rest = step(clock, driver, 50)  # 0..0.5 s: unloaded
        record = driver.tare(rest)
        # the first frame is flagged (nothing shows the stream began at a cycle's start), so 49 count
        expected = np.median([counts_from_sample(s.values) for _, s in source.samples[1:50]], axis=0)
        np.testing.assert_allclose(record.baseline, expected)
        assert record.method == "host-median" and record.n_frames == 49 and record.spread < 50
        step(clock, driver, 70)
        pressing = step(clock, driver, 50)  # 1.2..1.7 s: the press peaks
        with pytest.raises(DeviceError, match="tare refused"):
            driver.tare(pressing)
        with pytest.raises(DeviceError, match="at least"):
            driver.tare(rest[:2])


def test_one_frame_damaged_on_the_wire_neither_shifts_the_tare_nor_refuses_it() -> None:
    """SLCAN lines carry no checksum: a damaged one can decode as a wild count in one frame. The tare's median and
    MAD-based spread ignore it (a mean moved by ~600 counts and a standard deviation of ~4,600 refused the tare)."""
    from drivers.frames import TactileFrame
    from drivers.uskin import uskin_host_tare

    rng = np.random.default_rng(0)
    frames = [
        TactileFrame("uskin", host_t_ns=i, values=32768 + rng.normal(0, 3, (24, 3)), valid=True) for i in range(49)
    ]
    frames[20].values[7, 2] = 65535.0  # one line damaged on the wire
    record = uskin_host_tare(frames, 0, 50.0)
    assert abs(record.baseline[7, 2] - 32768) < 5 and record.spread < 10


def test_open_can_bus_wraps_python_can_errors_with_a_hint() -> None:
    with pytest.raises(DeviceNotFound) as info:
        open_can_bus("slcan", "/dev/ttyDOES-NOT-EXIST")
    assert info.value.hint and "dialout" in info.value.hint
    with pytest.raises(DeviceNotFound):
        open_can_bus("no-such-interface", "x")


def test_collect_helper_on_reader_mode_matches_poll_after_stop() -> None:
    """Frames queued by the reader before stop_reader() are still handed out by poll()."""
    clock = VirtualClock()
    with can_rig("virtual", clock, PressSource(USKIN)) as (driver, _, _):
        driver.start_reader()
        for _ in range(10):
            clock.advance_ns(PERIOD_NS)
        first = collect(driver, 4)
        driver.stop_reader()
        rest = driver.poll()
        assert len(first) + len(rest) == 10


def test_slcan_serial_side_defaults_to_the_kits_3_mbaud_with_rts_cts_unless_the_channel_names_a_speed() -> None:
    """slcand -S 3000000 -t hw: python-can's own defaults (115200 baud, no flow control) cannot carry the stream."""
    clock = VirtualClock()
    adapter = SimSlcanAdapter(f"uskin-driver-test-{next(_channels)}", clock=clock)
    try:
        bus = open_can_bus("slcan", adapter.url, sleep_after_open=0)
        try:
            port = bus.serialPortOrig  # type: ignore[attr-defined]
            assert (port.baudrate, port.rtscts) == (3_000_000, True)
        finally:
            bus.shutdown()
        bus = open_can_bus("slcan", f"{adapter.url}@115200", sleep_after_open=0)
        try:
            port = bus.serialPortOrig  # type: ignore[attr-defined]
            assert (port.baudrate, port.rtscts) == (115_200, False)
        finally:
            bus.shutdown()
    finally:
        adapter.close()


@pytest.mark.parametrize(("transport", "checksum"), [("virtual", "CAN CRC"), ("slcan", "none (slcan serial lines)")])
def test_the_driver_says_whether_its_wire_carries_a_checksum(transport: str, checksum: str) -> None:
    """Over slcan the ASCII lines carry no checksum: the session's sensor identity records what `valid` rests on."""
    with can_rig(transport, VirtualClock(), PressSource(USKIN)) as (driver, _, _):
        assert driver.identity()["wire_checksum"] == checksum
