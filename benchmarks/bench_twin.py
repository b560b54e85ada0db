"""Timing of the real-time controller twin as the real ur_rtde 1.6.5 client sees it.

    python benchmarks/bench_twin.py [--quick]

One controller twin (circle_pla in front of a uSkin pad) on a free 127.0.0.x, the real control and receive clients
connected, then three phases:

* **host loop**: ``initPeriod(); speedL(zero twist); waitPeriod()`` at 500 Hz, as a press loop runs: the host loop's
  achieved rate and period spread, and what one realtime call (``speedL``) costs the host;
* **round trip**: non-realtime commands (``zeroFtSensor``) one after another: the command's round trip (the client
  writes, the script sees it at its next cycle and signals done, the client sees "done" in the next data package
  and writes "clear"); a real controller has the same two-cycle floor (hardware-facts 3.8);
* **sweep**: blocking moves to 3 mm in front of the object at several approach angles and back (the scene builds a
  contact table for each new ray on the way in), while a thread reads the receive client's timestamp at ~1 kHz: the
  largest gap between consecutive controller timestamps a host sees, and how late the twin's cycles ran.

Each phase also records the twin's own statistics (cycles per second of wall time, worst lateness, late cycles,
skipped periods). The box may be shared (2 cores here), so the 1-minute load average goes into the JSON.
Writes docs/figures/bench_twin.json and docs/figures/bench_twin.png.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path
from typing import Any

import numpy as np
import rtde_control
import rtde_receive

from unitac_rig.bench import default_out_dir, machine_info, write_json
from unitac_rig.plotting import new_figure, save_figure
from unitac_rig.sim.scene import press_pose
from unitac_rig.sim.twin import ControllerParams, SceneSpec, start_twin_on_free_loopback
from unitac_rig.sim.twin.world import build_scene

CENTER_M = (-0.15, 0.625)
HEIGHT_M = 0.20


def _twin_stats(twin: Any) -> dict[str, float]:
    truth = twin.truth()
    return {
        "achieved_rate_hz": truth.achieved_rate_hz,
        "worst_lateness_ms": truth.worst_lateness_s * 1e3,
        "late_cycles": truth.late_cycles,
        "skipped_cycles": truth.skipped_cycles,
        "cycles": truth.cycles,
    }


def _percentiles(values_ms: np.ndarray) -> dict[str, float]:
    return {
        "n": int(values_ms.size),
        "p50_ms": float(np.percentile(values_ms, 50)),
        "p95_ms": float(np.percentile(values_ms, 95)),
        "p99_ms": float(np.percentile(values_ms, 99)),
        "max_ms": float(values_ms.max()),
    }


def host_loop(control: Any, twin: Any, seconds: float) -> tuple[dict[str, Any], np.ndarray]:
    twin.reset_timing()
    zero = [0.0] * 6
    starts, calls = [], []
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline:
        period = control.initPeriod()
        starts.append(time.perf_counter())
        control.speedL(zero, 0.5, 0.0)
        calls.append(time.perf_counter() - starts[-1])
        control.waitPeriod(period)
    control.speedStop(10.0)
    periods_ms = np.diff(starts) * 1e3
    result = {
        "achieved_hz": float(len(starts) / (starts[-1] - starts[0])),
        "period": _percentiles(periods_ms),
        "speedl_call": _percentiles(np.asarray(calls) * 1e3),
        "twin": _twin_stats(twin),
    }
    return result, periods_ms


def round_trip(control: Any, twin: Any, count: int) -> tuple[dict[str, Any], np.ndarray]:
    twin.reset_timing()
    times = []
    for _ in range(count):
        start = time.perf_counter()
        assert control.zeroFtSensor()
        times.append(time.perf_counter() - start)
    times_ms = np.asarray(times) * 1e3
    return {"command": "zeroFtSensor", **_percentiles(times_ms), "twin": _twin_stats(twin)}, times_ms


def sweep(control: Any, receive: Any, twin: Any, spec: SceneSpec, angles: list[float]) -> tuple[dict[str, Any], Any]:
    """Asynchronous moves polled from this thread (ur_rtde's blocking calls keep the GIL, so no other thread could
    watch during a blocking move): every distinct controller timestamp the receive client gets is recorded."""
    scene = build_scene(spec)  # the same scene, here only to find where the surface is
    stamps: list[float] = []

    def move(pose: np.ndarray) -> None:
        assert control.moveL(list(pose), 0.05, 0.5, True)
        while True:
            stamp = receive.getTimestamp()
            if not stamps or stamp != stamps[-1]:
                stamps.append(stamp)
            if control.getAsyncOperationProgress() < 0:
                return
            time.sleep(0.0005)

    twin.reset_timing()
    started = time.perf_counter()
    for angle in angles:
        clear = press_pose(angle, 90.0, object_center_m=CENTER_M, height_m=HEIGHT_M)
        move(clear)
        move(scene.pose_at_travel(angle, -3.0))
        move(clear)
    gaps_ms = np.diff(stamps) * 1e3
    return {
        "angles_deg": angles,
        "wall_s": time.perf_counter() - started,
        "controller_timestamp_gap": _percentiles(gaps_ms),
        "twin": _twin_stats(twin),
    }, gaps_ms


def draw(periods_ms: np.ndarray, round_trips_ms: np.ndarray, gaps_ms: np.ndarray, path: Path) -> Path:
    fig = new_figure(12.0, 3.6)
    axes = fig.subplots(1, 3)
    panels = [
        (periods_ms, "host 500 Hz loop period (ms)", 2.0),
        (round_trips_ms, "zeroFtSensor round trip (ms)", None),
        (gaps_ms, "controller time step seen by the host (ms)", 2.0),
    ]
    for ax, (values, label, nominal) in zip(axes, panels, strict=True):
        ax.hist(values, bins=60, color="tab:blue")
        ax.set_yscale("log")
        ax.set_xlabel(label)
        ax.set_ylabel("count")
        if nominal is not None:
            ax.axvline(nominal, color="tab:red", lw=1, ls="--", label=f"nominal {nominal:g} ms")
            ax.legend(fontsize=8)
    fig.suptitle("Controller twin with the real ur_rtde 1.6.5 client (one 2-core box, shared)")
    return save_figure(fig, path)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="short phases (a smoke run, not for the docs)")
    parser.add_argument("--out", type=Path, default=default_out_dir())
    args = parser.parse_args()
    loop_s, trips, angles = (2.0, 50, [-30.0, 0.0]) if args.quick else (10.0, 500, [-45.0, -20.0, 0.0, 20.0, 45.0])
    spec = SceneSpec("circle_pla", sensor="uskin", center_m=CENTER_M, seed=0)
    start = press_pose(0.0, 90.0, object_center_m=CENTER_M, height_m=HEIGHT_M)
    doc: dict[str, Any] = {"machine": machine_info(), "client": "ur_rtde 1.6.5 (rtde_control, rtde_receive)"}
    with start_twin_on_free_loopback(240, 250, scene=spec, start_pose=start, params=ControllerParams()) as twin:
        control = rtde_control.RTDEControlInterface(twin.host, 500.0)
        receive = rtde_receive.RTDEReceiveInterface(twin.host, 500.0, ["timestamp", "actual_TCP_pose"])
        try:
            doc["host_loop"], periods = host_loop(control, twin, loop_s)
            doc["round_trip"], trip_times = round_trip(control, twin, trips)
            doc["sweep"], gaps = sweep(control, receive, twin, spec, angles)
        finally:
            receive.disconnect()
            control.disconnect()
    out = args.out
    write_json(doc, out / "bench_twin.json")
    draw(periods, trip_times, gaps, out / "bench_twin.png")
    loop, trip, swept = doc["host_loop"], doc["round_trip"], doc["sweep"]
    print(f"load average {doc['machine']['load_average_1min']} on {doc['machine']['cpus']} CPUs")
    print(f"host loop: {loop['achieved_hz']:.1f} Hz (period p99 {loop['period']['p99_ms']:.2f} ms)")
    print(f"  speedL call p50 {loop['speedl_call']['p50_ms'] * 1e3:.0f} us; twin {loop['twin']}")
    print(f"round trip zeroFtSensor: p50 {trip['p50_ms']:.2f} ms, p95 {trip['p95_ms']:.2f} ms")
    print(f"  max {trip['max_ms']:.2f} ms; twin {trip['twin']}")
    gap = swept["controller_timestamp_gap"]
    print(f"sweep: controller timestamp gap p99 {gap['p99_ms']:.2f} ms, max {gap['max_ms']:.2f} ms")
    print(f"  twin {swept['twin']}")


if __name__ == "__main__":
    main()
