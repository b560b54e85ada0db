"""The data path against the hardware's rates: the recorder's sustained write rate, and the live PapillArray path.

1. Recorder: :meth:`unitac_rig.storage.recorder.SessionWriter.write_press` (journal file written, fsynced and renamed,
   then the press file written and the session file republished) on presses of realistic length carrying the
   streams the hardware produces: the robot at 500 Hz, the PapillArray at 1000 Hz (forces + displacements) and the
   uSkin at 100 Hz. The rate that counts is seconds of streams recorded per second of writing (the *real-time
   factor*); the combined figure writes one uSkin and one PapillArray press of the same length, so it covers all
   three streams (the robot twice). Every press is read back and compared array by array: the count of frames lost
   must be zero.
2. Live path: a simulated PapillArray hub streaming in real time (its own thread, 1000 Hz, real wire bytes over a
   pyserial URL) read by :class:`drivers.papillarray.PapillArrayDriver` in reader-thread mode for a few seconds while
   the caller polls every 2 ms as the press loop does; frames the hub sent against frames the driver delivered, and
   gaps in the hub's packet counter.

Wall-clock figures depend on the machine and its load, so they are reported against the hardware rate they must
beat, as ratios (headroom).
"""

from __future__ import annotations

import shutil
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

ROBOT_HZ = 500.0
PAPILLARRAY_HZ = 1000.0
USKIN_HZ = 100.0
GOAL_HEADROOM = 10.0
SENSOR_RATES_HZ = {"papillarray": PAPILLARRAY_HZ, "uskin": USKIN_HZ}


@dataclass(frozen=True)
class RecorderPlan:
    press_lengths_s: tuple[float, ...] = (1.5, 4.0, 8.0)
    presses_per_length: int = 8
    live_seconds: float = 5.0


def full_plan() -> RecorderPlan:
    return RecorderPlan()


def quick_plan() -> RecorderPlan:
    return RecorderPlan(press_lengths_s=(1.5, 4.0), presses_per_length=2, live_seconds=1.0)


# ---------------------------------------------------------------------------------------------------------------------
# 1. the recorder


def synthetic_press(sensor: str, length_s: float, index: int, rng: np.random.Generator) -> Any:
    """A :class:`PressRecord` of ``length_s`` seconds with the hardware's stream rates and plausible values.

    A force ramp to 10 N and back; robot at 500 Hz; tactile at the sensor's rate with a contiguous counter
    (PapillArray forces in N with displacements, uSkin raw counts around 33 000). Extraction computed as in a session.
    """
    from unitac_rig.rig.sensors import sensor_layout
    from unitac_rig.storage.extraction import extract_press
    from unitac_rig.storage.press_record import PressRecord, press_id

    layout = sensor_layout(sensor)
    k = round(ROBOT_HZ * length_s)
    m = round(SENSOR_RATES_HZ[sensor] * length_s)
    robot_t = np.arange(k) / ROBOT_HZ
    shape = np.minimum(1.0, 1.25 * np.sin(np.pi * robot_t / length_s))  # up, hold near 10 N, down
    press_force = 10.0 * shape + rng.normal(0.0, 0.5, k)
    robot_force = np.zeros((k, 6))
    robot_force[:, 1] = -press_force
    robot_force += rng.normal(0.0, 0.05, (k, 6))
    robot_pose = np.tile([-0.15, 0.6, 0.2, 0.0, 2.22, -2.22], (k, 1)) + rng.normal(0.0, 1e-6, (k, 6))
    tactile_t = np.arange(m) / SENSOR_RATES_HZ[sensor] + 0.0003
    load = np.interp(tactile_t, robot_t, 10.0 * shape)
    n = layout.n_taxels
    if sensor == "papillarray":
        values = (load[:, None, None] / n) * np.array([0.1, -0.05, 1.0]) + rng.normal(0.0, 0.02, (m, n, 3))
        values = np.round(values, 3)
        displacement = np.round(values / 6.0 + rng.normal(0.0, 0.005, (m, n, 3)), 3)
        baseline = np.zeros((n, 3))
    else:
        base = rng.normal(33_000.0, 2_000.0, (n, 3))
        values = np.round(base + 250.0 * load[:, None, None] + rng.normal(0.0, 8.0, (m, n, 3)))
        displacement = None
        baseline = base
    valid = np.ones(m, dtype=bool)
    angle = float(index % 91 - 45)
    record = PressRecord(
        press_id=press_id(0.0, angle) + f"_{index:04d}",
        rotation_deg=0.0,
        angle_deg=angle,
        status="complete",
        reason="force",
        robot_t_s=robot_t,
        robot_force=robot_force,
        robot_pose=robot_pose,
        press_force_n=press_force,
        tactile_t_s=tactile_t,
        tactile_values=values.astype(np.float32),
        tactile_seq=np.arange(1000 * index, 1000 * index + m, dtype=np.int64),
        tactile_device_t_us=np.round(tactile_t * 1e6).astype(np.int64),
        tactile_valid=valid,
        tactile_displacement_mm=None if displacement is None else displacement.astype(np.float32),
        tare_baseline=baseline,
        events=[(0.0, "start", "synthetic"), (length_s / 2, "stop", "force")],
        attrs={"strategy": "guarded", "speed_mm_s": 5.0, "threshold_n": 10.0, "peak_force_n": 10.0},
    )
    record.extraction = extract_press(robot_t, press_force, tactile_t, valid)
    return record


def _same(a: np.ndarray | None, b: np.ndarray | None) -> bool:
    if a is None or b is None:
        return a is None and b is None
    return a.shape == b.shape and bool(np.array_equal(np.asarray(a), np.asarray(b), equal_nan=True))


def measure_recorder(plan: RecorderPlan, work_dir: Path) -> dict[str, Any]:
    """Write ``presses_per_length`` presses per length and sensor, read them back, compare; timings and losses."""
    from unitac_rig.storage.reader import read_presses, session_files
    from unitac_rig.storage.recorder import SessionWriter

    rng = np.random.default_rng(0)
    rows = []
    for length in plan.press_lengths_s:
        per_sensor: dict[str, dict[str, Any]] = {}
        for sensor in ("papillarray", "uskin"):
            data_dir = work_dir / f"len{length:g}"
            object_id = f"bench{length:g}".replace(".", "p")
            writer = SessionWriter(data_dir, object_id, sensor, {"object": object_id, "sensor": sensor})
            records = [synthetic_press(sensor, length, i, rng) for i in range(plan.presses_per_length)]
            times = []
            for record in records:
                began = time.perf_counter()
                writer.write_press(record)
                times.append(time.perf_counter() - began)
            back = {r.press_id: r for r in read_presses(writer.path)}
            frames_written = sum(len(r.tactile_t_s) for r in records)
            lost = 0
            mismatched = 0
            for record in records:
                got = back.get(record.press_id)
                if got is None:
                    lost += len(record.tactile_t_s)
                    continue
                lost += max(0, len(record.tactile_t_s) - len(got.tactile_t_s))
                checks = (
                    _same(got.tactile_t_s, record.tactile_t_s),
                    _same(got.tactile_values, record.tactile_values),
                    _same(got.tactile_seq, record.tactile_seq),
                    _same(got.tactile_displacement_mm, record.tactile_displacement_mm),
                    _same(got.robot_t_s, record.robot_t_s),
                    _same(got.press_force_n, record.press_force_n.astype(np.float32)),
                )
                mismatched += not all(checks)
            seq = np.concatenate([b.tactile_seq for b in back.values()]) if back else np.zeros(0, np.int64)
            files = [*session_files(writer.path), *writer.journal.glob("*.h5")]
            file_mb = sum(p.stat().st_size for p in files) / 1e6
            per_sensor[sensor] = {
                "presses": len(records),
                "presses_read_back": len(back),
                "frames_written": frames_written,
                "frames_read_back": int(seq.size),
                "frames_lost": lost,
                "presses_not_identical": mismatched,
                "write_median_s": float(np.median(times)),
                "write_max_s": float(np.max(times)),
                "realtime_factor": length / float(np.median(times)),
                "mb_on_disk_per_press": file_mb / len(records),
            }
        combined_write_s = sum(s["write_median_s"] for s in per_sensor.values())
        rows.append(
            {
                "press_length_s": length,
                "robot_samples": round(ROBOT_HZ * length),
                "papillarray_frames": round(PAPILLARRAY_HZ * length),
                "uskin_frames": round(USKIN_HZ * length),
                "by_sensor": per_sensor,
                "combined_write_s": combined_write_s,
                "combined_headroom": length / combined_write_s,
            }
        )
    headroom = min(r["combined_headroom"] for r in rows)
    return {
        "rows": rows,
        "frames_lost": sum(s["frames_lost"] for r in rows for s in r["by_sensor"].values()),
        "presses_not_identical": sum(s["presses_not_identical"] for r in rows for s in r["by_sensor"].values()),
        "min_combined_headroom": headroom,
        "goal_headroom": GOAL_HEADROOM,
        "goal_met": headroom >= GOAL_HEADROOM,
    }


# ---------------------------------------------------------------------------------------------------------------------
# 2. the live path


def measure_live_papillarray(seconds: float, poll_period_s: float = 0.002) -> dict[str, Any]:
    """A real-time simulated hub at 1000 Hz read by the driver's reader thread for ``seconds``; sent vs delivered."""
    from drivers.layouts import PAPILLARRAY
    from drivers.papillarray import PapillArrayDriver
    from unitac_rig.sim.devices.papillarray import SimPapillArrayHub
    from unitac_rig.sim.synthetic_sources import PressSource

    hub = SimPapillArrayHub(source=PressSource(PAPILLARRAY), rate_hz=1000)
    driver = PapillArrayDriver(hub.url, rate_hz=1000)
    frames = []
    poll_gaps = []
    try:
        driver.connect()
        driver.start_reader()
        time.sleep(0.2)  # let the rate command land and the first packets arrive
        driver.poll()
        sent_before, counter_began = hub.packets_sent, hub.counter
        cpu_began, began = time.process_time(), time.perf_counter()
        last = began
        while time.perf_counter() - began < seconds:
            time.sleep(poll_period_s)
            frames.extend(driver.poll())
            now = time.perf_counter()
            poll_gaps.append(now - last)
            last = now
        sent_during, counter_ended = hub.packets_sent - sent_before, hub.counter
        elapsed = time.perf_counter() - began
        cpu = time.process_time() - cpu_began
        # what was still on the wire when the window closed: read until the window's last packet is in (<= 2 s)
        deadline = time.perf_counter() + 2.0
        while time.perf_counter() < deadline and not any(
            f.seq is not None and f.seq >= counter_ended - 1 for f in frames[-50:]
        ):
            time.sleep(0.01)
            frames.extend(driver.poll())
        health = driver.health()
    finally:
        driver.disconnect()
        hub.close()
    all_seq = np.array([f.seq for f in frames if f.seq is not None], dtype=np.int64)
    in_order = bool(np.all(np.diff(all_seq) > 0)) if all_seq.size > 1 else True
    # the packets the hub numbered during the window (its counter runs without wrapping here)
    seq = all_seq[(all_seq >= counter_began) & (all_seq < counter_ended)]
    missing = int((counter_ended - counter_began) - np.unique(seq).size)
    device_dt_us = np.diff([f.device_t_us for f in frames if f.device_t_us is not None])
    return {
        "seconds": elapsed,
        "hub_packets_sent": int(sent_during),
        "hub_rate_hz": sent_during / elapsed,
        "frames_delivered": int(seq.size),
        "counter_first": int(counter_began),
        "counter_last": int(counter_ended - 1),
        "counter_gaps": missing,
        "driver_sequence_gaps": health.sequence_gaps,
        "checksum_errors": health.checksum_errors,
        "bytes_dropped": health.bytes_dropped,
        "in_order": in_order,
        "device_period_us_median": float(np.median(device_dt_us)) if device_dt_us.size else None,
        "device_period_us_max": float(np.max(device_dt_us)) if device_dt_us.size else None,
        "poll_period_ms_median": 1e3 * float(np.median(poll_gaps)) if poll_gaps else None,
        "poll_period_ms_max": 1e3 * float(np.max(poll_gaps)) if poll_gaps else None,
        "cpu_share": cpu / elapsed,
    }


def run_recorder_benchmark(plan: RecorderPlan, work_dir: Path | None = None) -> dict[str, Any]:
    """Both measurements; ``work_dir`` (default: a temporary folder, removed afterwards) holds the sessions."""
    from unitac_rig.bench import machine_info

    host = machine_info()
    own = work_dir is None
    folder = Path(tempfile.mkdtemp(prefix="bench-recorder-")) if work_dir is None else Path(work_dir)
    try:
        recorder = measure_recorder(plan, folder)
    finally:
        if own:
            shutil.rmtree(folder, ignore_errors=True)
    live = measure_live_papillarray(plan.live_seconds)
    return {
        "benchmark": "recorder",
        "machine": host,
        "work_dir": str(folder),
        "filesystem": _filesystem(folder),
        "plan": {
            "press_lengths_s": list(plan.press_lengths_s),
            "presses_per_length": plan.presses_per_length,
            "live_seconds": plan.live_seconds,
            "rates_hz": {"robot": ROBOT_HZ, "papillarray": PAPILLARRAY_HZ, "uskin": USKIN_HZ},
        },
        "recorder": recorder,
        "live_papillarray": live,
    }


def _filesystem(path: Path) -> str:
    """The mount's file-system type (fsync costs differ: tmpfs makes it free), or 'unknown'."""
    try:
        target = str(Path(path).resolve())
        best, kind = "", "unknown"
        with open("/proc/mounts") as fh:
            for line in fh:
                parts = line.split()
                if len(parts) >= 3 and target.startswith(parts[1]) and len(parts[1]) > len(best):
                    best, kind = parts[1], parts[2]
        return kind
    except OSError:
        return "unknown"


def plot_recorder_benchmark(doc: dict[str, Any], path: Path) -> Path:
    """Headroom (recorded stream seconds per writing second) per press length and sensor, against the 10x goal."""
    from unitac_rig.plotting import new_figure, save_figure  # matplotlib loads slowly: only when drawing

    rows = doc["recorder"]["rows"]
    lengths = [r["press_length_s"] for r in rows]
    fig = new_figure(12.0, 4.6, dpi=100, layout="tight")
    ax, ax2 = fig.subplots(1, 2)
    x = np.arange(len(rows))
    width = 0.27
    series = [
        ("PapillArray 1000 Hz + robot 500 Hz", [r["by_sensor"]["papillarray"]["realtime_factor"] for r in rows]),
        ("uSkin 100 Hz + robot 500 Hz", [r["by_sensor"]["uskin"]["realtime_factor"] for r in rows]),
        ("all three streams", [r["combined_headroom"] for r in rows]),
    ]
    for i, (label, values) in enumerate(series):
        bars = ax.bar(x + (i - 1) * width, values, width, label=label)
        ax.bar_label(bars, fmt="%.0fx", fontsize=7)
    ax.axhline(GOAL_HEADROOM, color="red", ls=":", lw=1, label=f"goal {GOAL_HEADROOM:g}x")
    ax.set_xticks(x, [f"{v:g} s press" for v in lengths])
    ax.set_ylabel("stream seconds recorded per second of writing (x real time)")
    ax.set_yscale("log")
    ax.set_title(
        f"SessionWriter.write_press (journal + fsync + session), {doc['filesystem']}; "
        f"frames lost: {doc['recorder']['frames_lost']}",
        fontsize=9,
    )
    top = max(max(values) for _, values in series)
    ax.set_ylim(GOAL_HEADROOM / 3, top * 3)
    ax.legend(fontsize=8, loc="upper left")
    ax.grid(True, axis="y", which="both", alpha=0.3)
    live = doc["live_papillarray"]
    labels = ["hub sent", "driver delivered", "counter gaps"]
    values = [live["hub_packets_sent"], live["frames_delivered"], live["counter_gaps"]]
    bars = ax2.bar(labels, values, color=["tab:gray", "tab:green", "tab:red"])
    ax2.bar_label(bars, fmt="%d", fontsize=8)
    ax2.set_ylabel("frames")
    ax2.set_title(
        f"live: simulated hub at {live['hub_rate_hz']:.0f} Hz -> PapillArrayDriver reader thread, "
        f"{live['seconds']:.1f} s",
        fontsize=9,
    )
    ax2.grid(True, axis="y", alpha=0.3)
    return save_figure(fig, path)


def summary_lines(doc: dict[str, Any]) -> list[str]:
    rec = doc["recorder"]
    lines = [f"recorder ({doc['filesystem']} at {doc['work_dir']}):"]
    lines.append(f"{'press':>7s} {'sensor':>12s} {'write ms':>9s} {'x real time':>11s} {'MB/press':>9s} {'lost':>5s}")
    for r in rec["rows"]:
        for sensor, s in r["by_sensor"].items():
            lines.append(
                f"{r['press_length_s']:6.1f}s {sensor:>12s} {1e3 * s['write_median_s']:9.1f} "
                f"{s['realtime_factor']:11.1f} {s['mb_on_disk_per_press']:9.2f} {s['frames_lost']:5d}"
            )
        lines.append(f"{r['press_length_s']:6.1f}s {'all streams':>12s} headroom {r['combined_headroom']:.1f}x")
    lines.append(
        f"frames lost {rec['frames_lost']}, presses not identical on read-back {rec['presses_not_identical']}; "
        f"lowest headroom {rec['min_combined_headroom']:.1f}x (goal >= {GOAL_HEADROOM:g}x: "
        f"{'met' if rec['goal_met'] else 'NOT met'})"
    )
    live = doc["live_papillarray"]
    lines.append(
        f"live PapillArray: hub sent {live['hub_packets_sent']} packets in {live['seconds']:.2f} s "
        f"({live['hub_rate_hz']:.0f} Hz), driver delivered {live['frames_delivered']}, counter gaps "
        f"{live['counter_gaps']}, checksum errors {live['checksum_errors']}, CPU share {live['cpu_share']:.2f}"
    )
    return lines
