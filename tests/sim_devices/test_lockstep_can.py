"""The fast twin's CAN bus: python-can's bus interface with the virtual bus's delivery rules, without its deep copy."""

from __future__ import annotations

import itertools
import threading
from collections.abc import Iterator
from pathlib import Path

import can
import pytest

from unitac_rig.collection.session import collect_session
from unitac_rig.rig.config import parse_rig_config
from unitac_rig.rig.objects import get_object
from unitac_rig.sim.devices.lockstep_can import LockstepCanBus
from unitac_rig.sim.fast_rig import SimRig

_names = itertools.count()


@pytest.fixture
def channel() -> str:
    return f"lockstep-test-{next(_names)}"


@pytest.fixture
def buses(channel: str) -> Iterator[list[LockstepCanBus]]:
    opened = [LockstepCanBus(channel) for _ in range(3)]
    yield opened
    for bus in opened:
        bus.shutdown()


def _message(arbitration_id: int, data: bytes = b"\x01\x02") -> can.Message:
    return can.Message(arbitration_id=arbitration_id, data=data, is_extended_id=False)


def _drain(bus: can.BusABC) -> list[can.Message]:
    out = []
    while (message := bus.recv(timeout=0)) is not None:
        out.append(message)
    return out


def test_every_other_bus_on_the_channel_gets_each_message_in_order(buses: list[LockstepCanBus]) -> None:
    sender, a, b = buses
    for i in range(5):
        sender.send(_message(0x100 + i, bytes([i])))
    for receiver in (a, b):
        got = _drain(receiver)
        assert [m.arbitration_id for m in got] == [0x100 + i for i in range(5)]
        assert [bytes(m.data) for m in got] == [bytes([i]) for i in range(5)]
        assert all(m.is_rx and m.channel == sender.channel_id and not m.is_extended_id for m in got)
    assert sender.recv(timeout=0) is None  # not its own, unless asked


def test_own_messages_only_when_asked(channel: str) -> None:
    with LockstepCanBus(channel, receive_own_messages=True) as bus:
        bus.send(_message(0x200))
        (own,) = _drain(bus)
        assert own.arbitration_id == 0x200 and not own.is_rx


def test_receivers_get_their_own_copy(buses: list[LockstepCanBus]) -> None:
    sender, a, b = buses
    sent = _message(0x101, b"\x10\x20\x30")
    sender.send(sent)
    got_a, got_b = a.recv(timeout=0), b.recv(timeout=0)
    assert got_a is not None and got_b is not None
    got_a.data[0] = 0xFF
    sent.data[1] = 0xEE
    assert bytes(got_b.data) == b"\x10\x20\x30"
    assert bytes(got_a.data) == b"\xff\x20\x30"


def test_filters_apply_as_on_any_bus(channel: str) -> None:
    with (
        LockstepCanBus(channel) as sender,
        LockstepCanBus(channel, can_filters=[{"can_id": 0x135, "can_mask": 0x7FF, "extended": False}]) as receiver,
    ):
        for arbitration_id in (0x100, 0x135, 0x136, 0x135):
            sender.send(_message(arbitration_id))
        # as in python-can, a recv(timeout=0) that meets a filtered-out message returns None
        got = [receiver.recv(timeout=0) for _ in range(4)]
        assert [m.arbitration_id for m in got if m is not None] == [0x135, 0x135]
        assert receiver.recv(timeout=0) is None


def test_timestamps_come_from_the_sender_clock(channel: str) -> None:
    from drivers.clock import VirtualClock

    clock = VirtualClock(start_ns=2_500_000_000)
    with LockstepCanBus(channel, clock=clock) as sender, LockstepCanBus(channel) as receiver:
        sender.send(_message(0x100))
        message = receiver.recv(timeout=0)
        assert message is not None and message.timestamp == 2.5


def test_a_waiting_receiver_wakes_on_a_message_from_another_thread(buses: list[LockstepCanBus]) -> None:
    sender, receiver, _ = buses
    got: list[can.Message | None] = []
    reader = threading.Thread(target=lambda: got.append(receiver.recv(timeout=60.0)))
    reader.start()
    sender.send(_message(0x123))
    reader.join(timeout=60.0)
    assert not reader.is_alive()
    assert got[0] is not None and got[0].arbitration_id == 0x123


def test_a_closed_bus_refuses_and_leaves_the_channel(buses: list[LockstepCanBus]) -> None:
    sender, closed, other = buses
    closed.shutdown()
    with pytest.raises(can.CanOperationError):
        closed.send(_message(0x100))
    with pytest.raises(can.CanOperationError):
        closed.recv(timeout=0)
    sender.send(_message(0x100))
    assert len(_drain(other)) == 1


def test_the_fast_twin_never_deep_copies_a_can_message(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """python-can's virtual bus deep-copies each of the 2,400 uSkin messages per simulated second (issue 27: the
    largest single cost of a session); the fast twin's uSkin driver reads the same wire messages without it."""
    copies = []
    original = can.Message.__deepcopy__

    def counting(self: can.Message, memo: dict[int, object] | None) -> can.Message:
        copies.append(self.arbitration_id)
        return original(self, memo)

    monkeypatch.setattr(can.Message, "__deepcopy__", counting)
    with SimRig(parse_rig_config({"press": {"angle_count": 2}}), seed=0) as rig:
        outcome = collect_session(rig, get_object("hex_tpu"), "uskin", tmp_path, max_presses=1)
    assert outcome.complete == 1
    assert copies == []
