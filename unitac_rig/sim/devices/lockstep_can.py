"""An in-process CAN bus for the fast twin: python-can's bus interface, without the virtual bus's per-message copy.

python-can's ``virtual`` bus ``copy.deepcopy``\\ s every message for every receiver and passes it through a
``queue.Queue`` (two locks per message). A simulated uSkin sends 2,400 messages per simulated second, and that
transport was the largest single cost of the fast twin (issue 27: the sensor transport was 39 % of a uSkin session,
most of it the deep copy). :class:`LockstepCanBus` is a :class:`can.BusABC` like any other interface, so the uSkin
driver runs unchanged on it (``UskinCanDriver(bus)``), and it keeps what the driver and a real bus rely on:

* every other bus open on the same channel receives each sent message, in order; the sender only with
  ``receive_own_messages``;
* each receiver gets its own :class:`can.Message` (fields copied, data bytes copied, ``is_rx`` True, ``channel`` set):
  what one side does to a message never changes another side's;
* ``recv(timeout)`` returns at once with a queued message or None for ``timeout=0``, and otherwise waits on a
  condition (a device thread may feed it) at most ``timeout`` seconds; receive filters apply as on any bus;
* a shut-down bus refuses ``send``/``recv`` (``CanOperationError``) and leaves the channel.

What it drops: the deep copy (a field copy is enough: a Message holds only numbers, flags and its data bytes) and
the locks of ``queue.Queue`` (a ``collections.deque`` appends and pops atomically). Timestamps are the sender's
``clock`` (the simulated time on the fast twin) in seconds, as a socketcan bus stamps on reception, instead of the
wall time the virtual bus writes.
"""

from __future__ import annotations

import threading
import time
from collections import deque
from collections.abc import Callable, Iterable
from typing import Any

import can
from can.bus import BusABC

from drivers.clock import Clock

_channels_lock = threading.Lock()
_channels: dict[str, _Channel] = {}


class _Endpoint:
    """One open bus's receive queue; ``waiting`` counts receivers blocked on ``ready`` (so senders skip the lock)."""

    __slots__ = ("queue", "ready", "waiting")

    def __init__(self) -> None:
        self.queue: deque[can.Message] = deque()
        self.ready = threading.Condition(threading.Lock())
        self.waiting = 0


class _Channel:
    """The endpoints open on one channel name: a tuple replaced (under the lock) on open and shutdown, so a sender
    iterates a stable snapshot without taking a lock per message."""

    __slots__ = ("peers",)

    def __init__(self) -> None:
        self.peers: tuple[_Endpoint, ...] = ()


class LockstepCanBus(BusABC):
    """A CAN bus shared by every :class:`LockstepCanBus` of this process opened on the same ``channel`` name."""

    def __init__(
        self,
        channel: str,
        *,
        receive_own_messages: bool = False,
        clock: Clock | None = None,
        can_filters: can.typechecking.CanFilters | None = None,
        **kwargs: Any,
    ) -> None:
        self.channel_id = channel
        self.channel_info = f"simulated lockstep CAN channel {channel}"
        self.receive_own_messages = receive_own_messages
        self._clock = clock
        self._own = _Endpoint()
        self._open = True
        with _channels_lock:
            self._channel = _channels.setdefault(channel, _Channel())
            self._channel.peers = (*self._channel.peers, self._own)
        super().__init__(channel=channel, can_filters=can_filters, **kwargs)

    def _stamp(self) -> float:
        return self._clock.now_ns() / 1e9 if self._clock is not None else time.time()

    def _check_open(self) -> None:
        if not self._open:
            raise can.CanOperationError("Cannot operate on a closed bus")

    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        """Queue a copy of ``msg`` for every other bus on the channel (never blocks: the queues are unbounded)."""
        self._deliver(
            lambda timestamp, rx: (
                can.Message(
                    timestamp=timestamp,
                    arbitration_id=msg.arbitration_id,
                    is_extended_id=msg.is_extended_id,
                    is_remote_frame=msg.is_remote_frame,
                    is_error_frame=msg.is_error_frame,
                    channel=self.channel_id,
                    dlc=msg.dlc,
                    data=bytearray(msg.data),
                    is_fd=msg.is_fd,
                    is_rx=rx,
                    bitrate_switch=msg.bitrate_switch,
                    error_state_indicator=msg.error_state_indicator,
                ),
            )
        )

    def send_standard_frames(self, frames: list[tuple[int, bytes]]) -> None:
        """Send classic data frames given as (11-bit arbitration id, payload of at most 8 bytes), in order, as
        :meth:`send` would send ``can.Message(arbitration_id=..., data=..., is_extended_id=False)`` of each, without
        building those sender-side Messages: a simulated controller emits 2,400 a second (1.1 us each, measured)."""
        channel = self.channel_id
        self._deliver(
            lambda timestamp, rx: (
                can.Message(
                    timestamp=timestamp,
                    arbitration_id=arbitration_id,
                    is_extended_id=False,
                    channel=channel,
                    dlc=len(data),
                    data=bytearray(data),
                    is_rx=rx,
                )
                for arbitration_id, data in frames
            )
        )

    def _deliver(self, copies: Callable[[float, bool], Iterable[can.Message]]) -> None:
        """Queue ``copies(timestamp, is_rx)`` (each receiver its own Messages) for every other bus on the channel,
        and for this one with ``receive_own_messages``; wake a receiver blocked in :meth:`recv`."""
        self._check_open()
        timestamp = self._stamp()
        for peer in self._channel.peers:
            is_own = peer is self._own
            if is_own and not self.receive_own_messages:
                continue
            peer.queue.extend(copies(timestamp, not is_own))
            if peer.waiting:
                with peer.ready:
                    peer.ready.notify_all()

    def recv(self, timeout: float | None = None) -> can.Message | None:
        """The next message (see :meth:`can.BusABC.recv`); a queued one without filters is returned directly."""
        self._check_open()
        queue = self._own.queue
        if queue and self._filters is None:
            try:
                return queue.popleft()
            except IndexError:  # another thread took it meanwhile
                pass
        return super().recv(timeout)

    def _recv_internal(self, timeout: float | None) -> tuple[can.Message | None, bool]:
        self._check_open()
        own = self._own
        try:
            return own.queue.popleft(), False
        except IndexError:
            if timeout is not None and timeout <= 0:
                return None, False
        deadline = None if timeout is None else time.monotonic() + timeout
        with own.ready:
            own.waiting += 1
            try:
                while True:
                    try:
                        return own.queue.popleft(), False
                    except IndexError:
                        pass
                    if not self._open:
                        raise can.CanOperationError("Cannot operate on a closed bus")
                    remaining = None if deadline is None else deadline - time.monotonic()
                    if remaining is not None and remaining <= 0:
                        return None, False
                    own.ready.wait(remaining)
            finally:
                own.waiting -= 1

    def shutdown(self) -> None:
        """Leave the channel; a receiver blocked in :meth:`recv` wakes and raises."""
        super().shutdown()
        if not self._open:
            return
        self._open = False
        with _channels_lock:
            self._channel.peers = tuple(peer for peer in self._channel.peers if peer is not self._own)
            if not self._channel.peers and _channels.get(self.channel_id) is self._channel:
                del _channels[self.channel_id]
        with self._own.ready:
            self._own.ready.notify_all()
