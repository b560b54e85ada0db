"""The stages behind docs/results.md, each usable alone (``run_results.py`` and ``results_full.py`` call them).

One split's run trains UniTac-NV and both per-sensor baselines for every model seed of that split; then, per
member, the contact-geometry heads; then one compact JSON (``docs/results/<protocol>/split-<K>.json``) holds every
number the page shows for that split: per-member Table I under every metric reading, alignment, the validation
curves, the t-SNE mixing and per-member geometry (the paper's heads, the pooled same-sensor head, the strict
cross-sensor methods and the ceiling). The page is rendered from those files alone (``run_results.py
--report-only``).

Seeds: split ``K`` of a protocol trains model seeds ``K * n .. K * n + n - 1`` (no two splits share a seed: the
split-to-split spread is not correlated through init, dropout and shuffles); member ``m`` of split ``K`` draws its
geometry split from :func:`geometry_split_seed`, a seed of its own (the geometry split no longer follows the model
seed, so 25 members hold out 25 geometry test sets).
"""

from __future__ import annotations

import json
import time
from dataclasses import replace
from pathlib import Path
from typing import Any

from lab.geometry_heads import cross_sensor_geometry, pooled_geometry
from unitac_rig.bench import jsonable
from unitac_rig.learning.contact_geometry import GeometryConfig, geometry_for_run
from unitac_rig.learning.data import PairedDataset
from unitac_rig.learning.evaluate import evaluate_run, simple_predictions
from unitac_rig.learning.report import write_report
from unitac_rig.learning.run import TRAINING_PAIRS, checkpoint_path, load_test_set
from unitac_rig.learning.train import TrainConfig, load_run, train

PROTOCOLS = {"random": "random", "blocked": "blocked"}  # protocol name -> TrainConfig.split_mode
GEOMETRY_MODE = {"random": "random", "blocked": "blocked"}  # protocol -> GeometryConfig.split_mode
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


def model_seeds(split_seed: int, n_seeds: int) -> tuple[int, ...]:
    """Split ``K``'s model seeds: ``K * n .. K * n + n - 1``, so no seed repeats across splits."""
    return tuple(split_seed * n_seeds + i for i in range(n_seeds))


def geometry_split_seed(split_seed: int, member: int) -> int:
    """The geometry split's seed of member ``member`` of split ``split_seed``: unique per member and drawn in its
    own random stream (``hold_out_rays(..., stream=3)``), whatever the member's model seed."""
    return 10_000 + 100 * split_seed + member


def split_config(base: TrainConfig, protocol: str, split_seed: int, n_seeds: int) -> TrainConfig:
    return base.updated(
        {"split_seed": split_seed, "split_mode": PROTOCOLS[protocol], "seeds": model_seeds(split_seed, n_seeds)}
    )


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
    config = GeometryConfig(split_mode=GEOMETRY_MODE[protocol])
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
        geometry_for_run(run_dir, config=GeometryConfig(split_mode=GEOMETRY_MODE[protocol]))
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
