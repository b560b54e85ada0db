"""Would a uSkin baseline drift explain the lopsided recorded sessions? A probe of a term the scene leaves out.

    python benchmarks/fidelity_drift_probe.py [--draws 5] [--rates 0,0.5,1,1.5,2] [--out docs/figures]

The authors' baseline is each session's first 100 samples, so a drift shows as an offset that grows over the
session. This adds ``rate x t`` counts to the uSkin's lateral channels (x, y) of the scene-alone sweep (the presses
in session order, -45 to +45 deg, spread over the recorded session's length: ``times`` in their dataset_info.json)
and counts the uSkin min / max / |min|/max targets met per placement draw, at one rate for every session. Prints one
line per rate and writes OUT/fidelity_drift_probe.json. About 10 s per draw on one core. docs/simulator.md ("What is
left out") quotes its result; the scene itself has no drift term.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from unitac_rig.bench import default_out_dir, write_json
from unitac_rig.bench.fidelity import (
    RECORDED,
    REL_TOLERANCE,
    USKIN_MIN_MAX_RATIO,
    model_settings,
    uskin_sweep_forces,
)
from unitac_rig.sim.sensor_models import UskinModel

# Each recorded uSkin session's length, s (the last of its "times", dataset_info.json of the authors' repository).
SESSION_S = {
    "circle_pla": 647.6,
    "circle_tpu": 794.1,
    "hex_pla": 852.5,
    "hex_tpu": 1017.4,
    "square_pla": 1021.8,
    "square_tpu": 1141.8,
}
ANGLES = 91


def sweep_counts(seed: int) -> dict[str, np.ndarray]:
    """Per object, the uSkin counts (2 x angles, taxels, 3) at half and full press force, in session order."""
    scene_params, uskin_params, _ = model_settings({})
    uskin = UskinModel(uskin_params, np.random.default_rng([seed, 2]))
    forces = uskin_sweep_forces(scene_params, seed=seed, angles=ANGLES)
    return {object_id: uskin.signal_counts(f).astype(np.float64) for object_id, f in forces.items()}


def targets_met(counts: dict[str, np.ndarray], rate: float) -> tuple[int, dict[str, tuple[float, float]]]:
    """uSkin targets met with ``rate`` counts/s added to x and y over each session; -> (met, extremes per object)."""
    met, extremes = 0, {}
    for object_id, sweep in counts.items():
        t_s = np.repeat(np.linspace(0.0, SESSION_S[object_id], ANGLES), 2)
        drifted = sweep.copy()
        drifted[:, :, :2] += rate * t_s[:, None, None]
        low, high = float(drifted.min()), float(drifted.max())
        rec_low, rec_high = RECORDED[object_id]["uskin"]
        met += abs(low / rec_low - 1) <= REL_TOLERANCE
        met += abs(high / rec_high - 1) <= REL_TOLERANCE
        met += abs(low) / high >= USKIN_MIN_MAX_RATIO
        extremes[object_id] = (low, high)
    return met, extremes


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--draws", type=int, default=5, help="placement draws, seeds 0..N-1 (default 5)")
    parser.add_argument("--rates", default="0,0.5,1,1.5,2", help="drift rates to try, counts/s")
    parser.add_argument("--out", type=Path, default=default_out_dir(), help="folder for the JSON")
    args = parser.parse_args()
    try:
        rates = [float(r) for r in args.rates.split(",")]
    except ValueError:
        parser.error(f"--rates must be numbers separated by commas, got {args.rates!r}")
    if args.draws < 1:
        parser.error("--draws must be >= 1")
    draws = [sweep_counts(seed) for seed in range(args.draws)]
    rows = []
    for rate in rates:
        results = [targets_met(counts, rate) for counts in draws]
        met = [m for m, _ in results]
        square = results[0][1]["square_tpu"]
        rows.append({"rate_counts_per_s": rate, "met_per_draw": met, "square_tpu_seed0": square})
        print(f"{rate:4.1f} counts/s: {np.mean(met):4.1f} of {3 * len(RECORDED)} uSkin targets met per draw {met}; "
              f"square TPU (seed 0) {square[0]:+.0f} / {square[1]:+.0f}")  # fmt: skip
    path = write_json({"session_s": SESSION_S, "rows": rows}, args.out / "fidelity_drift_probe.json")
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
