"""The simulated wrist F/T's random parts: its bias drift and white noise, drawn from the arm's own generator a
block at a time (:class:`NormalBlocks`) and formed for many control periods at once (:class:`FtNoise`), with the
same draws and the same operations a period at a time would make, so a seeded arm gives the same readings."""

from __future__ import annotations

import numpy as np


class NormalBlocks:
    """Standard normal draws from ``rng`` taken a block at a time (one generator call per ~1,000 control periods
    instead of two per period). ``rng.normal(0, s, n)`` is ``s`` times the next ``n`` standard normals of the same
    stream, so ``s * take(n)`` gives bit for bit what drawing ``n`` at a time gave; the generator must not be drawn
    from elsewhere afterwards (the arm owns its stream)."""

    BLOCK = 12_288

    def __init__(self, rng: np.random.Generator) -> None:
        self._rng = rng
        self._block = np.empty(0)
        self._next = 0

    def take(self, n: int) -> np.ndarray:
        if self._next + n > self._block.size:
            self._block = np.concatenate([self._block[self._next :], self._rng.standard_normal(self.BLOCK)])
            self._next = 0
        out = self._block[self._next : self._next + n]
        self._next += n
        return out


class FtNoise:
    """The F/T's bias drift and white noise for the coming control periods, computed ``NormalBlocks.BLOCK`` normals
    at a time with the very operations, in the same order, that each period did on its own (so the same bits):
    per period six drift normals (if the drift is on), then six noise normals (if the noise is on), each scaled
    as ``(s * normals) * axis_scale``; the bias is the running sum of the drifts, which ``np.add.accumulate``
    forms one period after the other as the per-period additions did."""

    def __init__(self, normals: NormalBlocks, drift_step: float, noise_sigma: float, axis_scale: np.ndarray) -> None:
        self._normals = normals
        self._drift_step = drift_step if drift_step > 0 else None
        self._noise_sigma = noise_sigma if noise_sigma > 0 else None
        self._axis_scale = axis_scale
        self._per_period = 6 * ((self._drift_step is not None) + (self._noise_sigma is not None))
        self._bias: np.ndarray | None = None  # (periods, 6) bias after each coming period
        self._noise: np.ndarray | None = None  # (periods, 6)
        self._next = 0
        self._periods = 0

    def next(self, bias: np.ndarray) -> tuple[np.ndarray, np.ndarray | None]:
        """-> (the bias after this period's drift, this period's noise or None); ``bias`` is the bias before it."""
        if not self._per_period:
            return bias, None
        if self._next >= self._periods:
            self._refill(bias)
        k = self._next
        self._next += 1
        return (self._bias[k] if self._bias is not None else bias), (
            self._noise[k] if self._noise is not None else None
        )

    def _refill(self, bias: np.ndarray) -> None:
        periods = NormalBlocks.BLOCK // self._per_period
        draws = self._normals.take(periods * self._per_period).reshape(periods, self._per_period)
        column = 0
        self._bias = self._noise = None
        if self._drift_step is not None:
            steps = self._drift_step * draws[:, :6] * self._axis_scale
            self._bias = np.add.accumulate(np.concatenate([bias[None, :], steps]), axis=0)[1:]
            column = 6
        if self._noise_sigma is not None:
            self._noise = self._noise_sigma * draws[:, column : column + 6] * self._axis_scale
        self._next, self._periods = 0, periods
