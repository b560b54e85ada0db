"""Table I for a trained run: NMAE and SSIM per test row group (each object, all seen objects' held-out angles,
each unseen object) for every baseline and every UniTac-NV direction; latent alignment; ``RUN/metrics.json``.

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


def evaluate_run(run: LoadedRun, test: PairedDataset) -> dict[str, Any]:
    """The metrics.json content (without writing it)."""
    evaluator = Evaluator(test, run.normaliser, run.unseen_objects, torch.device("cpu"))
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
    first = history[0].get("test", {}).get("all", {}).get("latent_l1") if history else None
    final = distance.mean(dim=1).numpy() if distance is not None else None
    result: dict[str, Any] = {
        "table1": table,
        "latent_l1": {
            "first_epoch": float(np.mean(first)) if first is not None else None,
            "final": float(final.mean()) if final is not None else None,
            "final_per_member": final.tolist() if final is not None else None,
            "definition": "mean over test contacts of the Manhattan distance between matched UniTac-NV latents "
            "(averaged over sensor pairs)",
        },
        "epochs": int(run.payload["epoch"]),
        "train_seconds": float(run.payload["train_seconds"]),
        "seed": run.engine.seeds[0],
        "seeds": list(run.engine.seeds),
        "sensors": list(run.sensors),
        "test_rows": counts,
        "simulated": bool(test.simulated),
        "dataset_hash": run.payload["dataset_hash"],
        "provenance": run.payload.get("provenance", {}),
        "normaliser": "NMAE and SSIM use each sensor channel's training-set range (max - min, sensor units)",
    }
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
