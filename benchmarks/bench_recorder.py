"""The data path against the hardware's rates (see unitac_rig/bench/recorder.py).

    python benchmarks/bench_recorder.py [--quick] [--out docs/figures] [--work-dir DIR]

1. SessionWriter.write_press (journal + fsync + session file) on 1.5, 4 and 8 s presses carrying the robot at
   500 Hz and the PapillArray at 1000 Hz or the uSkin at 100 Hz; read back, compared array by array (frames lost
   must be 0); headroom = stream seconds per second of writing (goal >= 10x).
2. A simulated PapillArray hub streaming at 1000 Hz in real time, read by the driver's reader thread for 5 s:
   frames sent vs delivered, counter gaps.

Writes OUT/bench_recorder.json and OUT/bench_recorder.png. About 15 s; ``--quick`` a few seconds.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from unitac_rig.bench import default_out_dir, write_json
from unitac_rig.bench.recorder import (
    full_plan,
    plot_recorder_benchmark,
    quick_plan,
    run_recorder_benchmark,
    summary_lines,
)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--quick", action="store_true", help="smoke run: two press lengths, 1 s live")
    parser.add_argument("--out", type=Path, default=default_out_dir(), help="folder for the JSON and PNG")
    parser.add_argument("--work-dir", type=Path, default=None, help="where to write the test sessions (default: temp)")
    args = parser.parse_args()
    doc = run_recorder_benchmark(quick_plan() if args.quick else full_plan(), args.work_dir)
    for line in summary_lines(doc):
        print(line)
    json_path = write_json(doc, args.out / "bench_recorder.json")
    png_path = plot_recorder_benchmark(doc, args.out / "bench_recorder.png")
    print(f"wrote {json_path} and {png_path}")


if __name__ == "__main__":
    main()
