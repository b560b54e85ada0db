"""``RUN/report.md`` and its figures: Table I beside the paper's, training curves, t-SNE of the latents after the
first and last epoch, and reconstruction examples drawn as taxel maps.
"""

from __future__ import annotations

import json
import logging
from pathlib import Path
from typing import Any

import numpy as np
import torch

from unitac_rig.errors import UnitacError
from unitac_rig.learning.contact_geometry import GEOMETRY_JSON
from unitac_rig.learning.data import PairedDataset, object_shape_material
from unitac_rig.learning.engine import UNITAC_GROUP, baseline_name
from unitac_rig.learning.evaluate import METRICS_JSON, write_metrics
from unitac_rig.learning.paper import PAPER_TABLE1
from unitac_rig.learning.train import Evaluator, LoadedRun, direction_name, load_run, load_test_set
from unitac_rig.plotting import draw_taxel_map, new_figure, save_figure

log = logging.getLogger(__name__)

REPORT_MD = "report.md"
FIGURES = "figures"


def table_columns(sensors: tuple[str, ...], trained: set[str]) -> list[str]:
    """Baselines first, then for each source sensor: itself, then the others (the paper's column order)."""
    columns = [baseline_name(s) for s in sensors if baseline_name(s) in trained]
    for source in sensors:
        columns.append(direction_name(source, source))
        columns += [direction_name(source, t) for t in sensors if t != source]
    return columns


def plot_curves(history: list[dict[str, Any]], sensors: tuple[str, ...], path: Path) -> Path:
    """Test NMAE per direction (seen objects' held-out angles, unseen objects) and latent L1 against epoch."""
    evaluated = [h for h in history if "test" in h]
    subsets = [s for s in ("seen", "unseen") if any(s in h["test"] for h in evaluated)]
    fig = new_figure(5.2 * (len(subsets) + 1), 4.0, layout="tight")
    axes = fig.subplots(1, len(subsets) + 1, squeeze=False)
    for ax, subset in zip(axes[0], subsets, strict=False):
        points = [h for h in evaluated if subset in h["test"]]
        epochs = [h["epoch"] for h in points]
        for column in points[-1]["test"][subset]:
            if column == "latent_l1":
                continue
            values = [float(np.mean(h["test"][subset][column]["nmae"])) for h in points]
            style = "--" if column.startswith("ae_") else "-"
            ax.plot(epochs, values, style, label=column.replace("_to_", " → "), lw=1.2)
        ax.set_yscale("log")
        ax.set_xlabel("epoch")
        ax.set_ylabel("test NMAE")
        ax.set_title(f"reconstruction, {subset} objects")
        ax.legend(fontsize=7)
        ax.grid(alpha=0.3)
    ax = axes[0][-1]
    points = [h for h in evaluated if "latent_l1" in h["test"].get("all", {})]
    if points:
        ax.plot(
            [h["epoch"] for h in points], [float(np.mean(h["test"]["all"]["latent_l1"])) for h in points], color="black"
        )
    ax.set_xlabel("epoch")
    ax.set_ylabel("mean L1 distance")
    ax.set_title("latent distance between matched contacts")
    ax.grid(alpha=0.3)
    return save_figure(fig, path)


def plot_tsne(
    first: dict[str, np.ndarray],
    last: dict[str, np.ndarray],
    test: PairedDataset,
    rows: np.ndarray,
    path: Path,
    seed: int = 0,
) -> Path:
    """t-SNE of the UniTac-NV latents of the same test contacts after the first and the last epoch, coloured by
    sensor, by shape and by material."""
    from sklearn.manifold import TSNE

    sensors = [s for s in test.sensors if s in first and s in last]
    labels_shape, labels_material = zip(*(object_shape_material(o) for o in test.object_id[rows]), strict=True)
    colourings = {
        "sensor": np.repeat(np.array(sensors), len(rows)),
        "shape": np.tile(np.array(labels_shape), len(sensors)),
        "material": np.tile(np.array(labels_material), len(sensors)),
    }
    fig = new_figure(14, 9, layout="tight")
    axes = fig.subplots(2, 3)
    for r, (label, latents) in enumerate((("after epoch 1", first), ("after the last epoch", last))):
        stacked = np.concatenate([latents[s] for s in sensors], axis=0)
        perplexity = float(min(30.0, max(2.0, (len(stacked) - 1) / 3.0)))
        embedded = TSNE(n_components=2, perplexity=perplexity, init="pca", random_state=seed).fit_transform(stacked)
        for c, (name, values) in enumerate(colourings.items()):
            ax = axes[r][c]
            for category in sorted(set(values.tolist())):
                pick = values == category
                ax.scatter(embedded[pick, 0], embedded[pick, 1], s=4, alpha=0.6, label=str(category))
            ax.set_title(f"{label}, by {name}", fontsize=10)
            ax.set_xticks([])
            ax.set_yticks([])
            ax.legend(fontsize=7, markerscale=3)
    return save_figure(fig, path)


def pick_examples(test: PairedDataset, cross_nmae: np.ndarray, unseen: tuple[str, ...]) -> dict[str, list[int]]:
    """Rows to draw: one seen contact (strongest target of the first seen object, mid angle), and the best and
    worst unseen contacts by cross-sensor NMAE among presses past 8 N."""
    picks: dict[str, list[int]] = {}
    seen_rows = np.flatnonzero(~np.isin(test.object_id, list(unseen)))
    if seen_rows.size:
        first_object = test.object_id[seen_rows[0]]
        candidates = seen_rows[test.object_id[seen_rows] == first_object]
        strongest = candidates[test.target_n[candidates] == test.target_n[candidates].max()]
        picks["seen"] = [int(strongest[np.argmin(np.abs(test.angle_deg[strongest]))])]
    unseen_rows = np.flatnonzero(np.isin(test.object_id, list(unseen)) & (test.target_n >= 8.0))
    if unseen_rows.size:
        order = unseen_rows[np.argsort(cross_nmae[unseen_rows])]
        picks["unseen"] = [int(order[0]), int(order[-1])]
    return picks


def plot_reconstructions(run: LoadedRun, evaluator: Evaluator, rows: list[int], path: Path, title: str) -> Path | None:
    """One line of taxel maps per contact: each sensor's original, then every source -> target reconstruction."""
    from unitac_rig.rig.sensors import sensor_layout

    try:
        layouts = {s: sensor_layout(s) for s in run.sensors}
    except UnitacError:
        log.info("reconstruction figure skipped: a sensor of this run has no registered layout")
        return None
    sensors = run.sensors
    engine = run.engine.member(0, groups=[UNITAC_GROUP])
    panels = len(sensors) + len(sensors) ** 2
    fig = new_figure(2.6 * panels, 2.9 * len(rows), layout="tight")
    axes = fig.subplots(len(rows), panels, squeeze=False)
    index = torch.tensor(rows)
    latents = {s: engine.encode(UNITAC_GROUP, s, evaluator.inputs[s][index]) for s in sensors}
    decoded = {s: engine.decode(UNITAC_GROUP, latents[s]) for s in sensors}
    test = evaluator.dataset
    for r, row in enumerate(rows):
        frames: list[tuple[str, str, np.ndarray]] = []
        for s in sensors:
            frames.append((s, f"{s} original", test.values[s][row]))
        for source in sensors:
            for target in sensors:
                estimate = evaluator.to_frames(target, decoded[source][target][0, r]).numpy()
                frames.append((target, f"{source} → {target}", estimate))
        scale = {s: float(np.abs(test.values[s][row][:, 2]).max() or 1.0) for s in sensors}
        for c, (sensor, label, frame) in enumerate(frames):
            # the original's largest shear draws 0.45 pitch long in every panel of that sensor
            shear = float(np.linalg.norm(test.values[sensor][row][:, :2], axis=1).max() or 1.0)
            draw_taxel_map(
                axes[r][c],
                layouts[sensor],
                frame,
                vmin=-0.1 * scale[sensor],
                vmax=scale[sensor],
                title=label,
                arrow_scale=shear / (0.45 * layouts[sensor].pitch_mm),
            )
        axes[r][0].set_ylabel(
            f"{test.object_id[row]}\nrot {test.rotation_deg[row]:.0f}°, {test.angle_deg[row]:+.0f}°, "
            f"{test.target_n[row]:.2f} N",
            fontsize=8,
        )
    fig.suptitle(title)
    return save_figure(fig, path)


def _cell(value: dict[str, float] | None) -> str:
    return "–" if value is None else f"{value['nmae']:.3f} / {value['ssim']:.3f}"


def _paper_cell(row: str, column: str) -> str:
    pair = PAPER_TABLE1.get(row, {}).get(column)
    return "–" if pair is None else f"{pair[0]:.3f} / {pair[1]:.3f}"


def render_markdown(metrics: dict[str, Any], run: LoadedRun, figures: dict[str, str], geometry: dict | None) -> str:
    sensors = tuple(metrics["sensors"])
    table = metrics["table1"]
    trained = {column for row in table.values() for column in row}
    columns = table_columns(sensors, trained)
    summary = run.payload.get("dataset_summary", {})
    prov = metrics.get("provenance", {})
    lines = [
        "# UniTac-NV run report",
        "",
        f"- data: {summary.get('rows', '?')} joined contacts ({summary.get('train_rows', '?')} train, "
        f"{summary.get('test_rows', '?')} test), sensors {', '.join(sensors)}, "
        f"{'simulated' if metrics.get('simulated') else 'recorded'}; dataset hash `{metrics['dataset_hash'][:16]}`",
        f"- training: {metrics['epochs']} epochs, {metrics['train_seconds']:.1f} s, seeds {metrics['seeds']}, "
        f"batch {run.config.batch_size}, Adam lr {run.config.learning_rate}, dropout {run.config.shape.dropout}",
        f"- unitac-rig {prov.get('package_version', '?')}, commit `{str(prov.get('git_commit', '?'))[:12]}`, "
        f"torch {prov.get('torch_version', '?')}",
        "",
        "## Table I: NMAE / SSIM on the test set (ours, then the paper's)",
        "",
        "NMAE normaliser: each sensor channel's range (max - min) over the training frames; SSIM with global grid "
        "statistics per channel, C1 = (0.01 R)^2, C2 = (0.03 R)^2, averaged over x, y, z. "
        + ("Values are means over the run's seeds." if len(metrics["seeds"]) > 1 else ""),
        "",
        "| row | contacts | " + " | ".join(c.replace("_to_", " → ") for c in columns) + " |",
        "|---|---:|" + "---|" * len(columns),
    ]
    for row, cells in table.items():
        ours = " | ".join(_cell(cells.get(c)) for c in columns)
        lines.append(f"| {row} | {metrics['test_rows'][row]} | {ours} |")
        if row in PAPER_TABLE1:
            lines.append("| *paper* | | " + " | ".join(_paper_cell(row, c) for c in columns) + " |")
    latent = metrics["latent_l1"]
    if latent["final"] is not None:
        lines += [
            "",
            "## Latent alignment",
            "",
            f"Mean Manhattan distance between matched test latents: {latent['first_epoch']:.3f} after epoch 1, "
            f"{latent['final']:.3f} after epoch {metrics['epochs']}.",
        ]
    if geometry:
        lines += [
            "",
            f"## Contact geometry on {geometry['object']} (mean profile error, mm)",
            "",
            "| train → test | ours | paper |",
            "|---|---:|---:|",
        ]
        for s in geometry["scenarios"].values():
            paper = "–" if s.get("paper_mae_mm") is None else f"{s['paper_mae_mm']:.3f}"
            lines.append(f"| {s['train_sensor']} → {s['test_sensor']} | {s['mae_mm']:.3f} | {paper} |")
    if figures:
        lines += ["", "## Figures", ""]
        lines += [f"- {label}: ![{label}]({rel})" for label, rel in figures.items()]
    lines.append("")
    return "\n".join(lines)


def write_report(
    run_dir: Path, *, run: LoadedRun | None = None, test: PairedDataset | None = None, figures: bool = True
) -> Path:
    """metrics.json (recomputed), the figures and report.md for a run directory."""
    run_dir = Path(run_dir)
    run = run or load_run(run_dir)
    test = test or load_test_set(run_dir)
    metrics = write_metrics(run_dir, run, test)
    drawn: dict[str, str] = {}
    if figures:
        fig_dir = run_dir / FIGURES
        drawn["training curves"] = _rel(plot_curves(run.history, run.sensors, fig_dir / "curves.png"), run_dir)
        evaluator = Evaluator(test, run.normaliser, run.unseen_objects, torch.device("cpu"))
        first = run.payload.get("latents_first_epoch")
        rows = np.asarray(run.payload.get("tsne_rows", []), dtype=int)
        if first is not None and rows.size >= 10:
            latents = evaluator.latents(run.engine)
            last = {s: z[0, rows].numpy() for s, z in latents.items()}
            path = plot_tsne(first, last, test, rows, fig_dir / "tsne.png", seed=run.config.split_seed)
            drawn["t-SNE of the latents"] = _rel(path, run_dir)
        scores, _ = evaluator.per_frame(run.engine.member(0, groups=[UNITAC_GROUP]))
        cross = [direction_name(a, b) for a in run.sensors for b in run.sensors if a != b]
        cross_nmae = torch.stack([scores[c]["nmae"][0] for c in cross]).mean(dim=0).numpy()
        for subset, rows_picked in pick_examples(test, cross_nmae, run.unseen_objects).items():
            try:
                title = "seen object (held-out angle)" if subset == "seen" else "unseen object: best and worst"
                path_or_none = plot_reconstructions(
                    run, evaluator, rows_picked, fig_dir / f"reconstructions_{subset}.png", f"Reconstructions, {title}"
                )
            except ImportError:
                log.warning("reconstruction figures need unitac_rig.plotting, which is not installed")
                break
            if path_or_none is not None:
                drawn[f"reconstructions ({subset})"] = _rel(path_or_none, run_dir)
    else:  # keep the figures an earlier report drew
        known = {
            "curves.png": "training curves",
            "tsne.png": "t-SNE of the latents",
            "reconstructions_seen.png": "reconstructions (seen)",
            "reconstructions_unseen.png": "reconstructions (unseen)",
        }
        for name, label in known.items():
            if (run_dir / FIGURES / name).exists():
                drawn[label] = f"{FIGURES}/{name}"
    geometry_png = run_dir / FIGURES / "geometry.png"
    if geometry_png.exists():
        drawn["contact geometry"] = f"{FIGURES}/geometry.png"
    geometry_path = run_dir / GEOMETRY_JSON
    geometry = json.loads(geometry_path.read_text(encoding="utf-8")) if geometry_path.exists() else None
    report = run_dir / REPORT_MD
    report.write_text(render_markdown(metrics, run, drawn, geometry), encoding="utf-8")
    return report


def _rel(path: Path, root: Path) -> str:
    return str(Path(path).relative_to(root))


__all__ = ["METRICS_JSON", "REPORT_MD", "write_report"]
