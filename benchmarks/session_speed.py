"""Issue 27's "done when" for the press: ``collect --object hex_tpu`` twice on the simulated rig, measured.

    python benchmarks/session_speed.py [--object hex_tpu] [--seed 0] [--angles 91] [--out docs/figures]

Runs what ``unitac-rig collect --object hex_tpu`` runs with no rig file (the default press, the first session with the
uSkin, the second with the PapillArray: "swap sensors and rerun"), on the fast twin, and measures per session:

* rig time: simulated seconds from the first motion to the end of the last press (what a lab pays for);
* targets matched of those planned (25 per press), the median measured matching error (what the recording says);
* the median TRUE matching error: the simulator's own press force at each matched frame minus its target;
* the largest true |F| on the pad over the whole session;
* the same two errors re-extracted with the old method (moving average), for comparison;
* where a press's time goes (zero, approach, load, stop + dwell + retract + return), and CPU seconds.

Writes OUT/session_speed.json. About 5-10 CPU-minutes.
"""

from __future__ import annotations

import argparse
import math
import multiprocessing
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

import numpy as np

from drivers.clock import VirtualClock
from unitac_rig.bench import default_out_dir, machine_info, write_json
from unitac_rig.collection.session import collect_session
from unitac_rig.rig.config import RigConfig
from unitac_rig.rig.objects import get_object
from unitac_rig.rig.poses import tool_z
from unitac_rig.sim.fast_rig import SimRig
from unitac_rig.storage.extraction import ExtractionSettings, extract_press
from unitac_rig.storage.reader import read_presses
from unitac_rig.storage.recorder import session_path

GOALS: dict[str, float] = {
    "rig_time_s": 300.0,
    "median_error_n": 0.05,
    "true_median_error_n": 0.1,
    "peak_force_n": 12.0,
}


class Truth:
    """Clock listener: the simulator's true press force along the tool's z axis (N) at every step, and the largest
    true |F| on the pad."""

    def __init__(self, rig: SimRig) -> None:
        self.rig = rig
        self.t_s: list[float] = []
        self.press_n: list[float] = []
        self.peak_n = 0.0
        assert isinstance(rig.clock, VirtualClock)
        rig.clock.on_advance(self)

    def __call__(self, now_ns: int) -> None:
        arm = self.rig.sim_arm
        wrench = np.asarray(arm.true_wrench(), dtype=np.float64)
        self.peak_n = max(self.peak_n, float(np.linalg.norm(wrench[:3])))
        self.t_s.append(now_ns / 1e9)
        self.press_n.append(-float(wrench[:3] @ tool_z(arm.read_state().tcp_pose)))


def run_session(config: RigConfig, object_id: str, sensor: str, data: Path, seed: int) -> dict[str, Any]:
    obj = get_object(object_id)
    cpu = time.process_time()
    rig = SimRig(config, seed=seed)
    with rig:
        truth = Truth(rig)
        began = rig.clock.now_ns()
        outcome = collect_session(rig, obj, sensor, data)
        rig_time_s = (rig.clock.now_ns() - began) / 1e9
    cpu = time.process_time() - cpu
    presses = read_presses(session_path(data, object_id, sensor))
    truth_t, truth_f = np.asarray(truth.t_s), np.asarray(truth.press_n)
    old = ExtractionSettings(method="moving-average")
    errors: dict[str, list[np.ndarray]] = {"measured": [], "true": [], "old_measured": [], "old_true": []}
    matched = targets = old_matched = 0
    phases: dict[str, list[float]] = {}
    missed: list[dict[str, Any]] = []
    for press in presses:
        frame_t = np.asarray(press.tactile_t_s)
        # what the session stored, recomputed from its raw streams with its default settings (`unitac-rig extract`)
        ex = extract_press(press.robot_t_s, press.press_force_n, frame_t, press.tactile_valid, ExtractionSettings())
        ok = ~ex.miss
        if not ok.all():
            missed.append(
                {
                    "press": press.press_id,
                    "status": press.status,
                    "targets_n": ex.targets_n[~ok].tolist(),
                    "error_n": ex.error_n[~ok].tolist(),
                }
            )
        matched += int(ok.sum())
        targets += ex.targets_n.size
        errors["measured"].append(np.abs(ex.error_n[ok]))
        errors["true"].append(np.abs(np.interp(frame_t[ex.frame_index[ok]], truth_t, truth_f) - ex.targets_n[ok]))
        legacy = extract_press(press.robot_t_s, press.press_force_n, frame_t, press.tactile_valid, old)
        ok = ~legacy.miss
        old_matched += int(ok.sum())
        errors["old_measured"].append(np.abs(legacy.error_n[ok]))
        errors["old_true"].append(
            np.abs(np.interp(frame_t[legacy.frame_index[ok]], truth_t, truth_f) - legacy.targets_n[ok])
        )
        for name, seconds in press_phases(press.events, press.robot_t_s).items():
            phases.setdefault(name, []).append(seconds)
    pooled = {k: np.concatenate(v) if v else np.zeros(0) for k, v in errors.items()}
    medians = {k: median(v) for k, v in pooled.items()}
    row: dict[str, Any] = {
        "sensor": sensor,
        "presses": len(presses),
        "complete": sum(p.status == "complete" for p in presses),
        "stopped": outcome.stopped,
        "rig_time_s": rig_time_s,
        "per_press_s": rig_time_s / max(1, len(presses)),
        "targets": targets,
        "matched": matched,
        "median_error_n": median(pooled["measured"]),
        "true_median_error_n": median(pooled["true"]),
        "true_p95_error_n": float(np.percentile(pooled["true"], 95)) if pooled["true"].size else math.nan,
        "peak_force_n": truth.peak_n,
        "old_method": {
            "matched": old_matched,
            "median_error_n": median(pooled["old_measured"]),
            "true_median_error_n": median(pooled["old_true"]),
        },
        "missed": missed,
        "phases_mean_s": {k: float(np.mean(v)) for k, v in phases.items()},
        "cpu_s": cpu,
    }
    row["meets"] = {
        "rig_time": rig_time_s <= GOALS["rig_time_s"],
        "all_matched": matched == targets and targets == 25 * len(presses),
        "median_error": medians["measured"] <= GOALS["median_error_n"],
        "true_median_error": medians["true"] <= GOALS["true_median_error_n"],
        "peak_force": truth.peak_n <= GOALS["peak_force_n"],
    }
    return row


def press_phases(events: list[tuple[float, str, str]], robot_t: np.ndarray) -> dict[str, float]:
    """Where one press's recorded time went (s): approach (start to first contact), load (contact to the stop),
    after (stop, dwell, retract and the return to the stand-off, to the last recorded reading)."""
    first: dict[str, float] = {}
    for t, kind, _ in events:
        first.setdefault(kind, t)
    end = float(robot_t[-1]) if len(robot_t) else math.nan
    marks = [first.get("start", math.nan), first.get("contact", math.nan), first.get("stop", math.nan), end]
    return {name: marks[i + 1] - marks[i] for i, name in enumerate(("approach", "load", "after"))}


def median(values: np.ndarray) -> float:
    return float(np.median(values)) if values.size else math.nan


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--object", default="hex_tpu")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--angles", type=int, default=None, help="fewer approach angles for a smoke run")
    parser.add_argument("--out", type=Path, default=default_out_dir())
    args = parser.parse_args()
    config = RigConfig()
    if args.angles is not None:
        config = config.model_copy(update={"press": config.press.model_copy(update={"angle_count": args.angles})})
    with tempfile.TemporaryDirectory() as tmp:
        # `collect` twice: the second run mounts the other sensor. The two sessions share nothing but the data
        # folder, so they run side by side (simulated time does not depend on it).
        context = multiprocessing.get_context("spawn")
        with ProcessPoolExecutor(max_workers=2, mp_context=context) as pool:
            futures = [
                pool.submit(run_session, config, args.object, sensor, Path(tmp), args.seed)
                for sensor in ("uskin", "papillarray")
            ]
            rows = [future.result() for future in futures]
    for r in rows:
        print(
            f"{args.object} {r['sensor']}: {r['presses']} presses in {r['rig_time_s']:.1f} s rig time "
            f"({r['per_press_s']:.2f} s/press), {r['matched']}/{r['targets']} targets, median error "
            f"{r['median_error_n']:.3f} N measured / {r['true_median_error_n']:.3f} N true (old method "
            f"{r['old_method']['median_error_n']:.3f} / {r['old_method']['true_median_error_n']:.3f}), peak "
            f"{r['peak_force_n']:.2f} N, {r['cpu_s']:.0f} CPU-s; phases "
            + ", ".join(f"{k} {v:.2f} s" for k, v in r["phases_mean_s"].items())
        )
    doc = {
        "benchmark": "session_speed",
        "machine": machine_info(),
        "object": args.object,
        "seed": args.seed,
        "press": config.press.model_dump(mode="json"),
        "goals": GOALS,
        "sessions": rows,
        "all_met": all(all(r["meets"].values()) for r in rows),
    }
    print(f"all goals met: {doc['all_met']}")
    print(f"wrote {write_json(doc, args.out / 'session_speed.json')}")


if __name__ == "__main__":
    main()
