"""``RUN/report.md`` and its figures: Table I beside the paper's, training curves, t-SNE of the latents after the
first and last epoch, and reconstruction examples drawn as taxel maps.
"""

from __future__ import annotations

import json
import logging
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import torch

from unitac_rig.errors import UnitacError
from unitac_rig.learning.contact_geometry import GEOMETRY_JSON, GEOMETRY_PNG
from unitac_rig.learning.data import PairedDataset, object_shape_material
from unitac_rig.learning.engine import UNITAC_GROUP, baseline_name
from unitac_rig.learning.evaluate import (
    FRAME_BASELINE_TEXT,
    PREPROCESSING_TEXT,
    Evaluator,
    direction_name,
    metric_description,
    run_metrics,
)
from unitac_rig.learning.metric_table import alignment_metrics, frame_metrics
from unitac_rig.learning.metrics import latent_mixing
from unitac_rig.learning.paper import PAPER_TABLE1
from unitac_rig.learning.run import METRICS_JSON, LoadedRun, load_run, load_test_set, read_metrics, save_run_files
from unitac_rig.plotting import draw_taxel_map, new_figure, save_figure

log = logging.getLogger(__name__)

REPORT_MD = "report.md"
FIGURES = "figures"
FIGURE_LABELS = {  # file in RUN/figures -> its label in report.md, in the report's order
    "curves.png": "training curves",
    "tsne.png": "t-SNE of the latents",
    "reconstructions_seen.png": "reconstructions (seen)",
    "reconstructions_unseen.png": "reconstructions (unseen)",
    GEOMETRY_PNG: "contact geometry",
}


def table_columns(sensors: tuple[str, ...], trained: set[str]) -> list[str]:
    """Baselines first, then for each source sensor: itself, then the others (the paper's column order)."""
    columns = [baseline_name(s) for s in sensors if baseline_name(s) in trained]
    for source in sensors:
        columns.append(direction_name(source, source))
        columns += [direction_name(source, t) for t in sensors if t != source]
    return columns


def _evaluated(history: list[dict[str, Any]]) -> tuple[str, list[dict[str, Any]]]:
    """("val", records with validation scores), or ("test", ...) for a run that kept no validation rows."""
    validated = [h for h in history if "val" in h]
    if validated:
        return "val", validated
    return "test", [h for h in history if "test" in h]


def plot_curves(history: list[dict[str, Any]], sensors: tuple[str, ...], path: Path) -> Path:
    """Per-epoch validation curves: NMAE per direction and baseline (seen objects' validation angles), the raw
    matched-latent L1 (the paper's), the scale-free matched/unmatched ratio and the sensor mixing."""
    key, evaluated = _evaluated(history)
    subsets = [s for s in ("seen", "unseen") if any(s in h[key] for h in evaluated)]
    # two panels a row, 7 inches wide: readable on a page at 100 % (a 1 x 5 strip's text was tiny there)
    count = len(subsets) + 3
    rows = -(-count // 2)
    fig = new_figure(7.0, 3.1 * rows, layout="constrained")
    grid = fig.subplots(rows, 2, squeeze=False)
    axes = [grid[i // 2][i % 2] for i in range(count)]
    for spare in range(count, rows * 2):
        grid[spare // 2][spare % 2].set_visible(False)
    where = "validation" if key == "val" else "test"
    primary = frame_metrics()[0]  # the table's first frame metric (NMAE) draws the reconstruction curves
    for ax, subset in zip(axes, subsets, strict=False):
        points = [h for h in evaluated if subset in h[key]]
        epochs = [h["epoch"] for h in points]
        for column, value in points[-1][key][subset].items():
            if not isinstance(value, dict):
                continue
            values = [float(np.mean(h[key][subset][column][primary.name])) for h in points]
            style = "--" if column.startswith("ae_") else "-"
            ax.plot(epochs, values, style, label=column.replace("_to_", " → "), lw=1.2)
        ax.set_yscale("log")
        ax.set_xlabel("epoch")
        ax.set_ylabel(f"{where} {primary.label}")
        ax.set_title(f"reconstruction, {subset} objects ({where})", fontsize=10)
        ax.legend(fontsize=8)
        ax.grid(alpha=0.3)
    subset = "all" if any("all" in h[key] for h in evaluated) else (subsets[0] if subsets else "all")
    panels = (
        ("latent_l1", "mean L1 distance", "matched-latent L1 (raw, the paper's)"),
        ("latent_ratio", "matched / unmatched L1", "scale-free alignment (1 = chance, 0 = identical)"),
        ("mixing", "other-sensor share of 10 NN", "sensor mixing of the latents"),
    )
    for ax, (name, ylabel, title) in zip(axes[len(subsets) :], panels, strict=True):
        points = [h for h in evaluated if name in h[key].get(subset, {})]
        if points:
            epochs = [h["epoch"] for h in points]
            per_member = np.array([h[key][subset][name] for h in points], dtype=float)  # (points, members)
            for m in range(per_member.shape[1]):
                ax.plot(epochs, per_member[:, m], color="black", alpha=0.25, lw=0.8)
            ax.plot(epochs, per_member.mean(axis=1), color="black", lw=1.6, label="mean over seeds")
            if name == "mixing":
                expected = [float(np.mean(h[key][subset]["mixing_expected"])) for h in points]
                ax.plot(epochs, expected, "--", color="tab:green", label="perfect mixing")
            if name == "latent_ratio":
                ax.axhline(1.0, ls="--", color="tab:red", lw=1.0, label="chance")
            ax.legend(fontsize=8)
        else:
            ax.text(0.5, 0.5, "not measured in this run", ha="center", va="center", transform=ax.transAxes)
        ax.set_xlabel("epoch")
        ax.set_ylabel(ylabel)
        ax.set_title(f"{title}\n({where} contacts)", fontsize=10)
        ax.grid(alpha=0.3)
    return save_figure(fig, path)


def tsne_embeddings(
    first: dict[str, np.ndarray], last: dict[str, np.ndarray], sensors: list[str], seed: int = 0
) -> dict[str, np.ndarray]:
    """2-D t-SNE (sklearn, PCA init) of the latents after the first and the last epoch; rows: each sensor's
    contacts in ``sensors`` order."""
    from sklearn.manifold import TSNE
    from threadpoolctl import threadpool_limits

    out = {}
    for label, latents in (("first", first), ("last", last)):
        stacked = np.concatenate([latents[s] for s in sensors], axis=0)
        perplexity = float(min(30.0, max(2.0, (len(stacked) - 1) / 3.0)))
        # one BLAS/OpenMP thread: on ~1,200 points the default threads only contend (issue 27: 65 CPU-s of a 71 CPU-s
        # `train --epochs 20` against 4.8 CPU-s with one thread, the same embedding to the 4th decimal of mixing)
        with threadpool_limits(limits=1):
            tsne = TSNE(n_components=2, perplexity=perplexity, init="pca", random_state=seed)
            out[label] = tsne.fit_transform(stacked)
    return out


def embedding_mixing(embedded: np.ndarray, n_sensors: int) -> dict[str, float]:
    """Nearest-neighbour sensor mixing of an embedding whose rows are ``n_sensors`` equal blocks, one per sensor."""
    blocks = np.split(np.asarray(embedded, dtype=np.float64), n_sensors)
    observed, expected = latent_mixing(blocks)
    return {"mixing": observed, "mixing_expected": expected, "mixing_ratio": observed / expected}


def plot_tsne(
    first: dict[str, np.ndarray],
    last: dict[str, np.ndarray],
    test: PairedDataset,
    rows: np.ndarray,
    path: Path,
    seed: int = 0,
    embeddings: dict[str, np.ndarray] | None = None,
) -> Path:
    """t-SNE of the UniTac-NV latents of the same test contacts after the first and the last epoch, coloured by
    sensor, by shape and by material; each row's title gives its nearest-neighbour sensor mixing."""
    sensors = [s for s in test.sensors if s in first and s in last]
    embeddings = embeddings or tsne_embeddings(first, last, sensors, seed)
    labels_shape, labels_material = zip(*(object_shape_material(o) for o in test.object_id[rows]), strict=True)
    colourings = {
        "sensor": np.repeat(np.array(sensors), len(rows)),
        "shape": np.tile(np.array(labels_shape), len(sensors)),
        "material": np.tile(np.array(labels_material), len(sensors)),
    }
    fig = new_figure(14, 9, layout="tight")
    axes = fig.subplots(2, 3)
    for r, (label, key) in enumerate((("after epoch 1", "first"), ("after the last epoch", "last"))):
        embedded = embeddings[key]
        mixing = embedding_mixing(embedded, len(sensors))
        for c, (name, values) in enumerate(colourings.items()):
            ax = axes[r][c]
            for category in sorted(set(values.tolist())):
                pick = values == category
                ax.scatter(embedded[pick, 0], embedded[pick, 1], s=4, alpha=0.6, label=str(category))
            title = f"{label}, by {name}"
            if name == "sensor":
                share, perfect = mixing["mixing"], mixing["mixing_expected"]
                title += f"\nother-sensor share of 10 NN {share:.2f} (perfect {perfect:.2f})"
            ax.set_title(title, fontsize=10)
            ax.set_xticks([])
            ax.set_yticks([])
            ax.legend(fontsize=7, markerscale=3)
    return save_figure(fig, path)


def pick_examples(test: PairedDataset, cross_nmae: np.ndarray, unseen: tuple[str, ...]) -> dict[str, list[int]]:
    """Rows to draw: up to three seen contacts (the first seen object's strongest press at its most negative, middle
    and most positive test angle), and the best and worst unseen contacts by cross-sensor NMAE past 8 N."""
    picks: dict[str, list[int]] = {}
    seen_rows = np.flatnonzero(~np.isin(test.object_id, list(unseen)))
    if seen_rows.size:
        first_object = test.object_id[seen_rows[0]]
        candidates = seen_rows[test.object_id[seen_rows] == first_object]
        angles = np.unique(test.angle_deg[candidates])
        if len(angles) >= 3:  # each angle's strongest contact, at the first, middle and last angle
            at_angles = (
                candidates[test.angle_deg[candidates] == a] for a in (angles[0], angles[len(angles) // 2], angles[-1])
            )
            chosen = [at[np.argmax(test.target_n[at])] for at in at_angles]
        else:  # few test angles (a short sweep): one direction's weakest, middle and strongest contact
            ordered = candidates[np.argsort(test.target_n[candidates], kind="stable")]
            chosen = [ordered[0], ordered[len(ordered) // 2], ordered[-1]]
        picks["seen"] = list(dict.fromkeys(int(row) for row in chosen))
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
    # each sensor's panels side by side (its original, then every sensor's reconstruction of it) and one colour bar
    # per sensor and contact, in the sensor's units
    panels = len(sensors) * (1 + len(sensors))
    fig = new_figure(1.9 * panels + 0.9 * len(sensors), 2.3 * len(rows) + 0.7, layout="constrained")
    axes = fig.subplots(len(rows), panels, squeeze=False)
    index = torch.tensor(rows)
    latents = {s: engine.encode(UNITAC_GROUP, s, evaluator.inputs[s][index]) for s in sensors}
    decoded = {s: engine.decode(UNITAC_GROUP, latents[s]) for s in sensors}
    test = evaluator.dataset
    for r, row in enumerate(rows):
        for k, target in enumerate(sensors):
            frames = [(f"{target} original", test.values[target][row])]
            frames += [
                (f"{source} → {target}", evaluator.to_frames(target, decoded[source][target][0, r]).numpy())
                for source in sensors
            ]
            scale = float(np.abs(test.values[target][row][:, 2]).max() or 1.0)
            # the original's largest shear draws 0.45 pitch long in every panel of that sensor
            shear = float(np.linalg.norm(test.values[target][row][:, :2], axis=1).max() or 1.0)
            group = [axes[r][k * (1 + len(sensors)) + j] for j in range(len(frames))]
            for ax, (label, frame) in zip(group, frames, strict=True):
                mesh = draw_taxel_map(
                    ax,
                    layouts[target],
                    frame,
                    vmin=-0.1 * scale,
                    vmax=scale,
                    title=label,
                    arrow_scale=shear / (0.45 * layouts[target].pitch_mm),
                )
            bar = fig.colorbar(mesh, ax=group, fraction=0.05, pad=0.02, shrink=0.85)
            bar.set_label(f"normal ({layouts[target].units})", fontsize=8)
            bar.ax.tick_params(labelsize=7)
        axes[r][0].set_ylabel(
            f"{test.object_id[row]}\nrot {test.rotation_deg[row]:.0f}°, {test.angle_deg[row]:+.0f}°, "
            f"{test.target_n[row]:.2f} N",
            fontsize=8,
        )
    fig.suptitle(
        f"{title}\ncolour: normal (z) per taxel; arrows: shear (x, y), same scale within a sensor", fontsize=10
    )
    return save_figure(fig, path)


def _cell(value: dict[str, float] | None) -> str:
    """One Table I cell: every frame metric of the table the run scored, in the table's order (NMAE / SSIM)."""
    if value is None:
        return "–"
    return " / ".join(f"{value[m.name]:.3f}" for m in frame_metrics() if m.name in value)


def _paper_cell(row: str, column: str) -> str:
    pair = PAPER_TABLE1.get(row, {}).get(column)
    return "–" if pair is None else f"{pair[0]:.3f} / {pair[1]:.3f}"


def _fmt(value: Any) -> str:
    return "–" if value is None else f"{float(np.mean(value)):.3f}"


def alignment_lines(metrics: dict[str, Any]) -> list[str]:
    """The latent alignment section: raw L1, scale-free ratio and sensor mixing on the test contacts after epoch 1
    and at the end, and the t-SNE's mixing when the figures were drawn."""
    per_subset = metrics.get("alignment", {}).get("per_subset", {})
    if not per_subset:  # one sensor: nothing to align
        return []
    shown = [m for m in alignment_metrics() if any(m.name in entry for entry in per_subset.values())]
    lines = [
        "",
        "## Latent alignment (test contacts, after epoch 1 -> at the end, mean over seeds)",
        "",
        "| contacts | " + " | ".join(m.label for m in shown) + " |",
        "|---|" + "---|" * len(shown),
    ]
    for subset, entry in per_subset.items():
        cells = [
            "–"
            if m.name not in entry
            else _fmt(entry[m.name]["final"])
            if m.reference_for  # a reference value: only where training ended
            else f"{_fmt(entry[m.name]['first_epoch'])} → {_fmt(entry[m.name]['final'])}"
            for m in shown
        ]
        lines.append(f"| {subset} | " + " | ".join(cells) + " |")
    if any("latent_ratio" in entry for entry in per_subset.values()):
        lines += [
            "",
            "Read the alignment by the scale-free ratio (matched / unmatched L1, 1 = chance): the raw matched-latent "
            "L1 (the paper's measure) moves with the latents' scale, so it falls when the latents merely contract "
            "and can rise while matched contacts draw closer than unmatched ones.",
        ]
    tsne = metrics.get("tsne_mixing")
    if tsne:
        lines += [
            "",
            f"t-SNE of {tsne['contacts']} test contacts per sensor: other-sensor share of each point's 10 nearest "
            f"neighbours {tsne['first_epoch']['mixing']:.3f} after epoch 1 and {tsne['last_epoch']['mixing']:.3f} at "
            f"the end (perfect mixing {tsne['last_epoch']['mixing_expected']:.3f}).",
        ]
    return lines


def simple_baseline_lines(metrics: dict[str, Any]) -> list[str]:
    """Table I's simple baselines (fitted on the run's training contacts), with each one's UniTac-NV column."""
    simple = metrics.get("simple_baselines")
    if not simple:
        return []
    columns = list(simple["compared_with"])
    lines = [
        "",
        f"## Simple baselines: {' / '.join(m.label for m in frame_metrics())} on the same test contacts",
        "",
        f"Fitted on the run's {simple['train_rows']} training contacts: "
        + "; ".join(f"{k}: {v}" for k, v in simple["definition"].items())
        + f" (PCA k = {simple['pca_components']}). Compare each with UniTac-NV's column: "
        + ", ".join(f"{c} with {simple['compared_with'][c].replace('_to_', ' → ')}" for c in columns)
        + ".",
        "",
        "| row | " + " | ".join(c.replace("_to_", " → ") for c in columns) + " |",
        "|---|" + "---|" * len(columns),
    ]
    for row, cells in simple["table1"].items():
        lines.append(f"| {row} | " + " | ".join(_cell(cells.get(c)) for c in columns) + " |")
    return lines


def render_markdown(metrics: dict[str, Any], run: LoadedRun, figures: dict[str, str], geometry: dict | None) -> str:
    sensors = tuple(metrics["sensors"])
    table = metrics["table1"]
    described = metrics.get("metrics") or metric_description(run.config.nmae_normaliser, run.config.ssim_range)
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
        f"split seed {run.config.split_seed} ({summary.get('val_rows', 0)} validation rows), "
        f"batch {run.config.batch_size}, Adam lr {run.config.learning_rate}, dropout {run.config.shape.dropout}, "
        f"widths {list(run.config.shape.encoder_hidden)} / {run.config.shape.latent_dim} / "
        f"{list(run.config.shape.decoder_hidden)}"
        + (f", alignment term {run.config.shape.align_weight}" if run.config.shape.align_weight else ""),
        f"- preprocessing: {PREPROCESSING_TEXT[run.config.preprocessing]} (`{run.config.preprocessing}`); frames "
        f"referenced to {FRAME_BASELINE_TEXT[run.config.frame_baseline]} (`{run.config.frame_baseline}`)",
        f"- unitac-rig {prov.get('package_version', '?')}, commit `{str(prov.get('git_commit', '?'))[:12]}`, "
        f"torch {prov.get('torch_version', '?')}",
        "",
        f"## Table I: {' / '.join(m.label for m in frame_metrics())} on the test set (ours, then the paper's)",
        "",
        f"NMAE (`{described['nmae_normaliser']}`): {described['nmae']}. SSIM (`{described['ssim_range']}`): "
        f"{described['ssim']}. "
        + "".join(f"{m.label}: {m.description} ({m.units}). " for m in frame_metrics() if m.option is None)
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
    lines += simple_baseline_lines(metrics)
    lines += alignment_lines(metrics)
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
    run_dir: Path,
    *,
    run: LoadedRun | None = None,
    test: PairedDataset | None = None,
    figures: bool = True,
    nmae_normaliser: str | None = None,
    ssim_range: str | None = None,
    on_stage: Callable[[str], None] | None = None,
) -> Path:
    """metrics.json (recomputed), the figures and report.md for a run directory; the metric options default to the
    run's own. ``on_stage`` hears what each step (seconds to minutes on a small machine) is about to do."""
    stage = on_stage or (lambda message: None)
    run_dir = Path(run_dir)
    stage("loading the run and its test set")
    run = (run or load_run(run_dir)).scored_under(nmae_normaliser, ssim_range)
    test = test or load_test_set(run_dir)
    stage(f"scoring {len(test)} test contacts (metrics.json)")
    kept = (read_metrics(run_dir) or {}).get("tsne_mixing")
    metrics = run_metrics(run_dir, run, test)  # written with report.md at the end: an interrupted report keeps both
    if kept and not figures:  # the t-SNE is only recomputed with the figures
        metrics["tsne_mixing"] = kept
    drawn: set[str] = set()  # figures drawn now, by file name
    if figures:
        fig_dir = run_dir / FIGURES
        stage("drawing the training curves")
        plot_curves(run.history, run.sensors, fig_dir / "curves.png")
        drawn.add("curves.png")
        evaluator = Evaluator.for_run(run, test)
        first = run.payload.get("latents_first_epoch")
        rows = np.asarray(run.payload.get("tsne_rows", []), dtype=int)
        if first is not None and rows.size >= 10:
            stage(f"t-SNE of {rows.size} contacts' latents, first and last epoch (the slowest step)")
            latents = evaluator.latents(run.engine)
            last = {s: z[0, rows].numpy() for s, z in latents.items()}
            sensors = [s for s in test.sensors if s in first and s in last]
            embeddings = tsne_embeddings(first, last, sensors, seed=run.config.split_seed)
            plot_tsne(first, last, test, rows, fig_dir / "tsne.png", seed=run.config.split_seed, embeddings=embeddings)
            drawn.add("tsne.png")
            metrics["tsne_mixing"] = {
                "contacts": int(rows.size),
                "member": 0,
                "first_epoch": embedding_mixing(embeddings["first"], len(sensors)),
                "last_epoch": embedding_mixing(embeddings["last"], len(sensors)),
            }
        stage("drawing example reconstructions")
        scores = evaluator.per_frame(run.engine.member(0, groups=[UNITAC_GROUP]))
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
                drawn.add(path_or_none.name)
    shown = {  # without figures, those an earlier report drew; the geometry figure is `unitac-rig geometry`'s
        label: f"{FIGURES}/{name}"
        for name, label in FIGURE_LABELS.items()
        if name in drawn or ((not figures or name == GEOMETRY_PNG) and (run_dir / FIGURES / name).exists())
    }
    geometry_path = run_dir / GEOMETRY_JSON
    geometry = json.loads(geometry_path.read_text(encoding="utf-8")) if geometry_path.exists() else None
    stage("writing metrics.json and report.md")
    text = render_markdown(metrics, run, shown, geometry)
    save_run_files(run_dir, {METRICS_JSON: metrics, REPORT_MD: text})
    return run_dir / REPORT_MD


__all__ = ["REPORT_MD", "write_report"]
