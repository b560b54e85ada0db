"""Simulator fidelity report: the simulated rig's pooled signal statistics beside the authors' recorded ones.

The measuring code is benchmarks/lab/fidelity.py; the recorded numbers it compares against are carried there.

    python benchmarks/fidelity.py [--quick] [--angles N] [--seed S] [--imperfections all|none|...] [--out docs/figures]
        [--keep DIR]

Collects every object with a recorded session (circle, hexagon, square; PLA and TPU) with both sensors on the fast
simulated rig through the normal collection code, prints the table (simulated, recorded in brackets, * = outside
+-25 %) and the targets met, then switches each addition of issue 12 off in turn on the scene alone (no arm, no
noise: cheap) to show which recorded number it moves, and writes OUT/fidelity.json and OUT/fidelity.png. The full
run (91 angles, 12 sessions) takes tens of minutes on 2 busy cores (run it with ``nice -n 10``); ``--quick`` uses
15 angles and only prints (pooled extremes depend on how finely the sweep samples the worst angle, so a quick run is
indicative only).
"""

from __future__ import annotations

import argparse
from pathlib import Path

from lab.fidelity import QUICK_ANGLES, ablation_lines, plot_fidelity, run_fidelity, summary_lines
from unitac_rig.bench import default_out_dir, write_json


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--quick", action="store_true", help=f"{QUICK_ANGLES} angles; print only, write nothing")
    parser.add_argument("--angles", type=int, default=91, help="approach angles per object (default 91, as recorded)")
    parser.add_argument("--seed", type=int, default=0, help="simulated rig seed")
    parser.add_argument("--out", type=Path, default=default_out_dir(), help="folder for the JSON and PNG")
    parser.add_argument("--keep", type=Path, default=None, help="keep the session files in this folder")
    parser.add_argument(
        "--imperfections", default="all", help="the twin's imperfections (sim/imperfections.py; 'none': clean twin)"
    )
    args = parser.parse_args()
    angles = QUICK_ANGLES if args.quick else args.angles
    doc = run_fidelity(
        angles=angles,
        seed=args.seed,
        data_dir=args.keep,
        on_session=lambda obj, sensor, s: print(f"{obj} {sensor}: {s:.0f} s", flush=True),
        ablation=not args.quick,
        imperfections=args.imperfections,
    )
    for line in summary_lines(doc):
        print(line)
    if doc["ablation"] is not None:
        print("what each addition moves (scene alone, no arm or noise; set back -> final):")
        for line in ablation_lines(doc["ablation"]):
            print(line)
    if args.quick:
        return
    json_path = write_json(doc, args.out / "fidelity.json")
    png_path = plot_fidelity(doc, args.out / "fidelity.png")
    print(f"wrote {json_path} and {png_path}")


if __name__ == "__main__":
    main()
