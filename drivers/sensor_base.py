"""The base class of every tactile-sensor driver (:class:`PumpedSensor`): one decode path, polled on the caller's
thread or run on a reader thread. The interface it implements is :class:`drivers.sensor.TactileSensor`.

A driver subclasses :class:`PumpedSensor` and fills three hooks: ``_open()`` (open the transport and start the
device streaming), ``_close()`` (stop streaming, close) and ``_pump(wait_s)`` (decode whatever the transport holds,
waiting at most ``wait_s`` seconds for the first bytes). The base class keeps the health counters, the stall watch
(no frame within ``stall_timeout_s`` by the injected clock), the reader thread and its queue, and re-raises a
reader-thread failure (a port that went away) from the next :meth:`PumpedSensor.poll`.
"""

from __future__ import annotations

import collections
import logging
import threading
import time
from collections.abc import Callable
from types import TracebackType
from typing import Any

import numpy as np

from drivers.clock import Clock, MonotonicClock
from drivers.errors import DeviceError, DeviceTimeout
from drivers.frames import TactileFrame
from drivers.layouts import SensorLayout
from drivers.sensor import SensorHealth

logger = logging.getLogger(__name__)

READER_WAIT_S = 0.02  # how long one reader-thread pump waits for bytes before checking the stop flag
MAX_QUEUED_FRAMES = 100_000  # ~100 s at 1 kHz; older frames are dropped (and logged) if nobody polls
DEAD_AFTER_FRAMES = 100  # a taxel whose three axes never changed over this many valid frames is reported dead
# Messages in a row whose sensor has the wrong number of taxels before a driver stops with an error: one is damage
# that passed the link's own check (counted, skipped); 0.1 to 0.5 s of them is another sensor in that slot.
WRONG_SHAPE_LIMIT = 50


class TaxelWatch:
    """Tracks saturated and dead taxels over the valid frames of one connection."""

    def __init__(self, n_taxels: int, is_saturated: Callable[[np.ndarray], np.ndarray]) -> None:
        self._is_saturated = is_saturated
        self._first: np.ndarray | None = None
        self._changed = np.zeros(n_taxels, dtype=bool)
        self._saturated = np.zeros(n_taxels, dtype=bool)
        self.frames = 0

    def update(self, values: np.ndarray) -> None:
        self.frames += 1
        self._saturated |= np.asarray(self._is_saturated(values), dtype=bool)
        if self._first is None:
            self._first = values.copy()
        else:
            self._changed |= np.any(values != self._first, axis=1)

    def saturated_taxels(self) -> list[int]:
        return [int(i) for i in np.flatnonzero(self._saturated)]

    def dead_taxels(self) -> list[int]:
        if self.frames < DEAD_AFTER_FRAMES:
            return []
        return [int(i) for i in np.flatnonzero(~self._changed)]


class PumpedSensor:
    """Base class for tactile drivers: poll / reader thread / health / stall watch around a ``_pump`` hook."""

    layout: SensorLayout

    def __init__(
        self,
        layout: SensorLayout,
        *,
        clock: Clock | None,
        stall_timeout_s: float,
        thread_name: str,
        is_saturated: Callable[[np.ndarray], np.ndarray],
    ) -> None:
        if stall_timeout_s <= 0:
            raise ValueError("stall_timeout_s must be positive")
        self.layout = layout
        self.clock: Clock = clock if clock is not None else MonotonicClock()
        self.stall_timeout_s = stall_timeout_s
        self._thread_name = thread_name
        self._health = SensorHealth()
        self._watch = TaxelWatch(layout.n_taxels, is_saturated)
        self._lock = threading.Lock()
        self._queued = threading.Condition(self._lock)  # notified when the reader thread queues frames
        self._queue: collections.deque[TactileFrame] = collections.deque()
        self._reader: threading.Thread | None = None
        self._stop_reader = threading.Event()
        self._reader_error: BaseException | None = None
        self._connected = False
        self._watch_since_ns = 0
        self._stalled = False
        self._wrong_shape_in_a_row = 0

    # ---- hooks ------------------------------------------------------------------------------------------------
    def _open(self) -> None:
        raise NotImplementedError

    def _close(self) -> None:
        raise NotImplementedError

    def _pump(self, wait_s: float) -> list[TactileFrame]:
        raise NotImplementedError

    # ---- lifecycle --------------------------------------------------------------------------------------------
    @property
    def connected(self) -> bool:
        return self._connected

    def connect(self) -> None:
        """Open the transport and start streaming (no-op when already connected)."""
        if self._connected:
            return
        self._open()
        self._connected = True
        self._reader_error = None
        self._watch_since_ns = self.clock.now_ns()
        self._stalled = False

    def disconnect(self) -> None:
        """Stop the reader thread, stop streaming and close the transport. Safe to call more than once."""
        self.stop_reader()
        if not self._connected:
            return
        self._connected = False
        self._close()

    def reconnect(self) -> None:
        """Close and reopen the transport (after a disconnect fault or a device power cycle)."""
        was_reading = self._reader is not None
        self.stop_reader()
        if self._connected:
            self._connected = False
            try:
                self._close()
            except DeviceError as exc:
                logger.info("%s: ignoring error while closing for reconnect: %s", self.layout.name, exc)
        self.connect()
        with self._lock:
            self._health.reconnects += 1
        if was_reading:
            self.start_reader()

    def __enter__(self) -> PumpedSensor:
        self.connect()
        return self

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.disconnect()

    def _require_connected(self) -> None:
        if not self._connected:
            raise DeviceError(f"{self.layout.name} driver is not connected", hint="call connect() first")

    # ---- frames -----------------------------------------------------------------------------------------------
    def _account(self, frames: list[TactileFrame]) -> None:
        """Update health counters for freshly decoded frames (pump thread)."""
        if not frames:
            return
        with self._lock:
            for frame in frames:
                self._health.frames += 1
                if not frame.valid:
                    self._health.invalid_frames += 1
                else:
                    self._watch.update(frame.values)
            self._health.last_frame_ns = frames[-1].host_t_ns
            self._stalled = False

    def _right_shape(self, n_taxels: int, what: str, hint: str) -> bool:
        """False for a message whose sensor has ``n_taxels`` taxels, not the layout's (counted as damage, to skip);
        DeviceError saying ``what``, with ``hint``, once :data:`WRONG_SHAPE_LIMIT` came in a row."""
        if n_taxels == self.layout.n_taxels:
            self._wrong_shape_in_a_row = 0
            return True
        self._count(checksum_errors=1)
        self._wrong_shape_in_a_row += 1
        if self._wrong_shape_in_a_row < WRONG_SHAPE_LIMIT:
            return False
        raise DeviceError(
            f"{what} in {WRONG_SHAPE_LIMIT} messages in a row; the {self.layout.model} has {self.layout.n_taxels}",
            hint=hint,
        )

    def _check_stall(self) -> None:
        if not self._connected:
            return
        now_ns = self.clock.now_ns()
        with self._lock:
            since_ns = self._health.last_frame_ns
            reference_ns = max(since_ns, self._watch_since_ns) if since_ns is not None else self._watch_since_ns
            if not self._stalled and now_ns - reference_ns > self.stall_timeout_s * 1e9:
                self._stalled = True
                self._health.stalls += 1
                logger.warning(
                    "%s: no frame for %.3f s (stall timeout %.3f s)",
                    self.layout.name,
                    (now_ns - reference_ns) / 1e9,
                    self.stall_timeout_s,
                )

    @property
    def stalled(self) -> bool:
        """True while no frame has arrived within the stall timeout (cleared by the next frame)."""
        return self._stalled

    def poll(self) -> list[TactileFrame]:
        """Every frame completed since the last call (never blocks). Raises the reader thread's error once."""
        return self.poll_wait(0.0)

    def poll_wait(self, timeout_s: float) -> list[TactileFrame]:
        """Like :meth:`poll`, but waits up to ``timeout_s`` for the first frame, without a sleep loop: a live
        consumer (``unitac-rig stream``) gets each frame as soon as it is decoded. Without a reader thread the pump
        runs on the caller's thread, blocked in the transport until bytes arrive."""
        self._require_connected()
        if self._reader is None and self._reader_error is None:
            frames = self._take_queued()  # left over after stop_reader
            pumped = self._pump(0.0 if frames else timeout_s)
            self._account(pumped)
            frames += pumped
        else:
            with self._queued:
                if not self._queue and self._reader_error is None and timeout_s > 0:
                    self._queued.wait(timeout_s)
            frames = self._take_queued()
            if not frames and self._reader_error is not None:
                error, self._reader_error = self._reader_error, None
                raise error
        self._check_stall()
        return frames

    def _take_queued(self) -> list[TactileFrame]:
        """Frames the reader thread queued (also those left over after ``stop_reader``)."""
        with self._lock:
            frames = list(self._queue)
            self._queue.clear()
        return frames

    def wait_frames(self, n_frames: int, timeout_s: float) -> list[TactileFrame]:
        """Collect ``n_frames`` frames, waiting at most ``timeout_s`` wall-clock seconds (real devices, probes).

        Raises DeviceTimeout when fewer arrive in time.
        """
        deadline = time.monotonic() + timeout_s
        frames: list[TactileFrame] = []
        while len(frames) < n_frames:
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                raise DeviceTimeout(
                    f"{self.layout.name}: got {len(frames)} of {n_frames} frames within {timeout_s:g} s",
                    hint="check the device is powered and streaming (cable, CAN bitrate, controller id, port)",
                )
            frames += self.poll_wait(min(remaining, 0.05))
        return frames[:n_frames]

    # ---- reader thread ----------------------------------------------------------------------------------------
    def start_reader(self) -> None:
        """Run the pump on a background thread; ``poll()`` then returns what it queued."""
        self._require_connected()
        if self._reader is not None:
            return
        self._stop_reader.clear()
        self._reader_error = None
        self._reader = threading.Thread(target=self._reader_loop, name=self._thread_name, daemon=True)
        self._reader.start()

    def stop_reader(self) -> None:
        """Stop the background thread (frames it already queued stay available to ``poll()``)."""
        reader = self._reader
        if reader is None:
            return
        self._stop_reader.set()
        reader.join(timeout=5.0)
        if reader.is_alive():
            logger.error("%s: reader thread did not stop within 5 s", self.layout.name)
        self._reader = None

    def _reader_loop(self) -> None:
        try:
            while not self._stop_reader.is_set():
                frames = self._pump(READER_WAIT_S)
                self._account(frames)
                if frames:
                    with self._lock:
                        self._queue.extend(frames)
                        overflow = len(self._queue) - MAX_QUEUED_FRAMES
                        for _ in range(max(0, overflow)):
                            self._queue.popleft()
                        self._queued.notify_all()
                    if overflow > 0:
                        logger.warning("%s: nobody polls; dropped %d old frames", self.layout.name, overflow)
                self._check_stall()
        except BaseException as exc:  # handed to the caller through poll()
            logger.info("%s: reader thread stopped: %s", self.layout.name, exc)
            with self._queued:
                self._reader_error = exc
                self._queued.notify_all()

    # ---- health -----------------------------------------------------------------------------------------------
    def health(self) -> SensorHealth:
        """A snapshot of the counters (a copy: safe to keep)."""
        self._check_stall()
        with self._lock:
            snapshot = SensorHealth(**self._health.as_dict())
            snapshot.saturated_taxels = self._watch.saturated_taxels()
            snapshot.dead_taxels = self._watch.dead_taxels()
        return snapshot

    def _count(self, **increments: int) -> None:
        with self._lock:
            for name, value in increments.items():
                setattr(self._health, name, getattr(self._health, name) + value)

    def identity(self) -> dict[str, Any]:
        return {"sensor": self.layout.name, "model": self.layout.model, "units": self.layout.units}
