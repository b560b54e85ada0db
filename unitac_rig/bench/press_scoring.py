"""Scoring of the press benchmark's samples: force-matching error (misses counted), what the simulator knows and the
recording cannot, campaign time, the Pareto front of time against error, and the goal verdict."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    from unitac_rig.bench.press_benchmark import ExtractionVariant, PressBenchPlan, PressSample

CAMPAIGN_PRESSES = 1820  # 7 objects x 91 angles x 2 sensors, the irregular prism at 4 rotations
GOAL_MEDIAN_ERROR_N = 0.05
GOAL_TIME_FRACTION = 0.5  # of the campaign time guarded needs for the same error


def transit_time_s(distance_m: float, speed_m_s: float, accel_m_s2: float) -> float:
    """Duration (s) of a trapezoidal straight move: accelerate, cruise, decelerate (triangular when short)."""
    if distance_m <= 0:
        return 0.0
    if distance_m < speed_m_s**2 / accel_m_s2:
        return 2.0 * math.sqrt(distance_m / accel_m_s2)
    return distance_m / speed_m_s + speed_m_s / accel_m_s2


def campaign_transit_s(object_id: str) -> float:
    """Mean transit time (s) between consecutive stand-off poses of the 91-angle plan (press transit speed)."""
    from unitac_rig.collection.session import plan_presses
    from unitac_rig.rig.config import RigConfig
    from unitac_rig.rig.objects import get_object

    config = RigConfig()
    obj = get_object(object_id)
    plans = plan_presses(obj, config, [obj.rotations_deg[0]])
    positions = np.array([p.start_pose[:3] for p in plans])
    steps = np.linalg.norm(np.diff(positions, axis=0), axis=1)
    speed = config.press.transit_speed_mm_s / 1000.0
    return float(np.mean([transit_time_s(float(d), speed, 0.5) for d in steps]))


def ft_lag_s() -> float:
    """The simulated wrist F/T's lag on a ramp (s): transport latency + the low-pass filter's time constant."""
    from unitac_rig.sim.arm import SimArmParams

    params = SimArmParams()
    tau = 0.0 if params.ft_filter_cutoff_hz is None else 1.0 / (2 * math.pi * params.ft_filter_cutoff_hz)
    return params.ft_latency_s + tau


def nearest_rank(values: np.ndarray, q: float) -> float:
    """The q-quantile (0..1) by nearest rank, so infinities (misses) stay infinities instead of NaN."""
    if values.size == 0:
        return float("nan")
    ordered = np.sort(values)
    return float(ordered[max(0, math.ceil(q * ordered.size) - 1)])


@dataclass
class Score:
    presses: int = 0
    targets: int = 0
    misses: int = 0
    abs_error_n: list[np.ndarray] = field(default_factory=list)  # misses as inf
    true_abs_error_n: list[np.ndarray] = field(default_factory=list)  # matched targets only
    true_overshoot_n: list[float] = field(default_factory=list)
    true_peak_n: list[float] = field(default_factory=list)  # the true press force's largest value per press, N
    recorded_overshoot_n: list[float] = field(default_factory=list)
    rise_rate_n_s: list[float] = field(default_factory=list)
    cycle_s: list[float] = field(default_factory=list)
    phases_s: dict[str, list[float]] = field(default_factory=dict)
    statuses: dict[str, int] = field(default_factory=dict)

    def add(self, sample: PressSample, variant: ExtractionVariant, threshold_n: float) -> None:
        from unitac_rig.storage.extraction import ExtractionSettings, extract_press

        settings = ExtractionSettings(
            method=variant.method,  # type: ignore[arg-type]
            smoothing_samples=variant.smoothing_samples,
            tactile_latency_s=-ft_lag_s() if variant.ft_lag_compensation else 0.0,
            ft_lag_s=ft_lag_s(),
        )
        ex = extract_press(sample.robot_t_s, sample.press_force_n, sample.tactile_t_s, sample.tactile_valid, settings)
        self.presses += 1
        self.targets += ex.targets_n.size
        self.misses += int(ex.miss.sum())
        self.abs_error_n.append(np.where(ex.miss, np.inf, np.abs(ex.error_n)))
        matched = ~ex.miss
        if matched.any() and sample.truth_t_s.size:
            frame_times = sample.tactile_t_s[ex.frame_index[matched]]
            true_force = np.interp(frame_times, sample.truth_t_s, sample.truth_force_n)
            self.true_abs_error_n.append(np.abs(true_force - ex.targets_n[matched]))
        if sample.truth_force_n.size:
            self.true_overshoot_n.append(float(sample.truth_force_n.max()) - threshold_n)
            self.true_peak_n.append(float(sample.truth_force_n.max()))
        self.recorded_overshoot_n.append(sample.recorded_overshoot_n)
        lo, hi = np.searchsorted(ex.targets_n, [4.0, 9.5])
        t_lo, t_hi = ex.crossing_t_s[lo], ex.crossing_t_s[hi]
        if np.isfinite(t_lo) and np.isfinite(t_hi) and t_hi > t_lo:
            self.rise_rate_n_s.append((ex.targets_n[hi] - ex.targets_n[lo]) / (t_hi - t_lo))
        self.cycle_s.append(sample.cycle_s)
        for name, seconds in sample.phases_s.items():
            self.phases_s.setdefault(name, []).append(seconds)
        self.statuses[sample.status] = self.statuses.get(sample.status, 0) + 1

    def summary(self, transit_s: float) -> dict[str, Any]:
        errors = np.concatenate(self.abs_error_n) if self.abs_error_n else np.zeros(0)
        finite = errors[np.isfinite(errors)]
        true_errors = np.concatenate(self.true_abs_error_n) if self.true_abs_error_n else np.zeros(0)
        per_press_s = float(np.mean(self.cycle_s)) + transit_s if self.cycle_s else float("nan")
        return {
            "presses": self.presses,
            "statuses": dict(self.statuses),
            "press_cycle_s": float(np.mean(self.cycle_s)) if self.cycle_s else None,
            "phases_mean_s": {k: float(np.nanmean(v)) for k, v in self.phases_s.items() if np.isfinite(v).any()},
            "per_press_s": per_press_s,
            "campaign_h": per_press_s * CAMPAIGN_PRESSES / 3600.0,
            "median_abs_error_n": nearest_rank(errors, 0.5),
            "p95_abs_error_n": nearest_rank(errors, 0.95),
            "miss_rate": self.misses / self.targets if self.targets else None,
            "matched_median_abs_error_n": float(np.median(finite)) if finite.size else None,
            "true_median_abs_error_n": float(np.median(true_errors)) if true_errors.size else None,
            "true_p95_abs_error_n": float(np.percentile(true_errors, 95)) if true_errors.size else None,
            "true_overshoot_median_n": float(np.median(self.true_overshoot_n)) if self.true_overshoot_n else None,
            "true_overshoot_max_n": float(np.max(self.true_overshoot_n)) if self.true_overshoot_n else None,
            "true_overshoot_min_n": float(np.min(self.true_overshoot_n)) if self.true_overshoot_n else None,
            "true_peak_max_n": float(np.max(self.true_peak_n)) if self.true_peak_n else None,
            "recorded_overshoot_median_n": float(np.nanmedian(self.recorded_overshoot_n))
            if self.recorded_overshoot_n
            else None,
            "rise_rate_median_n_s": float(np.median(self.rise_rate_n_s)) if self.rise_rate_n_s else None,
        }


def pareto_front(points: Sequence[tuple[float, float]]) -> list[int]:
    """Indices of the points no other point beats on both axes (smaller is better on both), by increasing x."""
    order = sorted(range(len(points)), key=lambda i: (points[i][0], points[i][1]))
    front: list[int] = []
    best_y = math.inf
    for i in order:
        if points[i][1] < best_y:
            front.append(i)
            best_y = points[i][1]
    return front


def evaluate_goal(rows: list[dict[str, Any]]) -> dict[str, Any]:
    """The goal: some non-guarded setting reaches the median error goal in at most half of guarded's time for it."""
    reaching = [
        r for r in rows if is_finite_number(r["median_abs_error_n"]) and r["median_abs_error_n"] <= GOAL_MEDIAN_ERROR_N
    ]
    guarded = [r for r in reaching if r["strategy"] == "guarded"]
    guarded_best = min(guarded, key=lambda r: r["campaign_h"]) if guarded else None
    others = sorted((r for r in reaching if r["strategy"] != "guarded"), key=lambda r: r["campaign_h"])
    result: dict[str, Any] = {
        "goal_median_abs_error_n": GOAL_MEDIAN_ERROR_N,
        "goal_time_fraction": GOAL_TIME_FRACTION,
        "settings_reaching_error": [r["setting"] for r in reaching],
        "guarded_fastest_reaching": None if guarded_best is None else guarded_best["setting"],
        "guarded_campaign_h": None if guarded_best is None else guarded_best["campaign_h"],
        "best_other": None if not others else others[0]["setting"],
        "best_other_campaign_h": None if not others else others[0]["campaign_h"],
    }
    if guarded_best is not None and others:
        ratio = others[0]["campaign_h"] / guarded_best["campaign_h"]
        result["time_ratio"] = ratio
        result["met"] = ratio <= GOAL_TIME_FRACTION
    else:
        result["time_ratio"] = None
        result["met"] = False
    slowest_guarded = max((r for r in rows if r["strategy"] == "guarded"), key=lambda r: r["campaign_h"], default=None)
    if guarded_best is None and slowest_guarded is not None and others:
        result["time_ratio_vs_slowest_guarded"] = others[0]["campaign_h"] / slowest_guarded["campaign_h"]
    return result


def is_finite_number(value: Any) -> bool:
    return isinstance(value, float | int) and math.isfinite(value)


def score(plan: PressBenchPlan, samples: list[PressSample]) -> dict[str, Any]:
    """Per variant and setting: the pooled summary, per-sensor summaries, the Pareto front and the goal verdict."""
    from unitac_rig.rig.config import PressConfig

    threshold_n = PressConfig().threshold_n
    transit = float(np.mean([campaign_transit_s(o) for o in plan.objects]))
    strategies = {s.label: s.strategy for s in plan.settings}
    variants = []
    for variant in plan.variants:
        rows = []
        for setting in plan.settings:
            chosen = [
                s
                for s in samples
                if s.setting == setting.label
                and (s.sensor != "papillarray" or s.papillarray_rate_hz == variant.papillarray_rate_hz)
            ]
            pooled = Score()
            by_sensor: dict[str, Score] = {}
            for sample in chosen:
                pooled.add(sample, variant, threshold_n)
                by_sensor.setdefault(sample.sensor, Score()).add(sample, variant, threshold_n)
            rows.append(
                {
                    "setting": setting.label,
                    "strategy": strategies[setting.label],
                    **setting.press_config(),
                    **pooled.summary(transit),
                    "by_sensor": {name: sc.summary(transit) for name, sc in sorted(by_sensor.items())},
                }
            )
        points = [(r["campaign_h"], inf_if_missing(r["median_abs_error_n"])) for r in rows]
        front = pareto_front(points)
        true_points = [(r["campaign_h"], inf_if_missing(r["true_median_abs_error_n"])) for r in rows]
        true_front = pareto_front(true_points)
        for i, row in enumerate(rows):
            row["pareto"] = i in front
            row["pareto_true"] = i in true_front
        variants.append(
            {
                "name": variant.name,
                "papillarray_rate_hz": variant.papillarray_rate_hz,
                "smoothing_samples": variant.smoothing_samples,
                "tactile_latency_s": -ft_lag_s() if variant.ft_lag_compensation else 0.0,
                "rows": rows,
                "method": variant.method,
                "pareto_front": [rows[i]["setting"] for i in front],
                "pareto_front_true": [rows[i]["setting"] for i in true_front],
                "goal": evaluate_goal(rows),
            }
        )
    return {"transit_per_press_s": transit, "ft_lag_s": ft_lag_s(), "variants": variants}


def inf_if_missing(value: Any) -> float:
    return float(value) if is_finite_number(value) else math.inf
