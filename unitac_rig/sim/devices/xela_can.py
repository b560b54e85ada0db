"""A simulated XELA uSkin CAN controller, and a simulated SLCAN USB-CAN adapter to reach it over a serial port.

:class:`SimXelaController` sits on a python-can bus (``virtual`` by default) like the real controller board: it
waits for the start command (``0x200|id``, ``07 00``), then sends one message per taxel per sample (ids from the
map, counts rounded and clipped to 0..65535) until the stop command. A disconnect fault models a power loss: the
board stops, ignores the bus and, like the old firmware, needs a new start command afterwards.

:class:`SimSlcanAdapter` is the far end of ``simslcan://NAME``: it speaks the Lawicel ASCII protocol (``O``, ``C``,
``S0``..``S8``, ``V``, ``N``, ``F``, ``tIIILDD..``) on the serial side and bridges to a python-can ``virtual``
channel on the CAN side, so python-can's own ``slcan`` interface talks to a :class:`SimXelaController`.
"""

from __future__ import annotations

import collections
import logging
from typing import ClassVar, Literal

import can
import numpy as np

from drivers.clock import Clock, MonotonicClock
from protocols.xela_can import (
    USPA46_ID_MAP,
    TaxelIdMap,
    decode_stream_command,
    encode_taxel_message,
)
from unitac_rig.sim.devices.base import SampleTimer, SimDevice
from unitac_rig.sim.devices.lockstep_can import LockstepCanBus
from unitac_rig.sim.devices.serial_port import SimSerialEndpoint, unique_name
from unitac_rig.sim.faults import FaultInjector, FaultPlan
from unitac_rig.sim.sensor_signals import SignalSource

logger = logging.getLogger(__name__)


def counts_from_sample(values: np.ndarray) -> np.ndarray:
    """Raw counts as the controller's ADC gives them: rounded, clipped to 0..65535, int64."""
    return np.clip(np.rint(np.asarray(values, dtype=np.float64)), 0, 0xFFFF).astype(np.int64)


def taxel_payloads(counts: np.ndarray) -> list[bytes]:
    """The 8-byte payload of every taxel of one sample at once: row i is ``encode_taxel_message(id, *counts[i])``
    (a zero byte, X, Y, Z big-endian u16, a zero byte).

    ``counts`` (n, 3) must already be 0..65535 (:func:`counts_from_sample`). One numpy pass instead of a validated
    encode per message: at 24 messages a sample that encoding was the largest part of the simulated uSkin.
    """
    rows = np.zeros((len(counts), 8), dtype=np.uint8)
    rows[:, 1:7] = np.asarray(counts, dtype=">u2").view(np.uint8).reshape(len(counts), 6)
    blob = rows.tobytes()
    return [blob[i : i + 8] for i in range(0, len(blob), 8)]


class SimXelaController(SimDevice):
    """A uSkin controller board on a python-can bus, streaming ``source`` at ``rate_hz`` once started.

    The bus is ``can.Bus(interface=interface, channel=bus_channel)`` unless ``bus`` hands an open one (the fast twin
    passes a :class:`~unitac_rig.sim.devices.lockstep_can.LockstepCanBus`); the controller shuts it down on close.
    """

    def __init__(
        self,
        bus_channel: str,
        *,
        controller_id: int = 1,
        rate_hz: float = 100.0,
        source: SignalSource,
        clock: Clock | None = None,
        interface: str = "virtual",
        bus: can.BusABC | None = None,
        id_map: TaxelIdMap = USPA46_ID_MAP,
        faults: FaultPlan | None = None,
        missing_taxels: tuple[int, ...] = (),
        send_order: Literal["id", "map", "shuffled"] = "id",
    ) -> None:
        self.controller_id = controller_id
        self.source = source
        self.id_map = id_map
        # (taxel index, id) in the order the board sends each cycle. No source states it: "id" (0x100 first) is what
        # CAN arbitration gives a board that queues a whole cycle at once, "map" the order of XELA's map file (s1 =
        # 0x135 first), "shuffled" a new order every cycle (the host must not depend on one)
        self.send_order = send_order
        self._order_rng = np.random.default_rng(0)
        by_id = sorted(enumerate(id_map.ids), key=lambda item: item[1])
        self._send_order = list(enumerate(id_map.ids)) if send_order == "map" else by_id
        self.faults = FaultInjector(faults)
        self.missing_taxels = frozenset(missing_taxels)
        self.streaming = False
        self.samples_sent = 0
        self._powered_off = False
        # (release time ns, arbitration id, payload): a Message is built only when it goes on the bus
        self._delayed: collections.deque[tuple[int, int, bytes]] = collections.deque()
        for arbitration_id in id_map.ids:  # the codec's checks of the ids, once instead of per message
            encode_taxel_message(arbitration_id, 0, 0, 0)
        # ``bus``: an open bus on ``bus_channel`` to use instead (the fast twin's LockstepCanBus); closed with us
        if bus is None:
            bus = can.Bus(interface=interface, channel=bus_channel, receive_own_messages=False)
        self._bus = bus
        self._timer = SampleTimer(rate_hz, clock, self._tick, thread_name=f"sim-xela-can-{controller_id}")

    @property
    def clock(self) -> Clock:
        return self._timer.clock

    def _handle_commands(self) -> None:
        while True:
            message = self._bus.recv(timeout=0.0)
            if message is None:
                return
            if self._powered_off:
                continue
            command = decode_stream_command(message.arbitration_id, bytes(message.data))
            if command is not None and command[0] == self.controller_id:
                self.streaming = command[1]
                logger.debug("sim xela controller %d: streaming=%s", self.controller_id, self.streaming)

    def _tick(self, t_ns: int) -> None:
        if self.faults.is_disconnected(t_ns):
            self._powered_off = True
            self.streaming = False
            self._delayed.clear()
            self.faults.note_disconnected()
        else:
            self._powered_off = False
        self._handle_commands()
        self._send_due(t_ns)
        if not self.streaming:
            return
        if self.stalled(t_ns):
            return
        payloads = taxel_payloads(counts_from_sample(self.source.sample(t_ns).values))
        release_ns = self.faults.release_t_ns(t_ns)
        order = self._send_order
        if self.send_order == "shuffled":
            order = [order[i] for i in self._order_rng.permutation(len(order))]
        damage = self.faults.mangle if self.faults.damages_messages else None
        sent = 0
        for index, arbitration_id in order:
            if index in self.missing_taxels:
                continue
            payload = payloads[index] if damage is None else damage(payloads[index])
            if payload is None:
                continue
            sent += 1
            self._delayed.append((release_ns, arbitration_id, payload[:8]))
        if damage is None:
            self.faults.pass_messages(sent)  # mangle's count, once per cycle
        self.samples_sent += 1
        self._send_due(t_ns)

    def _send_due(self, now_ns: int) -> None:
        delayed = self._delayed
        if not delayed or delayed[0][0] > now_ns:
            return
        due: list[tuple[int, bytes]] = []
        while delayed and delayed[0][0] <= now_ns:
            _, arbitration_id, payload = delayed.popleft()
            due.append((arbitration_id, payload))
        if isinstance(self._bus, LockstepCanBus):
            self._bus.send_standard_frames(due)  # the receivers' Messages only, not one more to copy them from
            return
        for arbitration_id, payload in due:
            self._bus.send(can.Message(arbitration_id=arbitration_id, data=payload, is_extended_id=False))

    def close(self) -> None:
        """Stop the sample timer and leave the bus."""
        self._timer.close()
        self._bus.shutdown()


class SimSlcanAdapter(SimSerialEndpoint):
    """A Lawicel/SLCAN USB-CAN adapter: ``simslcan://NAME`` on the host side, a virtual CAN channel on the other.

    Received CAN frames are forwarded to the host as ``tIIILDD..\\r`` lines while the channel is open (``O``);
    ``faults`` damages those lines on the serial side (split, drop, corrupt, garbage, delay, disconnect).
    """

    SCHEME = "simslcan"
    BITRATE_COMMANDS: ClassVar[frozenset[str]] = frozenset(f"S{i}" for i in range(10))

    def __init__(
        self,
        can_channel: str,
        *,
        name: str | None = None,
        clock: Clock | None = None,
        faults: FaultPlan | None = None,
    ) -> None:
        self._bus = can.Bus(interface="virtual", channel=can_channel, receive_own_messages=False)
        self.channel_open = False
        self._line = bytearray()
        super().__init__(
            self.SCHEME,
            name or unique_name("slcan"),
            clock=clock or MonotonicClock(),
            faults=FaultInjector(faults),
        )

    # ---- CAN side -> host ----------------------------------------------------------------------------------------
    def refill(self) -> None:
        while True:
            message = self._bus.recv(timeout=0.0)
            if message is None:
                return
            if not self.channel_open or message.is_extended_id or message.is_error_frame:
                continue
            line = f"t{message.arbitration_id:03X}{message.dlc:d}{bytes(message.data).hex().upper()}\r"
            self.faults.start(self.clock.now_ns())
            self._push(line.encode("ascii"), self.clock.now_ns(), faulted=True)

    # ---- host -> adapter ------------------------------------------------------------------------------------------
    def on_attach(self) -> None:
        self.channel_open = False
        self._line.clear()
        while self._bus.recv(timeout=0.0) is not None:
            pass  # frames from before the port was opened are gone

    def on_detach(self) -> None:
        self.channel_open = False

    def on_host_bytes(self, data: bytes) -> None:
        for byte in data:
            if byte == 0x0D:
                reply = self._command(self._line.decode("ascii", errors="replace"))
                self._line.clear()
                self._push(reply.encode("ascii"), self.clock.now_ns(), faulted=False)
            else:
                self._line.append(byte)

    def _command(self, line: str) -> str:
        ok, error = "\r", "\a"
        if line == "":
            return ok  # python-can sends an empty data-bitrate command for classic CAN
        if line == "O" or line == "L":
            self.channel_open = True
            return ok
        if line == "C":
            self.channel_open = False
            return ok
        if line in self.BITRATE_COMMANDS:
            return error if self.channel_open else ok
        if line == "V":
            return "V1013\r"
        if line == "N":
            return "NSIM1\r"
        if line == "F":
            return "F00\r"
        if line[0] == "t" and self.channel_open:
            try:
                arbitration_id = int(line[1:4], 16)
                dlc = int(line[4])
                payload = bytes.fromhex(line[5 : 5 + 2 * dlc])
            except (ValueError, IndexError):
                return error
            if len(payload) != dlc:
                return error
            self._bus.send(can.Message(arbitration_id=arbitration_id, data=payload, is_extended_id=False))
            return "z\r"
        return error

    def close(self) -> None:
        """Unplug the adapter for good and leave the CAN channel."""
        self.close_endpoint()
        self._bus.shutdown()
