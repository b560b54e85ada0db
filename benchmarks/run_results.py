"""Reproduce the paper's results on a dataset and write docs/results.md.

Trains UniTac-NV and both per-sensor baselines for several seeds together (one batched run, 1000 epochs by default),
writes the run's metrics/report/figures, runs the contact-geometry task for every seed, and writes
``docs/results.md``: Table I as mean +- std over seeds beside the paper's numbers, latent alignment, geometry errors
beside the paper's, wall times and figures (copied to ``docs/figures/results_*.png``).

    python benchmarks/run_results.py --data DATA_DIR [--out runs/results] [--seeds 5] [--epochs 1000]
"""

from __future__ import annotations

import argparse
import json
import shutil
import time
from pathlib import Path

import numpy as np

from unitac_rig.learning.contact_geometry import geometry_for_run, run_geometry
from unitac_rig.learning.data import build_paired_dataset, load_sets
from unitac_rig.learning.paper import PAPER_GEOMETRY_MAE_MM, PAPER_TABLE1
from unitac_rig.learning.report import table_columns, write_report
from unitac_rig.learning.train import TrainConfig, load_run, load_test_set, train

ROOT = Path(__file__).resolve().parent.parent


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--data", type=Path, required=True)
    parser.add_argument("--out", type=Path, default=ROOT / "runs" / "results")
    parser.add_argument("--seeds", type=int, default=5)
    parser.add_argument("--epochs", type=int, default=1000)
    parser.add_argument("--eval-every", type=int, default=5)
    parser.add_argument("--resume", action="store_true", help="continue an interrupted --out run")
    parser.add_argument("--docs", type=Path, default=ROOT / "docs")
    args = parser.parse_args()

    began = time.perf_counter()
    dataset = build_paired_dataset(load_sets(args.data))
    print(f"{len(dataset)} pairs, sensors {dataset.sensors}, objects {dataset.objects}")
    config = TrainConfig(epochs=args.epochs, seeds=tuple(range(args.seeds)), eval_every=args.eval_every)

    def progress(record: dict) -> None:
        if record["epoch"] % 50 == 0:
            print(f"epoch {record['epoch']}: {record['seconds']:.0f} s")

    outcome = train(
        dataset,
        args.out,
        None if args.resume else config,
        resume=args.resume,
        epochs=args.epochs,
        device="auto",
        progress=progress,
    )
    run = load_run(args.out)
    test = load_test_set(args.out)
    report_began = time.perf_counter()
    write_report(args.out, run=run, test=test)
    report_seconds = time.perf_counter() - report_began

    geometry_began = time.perf_counter()
    geometry_runs = [run_geometry(run, test, member=m) for m in range(run.engine.members)]
    geometry_for_run(args.out)  # member 0: geometry.json and the outline figure
    write_report(args.out, run=run, test=test, figures=False)
    geometry_seconds = time.perf_counter() - geometry_began

    metrics = json.loads((args.out / "metrics.json").read_text())
    figures = copy_figures(args.out, args.docs / "figures")
    text = render(
        metrics,
        geometry_runs,
        outcome.train_seconds,
        report_seconds,
        geometry_seconds,
        time.perf_counter() - began,
        args,
        figures,
        dataset.simulated,
    )
    (args.docs / "results.md").write_text(text, encoding="utf-8")
    print(f"wrote {args.docs / 'results.md'}")


def copy_figures(run_dir: Path, target: Path) -> dict[str, str]:
    target.mkdir(parents=True, exist_ok=True)
    copied = {}
    for name in ("curves", "tsne", "reconstructions_seen", "reconstructions_unseen", "geometry"):
        source = run_dir / "figures" / f"{name}.png"
        if source.exists():
            shutil.copyfile(source, target / f"results_{name}.png")
            copied[name] = f"figures/results_{name}.png"
    return copied


def render(
    metrics: dict,
    geometry_runs: list,
    train_s: float,
    report_s: float,
    geometry_s: float,
    total_s: float,
    args: argparse.Namespace,
    figures: dict[str, str],
    simulated: bool,
) -> str:
    sensors = tuple(metrics["sensors"])
    table, spread = metrics["table1"], metrics.get("table1_std", {})
    columns = table_columns(sensors, {c for row in table.values() for c in row})
    prov = metrics["provenance"]
    lines = [
        "# Results: UniTac-NV reproduced",
        "",
        f"Data: `{args.data}` ({'simulated rig' if simulated else 'recorded'}), sensors {', '.join(sensors)}; "
        f"{sum(metrics['test_rows'].get(r, 0) for r in table if r != 'all_seen')} test contacts. "
        f"Seeds {metrics['seeds']} trained together (UniTac-NV + per-sensor baselines), {metrics['epochs']} epochs, "
        f"paper hyper-parameters. unitac-rig {prov.get('package_version')}, "
        f"commit `{prov.get('git_commit', '')[:12]}`.",
        "",
        f"Wall time: training {train_s / 60:.1f} min for all {len(metrics['seeds'])} seeds x "
        f"{1 + len(sensors)} models, report {report_s:.0f} s, geometry {geometry_s:.0f} s, "
        f"total {total_s / 60:.1f} min.",
        "",
        "Reproduce: `python benchmarks/run_results.py --data " + str(args.data) + f" --seeds {args.seeds} "
        f"--epochs {args.epochs}`.",
        "",
        "## Table I: NMAE / SSIM on the test set, mean ± std over seeds (paper below)",
        "",
        "NMAE normaliser: each sensor channel's training-set range; SSIM: global grid statistics per channel, "
        "C1 = (0.01 R)², C2 = (0.03 R)², averaged over x, y, z (see docs/learning.md).",
        "",
        "| row | " + " | ".join(c.replace("_to_", " → ") for c in columns) + " |",
        "|---|" + "---|" * len(columns),
    ]
    for row, cells in table.items():
        ours = []
        for c in columns:
            m, s = cells[c], spread.get(row, {}).get(c, {"nmae": 0.0, "ssim": 0.0})
            ours.append(f"{m['nmae']:.3f}±{s['nmae']:.3f} / {m['ssim']:.3f}±{s['ssim']:.3f}")
        lines.append(f"| {row} | " + " | ".join(ours) + " |")
        if row in PAPER_TABLE1:
            paper = PAPER_TABLE1[row]
            lines.append(
                "| *paper* | "
                + " | ".join(f"{paper[c][0]:.3f} / {paper[c][1]:.3f}" if c in paper else "–" for c in columns)
                + " |"
            )
    latent = metrics["latent_l1"]
    lines += [
        "",
        f"Latent alignment (mean Manhattan distance between matched test latents): {latent['first_epoch']:.3f} after "
        f"epoch 1 -> {latent['final']:.3f} after epoch {metrics['epochs']} (mean over seeds).",
        "",
        f"## Contact geometry on {geometry_runs[0].object_id}: mean profile error (mm), mean ± std over seeds",
        "",
        "| train → test | ours | paper |",
        "|---|---:|---:|",
    ]
    for name in geometry_runs[0].scenarios:
        errors = np.array([g.scenarios[name]["mae_mm"] for g in geometry_runs])
        paper = PAPER_GEOMETRY_MAE_MM.get(name)
        train_sensor, test_sensor = name.split("_to_")
        lines.append(
            f"| {train_sensor} → {test_sensor} | {errors.mean():.3f} ± {errors.std():.3f} | "
            f"{'–' if paper is None else f'{paper:.3f}'} |"
        )
    if figures:
        lines += ["", "## Figures", ""]
        lines += [f"![{name}]({path})" for name, path in figures.items()]
    lines.append("")
    return "\n".join(lines)


if __name__ == "__main__":
    main()
