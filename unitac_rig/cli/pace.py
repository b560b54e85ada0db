"""Time left at this run's pace, said as a person would (``about 12 min left``): the progress lines of ``collect``,
``campaign`` and ``train`` all say a duration with :func:`spoken_duration`, so an estimate reads the same everywhere;
``train`` measures its pace per epoch with :class:`Pace` (``collect`` and ``campaign`` count presses themselves).

The pace is measured on this run only (work done before a resume does not count: it took no time here), so the
estimate follows the load of the machine it runs on rather than a figure measured elsewhere.
"""

from __future__ import annotations

import time


def spoken_duration(seconds: float) -> str:
    """``45 s``, ``12 min``, ``1 h 05 min``: a duration rounded as a person would say it."""
    if seconds < 90:
        return f"{seconds:.0f} s"
    minutes = round(seconds / 60)
    return f"{minutes} min" if minutes < 60 else f"{minutes // 60} h {minutes % 60:02d} min"


class Pace:
    """Seconds per unit of work (press, epoch) since the first :meth:`update` of this run, and the time left."""

    def __init__(self) -> None:
        self._start: tuple[float, int] | None = None  # (monotonic time, units done) when first seen
        self._last: tuple[float, int] | None = None

    def update(self, done: int) -> None:
        """``done`` units are finished now (counted from the run's start, including any before a resume)."""
        now = time.monotonic()
        if self._start is None:
            self._start = (now, done)
        self._last = (now, done)

    def seconds_left(self, total: int) -> float | None:
        """Seconds until ``total`` units at this run's pace; None until a unit finished after the first update."""
        if self._start is None or self._last is None or self._last[1] <= self._start[1]:
            return None
        per_unit = (self._last[0] - self._start[0]) / (self._last[1] - self._start[1])
        return per_unit * max(total - self._last[1], 0)

    def left_text(self, total: int) -> str:
        """``about 12 min left``, or "" while the pace is not known yet or nothing is left."""
        left = self.seconds_left(total)
        return (
            ""
            if left is None or (self._last is not None and self._last[1] >= total)
            else (f"about {spoken_duration(left)} left")
        )
