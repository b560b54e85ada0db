"""Encode / decode / translate latency against the 1 ms budget of a 1000 Hz stream (unitac_rig/bench/inference.py).

    python benchmarks/bench_inference.py [--quick] [--run RUN] [--out docs/figures]

Without --run a tiny UniTac-NV model is trained first on synthetic force-matched sets (a few seconds; the network's
size, not its weights, decides the latency). Times one frame and batches of 4..1024 frames through the public
Translator API on the CPU, at 1 torch thread and at torch's default. Writes OUT/bench_inference.json and
OUT/bench_inference.png. About 30 s; ``--quick`` a few seconds.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from unitac_rig.bench import default_out_dir, write_json
from unitac_rig.bench.inference import (
    full_plan,
    plot_inference_benchmark,
    quick_plan,
    run_inference_benchmark,
    summary_lines,
)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--quick", action="store_true", help="smoke run: three batch sizes, short timings")
    parser.add_argument("--run", type=Path, default=None, help="a trained run directory (unitac-rig train --out)")
    parser.add_argument("--out", type=Path, default=default_out_dir(), help="folder for the JSON and PNG")
    args = parser.parse_args()
    doc = run_inference_benchmark(quick_plan() if args.quick else full_plan(), args.run)
    for line in summary_lines(doc):
        print(line)
    json_path = write_json(doc, args.out / "bench_inference.json")
    png_path = plot_inference_benchmark(doc, args.out / "bench_inference.png")
    print(f"wrote {json_path} and {png_path}")


if __name__ == "__main__":
    main()
