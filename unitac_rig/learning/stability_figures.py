"""The three figures of a stability report (:func:`unitac_rig.learning.stability.stability_report`): errors per
outline feature of the unseen object, PLA against TPU, and the spread of every Table I cell over the seeds."""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.axes import Axes

from unitac_rig.learning.stability import MATERIALS, METRICS
from unitac_rig.plotting import new_figure, save_figure

CORNERS_PNG = "stability_learning_corners.png"
MATERIALS_PNG = "stability_learning_materials.png"
SEEDS_PNG = "stability_learning_seeds.png"


def _value(cell: dict[str, Any] | None, key: str = "mean") -> float:
    if cell is None or cell.get(key) is None:
        return math.nan
    return float(cell[key])


def _label(column: str) -> str:
    return column.replace("_to_", " → ").replace("papillarray", "papill")


def plot_stability(report: dict[str, Any], out_dir: Path) -> dict[str, Path]:
    """The three figures of a :func:`stability_report` dict; returns {"corners"|"materials"|"seeds": path}."""
    out_dir = Path(out_dir)
    drawn = {"corners": _plot_corners(report, out_dir / CORNERS_PNG)}
    if report["materials"]["pooled"] is not None:
        drawn["materials"] = _plot_materials(report, out_dir / MATERIALS_PNG)
    drawn["seeds"] = _plot_seeds(report, out_dir / SEEDS_PNG)
    return drawn


def _grouped_bars(ax: Axes, names: Sequence[str], series: dict[str, tuple[list[float], list[float]]]) -> None:
    """Bars per name (x) and series (colour), error bars = std over seeds."""
    width = 0.8 / max(1, len(series))
    x = np.arange(len(names))
    for i, (label, (means, stds)) in enumerate(series.items()):
        ax.bar(x + (i - (len(series) - 1) / 2) * width, means, width, yerr=stds, capsize=2, label=label)
    ax.set_xticks(x)
    ax.set_xticklabels(names, fontsize=8)


def _plot_corners(report: dict[str, Any], path: Path) -> Path:
    features = [f for f in report["features"] if f["test_contacts"] > 0]
    names = [f["name"] for f in features]
    ticks = [f"{f['name']}\n{f['test_contacts']} contacts" for f in features]
    recon = report["reconstruction"]
    geometry = report["geometry"]
    panels = 3 if geometry is not None else 2
    fig = new_figure(max(9.0, 1.6 * len(names)), 3.6 * panels, layout="tight")
    axes = fig.subplots(panels, 1, squeeze=False)
    for ax, metric in zip(axes[:, 0], METRICS, strict=False):
        series = {
            _label(c): (
                [_value((recon[n] or {}).get(c, {}).get(metric)) for n in names],
                [_value((recon[n] or {}).get(c, {}).get(metric), "std") for n in names],
            )
            for c in report["columns"]
        }
        _grouped_bars(ax, ticks, series)
        ax.set_ylabel(f"reconstruction {metric.upper()}")
        whole = recon["whole object"]
        for j, c in enumerate(report["columns"]):
            ax.axhline(_value(whole[c][metric]), color=f"C{j}", lw=0.7, ls=":")
    # headroom above the tallest bar, so the legend (right) and the paper's remark (left) cover no bar
    axes[0, 0].set_ylim(top=axes[0, 0].get_ylim()[1] * 1.45)
    axes[0, 0].legend(fontsize=7, ncol=3, title="dotted: whole object", title_fontsize=7, loc="upper right")
    if geometry is not None:
        ax = axes[2, 0]
        per_feature = geometry["per_feature"]
        series = {
            _label(s): (
                [_value((per_feature[n] or {}).get(s)) for n in names],
                [_value((per_feature[n] or {}).get(s), "std") for n in names],
            )
            for s in geometry["scenarios"]
        }
        _grouped_bars(ax, ticks, series)
        for k, paper in enumerate(geometry["paper_mae_mm"].values()):
            if paper is not None:
                ax.axhline(paper, color=f"C{k}", lw=0.8, ls="--")
        reference = [_value(per_feature[n], "mean_profile_mae_mm") for n in names]
        ax.scatter(
            np.arange(len(names)), reference, marker="_", s=900, color="k", zorder=3, label="mean profile, no latent"
        )
        ax.set_ylabel("geometry profile MAE (mm)")
        ax.set_ylim(top=max(ax.get_ylim()[1], float(np.nanmax(np.asarray(reference, dtype=float)))) * 1.3)
        ax.legend(fontsize=7, ncol=3, title="dashed: paper, whole object", title_fontsize=7)
    failing = [
        i
        for i, f in enumerate(features)
        if f["interior_angle_deg"] is not None
        and round(f["interior_angle_deg"]) == round(report["paper_failing_corner_deg"])
    ]
    for ax in axes[:, 0]:
        for i in failing:
            ax.axvspan(i - 0.45, i + 0.45, color="red", alpha=0.08, zorder=0)
    if failing:
        _paper_note(axes[0, 0], failing[0], "paper: poor reconstructions at sharp edges\nwith a small contact area")
        _paper_note(
            axes[-1, 0],
            failing[0],
            "paper (Sec. IV-C): geometry estimation\nambiguous at the 80° corner"
            if geometry is not None
            else "paper: 80° corner",
        )
    seeds = len(report["seeds"])
    fig.suptitle(
        f"{report['object']}: errors by the outline feature the press hits (corner = contact origin within "
        f"{report['face_distance_mm']:g} mm of the vertex); bars: mean over {seeds} seed(s), error bars: std",
        fontsize=9,
    )
    return save_figure(fig, path)


def _paper_note(ax: Axes, x: float, text: str) -> None:
    """A dark-red remark at the top of the panel, beside bar ``x``."""
    ax.annotate(
        text,
        (x, 1.0),
        xycoords=("data", "axes fraction"),
        xytext=(4, -4),
        textcoords="offset points",
        fontsize=7,
        color="darkred",
        va="top",
    )


def _plot_materials(report: dict[str, Any], path: Path) -> Path:
    materials = report["materials"]
    pooled = materials["pooled"]
    columns = report["columns"]
    fig = new_figure(13.0, 4.2, layout="tight")
    axes = fig.subplots(1, 2)
    x = np.arange(len(columns))
    markers = ["o", "s", "^", "D", "v"]
    for ax, metric in zip(axes, METRICS, strict=True):
        for i, mat in enumerate(MATERIALS):
            offset = (i - 0.5) * 0.38
            means = [_value(pooled[c][metric][mat]) for c in columns]
            stds = [_value(pooled[c][metric][mat], "std") for c in columns]
            ax.bar(x + offset, means, 0.36, yerr=stds, capsize=2, color=f"C{i}", alpha=0.7, label=f"{mat} (pooled)")
            for k, (shape, entry) in enumerate(materials["per_shape"].items()):
                ax.scatter(
                    x + offset,
                    [_value(entry[c][metric][mat]) for c in columns],
                    marker=markers[k % len(markers)],
                    color="k",
                    s=14,
                    zorder=3,
                    label=shape if i == 0 else None,
                )
            paper = [(pooled[c][metric]["paper"] or {}).get(mat, math.nan) for c in columns]
            ax.scatter(
                x + offset,
                paper,
                marker="_",
                color="red",
                s=160,
                zorder=4,
                label="paper (mean of its rows)" if i == 0 else None,
            )
        ax.set_xticks(x)
        ax.set_xticklabels([_label(c) for c in columns], fontsize=8, rotation=20)
        ax.set_ylabel(metric.upper())
        ax.set_title(f"{metric.upper()}: PLA vs TPU (seen objects' held-out angles)", fontsize=9)
    axes[0].legend(fontsize=7)
    return save_figure(fig, path)


def _plot_seeds(report: dict[str, Any], path: Path) -> Path:
    """Heatmaps of each Table I cell's spread over seeds: colour = (max - min) relative to the mean for NMAE, and
    (max - min) for SSIM; text = mean ± std and [min, max]."""
    table = report["seed_spread"]
    rows = list(table)
    columns = report["columns"]
    fig = new_figure(1.9 * len(columns) + 2.5, 2 * (0.75 * len(rows) + 1.2), layout="tight")
    axes = fig.subplots(2, 1)
    for ax, metric in zip(axes, METRICS, strict=True):
        text_values = np.empty((len(rows), len(columns)), dtype=object)
        colour = np.full((len(rows), len(columns)), np.nan)
        for i, row in enumerate(rows):
            for j, column in enumerate(columns):
                cell = table[row][column][metric]
                mean, low, high = _value(cell), _value(cell, "min"), _value(cell, "max")
                width = high - low
                colour[i, j] = 100.0 * width / abs(mean) if metric == "nmae" and mean else width
                digits = 4 if metric == "nmae" else 3
                text = f"{mean:.{digits}f}±{_value(cell, 'std'):.{digits}f}\n[{low:.{digits}f}, {high:.{digits}f}]"
                if cell.get("paper") is not None:
                    text += f"\npaper {cell['paper']:.3f}"
                text_values[i, j] = text
        image = ax.imshow(colour, cmap="Oranges", aspect="auto", vmin=0.0)
        for i in range(len(rows)):
            for j in range(len(columns)):
                ax.text(j, i, text_values[i, j], ha="center", va="center", fontsize=6.5)
        ax.set_xticks(range(len(columns)))
        ax.set_xticklabels([_label(c) for c in columns], fontsize=8, rotation=20)
        ax.set_yticks(range(len(rows)))
        ax.set_yticklabels(rows, fontsize=8)
        label = "(max - min) / mean over seeds (%)" if metric == "nmae" else "max - min over seeds"
        fig.colorbar(image, ax=ax, fraction=0.04, label=label)
        ax.set_title(f"{metric.upper()}: mean ± std [min, max] over seeds, and the paper's value", fontsize=9)
    seeds = report["seeds"]
    fig.suptitle(f"Table I spread over {len(seeds)} seed(s) {seeds} (population std)", fontsize=9)
    return save_figure(fig, path)
