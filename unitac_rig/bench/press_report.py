"""The press benchmark's figure (campaign time against matching error, Pareto front) and its text summary."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

from unitac_rig.bench.press_scoring import (
    CAMPAIGN_PRESSES,
    GOAL_MEDIAN_ERROR_N,
    GOAL_TIME_FRACTION,
    inf_if_missing,
    is_finite_number,
    pareto_front,
)

STRATEGY_COLOURS = {"guarded": "tab:blue", "two-phase": "tab:orange", "force-ramp": "tab:green"}


def plot_press_benchmark(doc: dict[str, Any], path: Path) -> Path:
    """Campaign time against median matching error (Pareto front dashed) for the as-collected variant, the best
    variant at the default PapillArray rate, the best overall, and the simulator-truth error of the best overall."""
    from unitac_rig.plotting import new_figure, save_figure  # matplotlib loads slowly: only when drawing

    variants = doc["variants"]
    chosen = [variants[0]]
    for candidate in (
        _best_variant([v for v in variants if v["papillarray_rate_hz"] == variants[0]["papillarray_rate_hz"]]),
        _best_variant(variants),
    ):
        if all(candidate["name"] != v["name"] for v in chosen):
            chosen.append(candidate)
    panels = [(v, "median_abs_error_n", "median |matching error| (N), misses counted") for v in chosen]
    panels.append((chosen[-1], "true_median_abs_error_n", "median |true force at matched frame - target| (N)"))
    columns = 2
    rows = math.ceil(len(panels) / columns)
    fig = new_figure(13.0, 5.0 * rows, dpi=100, layout="tight")
    axes = fig.subplots(rows, columns, squeeze=False)
    values = [r[key] for v, key, _ in panels for r in v["rows"] if is_finite_number(r[key])]
    limits = (min([*values, GOAL_MEDIAN_ERROR_N]) / 1.5, max([*values, GOAL_MEDIAN_ERROR_N]) * 1.5)
    for ax, (variant, key, ylabel) in zip(axes.flat, panels, strict=False):
        _front_panel(ax, variant, key, ylabel)
        ax.set_ylim(*limits)
        prefix = "simulator truth, " if key.startswith("true") else ""
        ax.set_title(_wrap(prefix + variant["name"]), fontsize=10)
    for ax in list(axes.flat)[len(panels) :]:
        ax.axis("off")
    fig.suptitle(
        f"Press strategy: campaign time (x {CAMPAIGN_PRESSES} presses, simulated) vs force-matching error "
        f"({doc['presses_run']} presses: {', '.join(doc['plan']['objects'])}; {', '.join(doc['plan']['sensors'])})",
        fontsize=11,
    )
    return save_figure(fig, path)


def _wrap(text: str, width: int = 60) -> str:
    import textwrap

    return "\n".join(textwrap.wrap(text, width))


def _front_panel(ax: Any, variant: dict[str, Any], key: str, ylabel: str) -> None:
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
    ax.axhline(GOAL_MEDIAN_ERROR_N, color="red", lw=0.8, ls=":", label=f"goal {GOAL_MEDIAN_ERROR_N} N")
    units = {"guarded": "guarded (mm/s)", "two-phase": "two-phase (fast/slow mm/s)", "force-ramp": "force-ramp (N/s)"}
    for strategy, colour in STRATEGY_COLOURS.items():
        ax.scatter([], [], color=colour, label=units[strategy])
    ax.set_xlabel("campaign time (h, simulated)")
    ax.set_ylabel(ylabel, fontsize=9)
    ax.set_yscale("log")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8, loc="best")


def _best_variant(variants: list[dict[str, Any]]) -> dict[str, Any]:
    """The variant whose fastest setting at the goal error is fastest (else the lowest median error anywhere)."""

    def key(variant: dict[str, Any]) -> tuple[float, float]:
        reaching = [
            r["campaign_h"]
            for r in variant["rows"]
            if is_finite_number(r["median_abs_error_n"]) and r["median_abs_error_n"] <= GOAL_MEDIAN_ERROR_N
        ]
        best_error = min(inf_if_missing(r["median_abs_error_n"]) for r in variant["rows"])
        return (min(reaching) if reaching else math.inf, best_error)

    best: dict[str, Any] = min(variants, key=key)
    return best


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
            f"{'true med N':>10s} {'true peak-10 N':>14s} {'N/s':>5s}"
        )
        for r in variant["rows"]:
            lines.append(
                f"{r['setting']:26s} {r['per_press_s']:7.2f} {r['campaign_h']:10.2f} "
                f"{n(r['median_abs_error_n']):>8s} {n(r['p95_abs_error_n']):>6s} {r['miss_rate']:5.2f} "
                f"{n(r['true_median_abs_error_n']):>10s} {n(r['true_overshoot_median_n'], '{:+.2f}'):>14s} "
                f"{n(r['rise_rate_median_n_s'], '{:.1f}'):>5s}{'  front' if r['pareto'] else ''}"
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
