"""Reproduce the paper's results on a dataset over several splits and seeds, and write docs/results.md.

For each split seed (``--splits 3``: split seeds 0, 1, 2) one batched run trains UniTac-NV and both per-sensor
baselines for every model seed (``--seeds 5``: seeds 0..4) under the same config (paper hyper-parameters by default,
or ``--config FILE.toml``), then writes that run's metrics, report and figures and runs the contact-geometry task for
every member: the paper's heads (one per training sensor) and, beyond the paper, one head trained on both sensors'
latents. Runs already finished under ``--out`` are reused and unfinished ones resumed, so an interrupted
reproduction continues where it stopped.

docs/results.md then gets Table I as mean +- std over all seeds and splits beside the paper's, the split-to-split
and seed-to-seed spread, each headline claim marked reproduced or not with its measurement, the alignment curves
(raw and scale-free) over epochs, the t-SNE after the first and last epoch with its sensor mixing, geometry errors
beside the paper's, and the beyond-the-paper charts that ``benchmarks/beyond_paper.py`` wrote (if present). The
text between ``<!-- generated:start -->`` and ``<!-- generated:end -->`` is the script's; the rest of the file
(hand-written comparison) is kept.

    python benchmarks/run_results.py --data DATA [--out runs/results] [--seeds 5] [--splits 3] [--epochs 1000]
        [--eval-every 10] [--config FILE.toml] [--only-split K] [--report-only]
"""

from __future__ import annotations

import argparse
import json
import shutil
import time
from pathlib import Path
from typing import Any

import numpy as np

from unitac_rig.learning.config import load_config
from unitac_rig.learning.contact_geometry import geometry_for_run, run_geometry
from unitac_rig.learning.data import build_paired_dataset, load_sets
from unitac_rig.learning.evaluate import PREPROCESSING_TEXT, metric_description
from unitac_rig.learning.paper import PAPER_GEOMETRY_MAE_MM, PAPER_TABLE1
from unitac_rig.learning.pooled_geometry import pooled_geometry
from unitac_rig.learning.report import table_columns, write_report
from unitac_rig.learning.run import checkpoint_path
from unitac_rig.learning.train import TrainConfig, load_run, load_test_set, train
from unitac_rig.plotting import new_figure, save_figure

ROOT = Path(__file__).resolve().parent.parent
START, END = "<!-- generated:start -->", "<!-- generated:end -->"
GEOMETRY_MEMBERS = "geometry_members.json"
SEEN_DIRECTIONS = ("uskin_to_uskin", "uskin_to_papillarray", "papillarray_to_papillarray", "papillarray_to_uskin")
MIXED_ENOUGH = 0.5  # "interleaved": the other-sensor share of 10 NN is at least half its perfect-mixing value


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--data", type=Path, required=True)
    parser.add_argument("--out", type=Path, default=ROOT / "runs" / "results")
    parser.add_argument("--seeds", type=int, default=5, help="model seeds 0..N-1, trained together per split")
    parser.add_argument("--splits", type=int, default=3, help="split seeds 0..N-1, one run each")
    parser.add_argument("--epochs", type=int, default=1000)
    parser.add_argument("--eval-every", type=int, default=10, help="epochs between validation evaluations")
    parser.add_argument("--config", type=Path, default=None, help="TOML training config (docs/learning.md)")
    parser.add_argument("--report-only", action="store_true", help="only re-render from finished runs")
    parser.add_argument(
        "--only-split",
        type=int,
        action="append",
        default=None,
        help="train only this split seed (repeatable; "
        "several processes can share --out); the page is written once every split has finished",
    )
    parser.add_argument("--nmae-normaliser", default=None, help="score every run under this NMAE normaliser")
    parser.add_argument("--ssim-range", default=None, help="score every run under this SSIM range")
    parser.add_argument("--docs", type=Path, default=ROOT / "docs")
    args = parser.parse_args()

    flat = load_config(args.config) if args.config else {}
    base = TrainConfig().updated(
        {"eval_every": args.eval_every, **flat, "epochs": args.epochs, "seeds": tuple(range(args.seeds))}
    )
    dataset = None if args.report_only else build_paired_dataset(load_sets(args.data))
    if dataset is not None:
        print(f"{len(dataset)} pairs, sensors {dataset.sensors}, objects {dataset.objects}", flush=True)
    for split_seed in range(args.splits):
        if dataset is not None and (args.only_split is None or split_seed in args.only_split):
            run_split(dataset, args.out / f"split-{split_seed}", base.updated({"split_seed": split_seed}))
    unfinished = [k for k in range(args.splits) if not (args.out / f"split-{k}" / GEOMETRY_MEMBERS).exists()]
    if unfinished:
        print(f"splits {unfinished} not finished yet: results.md not written")
        return
    if args.nmae_normaliser or args.ssim_range:  # re-score the finished runs (no weight changes)
        for k in range(args.splits):
            write_report(
                args.out / f"split-{k}",
                figures=False,
                nmae_normaliser=args.nmae_normaliser,
                ssim_range=args.ssim_range,
            )
    splits = [collect_split(args.out / f"split-{k}", args.nmae_normaliser, args.ssim_range) for k in range(args.splits)]
    figures = draw_figures(splits, args.out, args.docs / "figures")
    text = render(splits, figures, args, base)
    write_results(args.docs / "results.md", text)
    print(f"wrote {args.docs / 'results.md'}")


def run_split(dataset: Any, run_dir: Path, config: TrainConfig) -> None:
    """Train (or resume, or reuse) one split's run; report, geometry per member (paper heads and pooled head)."""
    began = time.perf_counter()
    if checkpoint_path(run_dir).exists():
        done = int(load_run(run_dir).payload["epoch"])
        if done < config.epochs:
            print(f"{run_dir.name}: resuming at epoch {done}", flush=True)
            train(dataset, run_dir, None, resume=True, epochs=config.epochs, progress=_progress(run_dir))
        elif (run_dir / GEOMETRY_MEMBERS).exists():
            print(f"{run_dir.name}: finished, reused", flush=True)
            return
    else:
        train(dataset, run_dir, config, progress=_progress(run_dir))
    train_wall = time.perf_counter() - began
    run, test = load_run(run_dir), load_test_set(run_dir)
    report_began = time.perf_counter()
    write_report(run_dir, run=run, test=test)
    report_s = time.perf_counter() - report_began
    geometry_began = time.perf_counter()
    paper_heads, pooled = [], []
    for member in range(run.engine.members):
        head_began = time.perf_counter()
        result = run_geometry(run, test, member=member)
        paper_heads.append({"scenarios": result.scenarios, "seconds": time.perf_counter() - head_began})
        pooled.append(pooled_geometry(run, test, member=member))
    geometry_for_run(run_dir)  # member 0: geometry.json and the outline figure
    write_report(run_dir, run=run, test=test, figures=False)
    record = {
        "paper_heads": paper_heads,
        "pooled_head": pooled,
        "seconds": {
            "train_wall": train_wall,
            "report": report_s,
            "geometry": time.perf_counter() - geometry_began,
        },
    }
    (run_dir / GEOMETRY_MEMBERS).write_text(json.dumps(record, indent=2) + "\n", encoding="utf-8")
    print(f"{run_dir.name}: done in {(time.perf_counter() - began) / 60:.1f} min", flush=True)


def _progress(run_dir: Path) -> Any:
    def report(record: dict[str, Any]) -> None:
        if record["epoch"] % 50 == 0 or record["epoch"] == 1:
            print(f"{run_dir.name} epoch {record['epoch']}: {record['seconds']:.0f} s train", flush=True)

    return report


def collect_split(run_dir: Path, nmae_normaliser: str | None = None, ssim_range: str | None = None) -> dict[str, Any]:
    """What the results page needs from one finished split run (scored under the given metric options)."""
    metrics = json.loads((run_dir / "metrics.json").read_text(encoding="utf-8"))
    geometry = json.loads((run_dir / GEOMETRY_MEMBERS).read_text(encoding="utf-8"))
    run = load_run(run_dir).scored_under(nmae_normaliser, ssim_range)
    return {
        "dir": run_dir,
        "metrics": metrics,
        "geometry": geometry,
        "history": run.history,
        "config": run.config,
        "summary": run.payload.get("dataset_summary", {}),
    }


# ---- aggregation ---------------------------------------------------------------------------------------------


def members(splits: list[dict[str, Any]], row: str, column: str, metric: str) -> np.ndarray:
    """Every (split, seed) member's value of one Table I cell."""
    values: list[float] = []
    for split in splits:
        m = split["metrics"]
        per_member = m.get("table1_members", {}).get(row, {}).get(column, {}).get(metric)
        values += per_member if per_member is not None else [m["table1"][row][column][metric]]
    return np.asarray(values, dtype=float)


def split_means(splits: list[dict[str, Any]], row: str, column: str, metric: str) -> np.ndarray:
    return np.asarray([s["metrics"]["table1"][row][column][metric] for s in splits], dtype=float)


def alignment_values(splits: list[dict[str, Any]], subset: str, key: str, when: str) -> np.ndarray:
    """Per member (all splits), one alignment measure on the test contacts after epoch 1 or at the end."""
    values: list[float] = []
    for split in splits:
        entry = split["metrics"]["alignment"]["per_subset"].get(subset, {}).get(key, {}).get(when)
        if entry is not None:
            values += list(entry)
    return np.asarray(values, dtype=float)


def geometry_values(splits: list[dict[str, Any]], scenario: str) -> np.ndarray:
    values = []
    for split in splits:
        for head in split["geometry"]["paper_heads"] + split["geometry"]["pooled_head"]:
            if scenario in head["scenarios"]:
                values.append(head["scenarios"][scenario]["mae_mm"])
    return np.asarray(values, dtype=float)


def _pm(values: np.ndarray, digits: int = 3) -> str:
    return f"{values.mean():.{digits}f} ± {values.std():.{digits}f}"


# ---- claims --------------------------------------------------------------------------------------------------


def claims(splits: list[dict[str, Any]]) -> list[tuple[str, bool, str]]:
    """(claim, reproduced?, the measurement) for each headline claim of the paper."""
    out = []
    seen_ssim = {d: members(splits, "all_seen", d, "ssim") for d in SEEN_DIRECTIONS}
    worst = min(seen_ssim, key=lambda d: seen_ssim[d].mean())
    ok = all(v.mean() > 0.95 for v in seen_ssim.values())
    every = all((v > 0.95).all() for v in seen_ssim.values())
    out.append(
        (
            "Seen objects: SSIM > 0.95 in all four directions",
            ok,
            "all-seen SSIM "
            + ", ".join(f"{_arrow(d)} {seen_ssim[d].mean():.3f} (min {seen_ssim[d].min():.3f})" for d in seen_ssim)
            + f"; lowest {_arrow(worst)}; "
            + ("every member above 0.95" if every else "not every member above 0.95"),
        )
    )
    seen_nmae = {d: members(splits, "all_seen", d, "nmae") for d in SEEN_DIRECTIONS}
    hardest_nmae = max(seen_nmae, key=lambda d: seen_nmae[d].mean())
    hardest_ssim = min(seen_ssim, key=lambda d: seen_ssim[d].mean())
    target = "papillarray_to_uskin"
    out.append(
        (
            "PapillArray → uSkin is the hardest direction on seen objects",
            hardest_nmae == target and hardest_ssim == target,
            f"highest all-seen NMAE: {_arrow(hardest_nmae)} ({seen_nmae[hardest_nmae].mean():.3f}); lowest SSIM: "
            f"{_arrow(hardest_ssim)} ({seen_ssim[hardest_ssim].mean():.3f}); PapillArray → uSkin "
            f"{seen_nmae[target].mean():.3f} / {seen_ssim[target].mean():.3f}",
        )
    )
    rows = list(splits[0]["metrics"]["table1"])
    unseen_rows = rows[rows.index("all_seen") + 1 :] if "all_seen" in rows else []  # the table's order
    if unseen_rows:
        row = unseen_rows[0]
        columns = list(splits[0]["metrics"]["table1"]["all_seen"])
        worse = [
            c
            for c in columns
            if members(splits, row, c, "nmae").mean() > members(splits, "all_seen", c, "nmae").mean()
            and members(splits, row, c, "ssim").mean() < members(splits, "all_seen", c, "ssim").mean()
        ]
        out.append(
            (
                "The unseen object reconstructs worse than the seen ones",
                len(worse) == len(columns),
                f"{row} worse than all-seen in NMAE and SSIM for {len(worse)} of {len(columns)} columns"
                + (
                    ""
                    if len(worse) == len(columns)
                    else f" (not: {', '.join(_arrow(c) for c in columns if c not in worse)})"
                ),
            )
        )
    first = alignment_values(splits, "all", "latent_l1", "first_epoch")
    final = alignment_values(splits, "all", "latent_l1", "final")
    ratio_first = alignment_values(splits, "all", "latent_ratio", "first_epoch")
    ratio_final = alignment_values(splits, "all", "latent_ratio", "final")
    falls = int((final < first).sum())
    out.append(
        (
            "The raw matched-latent distance falls from epoch 1 to the end",
            falls == len(first),
            f"test matched-latent L1 {first.mean():.3f} after epoch 1 → {final.mean():.3f} at the end; falls in "
            f"{falls} of {len(first)} members. Scale-free (matched / unmatched L1): {ratio_first.mean():.3f} → "
            f"{ratio_final.mean():.3f}",
        )
    )
    tsne_first = [s["metrics"].get("tsne_mixing", {}).get("first_epoch") for s in splits]
    tsne_last = [s["metrics"].get("tsne_mixing", {}).get("last_epoch") for s in splits]
    mix_first = alignment_values(splits, "all", "mixing", "first_epoch")
    mix_final = alignment_values(splits, "all", "mixing", "final")
    expected = alignment_values(splits, "all", "mixing_expected", "final")
    tsne_ok = all(t is not None for t in tsne_last) and all(
        t["mixing"] >= MIXED_ENOUGH * t["mixing_expected"] and t["mixing"] > f["mixing"]
        for t, f in zip(tsne_last, tsne_first, strict=True)
        if t is not None and f is not None
    )
    tsne_text = ", ".join(
        f"{f['mixing']:.2f} → {t['mixing']:.2f}"
        for t, f in zip(tsne_last, tsne_first, strict=True)
        if t is not None and f is not None
    )
    out.append(
        (
            "After training the t-SNE interleaves the sensors",
            tsne_ok,
            f"other-sensor share of each point's 10 nearest neighbours in the t-SNE (member 0 of each split, "
            f"after epoch 1 → at the end): {tsne_text} (perfect mixing ≈ {expected.mean():.2f}; criterion ≥ "
            f"{MIXED_ENOUGH:.0%} of perfect and rising). In the 16-d latents, all test contacts, all members: "
            f"{mix_first.mean():.3f} → {mix_final.mean():.3f}",
        )
    )
    found = []
    ok = True
    for scenario, paper in PAPER_GEOMETRY_MAE_MM.items():
        values = geometry_values(splits, scenario)
        if values.size:
            ok &= bool(values.mean() <= paper)
            found.append(f"{_arrow(scenario)} {values.mean():.3f} (paper {paper:.3f})")
    out.append(("Contact geometry at or below the paper's in all four scenarios", ok, "; ".join(found) + " mm"))
    return out


def _arrow(name: str) -> str:
    return name.replace("_to_", " → ")


# ---- figures -------------------------------------------------------------------------------------------------


def draw_figures(splits: list[dict[str, Any]], out: Path, target: Path) -> dict[str, str]:
    """The alignment curves over all splits and seeds, plus split 0's run figures, copied under docs/figures."""
    target.mkdir(parents=True, exist_ok=True)
    figures = {"alignment": _rel(plot_alignment(splits, target / "results_alignment.png"))}
    figures["validation curves"] = _rel(plot_validation_nmae(splits, target / "results_curves.png"))
    first = splits[0]["dir"] / "figures"
    for name in ("tsne", "reconstructions_seen", "reconstructions_unseen", "geometry"):
        source = first / f"{name}.png"
        if source.exists():
            shutil.copyfile(source, target / f"results_{name}.png")
            figures[name] = f"figures/results_{name}.png"
    return figures


def _rel(path: Path) -> str:
    return f"figures/{path.name}"


def _curve(splits: list[dict[str, Any]], key: str) -> tuple[np.ndarray, np.ndarray]:
    """(epochs, values (points, members over all splits)) of one validation alignment measure on all contacts."""
    per_split = []
    for split in splits:
        points = [h for h in split["history"] if key in h.get("val", {}).get("all", {})]
        per_split.append({h["epoch"]: h["val"]["all"][key] for h in points})
    epochs = sorted(set.intersection(*(set(p) for p in per_split)))
    values = np.array([[v for p in per_split for v in p[e]] for e in epochs], dtype=float)
    return np.asarray(epochs), values


def plot_alignment(splits: list[dict[str, Any]], path: Path) -> Path:
    """Validation alignment per epoch, all seeds and splits: raw L1 (the paper's measure), the scale-free ratio and
    the sensor mixing; thin lines are members, the thick line their mean."""
    fig = new_figure(15, 4.2, layout="tight")
    axes = fig.subplots(1, 3)
    panels = (
        ("latent_l1", "matched-latent L1 (raw, the paper's)", "mean L1 distance"),
        ("latent_ratio", "matched / unmatched L1 (scale-free)", "ratio (1 = chance)"),
        ("mixing", "sensor mixing: other-sensor share of 10 NN", "share"),
    )
    for ax, (key, title, ylabel) in zip(axes, panels, strict=True):
        epochs, values = _curve(splits, key)
        if len(epochs):
            for m in range(values.shape[1]):
                ax.plot(epochs, values[:, m], color="0.5", alpha=0.35, lw=0.7)
            ax.plot(epochs, values.mean(axis=1), color="black", lw=1.8, label=f"mean of {values.shape[1]} members")
        if key == "mixing":
            e2, expected = _curve(splits, "mixing_expected")
            if len(e2):
                ax.plot(e2, expected.mean(axis=1), "--", color="tab:green", label="perfect mixing")
        if key == "latent_ratio":
            ax.axhline(1.0, ls="--", color="tab:red", lw=1.0, label="chance")
        ax.set_xscale("log")
        ax.set_xlabel("epoch")
        ax.set_ylabel(ylabel)
        ax.set_title(f"{title}\nvalidation contacts, all splits and seeds", fontsize=9)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7)
    return save_figure(fig, path)


def plot_validation_nmae(splits: list[dict[str, Any]], path: Path) -> Path:
    """Validation NMAE and SSIM per direction against epoch, mean over all seeds and splits."""
    fig = new_figure(11, 4.2, layout="tight")
    axes = fig.subplots(1, 2)
    columns = list(splits[0]["metrics"]["table1"]["all_seen"])
    for ax, metric in zip(axes, ("nmae", "ssim"), strict=True):
        for column in columns:
            per_split = []
            for split in splits:
                points = [h for h in split["history"] if column in h.get("val", {}).get("seen", {})]
                per_split.append({h["epoch"]: h["val"]["seen"][column][metric] for h in points})
            epochs = sorted(set.intersection(*(set(p) for p in per_split)))
            values = np.array([[v for p in per_split for v in p[e]] for e in epochs], dtype=float)
            if len(epochs):
                style = "--" if column.startswith("ae_") else "-"
                ax.plot(epochs, values.mean(axis=1), style, label=_arrow(column), lw=1.3)
        ax.set_xscale("log")
        if metric == "nmae":
            ax.set_yscale("log")
        ax.set_xlabel("epoch")
        ax.set_ylabel(f"validation {metric.upper()} (seen objects)")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7)
    return save_figure(fig, path)


# ---- the page ------------------------------------------------------------------------------------------------


def render(splits: list[dict[str, Any]], figures: dict[str, str], args: argparse.Namespace, base: TrainConfig) -> str:
    first = splits[0]["metrics"]
    config = splits[0]["config"]
    sensors = tuple(first["sensors"])
    table = first["table1"]
    columns = table_columns(sensors, {c for row in table.values() for c in row})
    n_members = len(members(splits, "all_seen", columns[0], "nmae"))
    prov = first["provenance"]
    described = metric_description(config.nmae_normaliser, config.ssim_range)
    summary = splits[0]["summary"]
    train_minutes = sum(s["geometry"]["seconds"]["train_wall"] for s in splits) / 60
    geometry_minutes = sum(s["geometry"]["seconds"]["geometry"] for s in splits) / 60
    shape = config.shape
    lines = [
        START,
        "# Results: UniTac-NV reproduced",
        "",
        f"Data: {'the simulated campaign' if first['simulated'] else 'recorded sessions'} (`--data "
        f"{args.data.name}`), sensors {', '.join(sensors)}; per split {summary.get('train_rows')} training, "
        f"{summary.get('val_rows')} validation and {summary.get('test_rows')} test contacts. "
        f"{len(splits)} splits (split seeds {[s['config'].split_seed for s in splits]}) x {len(config.seeds)} model "
        f"seeds {list(config.seeds)} = {n_members} trained members per model, each run training UniTac-NV and "
        f"both per-sensor baselines together; {first['epochs']} epochs, batch {config.batch_size}, Adam lr "
        f"{config.learning_rate}, dropout {shape.dropout}, widths {list(shape.encoder_hidden)} / "
        f"{shape.latent_dim} / {list(shape.decoder_hidden)}. unitac-rig {prov.get('package_version')}, commit "
        f"`{str(prov.get('git_commit', ''))[:12]}`.",
        "",
        f"Preprocessing: {PREPROCESSING_TEXT[config.preprocessing]} (`{config.preprocessing}`). NMAE "
        f"(`{described['nmae_normaliser']}`): {described['nmae']}. SSIM (`{described['ssim_range']}`): "
        f"{described['ssim']}. Why these: docs/learning.md (Preprocessing and metrics).",
        "",
        f"Wall time on the shared 2-core box (no GPU): training {train_minutes:.0f} min for all splits, geometry "
        f"{geometry_minutes:.0f} min.",
        "",
        f"Reproduce: `unitac-rig campaign --data DATA --no-live`, then `python benchmarks/run_results.py --data DATA "
        f"--seeds {len(config.seeds)} --splits {len(splits)} --epochs {first['epochs']}` (and "
        "`python benchmarks/beyond_paper.py --data DATA` for the beyond-the-paper section).",
        "",
        "## Headline claims",
        "",
        "| claim | reproduced | measurement |",
        "|---|---|---|",
    ]
    for claim, ok, text in claims(splits):
        lines.append(f"| {claim} | {'yes' if ok else '**no**'} | {text} |")
    lines += [
        "",
        f"## Table I: NMAE / SSIM on the test set, mean ± std over {n_members} members ({len(splits)} splits x "
        f"{len(config.seeds)} seeds), paper below",
        "",
        "| row | " + " | ".join(_arrow(c) for c in columns) + " |",
        "|---|" + "---|" * len(columns),
    ]
    for row in table:
        cells = []
        for c in columns:
            n, s = members(splits, row, c, "nmae"), members(splits, row, c, "ssim")
            cells.append(f"{n.mean():.3f}±{n.std():.3f} / {s.mean():.3f}±{s.std():.3f}")
        lines.append(f"| {row} | " + " | ".join(cells) + " |")
        if row in PAPER_TABLE1:
            paper = PAPER_TABLE1[row]
            lines.append(
                "| *paper* | "
                + " | ".join(f"{paper[c][0]:.3f} / {paper[c][1]:.3f}" if c in paper else "–" for c in columns)
                + " |"
            )
    lines += [
        "",
        "Spread of the all-seen row: standard deviation of the per-split means (split to split) against the mean "
        "standard deviation over seeds within a split (seed to seed):",
        "",
        "| column | NMAE split-to-split | NMAE seed-to-seed | SSIM split-to-split | SSIM seed-to-seed |",
        "|---|---:|---:|---:|---:|",
    ]
    for c in columns:
        within = {
            metric: np.mean([s["metrics"].get("table1_std", {}).get("all_seen", {}).get(c, {}).get(metric, 0.0)
                             for s in splits])
            for metric in ("nmae", "ssim")
        }  # fmt: skip
        lines.append(
            f"| {_arrow(c)} | {split_means(splits, 'all_seen', c, 'nmae').std():.4f} | {within['nmae']:.4f} | "
            f"{split_means(splits, 'all_seen', c, 'ssim').std():.4f} | {within['ssim']:.4f} |"
        )
    lines += _variants_lines(splits, columns)
    lines += _consistency_lines(splits, columns)
    lines += [
        "",
        "## Latent alignment (test contacts, after epoch 1 → at the end, mean over all members)",
        "",
        "| contacts | matched L1 (paper's) | matched / unmatched L1 | sensor mixing (10 NN) | perfect mixing |",
        "|---|---|---|---|---|",
    ]
    for subset in ("all", "seen", "unseen"):
        cells = []
        for key in ("latent_l1", "latent_ratio", "mixing"):
            before = alignment_values(splits, subset, key, "first_epoch")
            after = alignment_values(splits, subset, key, "final")
            cells.append(f"{before.mean():.3f} → {after.mean():.3f}" if before.size and after.size else "–")
        expected = alignment_values(splits, subset, "mixing_expected", "final")
        lines.append(f"| {subset} | " + " | ".join(cells) + f" | {expected.mean() if expected.size else 0:.3f} |")
    lines += [
        "",
        f"## Contact geometry on the unseen object: mean profile error (mm), mean ± std over {n_members} members",
        "",
        "| train → test | ours | paper |",
        "|---|---:|---:|",
    ]
    for name in splits[0]["geometry"]["paper_heads"][0]["scenarios"]:
        paper_mm = PAPER_GEOMETRY_MAE_MM.get(name)
        paper_cell = "–" if paper_mm is None else f"{paper_mm:.3f}"
        lines.append(f"| {_arrow(name)} | {_pm(geometry_values(splits, name))} | {paper_cell} |")
    for name in splits[0]["geometry"]["pooled_head"][0]["scenarios"]:
        lines.append(
            f"| {_arrow(name)} (beyond the paper: one head on both sensors' latents) | "
            f"{_pm(geometry_values(splits, name))} | – |"
        )
    beyond = args.docs / "figures" / "beyond_paper.json"
    if beyond.exists():
        from beyond_paper import render_section  # the sibling script, on sys.path when this one runs

        lines += ["", *render_section(json.loads(beyond.read_text(encoding="utf-8")))]
    lines += ["", "## Figures", ""]
    captions = {
        "alignment": "Alignment over training (validation contacts): raw L1, scale-free ratio, sensor mixing",
        "validation curves": "Validation NMAE / SSIM per direction over training (seen objects)",
        "tsne": "t-SNE of the test latents after epoch 1 (top) and at the end (bottom), split 0, seed 0",
        "reconstructions_seen": "Reconstructions, seen object (held-out angle)",
        "reconstructions_unseen": "Reconstructions, unseen object: best and worst",
        "geometry": "Contact geometry, split 0, seed 0",
    }
    for name, rel in figures.items():
        lines += [f"{captions.get(name, name)}:", "", f"![{name}]({rel})", ""]
    lines.append(END)
    return "\n".join(lines)


def _variants_lines(splits: list[dict[str, Any]], columns: list[str]) -> list[str]:
    """The all-seen NMAE and SSIM under every metric option, on the *validation* contacts (the choice of reading is
    made there), beside the paper's all-seen row, with the geometric mean over columns of ours / the paper's (NMAE)
    and (1 - ours) / (1 - the paper's) (SSIM): 1 where the magnitudes match."""
    variants = [s["metrics"].get("validation_metric_variants") for s in splits]
    if not all(variants):
        return []
    paper = PAPER_TABLE1["all_seen"]
    lines = [
        "",
        "### The same models under every metric reading (validation contacts, seen objects, mean over members)",
        "",
        "| metric | option | " + " | ".join(_arrow(c) for c in columns) + " | geometric-mean ratio to the paper's |",
        "|---|---|" + "---|" * len(columns) + "---:|",
    ]
    for metric, index in (("nmae", 0), ("ssim", 1)):
        for option in variants[0][metric]:
            values = [_variant_mean(variants, metric, option, c) for c in columns]
            # NMAE: ours / paper's; SSIM: (1 - ours) / (1 - paper's), the dissimilarities (SSIM may be negative)
            ratios = [
                v / paper[c][0] if metric == "nmae" else (1.0 - v) / (1.0 - paper[c][1])
                for v, c in zip(values, columns, strict=True)
                if c in paper
            ]
            lines.append(
                f"| {metric.upper()} | `{option}` | "
                + " | ".join(f"{v:.3f}" for v in values)
                + f" | {float(np.exp(np.mean(np.log(ratios)))):.2f} |"
            )
        lines.append(
            f"| {metric.upper()} | *paper, all seen (test)* | "
            + " | ".join(f"{paper[c][index]:.3f}" if c in paper else "–" for c in columns)
            + " | 1 |"
        )
    return lines


def _variant_mean(variants: list[Any], metric: str, option: str, column: str) -> float:
    """One validation metric under one reading, averaged over every member of every split."""
    return float(np.mean([v for split in variants for v in split[metric][option][column]]))


def _consistency_lines(splits: list[dict[str, Any]], columns: list[str]) -> list[str]:
    """How much SSIM a unit of NMAE costs, (1 - SSIM) / NMAE (geometric mean over the columns), under every pair of
    readings, beside the paper's own pairs. Independent of how large the errors are (the simulated contacts are
    cleaner than recorded ones), it asks which reading makes our NMAE and SSIM relate the way the paper's do."""
    variants = [s["metrics"].get("validation_metric_variants") for s in splits]
    if not all(variants):
        return []
    paper = PAPER_TABLE1["all_seen"]
    shared = [c for c in columns if c in paper]
    paper_slope = float(np.exp(np.mean([np.log((1.0 - paper[c][1]) / paper[c][0]) for c in shared])))

    ssim_options = list(variants[0]["ssim"])
    lines = [
        "",
        f"SSIM lost per unit of NMAE, (1 − SSIM) / NMAE, geometric mean over the columns, divided by the paper's "
        f"({paper_slope:.2f} on its all-seen row): 1 where our two metrics relate as the paper's do, whatever the "
        "size of the errors.",
        "",
        "| NMAE normaliser \\ SSIM range | " + " | ".join(f"`{o}`" for o in ssim_options) + " |",
        "|---|" + "---:|" * len(ssim_options),
    ]
    for nmae_option in variants[0]["nmae"]:
        cells = []
        for ssim_option in ssim_options:
            slopes = [
                np.log(
                    max(1.0 - _variant_mean(variants, "ssim", ssim_option, c), 1e-6)
                    / _variant_mean(variants, "nmae", nmae_option, c)
                )
                for c in shared
            ]
            cells.append(f"{float(np.exp(np.mean(slopes))) / paper_slope:.2f}")
        lines.append(f"| `{nmae_option}` | " + " | ".join(cells) + " |")
    return lines


def write_results(path: Path, generated: str) -> None:
    """Replace the generated block of ``path`` and keep every hand-written line around it; a file without the
    markers keeps its sections from "## How the data were made" on after the new block."""
    old = path.read_text(encoding="utf-8") if path.exists() else ""
    if START in old and END in old:
        before, rest = old.split(START, 1)
        after = rest.split(END, 1)[1]
        text = before + generated + after
    else:
        kept = old[old.index("## How the data were made") :] if "## How the data were made" in old else ""
        text = generated + ("\n\n" + kept if kept else "\n")
    path.write_text(text, encoding="utf-8")


if __name__ == "__main__":
    main()
