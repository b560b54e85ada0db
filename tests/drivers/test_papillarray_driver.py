"""PapillArrayDriver over the simulated hub behind the simpapill:// pyserial URL."""

from __future__ import annotations

import contextlib
import time
from collections.abc import Iterator

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from drivers.clock import VirtualClock
from drivers.errors import DeviceError, DeviceNotFound
from drivers.frames import TactileFrame
from drivers.layouts import PAPILLARRAY
from drivers.papillarray import PapillArrayDriver, implausible_pillars
from drivers.sensor_base import WRONG_SHAPE_LIMIT
from protocols.papillarray import PapillArrayPacket, PillarSensorData, encode_packet
from tests.drivers.driver_helpers import PERIOD_NS, run_mode, step
from unitac_rig.sim.devices import SimPapillArrayHub
from unitac_rig.sim.faults import FaultPlan
from unitac_rig.sim.sensor_models import PapillArrayParams
from unitac_rig.sim.sensor_signals import SensorSample, SignalSource
from unitac_rig.sim.synthetic_sources import PressSource, RecordingSource


@contextlib.contextmanager
def hub_rig(
    clock: VirtualClock, source: SignalSource, *, faults: FaultPlan | None = None, slot: int = 0
) -> Iterator[tuple[PapillArrayDriver, SimPapillArrayHub]]:
    hub = SimPapillArrayHub(source=source, clock=clock, faults=faults, slot=slot)
    driver = PapillArrayDriver(hub.url, clock=clock, slot=slot)
    try:
        driver.connect()
        yield driver, hub
    finally:
        driver.disconnect()
        hub.close()


def by_time(source: RecordingSource) -> dict[int, SensorSample]:
    """What the source produced, keyed by its time in us (= the hub timestamp: the hub powered up at t = 0)."""
    return {t_ns // 1000: sample for t_ns, sample in source.samples}


def assert_frames_match_source(frames: list[TactileFrame], source: RecordingSource) -> None:
    sent = by_time(source)
    for frame in frames:
        assert frame.device_t_us is not None
        sample = sent[frame.device_t_us]
        np.testing.assert_allclose(frame.values, sample.values, rtol=1e-6, atol=1e-6)  # float32 on the wire
        assert frame.displacement_mm is not None and sample.displacement_mm is not None
        np.testing.assert_allclose(frame.displacement_mm, sample.displacement_mm, rtol=1e-6, atol=1e-6)


@pytest.mark.parametrize("mode", ["poll", "reader"])
@pytest.mark.parametrize("slot", [0, 1])
def test_frames_carry_the_source_forces_and_displacements_with_hub_counter_and_time(mode: str, slot: int) -> None:
    clock = VirtualClock()
    source = RecordingSource(PressSource(PAPILLARRAY, seed=2))
    with hub_rig(clock, source, slot=slot) as (driver, hub):
        assert hub.rate_hz == 100  # the driver set it on connect
        frames = run_mode(mode, clock, driver, 30)
    assert len(frames) == 30
    assert [f.seq for f in frames] == list(range(30))
    assert np.diff([f.device_t_us for f in frames]).tolist() == [10_000] * 29
    assert all(f.valid and f.sensor == "papillarray" for f in frames)
    assert_frames_match_source(frames, source)
    assert driver.health().sequence_gaps == 0


def test_corrupted_packets_and_garbage_lose_only_the_damaged_packets() -> None:
    clock = VirtualClock()
    source = RecordingSource(PressSource(PAPILLARRAY))
    plan = FaultPlan(seed=9, corrupt_prob=0.1, garbage_prob=0.1, split_max_bytes=300)
    with hub_rig(clock, source, faults=plan) as (driver, hub):
        frames = step(clock, driver, 100)
        frames += step(clock, driver, 5, period_ns=0)  # drain what the split reads left behind
        counts = hub.faults.counts
    assert counts.messages_corrupted > 3 and counts.garbage_bytes > 0
    assert_frames_match_source(frames, source)
    corrupted = set(counts.corrupted_indices)
    expected_seqs = [i for i in range(counts.messages_seen) if i not in corrupted]
    assert [f.seq for f in frames] == expected_seqs
    health = driver.health()
    assert health.bytes_dropped >= counts.garbage_bytes
    assert health.checksum_errors >= 1
    assert health.sequence_gaps == len([i for i in corrupted if i < expected_seqs[-1]])


def test_dropped_packets_show_up_as_counter_gaps() -> None:
    clock = VirtualClock()
    with hub_rig(clock, PressSource(PAPILLARRAY), faults=FaultPlan(seed=1, drop_message_prob=0.1)) as (driver, hub):
        frames = step(clock, driver, 100)
        dropped = hub.faults.counts.dropped_indices
    assert dropped
    assert len(frames) == 100 - len(dropped)
    last_seq = frames[-1].seq
    assert last_seq is not None
    assert driver.health().sequence_gaps == len([i for i in dropped if i < last_seq])


@settings(max_examples=15, deadline=None)
@given(seed=st.integers(0, 2**16), split_max_bytes=st.integers(1, 900))
def test_any_chunking_of_the_stream_yields_every_packet_in_order(seed: int, split_max_bytes: int) -> None:
    clock = VirtualClock()
    plan = FaultPlan(seed=seed, split_max_bytes=split_max_bytes)
    with hub_rig(clock, PressSource(PAPILLARRAY, seed=seed), faults=plan) as (driver, _):
        frames = step(clock, driver, 8)
        for _ in range(200):
            if len(frames) == 8:
                break
            frames += driver.poll()
    assert [f.seq for f in frames] == list(range(8))
    health = driver.health()
    assert (health.checksum_errors, health.bytes_dropped, health.sequence_gaps) == (0, 0, 0)


def test_stall_detected_then_cleared() -> None:
    clock = VirtualClock()
    with hub_rig(clock, PressSource(PAPILLARRAY)) as (driver, hub):
        step(clock, driver, 5)
        hub.faults.force_stall()
        assert step(clock, driver, 60) == []
        assert driver.stalled and driver.health().stalls == 1
        hub.faults.force_stall(False)
        frames = step(clock, driver, 3)
        assert len(frames) == 3 and not driver.stalled
        # the hub kept counting while nothing reached the host
        assert driver.health().sequence_gaps == 60


@pytest.mark.parametrize("mode", ["poll", "reader"])
def test_unplugged_hub_raises_and_reconnect_after_replug_restores_rate_and_stream(mode: str) -> None:
    clock = VirtualClock()
    with hub_rig(clock, PressSource(PAPILLARRAY)) as (driver, hub):
        step(clock, driver, 3)
        if mode == "reader":
            driver.start_reader()
        hub.faults.force_disconnect()
        clock.advance_ns(PERIOD_NS)
        with pytest.raises(DeviceError, match="went away"):
            for _ in range(1000):
                driver.poll()
                time.sleep(0.001)
        with pytest.raises(DeviceNotFound):
            driver.reconnect()  # still unplugged
        hub.faults.force_disconnect(False)
        clock.advance_ns(PERIOD_NS)  # powers up again at 1000 Hz
        assert hub.rate_hz == 1000
        driver.reconnect()
        assert hub.rate_hz == 100
        frames = step(clock, driver, 5)
        assert [f.seq for f in frames] == [0, 1, 2, 3, 4]  # the hub's counter restarted at power-up
        assert driver.health().reconnects == 1


def test_tare_biases_the_hub_when_unloaded_and_refuses_under_load_or_motion() -> None:
    clock = VirtualClock()
    source = PressSource(PAPILLARRAY, period_s=8.0, rest_fraction=0.5, params=PapillArrayParams(offset_sd_mm=0.03))
    offset_n = source.model.offset_n[4, 2]  # the unbiased hub's offset on the centre pillar's z, N
    with hub_rig(clock, source) as (driver, hub):
        idle = step(clock, driver, 50)
        assert abs(offset_n) > 0.05
        assert np.mean([f.values[4, 2] for f in idle]) == pytest.approx(offset_n, abs=0.02)
        record = driver.tare(idle)
        assert hub.biased and record.method == "device-bias" and record.spread < 0.1
        np.testing.assert_array_equal(record.baseline, np.zeros((9, 3)))
        after = step(clock, driver, 20)
        assert np.abs(np.mean([f.values[:, 2] for f in after], axis=0)).max() < 0.02
        step(clock, driver, 300)  # the tare took 2 s: now at 5.7 s, into the press
        loaded = step(clock, driver, 20)
        with pytest.raises(DeviceError, match="contact"):
            driver.tare(loaded)
    with hub_rig(
        VirtualClock(),
        PressSource(PAPILLARRAY, peak_load_n=0.0, params=PapillArrayParams(noise_mm=0.02, offset_sd_mm=0.0)),
    ) as (
        driver,
        hub,
    ):
        shaky = step(hub.clock, driver, 50)  # type: ignore[arg-type]
        with pytest.raises(DeviceError, match="std"):
            driver.tare(shaky)
        assert not hub.biased


def test_missing_port_unknown_scheme_and_bad_settings_are_reported() -> None:
    with pytest.raises(DeviceNotFound) as info:
        PapillArrayDriver("/dev/ttyACM-not-here").connect()
    assert info.value.hint is not None and "dialout" in info.value.hint
    with pytest.raises(DeviceNotFound):
        PapillArrayDriver("nosuchscheme://x").connect()
    with pytest.raises(DeviceNotFound):
        PapillArrayDriver("simpapill://no-hub-by-this-name").connect()
    with pytest.raises(DeviceError, match="rate"):
        PapillArrayDriver("simpapill://x", rate_hz=300)
    with pytest.raises(DeviceError, match="slot"):
        PapillArrayDriver("simpapill://x", slot=2)


def test_a_slot_with_another_pillar_count_is_one_clear_device_error() -> None:
    """The stream allows up to 25 pillars per sensor; a 2x2 array in the slot must not reach the 3x3 pipeline."""
    driver = PapillArrayDriver("loop://", clock=VirtualClock())
    driver.connect()  # loop:// echoes the driver's own commands: garbage the parser skips
    try:
        packet = PapillArrayPacket(counter=1, timestamp_us=0, sensors=[PillarSensorData.unloaded(4)])
        driver._port.write(encode_packet(packet))  # type: ignore[union-attr]
        assert driver.poll() == [] and driver.health().checksum_errors == 1  # one could be damage: skipped
        with pytest.raises(DeviceError, match="reports 4 pillars"):  # a whole run of them is the wrong array
            for _ in range(WRONG_SHAPE_LIMIT - 1):
                driver._port.write(encode_packet(packet))  # type: ignore[union-attr]  # (loop:// holds 4 KiB)
                driver.poll()
    finally:
        driver.disconnect()


def test_a_stream_without_hub_or_global_blocks_still_gives_frames() -> None:
    """A controller (or a fake written from the packet facts) that sends pillar data alone: frames carry the pillar
    forces and displacements, with no device counter or time, and no counter gaps are invented."""
    driver = PapillArrayDriver("loop://", clock=VirtualClock())
    driver.connect()
    try:
        sensor = PillarSensorData.unloaded()
        sensor.forces_n[4] = [0.25, -0.5, 3.0]  # the centre pillar pressed
        sensor.displacements_mm[4] = [0.0, 0.0, 0.75]
        packet = PapillArrayPacket(counter=None, timestamp_us=None, sensors=[sensor, PillarSensorData.unloaded()])
        for _ in range(3):
            driver._port.write(encode_packet(packet, include_slip=False, include_global=False))  # type: ignore[union-attr]
        frames = driver.poll()
        assert len(frames) == 3
        assert all(f.seq is None and f.device_t_us is None for f in frames)
        assert frames[-1].values[4].tolist() == [0.25, -0.5, 3.0]
        assert frames[-1].displacement_mm is not None and frames[-1].displacement_mm[4].tolist() == [0.0, 0.0, 0.75]
        assert driver.health().sequence_gaps == 0
        for counter in (5, None, 6):  # a hub block now and then: nothing to compare against in between
            mixed = PapillArrayPacket(counter, None if counter is None else 0, packet.sensors)
            driver._port.write(encode_packet(mixed))  # type: ignore[union-attr]
        assert [f.seq for f in driver.poll()] == [5, None, 6]
        assert driver.health().sequence_gaps == 0
    finally:
        driver.disconnect()


def _packet_with(counter: int, fz: dict[int, float]) -> PapillArrayPacket:
    sensor = PillarSensorData.unloaded()
    for pillar, value in fz.items():
        sensor.forces_n[pillar, 2] = value
        sensor.displacements_mm[pillar, 2] = value / 6.0  # about 6 N/mm, as the rated 15 N at 2.5 mm
    return PapillArrayPacket(
        counter=counter, timestamp_us=counter * 1000, sensors=[sensor, PillarSensorData.unloaded()]
    )


def test_bit_flips_the_checksum_cannot_see_are_caught_as_impossible_values_and_counted() -> None:
    """Issue 28: the checksum is a 16-bit byte sum, so a bit set in one byte and the same bit cleared in another
    cancel. Here pillar 4's Fz (1.5 N) becomes NaN and pillar 5's (2.5 N) a denormal; the packet passes the checksum,
    and the driver flags pillar 4 and counts the frame, and the health report says what the checksum misses."""
    driver = PapillArrayDriver("loop://", clock=VirtualClock(), rate_hz=1000)
    driver.connect()
    try:
        good = encode_packet(_packet_with(1, {4: 1.5, 5: 2.5}))
        damaged = bytearray(encode_packet(_packet_with(2, {4: 1.5, 5: 2.5})))
        at_4, at_5 = damaged.find(np.float32(1.5).tobytes()), damaged.find(np.float32(2.5).tobytes())
        assert damaged.count(np.float32(1.5).tobytes()) == 1 and damaged.count(np.float32(2.5).tobytes()) == 1
        damaged[at_4 + 3] ^= 0x40  # 0x3f -> 0x7f: bit 6 set
        damaged[at_5 + 3] ^= 0x40  # 0x40 -> 0x00: bit 6 cleared, the byte sum is unchanged
        after = encode_packet(_packet_with(3, {4: 1.5, 5: 2.5}))
        driver._port.write(good + bytes(damaged) + after)  # type: ignore[union-attr]
        frames = driver.poll()
        health = driver.health()
    finally:
        driver.disconnect()
    assert [f.seq for f in frames] == [1, 2, 3]  # the damaged packet passed the checksum
    assert [f.valid for f in frames] == [True, False, True]
    assert frames[1].stale_mask is not None and np.flatnonzero(frames[1].stale_mask).tolist() == [4]
    assert (health.implausible_frames, health.checksum_errors, health.invalid_frames) == (1, 0, 1)
    assert "16-bit" in health.link_check and "cancel" in health.link_check


@pytest.mark.parametrize(
    ("reading", "previous", "dt_s", "flagged"),
    [
        ([0.5, -0.5, 14.9, 0.1, -0.1, 2.4], None, None, False),  # within the rated range
        ([15.9, -15.9, 59.9, 3.9, -3.9, 9.9], None, None, False),  # overload, but a pillar can be driven there
        ([16.1, 0, 0, 0, 0, 0], None, None, True),  # 4x the rated shear
        ([0, 0, 60.1, 0, 0, 0], None, None, True),
        ([0, 0, 0, 0, 0, 10.1], None, None, True),  # a tip 10 mm down
        ([0, 0, float("nan"), 0, 0, 0], None, None, True),
        ([0, 0, float("inf"), 0, 0, 0], None, None, True),
        ([0, 0, 1e30, 0, 0, 0], None, None, True),
        ([0, 0, 50.0, 0, 0, 0], [0, 0, -50.0, 0, 0, 0], 0.001, True),  # 100 N in 1 ms: over 77 % of the span
        ([0, 0, 50.0, 0, 0, 0], [0, 0, -50.0, 0, 0, 0], 0.01, False),  # in 10 ms the filter lets it through
        ([0, 0, 14.0, 0, 0, 2.0], [0, 0, 0.0, 0, 0, 0.0], 0.001, False),  # a hard press within one sample
    ],
)
def test_impossible_means_beyond_what_the_pillar_and_the_hubs_filter_allow(
    reading: list[float], previous: list[float] | None, dt_s: float | None, flagged: bool
) -> None:
    readings = np.zeros((9, 6))
    readings[4] = reading
    before = None if previous is None else np.zeros((9, 6))
    if before is not None and previous is not None:
        before[4] = previous
    assert implausible_pillars(readings, before, dt_s).tolist() == [False] * 4 + [flagged] + [False] * 4


def test_an_unbiased_hub_is_biased_whatever_its_offset_and_a_bias_under_load_is_refused_next_time() -> None:
    """After power-up (or a replug) the hub reads its zero's offset and drift, here 0.8 N on a pillar with nothing
    touching it: the SDK's 0.5 N contact threshold cannot tell that from a load, so the first bias since the port
    opened is taken (a campaign of hours stopped at a session's start on this). A bias taken under load shows
    at the next tare as a negative Fz unloaded, refused with that cause; a reconnect biases afresh."""
    params = PapillArrayParams(offset_sd_mm=0.0, noise_mm=0.0005)
    clock = VirtualClock()
    source = PressSource(PAPILLARRAY, period_s=8.0, rest_fraction=0.5, params=params)
    source.model.offset_mm[4, 2] = 0.8 / source.model.calibration[2]  # a drifted zero, not a load
    with hub_rig(clock, source) as (driver, hub):
        idle = step(clock, driver, 50)
        assert min(f.values[4, 2] for f in idle) > 0.5  # what the check used to refuse
        driver.tare(idle)
        assert hub.biased
        assert np.abs(step(clock, driver, 20)[-1].values[:, 2]).max() < 0.05
        step(clock, driver, 300)  # into the press
        with pytest.raises(DeviceError, match="contact"):
            driver.tare(step(clock, driver, 20))  # biased since the port opened: the check is made
    clock = VirtualClock()
    with hub_rig(clock, PressSource(PAPILLARRAY, period_s=8.0, rest_fraction=0.5, params=params)) as (driver, hub):
        step(clock, driver, 550)  # into the press (free air for the first 4 s of each 8)
        loaded = step(clock, driver, 20)
        assert max(f.values[:, 2].max() for f in loaded) > 0.5
        driver.tare(loaded)  # the first bias: taken on the caller's word
        step(clock, driver, 100)  # free air again (8 s on)
        unloaded = step(clock, driver, 20)
        assert min(f.values[:, 2].min() for f in unloaded) < -0.5  # the load it zeroed, now missing
        with pytest.raises(DeviceError, match="taken while it was loaded"):
            driver.tare(unloaded)
        driver.reconnect()
        driver.tare(step(clock, driver, 20))  # afresh: a new first bias, in free air
        assert np.abs(step(clock, driver, 20)[-1].values[:, 2]).max() < 0.05
