"""Press strategy and speed against force-matching accuracy, on the simulated rig, in one run.

Every setting (``guarded`` at several speeds, ``two-phase`` at several slow speeds, ``force-ramp`` at several ramp
rates) presses the same object mix (a PLA and a TPU prism, both sensors, several angles, a few seeds) through the
real press routine (:func:`unitac_rig.collection.press.run_press`) and the real drivers. Per setting it reports

* the simulated time of one press cycle (stand-off settle + zero + tare, approach, press, dwell, retract, return to
  the stand-off; the transit between stand-offs is added from the 91-angle plan) and of a paper campaign (x 1820
  presses); as in a session, presses after the first that confirms the object's placement start from the smaller
  confirmed stand-off;
* the force-matching error of :func:`unitac_rig.storage.extraction.extract_press` over the 25 targets: median
  and p95 of |error| with every miss counted as an infinite error, the miss rate, and the median of the matched
  targets alone;
* what the simulator knows and the recording cannot: the *true* press force at each matched frame minus its target,
  and the true peak minus the threshold (overshoot; negative = stopped short because a noisy sample crossed first);
* the force rise rate between the 4 N and 9.5 N crossings (N/s).

The raw streams are kept in memory, so the extraction is re-run for each *variant* (:data:`VARIANTS`: the fitted
force, the default, and the old moving average of 15 samples) without pressing again. Simulated times do not depend
on the machine; only wall time does.

This module plans, presses, scores (error with misses counted, campaign time, the Pareto front of time against
error, the goal verdict) and reports (the figure and the text summary).
"""

from __future__ import annotations

import math
import multiprocessing
import textwrap
import time
from collections.abc import Callable, Sequence
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np


@dataclass(frozen=True)
class PressSetting:
    """One press configuration to measure (speeds in mm/s, ramp in N/s)."""

    strategy: str
    speed_mm_s: float = 5.0
    fast_speed_mm_s: float = 15.0
    ramp_rate_n_s: float = 8.0

    @property
    def label(self) -> str:
        if self.strategy == "guarded":
            return f"guarded {self.speed_mm_s:g} mm/s"
        if self.strategy == "two-phase":
            return f"two-phase {self.fast_speed_mm_s:g}/{self.speed_mm_s:g} mm/s"
        return f"force-ramp {self.ramp_rate_n_s:g} N/s"

    def press_config(self) -> dict[str, Any]:
        return asdict(self)


# variant name -> the extraction's force estimate: the fitted, lag-compensated true force (with the simulated wrist's
# own lag) or the old moving average of the recorded force
VARIANTS = {"fit (the default)": "fit", "moving average of 15 (the old method)": "moving-average"}
PAPILLARRAY_RATE_HZ = 100  # the simulated hub's stream rate in every cell


@dataclass(frozen=True)
class PressBenchPlan:
    settings: tuple[PressSetting, ...]
    objects: tuple[str, ...] = ("hex_pla", "hex_tpu")
    sensors: tuple[str, ...] = ("uskin", "papillarray")
    angle_count: int = 5
    angle_span_deg: float = 90.0  # the angles are spread evenly over +-half of this
    seeds: tuple[int, ...] = (0, 1)


def full_plan() -> PressBenchPlan:
    """Every strategy at the speeds worth choosing from, on a stiff and a soft prism, with both sensors.

    Three angles per session, 10 degrees apart (the campaign's transit is added from the 91-angle plan, so a short
    arc only saves simulated transit), one seed: the chart is regenerated on a shared 2-core machine."""
    settings = (
        *(PressSetting("guarded", speed_mm_s=v) for v in (2.0, 3.0, 5.0, 8.0)),
        *(PressSetting("two-phase", speed_mm_s=v, fast_speed_mm_s=15.0) for v in (1.0, 2.0, 3.0, 4.0)),
        *(PressSetting("two-phase", speed_mm_s=v, fast_speed_mm_s=30.0) for v in (2.0, 3.0)),
        *(PressSetting("force-ramp", ramp_rate_n_s=r) for r in (4.0, 8.0, 16.0, 32.0)),
    )
    return PressBenchPlan(settings=settings, angle_count=3, angle_span_deg=10.0, seeds=(0,))


def quick_plan() -> PressBenchPlan:
    """A smoke run (well under a minute on 2 cores): one object, two angles, one seed, four settings."""
    settings = (
        PressSetting("guarded", speed_mm_s=2.0),
        PressSetting("guarded", speed_mm_s=8.0),
        PressSetting("two-phase", speed_mm_s=2.0),
        PressSetting("force-ramp", ramp_rate_n_s=8.0),
    )
    return PressBenchPlan(settings=settings, objects=("hex_pla",), angle_count=2, seeds=(0,))


# ---------------------------------------------------------------------------------------------------------------------
# pressing


@dataclass
class PressSample:
    """One press's raw streams and what the simulator knew (times in simulated s, forces in N)."""

    setting: str
    object_id: str
    sensor: str
    seed: int
    angle_deg: float
    status: str
    reason: str
    cycle_s: float  # run_press from the stand-off (already there) to the end of the retract
    recorded_overshoot_n: float  # measured peak - threshold, as the press record keeps it
    robot_t_s: np.ndarray
    press_force_n: np.ndarray
    tactile_t_s: np.ndarray
    tactile_valid: np.ndarray
    truth_t_s: np.ndarray
    truth_force_n: np.ndarray
    phases_s: dict[str, float] = field(default_factory=dict)  # settle, approach, load, dwell+retract (simulated s)
    wall_s: float = 0.0


@dataclass(frozen=True)
class Cell:
    """One rig session of the benchmark: a setting on one object with one sensor and seed."""

    setting: PressSetting
    object_id: str
    sensor: str
    seed: int
    angle_count: int
    angle_span_deg: float = 90.0


def run_cell(cell: Cell) -> list[PressSample]:
    """Press every angle of ``cell`` on a fresh simulated rig; returns one sample per press."""
    from drivers.errors import DeviceTimeout, ProtectiveStop
    from unitac_rig.collection.press import run_press
    from unitac_rig.collection.session import confirmed_standoff_mm, placement_confirmed, plan_presses, session_tare
    from unitac_rig.collection.transit import move_clear, with_standoff
    from unitac_rig.errors import SafetyLimit
    from unitac_rig.rig.config import parse_rig_config
    from unitac_rig.rig.objects import get_object
    from unitac_rig.sim.fast_rig import SimRig
    from unitac_rig.storage.press_record import PressRecord

    half = cell.angle_span_deg / 2
    arc = {"angle_count": cell.angle_count, "angle_min_deg": -half, "angle_max_deg": half}
    config = parse_rig_config({"press": {**cell.setting.press_config(), **arc}})
    press, limits = config.press, config.limits
    obj = get_object(cell.object_id)
    rotation = obj.rotations_deg[0]
    plans = plan_presses(obj, config, [rotation])
    samples: list[PressSample] = []
    rig = SimRig(config, seed=cell.seed, sensor_options={"papillarray": {"rate_hz": PAPILLARRAY_RATE_HZ}})
    with rig:
        sensor = rig.open_sensor(cell.sensor)
        try:
            rig.mount(obj, rotation, cell.sensor)
            session_tare(rig, sensor, plans[0])  # the session's start: wrist zeroed, sensor tared at the stand-off
            clearance_m = config.object.clearance_mm / 1000.0
            confirmed = False
            for plan in plans:
                if confirmed:  # as the session does: the smaller stand-off once a press confirmed the placement
                    plan = with_standoff(plan, confirmed_standoff_mm(config))
                # the session's transit to the stand-off, done before the clock starts: a cycle excludes transit
                move_clear(rig.arm, plan, clearance_m, config.press.transit_speed_mm_s / 1000.0, config.limits)
                truth = _TruthRecorder(rig, plan.direction)
                began_ns, began_wall = rig.clock.now_ns(), time.perf_counter()
                record: PressRecord | None
                try:
                    record = run_press(
                        rig.arm, sensor, plan, press, limits, on_tick=truth.on_tick, clearance_m=clearance_m
                    )
                except (SafetyLimit, ProtectiveStop, DeviceTimeout) as exc:
                    record = exc.press_record
                    if record is None:
                        raise
                    rig.sim_arm.unlock_protective_stop()
                    rig.sim_arm.reupload_script()  # as on a controller: unlocking alone does not restart it
                confirmed = confirmed or placement_confirmed(record, config)
                samples.append(
                    PressSample(
                        setting=cell.setting.label,
                        object_id=cell.object_id,
                        sensor=cell.sensor,
                        seed=cell.seed,
                        angle_deg=plan.angle_deg,
                        status=record.status,
                        reason=record.reason,
                        cycle_s=(rig.clock.now_ns() - began_ns) / 1e9,
                        recorded_overshoot_n=float(record.attrs.get("overshoot_n", float("nan"))),
                        robot_t_s=np.asarray(record.robot_t_s),
                        press_force_n=np.asarray(record.press_force_n),
                        tactile_t_s=np.asarray(record.tactile_t_s),
                        tactile_valid=np.asarray(record.tactile_valid),
                        truth_t_s=np.asarray(truth.t_s),
                        truth_force_n=np.asarray(truth.force_n),
                        phases_s=_phases(record.events, began_ns / 1e9, rig.clock.now_ns() / 1e9),
                        wall_s=time.perf_counter() - began_wall,
                    )
                )
        finally:
            sensor.disconnect()
    return samples


class _TruthRecorder:
    """on_tick hook: the simulator's true press force (N) at every control period, with its simulated time (s)."""

    def __init__(self, rig: Any, direction: np.ndarray) -> None:
        self.rig, self.direction = rig, direction
        self.t_s: list[float] = []
        self.force_n: list[float] = []

    def on_tick(self, _: Any) -> None:
        self.t_s.append(self.rig.clock.now_ns() / 1e9)
        self.force_n.append(-float(np.dot(self.rig.sim_arm.true_wrench()[:3], self.direction)))


def _phases(events: list[tuple[float, str, str]], began_s: float, ended_s: float) -> dict[str, float]:
    """Where a press cycle's time went (s): settle (zero + tare at the stand-off), approach (to first contact),
    load (contact to the stop), unload (stopping, dwell and retract)."""
    first: dict[str, float] = {}
    for t, kind, _ in events:
        first.setdefault(kind, t)
    marks = [began_s, first.get("start", math.nan), first.get("contact", math.nan), first.get("stop", math.nan)]
    marks.append(ended_s)
    names = ("settle", "approach", "load", "unload")
    return {name: marks[i + 1] - marks[i] for i, name in enumerate(names)}


def plan_cells(plan: PressBenchPlan) -> list[Cell]:
    """Every rig session the plan needs: each setting on each object with each sensor and seed."""
    cells = [
        Cell(setting, object_id, sensor, seed, plan.angle_count, plan.angle_span_deg)
        for setting in plan.settings
        for object_id in plan.objects
        for sensor in plan.sensors
        for seed in plan.seeds
    ]
    # slow settings first, so the pool's last jobs are short
    return sorted(cells, key=lambda c: -_expected_cost(c.setting))


def _expected_cost(setting: PressSetting) -> float:
    if setting.strategy == "force-ramp":
        return 10.0 / setting.ramp_rate_n_s
    return 4.0 / setting.speed_mm_s


def collect_samples(
    plan: PressBenchPlan, jobs: int = 1, on_cell: Callable[[int, int], None] | None = None
) -> list[PressSample]:
    """Run every cell of ``plan`` (in ``jobs`` processes when > 1); ``on_cell(done, total)`` after each."""
    cells = plan_cells(plan)
    samples: list[PressSample] = []
    if jobs <= 1:
        for i, cell in enumerate(cells):
            samples.extend(run_cell(cell))
            if on_cell is not None:
                on_cell(i + 1, len(cells))
        return samples
    context = multiprocessing.get_context("spawn")  # no fork with library threads around
    with ProcessPoolExecutor(max_workers=jobs, mp_context=context) as pool:
        futures = [pool.submit(run_cell, cell) for cell in cells]
        for i, future in enumerate(as_completed(futures)):
            samples.extend(future.result())
            if on_cell is not None:
                on_cell(i + 1, len(cells))
    return samples


def run_press_benchmark(
    plan: PressBenchPlan, jobs: int = 1, on_cell: Callable[[int, int], None] | None = None
) -> dict[str, Any]:
    """Press, score, and return the whole result as a JSON-ready dict."""
    from unitac_rig.bench import machine_info

    host = machine_info()
    began = time.perf_counter()
    samples = collect_samples(plan, jobs, on_cell)
    wall = time.perf_counter() - began
    simulated = float(sum(s.cycle_s for s in samples))
    return {
        "benchmark": "press",
        "machine": host,
        "plan": {
            "settings": [s.label for s in plan.settings],
            "objects": list(plan.objects),
            "sensors": list(plan.sensors),
            "angle_count": plan.angle_count,
            "angle_span_deg": plan.angle_span_deg,
            "seeds": list(plan.seeds),
            "papillarray_rate_hz": PAPILLARRAY_RATE_HZ,
            "campaign_presses": CAMPAIGN_PRESSES,
        },
        "presses_run": len(samples),
        "wall_s": wall,
        "jobs": jobs,
        "simulated_press_s": simulated,
        "simulated_per_wall": simulated / wall if wall > 0 else None,
        **score(plan, samples),
    }


# ---- scoring ----------------------------------------------------------------------------------------------------
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

    def add(self, sample: PressSample, method: str, threshold_n: float) -> None:
        from unitac_rig.storage.extraction import ExtractionSettings, extract_press

        settings = ExtractionSettings(method=method, ft_lag_s=ft_lag_s())  # type: ignore[arg-type]
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
    for name, method in VARIANTS.items():
        rows = []
        for setting in plan.settings:
            pooled = Score()
            by_sensor: dict[str, Score] = {}
            for sample in (s for s in samples if s.setting == setting.label):
                pooled.add(sample, method, threshold_n)
                by_sensor.setdefault(sample.sensor, Score()).add(sample, method, threshold_n)
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
                "name": name,
                "rows": rows,
                "method": method,
                "pareto_front": [rows[i]["setting"] for i in front],
                "pareto_front_true": [rows[i]["setting"] for i in true_front],
                "goal": evaluate_goal(rows),
            }
        )
    return {"transit_per_press_s": transit, "ft_lag_s": ft_lag_s(), "variants": variants}


def inf_if_missing(value: Any) -> float:
    return float(value) if is_finite_number(value) else math.inf


# ---- the figure and the summary ----------------------------------------------------------------------------------
STRATEGY_COLOURS = {"guarded": "tab:blue", "two-phase": "tab:orange", "force-ramp": "tab:green"}


def plot_press_benchmark(doc: dict[str, Any], path: Path) -> Path:
    """Campaign time against the median matching error, measured (what the recording says) and true (the simulator's
    force at the matched frame), for the default extraction (the fit) and the old moving average, and against the
    largest true press force; the Pareto front of each panel dashed."""
    from unitac_rig.plotting import new_figure, save_figure  # matplotlib loads slowly: only when drawing

    variants = doc["variants"]
    fit = variants[0]
    old = next((v for v in variants if v.get("method") == "moving-average"), variants[-1])
    panels = [
        (fit, "median_abs_error_n", "median |matching error| (N), misses counted", "measured, "),
        (fit, "true_median_abs_error_n", "median |true force at matched frame - target| (N)", "simulator truth, "),
        (old, "median_abs_error_n", "median |matching error| (N), misses counted", "measured, "),
        (old, "true_median_abs_error_n", "median |true force at matched frame - target| (N)", "simulator truth, "),
    ]
    fig = new_figure(13.0, 15.0, dpi=100, layout="tight")
    axes = fig.subplots(3, 2, squeeze=False)
    values = [r[key] for v, key, _, _ in panels for r in v["rows"] if is_finite_number(r[key])]
    limits = (min([*values, GOAL_MEDIAN_ERROR_N]) / 1.5, max([*values, GOAL_MEDIAN_ERROR_N]) * 1.5)
    for ax, (variant, key, ylabel, prefix) in zip(axes.flat, panels, strict=False):
        _front_panel(ax, variant, key, ylabel)
        ax.set_ylim(*limits)
        ax.set_title(_wrap(prefix + variant["name"]), fontsize=10)
    ax = axes[2][0]
    _front_panel(ax, fit, "true_peak_max_n", "largest true press force (N)", goal_n=None, log=False)
    ax.set_title("largest true press force of any press (the stop is at 10 N)", fontsize=10)
    ax = axes[2][1]
    _front_panel(ax, fit, "miss_rate", "fraction of targets missed", goal_n=None, log=False)
    ax.set_title(_wrap("missed targets, " + fit["name"]), fontsize=10)
    fig.suptitle(
        f"Press strategy: campaign time (x {CAMPAIGN_PRESSES} presses, simulated) vs force-matching error "
        f"({doc['presses_run']} presses: {', '.join(doc['plan']['objects'])}; {', '.join(doc['plan']['sensors'])})",
        fontsize=11,
    )
    return save_figure(fig, path)


def _wrap(text: str, width: int = 60) -> str:
    return "\n".join(textwrap.wrap(text, width))


def _front_panel(
    ax: Any,
    variant: dict[str, Any],
    key: str,
    ylabel: str,
    goal_n: float | None = GOAL_MEDIAN_ERROR_N,
    log: bool = True,
) -> None:
    rows = variant["rows"]
    for row in rows:
        y = row[key]
        if not is_finite_number(y):
            continue
        ax.scatter(row["campaign_h"], y, color=STRATEGY_COLOURS[row["strategy"]], s=40, zorder=3)
        ax.annotate(
            row["setting"].split(" ", 1)[1].replace(" mm/s", "").replace(" N/s", ""),
            (row["campaign_h"], y),
            textcoords="offset points",
            xytext=(4, 3),
            fontsize=7,
        )
    points = [(r["campaign_h"], inf_if_missing(r[key])) for r in rows]
    front = [i for i in pareto_front(points) if math.isfinite(points[i][1])]
    if front:
        ax.step(
            [points[i][0] for i in front],
            [points[i][1] for i in front],
            where="post",
            color="black",
            lw=1,
            ls="--",
            label="Pareto front",
        )
    if goal_n is not None:
        ax.axhline(goal_n, color="red", lw=0.8, ls=":", label=f"goal {goal_n} N")
    units = {"guarded": "guarded (mm/s)", "two-phase": "two-phase (fast/slow mm/s)", "force-ramp": "force-ramp (N/s)"}
    for strategy, colour in STRATEGY_COLOURS.items():
        ax.scatter([], [], color=colour, label=units[strategy])
    ax.set_xlabel("campaign time (h, simulated)")
    ax.set_ylabel(ylabel, fontsize=9)
    if log:
        ax.set_yscale("log")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8, loc="best")


def summary_lines(doc: dict[str, Any]) -> list[str]:
    """A plain-text table per variant and the goal verdict."""

    def n(value: Any, fmt: str = "{:.3f}") -> str:
        return fmt.format(value) if is_finite_number(value) else "inf"

    lines = [
        f"{doc['presses_run']} presses in {doc['wall_s']:.0f} s wall ({doc['jobs']} processes); "
        f"{doc['simulated_press_s']:.0f} s simulated; transit between stand-offs {doc['transit_per_press_s']:.3f} s"
    ]
    for variant in doc["variants"]:
        lines.append("")
        lines.append(f"== {variant['name']}")
        lines.append(
            f"{'setting':26s} {'s/press':>7s} {'campaign h':>10s} {'median N':>8s} {'p95 N':>6s} {'miss':>5s} "
            f"{'true med N':>10s} {'true peak-10 N':>14s} {'max peak N':>10s} {'N/s':>5s}"
        )
        for r in variant["rows"]:
            lines.append(
                f"{r['setting']:26s} {r['per_press_s']:7.2f} {r['campaign_h']:10.2f} "
                f"{n(r['median_abs_error_n']):>8s} {n(r['p95_abs_error_n']):>6s} {r['miss_rate']:5.2f} "
                f"{n(r['true_median_abs_error_n']):>10s} {n(r['true_overshoot_median_n'], '{:+.2f}'):>14s} "
                f"{n(r.get('true_peak_max_n'), '{:.2f}'):>10s} {n(r['rise_rate_median_n_s'], '{:.1f}'):>5s}"
                f"{'  front' if r['pareto'] else ''}{'  true-front' if r.get('pareto_true') else ''}"
            )
        goal = variant["goal"]
        if goal["guarded_fastest_reaching"] is None:
            verdict = f"guarded never reaches {GOAL_MEDIAN_ERROR_N} N"
            if goal["best_other"] is not None:
                verdict += f"; {goal['best_other']} does, at {goal['best_other_campaign_h']:.2f} h"
        elif goal["best_other"] is None:
            verdict = f"only guarded reaches {GOAL_MEDIAN_ERROR_N} N ({goal['guarded_fastest_reaching']})"
        else:
            verdict = (
                f"{goal['best_other']} reaches {GOAL_MEDIAN_ERROR_N} N in {goal['time_ratio']:.2f}x the time of "
                f"{goal['guarded_fastest_reaching']} -> goal (<= {GOAL_TIME_FRACTION}x) "
                f"{'MET' if goal['met'] else 'not met'}"
            )
        lines.append(f"goal: {verdict}")
    return lines
