"""Decode throughput of the wire codecs on one core, as multiples of each device's highest data rate.

    python benchmarks/bench_codecs.py [--quick]

* PapillArray: framed packets with 2 sensor slots x 9 pillars and the slip blocks (815 bytes each), fed to
  ``PacketParser`` in 4 KiB reads and in 64-byte reads (a reader that wakes on every USB packet); hardware peak
  1000 packets/s.
* uSkin over CAN: 24 taxel messages per frame through ``FrameAssembler``; hardware ~100 frames/s (2400 messages/s).
* xela_server: one 24-taxel sensor per JSON message through ``decode_message`` (hex string and int list forms);
  the server broadcasts ~100 messages/s.

All codecs run on the one Python thread (so on one core at a time). Each figure is the best of several repeats (the
least disturbed run); the 1-minute load average at the start is recorded because the box may be shared.
Writes docs/figures/bench_codecs.json and docs/figures/bench_codecs.png.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import time
from collections.abc import Callable
from pathlib import Path

import matplotlib
import numpy as np

matplotlib.use("Agg")
import matplotlib.pyplot as plt

from protocols.papillarray import PacketParser, PapillArrayPacket, PillarSensorData, encode_packet
from protocols.xela_can import USPA46_ID_MAP, FrameAssembler, encode_taxel_message
from protocols.xela_ws import XelaSensorData, XelaWelcome, decode_message, encode_data_message

ROOT = Path(__file__).resolve().parents[1]
FIGURES = ROOT / "docs" / "figures"
TARGET_MULTIPLE = 50.0

HARDWARE_PEAK = {
    "papillarray_packets_per_s": 1000.0,
    "uskin_can_frames_per_s": 100.0,
    "xela_server_msgs_per_s": 100.0,
}


def best_rate(run: Callable[[], int], repeats: int) -> float:
    """Items per second of the fastest of ``repeats`` runs (``run`` returns how many items it processed)."""
    best = 0.0
    for _ in range(repeats):
        start = time.perf_counter()
        items = run()
        elapsed = time.perf_counter() - start
        best = max(best, items / elapsed)
    return best


def papillarray_stream(n_packets: int, rng: np.random.Generator) -> bytes:
    def sensor() -> PillarSensorData:
        return PillarSensorData(
            forces_n=rng.normal(0.0, 1.0, (9, 3)),
            displacements_mm=rng.normal(0.0, 0.2, (9, 3)),
            global_force_n=rng.normal(0.0, 3.0, 3),
            global_torque_nmm=rng.normal(0.0, 20.0, 3),
            slip_states=rng.integers(-2, 4, 9),
            pillar_friction=rng.uniform(0.1, 1.0, 9),
            slip_active=1,
            friction_estimate=0.6,
            target_grip_force_n=-1.0,
        )

    templates = [encode_packet(PapillArrayPacket(i, 1000 * i, [sensor(), sensor()])) for i in range(64)]
    return b"".join(templates[i % len(templates)] for i in range(n_packets))


def bench_papillarray(n_packets: int, repeats: int, read_size: int) -> dict[str, float]:
    stream = papillarray_stream(n_packets, np.random.default_rng(1))
    chunks = [stream[i : i + read_size] for i in range(0, len(stream), read_size)]

    def run() -> int:
        parser = PacketParser()
        count = 0
        for chunk in chunks:
            count += len(parser.feed(chunk))
        assert count == n_packets and parser.bytes_dropped == 0
        return count

    rate = best_rate(run, repeats)
    return {
        "packets_per_s": rate,
        "bytes_per_packet": len(stream) / n_packets,
        "read_size_bytes": read_size,
        "items": n_packets,
    }


def bench_uskin_can(n_frames: int, repeats: int) -> dict[str, float]:
    rng = np.random.default_rng(2)
    ids = USPA46_ID_MAP.ids
    messages = []
    for frame in range(n_frames):
        counts = rng.integers(15_000, 40_000, size=(24, 3))
        for index, arbitration_id in enumerate(ids):
            payload = encode_taxel_message(arbitration_id, *counts[index].tolist())
            messages.append((arbitration_id, payload, frame * 10_000_000 + index * 400_000))

    def run() -> int:
        assembler = FrameAssembler()
        frames = 0
        for arbitration_id, payload, t_ns in messages:
            if assembler.add(arbitration_id, payload, t_ns) is not None:
                frames += 1
        assert frames == n_frames and assembler.messages == 24 * n_frames and assembler.incomplete_frames == 0
        return frames

    frames_per_s = best_rate(run, repeats)
    return {"frames_per_s": frames_per_s, "messages_per_s": 24 * frames_per_s, "items": n_frames}


def bench_xela_server(n_messages: int, repeats: int, as_hex: bool) -> dict[str, float]:
    rng = np.random.default_rng(3)
    texts = [
        encode_data_message(
            seq, 1.7e9 + seq / 100, [XelaSensorData(1, "uSPa46", 24, rng.integers(15_000, 40_000, (24, 3)))], as_hex
        )
        for seq in range(n_messages)
    ]

    first = decode_message(texts[0])
    assert not isinstance(first, XelaWelcome) and first.sensors[1].values.shape == (24, 3)

    def run() -> int:
        for text in texts:
            decode_message(text)
        return len(texts)

    return {"msgs_per_s": best_rate(run, repeats), "bytes_per_msg": sum(map(len, texts)) / n_messages}


def machine() -> dict[str, object]:
    model = platform.processor() or "unknown"
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                model = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    return {
        "cpu": model,
        "load_average_1min": round(os.getloadavg()[0], 2) if hasattr(os, "getloadavg") else None,
        "logical_cpus": os.cpu_count(),
        "python": platform.python_version(),
        "numpy": np.__version__,
        "platform": platform.platform(),
    }


def plot(results: dict[str, dict[str, float]], path: Path) -> None:
    labels = [
        "PapillArray\n4 KiB reads\n(peak 1000 packets/s)",
        "PapillArray\n64 B reads\n(peak 1000 packets/s)",
        "uSkin CAN\nFrameAssembler\n(~100 frames/s)",
        "xela_server JSON\nhex data\n(~100 msg/s)",
        "xela_server JSON\nint-list data\n(~100 msg/s)",
    ]
    multiples = [
        results["papillarray"]["x_hardware"],
        results["papillarray_64b_reads"]["x_hardware"],
        results["uskin_can"]["x_hardware"],
        results["xela_server_hex"]["x_hardware"],
        results["xela_server_list"]["x_hardware"],
    ]
    fig, ax = plt.subplots(figsize=(10.5, 5.4), dpi=120)
    colors = ["#3b7dd8", "#7fa7e3", "#2a9d8f", "#c0462a", "#b5651d"]
    bars = ax.bar(labels, multiples, color=colors, edgecolor="black", linewidth=0.6)
    ax.set_yscale("log")
    ax.axhline(TARGET_MULTIPLE, color="black", linestyle="--", linewidth=1.2, label=f"target {TARGET_MULTIPLE:.0f}x")
    ax.axhline(1.0, color="dimgrey", linestyle=":", linewidth=1.2, label="device peak rate (1x)")
    ax.legend(loc="upper right", fontsize=10, framealpha=0.95)
    absolute = [
        f"{results['papillarray']['packets_per_s'] / 1000:,.0f}k packets/s",
        f"{results['papillarray_64b_reads']['packets_per_s'] / 1000:,.0f}k packets/s",
        f"{results['uskin_can']['frames_per_s'] / 1000:,.0f}k frames/s",
        f"{results['xela_server_hex']['msgs_per_s'] / 1000:,.0f}k msg/s",
        f"{results['xela_server_list']['msgs_per_s'] / 1000:,.0f}k msg/s",
    ]
    for bar, multiple, rate in zip(bars, multiples, absolute, strict=True):
        x = bar.get_x() + bar.get_width() / 2
        ax.text(x, multiple * 1.12, f"{multiple:,.0f}x", ha="center", va="bottom", fontsize=12, fontweight="bold")
        ax.text(x, 1.6, rate, ha="center", va="bottom", fontsize=10, color="white", fontweight="bold")
    ax.set_ylim(0.5, max(multiples) * 8)
    ax.set_ylabel("decode throughput / device peak rate (log scale)", fontsize=11)
    ax.set_title("Wire codec decode throughput on one CPU core", fontsize=13)
    ax.tick_params(axis="x", labelsize=10)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="fewer items and repeats (smoke run)")
    args = parser.parse_args()
    scale, repeats = (0.1, 2) if args.quick else (1.0, 5)
    host = machine()

    papillarray = bench_papillarray(int(20_000 * scale), repeats, read_size=4096)
    papillarray_small = bench_papillarray(int(20_000 * scale), repeats, read_size=64)
    uskin = bench_uskin_can(int(10_000 * scale), repeats)
    xela_hex = bench_xela_server(int(10_000 * scale), repeats, as_hex=True)
    xela_list = bench_xela_server(int(10_000 * scale), repeats, as_hex=False)

    papillarray["x_hardware"] = papillarray["packets_per_s"] / HARDWARE_PEAK["papillarray_packets_per_s"]
    papillarray_small["x_hardware"] = papillarray_small["packets_per_s"] / HARDWARE_PEAK["papillarray_packets_per_s"]
    uskin["x_hardware"] = uskin["frames_per_s"] / HARDWARE_PEAK["uskin_can_frames_per_s"]
    xela_hex["x_hardware"] = xela_hex["msgs_per_s"] / HARDWARE_PEAK["xela_server_msgs_per_s"]
    xela_list["x_hardware"] = xela_list["msgs_per_s"] / HARDWARE_PEAK["xela_server_msgs_per_s"]
    results = {
        "papillarray": papillarray,
        "papillarray_64b_reads": papillarray_small,
        "uskin_can": uskin,
        "xela_server_hex": xela_hex,
        "xela_server_list": xela_list,
    }
    report = {
        "command": "python benchmarks/bench_codecs.py" + (" --quick" if args.quick else ""),
        "machine": host,
        "hardware_peak": HARDWARE_PEAK,
        "target_multiple": TARGET_MULTIPLE,
        "repeats": repeats,
        "results": results,
    }
    FIGURES.mkdir(parents=True, exist_ok=True)
    (FIGURES / "bench_codecs.json").write_text(json.dumps(report, indent=2) + "\n")
    plot(results, FIGURES / "bench_codecs.png")

    print(f"machine: {host['cpu']} ({host['logical_cpus']} logical CPUs, load average {host['load_average_1min']})")
    print(f"PapillArray  {papillarray['packets_per_s']:>10,.0f} packets/s  = {papillarray['x_hardware']:6.0f}x 1000/s")
    print(
        f"  64 B reads {papillarray_small['packets_per_s']:>10,.0f} packets/s  = "
        f"{papillarray_small['x_hardware']:6.0f}x 1000/s"
    )
    print(
        f"uSkin CAN    {uskin['frames_per_s']:>10,.0f} frames/s   = {uskin['x_hardware']:6.0f}x 100/s"
        f"  ({uskin['messages_per_s']:,.0f} messages/s)"
    )
    print(f"xela hex     {xela_hex['msgs_per_s']:>10,.0f} msgs/s     = {xela_hex['x_hardware']:6.0f}x 100/s")
    print(f"xela list    {xela_list['msgs_per_s']:>10,.0f} msgs/s     = {xela_list['x_hardware']:6.0f}x 100/s")
    print(f"wrote {FIGURES / 'bench_codecs.json'} and {FIGURES / 'bench_codecs.png'}")


if __name__ == "__main__":
    main()
