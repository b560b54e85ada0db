"""``unitac-rig stream`` on the real-time twin for 30 s: is every frame of a 1 kHz PapillArray translated, and within
its 1 ms budget?

    python benchmarks/stream_latency.py [--seconds 30] [--run RUN]

The real-time twin (``RigTwin``: its controller in its own process, its PapillArray hub served from this one) has
its rig file set to 1000 Hz; ``unitac-rig stream RUN --rig that file`` runs in its own process, its JSON lines read
from a pipe by this script (a controller's place), while the arm presses the object again and again through the real
ur_rtde client. RUN is a small UniTac-NV run on synthetic uSkin + PapillArray contacts with a fitted geometry
estimator (trained here unless --run is given): the per-frame work is the same for any run of the default shape.

Latency is host time on one clock: from the driver's stamp when a frame was complete (``TactileFrame.host_t_ns``,
``time.monotonic_ns``) to the moment the frame's line was written and flushed into the pipe. It leaves out the wire
(device to host) before the stamp and the reader after the pipe. Writes docs/figures/stream_latency.json and .png.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np
import rtde_control

from unitac_rig.bench import default_out_dir, machine_info, write_json
from unitac_rig.plotting import new_figure, save_figure
from unitac_rig.sim.twin.rig import RigTwin
from unitac_rig.sim.twin.world import build_scene

FIGURES = default_out_dir()
BUDGET_MS = 1.0  # one frame period of a PapillArray at 1 kHz


def train_small_run(out: Path) -> Path:
    """The benchmarks' tiny UniTac-NV run (30 epochs) with a fitted geometry estimator: what ``stream`` loads."""
    from unitac_rig.bench.inference import train_tiny_run
    from unitac_rig.learning.contact_geometry import GeometryConfig, geometry_for_run

    geometry_for_run(train_tiny_run(out, epochs=30), config=GeometryConfig(epochs=5))
    return out


def wait_for(condition, timeout_s: float) -> bool:  # type: ignore[no-untyped-def]
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if condition():
            return True
        time.sleep(0.05)
    return bool(condition())


def press_until(twin: RigTwin, stop: threading.Event, counts: dict[str, int]) -> None:
    """Press circle_pla 1.5 mm past first touch and back, over and over, until ``stop``."""
    pressed, home = build_scene(twin.spec).pose_at_travel(0.0, 1.5), twin.controller.settings.start_pose
    control = rtde_control.RTDEControlInterface(twin.host, 500.0)
    try:
        while not stop.is_set():
            control.moveL(list(pressed), 0.1, 0.5)
            control.moveL(list(home), 0.1, 0.5)
            counts["presses"] += 1
    finally:
        control.disconnect()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--seconds", type=float, default=30.0)
    parser.add_argument("--run", type=Path, default=None, help="a trained run (default: train a small one here)")
    parser.add_argument("--host", default="127.0.0.175", help="loopback address of the twin (127.0.0.170-179)")
    args = parser.parse_args()
    env = {**os.environ, "PYTHONUNBUFFERED": "1"}
    with tempfile.TemporaryDirectory(prefix="stream-latency-") as tmp_name:
        tmp = Path(tmp_name)
        run = args.run or train_small_run(tmp / "run")
        rig_file = tmp / "twin.toml"
        # the twin's controller runs in its own process; its PapillArray hub is served from threads of this one
        twin = RigTwin("circle_pla", sensor="papillarray", host=args.host, seed=0)
        try:
            rig_file.write_text(twin.rig_file().replace("rate_hz = 100", "rate_hz = 1000"))
            summary_path = tmp / "summary.json"
            command = [sys.executable, "-m", "unitac_rig", "stream", str(run), "--rig", str(rig_file)]
            command += ["--sensor", "papillarray", "--duration", str(args.seconds), "--summary", str(summary_path)]
            stream = subprocess.Popen(
                command,
                stdout=subprocess.PIPE,
                stderr=subprocess.PIPE,
                env=env,
            )
            items: list[dict] = []

            def read_lines() -> None:
                assert stream.stdout is not None
                for line in stream.stdout:
                    item = json.loads(line)
                    items.append(
                        {
                            "seq": item["seq"],
                            "latent": len(item["latent"]),
                            "uskin": len(item["translated"]["uskin"]),
                            "geometry": len(item["geometry_mm"]),
                        }
                    )

            reader = threading.Thread(target=read_lines, name="stream-reader")
            reader.start()
            stop = threading.Event()
            counts = {"presses": 0}
            if not wait_for(lambda: len(items) > 0 or stream.poll() is not None, 120.0) or not items:
                raise SystemExit(f"stream produced nothing: {stream.stderr.read().decode() if stream.stderr else ''}")
            presser = threading.Thread(target=press_until, args=(twin, stop, counts), name="presser")
            presser.start()
            stream.wait(timeout=args.seconds + 120)  # the reader thread drains stdout
            err = stream.stderr.read() if stream.stderr else b""
            stop.set()
            presser.join(timeout=30)
            reader.join(timeout=30)
            if stream.returncode != 0:
                raise SystemExit(f"stream failed: {err.decode()}")
            summary = json.loads(summary_path.read_text())
        finally:
            twin.close()
    seqs = np.array([i["seq"] for i in items])
    complete = all(i["latent"] == 16 and i["uskin"] == 24 and i["geometry"] == 11 for i in items)
    latency = summary["latency_ms"]
    result = {
        "what": "unitac-rig stream on the real-time twin: PapillArray at 1 kHz, translation to uSkin + latent + "
        "geometry per frame, JSON lines into a pipe; latency = host time from the driver's frame stamp to the "
        "line written",
        "machine": machine_info(),
        "seconds": summary["seconds"],
        "presses_during_stream": counts["presses"],
        "frames_out": summary["frames_out"],
        "lines_read": len(items),
        "rate_hz": summary["rate_hz"],
        "seq_gaps_in_lines": int(np.sum(np.diff(seqs) - 1)) if seqs.size > 1 else 0,
        "seq_gaps_device_counter": summary["seq_gaps"],
        "driver": {k: summary["driver"].get(k) for k in ("frames", "sequence_gaps", "checksum_errors", "stalls")},
        "every_line_complete": complete,
        "latency_ms": latency,
        "budget_ms": BUDGET_MS,
        "median_within_budget": latency["median"] is not None and latency["median"] < BUDGET_MS,
        "histogram_ms": summary["histogram_ms"],
    }
    write_json(result, FIGURES / "stream_latency.json")
    counts_ms = np.asarray(summary["histogram_ms"]["counts"])
    edges = np.arange(counts_ms.size) * summary["histogram_ms"]["bin_ms"]
    fig = new_figure(7, 3.5, layout="tight")
    ax = fig.subplots()
    ax.bar(edges, counts_ms, width=summary["histogram_ms"]["bin_ms"], align="edge")
    ax.axvline(BUDGET_MS, color="red", linestyle="--", label="1 ms: one frame at 1 kHz")
    ax.axvline(latency["median"], color="black", label=f"median {latency['median']:.3f} ms")
    ax.set_yscale("log")
    ax.set_xlabel("host latency per frame, ms (frame stamped -> line written; last bin: >= 5 ms)")
    ax.set_ylabel("frames")
    ax.set_title(
        f"stream, {summary['frames_out']} frames in {summary['seconds']:.0f} s, "
        f"{result['machine']['cpus']} CPUs, load {result['machine']['load_average_1min']}"
    )
    ax.legend()
    save_figure(fig, FIGURES / "stream_latency.png")
    print(json.dumps({k: v for k, v in result.items() if k not in ("histogram_ms", "machine")}, indent=1))


if __name__ == "__main__":
    main()
