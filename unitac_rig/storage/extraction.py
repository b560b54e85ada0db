"""Force-matched extraction: for each press, pick the tactile frame that goes with each target wrist force.

Two ways to estimate the press force a frame goes with (``ExtractionSettings.method``):

``"fit"`` (the default): the *true* press force, estimated from the whole press instead of a few noisy samples. A
UR's wrist force has ~0.4 N of noise per 500 Hz reading even after its filter and lags the true force by
``ft_lag_s`` (transport latency + filter time constant, ~12 ms); a moving average of it matches frames to within
~0.05 N of *itself* while the true force at those frames is ~0.2 N off. So:

1. the baseline (what the zero left over) is re-estimated from the free-air readings before first contact and after
   the pad has left the object again (any sample whose neighbourhood average is under ``FREE_AIR_N``, away from the
   contact by ``FREE_AIR_GUARD_S``), and subtracted;
2. the loading ramp (from ``RAMP_START_N`` below the lowest target up to the peak of the smoothed force) is fitted by
   least squares with a cubic spline in time (knots every ``fit_knot_s``): smooth and averaging hundreds of readings;
3. the fitted curve is shifted earlier by ``ft_lag_s``: the true force at time t is the fitted reading at t + lag;
4. each target's crossing is the first upward crossing of that curve; the matched frame is the nearest tactile frame
   (after ``tactile_latency_s``) and its force is the curve at the frame's time. A target the curve never reaches
   is matched at the curve's peak, and its error says by how much it fell short: the press stops on the *measured*
   force, so the true force tops out within a few tenths of a newton of the stop target either way, and a frame
   within ``tolerance_n`` of a target counts, as in the moving-average method.

``"moving-average"`` (sessions recorded before the fit; still selectable): for every target force F* on the
*loading ramp* of a press:

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

Both methods then apply the same miss rules (frame gap, invalid frame, tolerance). Everything here is a pure function
of the raw streams, so ``unitac-rig extract`` can recompute it with other settings (sessions store theirs).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field
from typing import Literal

import numpy as np

MAX_SMOOTHING_SAMPLES = 5000  # 10 s at 500 Hz: longer than any press; larger windows only flatten it
MAX_LATENCY_S = 1.0  # a tactile delay beyond a second is a wrong setting, not a sensor (frames arrive at 100-1000 Hz)
FREE_AIR_N = 1.0  # fit: a reading whose 50 ms neighbourhood averages under this (after the zero) is free air, N
FREE_AIR_GUARD_S = 0.05  # ... and only at least this far (s) from any reading above it (contact begins softly)
RAMP_START_N = 1.5  # fit: the ramp fit starts where the smoothed force passes (lowest target - this), N
FREE_AIR_SMOOTHING_S = 0.05  # the neighbourhood average that tells free air from contact, s


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
    # "fit": the fitted, lag-compensated true force (module docstring); "moving-average": the recorded force smoothed
    # by ``smoothing_samples`` (what sessions before the fit used; their stored settings lack this field)
    method: Literal["fit", "moving-average"] = "fit"
    ft_lag_s: float = 0.012  # fit: the wrist F/T's lag behind the true force, s (a UR e-series: ~4 ms + 8 ms filter)
    fit_knot_s: float = 0.5  # fit: spline knot spacing on the loading ramp, s (longer: less noise, more bias)

    def problems(self) -> list[tuple[str, str]]:
        """(field, what is wrong) for every setting extraction cannot work with; empty when all are usable."""
        found: list[tuple[str, str]] = []
        if not (math.isfinite(self.tolerance_n) and self.tolerance_n > 0):
            found.append(("tolerance_n", f"must be a positive number of newtons, got {self.tolerance_n:g}"))
        if not 1 <= self.smoothing_samples <= MAX_SMOOTHING_SAMPLES:
            found.append(
                ("smoothing_samples", f"must be 1 to {MAX_SMOOTHING_SAMPLES} samples, got {self.smoothing_samples}")
            )
        if not (math.isfinite(self.tactile_latency_s) and abs(self.tactile_latency_s) <= MAX_LATENCY_S):
            found.append(
                (
                    "tactile_latency_s",
                    f"must be a number of seconds within ±{MAX_LATENCY_S:g}, got {self.tactile_latency_s:g}",
                )
            )
        if not (math.isfinite(self.max_frame_gap_s) and self.max_frame_gap_s > 0):
            found.append(("max_frame_gap_s", f"must be a positive number of seconds, got {self.max_frame_gap_s:g}"))
        if not self.targets_n or not all(math.isfinite(t) and t > 0 for t in self.targets_n):
            found.append(("targets_n", "must be one or more positive forces in newtons"))
        if self.method not in ("fit", "moving-average"):
            found.append(("method", f"must be 'fit' or 'moving-average', got {self.method!r}"))
        if not (math.isfinite(self.ft_lag_s) and 0 <= self.ft_lag_s <= MAX_LATENCY_S):
            found.append(("ft_lag_s", f"must be a number of seconds in [0, {MAX_LATENCY_S:g}], got {self.ft_lag_s:g}"))
        if not (math.isfinite(self.fit_knot_s) and self.fit_knot_s > 0):
            found.append(("fit_knot_s", f"must be a positive number of seconds, got {self.fit_knot_s:g}"))
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


def nearest_index(sorted_t: np.ndarray, query: np.ndarray) -> np.ndarray:
    """Index of the element of ``sorted_t`` nearest each of ``query`` (the earlier one on a tie)."""
    pos = np.searchsorted(sorted_t, query)
    left = np.clip(pos - 1, 0, sorted_t.size - 1)
    right = np.clip(pos, 0, sorted_t.size - 1)
    return np.where(np.abs(sorted_t[right] - query) < np.abs(sorted_t[left] - query), right, left)


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


def free_air_baseline(t_s: np.ndarray, force_n: np.ndarray) -> float:
    """The mean reading (N) where nothing touches the pad: samples whose ``FREE_AIR_SMOOTHING_S`` average is under
    ``FREE_AIR_N`` and which are at least ``FREE_AIR_GUARD_S`` from any sample above it (longer before a slow first
    contact); 0 with fewer than 10.

    What the F/T zero left over (a zero from a short window is off by ~0.1-0.2 N), measured on the press itself."""
    t_s, force_n = np.asarray(t_s, np.float64), np.asarray(force_n, np.float64)
    if force_n.size < 10:
        return 0.0
    window = max(1, round(FREE_AIR_SMOOTHING_S / _sample_period_s(t_s)))
    smoothed = smooth(force_n, window)
    loaded_t = t_s[smoothed >= FREE_AIR_N]
    if loaded_t.size == 0:
        free = np.ones(force_n.size, bool)
    else:
        pos = np.searchsorted(loaded_t, t_s)
        before = np.abs(t_s - loaded_t[np.clip(pos - 1, 0, loaded_t.size - 1)])
        after = np.abs(loaded_t[np.clip(pos, 0, loaded_t.size - 1)] - t_s)
        free = np.minimum(before, after) >= FREE_AIR_GUARD_S
        # A slow press into a soft object takes a while to show FREE_AIR_N: leave out twice the time the force took
        # from FREE_AIR_N to 2 x FREE_AIR_N before it (on a linear or stiffening contact, at least its rise from 0).
        higher = t_s[smoothed >= 2 * FREE_AIR_N]
        rise_s = float(higher[0] - loaded_t[0]) if higher.size and higher[0] > loaded_t[0] else 0.0
        free &= ~((t_s >= loaded_t[0] - 2 * rise_s) & (t_s <= loaded_t[0]))
    return float(force_n[free].mean()) if free.sum() >= 10 else 0.0


def fit_loading_ramp(
    t_s: np.ndarray, force_n: np.ndarray, lowest_target_n: float, settings: ExtractionSettings
) -> tuple[np.ndarray, np.ndarray] | None:
    """The estimated true press force on the loading ramp: (times (s), force (N)), or None with no ramp to fit.

    Baseline-corrected (:func:`free_air_baseline`), least-squares cubic spline in time from where the smoothed force
    passes ``lowest_target_n - RAMP_START_N`` to its peak (knots every ``settings.fit_knot_s``), and shifted earlier
    by ``settings.ft_lag_s`` (the reading at t + lag is the true force at t)."""
    t_s, force_n = np.asarray(t_s, np.float64), np.asarray(force_n, np.float64)
    if force_n.size < 8:
        return None
    force = force_n - free_air_baseline(t_s, force_n)
    smoothed = smooth(force, max(1, round(FREE_AIR_SMOOTHING_S / _sample_period_s(t_s))))
    peak = int(np.argmax(smoothed))
    below = np.nonzero(smoothed[: peak + 1] < lowest_target_n - RAMP_START_N)[0]
    lo = int(below[-1]) if below.size else 0
    ramp_t, ramp_f = t_s[lo : peak + 1], force[lo : peak + 1]
    if ramp_t.size < 8 or ramp_t[-1] <= ramp_t[0]:
        return None
    span = ramp_t[-1] - ramp_t[0]
    x = (ramp_t - ramp_t[0]) / span
    intervals = max(1, min(round(span / settings.fit_knot_s), (ramp_t.size - 4) // 8))
    basis = _cubic_spline_basis(x, intervals)
    coef, *_ = np.linalg.lstsq(basis, ramp_f, rcond=None)
    return ramp_t - settings.ft_lag_s, basis @ coef


def _cubic_spline_basis(x: np.ndarray, intervals: int) -> np.ndarray:
    """Truncated-power basis of a cubic spline on [0, 1] with ``intervals`` equal pieces (C2 at the knots)."""
    columns = [np.ones_like(x), x, x**2, x**3]
    columns += [np.clip(x - k / intervals, 0.0, None) ** 3 for k in range(1, intervals)]
    return np.column_stack(columns)


def _sample_period_s(t_s: np.ndarray) -> float:
    steps = np.diff(t_s)
    steps = steps[steps > 0]
    return float(np.median(steps)) if steps.size else 0.002


def _fit_crossings(
    robot_t: np.ndarray, raw: np.ndarray, targets: np.ndarray, settings: ExtractionSettings
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Crossing times of the fitted true force; -> (crossings, curve times, curve force) (empty curve: no ramp)."""
    crossing = np.full(targets.size, np.nan)
    if targets.size == 0:
        return crossing, np.zeros(0), np.zeros(0)
    fitted = fit_loading_ramp(robot_t, raw, float(targets.min()), settings)
    if fitted is None:
        return crossing, np.zeros(0), np.zeros(0)
    curve_t, curve_f = fitted
    crossing = first_upward_crossings(curve_t, curve_f, targets)
    top = int(np.argmax(curve_f))
    short = np.isnan(crossing) & (curve_f[top] >= targets - settings.tolerance_n)
    crossing[short] = curve_t[top]  # the nearest the ramp came to these targets: matched there, the error says so
    return crossing, curve_t, curve_f


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
    robot_t = np.asarray(robot_t_s, dtype=np.float64)
    raw = np.asarray(press_force_n, np.float64)
    frame_t = np.asarray(tactile_t_s, dtype=np.float64) - settings.tactile_latency_s
    valid = np.ones(frame_t.size, bool) if tactile_valid is None else np.asarray(tactile_valid, bool)

    if settings.method == "fit":
        crossing, curve_t, curve_f = _fit_crossings(robot_t, raw, targets, settings)

        def force_at_times(times: np.ndarray, reached: np.ndarray) -> np.ndarray:
            return np.interp(times, curve_t, curve_f) if curve_t.size else np.full(times.shape, np.nan)

    elif settings.method == "moving-average":
        force = smooth(press_force_n, settings.smoothing_samples)
        crossing = first_upward_crossings(robot_t, force, targets)
        # Smoothing lowers a short peak: a target the raw force reached but the smoothed force did not (the last
        # ones, at the stop) takes its crossing from the raw force.
        from_raw = np.isnan(crossing)
        if from_raw.any():
            crossing[from_raw] = first_upward_crossings(robot_t, raw, targets[from_raw])

        def force_at_times(times: np.ndarray, reached: np.ndarray) -> np.ndarray:
            return np.where(from_raw[reached], np.interp(times, robot_t, raw), np.interp(times, robot_t, force))

    else:
        raise ValueError(f"unknown extraction method {settings.method!r} (fit or moving-average)")
    frame_index = np.full(n, -1, dtype=np.int64)
    frame_time = np.full(n, np.nan)
    force_at = np.full(n, np.nan)
    miss = np.ones(n, dtype=bool)
    if frame_t.size and robot_t.size:
        reached = ~np.isnan(crossing)
        nearest = nearest_index(frame_t, crossing[reached])
        frame_index[reached] = nearest
        frame_time[reached] = frame_t[nearest]
        force_at[reached] = force_at_times(frame_t[nearest], reached)
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
