"""Which fidelity misses are the model's and which the seeded draw's: the min/max targets over many placement draws.

    python benchmarks/fidelity_draws.py [--draws 10] [--angles 91] [--set NAME=VALUE ...] [--out docs/figures]

The simulated rig draws one centring error per object placement and one pad pitch per sensor mount from its seed, so
the fidelity report (benchmarks/fidelity.py, one seed) sees one draw; a circle's extremes in particular move with
where the contact lands on the pad. This repeats the scene-alone statistics (no arm, no noise, as the ablation) for
seeds 0..N-1 and prints, per target still missed in any draw, the median and range of its relative error and in how
many draws it misses. Writes OUT/fidelity_draws.json. About 2 s per draw on one core (~15 s with the bending on).

``--set`` runs the same count with the model changed (a term the scene leaves off switched on, a parameter moved:
any SceneParams or UskinParams field, or MATERIAL.field) and writes OUT/fidelity_draws_<settings>.json instead, e.g.
``--set bending_lever_mm=90`` or ``--set rotation_error_deg=2``; how docs/simulator.md's "What is left out"
rows were measured.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from lab.fidelity import draw_spread, model_settings
from unitac_rig.bench import default_out_dir, write_json
from unitac_rig.errors import ConfigError


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--draws", type=int, default=10, help="seeds 0..N-1 (default 10)")
    parser.add_argument("--angles", type=int, default=91, help="approach angles (default 91)")
    parser.add_argument(
        "--set", dest="settings", action="append", default=[], metavar="NAME=VALUE", help="change one model parameter"
    )
    parser.add_argument("--out", type=Path, default=default_out_dir(), help="folder for the JSON")
    args = parser.parse_args()
    settings: dict[str, float] = {}
    for item in args.settings:
        name, _, value = item.partition("=")
        try:
            settings[name.strip()] = float(value)  # no "=" leaves value empty: not a number either
        except ValueError:
            parser.error(f"--set wants NAME=NUMBER, got {item!r}")
    try:
        model_settings(settings)
    except ConfigError as exc:
        parser.error(str(exc))
    doc = draw_spread(range(args.draws), angles=args.angles, settings=settings)
    print(f"targets met per draw (of {doc['targets_per_draw']}): {doc['met_per_draw']}")
    missed = sorted(doc["targets"].items(), key=lambda kv: -kv[1]["missed_in"])
    for key, row in missed:
        if row["missed_in"]:
            print(
                f"{key:34s} missed in {row['missed_in']:2d}/{len(doc['seeds'])}  median {row['median']:+.0%}"
                f"  range {row['min']:+.0%} .. {row['max']:+.0%}"
            )
    suffix = "".join(f"_{name}={value:g}" for name, value in sorted(settings.items()))
    print(f"wrote {write_json(doc, args.out / f'fidelity_draws{suffix}.json')}")


if __name__ == "__main__":
    main()
