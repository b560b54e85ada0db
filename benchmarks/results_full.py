"""The results protocol behind docs/results.md: collect the simulated campaign (or read ``--data``), train the
paper's random split and the blocked split (splits x model seeds each), run every geometry head, write one compact
JSON per split, the figures and the results page under OUT (the page: ``run_results.py``, from the JSON alone).
Nothing else goes to OUT (the data and the runs stay in --work; finished runs there are reused, unfinished resumed).

Stages, each in parallel processes (``--jobs``, one torch thread each: the layers are tiny, see
``run.default_threads``):

1. collect: one ``unitac-rig collect`` per (object, sensor) on the simulated rig (seed 0; the placement is drawn per
   object and shared by both sensors' sessions, as ``campaign`` does); reused when the session is complete; skipped
   with ``--data`` (recorded or earlier sessions);
2. a 2-epoch probe of every run measures the seconds per epoch under the real load; the epochs then trained are
   ``--epochs`` or, when that would overrun ``--budget-s``, the most (a multiple of 10) that fit, and the page says
   how many were trained;
3. every run resumed to those epochs, or until ``--patience`` epochs pass without a better validation NMAE (the
   epoch reached is in each split's JSON);
4. per member: the paper's geometry heads, the pooled same-sensor head, the strict cross-sensor methods (the tuned
   ceiling on ``--ceiling-members`` members per split);
5. per split: report, Table I under every metric reading, one JSON; then the page from the JSON.

Seeds: split ``K`` of a protocol trains model seeds ``K * n .. K * n + n - 1`` (no two splits share a seed: the
split-to-split spread is not correlated through init, dropout and shuffles); member ``m`` of split ``K`` draws its
geometry split from :func:`geometry_split_seed`, a seed of its own (25 members hold out 25 geometry test sets).

    python benchmarks/results_full.py OUT [--work DIR] [--data DATA | --rig RIG.toml] [--config FILE.toml] [--jobs 16]
        [--budget-s 500] [--epochs 1000] [--splits 5] [--seeds 5] [--angles N] [--frame-baseline recording|press]
        [--protocol random --protocol blocked] [--ceiling-members 1] [--patience 100]

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
from dataclasses import replace
from pathlib import Path
from typing import Any

import run_results  # the sibling script: the page from the JSON
from lab.geometry_heads import cross_sensor_geometry, pooled_geometry
from unitac_rig.bench import jsonable
from unitac_rig.learning.config import load_config
from unitac_rig.learning.contact_geometry import GeometryConfig, geometry_for_run
from unitac_rig.learning.data import PairedDataset, build_paired_dataset, load_sets
from unitac_rig.learning.evaluate import evaluate_run, simple_predictions
from unitac_rig.learning.report import write_report
from unitac_rig.learning.run import TRAINING_PAIRS, checkpoint_path, load_test_set, save_test_set
from unitac_rig.learning.train import TrainConfig, load_run, train
from unitac_rig.rig.objects import list_objects
from unitac_rig.storage.reader import FRAME_BASELINES
from unitac_rig.storage.summary import inspect_dataset

ROOT = Path(__file__).resolve().parent.parent
SENSORS = ("uskin", "papillarray")
PROBE_EPOCHS = 2
COLLECTION_JSON = "collection.json"  # run_results reads it beside the protocols' folders
EVAL_OVERHEAD = 1.25  # validation every 10 epochs, checkpoints and the process's start, on top of training time
PATIENCE = 100  # epochs without a better validation NMAE before a run stops (train.TrainConfig.patience)
GEOMETRY_RESERVE_S = 160.0  # wall seconds kept for stages 4-5 at full size on 16 cores (estimate: docs/learning.md)
# every NMAE normaliser and every SSIM range, in four evaluations; the first is the default reading
READINGS = (
    ("channel_range", "sensor_range"),
    ("sensor_range", "channel_range"),
    ("channel_std", "z_range"),
    ("frame_range", "sensor_range"),
)
SEEN_PAIRS = TRAINING_PAIRS  # folder in a run: the seen objects' training pairs (the linear map, the CCA, baselines)
MEMBER_JSON = "geometry_member_{}.json"
DIGITS = 6  # significant digits kept in the committed JSON


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("out", type=Path)
    parser.add_argument("--work", type=Path, default=Path("/tmp/unitac-results-work"))
    parser.add_argument("--data", type=Path, default=None, help="train on these sessions instead of collecting")
    parser.add_argument(
        "--rig",
        type=Path,
        default=ROOT / "examples" / "paper-pace.toml",
        help="rig file the collection runs with (default: the simulated rig at the paper's pace)",
    )
    parser.add_argument("--config", type=Path, default=None, help="TOML training config (docs/learning.md)")
    parser.add_argument(
        "--frame-baseline",
        choices=FRAME_BASELINES,
        default="recording",
        help="what frames are referenced to (default: the paper's one baseline per recording; docs/learning.md)",
    )
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

    data = args.data or args.work / "data"
    if args.data is None:
        collect(data, args.angles, args.jobs, logs, args.rig)
        mark("collected")
    write_collection(data, args.out / "results" / COLLECTION_JSON)
    dataset_dir = args.work / "dataset"
    flat = (load_config(args.config) if args.config else {}) | {"frame_baseline": args.frame_baseline}
    save_dataset(data, dataset_dir, args.frame_baseline)
    mark("dataset built")
    runs = [(p, k) for p in protocols for k in range(args.splits)]
    pool = ProcessPoolExecutor(max_workers=args.jobs, mp_context=multiprocessing.get_context("spawn"))
    with pool:
        common = (dataset_dir, args.work, args.seeds, args.patience, flat)
        probes = list(pool.map(_train_task, [(common, p, k, PROBE_EPOCHS) for p, k in runs]))
        per_epoch = max(probes) * EVAL_OVERHEAD
        mark("probe trained")
        left = args.budget_s - (time.monotonic() - began) - args.reserve_s
        waves = -(-len(runs) // args.jobs)  # runs beyond the cores wait for a free one
        fitting = int(left / (per_epoch * waves)) // 10 * 10
        epochs = max(PROBE_EPOCHS, min(args.epochs, fitting))
        timings.update(seconds_per_epoch=round(per_epoch, 3), epochs=epochs, epochs_asked=args.epochs)
        print(f"{per_epoch:.2f} s per epoch per run: training {epochs} epochs ({args.epochs} asked)", flush=True)
        list(pool.map(_train_task, [(common, p, k, epochs) for p, k in runs]))
        mark("trained")
        geometry_members = min(args.seeds, args.geometry_members or args.seeds)
        members = [(args.work, p, k, m, m < args.ceiling_members) for p, k in runs for m in range(geometry_members)]
        members.sort(key=lambda t: not t[4])  # the ceiling members first: they take longest
        list(pool.map(_geometry_task, members))
        mark("geometry")
        list(pool.map(_export_task, [(args.work, p, k, args.out) for p, k in runs]))
        mark("exported")
    run_results.write_page(args.out / "results", args.out / "results.md", args.work / "runs")
    mark("rendered")
    (args.out / "timings.json").write_text(json.dumps(timings, indent=2) + "\n", encoding="utf-8")


def collect(data: Path, angles: int | None, jobs: int, logs: Path, rig: Path | None = None) -> None:
    """One ``unitac-rig collect`` process per (object, sensor) with the rig file ``rig`` (None: the simulated
    rig's defaults), the longest sessions first."""
    objects = sorted(list_objects(), key=lambda o: -len(o.rotations_deg))
    commands = []
    for obj in objects:
        for sensor in SENSORS:
            command = [sys.executable, "-m", "unitac_rig", "collect", "--object", obj.id, "--sensor", sensor]
            command += ["--no-live", "--data", str(data), "--seed", "0"]
            if rig is not None:
                command += ["--rig", str(rig)]
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
    report = inspect_dataset(data)
    for session in report["sessions"]:
        session.pop("writer", None)  # who holds the write lease now: nobody, and nothing the page needs
    target.parent.mkdir(parents=True, exist_ok=True)
    target.write_text(json.dumps(report, indent=1) + "\n", encoding="utf-8")


def save_dataset(data: Path, target: Path, baseline: str) -> None:
    """Join the sessions once (frames referenced to ``baseline``); every worker reads the joined contacts back
    (``load_test_set``) in a second."""
    dataset = build_paired_dataset(load_sets(data, baseline))
    target.mkdir(parents=True, exist_ok=True)
    save_test_set(target, dataset)
    print(f"{len(dataset)} pairs, objects {', '.join(dataset.objects)}", flush=True)


def _train_task(task: tuple[tuple[Path, Path, int, int, dict[str, Any]], str, int, int]) -> float:
    """Train (or resume) one split's run to ``epochs`` (fewer where early stopping ends it); returns its training
    seconds per epoch."""
    (dataset_dir, work, seeds, patience, flat), protocol, split, epochs = task
    run_dir = work / "runs" / protocol / f"split-{split}"
    # validation every 10 epochs, at most about 25 times a run: curves enough, and evaluation stays under a tenth
    every = max(10, epochs // 250 * 10)
    base = TrainConfig().updated({"eval_every": every, **flat, "epochs": epochs, "patience": patience})
    config = split_config(base, protocol, split, seeds)
    train_split(load_test_set(dataset_dir), run_dir, config, log=lambda message: None)
    payload = load_run(run_dir).payload
    return float(payload["train_seconds"]) / max(1, int(payload["epoch"]))


def _geometry_task(task: tuple[Path, str, int, int, bool]) -> None:
    work, protocol, split, member, ceiling = task
    geometry_member(work / "runs" / protocol / f"split-{split}", protocol, member, ceiling)


def _export_task(task: tuple[Path, str, int, Path]) -> None:
    work, protocol, split, out = task
    run_dir = work / "runs" / protocol / f"split-{split}"
    export_split(run_dir, protocol, out / "results" / protocol / f"split-{split}.json")


def model_seeds(split_seed: int, n_seeds: int) -> tuple[int, ...]:
    """Split ``K``'s model seeds: ``K * n .. K * n + n - 1``, so no seed repeats across splits."""
    return tuple(split_seed * n_seeds + i for i in range(n_seeds))


def geometry_split_seed(split_seed: int, member: int) -> int:
    """The geometry split's seed of member ``member`` of split ``split_seed``: unique per member and drawn in its
    own random stream (``hold_out_rays(..., stream=3)``), whatever the member's model seed."""
    return 10_000 + 100 * split_seed + member


def split_config(base: TrainConfig, protocol: str, split_seed: int, n_seeds: int) -> TrainConfig:
    return base.updated({"split_seed": split_seed, "split_mode": protocol, "seeds": model_seeds(split_seed, n_seeds)})


def train_split(dataset: PairedDataset, run_dir: Path, config: TrainConfig, log: Any = print) -> float:
    """Train, resume to ``config.epochs`` or reuse one split's run; keeps the seen objects' training pairs beside
    it. Returns the training wall seconds spent now."""
    began = time.perf_counter()
    if checkpoint_path(run_dir).exists():
        done = int(load_run(run_dir).payload["epoch"])
        if done < config.epochs:
            log(f"{run_dir}: resuming at epoch {done} to {config.epochs}")
            train(dataset, run_dir, None, resume=True, epochs=config.epochs)
    else:
        train(dataset, run_dir, config)  # keeps the training pairs in RUN/seen_pairs (run.save_training_pairs)
    return time.perf_counter() - began


def geometry_member(
    run_dir: Path, protocol: str, member: int, ceiling: bool, epochs: int | None = None
) -> dict[str, Any]:
    """Every geometry head for one member: the paper's heads (the paper's random split, or blocked rays) and the
    strict cross-sensor study; with ``ceiling`` also the tuned ceiling and the pooled same-sensor head on the same
    split (the two costliest: 100 and 40 CPU-s a member at full size, so a full run gives them to the first member
    of each split). Written to ``RUN/geometry_member_<m>.json`` and returned."""
    run, test = load_run(run_dir), load_test_set(run_dir)
    split_seed = geometry_split_seed(int(run.config.split_seed), member)
    config = GeometryConfig(split_mode=protocol)
    if epochs is not None:  # the paper's 80 unless a quick check asks for fewer
        config = replace(config, epochs=epochs)
    seen = load_test_set(run_dir / SEEN_PAIRS) if (run_dir / SEEN_PAIRS).exists() else None
    cross = cross_sensor_geometry(
        run, test, member=member, split_seed=split_seed, seen=seen, config=config, ceiling=ceiling
    )
    paper = cross["methods"]["paper"]  # the paper's heads, one per training sensor, fitted among the methods
    scenarios = {name: {"mae_mm": mae} for name, mae in {**paper["same"], **paper["cross"]}.items()}
    record: dict[str, Any] = {
        "member": member,
        "model_seed": run.engine.seeds[member],
        "geometry_split_seed": split_seed,
        "paper_heads": {"scenarios": scenarios, "seconds": paper["seconds"] * len(run.sensors)},
        "cross_sensor": cross,
    }
    if ceiling:
        pooled = pooled_geometry(run, test, member=member, config=config, split_seed=split_seed)
        for scenario in pooled["scenarios"].values():
            scenario.pop("per_point_mae_mm", None)
        record["pooled_head"] = pooled
    (run_dir / MEMBER_JSON.format(member)).write_text(json.dumps(jsonable(record, DIGITS)) + "\n", encoding="utf-8")
    return record


def export_split(run_dir: Path, protocol: str, target: Path, figures: bool = True) -> dict[str, Any]:
    """The report (metrics.json, t-SNE mixing, figures with ``figures``), Table I under every reading and the
    per-member geometry, as one compact JSON at ``target``."""
    run, test = load_run(run_dir), load_test_set(run_dir)
    began = time.perf_counter()
    write_report(run_dir, run=run, test=test, figures=figures)
    if figures and int(run.config.split_seed) == 0:  # the outline figure, split 0 member 0 (the page shows it)
        geometry_for_run(run_dir, config=GeometryConfig(split_mode=protocol))
    metrics = json.loads((run_dir / "metrics.json").read_text(encoding="utf-8"))
    readings = {}
    simple = simple_predictions(run_dir, run, test)  # fitted once, scored under every reading
    for nmae, ssim in READINGS:
        scored = evaluate_run(run.scored_under(nmae, ssim), test, simple)
        readings[f"{nmae}|{ssim}"] = {
            "nmae_normaliser": nmae,
            "ssim_range": ssim,
            "table1_members": scored.get("table1_members") or _as_members(scored["table1"]),
        }
        if "simple_baselines" in scored:
            readings[f"{nmae}|{ssim}"]["simple_baselines"] = scored["simple_baselines"]["table1"]
    members = [
        json.loads((run_dir / MEMBER_JSON.format(m)).read_text(encoding="utf-8"))
        for m in range(run.engine.members)
        if (run_dir / MEMBER_JSON.format(m)).exists()
    ]
    doc = {
        "protocol": protocol,
        "split_seed": int(run.config.split_seed),
        "config": run.config.to_dict(),
        "summary": run.payload.get("dataset_summary", {}),
        "split": {
            k: v for k, v in run.payload["split"].items() if k in ("mode", "gap_deg", "test_directions", "not_held_out")
        },
        "metrics": {k: v for k, v in metrics.items() if k not in ("config",)},
        "readings": readings,
        "history": compact_history(run.history),
        "geometry": {"members": members},
        "seconds": {
            "train": float(run.payload["train_seconds"]),
            "report": time.perf_counter() - began,
            "geometry_cpu": float(sum(_member_seconds(m) for m in members)),
        },
    }
    target.parent.mkdir(parents=True, exist_ok=True)
    target.write_text(json.dumps(jsonable(doc, DIGITS), separators=(",", ":")) + "\n", encoding="utf-8")
    return doc


def _as_members(table: dict[str, Any]) -> dict[str, Any]:
    """A one-member run's table as the per-member form (lists of one)."""
    return {r: {c: {m: [v] for m, v in cell.items()} for c, cell in row.items()} for r, row in table.items()}


def _member_seconds(member: dict[str, Any]) -> float:
    cross = member["cross_sensor"]
    ceiling = sum(v.get("seconds", 0.0) for v in cross.get("ceiling", {}).values())
    pooled = member.get("pooled_head", {}).get("seconds", 0.0)
    methods = sum(m["seconds"] for m in cross["methods"].values())
    return float(member["paper_heads"]["seconds"] + pooled + ceiling + methods)


def compact_history(history: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """The evaluated epochs' validation curves only: per direction NMAE / SSIM on seen contacts and the alignment
    measures on all contacts, one value per member."""
    keys = ("latent_l1", "latent_ratio", "mixing", "mixing_expected")
    out = []
    for h in history:
        val = h.get("val")
        if not val:
            continue
        seen = {
            c: {m: v for m, v in cell.items() if m in ("nmae", "ssim")}
            for c, cell in val.get("seen", {}).items()
            if isinstance(cell, dict)
        }
        out.append(
            {
                "epoch": h["epoch"],
                "val": {"seen": seen, "all": {k: val["all"][k] for k in keys if k in val.get("all", {})}},
            }
        )
    return out


if __name__ == "__main__":
    main()
