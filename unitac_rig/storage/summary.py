"""Summaries of a dataset directory: per session progress and matching quality, and per object the cross-sensor join."""

from __future__ import annotations

from collections import defaultdict
from pathlib import Path
from typing import Any

import numpy as np

from unitac_rig.storage.lease import lease_holder
from unitac_rig.storage.reader import list_sessions, press_counts, press_summaries, rig_label
from unitac_rig.storage.recorder import journal_dir


def _stats(values: list[float], keys: tuple[str, ...]) -> dict[str, float | None]:
    if not values:
        return dict.fromkeys(keys)
    arr = np.asarray(values, dtype=np.float64)
    stats = {"median": np.median(arr), "p95": np.percentile(arr, 95), "max": np.max(arr)}
    return {k: round(float(stats[k]), 4) for k in keys}


def inspect_dataset(data_dir: Path) -> dict[str, Any]:
    """The ``inspect --json`` document (see docs/dataset.md for every key)."""
    sessions = []
    # object -> (rig, sensor) -> join keys: pairs join only within one rig (unitac_rig.storage.paired)
    keys_by_object: dict[str, dict[tuple[str, str], set[tuple[float, float, float]]]] = defaultdict(dict)
    for info in list_sessions(data_dir):
        presses = press_summaries(info.path)
        counts = press_counts(info.attrs, presses)
        complete = [p for p in presses if p["status"] == "complete"]
        errors: list[float] = []
        matched = missed = 0
        keys: set[tuple[float, float, float]] = set()
        for p in complete:
            ex = p["extraction"]
            if ex is None:
                continue
            hit = ~ex.miss
            matched += int(hit.sum())
            missed += int(ex.miss.sum())
            errors.extend(np.abs(ex.error_n[hit]).tolist())
            for target in ex.targets_n[hit]:
                keys.add((float(p["rotation_deg"]), float(p["angle_deg"]), round(float(target), 2)))
        rig = rig_label(info.attrs)
        keys_by_object[info.object_id][(rig, info.sensor)] = keys
        peaks = [float(p.get("peak_force_n", np.nan)) for p in complete if "peak_force_n" in p]
        sessions.append(
            {
                "object": info.object_id,
                "sensor": info.sensor,
                "simulated": info.simulated,
                "rig": rig,  # which rig recorded it ("simulated: <name>", "hardware: <name>", "imported: ..."), or ""
                "file": info.path.name,
                # "verified" (every press matched its checksums), "repaired from the journal, ...", or why not
                "integrity": info.integrity,
                **{f"presses_{k}": n for k, n in counts.items()},
                "targets_matched": matched,
                "targets_missed": missed,
                "match_error_n": _stats(errors, ("median", "p95", "max")),
                "peak_force_n": _stats(peaks, ("median", "max")),
                "duration_s": round(float(sum(float(p.get("duration_s", 0.0)) for p in presses)), 3),
                # who holds the session's write lease now (pid, host, command, since_unix), None when nobody writes
                "writer": lease_holder(journal_dir(Path(data_dir), info.object_id, info.sensor)),
            }
        )
    pairs = {}
    for object_id, by_rig_sensor in sorted(keys_by_object.items()):
        total = 0
        for rig in {r for r, _ in by_rig_sensor}:
            sets = [keys for (r, _), keys in by_rig_sensor.items() if r == rig]
            total += len(set.intersection(*sets)) if len(sets) > 1 else 0
        pairs[object_id] = total
    return {"sessions": sessions, "pairs": pairs}
