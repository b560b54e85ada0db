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
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

from lab.versions import ROOT, checkout, run_worker, short_commit


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
            main(
                [
                    "train",
                    "--data",
                    str(data),
                    "--out",
                    str(Path(tmp) / "run"),
                    "--epochs",
                    str(epochs),
                    "--split-seed",
                    str(seed),
                ]
            )
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
    # the workers import only the version they measure, so this checkout's package is imported here, not on top
    from unitac_rig.bench import default_out_dir, machine_info, write_json

    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--data", type=Path, required=True, help="dataset folder (both sensors' sessions)")
    parser.add_argument("--epochs", type=int, default=20)
    parser.add_argument("--seed", type=int, default=0, help="the split seed (0)")
    parser.add_argument("--before", default="HEAD~1", help="commit measured as 'before'")
    parser.add_argument("--out", type=Path, default=default_out_dir() / "train_cost.json")
    parser.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.worker:
        print(json.dumps(run_train(args.data, args.epochs, args.seed)))
        return
    before_ref = short_commit(args.before)
    results: dict[str, Any] = {}
    with checkout(before_ref) as before_tree:
        for label, code in (("before", before_tree), ("after", ROOT)):
            command = [str(Path(__file__).resolve()), "--worker", "--data", str(args.data.resolve())]
            results[label] = run_worker(code, [*command, "--epochs", str(args.epochs), "--seed", str(args.seed)])
            split = ", ".join(f"{k} {v:.1f}" for k, v in results[label]["phases_cpu_s"].items())
            print(f"{label:6s} {results[label]['cpu_s']:.1f} CPU-s ({split})")
    doc = {
        "what": "CPU seconds of `unitac-rig train` by phase, before and after the t-SNE thread limit (issue 27)",
        "command": "python benchmarks/train_cost.py " + " ".join(sys.argv[1:]),
        "before_commit": before_ref,
        "epochs": args.epochs,
        "machine": machine_info(),
        "results": results,
    }
    print(f"wrote {write_json(doc, args.out)}")


if __name__ == "__main__":
    main()
