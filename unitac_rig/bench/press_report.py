"""The press benchmark's figure (campaign time against matching error, Pareto front) and its text summary."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

from unitac_rig.bench.press_benchmark import (
    CAMPAIGN_PRESSES,
    GOAL_MEDIAN_ERROR_N,
    GOAL_TIME_FRACTION,
    inf_if_missing,
    is_finite_number,
    pareto_front,
)

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
    import textwrap

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
