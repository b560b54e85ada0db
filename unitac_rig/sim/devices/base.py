"""What every simulated device shares: when it samples (:class:`SampleTimer`), how a fault plan gates a sample and
how it closes (:class:`SimDevice`).

With a clock that has ``on_advance`` (:class:`drivers.clock.VirtualClock`) the device emits, inside the advance call,
every sample that fell due (deterministic and as fast as the caller advances). With any other clock (or none) a
thread emits at the rate in real time, stamping samples with that clock; it never bursts to catch up after a hiccup.
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable
from types import TracebackType
from typing import Self

from drivers.clock import Clock, MonotonicClock
from unitac_rig.sim.faults import FaultInjector

logger = logging.getLogger(__name__)

MAX_CATCH_UP_PERIODS = 5  # a real-time thread that fell further behind skips ahead instead of bursting


class SampleTimer:
    """Calls ``tick(t_ns)`` once per sample period (ns on ``clock``) until :meth:`close`."""

    def __init__(self, rate_hz: float, clock: Clock | None, tick: Callable[[int], None], thread_name: str) -> None:
        if rate_hz <= 0:
            raise ValueError(f"sample rate must be positive, got {rate_hz} Hz")
        self.clock: Clock = clock if clock is not None else MonotonicClock()
        self._virtual = hasattr(clock, "on_advance") and hasattr(clock, "remove_listener")
        self._tick = tick
        self._period_ns = round(1e9 / rate_hz)
        self._next_ns = self.clock.now_ns() + self._period_ns
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._lock = threading.Lock()
        if self._virtual:
            self.clock.on_advance(self._on_advance)  # type: ignore[attr-defined]
        else:
            self._thread = threading.Thread(target=self._run, name=thread_name, daemon=True)
            self._thread.start()

    def set_rate(self, rate_hz: float) -> None:
        """Change the sample rate from the next sample on."""
        with self._lock:
            last_ns = self._next_ns - self._period_ns
            self._period_ns = round(1e9 / rate_hz)
            self._next_ns = last_ns + self._period_ns

    def _due(self, now_ns: int) -> int | None:
        with self._lock:
            if self._next_ns > now_ns:
                return None
            t_ns = self._next_ns
            self._next_ns += self._period_ns
            return t_ns

    def _on_advance(self, now_ns: int) -> None:
        if self._next_ns > now_ns:
            return  # nothing due (most advances: the arm's 2 ms period is shorter than a sample's)
        while not self._stop.is_set():
            t_ns = self._due(now_ns)
            if t_ns is None:
                return
            self._tick(t_ns)

    def _run(self) -> None:
        try:
            while not self._stop.is_set():
                now_ns = self.clock.now_ns()
                with self._lock:
                    if now_ns - self._next_ns > MAX_CATCH_UP_PERIODS * self._period_ns:
                        self._next_ns = now_ns
                    wait_s = (self._next_ns - now_ns) / 1e9
                if wait_s > 0 and self._stop.wait(wait_s):
                    return
                t_ns = self._due(self.clock.now_ns())
                if t_ns is not None:
                    self._tick(self.clock.now_ns())
        except Exception:  # a simulator bug must not die silently
            logger.exception("simulated device thread %s crashed", threading.current_thread().name)

    def close(self) -> None:
        self._stop.set()
        if self._virtual:
            self.clock.remove_listener(self._on_advance)  # type: ignore[attr-defined]
        elif self._thread is not None:
            self._thread.join(timeout=5.0)
            self._thread = None


class SimDevice:
    """The base of every simulated device: ``faults`` (its fault injector), :meth:`close`, and a context manager that
    closes it."""

    faults: FaultInjector

    def stalled(self, t_ns: int) -> bool:
        """Start the fault plan's clock at the first streamed sample, and say (and count) whether ``t_ns`` falls in
        a planned or forced stall, when the device sends nothing."""
        self.faults.start(t_ns)
        if self.faults.is_stalled(t_ns):
            self.faults.note_stalled()
            return True
        return False

    def close(self) -> None:
        raise NotImplementedError

    def __enter__(self) -> Self:
        return self

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.close()
