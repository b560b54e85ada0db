"""Would a non-linear uSkin taxel close the polygon maxima and the square TPU pair? A probe of a term the scene
leaves out.

    python benchmarks/fidelity_hall_probe.py [--draws 5] [--strains 0,0.1,0.12,0.14] [--bending-lever-mm 70]
        [--out docs/figures]

Each uSkin taxel reads a magnet through a Hall sensor; as the skin under it compresses, the magnet comes closer and
the field grows as the inverse cube of the distance, so the normal reading rises faster than the load. With a
compression of ``c`` (fraction of the magnet's height per newton on the taxel, capped at 0.9) the normal signal is
``gain x F x ((1 - cF)^-3 - 1) / (3cF)`` (``gain x F`` as c -> 0). The recorded maxima point that way: the scene's
circle maxima are 15-18 % above the recorded ones and its polygon maxima 20-28 % below, and a polygon corner loads a
taxel ~1.5x as hard as a circle does. For each strain the probe re-scans the normal and shear gains (a grid) and
keeps the pair with the smallest worst median error of the twelve uSkin min/max targets over ``--draws`` placement
draws (scene alone, as ``fidelity_fit.py``). ``--bending-lever-mm`` switches on the prism's bending (off in the
scene), which concentrates a TPU face press on the pad's bottom row. Prints one line per strain and writes
OUT/fidelity_hall_probe[_bending_lever_mm=L].json.
About 2 min on one core. docs/simulator.md ("What is left out") quotes its result; the scene has no such term.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from unitac_rig.bench import default_out_dir, write_json
from unitac_rig.bench.fidelity import REL_TOLERANCE, best_uskin_gains, model_settings, uskin_sweep_forces


def hall_factor(normal_n: np.ndarray, strain_per_n: float) -> np.ndarray:
    """Reading / linear reading of a taxel whose magnet closes in by ``strain_per_n`` of its height per newton."""
    eps = np.clip(strain_per_n * np.clip(normal_n, 0.0, None), 0.0, 0.9)
    safe = np.where(eps > 1e-9, eps, 0.5)  # any value away from 0 and 1: those entries are replaced below
    return np.where(eps > 1e-9, ((1.0 - safe) ** -3 - 1.0) / (3.0 * safe), 1.0)


def sweep_forces(seed: int, bending_lever_mm: float = 0.0) -> dict[str, np.ndarray]:
    """Per object, the uSkin taxel forces (2 x angles, taxels, 3) N of the scene-alone sweep."""
    scene_params, _, _ = model_settings({"bending_lever_mm": bending_lever_mm} if bending_lever_mm else {})
    return uskin_sweep_forces(scene_params, seed=seed)


def with_hall(forces: dict[str, np.ndarray], strain: float) -> dict[str, np.ndarray]:
    """The forces with each taxel's normal load scaled by :func:`hall_factor` (what the linear gain then reads)."""
    out = {}
    for object_id, f in forces.items():
        bent = f.copy()
        bent[..., 2] *= hall_factor(f[..., 2], strain)
        out[object_id] = bent
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--draws", type=int, default=5, help="placement draws (seeds 0..N-1)")
    parser.add_argument("--strains", default="0,0.1,0.12,0.14", help="compression per newton, comma-separated")
    parser.add_argument("--bending-lever-mm", type=float, default=0.0, help="prism bending lever (0: off)")
    parser.add_argument("--out", type=Path, default=default_out_dir())
    args = parser.parse_args()
    strains = [float(s) for s in args.strains.split(",")]
    draws = [sweep_forces(seed, args.bending_lever_mm) for seed in range(args.draws)]
    rows = []
    for strain in strains:
        bent_draws = [with_hall(f, strain) for f in draws]  # the same for every gain pair
        best = {"strain_per_n": strain} | best_uskin_gains(bent_draws)
        rows.append(best)
        misses = {k: round(v, 2) for k, v in best["median_errors"].items() if abs(v) > REL_TOLERANCE}
        print(f"strain {strain:g}/N: gains {best['gain_normal']:.0f} / {best['gain_shear']:.0f}, "
              f"{best['met']} of 12 met, worst {best['worst']:+.2f}; missed {misses}", flush=True)  # fmt: skip
    suffix = f"_bending_lever_mm={args.bending_lever_mm:g}" if args.bending_lever_mm else ""
    doc = {"command": "python benchmarks/fidelity_hall_probe.py", "draws": args.draws,
           "bending_lever_mm": args.bending_lever_mm, "rows": rows}  # fmt: skip
    print(f"wrote {write_json(doc, args.out / f'fidelity_hall_probe{suffix}.json')}")


if __name__ == "__main__":
    main()
