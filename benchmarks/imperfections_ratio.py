"""The unseen/seen NMAE ratio per Table I column of trained runs, beside the paper's (issue 38's held-out check).

    python benchmarks/imperfections_ratio.py [LABEL=RUN ...] [--data LABEL=DATA ...] [--scene LABEL=K=V,K=V ...]
        [--out FILE.json]

Each RUN is a ``unitac-rig train`` run directory (its ``metrics.json``), e.g. one trained on a campaign of the
realistic twin (``unitac-rig campaign --angles 9``) and one on the clean twin (``--imperfections none``). The check:
every column's ratio (unseen irregular prism / all seen objects) within a factor 1.5 of the paper's.

``--data LABEL=DATA`` (a campaign's session folder) adds how far the unseen prism's contacts lie from the seen
objects' in the data itself, before any training: each contact's nearest seen contact of another press (mean absolute
difference over the channels, each scaled by its range over the dataset), the unseen prism's median against a seen
object's (every third contact). A ratio near 1 says the unseen object's readings are no further from what training
sees than a held-out angle of a seen object is.

``--scene LABEL=KEY=VALUE,...`` (``LABEL=`` alone: the scene as it is) screens a scene mechanism in seconds: the same
distance on the scene's own loads (and pillar displacements), no sensor model, no noise, every object at its
rotations, 9 angles over +-45 deg (``--scene-angles``), 10 forces 2-11 N, with those :class:`SceneParams` fields
changed (seed 0). The ratio grows with the angles: a held-out seen angle has nearer neighbours.
"""

from __future__ import annotations

import argparse
import json
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from unitac_rig.bench import write_json
from unitac_rig.learning.paper import PAPER_TABLE1, TABLE1_COLUMNS
from unitac_rig.rig.objects import list_objects
from unitac_rig.sim.fast_rig import seeded_scene
from unitac_rig.sim.scene_params import SceneParams
from unitac_rig.storage.paired import build_paired_dataset, load_sets

COLUMNS = TABLE1_COLUMNS
SEEN, UNSEEN = "all_seen", "irregular_pla"
FACTOR = 1.5  # the tolerance on each column's ratio


def paper_ratios() -> dict[str, float]:
    return {c: PAPER_TABLE1[UNSEEN][c][0] / PAPER_TABLE1[SEEN][c][0] for c in COLUMNS}


def run_ratios(metrics: dict[str, Any]) -> dict[str, Any]:
    """Seen and unseen NMAE per column of one run's metrics.json, their ratio, and whether it is within FACTOR."""
    table = metrics["table1"]
    paper = paper_ratios()
    out: dict[str, Any] = {}
    for c in COLUMNS:
        seen, unseen = table[SEEN][c]["nmae"], table[UNSEEN][c]["nmae"]
        ratio = unseen / seen
        out[c] = {
            "seen_nmae": seen,
            "unseen_nmae": unseen,
            "ratio": ratio,
            "paper_ratio": paper[c],
            "within": bool(1 / FACTOR <= ratio / paper[c] <= FACTOR),
        }
    return out


def nearest_seen_distance(data_dir: Path) -> dict[str, dict[str, float]]:
    """Per sensor: the median distance of seen and of unseen contacts to their nearest seen contact of another
    press (channel-range units), and unseen / seen."""
    ds = build_paired_dataset(load_sets(data_dir))
    unseen = ds.object_id == UNSEEN
    press = np.array([f"{o}|{r:g}|{a:g}" for o, r, a in zip(ds.object_id, ds.rotation_deg, ds.angle_deg, strict=True)])
    return {
        sensor: _distance_ratio(ds.values[sensor].reshape(len(ds), -1), press, unseen, step=3) for sensor in ds.sensors
    }


def scene_distance(
    changes: dict[str, float], angles: int = 9, sensors: tuple[str, ...] = ("uskin", "papillarray")
) -> dict[str, Any]:
    """:func:`nearest_seen_distance` on the scene's own loads (the ``--scene`` screen), ``changes`` applied to
    :class:`SceneParams`: every contact counts (no sampling), the press ids as in a campaign."""
    params = replace(SceneParams(), **changes)  # type: ignore[arg-type]  # field names checked by SceneParams
    out: dict[str, Any] = {"changes": changes, "angles": angles}
    for sensor in sensors:
        rows, press, unseen = [], [], []
        for obj in list_objects():
            for rotation in obj.rotations_deg:
                scene = seeded_scene(obj, rotation, sensor, seed=0, params=params)
                for angle in np.linspace(-45.0, 45.0, angles):
                    for force in np.linspace(2.0, 11.0, 10):
                        loads = scene.loads_at_force(float(angle), float(force))
                        parts = [loads.forces_n] + ([] if loads.displacement_mm is None else [loads.displacement_mm])
                        rows.append(np.concatenate([v.ravel() for v in parts]))
                        press.append(f"{obj.id}|{rotation:g}|{angle:g}")
                        unseen.append(obj.id == UNSEEN)
        out[sensor] = _distance_ratio(np.array(rows), np.array(press), np.array(unseen))
    return out


def _distance_ratio(x: np.ndarray, press: np.ndarray, unseen: np.ndarray, step: int = 1) -> dict[str, float]:
    """Median distance (mean |difference| over the channels, each scaled by its range) of every ``step``-th seen and
    unseen row to its nearest seen row of another press; their ratio."""
    x = x.astype(np.float64)
    span = x.max(axis=0) - x.min(axis=0)
    x = x / np.where(span > 0, span, 1.0)
    seen_rows = np.flatnonzero(~unseen)

    def nearest(i: int) -> float:
        others = seen_rows[press[seen_rows] != press[i]]
        return float(np.min(np.abs(x[others] - x[i]).mean(axis=1)))

    seen_d = float(np.median([nearest(i) for i in seen_rows[::step]]))
    unseen_d = float(np.median([nearest(i) for i in np.flatnonzero(unseen)[::step]]))
    return {"seen": seen_d, "unseen": unseen_d, "ratio": unseen_d / seen_d}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("runs", nargs="*", metavar="LABEL=RUN")
    parser.add_argument("--data", action="append", default=[], metavar="LABEL=DATA", help="a campaign's sessions")
    parser.add_argument(
        "--scene", action="append", default=[], metavar="LABEL=K=V,...", help="screen scene parameter changes"
    )
    parser.add_argument("--scene-angles", type=int, default=9, help="approach angles of the --scene screen")
    parser.add_argument("--out", type=Path, default=None, help="write the table as JSON here")
    args = parser.parse_args()
    doc: dict[str, Any] = {
        "what": "unseen/seen NMAE ratio per Table I column (issue 38)",
        "runs": {},
        "data": {},
        "scene": {},
    }
    for item in args.scene:
        label, _, spec = item.partition("=")
        changes = {k: float(v) for k, _, v in (c.partition("=") for c in spec.split(",") if c)}
        doc["scene"][label] = screened = scene_distance(changes, args.scene_angles)
        screen = "  ".join(f"{sensor} x{screened[sensor]['ratio']:.2f}" for sensor in ("uskin", "papillarray"))
        print(f"scene {label} {changes}: nearest seen contact, unseen / seen {screen}")
    for item in args.data:
        label, _, data_dir = item.partition("=")
        doc["data"][label] = distances = nearest_seen_distance(Path(data_dir))
        for sensor, d in distances.items():
            print(
                f"{label} {sensor}: nearest seen contact, seen {d['seen']:.4f} unseen {d['unseen']:.4f}"
                f" (x{d['ratio']:.2f})"
            )
    for item in args.runs:
        label, _, run = item.partition("=")
        metrics = json.loads((Path(run) / "metrics.json").read_text())
        ratios = run_ratios(metrics)
        doc["runs"][label] = {"epochs": metrics.get("epochs"), "seed": metrics.get("seed"), "columns": ratios}
        print(f"{label} ({metrics.get('epochs')} epochs, seed {metrics.get('seed')})")
        for c, r in ratios.items():
            mark = "" if r["within"] else " *"
            print(
                f"  {c:28s} seen {r['seen_nmae']:.4f} unseen {r['unseen_nmae']:.4f}"
                f" ratio {r['ratio']:.2f} (paper {r['paper_ratio']:.2f}){mark}"
            )
    if args.out is not None:
        print(f"wrote {write_json(doc, args.out)}")


if __name__ == "__main__":
    main()
