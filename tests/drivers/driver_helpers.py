"""Helpers for the driver tests (imported by name, not a conftest, so test folders can run together): lockstep
stepping on a virtual clock and collecting reader-thread frames."""

from __future__ import annotations

import time
from typing import Any

from drivers.clock import VirtualClock
from drivers.frames import TactileFrame

PERIOD_NS = 10_000_000  # 100 Hz


def step(clock: VirtualClock, driver: Any, n_periods: int, period_ns: int = PERIOD_NS) -> list[TactileFrame]:
    """Advance the virtual clock one sample period at a time, polling after each (lockstep, deterministic)."""
    frames: list[TactileFrame] = []
    for _ in range(n_periods):
        clock.advance_ns(period_ns)
        frames += driver.poll()
    return frames


def collect(driver: Any, n_frames: int, timeout_s: float = 5.0) -> list[TactileFrame]:
    """Poll until ``n_frames`` arrived or the timeout (for reader-thread and real-time cases)."""
    frames: list[TactileFrame] = []
    deadline = time.monotonic() + timeout_s
    while len(frames) < n_frames and time.monotonic() < deadline:
        frames += driver.poll()
        time.sleep(0.002)
    return frames


def run_mode(mode: str, clock: VirtualClock, driver: Any, n_periods: int) -> list[TactileFrame]:
    """``n_periods`` samples in poll (lockstep) or reader-thread mode; returns every frame they produced."""
    if mode == "poll":
        return step(clock, driver, n_periods)
    # The reader stamps frames with the clock when it decodes them, so each period is let through before the
    # next: a virtual clock racing ahead of the thread would make taxels look stale (as real time never does).
    driver.start_reader()
    frames: list[TactileFrame] = []
    try:
        for i in range(n_periods):
            clock.advance_ns(PERIOD_NS)
            frames += collect(driver, i + 1 - len(frames), timeout_s=2.0)
        return frames
    finally:
        driver.stop_reader()
