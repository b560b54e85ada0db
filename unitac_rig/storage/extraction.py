"""Force-matched extraction: for each press, pick the tactile frame that goes with each target wrist force.

For every target force F* (25 targets, 4.00..10.00 N in 0.25 N steps, as in the paper) on the *loading ramp* of a press:

1. the press force (wrist force along the press direction, N) is smoothed with a centred moving average
   (``smoothing_samples``; the UR's F/T is noisy, and a single noisy sample must not decide a crossing);
2. the crossing time t* is the first upward crossing of F* before the peak, linearly interpolated between the two
   force samples that bracket it (a target only the raw force reached, because smoothing lowered the peak, is
   matched on the raw force throughout);
3. the matched frame is the tactile frame nearest in time to t* (after shifting tactile host times by
   ``tactile_latency_s``, the sensor's known delay, 0 by default);
4. the force at that frame is the smoothed press force interpolated at the frame's time; the matching error is that
   force minus F*;
5. a target is a *miss* when the press never reached it on the loading ramp, when the nearest frame is more than
   ``max_frame_gap_s`` from t*, when that frame is flagged invalid (missing or stale taxels), or when
   ``|error| > tolerance_n``.

Everything here is a pure function of the raw streams, so ``unitac-rig extract`` can recompute it with other settings.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field

import numpy as np

MAX_SMOOTHING_SAMPLES = 5000  # 10 s at 500 Hz: longer than any press; larger windows only flatten it
MAX_LATENCY_S = 1.0  # a tactile delay beyond a second is a wrong setting, not a sensor (frames arrive at 100-1000 Hz)


def default_targets_n() -> np.ndarray:
    """The paper's 25 target forces: 4.00..10.00 N in 0.25 N steps."""
    return np.round(np.arange(4.0, 10.0 + 1e-9, 0.25), 2)


@dataclass(frozen=True)
class ExtractionSettings:
    targets_n: tuple[float, ...] = tuple(float(x) for x in default_targets_n())
    tolerance_n: float = 0.5
    smoothing_samples: int = 15  # 30 ms at 500 Hz: the UR F/T noise is correlated over ~10 ms
    max_frame_gap_s: float = 0.05
    tactile_latency_s: float = 0.0

    def problems(self) -> list[tuple[str, str]]:
        """(field, what is wrong) for every setting extraction cannot work with; empty when all are usable."""
        found: list[tuple[str, str]] = []
        if not (math.isfinite(self.tolerance_n) and self.tolerance_n > 0):
            found.append(("tolerance_n", f"must be a positive number of newtons, got {self.tolerance_n:g}"))
        if not 1 <= self.smoothing_samples <= MAX_SMOOTHING_SAMPLES:
            found.append(("smoothing_samples", f"must be 1 to {MAX_SMOOTHING_SAMPLES} samples, got "
                          f"{self.smoothing_samples}"))  # fmt: skip
        if not (math.isfinite(self.tactile_latency_s) and abs(self.tactile_latency_s) <= MAX_LATENCY_S):
            found.append(("tactile_latency_s", f"must be a number of seconds within ±{MAX_LATENCY_S:g}, got "
                          f"{self.tactile_latency_s:g}"))  # fmt: skip
        if not (math.isfinite(self.max_frame_gap_s) and self.max_frame_gap_s > 0):
            found.append(("max_frame_gap_s", f"must be a positive number of seconds, got {self.max_frame_gap_s:g}"))
        if not self.targets_n or not all(math.isfinite(t) and t > 0 for t in self.targets_n):
            found.append(("targets_n", "must be one or more positive forces in newtons"))
        return found

    def to_dict(self) -> dict[str, object]:
        d = asdict(self)
        d["targets_n"] = list(self.targets_n)
        return d

    @classmethod
    def from_dict(cls, d: dict[str, object]) -> ExtractionSettings:
        kwargs = dict(d)
        if "targets_n" in kwargs:
            kwargs["targets_n"] = tuple(float(x) for x in kwargs["targets_n"])  # type: ignore[attr-defined]
        return cls(**kwargs)  # type: ignore[arg-type]


@dataclass
class Extraction:
    """Per-target result arrays, each of length n_targets (frame_index -1 where no frame was chosen)."""

    targets_n: np.ndarray
    crossing_t_s: np.ndarray  # NaN where the ramp never reached the target
    frame_index: np.ndarray  # int64, index into the press's tactile stream, -1 if none
    frame_t_s: np.ndarray
    force_at_frame_n: np.ndarray
    error_n: np.ndarray
    miss: np.ndarray  # bool
    settings: ExtractionSettings = field(default_factory=ExtractionSettings)

    @property
    def n_matched(self) -> int:
        return int((~self.miss).sum())


def smooth(values: np.ndarray, window: int) -> np.ndarray:
    """Centred moving average with edge-shrinking windows (no phase shift, same length)."""
    values = np.asarray(values, dtype=np.float64)
    if window <= 1 or values.size == 0:
        return values.copy()
    half = window // 2
    padded_sum = np.concatenate([[0.0], np.cumsum(values)])
    idx = np.arange(values.size)
    lo = np.clip(idx - half, 0, values.size)
    hi = np.clip(idx + half + 1, 0, values.size)
    return (padded_sum[hi] - padded_sum[lo]) / (hi - lo)


def first_upward_crossings(t_s: np.ndarray, force_n: np.ndarray, targets_n: np.ndarray) -> np.ndarray:
    """Interpolated time at which ``force_n`` first rises through each target, up to its peak (NaN if never)."""
    t_s = np.asarray(t_s, dtype=np.float64)
    force_n = np.asarray(force_n, dtype=np.float64)
    out = np.full(len(targets_n), np.nan)
    if force_n.size < 2:
        return out
    peak = int(np.argmax(force_n))
    ramp_f = force_n[: peak + 1]
    ramp_t = t_s[: peak + 1]
    for k, target in enumerate(targets_n):
        above = np.nonzero(ramp_f >= target)[0]
        if above.size == 0:
            continue
        i = int(above[0])
        if i == 0:
            out[k] = ramp_t[0] if ramp_f[0] == target else np.nan
            continue
        f0, f1 = ramp_f[i - 1], ramp_f[i]
        frac = (target - f0) / (f1 - f0) if f1 != f0 else 0.0
        out[k] = ramp_t[i - 1] + frac * (ramp_t[i] - ramp_t[i - 1])
    return out


def extract_press(
    robot_t_s: np.ndarray,
    press_force_n: np.ndarray,
    tactile_t_s: np.ndarray,
    tactile_valid: np.ndarray | None = None,
    settings: ExtractionSettings | None = None,
) -> Extraction:
    """Match each target force to a tactile frame (see the module docstring for the rules)."""
    settings = settings or ExtractionSettings()
    targets = np.asarray(settings.targets_n, dtype=np.float64)
    n = targets.size
    force = smooth(press_force_n, settings.smoothing_samples)
    robot_t = np.asarray(robot_t_s, dtype=np.float64)
    frame_t = np.asarray(tactile_t_s, dtype=np.float64) - settings.tactile_latency_s
    valid = np.ones(frame_t.size, bool) if tactile_valid is None else np.asarray(tactile_valid, bool)

    crossing = first_upward_crossings(robot_t, force, targets)
    # Smoothing lowers a short peak: a target the raw force reached but the smoothed force did not (the last ones,
    # at the stop) takes its crossing from the raw force.
    raw = np.asarray(press_force_n, np.float64)
    from_raw = np.isnan(crossing)
    if from_raw.any():
        crossing[from_raw] = first_upward_crossings(robot_t, raw, targets[from_raw])
    frame_index = np.full(n, -1, dtype=np.int64)
    frame_time = np.full(n, np.nan)
    force_at = np.full(n, np.nan)
    miss = np.ones(n, dtype=bool)
    if frame_t.size and robot_t.size:
        reached = ~np.isnan(crossing)
        # nearest frame in time to each crossing
        pos = np.searchsorted(frame_t, crossing[reached])
        left = np.clip(pos - 1, 0, frame_t.size - 1)
        right = np.clip(pos, 0, frame_t.size - 1)
        pick_right = np.abs(frame_t[right] - crossing[reached]) < np.abs(frame_t[left] - crossing[reached])
        nearest = np.where(pick_right, right, left)
        frame_index[reached] = nearest
        frame_time[reached] = frame_t[nearest]
        force_at[reached] = np.where(
            from_raw[reached], np.interp(frame_t[nearest], robot_t, raw), np.interp(frame_t[nearest], robot_t, force)
        )
        gap_ok = np.abs(frame_t[nearest] - crossing[reached]) <= settings.max_frame_gap_s
        miss[reached] = ~(gap_ok & valid[nearest])
    error = force_at - targets
    miss |= ~(np.abs(error) <= settings.tolerance_n)  # NaN counts as a miss
    return Extraction(
        targets_n=targets,
        crossing_t_s=crossing,
        frame_index=frame_index,
        frame_t_s=frame_time,
        force_at_frame_n=force_at,
        error_n=error,
        miss=miss,
        settings=settings,
    )
