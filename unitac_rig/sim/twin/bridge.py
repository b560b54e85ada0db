"""A simulated serial device served over TCP, so a host reaches it with pyserial's ``socket://HOST:PORT`` URL.

The device itself is one of the simulator's serial endpoints (the PapillArray hub, the SLCAN adapter): the bridge
opens its in-process ``sim...://`` port when a TCP client connects (the device then sees a host open its port, as
when a USB cable is plugged into a PC) and copies bytes both ways until either side closes. One client at a time, as
with a serial port; a second connection waits until the first has gone. Like a USB-serial adapter or a
ser2net server, the bridge adds nothing to the byte stream.
"""

from __future__ import annotations

import contextlib
import logging
import select
import socket
import threading
from types import TracebackType

import serial

logger = logging.getLogger(__name__)

_POLL_S = 0.002  # the bridge's latency floor: a byte waits at most this long on either side


class TcpSerialBridge:
    """Serve the simulated serial port at ``device_url`` (e.g. ``simpapill://hub-1``) on ``host:port`` (0: any).

    Raises OSError when the address is taken.
    """

    def __init__(self, device_url: str, host: str, port: int = 0) -> None:
        self.device_url = device_url
        self._listener = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        try:
            self._listener.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            self._listener.bind((host, port))
            self._listener.listen(1)
        except OSError:
            self._listener.close()
            raise
        self.host, self.port = self._listener.getsockname()[:2]
        self._stop = threading.Event()
        self.connections = 0
        self._thread = threading.Thread(target=self._serve, name=f"twin-bridge-{self.port}", daemon=True)
        self._thread.start()

    @property
    def url(self) -> str:
        """What a host gives pyserial (or python-can's slcan interface) to reach the device."""
        return f"socket://{self.host}:{self.port}"

    def _serve(self) -> None:
        try:
            while not self._stop.is_set():
                ready, _, _ = select.select([self._listener], [], [], 0.05)
                if not ready:
                    continue
                try:
                    client, peer = self._listener.accept()
                except OSError:
                    continue
                self.connections += 1
                logger.debug("bridge %s: host %s:%d connected", self.device_url, *peer[:2])
                with contextlib.closing(client):
                    self._pump(client)
        except Exception:  # a simulator bug must not die silently
            logger.exception("TCP bridge for %s crashed", self.device_url)

    def _pump(self, client: socket.socket) -> None:
        client.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        client.setblocking(False)
        try:
            port = serial.serial_for_url(self.device_url, timeout=_POLL_S)
        except serial.SerialException as exc:
            logger.warning("bridge %s: the device is not there (%s); dropping the host", self.device_url, exc)
            return
        try:
            while not self._stop.is_set():
                data = port.read(4096)  # waits up to _POLL_S
                if data:
                    client.setblocking(True)
                    try:
                        client.sendall(data)
                    finally:
                        client.setblocking(False)
                readable, _, _ = select.select([client], [], [], 0)
                if readable:
                    incoming = client.recv(65536)
                    if not incoming:
                        return  # the host closed the port
                    port.write(incoming)
        except (OSError, serial.SerialException) as exc:
            logger.debug("bridge %s: connection ended: %s", self.device_url, exc)
        finally:
            port.close()

    def close(self) -> None:
        """Stop serving: the host's connection closes, as when the cable is pulled."""
        self._stop.set()
        self._thread.join(timeout=5.0)
        self._listener.close()

    def __enter__(self) -> TcpSerialBridge:
        return self

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.close()
