"""A simulated xela_server: a real WebSocket server on 127.0.0.1 broadcasting uSkin readings as xela_server does.

Each client first gets the Welcome, then one JSON data message per sample (``message`` = broadcast sequence number,
``time`` = server Unix time, the sensor under its number as a string, counts as 4-hex-digit strings by default).
Faults per message: drop (the sequence number still advances, so clients see the gap), corrupt (a bit flip in the
JSON text), delay is not modelled here (TCP keeps order; a delay is a stall). A stall stops broadcasting; a
disconnect closes every connection and answers new ones with HTTP 503 until it ends (reconnect possible).
"""

from __future__ import annotations

import logging
import threading
import time

import numpy as np
from websockets.datastructures import Headers
from websockets.exceptions import ConnectionClosed
from websockets.http11 import Request, Response
from websockets.sync.server import Server, ServerConnection, serve

from drivers.clock import Clock, MonotonicClock
from protocols.xela_ws import XelaSensorData, encode_data_message, encode_welcome
from unitac_rig.sim.devices.base import SampleTimer, SimDevice
from unitac_rig.sim.devices.xela_can import counts_from_sample
from unitac_rig.sim.faults import FaultInjector, FaultPlan
from unitac_rig.sim.sensor_signals import SignalSource

logger = logging.getLogger(__name__)


class SimXelaServer(SimDevice):
    """xela_server on ``host:port`` (0 picks a free port; see :attr:`url`) streaming ``source`` at ``rate_hz``.

    ``calibrated_n_per_count``: when set, messages also carry ``calibrated`` forces in N, (counts - the counts at
    start-up) times this factor, as the server's force-calibration module would; else ``calibrated`` is null.
    """

    def __init__(
        self,
        host: str = "127.0.0.1",
        port: int = 0,
        *,
        source: SignalSource,
        rate_hz: float = 100,
        model: str = "uSPa46",
        sensor_number: int = 1,
        clock: Clock | None = None,
        faults: FaultPlan | None = None,
        as_hex: bool = True,
        calibrated_n_per_count: float | None = None,
    ) -> None:
        self.source = source
        self.model = model
        self.sensor_number = sensor_number
        self.as_hex = as_hex
        self.calibrated_n_per_count = calibrated_n_per_count
        self.faults = FaultInjector(faults)
        self.seq = 0
        self._zero_counts: np.ndarray | None = None
        self._lock = threading.Lock()
        self._closed = False
        self._server: Server = serve(
            self._handle,
            host,
            port,
            compression=None,
            process_request=self._process_request,
            ping_interval=None,
        )
        self.host, self.port = self._server.socket.getsockname()[:2]
        self._serve_thread = threading.Thread(
            target=self._server.serve_forever, name=f"sim-xela-server-{self.port}", daemon=True
        )
        self._serve_thread.start()
        the_clock = clock or MonotonicClock()
        self._epoch_offset_s = time.time() - the_clock.now_ns() / 1e9  # server "Unix time" = clock + offset
        self._timer = SampleTimer(rate_hz, the_clock, self._tick, thread_name=f"sim-xela-server-tick-{self.port}")

    @property
    def url(self) -> str:
        return f"ws://{self.host}:{self.port}"

    @property
    def clock(self) -> Clock:
        return self._timer.clock

    # ---- connections ------------------------------------------------------------------------------------------
    def _process_request(self, connection: ServerConnection, request: Request) -> Response | None:
        if self.faults.is_disconnected(self.clock.now_ns()):
            return Response(503, "Service Unavailable", Headers(), b"simulated disconnect\n")
        return None

    def _handle(self, connection: ServerConnection) -> None:
        try:
            connection.send(encode_welcome(server="unitac-rig simulated xela_server"))
            for _ in connection:  # xela_server ignores what clients send; this returns when they go
                pass
        except ConnectionClosed:
            pass

    # ---- broadcasting -----------------------------------------------------------------------------------------
    def _tick(self, t_ns: int) -> None:
        if self.faults.is_disconnected(t_ns):
            self.faults.note_disconnected()
            for connection in self._server.connections:
                connection.close(1011, "simulated disconnect")
            return
        if self.stalled(t_ns):
            return
        counts = counts_from_sample(self.source.sample(t_ns).values)
        calibrated = None
        if self.calibrated_n_per_count is not None:
            if self._zero_counts is None:
                self._zero_counts = counts.copy()
            calibrated = (counts - self._zero_counts) * self.calibrated_n_per_count
        self.seq += 1
        sensor = XelaSensorData(
            sensor_number=self.sensor_number, model=self.model, taxels=len(counts), values=counts, calibrated=calibrated
        )
        text = encode_data_message(self.seq, self._epoch_offset_s + t_ns / 1e9, [sensor], as_hex=self.as_hex)
        for connection in self._server.connections:
            damaged = self.faults.mangle(text.encode("utf-8"))
            if damaged is None:
                continue
            try:
                connection.send(damaged.decode("utf-8", errors="replace"))
            except ConnectionClosed:
                continue

    def close(self) -> None:
        """Stop broadcasting, close every connection and the listening socket."""
        with self._lock:
            if self._closed:
                return
            self._closed = True
        self._timer.close()
        self._server.shutdown()
        self._serve_thread.join(timeout=5.0)
