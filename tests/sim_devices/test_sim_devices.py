"""The simulated devices answer like the real ones on their real transports (checked with raw transport calls)."""

from __future__ import annotations

import itertools
import json
from collections.abc import Iterator

import can
import numpy as np
import pytest
import serial
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp
from websockets.sync.client import connect as ws_connect

import unitac_rig.sim  # noqa: F401  (registers the simpapill:// and simslcan:// URL handlers)
from drivers.clock import VirtualClock
from drivers.layouts import PAPILLARRAY, USKIN
from protocols.papillarray import PacketParser
from protocols.xela_can import USPA46_ID_MAP, decode_taxel_message
from unitac_rig.sim.devices import SimPapillArrayHub, SimSlcanAdapter, SimXelaController
from unitac_rig.sim.devices.xela_server import SimXelaServer
from unitac_rig.sim.faults import FaultInjector, FaultPlan
from unitac_rig.sim.sensor_models import PapillArrayParams
from unitac_rig.sim.sensor_signals import SensorSample
from unitac_rig.sim.synthetic_sources import PressSource

_channels = itertools.count()
MS = 1_000_000


class Constant:
    """A source that always reads the same values."""

    def __init__(self, values: np.ndarray, displacement: np.ndarray | None = None) -> None:
        self.values = values
        self.displacement = displacement

    def sample(self, t_ns: int) -> SensorSample:
        return SensorSample(values=self.values, displacement_mm=self.displacement)


@pytest.fixture
def channel() -> str:
    return f"sim-devices-test-{next(_channels)}"


@pytest.fixture
def host_bus(channel: str) -> Iterator[can.BusABC]:
    bus = can.Bus(interface="virtual", channel=channel)
    yield bus
    bus.shutdown()


def _drain(bus: can.BusABC) -> list[can.Message]:
    out = []
    while (message := bus.recv(timeout=0)) is not None:
        out.append(message)
    return out


def test_controller_is_silent_until_started_and_stops_on_command(channel: str, host_bus: can.BusABC) -> None:
    clock = VirtualClock()
    values = np.tile([100.4, 200.6, 70_000.0], (24, 1))  # rounds to 100, 201; clips to 65535
    with SimXelaController(channel, controller_id=3, source=Constant(values), clock=clock):
        clock.advance_ns(30 * MS)
        assert _drain(host_bus) == []
        host_bus.send(can.Message(arbitration_id=0x201, data=b"\x07\x00", is_extended_id=False))  # other board
        clock.advance_ns(10 * MS)
        assert _drain(host_bus) == []
        host_bus.send(can.Message(arbitration_id=0x203, data=b"\x07\x00", is_extended_id=False))
        clock.advance_ns(20 * MS)  # two samples
        messages = _drain(host_bus)
        assert [m.arbitration_id for m in messages] == sorted(USPA46_ID_MAP.ids) * 2  # each cycle in id order
        taxel = decode_taxel_message(messages[0].arbitration_id, bytes(messages[0].data))
        assert (taxel.x, taxel.y, taxel.z) == (100, 201, 65535)
        host_bus.send(can.Message(arbitration_id=0x203, data=b"\x07\x01", is_extended_id=False))
        clock.advance_ns(20 * MS)
        assert _drain(host_bus) == []


@pytest.mark.parametrize("plan", [None, FaultPlan(delay_s=0.005)])
def test_a_plan_that_damages_nothing_counts_every_message_without_mangling_each(
    channel: str, host_bus: can.BusABC, plan: FaultPlan | None, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The controller counts what it sent as the fault injector would, but a plan without per-message damage (none,
    or only a delay) no longer copies each of the 2,400 messages per simulated second through ``mangle``."""
    mangled: list[bytes] = []
    monkeypatch.setattr(FaultInjector, "mangle", lambda self, message: mangled.append(message) or message)
    clock = VirtualClock()
    with SimXelaController(channel, source=PressSource(USKIN), clock=clock, faults=plan) as controller:
        host_bus.send(can.Message(arbitration_id=0x201, data=b"\x07\x00", is_extended_id=False))
        clock.advance_ns(50 * MS)
        host_bus.send(can.Message(arbitration_id=0x201, data=b"\x07\x01", is_extended_id=False))
        clock.advance_ns(20 * MS)  # the delayed ones are out too
        messages = _drain(host_bus)
        assert len(messages) == controller.faults.counts.messages_seen == 24 * controller.samples_sent > 0
    assert mangled == []


def test_slcan_adapter_speaks_lawicel_and_bridges_to_can(channel: str) -> None:
    clock = VirtualClock()
    with (
        SimXelaController(channel, source=PressSource(USKIN), clock=clock),
        SimSlcanAdapter(channel, clock=clock) as adapter,
    ):
        port = serial.serial_for_url(adapter.url, timeout=0)
        try:
            port.write(b"V\r")
            assert port.read(100) == b"V1013\r"
            port.write(b"S8\rO\rS6\r")  # bitrate only while closed
            assert port.read(100) == b"\r\r\a"
            port.write(b"t20120700\r")  # start controller 1
            assert port.read(100) == b"z\r"
            clock.advance_ns(10 * MS)
            lines = port.read(10_000).split(b"\r")[:-1]
            assert len(lines) == 24
            assert lines[0].startswith(b"t1008") and len(lines[0]) == 5 + 16
            port.write(b"C\r")
            port.read(100)
            clock.advance_ns(10 * MS)
            assert port.read(10_000) == b""  # closed channel forwards nothing
        finally:
            port.close()


def test_serial_url_errors_busy_port_and_unplug() -> None:
    with pytest.raises(serial.SerialException, match="no simulated device"):
        serial.serial_for_url("simpapill://nobody-here")
    clock = VirtualClock()
    with SimPapillArrayHub(source=PressSource(PAPILLARRAY), clock=clock) as hub:
        port = serial.serial_for_url(hub.url, timeout=0)
        try:
            with pytest.raises(serial.SerialException, match="busy"):
                serial.serial_for_url(hub.url)
            hub.faults.force_disconnect()
            with pytest.raises(serial.SerialException, match="disconnected"):
                port.read(10)
            with pytest.raises(serial.SerialException, match="unplugged"):
                serial.serial_for_url(hub.url)
            hub.faults.force_disconnect(False)
        finally:
            port.close()
        again = serial.serial_for_url(hub.url, timeout=0)  # replugged: opens again
        again.close()
    with pytest.raises(serial.SerialException):
        serial.serial_for_url(hub.url)  # closed hub is gone


def test_hub_streams_only_to_an_open_port_at_1khz_and_obeys_rate_and_bias() -> None:
    clock = VirtualClock()
    source = PressSource(PAPILLARRAY, peak_load_n=0.0, params=PapillArrayParams(noise_mm=0.0, offset_sd_mm=0.03))
    offset_z = source.model.offset_n[:, 2]  # what the unbiased hub reads, N
    with SimPapillArrayHub(source=source, clock=clock, slot=1, bias_delay_s=1.0) as hub:
        clock.advance_ns(50 * MS)
        assert hub.packets_sent == 0  # waiting for a serial connection
        port = serial.serial_for_url(hub.url, timeout=0)
        parser = PacketParser()
        try:
            clock.advance_ns(10 * MS)
            packets = parser.feed(port.read(1_000_000))
            assert len(packets) == 10  # 1000 Hz after power-up
            assert [p.counter for p in packets] == list(range(10))
            assert np.diff([p.timestamp_us for p in packets]).tolist() == [1000] * 9
            assert np.abs(offset_z).max() > 0.05
            assert packets[0].sensors[1].forces_n[:, 2] == pytest.approx(offset_z, abs=1e-3)
            assert not np.any(packets[0].sensors[0].forces_n)  # the other slot is idle
            port.write(b"f100\n")
            clock.advance_ns(100 * MS)
            assert len(parser.feed(port.read(1_000_000))) == 10
            port.write(b"z\n")
            clock.advance_ns(900 * MS)
            assert parser.feed(port.read(1_000_000))[-1].sensors[1].forces_n[4, 2] == pytest.approx(
                offset_z[4], abs=1e-3
            )
            clock.advance_ns(200 * MS)
            after = parser.feed(port.read(1_000_000))[-1].sensors[1]
            assert after.forces_n == pytest.approx(np.zeros((9, 3)))
        finally:
            port.close()


def test_xela_server_sends_welcome_then_numbered_data() -> None:
    values = np.tile([1, 2, 3], (24, 1))
    with (
        SimXelaServer(source=Constant(values), rate_hz=200) as server,
        ws_connect(server.url, open_timeout=5) as ws,
    ):
        welcome = json.loads(ws.recv(timeout=5))
        assert welcome["message"] == "Welcome"
        first, second = json.loads(ws.recv(timeout=5)), json.loads(ws.recv(timeout=5))
        assert second["message"] == first["message"] + 1
        assert first["1"]["model"] == "uSPa46" and first["1"]["taxels"] == 24
        assert first["1"]["data"].split(",")[:3] == ["0001", "0002", "0003"]
        assert first["1"]["calibrated"] is None


@settings(max_examples=200, deadline=None)
@given(
    hnp.arrays(np.float64, (9, 3), elements=st.floats(-1e3, 1e3)),
    hnp.arrays(np.float64, (9, 3), elements=st.floats(-1e3, 1e3)),
)
def test_the_hub_torque_is_numpys_cross_product_bit_for_bit(a: np.ndarray, b: np.ndarray) -> None:
    """The hub's global torque is Σ r × F per sample; its own cross product must give numpy's exact bits (signed
    zeros too), or a seeded PapillArray session would change."""
    from unitac_rig.sim.devices.papillarray import _cross_rows

    ours, numpys = _cross_rows(a, b), np.cross(a, b)
    assert np.array_equal(ours, numpys) and np.array_equal(np.signbit(ours), np.signbit(numpys))
