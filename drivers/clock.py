"""The clock seam between hardware and the simulated rig.

Drivers stamp every frame with ``clock.now_ns()``. On hardware that is ``time.monotonic_ns()``; on the simulated rig
it is a virtual clock advanced by the simulated arm's control period, so a seeded run is deterministic and runs far
faster than real time.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Protocol


class Clock(Protocol):
    def now_ns(self) -> int:
        """Monotonic time in nanoseconds."""
        ...

    def sleep(self, seconds: float) -> None:
        """Wait ``seconds`` (real or virtual)."""
        ...


class MonotonicClock:
    """Wall-independent host clock for real hardware."""

    def now_ns(self) -> int:
        return time.monotonic_ns()

    def sleep(self, seconds: float) -> None:
        if seconds > 0:
            time.sleep(seconds)


class VirtualClock:
    """A clock that only moves when told to (simulated rig, tests).

    ``sleep`` advances the clock instead of blocking, and listeners registered with ``on_advance`` are called with the
    new time so simulated devices can emit the samples that fall due.
    """

    def __init__(self, start_ns: int = 0) -> None:
        self._now_ns = start_ns
        self._listeners: list[Callable[[int], None]] = []  # called with the new time (ns)

    def now_ns(self) -> int:
        return self._now_ns

    def sleep(self, seconds: float) -> None:
        self.advance_ns(round(seconds * 1e9))

    def advance_ns(self, delta_ns: int) -> None:
        if delta_ns < 0:
            raise ValueError("a virtual clock cannot run backwards")
        self._now_ns += delta_ns
        for listener in list(self._listeners):
            listener(self._now_ns)

    def on_advance(self, listener: Callable[[int], None]) -> None:
        self._listeners.append(listener)

    def remove_listener(self, listener: Callable[[int], None]) -> None:
        if listener in self._listeners:
            self._listeners.remove(listener)
