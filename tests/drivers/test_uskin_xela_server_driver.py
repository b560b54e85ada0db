"""UskinXelaServerDriver against the simulated xela_server (a real WebSocket server on 127.0.0.1, real time)."""

from __future__ import annotations

import contextlib
import socket
import threading
import time
from collections.abc import Iterator, Sequence

import numpy as np
import pytest
from websockets.sync.server import ServerConnection, serve

from drivers.errors import DeviceError, DeviceNotFound
from drivers.layouts import USKIN
from drivers.sensor_base import WRONG_SHAPE_LIMIT
from drivers.uskin import UskinXelaServerDriver
from protocols.xela_ws import XelaSensorData, encode_data_message, encode_welcome
from tests.drivers.driver_helpers import collect
from unitac_rig.sim.devices import counts_from_sample
from unitac_rig.sim.devices.xela_server import SimXelaServer
from unitac_rig.sim.faults import FaultPlan
from unitac_rig.sim.sensor_signals import SensorSample
from unitac_rig.sim.synthetic_sources import PressSource, RecordingSource

RATE_HZ = 500  # fast, to keep the real-time tests short


@contextlib.contextmanager
def server_rig(
    source: RecordingSource, *, faults: FaultPlan | None = None, **server_options: object
) -> Iterator[tuple[UskinXelaServerDriver, SimXelaServer]]:
    server = SimXelaServer(source=source, rate_hz=RATE_HZ, faults=faults, **server_options)  # type: ignore[arg-type]
    driver = UskinXelaServerDriver(server.url, connect_timeout_s=5.0, stall_timeout_s=0.1)
    try:
        driver.connect()
        yield driver, server
    finally:
        driver.disconnect()
        server.close()


@pytest.mark.parametrize("batched", [False, True], ids=["as-they-come", "in-batches"])
def test_frames_carry_the_server_counts_and_message_numbers_in_poll_and_reader_mode(batched: bool) -> None:
    """``in-batches``: every read finds several messages waiting, as on a loaded box (the reads are made late on
    purpose; what is asserted holds however the messages are batched)."""
    source = RecordingSource(PressSource(USKIN, seed=8))
    with server_rig(source, calibrated_n_per_count=0.001) as (driver, _):
        if batched:
            pump = driver._pump

            def late_pump(wait_s: float) -> list:
                time.sleep(0.02)  # 10 messages at 500 Hz wait meanwhile
                return pump(wait_s)

            driver._pump = late_pump  # type: ignore[method-assign]
        polled = driver.wait_frames(20, timeout_s=30.0)  # waits for the frames; the timeout is only a safety net
        driver.start_reader()
        threaded = collect(driver, 20, timeout_s=30.0)
        driver.stop_reader()
        assert driver.welcome is not None and driver.welcome["message"] == "Welcome"
    assert len(polled) == 20 and len(threaded) >= 20
    # Each mode's frames are consecutive messages. Between the modes messages may pass unseen by this test:
    # wait_frames returns exactly 20 frames, and under load its last read may have decoded more than it needed
    # (the 23 != 22 at index 20 this test used to fail on); the server never skipped a number (no gap counted).
    for frames in (polled, threaded):
        seqs = [f.seq for f in frames]
        assert seqs == list(range(seqs[0], seqs[0] + len(seqs)))  # no gaps, no repeats
    assert threaded[0].seq is not None and polled[-1].seq is not None and threaded[0].seq > polled[-1].seq
    sent = [counts_from_sample(sample.values) for _, sample in source.samples]
    for frame in polled + threaded:
        assert frame.seq is not None and frame.device_t_us is not None
        np.testing.assert_array_equal(frame.values, sent[frame.seq - 1])  # message n carries the n-th sample
        assert frame.calibrated_n is not None
        np.testing.assert_allclose(frame.calibrated_n, (sent[frame.seq - 1] - sent[0]) * 0.001)
    assert driver.health().sequence_gaps == 0


def test_dropped_messages_are_counted_as_sequence_gaps_and_bad_json_as_errors() -> None:
    source = RecordingSource(PressSource(USKIN))
    plan = FaultPlan(seed=5, drop_message_prob=0.2, corrupt_prob=0.3)
    with server_rig(source, faults=plan) as (driver, _):
        frames = driver.wait_frames(60, timeout_s=10.0)
    seqs = [f.seq for f in frames if f.seq is not None]
    health = driver.health()
    # every message number missing between the first and the last frame is a counted gap, or an unreadable one
    missing = (seqs[-1] - seqs[0] + 1) - len(seqs)
    assert missing > 0 and health.checksum_errors > 0
    assert health.sequence_gaps + health.checksum_errors >= missing
    assert health.sequence_gaps <= missing


def test_server_going_away_raises_and_reconnect_works_once_it_is_back() -> None:
    source = RecordingSource(PressSource(USKIN))
    with server_rig(source) as (driver, server):
        driver.wait_frames(5, timeout_s=5.0)
        server.faults.force_disconnect()
        with pytest.raises(DeviceError, match="closed the connection"):
            collect(driver, 10_000, timeout_s=5.0)
        # while the server answers 503 the driver keeps retrying; it succeeds once the server is back
        release = threading.Timer(0.3, server.faults.force_disconnect, args=(False,))
        release.start()
        try:
            driver.reconnect()
        finally:
            release.join()
        assert len(driver.wait_frames(5, timeout_s=5.0)) == 5
        assert driver.health().reconnects == 1


def test_a_silent_server_is_reported_as_a_stall() -> None:
    with server_rig(RecordingSource(PressSource(USKIN))) as (driver, server):
        driver.wait_frames(3, timeout_s=5.0)
        server.faults.force_stall()
        collect(driver, 10_000, timeout_s=0.4)  # 0.4 s > 0.1 s stall timeout
        assert driver.stalled and driver.health().stalls == 1
        server.faults.force_stall(False)
        driver.wait_frames(3, timeout_s=5.0)
        assert not driver.stalled


def test_no_server_is_device_not_found_with_a_hint() -> None:
    with socket.socket() as probe:  # a port nobody listens on
        probe.bind(("127.0.0.1", 0))
        port = probe.getsockname()[1]
    driver = UskinXelaServerDriver(f"ws://127.0.0.1:{port}", connect_timeout_s=0.3)
    with pytest.raises(DeviceNotFound) as info:
        driver.connect()
    assert info.value.hint is not None and "xela_server" in info.value.hint


def test_tare_over_the_server_frames() -> None:
    with server_rig(RecordingSource(PressSource(USKIN, peak_load_n=0.0))) as (driver, _):
        frames = driver.wait_frames(20, timeout_s=5.0)
        record = driver.tare(frames)
    np.testing.assert_allclose(record.baseline, np.median([f.values for f in frames], axis=0))
    assert record.method == "host-median"


class _Placeholders:
    """Server data with XELA's "no data" placeholders: FA00 on taxel 3's x, all-zero taxel 5."""

    def sample(self, t_ns: int) -> SensorSample:
        values = np.full((24, 3), 20_000.0)
        values[3, 0] = 0xFA00
        values[5] = 0.0
        return SensorSample(values=values, displacement_mm=None)


def test_placeholder_taxels_from_the_server_are_flagged_like_on_can() -> None:
    with server_rig(RecordingSource(_Placeholders())) as (driver, _):
        frames = driver.wait_frames(3, timeout_s=5.0)
    assert frames and all(not f.valid for f in frames)
    assert all(f.stale_mask is not None and list(np.flatnonzero(f.stale_mask)) == [3, 5] for f in frames)


def _data(seq: int, taxels: int = 24, time_s: float = 1.7e9) -> str:
    counts = np.full((taxels, 3), 20_000 + seq)
    return encode_data_message(seq, time_s, [XelaSensorData(1, "uSPa46", taxels, counts)], as_hex=True)


# What issue 28's review sent that crashed the reader thread or was read as counts (each is one message).
_GOOD_DATA = _data(0)
HOSTILE_MESSAGES = [
    _GOOD_DATA.replace('"time": 1700000000.0', '"time": 1' + "0" * 400),  # OverflowError in the codec
    _GOOD_DATA.replace('"time": 1700000000.0', '"time": 1e303'),  # passed the codec, OverflowError in the driver
    _GOOD_DATA.replace('"time": 1700000000.0', '"time": NaN'),
    _GOOD_DATA.replace('"message": 0', '"message": -1'),
    _GOOD_DATA.replace("4E20", "-FFF", 1),  # read as -4095
    _GOOD_DATA.replace("4E20", "0x1F", 1),
    _GOOD_DATA.replace("4E20", "F_FF", 1),
    _GOOD_DATA.replace("4E20", "\u0661\u0662\u0663\u0664", 1),  # Arabic-Indic digits
    _GOOD_DATA.replace('"calibrated": null', '"calibrated": [' + ", ".join(["1e400"] * 72) + "]"),
    _data(0, taxels=16),  # one damaged message with the wrong taxel count
    "[" * 100_000,
    b"\xff\xfe\x00garbage",
]


@pytest.mark.parametrize("mode", ["poll", "reader"])
def test_the_reader_survives_whatever_the_server_sends_and_counts_it(mode: str) -> None:
    """Issue 28: each hostile message is counted and skipped, the good ones around them come through, and the reader
    thread keeps running (it used to die on OverflowError)."""
    script = [_data(1), *HOSTILE_MESSAGES, _data(2), _data(3)]
    with _scripted_server(script) as url:
        driver = UskinXelaServerDriver(url, connect_timeout_s=5.0, stall_timeout_s=5.0)
        driver.connect()
        try:
            if mode == "reader":
                driver.start_reader()
                frames = collect(driver, 3, timeout_s=10.0)
            else:
                frames = driver.wait_frames(3, timeout_s=10.0)
            health = driver.health()
        finally:
            driver.disconnect()
    assert [f.seq for f in frames] == [1, 2, 3]
    assert all(f.valid and int(f.values.min()) == 20_000 + f.seq for f in frames)  # type: ignore[operator]
    assert health.checksum_errors == len(HOSTILE_MESSAGES)


def test_a_server_that_only_sends_the_wrong_sensor_size_is_an_error_with_a_hint() -> None:
    script = [_data(seq, taxels=16) for seq in range(WRONG_SHAPE_LIMIT)]
    with _scripted_server(script) as url:
        driver = UskinXelaServerDriver(url, connect_timeout_s=5.0, stall_timeout_s=5.0)
        driver.connect()
        try:
            with pytest.raises(DeviceError, match="16 taxels") as info:
                driver.wait_frames(1, timeout_s=10.0)
        finally:
            driver.disconnect()
    assert info.value.hint is not None and "--sensor-number" in info.value.hint


@contextlib.contextmanager
def _scripted_server(script: Sequence[str | bytes]) -> Iterator[str]:
    """A WebSocket server on 127.0.0.1 that sends a welcome, then ``script``, then holds the connection open."""
    done = threading.Event()

    def handler(connection: ServerConnection) -> None:
        connection.send(encode_welcome())
        for message in script:
            connection.send(message)
        done.wait(15.0)

    with serve(handler, "127.0.0.1", 0) as server:
        thread = threading.Thread(target=server.serve_forever, daemon=True)
        thread.start()
        try:
            yield f"ws://127.0.0.1:{server.socket.getsockname()[1]}"
        finally:
            done.set()
            server.shutdown()
            thread.join(5.0)
