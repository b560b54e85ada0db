"""Issue 37: does anything but a host fault stop the controller's program, on a loaded box?

    python benchmarks/control_loop_load.py [--sessions 30] [--angles 3] [--dry-runs 3] [--kills 2] [--no-campaign]

The box is loaded first: two busy processes per core and a writer that writes 1 MiB and fsyncs, in a loop. Then:

* **GIL starvation** (why the watchdog is not kept alive by a thread while the session works): a thread that wakes
  every 20 ms, as ``UR5eArm.keep_alive``'s kicker does, in a process whose main thread writes gzip-compressed HDF5
  press files; its worst gap against a 6 Hz watchdog's 167 ms. The same wake-up loop in a process of its own is the
  comparison (only the OS scheduler in the way).
* **sessions**: ``unitac-rig collect --rig`` against the real-time twin (``RigTwin``, circle_pla, PapillArray), each
  into a fresh data directory; the twin's watchdog trips counted per session (none is injected, so every trip is
  one no fault caused), with the exit status.
* **dry runs**: ``collect --rig --dry-run``, likewise.
* **campaign**: ``unitac-rig campaign --rig`` with two objects (the operator's Enter fed on stdin).
* **host death**: a collect killed (SIGKILL) or frozen (SIGSTOP) the moment the twin's true force reaches 5 N; the
  controller time from the host's last RTDE write to the arm at rest (the bound is 0.25 s).

Writes docs/figures/control_loop_load.json. The box may be shared: its load average is in the JSON.
"""

from __future__ import annotations

import argparse
import gc
import json
import os
import signal
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from lab.twin_runs import collect_command, host_load
from unitac_rig.bench import machine_info, write_json
from unitac_rig.sim.twin import ControllerParams, TwinTruth, first_free_loopback
from unitac_rig.sim.twin.rig import RigTwin

OUT = Path(__file__).resolve().parent.parent / "docs" / "figures" / "control_loop_load.json"
OBJECT = "circle_pla"
WATCHDOG_S = 1.0 / 6.0  # the default watchdog's window
PRESSING_N = 5.0
REST_BOUND_S = 0.25
KICK_S = 0.02
_KICKER = """
import sys, time
gaps, last, end = [], time.monotonic(), time.monotonic() + float(sys.argv[1])
while time.monotonic() < end:
    time.sleep(0.02)
    now = time.monotonic(); gaps.append(now - last); last = now
print(max(gaps))
"""


def _hdf5_press(scratch: Path) -> Callable[[], None]:
    """Write one press-sized, gzip-compressed HDF5 file (h5py's filters run inside HDF5)."""
    import h5py

    press = np.random.default_rng(0).normal(size=(20_000, 24, 3)).astype(np.float32)  # 20 s of uSkin at 1 kHz

    def write() -> None:
        with h5py.File(scratch / "press.h5", "w") as fh:
            fh.create_dataset("frames", data=press, compression="gzip", compression_opts=6)

    return write


def _gil_holding_calls() -> Callable[[], None]:
    """Single C calls that keep the GIL for their whole length: serializing and sorting a large record, then a full
    garbage collection over it (what a recorder's metadata and its garbage cost)."""
    record = [{"t": i * 1e-3, "f": [float(i), 0.5, 0.25], "id": f"p{i}"} for i in range(150_000)]
    keys = np.random.default_rng(1).random(1_000_000).tolist()

    def work() -> None:
        json.dumps(record)
        sorted(keys)
        gc.collect()

    return work


def gil_starvation(seconds: float, scratch: Path) -> dict[str, dict[str, float]]:
    """Worst gap of a 20 ms wake-up thread while this process's main thread works, per kind of work, and of the same
    loop alone in a process of its own."""
    alone = subprocess.Popen([sys.executable, "-c", _KICKER, str(2 * seconds)], stdout=subprocess.PIPE, text=True)
    result: dict[str, dict[str, float]] = {}
    for name, work in (("hdf5_gzip_writes", _hdf5_press(scratch)), ("gil_holding_calls", _gil_holding_calls())):
        gaps: list[float] = []
        done = threading.Event()

        def kicker(gaps: list[float] = gaps, done: threading.Event = done) -> None:
            last = time.monotonic()
            while not done.wait(KICK_S):
                now = time.monotonic()
                gaps.append(now - last)
                last = now

        thread = threading.Thread(target=kicker, daemon=True)
        thread.start()
        end, rounds = time.monotonic() + seconds, 0
        while time.monotonic() < end:
            work()
            rounds += 1
        done.set()
        thread.join()
        result[name] = {
            "thread_worst_gap_ms": round(1e3 * max(gaps), 1),
            "thread_p99_gap_ms": round(1e3 * float(np.percentile(gaps, 99)), 1),
            "thread_gaps_over_watchdog": sum(g > WATCHDOG_S for g in gaps),
            "rounds": rounds,
        }
    out, _ = alone.communicate()
    result["own_process"] = {"worst_gap_ms": round(1e3 * float(out.strip()), 1)}
    return result


HOST_PREFIX: list[str] = []  # e.g. chrt -f 5: the collecting process under real-time scheduling (--host-fifo)


def _run(rig: RigTwin, cmd: list[str], stdin: str | None = None) -> dict[str, Any]:
    rig.controller.reset_timing()
    before = rig.controller.truth()
    started = time.monotonic()
    proc = subprocess.run(cmd, input=stdin, capture_output=True, text=True, timeout=900, check=False)
    after = rig.controller.truth()
    trips = after.watchdog_trips - before.watchdog_trips
    return {
        "exit": proc.returncode,
        "wall_s": round(time.monotonic() - started, 1),
        "watchdog_trips": trips,
        "protective_stops": after.protective_stops - before.protective_stops,
        "last_error": rig.controller.status().get("last_error") if trips else None,
        "twin_worst_lateness_ms": round(1e3 * after.worst_lateness_s, 1),  # the twin's own scheduling, not the host's
        "twin_late_cycles": after.late_cycles,
        "tail": (proc.stdout + proc.stderr).strip().splitlines()[-6:] if proc.returncode or trips else [],
    }


def repeated_runs(label: str, count: int, angles: int, scratch: Path, host: str, seed: int, *extra: str) -> list[Any]:
    """``collect --rig`` ``count`` times on one twin, each into a fresh data directory (``extra``: ``--dry-run`` for
    every stand-off and clearance waypoint with nothing pressed or recorded)."""
    runs = []
    with RigTwin(OBJECT, sensor="papillarray", host=host, seed=seed) as rig:
        rig_file = scratch / f"{label}.toml"
        rig_file.write_text(rig.rig_file())
        print(f"twin scheduling: {rig.controller.status().get('scheduling')}", flush=True)
        for index in range(count):
            cmd = collect_command(rig_file, scratch / f"{label}{index}", OBJECT, angles, *extra, prefix=HOST_PREFIX)
            run = _run(rig, cmd)
            print(f"{label} {index + 1}/{count}: {run}", flush=True)
            runs.append(run)
    return runs


def _only_sensor(rig_text: str, sensor: str) -> str:
    """The rig file without the other sensors' tables (a campaign collects with every sensor the file names)."""
    kept, skipping = [], False
    for line in rig_text.splitlines():
        if line.startswith("["):
            skipping = line.startswith("[sensors.") and not line.startswith(f"[sensors.{sensor}]")
        if not skipping:
            kept.append(line)
    return "\n".join(kept) + "\n"


def campaign(angles: int, scratch: Path, host: str) -> dict[str, Any]:
    with RigTwin("circle_pla", sensor="papillarray", host=host, seed=4) as rig:
        rig_file = scratch / "campaign.toml"
        rig_file.write_text(_only_sensor(rig.rig_file(), "papillarray"))  # the twin serves the mounted one only
        cmd = [*HOST_PREFIX, sys.executable, "-m", "unitac_rig", "campaign", "--rig", str(rig_file)]
        cmd += ["--objects", "circle_pla,circle_tpu", "--angles", str(angles), "--data", str(scratch / "campaign")]
        cmd.append("--no-live")
        run = _run(rig, cmd, stdin="\n" * 8)  # mount the sensor, then each object
    print(f"campaign: {run}", flush=True)
    return run


def _watch(rig: RigTwin, seconds: float) -> list[TwinTruth]:
    seen, end = [], time.monotonic() + seconds
    while time.monotonic() < end:
        seen.append(rig.controller.truth())
        time.sleep(0.002)
    return seen


def host_death(how: str, angles: int, scratch: Path, host: str) -> dict[str, Any]:
    """Kill or freeze a collect mid-press; the controller time from its last write to the arm at rest for good."""
    with RigTwin(
        "circle_pla", sensor="papillarray", host=host, seed=2, params=ControllerParams(unlock_delay_s=0.3)
    ) as rig:
        rig_file = scratch / f"{how}.toml"
        rig_file.write_text(rig.rig_file())
        proc = subprocess.Popen(
            collect_command(rig_file, scratch / how, OBJECT, angles, prefix=HOST_PREFIX),
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
        )
        try:
            deadline = time.monotonic() + 300
            while rig.controller.truth().force_n < PRESSING_N:
                if time.monotonic() > deadline or proc.poll() is not None:
                    return {"how": how, "error": "never pressed", "exit": proc.poll()}
                time.sleep(0.002)
            rig.controller.reset_peak()
            os.kill(proc.pid, signal.SIGKILL if how == "kill -9" else signal.SIGSTOP)
            seen = _watch(rig, 0.8)
        finally:
            proc.kill()
            proc.wait()
        moving = [t.controller_t_s for t in seen if not t.at_rest]
        rest_from = max(moving) if moving else seen[0].controller_t_s
        last = seen[-1]
        return {
            "how": how,
            "at_rest_at_end": last.at_rest,
            "rest_after_last_write_s": round(rest_from - last.last_input_t_s, 3),
            "watchdog_trips": last.watchdog_trips,
            "peak_after_signal_n": round(last.peak_force_n, 2),
        }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sessions", type=int, default=30)
    parser.add_argument("--angles", type=int, default=3)
    parser.add_argument("--kills", type=int, default=2, help="runs of each of kill -9 and SIGSTOP")
    parser.add_argument("--no-campaign", action="store_true")
    parser.add_argument("--dry-runs", type=int, default=3)
    parser.add_argument("--host-fifo", type=int, default=0, help="run each collect under chrt -f N (0: as is)")
    parser.add_argument("--out", type=Path, default=OUT)
    parser.add_argument("--gil-seconds", type=float, default=10.0)
    args = parser.parse_args()
    if args.host_fifo:
        HOST_PREFIX[:] = ["chrt", "-f", str(args.host_fifo)]
    result: dict[str, Any] = {"args": {k: str(v) for k, v in vars(args).items()}}
    with tempfile.TemporaryDirectory() as tmp, host_load(Path(tmp)) as load_processes:
        scratch = Path(tmp)
        time.sleep(2.0)  # let the load average see them
        result["load_processes"] = load_processes
        result["gil"] = gil_starvation(args.gil_seconds, scratch)
        print(f"GIL: {result['gil']}", flush=True)
        host = first_free_loopback(220, 239)
        result["sessions"] = repeated_runs("session", args.sessions, args.angles, scratch, host, 3)
        result["dry_runs"] = repeated_runs("dry-run", args.dry_runs, args.angles, scratch, host, 5, "--dry-run")
        if not args.no_campaign:
            result["campaign"] = campaign(args.angles, scratch, host)
        result["host_death"] = [
            host_death(how, args.angles, scratch, host) for how in ("kill -9", "SIGSTOP") for _ in range(args.kills)
        ]
        print(f"host death: {result['host_death']}", flush=True)
        result["machine"] = machine_info()  # the load average with the load still on
    runs = result["sessions"] + result["dry_runs"] + ([result["campaign"]] if "campaign" in result else [])
    result["summary"] = {
        "sessions": len(result["sessions"]),
        "sessions_exit_0": sum(r["exit"] == 0 for r in result["sessions"]),
        "dry_runs": len(result["dry_runs"]),
        "dry_runs_exit_0": sum(r["exit"] == 0 for r in result["dry_runs"]),
        "runs_with_a_watchdog_trip": sum(r["watchdog_trips"] > 0 for r in runs),
        "worst_rest_after_last_write_s": max(
            (d["rest_after_last_write_s"] for d in result["host_death"] if "rest_after_last_write_s" in d),
            default=None,
        ),
    }
    print(result["summary"], flush=True)
    write_json(result, args.out)


if __name__ == "__main__":
    main()
