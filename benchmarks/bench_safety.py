"""Safety of the press when the host stalls or dies: true peak force against host stall length, before and after.

The measuring code is benchmarks/lab/safety.py (the per-process worker is benchmarks/lab/safety_worker.py).

    python benchmarks/bench_safety.py [--quick] [--jobs 2] [--out docs/figures] [--before f419c22] [--after-only]

For each press strategy, on the fast twin (whose controller goes on executing while the host is frozen or dead):
host stalls of 0, 50, 100, 200, 500 and 1000 ms and a host death, each placed at six moments of the press (first
touch, 2, 5, 8, 9, 9.5 N of true force) on two seeds, with the worst moment reported; then a 13-angle session per
strategy and sensor for overshoot and matching error. "before" is the commit issue 11 reviewed, unpacked with
``git archive``; "after" is this checkout. Writes OUT/bench_safety.json and OUT/bench_safety.png. About 30-40 min on
2 idle cores; ``--quick`` takes a few minutes. ``--twin`` adds the real-time twin (the hardware path with the real
ur_rtde clients): a collecting process killed with kill -9 mid-press, before and after, and a 5-angle session per
strategy (about 10 min more); ``--twin-only`` runs just that part and adds it to an existing JSON.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
from pathlib import Path

from lab.safety import BEFORE_COMMIT, SafetyPlan, draw, quick_plan, run, run_twin
from unitac_rig.bench import default_out_dir, write_json


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--quick", action="store_true", help="smoke run: two strategies, two stalls, one seed")
    parser.add_argument("--jobs", type=int, default=2, help="worker processes per version")
    parser.add_argument("--out", type=Path, default=default_out_dir(), help="folder for the JSON and PNG")
    parser.add_argument("--before", default=BEFORE_COMMIT, help="the commit measured as 'before'")
    parser.add_argument("--after-only", action="store_true", help="skip the 'before' column")
    parser.add_argument("--twin", action="store_true", help="also kill -9 and short sessions on the real-time twin")
    parser.add_argument("--twin-only", action="store_true", help="only the real-time twin part, added to OUT's JSON")
    args = parser.parse_args()
    plan = quick_plan() if args.quick else SafetyPlan()
    plan = dataclasses.replace(plan, jobs=args.jobs, versions=("after",) if args.after_only else plan.versions)
    json_file = args.out / "bench_safety.json"
    doc = json.loads(json_file.read_text()) if args.twin_only else run(plan, before_commit=args.before)
    if args.twin or args.twin_only:
        doc["twin"] = run_twin(plan, before_commit=args.before)
        for death in doc["twin"]["deaths"]:
            print(f"  twin kill -9 ({death['version']}, {death['strategy']}): peak {death['peak_abs_n']:.1f} N, "
                  f"rest {death['rest_after_last_write_s']} s after the last write")  # fmt: skip
        for strategy, s in doc["twin"]["sessions"].items():
            print(f"  twin session {strategy}: {s['complete']}/{s['presses']} complete, true overshoot "
                  f"{s['true_overshoot_median_n']} N, |matching error| {s['match_error_median_n']} N")  # fmt: skip
    for name, version in doc["versions"].items():
        print(f"== {name}")
        for strategy, summary in version["stalls"].items():
            cells = ", ".join(f"{r['label']}: {r['worst_peak_abs_n']:.1f} N" for r in summary["rows"])
            print(f"  {strategy:10s} worst true |F| by stall: {cells}")
        for strategy, s in version["sessions"].items():
            print(f"  {strategy:10s} true overshoot {s['true_overshoot_median_n']} N, |matching error| median "
                  f"{s['match_error_median_n']} N, misses {s['misses']}/{s['targets']}")  # fmt: skip
    print("goals:", doc["goals"])
    json_path = write_json(doc, json_file)
    png_path = draw(doc, args.out / "bench_safety.png")
    print(f"wrote {json_path} and {png_path}")


if __name__ == "__main__":
    main()
