"""Press strategy and speed against force-matching accuracy on the simulated rig.

The measuring code is unitac_rig/bench/press_benchmark.py (scoring in press_scoring.py, figure in press_report.py).

    python benchmarks/bench_press.py [--quick] [--jobs 2] [--out docs/figures]

Runs guarded at 1-8 mm/s, two-phase at 1-3 mm/s after a 15 mm/s approach and force-ramp at 2-32 N/s on hex_pla and
hex_tpu with both sensors, 5 angles and 2 seeds (PapillArray at 100 and 1000 Hz), then scores every extraction
variant. Prints the tables, writes OUT/bench_press.json and OUT/bench_press.png. About 5 minutes on 2 cores;
``--quick`` (one object, two angles, four settings) takes a few seconds.
"""

from __future__ import annotations

import argparse
import os
from pathlib import Path

from unitac_rig.bench import default_out_dir, write_json
from unitac_rig.bench.press_benchmark import full_plan, quick_plan, run_press_benchmark
from unitac_rig.bench.press_report import plot_press_benchmark, summary_lines


def progress(done: int, total: int) -> None:
    print(f"\r{done}/{total} rig sessions", end="", flush=True)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--quick", action="store_true", help="smoke run: one object, two angles, four settings")
    parser.add_argument("--jobs", type=int, default=os.cpu_count() or 1, help="processes (default: all CPUs)")
    parser.add_argument("--out", type=Path, default=default_out_dir(), help="folder for the JSON and PNG")
    args = parser.parse_args()
    plan = quick_plan() if args.quick else full_plan()
    doc = run_press_benchmark(
        plan, jobs=args.jobs, on_cell=lambda done, total: print(f"\r{done}/{total} rig sessions", end="", flush=True)
    )
    print()
    for line in summary_lines(doc):
        print(line)
    json_path = write_json(doc, args.out / "bench_press.json")
    png_path = plot_press_benchmark(doc, args.out / "bench_press.png")
    print(f"wrote {json_path} and {png_path}")


if __name__ == "__main__":
    main()
