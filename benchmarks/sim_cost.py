"""Simulator cost: CPU seconds per simulated second of a fast-twin session, before and after, for both sensors.

Run: ``python benchmarks/sim_cost.py --presses 30 --pairs 3 --campaign-presses 8`` (about 10 minutes on the loaded
2-core box; ``--full`` also runs the whole campaign on each code version, hours). Writes
``docs/figures/sim_cost.json`` and prints a summary.

Each measurement is one seeded session (``SimRig(seed)``, ``collect_session``; ``hex_tpu``, 91 angles unless told
otherwise) in a fresh process, timed with ``time.process_time`` around the session alone (imports done first). The
*simulator's* share comes from stack samples every millisecond of process CPU time (``ITIMER_PROF``; the kernel's
tick makes it about every 4 ms): a sample is the simulator's when a frame on its stack runs simulator code (the
simulated arm, devices, scene and transports); the rest is the host code a real rig runs too (the press routine,
the drivers' decoding, the recorder). Versions are measured in ``--pairs`` alternating rounds and the medians
reported, with the median of the per-round before/after ratios.

"Before" is another commit (default ``2813621``, the commit issue 27 measured), checked out with
``git worktree add`` into a temporary folder and imported through ``PYTHONPATH``; "after" is this checkout. The
campaign (the six seen objects x 91 presses and the irregular prism x 4 rotations x 91, with both sensors: 1820
presses) is estimated from ``--campaign-presses`` presses of every object with each sensor, per-press CPU times the
object's presses; ``--full`` runs ``unitac-rig campaign`` instead.
"""

from __future__ import annotations

import argparse
import contextlib
import importlib
import json
import os
import resource
import signal
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

from lab.versions import ROOT, checkout, run_worker, short_commit

SENSORS = ("uskin", "papillarray")


# ---- the worker: one session in this process ----------------------------------------------------------------------
# A sample counts as the simulator's when any frame on the stack runs simulator code: the simulated arm, devices,
# scene and transports (unitac_rig/sim/, and python-can's virtual bus, which carried the uSkin before the lockstep
# bus). Everything else is host code a real rig runs too.
_SIMULATOR_FILES = (
    os.sep + os.path.join("unitac_rig", "sim") + os.sep,
    os.path.join("can", "interfaces", "virtual.py"),
)
SAMPLE_INTERVAL_S = 0.001  # of process CPU time


class _CpuSampler:
    """Sample the main thread's stack every ``SAMPLE_INTERVAL_S`` of process CPU time (``ITIMER_PROF``) and count
    the samples inside simulator code. Statistical, but it adds nothing to the code it measures: thin timers around
    the simulator's entry points (the first version of this benchmark) cost two ``process_time`` system calls per
    call, 0.4 M calls a session, which inflated both versions' figures by 10-35 %."""

    def __init__(self) -> None:
        self.total = 0
        self.simulator = 0
        self._files: dict[str, bool] = {}

    def _in_simulator(self, filename: str) -> bool:
        known = self._files.get(filename)
        if known is None:
            known = self._files[filename] = any(part in filename for part in _SIMULATOR_FILES)
        return known

    def _on_signal(self, signum: int, frame: Any) -> None:
        self.total += 1
        while frame is not None:
            if self._in_simulator(frame.f_code.co_filename):
                self.simulator += 1
                return
            frame = frame.f_back

    def __enter__(self) -> _CpuSampler:
        signal.signal(signal.SIGPROF, self._on_signal)
        signal.setitimer(signal.ITIMER_PROF, SAMPLE_INTERVAL_S, SAMPLE_INTERVAL_S)
        return self

    def __exit__(self, *exc: object) -> None:
        signal.setitimer(signal.ITIMER_PROF, 0.0, 0.0)
        signal.signal(signal.SIGPROF, signal.SIG_DFL)


def _preload() -> None:
    """Import what a session imports on first use (a sensor's driver and simulated devices, python-can), so the
    session's CPU is the session's and not the interpreter's (an import happens once per process, not per press)."""
    for name in (
        "can",
        "unitac_rig.sim.devices",
        "drivers.uskin",
        "drivers.papillarray",
        "unitac_rig.sim.fast_sensors",
    ):
        with contextlib.suppress(ImportError):
            importlib.import_module(name)


def run_session(sensor: str, object_id: str, angles: int, presses: int | None, seed: int) -> dict[str, Any]:
    """One seeded session of the code on ``sys.path``; CPU, simulated time and what the session recorded."""
    from unitac_rig.collection.session import collect_session
    from unitac_rig.rig.config import parse_rig_config
    from unitac_rig.rig.objects import get_object
    from unitac_rig.sim.fast_rig import SimRig
    from unitac_rig.storage.summary import inspect_dataset

    _preload()
    rig = SimRig(parse_rig_config({"press": {"angle_count": angles}}), seed=seed)
    marks: list[float] = []  # process CPU (s) as each press is recorded

    def on_press(_: object) -> None:
        marks.append(time.process_time())

    with tempfile.TemporaryDirectory() as tmp:
        with _CpuSampler() as sampler:
            start = time.process_time()
            outcome = collect_session(
                rig, get_object(object_id), sensor, Path(tmp), max_presses=presses, on_press=on_press
            )
            cpu_s = time.process_time() - start
        sim_s = rig.clock.now_ns() / 1e9
        rig.close()
        (summary,) = inspect_dataset(Path(tmp))["sessions"]
    share = sampler.simulator / max(1, sampler.total)
    presses_done = max(1, outcome.complete + outcome.failed)
    return {
        "sensor": sensor,
        "object": object_id,
        "angles": angles,
        "presses_complete": outcome.complete,
        "presses_failed": outcome.failed,
        "cpu_s": round(cpu_s, 3),
        "simulated_s": round(sim_s, 3),
        "cpu_per_simulated_s": round(cpu_s / sim_s, 5),
        "samples": sampler.total,
        "simulator_share": round(share, 4),
        "simulator_cpu_s": round(cpu_s * share, 3),
        "simulator_cpu_per_simulated_s": round(cpu_s * share / sim_s, 5),
        "host_cpu_per_simulated_s": round(cpu_s * (1 - share) / sim_s, 5),
        "cpu_per_press_s": round(cpu_s / presses_done, 4),
        # after the first press (the session's start: first move, tare, opening the sensor, is in the first)
        "cpu_per_later_press_s": round((marks[-1] - marks[0]) / (len(marks) - 1), 4) if len(marks) > 1 else None,
        "cpu_session_start_s": round(2 * marks[0] - marks[1] - start, 4) if len(marks) > 1 else None,
        "simulated_per_press_s": round(sim_s / presses_done, 4),
        "targets_matched": summary["targets_matched"],
        "targets_missed": summary["targets_missed"],
        "match_error_median_n": summary["match_error_n"]["median"],
        "peak_force_median_n": summary["peak_force_n"]["median"],
    }


def period_cost() -> dict[str, float]:
    """CPU (µs) of one control period of the simulated arm alone, best of 5 runs, in free air with ``hex_tpu``
    mounted and the host reading the state each period: at rest, and in force mode at its speed limit with the host
    re-sending the same command each period (what the press's approach does)."""
    import numpy as np

    from unitac_rig.rig.config import parse_rig_config
    from unitac_rig.rig.objects import get_object
    from unitac_rig.sim.fast_rig import SimRig

    rig = SimRig(parse_rig_config({}), seed=0)
    rig.mount(get_object("hex_tpu"), 0.0, "papillarray")
    arm = rig.sim_arm

    def best_us(period: Any, n: int) -> float:
        runs = []
        for _ in range(5):
            start = time.process_time()
            for _ in range(n):
                period()
            runs.append((time.process_time() - start) / n * 1e6)
        return round(min(runs), 2)

    def at_rest() -> None:
        arm.wait_period()
        arm.read_state()

    rest = best_us(at_rest, 4000)
    frame, selection = np.array(arm.read_state().tcp_pose), np.array([0, 0, 1.0, 0, 0, 0])
    limits = np.array([0, 0, 0.002, 0, 0, 0])

    def pulling_back() -> None:  # a set-point pulling away from the object: free air, at the speed limit
        arm.force_mode(frame, selection, np.array([0, 0, -2.0, 0, 0, 0]), limits)
        arm.wait_period()
        arm.read_state()

    force = best_us(pulling_back, 2000)
    rig.close()
    return {"rest_us": rest, "force_mode_at_speed_limit_us": force}


# ---- the driver: versions in subprocesses --------------------------------------------------------------------------
def measure(code: Path, sensor: str, object_id: str, angles: int, presses: int | None, seed: int) -> dict[str, Any]:
    """Run one session of the code in ``code`` in a fresh process (imports from ``code`` only)."""
    command = [str(Path(__file__).resolve()), "--worker", sensor, "--object", object_id]
    command += ["--angles", str(angles), "--seed", str(seed)]
    if presses:
        command += ["--presses", str(presses)]
    return run_worker(code, command)


def campaign_presses() -> dict[str, int]:
    """Presses per object and sensor in the paper's campaign: each of the object's rotations, 91 angles (the six
    seen objects 91 each, the irregular prism 4 x 91 = 364; 910 per sensor)."""
    from unitac_rig.rig.objects import list_objects

    return {obj.id: len(obj.rotations_deg) * 91 for obj in list_objects()}


def run_campaign(code: Path) -> dict[str, float]:
    """``unitac-rig campaign`` of the code in ``code`` in a child process: its CPU (user + sys) and wall time."""
    with tempfile.TemporaryDirectory() as tmp:
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        start = time.monotonic()
        command = [sys.executable, "-m", "unitac_rig", "campaign", "--data", tmp, "--no-live"]
        env = {**os.environ, "PYTHONPATH": str(code)}
        subprocess.run(command, env=env, cwd=tmp, check=True, capture_output=True)
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return {"cpu_s": round(cpu, 1), "wall_s": round(time.monotonic() - start, 1)}


_FIGURES = ("cpu_per_simulated_s", "simulator_cpu_per_simulated_s", "host_cpu_per_simulated_s", "cpu_per_press_s")


def _median_session(runs: list[dict[str, Any]]) -> dict[str, Any]:
    """The first run's record (what the session recorded is the same every run: seeded), with each CPU figure the
    median over the runs and the runs' figures kept."""
    out = dict(runs[0])
    for key in ("cpu_s", "simulator_cpu_s", "simulator_share", *_FIGURES):
        out[key] = round(statistics.median(r[key] for r in runs), 5)
    out["runs"] = [{key: r[key] for key in ("cpu_s", "simulator_share", *_FIGURES)} for r in runs]
    return out


def measure_pairs(trees: dict[str, Path], args: argparse.Namespace) -> dict[str, dict[str, Any]]:
    """``args.pairs`` rounds of one session per version and sensor, the versions alternating, so a drift in the
    shared machine's load hits both alike; per version and sensor the median figures and the per-round ratios."""
    runs: dict[str, dict[str, list[dict[str, Any]]]] = {v: {s: [] for s in args.sensors} for v in trees}
    for _ in range(args.pairs):
        for sensor in args.sensors:
            for version, code in trees.items():
                runs[version][sensor].append(measure(code, sensor, args.object, args.angles, args.presses, args.seed))
    versions = {v: {"sessions": {s: _median_session(runs[v][s]) for s in args.sensors}} for v in trees}
    for sensor in args.sensors:
        pairs = list(zip(runs["before"][sensor], runs["after"][sensor], strict=True))
        versions["after"]["sessions"][sensor]["ratios_before_over_after"] = {
            figure: round(statistics.median(b[figure] / a[figure] for b, a in pairs), 2)
            for figure in ("cpu_per_simulated_s", "simulator_cpu_per_simulated_s", "host_cpu_per_simulated_s")
        }
    return versions


def campaign_estimate(code: Path, args: argparse.Namespace) -> dict[str, Any]:
    """CPU of the whole campaign from ``args.campaign_presses`` presses of every object with each sensor: per (object,
    sensor) the session's start (its first press less a later one) plus the CPU of a later press times the object's
    presses in the campaign."""
    presses = campaign_presses()
    per_object: dict[str, dict[str, dict[str, float]]] = {}
    total = 0.0
    for object_id, count in presses.items():
        per_object[object_id] = {}
        for sensor in SENSORS:
            s = measure(code, sensor, object_id, 91, args.campaign_presses, args.seed)
            start_s, per_press_s = s["cpu_session_start_s"], s["cpu_per_later_press_s"]
            per_object[object_id][sensor] = {"session_start_s": start_s, "per_press_s": per_press_s}
            total += start_s + per_press_s * count
    return {"presses": presses, "cpu_by_object": per_object, "cpu_s": round(total, 1)}


def _print(label: str, s: dict[str, Any]) -> None:
    print(
        f"{label:6s} {s['sensor']:11s} {s['cpu_s']:7.2f} CPU-s / {s['simulated_s']:7.1f} simulated s = "
        f"{s['cpu_per_simulated_s']:.4f} (simulator {s['simulator_cpu_per_simulated_s']:.4f}, host "
        f"{s['host_cpu_per_simulated_s']:.4f}); {s['presses_complete']} presses, "
        f"{s['targets_matched']} targets matched, median error {s['match_error_median_n']} N, "
        f"median peak {s['peak_force_median_n']} N"
    )


def main() -> None:
    # the workers import only the version they measure, so this checkout's package is imported here, not on top
    from unitac_rig.bench import default_out_dir, machine_info, write_json

    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--before", default="2813621", help="commit measured as 'before' (default: 2813621)")
    parser.add_argument("--object", default="hex_tpu")
    parser.add_argument("--angles", type=int, default=91, help="angles in the session's plan (91)")
    parser.add_argument("--presses", type=int, default=None, help="stop after this many presses (default: all)")
    parser.add_argument("--seed", type=int, default=0, help="the simulated rig's seed (0)")
    parser.add_argument("--sensors", nargs="+", default=list(SENSORS), choices=SENSORS)
    parser.add_argument("--pairs", type=int, default=3, help="alternating before/after rounds (3)")
    parser.add_argument(
        "--campaign-presses", type=int, default=0, help="estimate the campaign from this many presses per object"
    )
    parser.add_argument("--full", action="store_true", help="also run the whole campaign on each version (long)")
    parser.add_argument("--out", type=Path, default=default_out_dir() / "sim_cost.json")
    parser.add_argument(
        "--period-cost", action="store_true", help="only time one simulated control period alone, before and after"
    )
    parser.add_argument("--worker", choices=SENSORS, help=argparse.SUPPRESS)
    parser.add_argument("--period-worker", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.worker:
        print(json.dumps(run_session(args.worker, args.object, args.angles, args.presses, args.seed)))
        return
    if args.period_worker:
        print(json.dumps(period_cost()))
        return
    if args.period_cost:
        with checkout(args.before) as before_tree:
            for label, code in (("before", before_tree), ("after", ROOT)):
                cost = run_worker(code, [str(Path(__file__).resolve()), "--period-worker"])
                print(f"{label} ({args.before if label == 'before' else 'this checkout'}): {json.dumps(cost)}")
        return
    with checkout(args.before) as before_tree:
        trees = {"before": before_tree, "after": ROOT}
        versions = measure_pairs(trees, args)
        for label, code in trees.items():
            for s in versions[label]["sessions"].values():
                _print(label, s)
            if args.campaign_presses:
                versions[label]["campaign_estimate"] = estimate = campaign_estimate(code, args)
                print(f"{label:6s} campaign estimate {estimate['cpu_s'] / 60:.1f} CPU-min")
            if args.full:
                versions[label]["campaign_measured"] = run_campaign(code)
    for sensor, s in versions["after"]["sessions"].items():
        print(f"before/after {sensor}: {json.dumps(s['ratios_before_over_after'])}")
    doc = {
        "what": "CPU seconds per simulated second of one seeded fast-twin session, before and after (issue 27)",
        "command": "python benchmarks/sim_cost.py " + " ".join(sys.argv[1:]),
        "before_commit": args.before,
        "after_commit": short_commit(),
        "machine": machine_info(),
        "object": args.object,
        "angles": args.angles,
        "presses": args.presses,
        "seed": args.seed,
        "pairs": args.pairs,
        "versions": versions,
    }
    print(f"wrote {write_json(doc, args.out)}")


if __name__ == "__main__":
    main()
