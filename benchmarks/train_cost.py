"""What ``unitac-rig train`` spends its CPU on, by phase, before and after the t-SNE's thread limit (issue 27).

Run: ``python benchmarks/train_cost.py --data DATA`` (a dataset with both sensors' sessions, e.g. two
``unitac-rig collect --object hex_tpu`` runs). Writes ``docs/figures/train_cost.json`` and prints the split.

Each version runs ``unitac-rig train --data DATA --out TMP --epochs N`` in a fresh process; thin timers add up the
process CPU (every thread: ``time.process_time``) spent in each phase: data load (``load_sets`` and
``build_paired_dataset``), training (``train``, with its per-epoch validation), evaluation (``write_metrics``) and
the t-SNE (``tsne_embeddings``); "report, rest" is the rest of ``write_report`` (figures, markdown). "Before" is
another commit (default: the parent of the thread limit) in a ``git worktree``, imported through ``PYTHONPATH``.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

from sim_cost import checkout

ROOT = Path(__file__).resolve().parent.parent
OUT = ROOT / "docs" / "figures" / "train_cost.json"


def _timed(module: Any, name: str, totals: dict[str, float], label: str) -> None:
    inner = getattr(module, name)

    def wrapper(*args: Any, **kwargs: Any) -> Any:
        start = time.process_time()
        try:
            return inner(*args, **kwargs)
        finally:
            totals[label] = totals.get(label, 0.0) + time.process_time() - start

    setattr(module, name, wrapper)


def run_train(data: Path, epochs: int, seed: int) -> dict[str, Any]:
    """``train`` on the code on ``sys.path``, CPU by phase."""
    import unitac_rig.learning.data as data_module
    import unitac_rig.learning.report as report_module
    import unitac_rig.learning.train as train_module
    from unitac_rig.cli import main

    totals: dict[str, float] = {}
    _timed(data_module, "load_sets", totals, "data load")
    _timed(data_module, "build_paired_dataset", totals, "data load")
    _timed(train_module, "train", totals, "training")
    _timed(report_module, "write_report", totals, "report")
    _timed(report_module, "write_metrics", totals, "evaluation")
    _timed(report_module, "tsne_embeddings", totals, "t-SNE")
    with tempfile.TemporaryDirectory() as tmp:
        start = time.process_time()
        wall = time.monotonic()
        try:
            main(["train", "--data", str(data), "--out", str(Path(tmp) / "run"), "--epochs", str(epochs),
                  "--split-seed", str(seed)])  # fmt: skip
        except SystemExit as exc:
            if exc.code not in (0, None):
                raise
        cpu = time.process_time() - start
        wall_s = time.monotonic() - wall
        metrics = json.loads((Path(tmp) / "run" / "metrics.json").read_text())
    report_rest = totals.get("report", 0.0) - totals.get("evaluation", 0.0) - totals.get("t-SNE", 0.0)
    phases = {
        "data load": totals.get("data load", 0.0),
        "training": totals.get("training", 0.0),
        "evaluation": totals.get("evaluation", 0.0),
        "t-SNE": totals.get("t-SNE", 0.0),
        "report, rest": report_rest,
    }
    phases["other (imports excluded)"] = cpu - sum(phases.values())
    return {
        "cpu_s": round(cpu, 2),
        "wall_s": round(wall_s, 2),
        "phases_cpu_s": {k: round(v, 2) for k, v in phases.items()},
        "tsne_mixing": metrics.get("tsne_mixing"),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--data", type=Path, required=True, help="dataset folder (both sensors' sessions)")
    parser.add_argument("--epochs", type=int, default=20)
    parser.add_argument("--seed", type=int, default=0, help="the split seed (0)")
    parser.add_argument("--before", default="HEAD~1", help="commit measured as 'before'")
    parser.add_argument("--out", type=Path, default=OUT)
    parser.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.worker:
        print(json.dumps(run_train(args.data, args.epochs, args.seed)))
        return
    before_ref = subprocess.run(
        ["git", "-C", str(ROOT), "rev-parse", "--short", args.before], capture_output=True, text=True, check=True
    ).stdout.strip()
    results: dict[str, Any] = {}
    with checkout(before_ref) as before_tree:
        for label, code in (("before", before_tree), ("after", ROOT)):
            command = [sys.executable, str(Path(__file__).resolve()), "--worker", "--data", str(args.data.resolve())]
            command += ["--epochs", str(args.epochs), "--seed", str(args.seed)]
            env = {**os.environ, "PYTHONPATH": f"{code}{os.pathsep}{Path(__file__).resolve().parent}"}
            done = subprocess.run(command, env=env, cwd=tempfile.gettempdir(), capture_output=True, text=True)
            if done.returncode != 0:
                raise SystemExit(f"train on {code} failed:\n{done.stderr[-2000:]}")
            results[label] = json.loads(done.stdout.strip().splitlines()[-1])
            split = ", ".join(f"{k} {v:.1f}" for k, v in results[label]["phases_cpu_s"].items())
            print(f"{label:6s} {results[label]['cpu_s']:.1f} CPU-s ({split})")
    doc = {
        "what": "CPU seconds of `unitac-rig train` by phase, before and after the t-SNE thread limit (issue 27)",
        "command": "python benchmarks/train_cost.py " + " ".join(sys.argv[1:]),
        "before_commit": before_ref,
        "epochs": args.epochs,
        "cpus": os.cpu_count(),
        "load_avg": os.getloadavg(),
        "results": results,
    }
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(doc, indent=2) + "\n")
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
