"""Would the skin's creep make the square TPU uSkin sweep lopsided? A probe of a term the scene leaves out.

    python benchmarks/fidelity_creep_probe.py [--draws 5] [--fractions 0,0.2,0.4,0.6] [--taus 1,5,20]
        [--duty 0.3] [--reverse-order] [--out docs/figures]

The recorded square TPU session reads a maximum of 5,260 counts and a minimum of only -2,842 (max / |min| 1.85); the
scene alone gives ~1.0, because a square's tilted faces shear the skin the same way on both sides of the sweep. The
one time-dependent term a minimal model may carry (scene-facts: "one first-order relaxation term at most") is the
silicone's creep, a standard linear solid: under a held load the skin's deformation grows towards (1 + f) times
its instant value with time constant tau, and after unloading it relaxes back with the same tau. Because it carries
history from press to press along the -45..+45 deg sweep (the recorded press order), it is the one candidate that
could read one side of a sweep larger than the other.

Each press of the scene-alone sweep (half and full press force, as ``fidelity_fit.py``) is taken as loaded for
``--duty`` of a press cycle (the recorded cycles are 6-12 s, the simulated rig's press windows 2-5 s) and unloaded
for the rest; tau is in press cycles. For every (f, tau) the probe re-scans the uSkin's normal and shear gains and
keeps the pair with the smallest worst median error of the twelve uSkin min/max targets over ``--draws`` placement
draws, and reports the square TPU's max / |min| at those gains. ``--reverse-order`` presses +45 -> -45 deg instead,
in case the recorded order was the other one. Prints one line per setting and writes
OUT/fidelity_creep_probe[_reversed].json. About 30 s on one core. docs/simulator.md ("What is left out") quotes the
result; the scene has no such term.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from unitac_rig.bench import default_out_dir, write_json
from unitac_rig.bench.fidelity import (
    RECORDED,
    REL_TOLERANCE,
    best_uskin_gains,
    model_settings,
    uskin_sweep_forces,
    uskin_with_gains,
    with_creep,
)


def reversed_presses(forces: np.ndarray) -> np.ndarray:
    """The sweep pressed in the opposite order, each press still half force then full (2 x presses, taxels, 3)."""
    presses = forces.reshape(forces.shape[0] // 2, 2, *forces.shape[1:])
    return presses[::-1].reshape(forces.shape)


def square_tpu_ratio(draws: list[dict[str, np.ndarray]], gain_n: float, gain_s: float) -> float:
    """Median over the draws of the square TPU session's max / |min| in counts at these gains (recorded 1.85)."""
    ratios = []
    for seed, forces in enumerate(draws):
        counts = uskin_with_gains(gain_n, gain_s, seed).signal_counts(forces["square_tpu"])
        ratios.append(float(counts.max()) / abs(float(counts.min())))
    return float(np.median(ratios))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--draws", type=int, default=5, help="placement draws (seeds 0..N-1)")
    parser.add_argument("--fractions", default="0,0.2,0.4,0.6", help="creep fractions f, comma-separated")
    parser.add_argument("--taus", default="1,5,20", help="creep time constants, press cycles, comma-separated")
    parser.add_argument("--duty", type=float, default=0.3, help="loaded fraction of a press cycle (default 0.3)")
    parser.add_argument("--reverse-order", action="store_true", help="press +45 -> -45 deg")
    parser.add_argument("--out", type=Path, default=default_out_dir())
    args = parser.parse_args()
    scene_params, _, _ = model_settings({})
    draws = [uskin_sweep_forces(scene_params, seed=seed) for seed in range(args.draws)]
    if args.reverse_order:  # pooled extremes do not depend on the order the presses are stored in
        draws = [{k: reversed_presses(f) for k, f in d.items()} for d in draws]
    low, high = RECORDED["square_tpu"]["uskin"]
    rows = []
    for fraction in (float(f) for f in args.fractions.split(",")):
        for tau in (float(t) for t in args.taus.split(",")) if fraction else (1.0,):
            crept = [{k: with_creep(f, fraction, tau, args.duty) for k, f in d.items()} for d in draws]
            best = {"fraction": fraction, "tau_cycles": tau} | best_uskin_gains(crept)
            best["square_tpu_max_over_abs_min"] = square_tpu_ratio(crept, best["gain_normal"], best["gain_shear"])
            rows.append(best)
            misses = {k: round(v, 2) for k, v in best["median_errors"].items() if abs(v) > REL_TOLERANCE}
            print(f"f {fraction:g}, tau {tau:g} cycles: gains {best['gain_normal']:.0f} / {best['gain_shear']:.0f}, "
                  f"{best['met']} of 12 met, square TPU max/|min| {best['square_tpu_max_over_abs_min']:.2f} "
                  f"(recorded {high / abs(low):.2f}); missed {misses}", flush=True)  # fmt: skip
    doc = {"command": "python benchmarks/fidelity_creep_probe.py", "draws": args.draws, "duty": args.duty,
           "reverse_order": args.reverse_order, "recorded_square_tpu_max_over_abs_min": high / abs(low),
           "rows": rows}  # fmt: skip
    suffix = "_reversed" if args.reverse_order else ""
    print(f"wrote {write_json(doc, args.out / f'fidelity_creep_probe{suffix}.json')}")


if __name__ == "__main__":
    main()
