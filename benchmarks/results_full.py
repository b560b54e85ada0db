"""The whole results protocol in one command, for a many-core machine: collect the simulated campaign, train the
paper's random split and the blocked split (splits x model seeds each), run every geometry head, write the compact
JSON, the figures and the results page under OUT. Nothing else goes to OUT (the data and the runs stay in --work).

Stages, each in parallel processes (``--jobs``, one torch thread each: the layers are tiny, see
``run.default_threads``):

1. collect: one ``unitac-rig collect`` per (object, sensor) on the simulated rig (seed 0; the placement is drawn per
   object and shared by both sensors' sessions, as ``campaign`` does); reused when the session is complete;
2. a 2-epoch probe of every run measures the seconds per epoch under the real load; the epochs then trained are
   ``--epochs`` or, when that would overrun ``--budget-s``, the most (a multiple of 10) that fit, and the page says
   how many were trained;
3. every run resumed to those epochs, or until ``--patience`` epochs pass without a better validation NMAE (the
   epoch reached is in each split's JSON);
4. per member: the paper's geometry heads, the pooled same-sensor head, the strict cross-sensor methods (the tuned
   ceiling on ``--ceiling-members`` members per split);
5. per split: report, Table I under every metric reading, one JSON; then the page from the JSON.

    python benchmarks/results_full.py OUT [--work DIR] [--jobs 16] [--budget-s 500] [--epochs 1000]
        [--splits 5] [--seeds 5] [--angles N] [--protocol random --protocol blocked] [--ceiling-members 1]
        [--patience 100]

OUT gets ``results/<protocol>/split-<K>.json`` and ``results/collection.json`` (commit as docs/results/),
``figures/`` (docs/figures/), ``results.md`` (docs/results.md: the repo's page with the generated block replaced),
``timings.json`` and ``logs/``. Tiny check on a small machine: ``--angles 5 --splits 1 --seeds 2 --epochs 2 --jobs 2``.
"""

from __future__ import annotations

import argparse
import json
import multiprocessing
import os
import subprocess
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent))

SENSORS = ("uskin", "papillarray")
PROBE_EPOCHS = 2
COLLECTION_JSON = "collection.json"  # run_results reads it beside the protocols' folders
EVAL_OVERHEAD = 1.25  # validation every 10 epochs, checkpoints and the process's start, on top of training time
PATIENCE = 100  # epochs without a better validation NMAE before a run stops (train.TrainConfig.patience)
GEOMETRY_RESERVE_S = 160.0  # wall seconds kept for stages 4-5 at full size on 16 cores (estimate: docs/learning.md)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("out", type=Path)
    parser.add_argument("--work", type=Path, default=Path("/tmp/unitac-results-work"))
    parser.add_argument("--jobs", type=int, default=os.cpu_count() or 2)
    parser.add_argument("--budget-s", type=float, default=500.0, help="wall seconds for everything")
    parser.add_argument("--epochs", type=int, default=1000, help="at most this many (fewer if the budget says so)")
    parser.add_argument(
        "--patience",
        type=int,
        default=PATIENCE,
        help="stop a run after this many epochs without a better validation NMAE",
    )
    parser.add_argument("--splits", type=int, default=5)
    parser.add_argument("--seeds", type=int, default=5)
    parser.add_argument("--angles", type=int, default=None, help="approach angles per sweep (default: the rig's 91)")
    parser.add_argument("--protocol", action="append", choices=("random", "blocked"), default=None)
    parser.add_argument(
        "--ceiling-members", type=int, default=1, help="members per split that also run the ceiling and pooled head"
    )
    parser.add_argument("--geometry-members", type=int, default=None, help="members per split with geometry (all)")
    parser.add_argument("--reserve-s", type=float, default=GEOMETRY_RESERVE_S, help="wall kept for geometry + JSON")
    args = parser.parse_args()
    began = time.monotonic()
    protocols = args.protocol or ["random", "blocked"]
    logs = args.out / "logs"
    logs.mkdir(parents=True, exist_ok=True)
    timings: dict[str, Any] = {"jobs": args.jobs, "budget_s": args.budget_s}

    def mark(stage: str) -> None:
        timings[stage] = round(time.monotonic() - began, 1)
        print(f"[{timings[stage]:6.1f} s] {stage}", flush=True)

    data = args.work / "data"
    collect(data, args.angles, args.jobs, logs)
    write_collection(data, args.out / "results" / COLLECTION_JSON)
    mark("collected")
    dataset_dir = args.work / "dataset"
    save_dataset(data, dataset_dir)
    mark("dataset built")
    runs = [(p, k) for p in protocols for k in range(args.splits)]
    pool = ProcessPoolExecutor(max_workers=args.jobs, mp_context=multiprocessing.get_context("spawn"))
    with pool:
        probes = list(
            pool.map(
                _train_task, [(dataset_dir, args.work, p, k, args.seeds, PROBE_EPOCHS, args.patience) for p, k in runs]
            )
        )
        per_epoch = max(probes) * EVAL_OVERHEAD
        mark("probe trained")
        left = args.budget_s - (time.monotonic() - began) - args.reserve_s
        waves = -(-len(runs) // args.jobs)  # runs beyond the cores wait for a free one
        fitting = int(left / (per_epoch * waves)) // 10 * 10
        epochs = max(PROBE_EPOCHS, min(args.epochs, fitting))
        timings.update(seconds_per_epoch=round(per_epoch, 3), epochs=epochs, epochs_asked=args.epochs)
        print(f"{per_epoch:.2f} s per epoch per run: training {epochs} epochs ({args.epochs} asked)", flush=True)
        tasks = [(dataset_dir, args.work, p, k, args.seeds, epochs, args.patience) for p, k in runs]
        list(pool.map(_train_task, tasks))
        mark("trained")
        geometry_members = min(args.seeds, args.geometry_members or args.seeds)
        tasks = [(args.work, p, k, m, m < args.ceiling_members) for p, k in runs for m in range(geometry_members)]
        tasks.sort(key=lambda t: not t[4])  # the ceiling members first: they take longest
        list(pool.map(_geometry_task, tasks))
        mark("geometry")
        list(pool.map(_export_task, [(args.work, p, k, args.out) for p, k in runs]))
        mark("exported")
    import run_results  # the sibling script: the page from the JSON

    run_results.write_page(args.out / "results", args.out / "results.md", args.work / "runs")
    mark("rendered")
    (args.out / "timings.json").write_text(json.dumps(timings, indent=2) + "\n", encoding="utf-8")


def collect(data: Path, angles: int | None, jobs: int, logs: Path) -> None:
    """One ``unitac-rig collect`` process per (object, sensor), the longest sessions first."""
    from unitac_rig.rig.objects import list_objects

    objects = sorted(list_objects(), key=lambda o: -len(o.rotations_deg))
    commands = []
    for obj in objects:
        for sensor in SENSORS:
            command = [sys.executable, "-m", "unitac_rig", "collect", "--object", obj.id, "--sensor", sensor]
            command += ["--no-live", "--data", str(data), "--seed", "0"]
            if angles is not None:
                command += ["--angles", str(angles)]
            commands.append((f"collect_{obj.id}_{sensor}", command))
    running: list[tuple[str, subprocess.Popen[bytes], Any]] = []
    failed = []
    while commands or running:
        while commands and len(running) < jobs:
            name, command = commands.pop(0)
            log = (logs / f"{name}.log").open("wb")
            running.append((name, subprocess.Popen(command, stdout=log, stderr=subprocess.STDOUT), log))
        name, process, log = running.pop(0)
        if process.wait() != 0:
            failed.append(name)
        log.close()
    if failed:
        raise SystemExit(f"collection failed for {', '.join(failed)}: see {logs}")


def write_collection(data: Path, target: Path) -> None:
    """The collection's statistics (``unitac-rig inspect --json``: per session presses, matched targets, match
    error, peak force; per object the joined pairs) as committed JSON, so the page's collection line has a source."""
    from unitac_rig.storage.summary import inspect_dataset

    report = inspect_dataset(data)
    for session in report["sessions"]:
        session.pop("writer", None)  # who holds the write lease now: nobody, and nothing the page needs
    target.parent.mkdir(parents=True, exist_ok=True)
    target.write_text(json.dumps(report, indent=1) + "\n", encoding="utf-8")


def save_dataset(data: Path, target: Path) -> None:
    """Join the sessions once; every worker reads the joined contacts back (``load_test_set``) in a second."""
    from unitac_rig.learning.data import build_paired_dataset, load_sets
    from unitac_rig.learning.run import save_test_set

    dataset = build_paired_dataset(load_sets(data))
    target.mkdir(parents=True, exist_ok=True)
    save_test_set(target, dataset)
    print(f"{len(dataset)} pairs, objects {', '.join(dataset.objects)}", flush=True)


def _train_task(task: tuple[Path, Path, str, int, int, int, int]) -> float:
    """Train (or resume) one split's run to ``epochs`` (fewer where early stopping ends it); returns its training
    seconds per epoch."""
    dataset_dir, work, protocol, split, seeds, epochs, patience = task
    from results_stages import split_config, train_split
    from unitac_rig.learning.run import load_test_set
    from unitac_rig.learning.train import TrainConfig, load_run

    run_dir = work / "runs" / protocol / f"split-{split}"
    # validation every 10 epochs, at most about 25 times a run: curves enough, and evaluation stays under a tenth
    every = max(10, epochs // 250 * 10)
    base = TrainConfig().updated({"eval_every": every, "epochs": epochs, "patience": patience})
    config = split_config(base, protocol, split, seeds)
    train_split(load_test_set(dataset_dir), run_dir, config, log=lambda message: None)
    payload = load_run(run_dir).payload
    return float(payload["train_seconds"]) / max(1, int(payload["epoch"]))


def _geometry_task(task: tuple[Path, str, int, int, bool]) -> None:
    work, protocol, split, member, ceiling = task
    from results_stages import geometry_member

    geometry_member(work / "runs" / protocol / f"split-{split}", protocol, member, ceiling)


def _export_task(task: tuple[Path, str, int, Path]) -> None:
    work, protocol, split, out = task
    from results_stages import export_split

    export_split(
        work / "runs" / protocol / f"split-{split}", protocol, out / "results" / protocol / f"split-{split}.json"
    )


if __name__ == "__main__":
    main()
