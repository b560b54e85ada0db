"""The simulated serial port, so a simulated device is "just another port" behind a pyserial URL.

pyserial's ``serial_for_url("simpapill://hub0")`` imports ``<package>.protocol_simpapill`` from every package in
``serial.protocol_handler_packages``; importing :mod:`unitac_rig.sim` appends :mod:`unitac_rig.sim.devices` there.
Each scheme module (``protocol_simpapill``, ``protocol_simslcan``) holds a :class:`SimSerialPort` subclass; the far
end of the port is a :class:`SimSerialEndpoint` registered under a name by the simulated device (the PapillArray
hub, the SLCAN adapter).

The endpoint keeps the device-to-host byte stream: messages go through the device's
:class:`~unitac_rig.sim.faults.FaultInjector` (drop, corrupt, garbage, delay), host reads take random chunks when a
split is planned, and a disconnect makes every operation on the open port raise ``SerialException`` (as pyserial
does when a USB device is unplugged) and refuses to reopen until the fault ends.
"""

from __future__ import annotations

import collections
import itertools
import threading
import time
from typing import Any

from serial import SerialBase, SerialException
from serial.serialutil import PortNotOpenError, to_bytes

from drivers.clock import Clock
from unitac_rig.sim.devices.base import SimDevice
from unitac_rig.sim.faults import FaultInjector

_registry_lock = threading.Lock()
_registry: dict[tuple[str, str], SimSerialEndpoint] = {}
_name_counter = itertools.count(1)


def unique_name(prefix: str) -> str:
    """A device name not used before in this process (letters, digits and '-')."""
    return f"{prefix}-{next(_name_counter)}"


def lookup(scheme: str, name: str) -> SimSerialEndpoint | None:
    with _registry_lock:
        return _registry.get((scheme, name))


class SimSerialEndpoint(SimDevice):
    """The device side of one simulated serial port (one host may have it open at a time).

    Subclasses override :meth:`on_host_bytes` (commands from the host), and optionally :meth:`on_attach`,
    :meth:`on_detach` and :meth:`refill` (called before each host read, to pull data produced elsewhere).
    """

    def __init__(self, scheme: str, name: str, *, clock: Clock, faults: FaultInjector) -> None:
        self.scheme = scheme
        self.name = name
        self.clock = clock
        self.faults = faults
        self._cond = threading.Condition()
        self._pending: collections.deque[tuple[int, bytes]] = collections.deque()  # (release_ns, bytes)
        self._ready = bytearray()
        self._generation = 0
        self._attached = False
        with _registry_lock:
            if (scheme, name) in _registry:
                raise ValueError(f"a simulated device is already registered as {scheme}://{name}")
            _registry[(scheme, name)] = self

    @property
    def url(self) -> str:
        return f"{self.scheme}://{self.name}"

    @property
    def attached(self) -> bool:
        return self._attached

    def close_endpoint(self) -> None:
        """Remove the port: open host ports fail from now on, reopening says the port does not exist."""
        with _registry_lock:
            _registry.pop((self.scheme, self.name), None)
        with self._cond:
            if self._attached:
                self._drop_host()
            self._cond.notify_all()

    # ---- hooks ------------------------------------------------------------------------------------------------
    def on_host_bytes(self, data: bytes) -> None:
        """Bytes the host wrote (called with the port lock held)."""

    def on_attach(self) -> None:
        """The host opened the port."""

    def on_detach(self) -> None:
        """The host closed the port, or it was unplugged."""

    def refill(self) -> None:
        """Pull device output produced elsewhere into the stream (called with the lock held, before reads)."""

    # ---- device side ------------------------------------------------------------------------------------------
    def send_to_host(self, data: bytes, t_ns: int, *, faulted: bool = True) -> None:
        """Queue ``data`` (one message) for the host; dropped when no host has the port open."""
        with self._cond:
            if not self._attached:
                return
            self._push(data, t_ns, faulted=faulted)
            self._cond.notify_all()

    def _push(self, data: bytes, t_ns: int, *, faulted: bool) -> None:
        out: bytes | None = self.faults.mangle(data) if faulted else data
        if out:
            self._pending.append((self.faults.release_t_ns(t_ns) if faulted else t_ns, out))

    def _release_due(self) -> None:
        if not self._ready:  # pull lazily: python-can's slcan reads one byte per call
            self.refill()
        now_ns = self.clock.now_ns()
        while self._pending and self._pending[0][0] <= now_ns:
            self._ready += self._pending.popleft()[1]

    def check_disconnect(self) -> bool:
        """Apply a planned or forced disconnect; True when the port is gone right now."""
        gone = self.faults.is_disconnected(self.clock.now_ns())
        if gone:
            with self._cond:
                if self._attached:
                    self._drop_host()
                self._cond.notify_all()
        return gone

    def _drop_host(self) -> None:
        self._attached = False
        self._generation += 1
        self._pending.clear()
        self._ready.clear()
        self.on_detach()

    # ---- host side (called by SimSerialPort) ------------------------------------------------------------------
    def _alive(self, generation: int) -> None:
        if generation != self._generation or not self._attached:
            raise SerialException(f"{self.url}: device disconnected (the port went away)")

    def attach(self) -> int:
        if self.check_disconnect() or lookup(self.scheme, self.name) is not self:
            raise SerialException(f"could not open port {self.url}: no such device (unplugged)")
        with self._cond:
            if self._attached:
                raise SerialException(f"could not open port {self.url}: port is busy")
            self._attached = True
            self._pending.clear()
            self._ready.clear()
            self.on_attach()
            return self._generation

    def detach(self, generation: int) -> None:
        with self._cond:
            if generation == self._generation and self._attached:
                self._drop_host()

    def host_write(self, generation: int, data: bytes) -> int:
        self.check_disconnect()
        with self._cond:
            self._alive(generation)
            self.on_host_bytes(data)
            self._cond.notify_all()
        return len(data)

    def host_in_waiting(self, generation: int) -> int:
        self.check_disconnect()
        with self._cond:
            self._alive(generation)
            self._release_due()
            return len(self._ready)

    def host_reset_input(self, generation: int) -> None:
        with self._cond:
            self._alive(generation)
            self._release_due()
            self._ready.clear()

    def host_read(self, generation: int, size: int, timeout_s: float | None) -> bytes:
        """pyserial read semantics: up to ``size`` bytes, waiting at most ``timeout_s`` (None: until ``size``)."""
        deadline = None if timeout_s is None else time.monotonic() + timeout_s
        out = bytearray()
        while True:
            self.check_disconnect()
            with self._cond:
                self._alive(generation)
                self._release_due()
                if self._ready:
                    take = self.faults.chunk_size(min(len(self._ready), size - len(out)))
                    out += self._ready[:take]
                    del self._ready[:take]
                if len(out) >= size or timeout_s == 0:
                    return bytes(out)
                remaining = None if deadline is None else deadline - time.monotonic()
                if remaining is not None and remaining <= 0:
                    return bytes(out)
                # Wake at least every 5 ms: delayed bytes and refills are released by time, not by a notify.
                self._cond.wait(0.005 if remaining is None else min(remaining, 0.005))


class SimSerialPort(SerialBase):
    """pyserial ``Serial`` class for a simulated device URL; subclasses set ``SCHEME``."""

    SCHEME = ""
    is_open: bool

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        self._endpoint: SimSerialEndpoint | None = None
        self._generation = -1
        super().__init__(*args, **kwargs)

    def open(self) -> None:
        if self.is_open:
            raise SerialException("Port is already open.")
        if self._port is None:
            raise SerialException("Port must be configured before it can be used.")
        scheme, _, rest = str(self._port).partition("://")  # scheme://name[?options]
        scheme, name = scheme.lower(), rest.split("?", 1)[0].strip("/")
        if scheme != self.SCHEME:
            raise SerialException(f"expected a {self.SCHEME}:// URL, got {self._port!r}")
        endpoint = lookup(scheme, name)
        if endpoint is None:
            raise SerialException(f"could not open port {self._port}: no simulated device named {name!r}")
        self._generation = endpoint.attach()
        self._endpoint = endpoint
        self.is_open = True

    def close(self) -> None:
        if self.is_open and self._endpoint is not None:
            self._endpoint.detach(self._generation)
        self.is_open = False
        self._endpoint = None

    def _require(self) -> SimSerialEndpoint:
        if not self.is_open or self._endpoint is None:
            raise PortNotOpenError()
        return self._endpoint

    @property
    def in_waiting(self) -> int:
        return self._require().host_in_waiting(self._generation)

    def read(self, size: int = 1) -> bytes:
        return self._require().host_read(self._generation, size, self._timeout)

    def write(self, data: Any) -> int:
        return self._require().host_write(self._generation, to_bytes(data))

    def flush(self) -> None:
        self._require()

    def reset_input_buffer(self) -> None:
        self._require().host_reset_input(self._generation)

    def _reconfigure_port(self, *args: Any, **kwargs: Any) -> None:
        """Baud rate and framing mean nothing to a simulated USB CDC device."""

    def _update_rts_state(self) -> None:
        pass

    def _update_dtr_state(self) -> None:
        pass

    def _update_break_state(self) -> None:
        pass
