"""Table I for a trained run: NMAE and SSIM per test row group (each object, all seen objects' held-out angles,
each unseen object) for every baseline and every UniTac-NV direction, under the run's metric options; latent
alignment (raw, scale-free and sensor mixing, after epoch 1 and at the end); ``RUN/metrics.json``.

With several members (seeds) the table holds the mean over members, ``table1_std`` the standard deviation and
``table1_members`` each member's values.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import torch

from unitac_rig.learning.data import PairedDataset
from unitac_rig.learning.metrics import MIXING_K
from unitac_rig.learning.paper import TABLE1_ROWS
from unitac_rig.learning.train import Evaluator, LoadedRun, load_run, load_test_set

METRICS_JSON = "metrics.json"
ALL_SEEN = "all_seen"


def table_rows(test: PairedDataset, unseen: tuple[str, ...]) -> list[tuple[str, np.ndarray]]:
    """(row name, row mask) in the paper's order: seen objects, ``all_seen``, then unseen objects."""
    objects = test.objects
    order = [o for o in TABLE1_ROWS if o in objects] + sorted(o for o in objects if o not in TABLE1_ROWS)
    seen = [o for o in order if o not in unseen]
    rows = [(o, test.object_id == o) for o in seen]
    if seen:
        rows.append((ALL_SEEN, ~np.isin(test.object_id, list(unseen))))
    rows += [(o, test.object_id == o) for o in order if o in unseen]
    return rows


def metric_description(nmae_normaliser: str, ssim_range: str) -> dict[str, str]:
    """One sentence per option choice, for metrics.json, report.md and the terminal."""
    return {
        "nmae_normaliser": nmae_normaliser,
        "ssim_range": ssim_range,
        "nmae": NMAE_TEXT[nmae_normaliser],
        "ssim": f"global grid statistics per channel, C1 = (0.01 L)^2, C2 = (0.03 L)^2, averaged over x, y, z; "
        f"L = {SSIM_TEXT[ssim_range]}",
    }


NMAE_TEXT = {
    "channel_range": "mean |error| per channel divided by that sensor channel's training range (max - min)",
    "sensor_range": "mean |error| per channel divided by the whole sensor's training range (all taxels and axes)",
    "channel_std": "mean |error| per channel divided by that sensor channel's training standard deviation",
    "frame_range": "mean |error| per channel divided by the true frame's own range (max - min, all axes)",
}
SSIM_TEXT = {
    "channel_range": "each sensor channel's training range",
    "sensor_range": "the whole sensor's training range (all taxels and axes)",
    "z_range": "the sensor's normal (z) channel training range, for all three channels",
}
PREPROCESSING_TEXT = {
    "channel_z": "per-channel z-score (each sensor channel's training mean and standard deviation)",
    "sensor_minmax": "per-sensor min-max scaling (one training min and range per sensor, pooled over taxels and axes)",
    "sensor_scale": "per-sensor scale (one pooled training standard deviation per sensor, no shift)",
    "raw": "raw readings (sensor units, no scaling)",
}


def _mean_over_members(values: Any) -> float | None:
    return None if values is None else float(np.mean(values))


def evaluate_run(run: LoadedRun, test: PairedDataset) -> dict[str, Any]:
    """The metrics.json content (without writing it)."""
    config = run.config
    evaluator = Evaluator.for_run(run, test)
    scores, distance = evaluator.per_frame(run.engine)
    members = run.engine.members
    table: dict[str, dict[str, dict[str, float]]] = {}
    table_std: dict[str, dict[str, dict[str, float]]] = {}
    table_members: dict[str, dict[str, dict[str, list[float]]]] = {}
    counts: dict[str, int] = {}
    for row, mask in table_rows(test, run.unseen_objects):
        index = torch.from_numpy(mask)
        counts[row] = int(mask.sum())
        table[row], table_std[row], table_members[row] = {}, {}, {}
        for column, metrics in scores.items():
            per_member = {name: values[:, index].mean(dim=1).numpy() for name, values in metrics.items()}
            table[row][column] = {name: float(v.mean()) for name, v in per_member.items()}
            table_std[row][column] = {name: float(v.std()) for name, v in per_member.items()}
            table_members[row][column] = {name: v.tolist() for name, v in per_member.items()}

    history = run.history
    first_test = history[0].get("test", {}) if history else {}
    first = first_test.get("all", {}).get("latent_l1")
    final = distance.mean(dim=1).numpy() if distance is not None else None
    alignment: dict[str, Any] = {}
    for subset, subset_mask in evaluator.subsets.items():
        if not bool(subset_mask.any()) or distance is None:
            continue
        now = evaluator.alignment(run.engine, subset_mask)
        then = first_test.get(subset, {})
        alignment[subset] = {
            key: {"first_epoch": then.get(key), "final": now[key]}
            for key in ("latent_l1", "latent_ratio", "mixing", "mixing_expected")
        }
    result: dict[str, Any] = {
        "table1": table,
        "latent_l1": {
            "first_epoch": float(np.mean(first)) if first is not None else None,
            "final": float(final.mean()) if final is not None else None,
            "final_per_member": final.tolist() if final is not None else None,
            "definition": "mean over test contacts of the Manhattan distance between matched UniTac-NV latents "
            "(averaged over sensor pairs)",
        },
        "alignment": {
            "per_subset": alignment,
            "definition": {
                "latent_l1": "mean Manhattan distance between the two sensors' latents of the same test contact "
                "(the paper's alignment measure; it also changes with the latents' scale)",
                "latent_ratio": "mean matched L1 / mean L1 between one sensor's latent of contact i and the other's "
                "of contact j != i (scale-free: 1 = no closer than any other contact, 0 = identical)",
                "mixing": f"fraction of each latent's {MIXING_K} nearest neighbours (Euclidean, both sensors pooled) "
                "that come from the other sensor, averaged over latents",
                "mixing_expected": "the same fraction with the sensor labels shuffled (perfect mixing)",
            },
            "note": "first_epoch values are the test rows scored once after epoch 1 (per member); they are never "
            "used for a choice",
        },
        "epochs": int(run.payload["epoch"]),
        "train_seconds": float(run.payload["train_seconds"]),
        "seed": run.engine.seeds[0],
        "seeds": list(run.engine.seeds),
        "split_seed": int(config.split_seed),
        "sensors": list(run.sensors),
        "test_rows": counts,
        "simulated": bool(test.simulated),
        "dataset_hash": run.payload["dataset_hash"],
        "provenance": run.payload.get("provenance", {}),
        "preprocessing": {"scaling": config.preprocessing, "text": PREPROCESSING_TEXT[config.preprocessing]},
        "metrics": metric_description(config.nmae_normaliser, config.ssim_range),
        "normaliser": NMAE_TEXT[config.nmae_normaliser],
        "config": config.to_dict(),
    }
    variants = next((h["val_metric_variants"] for h in reversed(history) if "val_metric_variants" in h), None)
    if variants:
        result["validation_metric_variants"] = variants
    if members > 1:
        result["table1_std"] = table_std
        result["table1_members"] = table_members
    return result


def write_metrics(run_dir: Path, run: LoadedRun | None = None, test: PairedDataset | None = None) -> dict[str, Any]:
    run = run or load_run(run_dir)
    test = test or load_test_set(run_dir)
    metrics = evaluate_run(run, test)
    (Path(run_dir) / METRICS_JSON).write_text(json.dumps(metrics, indent=2) + "\n", encoding="utf-8")
    return metrics
