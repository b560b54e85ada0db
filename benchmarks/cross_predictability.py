"""What one sensor's frame determines of the other's: the ceiling on cross-sensor reconstruction, per channel.

The measuring code is benchmarks/lab/cross_sensor.py.

    python benchmarks/cross_predictability.py [--quick] [--seeds 0,1] [--out docs/figures]

For matched contacts of the six seen objects on the noise-free simulated scene (no arm, no autoencoder), fits an MLP
from one sensor's whole frame to the other's on 82 of the 91 approach angles and scores the 9 held out, per force
channel, as R^2. Repeats with each of the scene's seeded errors switched (the centring error drawn per session as
the rig did before, shared by both sensors as now, or off; the pad pitch, skin bulge and TPU drag off) to say which
one takes information away. Writes OUT/cross_predictability.json and OUT/cross_predictability.png. About 2-3 min per
variant and rig seed on one core; ``--quick`` uses 31 angles, 500 steps and the first two variants, and only prints.
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from lab.cross_sensor import CHANNELS, VARIANTS, plot_cross_predictability, run_cross_predictability
from unitac_rig.bench import default_out_dir, write_json


def _line(name: str, result: dict[str, Any]) -> str:
    cells = [
        f"{direction.replace('papillarray', 'p').replace('uskin', 'u').replace('_to_', '->')} "
        + "/".join(f"{result['mean'][direction][c]:.3f}" for c in CHANNELS)
        for direction in result["mean"]
    ]
    return f"{name:32s} " + "   ".join(cells) + f"   ({result['seconds']:.0f} s)"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--quick", action="store_true", help="31 angles, 500 steps, two variants; print only")
    parser.add_argument("--seeds", default="0,1", help="comma-separated simulated rig seeds (default 0,1)")
    parser.add_argument("--out", type=Path, default=default_out_dir(), help="folder for the JSON and PNG")
    args = parser.parse_args()
    seeds = [int(s) for s in args.seeds.split(",") if s.strip()]
    print("R^2 on held-out angles, x/y/z, mean over rig seeds", flush=True)
    doc = run_cross_predictability(
        variants=list(VARIANTS)[:2] if args.quick else list(VARIANTS),
        rig_seeds=seeds,
        angles=31 if args.quick else 91,
        steps=500 if args.quick else 2000,
        on_variant=lambda name, result: print(_line(name, result), flush=True),
    )
    if args.quick:
        return
    json_path = write_json(doc, args.out / "cross_predictability.json")
    png_path = plot_cross_predictability(doc, args.out / "cross_predictability.png")
    print(f"wrote {json_path} and {png_path}")


if __name__ == "__main__":
    main()
