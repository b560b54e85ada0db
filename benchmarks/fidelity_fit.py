"""Refit the scene's existing terms to the recorded statistics: how close can they get without new physics?

    python benchmarks/fidelity_fit.py [--params a,b,...] [--rounds N] [--angles N] [--draws N] [--out docs/figures]

Coordinate descent (benchmarks/lab/fidelity.py, ``refit``) on the scene alone (no arm, no noise; the same
statistics as the ablation in benchmarks/fidelity.py) over the named parameters (default: all of
``FIT_PARAMETERS`` but the terms the scene leaves off, which are fitted only when named), starting from the
defaults. Prints the cost each round and, at the end, every target still more than 25 % off at 91 angles, and
writes OUT/fidelity_fit.json. A few minutes on one core. ``--draws N`` fits each target's median over N placement
draws instead of seed 0's one draw (N times slower) and writes OUT/fidelity_fit_draws.json.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from lab.fidelity import FIT_PARAMETERS, REL_TOLERANCE, TERMS_OFF_BY_DEFAULT, fit_evaluation, refit
from unitac_rig.bench import default_out_dir, write_json


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    default_names = [name for name in FIT_PARAMETERS if name not in TERMS_OFF_BY_DEFAULT]
    parser.add_argument("--params", default=",".join(default_names), help="comma-separated parameters to fit")
    parser.add_argument("--rounds", type=int, default=25, help="descent rounds (default 25)")
    parser.add_argument("--angles", type=int, default=31, help="approach angles while fitting (default 31)")
    parser.add_argument("--seed", type=int, default=0, help="scene seed (the first of --draws)")
    parser.add_argument("--draws", type=int, default=1, help="fit the median over this many placement draws")
    parser.add_argument("--out", type=Path, default=default_out_dir(), help="folder for the JSON")
    args = parser.parse_args()
    names = [n.strip() for n in args.params.split(",") if n.strip()]
    unknown = [n for n in names if n not in FIT_PARAMETERS]
    if unknown:
        parser.error(f"cannot fit {', '.join(unknown)}; choose from {', '.join(FIT_PARAMETERS)}")
    doc = refit(
        names,
        rounds=args.rounds,
        angles=args.angles,
        seed=args.seed,
        draws=args.draws,
        on_round=lambda i, cost, values: print(
            f"round {i}: cost {cost:.3f} " + " ".join(f"{k}={v:.3g}" for k, v in values.items()), flush=True
        ),
    )
    doc["at_91_angles"] = {}
    for label, values in (("defaults", doc["start"]["values"]), ("fitted", doc["end"]["values"])):
        cost, errors = fit_evaluation(values, angles=91, seed=args.seed, draws=args.draws)
        part = doc["at_91_angles"][label] = {"values": values, "cost": cost, "errors": errors}
        off = {k: v for k, v in part["errors"].items() if abs(v) > REL_TOLERANCE}
        print(f"{label} (91 angles): cost {part['cost']:.3f}, {len(off)} targets off by more than 25 %")
        for key, err in off.items():
            print(f"  {key} {100 * err:+.0f}%")
    name = "fidelity_fit.json" if args.draws <= 1 else "fidelity_fit_draws.json"
    print(f"wrote {write_json(doc, args.out / name)}")


if __name__ == "__main__":
    main()
