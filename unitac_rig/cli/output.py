"""What the commands print, said the same way everywhere: the one console of standard output, durations, the time
left at this run's pace (``about 12 min left``: ``collect``, ``campaign``, ``train``), and how often a log (no
terminal to redraw a bar) gets a progress line.

The pace is measured on this run only (work done before a resume took no time here), so the estimate follows the
load of the machine it runs on rather than a figure measured elsewhere.
"""

from __future__ import annotations

import time

from rich.console import Console

console = Console()  # standard output; errors and interruption lines go to stderr through typer.echo(err=True)
LOG_LINE_EVERY_S = 10.0  # without a terminal (a log, nohup, CI): a progress line at most this often, s


def spoken_duration(seconds: float) -> str:
    """``45 s``, ``12 min``, ``1 h 05 min``: a duration rounded as a person would say it."""
    if seconds < 90:
        return f"{seconds:.0f} s"
    minutes = round(seconds / 60)
    return f"{minutes} min" if minutes < 60 else f"{minutes // 60} h {minutes % 60:02d} min"


class Pace:
    """Seconds per unit of work (press, epoch) since this run started, and the time left at that pace.

    ``done_before``: units finished before this run; by default one less than the first :meth:`update` says."""

    def __init__(self, done_before: int | None = None) -> None:
        self.started = time.monotonic()
        self._first = done_before
        self._last = (self.started, done_before or 0)

    def update(self, done: int) -> None:
        """``done`` units are finished now (counted from the very start, including any before a resume)."""
        if self._first is None:
            self._first = done - 1
        self._last = (time.monotonic(), done)

    def left_text(self, units_left: int) -> str:
        """``about 12 min left``, or "" while no unit of this run finished or nothing is left."""
        when, done = self._last
        if self._first is None or done <= self._first or units_left <= 0:
            return ""
        return f"about {spoken_duration((when - self.started) / (done - self._first) * units_left)} left"


class EveryFewSeconds:
    """Throttle for progress lines written to a log: the first call, then one every ``seconds``, and the last."""

    def __init__(self, seconds: float = LOG_LINE_EVERY_S) -> None:
        self.seconds = seconds
        self._last: float | None = None

    def due(self, *, last: bool = False) -> bool:
        now = time.monotonic()
        if last or self._last is None or now - self._last >= self.seconds:
            self._last = now
            return True
        return False
