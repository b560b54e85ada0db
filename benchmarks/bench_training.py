"""Training speed of UniTac-NV: the stacked autograd trainer against torch.func vmap and the plain eager loop (both
over the plain per-member networks sliced out of the stacked model), at 1, 3 and 15 stacked models; the 5-seed paper
run's wall time; budget against accuracy. Measuring code: benchmarks/lab/training.py.

    nice -n 10 python benchmarks/bench_training.py [--data DIR] [--quick] [--out docs/figures]
        [--rounds 8] [--seconds-per-cell 0.6] [--paper-run-epochs 5] [--budget-epochs 100]

Data: ``--data DIR`` (session files), else synthetic contacts of the paper's size (7 objects x 91 angles x 25
targets, irregular prism x 4 rotations = 22,750 pairs, 12,300 training pairs; unitac_rig.learning.synthetic_data).
Writes OUT/bench_training.json and OUT/bench_training.png. About 3 minutes on an idle 2-core box (more under load);
``--quick`` seconds.
"""

from __future__ import annotations

import argparse
import time
from dataclasses import replace
from pathlib import Path

from drivers.layouts import PAPILLARRAY, USKIN
from lab.training import (
    full_plan,
    plot_training_benchmark,
    quick_plan,
    run_training_benchmark,
    summary_lines,
)
from unitac_rig.bench import default_out_dir, write_json
from unitac_rig.learning.data import build_paired_dataset, load_sets
from unitac_rig.learning.synthetic_data import synthetic_matched_sets

PAPER_OBJECTS = ("circle_pla", "square_pla", "hex_pla", "circle_tpu", "square_tpu", "hex_tpu", "irregular_pla")
QUICK_OBJECTS = ("circle_pla", "hex_tpu", "irregular_pla")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--data", type=Path, default=None, help="session files (default: paper-sized synthetic)")
    parser.add_argument("--quick", action="store_true", help="smoke run: small data, short timings")
    parser.add_argument("--out", type=Path, default=default_out_dir(), help="folder for the JSON and PNG")
    parser.add_argument("--rounds", type=int, default=None)
    parser.add_argument("--seconds-per-cell", type=float, default=None)
    parser.add_argument("--paper-run-epochs", type=int, default=None)
    parser.add_argument("--budget-epochs", type=int, default=None, help="0 skips the budget/accuracy run")
    args = parser.parse_args()

    plan = quick_plan() if args.quick else full_plan()
    overrides = {
        "rounds": args.rounds,
        "seconds_per_cell": args.seconds_per_cell,
        "paper_run_epochs": args.paper_run_epochs,
        "budget_epochs": args.budget_epochs,
    }
    plan = replace(plan, **{k: v for k, v in overrides.items() if v is not None})

    began = time.perf_counter()
    if args.data:
        sets, source = load_sets(args.data), str(args.data)
    elif args.quick:
        angles = tuple(float(a) for a in range(-45, 46, 9))
        sets = synthetic_matched_sets(
            QUICK_OBJECTS, [USKIN, PAPILLARRAY], angles_deg=angles, targets_n=(4.0, 7.0, 10.0)
        )
        source = "synthetic (unitac_rig.learning.synthetic_data), small"
    else:
        sets = synthetic_matched_sets(PAPER_OBJECTS, [USKIN, PAPILLARRAY])
        source = "synthetic (unitac_rig.learning.synthetic_data), paper-sized"
    dataset = build_paired_dataset(sets)
    print(f"data ready in {time.perf_counter() - began:.1f} s")

    doc = run_training_benchmark(dataset, source, plan)
    for line in summary_lines(doc):
        print(line)
    json_path = write_json(doc, args.out / "bench_training.json")
    png_path = plot_training_benchmark(doc, args.out / "bench_training.png")
    print(f"wrote {json_path} and {png_path} ({time.perf_counter() - began:.0f} s in all)")


if __name__ == "__main__":
    main()
