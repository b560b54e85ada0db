"""XELA uSkin uSPa46 drivers: raw CAN (python-can bus) and XELA's own xela_server WebSocket.

Both hand out :class:`~drivers.frames.TactileFrame` s of raw 16-bit counts, shape (24, 3), row-major layout order,
stamped with the injected clock when the frame completed. Raw counts rest anywhere between ~16 000 and ~37 000 per
taxel-axis, so a tare is a host-side mean over unloaded frames (the sensor has no bias command).
"""

from __future__ import annotations

import contextlib
import logging
import time
from typing import Any

import can
import numpy as np
from websockets.exceptions import ConnectionClosed, InvalidHandshake, InvalidURI
from websockets.sync.client import ClientConnection
from websockets.sync.client import connect as ws_connect

from drivers.clock import Clock
from drivers.errors import DeviceError, DeviceNotFound, DeviceTimeout
from drivers.frames import TactileFrame
from drivers.layouts import USKIN
from drivers.sensor import TareRecord
from drivers.sensor_base import PumpedSensor
from protocols.errors import ProtocolError
from protocols.xela_can import (
    USPA46_ID_MAP,
    AssembledFrame,
    FrameAssembler,
    TaxelIdMap,
    decode_stream_command,
    encode_stream_command,
    invalid_taxels,
)
from protocols.xela_ws import XelaDataMessage, XelaWelcome, decode_message

logger = logging.getLogger(__name__)

SATURATED_HIGH_COUNTS = 65_000  # at or above: the Hall chip's 16-bit range is exhausted
SATURATED_LOW_COUNTS = 500  # at or below: likewise at the bottom (or a shorted channel)
MAX_TARE_SPREAD_COUNTS = 50.0  # idle noise peaks ~25 counts; a larger per-channel std means a press in progress
MIN_TARE_FRAMES = 5
MAX_MESSAGES_PER_PUMP = 50_000  # bound one poll() on a bus that never goes quiet
# ... and bound it in time: a reader only slightly faster than the bus (python-can's slcan reads one byte per call,
# ~4,000 messages/s on a 2-core box against the uSkin's 2,400) would otherwise hold every frame for seconds
PUMP_BUDGET_S = 0.02
# A taxel value older than this (host clock) when its frame closes is flagged stale. A controller may spread its 24
# messages over the cycle (about 2.5 ms per read is all that is published: a 60 ms cycle at one message per read),
# so this allows cycles down to 4 Hz; the driver reports a stall after stall_timeout_s (0.5 s).
STALE_AFTER_S = 0.25
SLCAN_TTY_BAUDRATE = 3_000_000  # the FTDI USB-CAN adapter of a uSPa46 kit: slcand -S 3000000 ...
SLCAN_RTSCTS = True  # ... -t hw (hardware flow control)


def uskin_saturated(values: np.ndarray) -> np.ndarray:
    """Per-taxel flag (n_taxels,): any axis at or beyond the 16-bit range limits (counts)."""
    values = np.asarray(values)
    return np.any((values >= SATURATED_HIGH_COUNTS) | (values <= SATURATED_LOW_COUNTS), axis=1)


def uskin_host_tare(frames: list[TactileFrame], now_ns: int, max_spread_counts: float) -> TareRecord:
    """Median of the valid unloaded frames (counts); refuses when the per-channel spread says the pad is moving.

    Median and a MAD-based spread (1.4826 x the median absolute deviation: the standard deviation for Gaussian
    noise), not mean and standard deviation: SLCAN lines carry no checksum, so one line damaged on the wire can
    decode as a wild value in one frame, which must neither shift the baseline nor read as a pad being pressed."""
    valid = [f.values for f in frames if f.valid]
    if len(valid) < MIN_TARE_FRAMES:
        raise DeviceError(
            f"uskin tare needs at least {MIN_TARE_FRAMES} valid frames, got {len(valid)} of {len(frames)}",
            hint="record a second of unloaded frames (with every taxel reporting) before taring",
        )
    stack = np.stack(valid).astype(np.float64)
    median = np.median(stack, axis=0)
    spread = float(1.4826 * np.median(np.abs(stack - median), axis=0).max())
    if spread > max_spread_counts:
        raise DeviceError(
            f"uskin tare refused: taxel spread {spread:.0f} counts exceeds {max_spread_counts:.0f} "
            "(something is pressing on the pad)",
            hint="move the sensor clear of the object, wait ~3 s for the skin to settle, then tare again",
        )
    return TareRecord(baseline=median, n_frames=len(valid), host_t_ns=now_ns, method="host-median", spread=spread)


_CAN_HINTS = {
    "socketcan": "bring the interface up: sudo ip link set {channel} up type can bitrate {bitrate}",
    "slcan": "check the adapter's serial port ({channel}) exists and you are in the dialout group; or bring it up as "
    "SocketCAN: sudo slcand -o -s8 -t hw -S 3000000 /dev/ttyUSB0 && sudo ip link set slcan0 up",
    "pcan": "check the PEAK adapter is plugged in and its driver is loaded (channel e.g. PCAN_USBBUS1)",
}


def open_can_bus(interface: str, channel: str, bitrate: int = 1_000_000, **options: Any) -> can.BusABC:
    """Open a python-can bus for the uSkin (1 Mbit/s), turning python-can's errors into DeviceNotFound with a hint.

    ``options`` go to ``can.Bus`` (e.g. ``sleep_after_open=0`` for a simulated SLCAN adapter). For ``slcan`` the
    serial side defaults to the uSPa46 kit's adapter settings (``slcand -S 3000000 -t hw``: 3 Mbaud, RTS/CTS), not
    python-can's 115200 baud without flow control; a ``channel`` ending in ``@BAUD`` or explicit ``tty_baudrate`` /
    ``rtscts`` options override them.
    """
    if interface == "slcan" and "@" not in channel:
        options.setdefault("tty_baudrate", SLCAN_TTY_BAUDRATE)
        options.setdefault("rtscts", SLCAN_RTSCTS)
    hint = _CAN_HINTS.get(
        interface,
        "check the --can-interface name and channel; python-can lists interfaces in can.interfaces.VALID_INTERFACES",
    ).format(channel=channel, bitrate=bitrate)
    try:
        if interface == "virtual":
            return can.Bus(interface=interface, channel=channel, **options)
        return can.Bus(interface=interface, channel=channel, bitrate=bitrate, **options)
    except can.CanInterfaceNotImplementedError as exc:
        raise DeviceNotFound(f"CAN interface {interface!r} is not available: {exc}", hint=hint) from exc
    except (can.CanError, OSError, ValueError) as exc:
        raise DeviceNotFound(f"cannot open CAN {interface} channel {channel!r}: {exc}", hint=hint) from exc


class _UskinDriver(PumpedSensor):
    """What both uSkin transports share: the layout, the saturation rule and the host-side tare (counts)."""

    def __init__(
        self, thread_name: str, clock: Clock | None, stall_timeout_s: float, max_tare_spread_counts: float
    ) -> None:
        super().__init__(
            USKIN, clock=clock, stall_timeout_s=stall_timeout_s, thread_name=thread_name, is_saturated=uskin_saturated
        )
        self.max_tare_spread_counts = max_tare_spread_counts

    def tare(self, frames: list[TactileFrame]) -> TareRecord:
        """Host-side baseline from unloaded frames (the uSkin has no tare command); refuses when they spread more
        than a resting pad."""
        return uskin_host_tare(frames, self.clock.now_ns(), self.max_tare_spread_counts)


def _is_slcan(bus: Any) -> bool:
    """True for python-can's serial slcan bus (ASCII lines over a serial port, without a checksum)."""
    return type(bus).__name__.lower().startswith("slcan")


class UskinCanDriver(_UskinDriver):
    """uSPa46 over raw CAN: sends the start command on connect, assembles per-taxel messages into frames.

    ``bus`` is any python-can bus (socketcan, slcan, pcan, virtual); with ``owns_bus`` the driver shuts it down on
    disconnect. Frames have no device counter (``seq`` None): the wire has none, so a frame is valid only when the
    assembler proves it holds one controller cycle (see :class:`~protocols.xela_can.FrameAssembler`); the first few
    frames after connecting, before it has learned where cycles start, are flagged. ``cycle_start_id`` is for
    firmware known to send one id first (needed where the controller spreads its messages evenly over the cycle).
    """

    def __init__(
        self,
        bus: can.BusABC,
        *,
        controller_id: int = 1,
        id_map: TaxelIdMap = USPA46_ID_MAP,
        clock: Clock | None = None,
        stall_timeout_s: float = 0.5,
        owns_bus: bool = False,
        max_tare_spread_counts: float = MAX_TARE_SPREAD_COUNTS,
        cycle_start_id: int | None = None,
    ) -> None:
        if id_map.n_taxels != USKIN.n_taxels:
            raise DeviceError(
                f"id map {id_map.name!r} has {id_map.n_taxels} taxels, the uSPa46 has {USKIN.n_taxels}",
                hint="use USPA46_ID_MAP or a 24-id map",
            )
        super().__init__(f"uskin-can-{controller_id}", clock, stall_timeout_s, max_tare_spread_counts)
        self.bus = bus
        self.controller_id = controller_id
        self.id_map = id_map
        self.owns_bus = owns_bus
        self._bus_shut_down = False
        self._start_command = encode_stream_command(controller_id, True)
        self._stop_command = encode_stream_command(controller_id, False)
        self.cycle_start_id = cycle_start_id
        self._assembler = self._new_assembler()

    # ---- transport --------------------------------------------------------------------------------------------
    def _send(self, command: tuple[int, bytes]) -> None:
        arbitration_id, payload = command
        message = can.Message(arbitration_id=arbitration_id, data=payload, is_extended_id=False)
        try:
            self.bus.send(message, timeout=0.5)
        except (can.CanError, OSError, ValueError) as exc:
            raise DeviceError(
                f"cannot send the stream command to uSkin controller {self.controller_id}: {exc}",
                hint="check the CAN cable, termination and that the bus is up at 1 Mbit/s",
            ) from exc

    def _new_assembler(self) -> FrameAssembler:
        return FrameAssembler(
            self.id_map, stale_after_ns=round(STALE_AFTER_S * 1e9), cycle_start_id=self.cycle_start_id
        )

    def _open(self) -> None:
        self._assembler = self._new_assembler()
        self._send(self._start_command)
        logger.info("uskin: start command sent to controller %d", self.controller_id)

    def _close(self) -> None:
        try:
            self._send(self._stop_command)
        except DeviceError as exc:
            logger.warning("uskin: could not send the stop command: %s", exc)

    def disconnect(self) -> None:
        """Stop streaming, stop the reader, and shut the bus down when the driver owns it."""
        super().disconnect()
        if self.owns_bus and not self._bus_shut_down:
            self._bus_shut_down = True
            try:
                self.bus.shutdown()
            except (can.CanError, OSError) as exc:
                logger.warning("uskin: error shutting the bus down: %s", exc)

    def _skip_damaged_line(self, exc: BaseException) -> bool:
        """True (and counted) when ``exc`` is python-can's slcan parser choking on one damaged ASCII line.

        python-can raises ValueError/IndexError for a line with bad hex, and wraps a line that is not UTF-8 in
        CanOperationError while keeping its bytes in the line buffer; ``flush()`` clears that buffer (and the unread
        input), otherwise every later line would fail too. A port that went away is a different cause: not skipped.
        """
        cause = exc if isinstance(exc, ValueError | IndexError) else exc.__cause__
        if not isinstance(cause, ValueError | IndexError):
            return False
        logger.debug("uskin: unreadable CAN line skipped: %s", cause)
        self._count(checksum_errors=1)
        flush = getattr(self.bus, "flush", None)
        if isinstance(cause, UnicodeDecodeError) and callable(flush):
            flush()
        return True

    def _serial_bytes_waiting(self) -> bool:
        """True when the bus is python-can's slcan and its serial port still holds unread bytes."""
        port = getattr(self.bus, "serialPortOrig", None)
        if port is None:
            return False
        try:
            return bool(port.in_waiting)
        except (OSError, ValueError) as exc:  # pyserial's SerialException is an OSError
            raise DeviceError(
                f"uSkin SLCAN adapter failed: {exc}", hint="the adapter went away; replug it, then reconnect"
            ) from exc

    def _frame(self, assembled: AssembledFrame) -> TactileFrame:
        return TactileFrame(
            sensor=USKIN.name,
            host_t_ns=self.clock.now_ns(),
            values=assembled.values,
            seq=None,
            device_t_us=None,
            valid=assembled.valid,
            stale_mask=None if assembled.valid else assembled.stale_mask,
        )

    def _pump(self, wait_s: float) -> list[TactileFrame]:
        frames: list[TactileFrame] = []
        timeout = wait_s
        # on the driver's clock, so a virtual clock (the fast twin, lockstep) never cuts a pump short
        give_back_ns = self.clock.now_ns() + round((wait_s + PUMP_BUDGET_S) * 1e9)
        for _ in range(MAX_MESSAGES_PER_PUMP):
            if frames and self.clock.now_ns() > give_back_ns:
                break  # hand these frames over; the rest stays in the transport for the next pump
            try:
                message = self.bus.recv(timeout=timeout)
            except (can.CanError, OSError, ValueError, IndexError) as exc:
                if not self._skip_damaged_line(exc):
                    raise DeviceError(
                        f"uSkin CAN bus failed: {exc}",
                        hint="the adapter or bus went away; check the cable/adapter, then reconnect",
                    ) from exc
                continue
            if message is None:
                if self._serial_bytes_waiting():
                    continue  # an slcan reply line ("z", OK) made recv() return None with frames still queued
                drained = self._assembler.flush(self.clock.now_ns())  # the quiet ends a waiting frame
                if drained is not None:
                    frames.append(self._frame(drained))
                break
            timeout = 0.0
            if message.is_error_frame or message.is_remote_frame or message.is_extended_id:
                continue
            data = bytes(message.data)
            if decode_stream_command(message.arbitration_id, data) is not None:
                continue  # a stream command from this or another host
            assembled = self._assembler.add(message.arbitration_id, data, self.clock.now_ns())
            if assembled is not None:
                frames.append(self._frame(assembled))
        return frames

    def link_counters(self) -> dict[str, int]:
        """The frame assembler's counters (messages, unknown_ids, invalid_messages, frames, incomplete_frames,
        unproven_frames)."""
        return self._assembler.counters()

    def identity(self) -> dict[str, Any]:
        return {
            **super().identity(),
            "transport": f"can:{getattr(self.bus, 'channel_info', type(self.bus).__name__)}",
            "controller_id": self.controller_id,
            "id_map": self.id_map.name,
            # what a frame's `valid` can rest on: the CAN CRC on a native interface; over python-can's slcan the
            # serial ASCII lines carry no checksum, so a damaged digit that still parses is not caught
            "wire_checksum": "none (slcan serial lines)" if _is_slcan(self.bus) else "CAN CRC",
        }


XELA_SERVER_HINT = (
    "start xela_server (e.g. xela_server -f /etc/xela/xServ.ini -p 5000) and check the address it binds: some "
    "versions ignore --ip and listen on the primary network address, not 127.0.0.1"
)
RETRY_INTERVAL_S = 0.1  # between connection attempts while the server starts
CLIENT_MAX_QUEUE = 4096  # messages the WebSocket client buffers between polls (~40 s at 100 Hz)


class UskinXelaServerDriver(_UskinDriver):
    """uSPa46 through XELA's xela_server WebSocket (``ws://HOST:5000``), one sensor number of its broadcast.

    ``seq`` is the server's message number (gaps counted), ``device_t_us`` the server time in microseconds, and
    ``calibrated_n`` the server's force estimate when its calibration module is on.
    """

    def __init__(
        self,
        url: str = "ws://127.0.0.1:5000",
        *,
        sensor_number: int = 1,
        clock: Clock | None = None,
        connect_timeout_s: float = 5.0,
        stall_timeout_s: float = 0.5,
        max_tare_spread_counts: float = MAX_TARE_SPREAD_COUNTS,
    ) -> None:
        super().__init__(f"uskin-xela-server-{sensor_number}", clock, stall_timeout_s, max_tare_spread_counts)
        self.url = url
        self.sensor_number = sensor_number
        self.connect_timeout_s = connect_timeout_s
        self.welcome: dict[str, Any] | None = None
        self.model: str | None = None
        self._ws: ClientConnection | None = None
        self._ws_stack: contextlib.ExitStack | None = None
        self._last_seq: int | None = None
        self._missing_sensor_logged = False

    def _open(self) -> None:
        deadline = time.monotonic() + self.connect_timeout_s
        attempts = 0
        while True:
            attempts += 1
            remaining = deadline - time.monotonic()
            try:
                stack = contextlib.ExitStack()
                # Entered as a context manager: the form every websockets version >= 12 supports without warning.
                self._ws = stack.enter_context(
                    ws_connect(
                        self.url,
                        open_timeout=max(remaining, 0.1),
                        compression=None,
                        max_queue=CLIENT_MAX_QUEUE,
                        ping_interval=None,
                    )
                )
                self._ws_stack = stack
                break
            except InvalidURI as exc:
                raise DeviceNotFound(f"bad xela_server URL {self.url!r}: {exc}", hint="use ws://HOST:PORT") from exc
            except (OSError, InvalidHandshake, TimeoutError) as exc:
                if time.monotonic() + RETRY_INTERVAL_S >= deadline:
                    error = DeviceNotFound if isinstance(exc, ConnectionRefusedError) else DeviceTimeout
                    raise error(
                        f"no xela_server at {self.url} after {self.connect_timeout_s:g} s ({attempts} tries): {exc}",
                        hint=XELA_SERVER_HINT,
                    ) from exc
                time.sleep(RETRY_INTERVAL_S)  # the server may still be starting
        self._last_seq = None
        logger.info("uskin: connected to xela_server %s after %d tries", self.url, attempts)

    def _close(self) -> None:
        stack, self._ws_stack, self._ws = self._ws_stack, None, None
        if stack is not None:
            stack.close()

    def _pump(self, wait_s: float) -> list[TactileFrame]:
        if self._ws is None:
            raise DeviceError("xela_server connection is not open", hint="call connect() first")
        frames: list[TactileFrame] = []
        timeout = wait_s
        for _ in range(MAX_MESSAGES_PER_PUMP):
            try:
                text = self._ws.recv(timeout=timeout)
            except TimeoutError:
                break
            except ConnectionClosed as exc:
                raise DeviceError(
                    f"xela_server at {self.url} closed the connection: {exc}",
                    hint="check xela_server is still running (it can die mid-run), then reconnect()",
                ) from exc
            timeout = 0.0
            try:
                message = decode_message(text)
            except ProtocolError as exc:
                logger.debug("uskin: unreadable xela_server message: %s", exc)
                self._count(checksum_errors=1)
                continue
            if isinstance(message, XelaWelcome):
                self.welcome = message.raw
                continue
            frame = self._frame(message)
            if frame is not None:
                frames.append(frame)
        return frames

    def _frame(self, message: XelaDataMessage) -> TactileFrame | None:
        if self._last_seq is not None and message.seq > self._last_seq + 1:
            self._count(sequence_gaps=message.seq - self._last_seq - 1)
        self._last_seq = message.seq
        sensor = message.sensors.get(self.sensor_number)
        if sensor is None:
            if not self._missing_sensor_logged:
                logger.warning(
                    "uskin: xela_server message has sensors %s, not %d", sorted(message.sensors), self.sensor_number
                )
                self._missing_sensor_logged = True
            return None
        if not self._right_shape(  # the codec made values (taxels, 3)
            sensor.taxels,
            f"xela_server sensor {self.sensor_number} ({sensor.model[:40]}) has {sensor.taxels} taxels",
            hint="pick the uSPa46's sensor number (--sensor-number) or fix the model in xServ.ini",
        ):
            return None  # one damaged message; the reader goes on
        self.model = sensor.model
        invalid = invalid_taxels(sensor.values)  # e.g. FA00 placeholders while the server has no data yet
        return TactileFrame(
            sensor=USKIN.name,
            host_t_ns=self.clock.now_ns(),
            values=sensor.values,
            seq=message.seq,
            device_t_us=round(message.server_time_s * 1e6),
            calibrated_n=sensor.calibrated,
            valid=not invalid.any(),
            stale_mask=invalid if invalid.any() else None,
        )

    def identity(self) -> dict[str, Any]:
        return {
            **super().identity(),
            "transport": f"xela_server:{self.url}",
            "sensor_number": self.sensor_number,
            "reported_model": self.model,
        }
