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
import os
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

from protocols.papillarray import PacketParser, PapillArrayPacket, PillarSensorData, encode_packet
from protocols.xela_can import USPA46_ID_MAP, FrameAssembler, encode_taxel_message
from protocols.xela_ws import XelaSensorData, XelaWelcome, decode_message, encode_data_message
from unitac_rig.bench import default_out_dir, machine_info, write_json
from unitac_rig.plotting import new_figure, save_figure

TARGET_MULTIPLE = 50.0

HARDWARE_PEAK = {
    "papillarray_packets_per_s": 1000.0,
    "uskin_can_frames_per_s": 100.0,
    "xela_server_msgs_per_s": 100.0,
}


Bench = tuple[Callable[[], int], dict[str, float]]  # (run -> items processed, facts about the workload)


def measure(benches: dict[str, Bench], repeats: int) -> dict[str, dict[str, float]]:
    """Time every bench ``repeats`` times, interleaved so each one samples the whole window; best and median rate."""
    rates: dict[str, list[float]] = {name: [] for name in benches}
    for _ in range(repeats):
        for name, (run, _) in benches.items():
            start = time.perf_counter()
            items = run()
            rates[name].append(items / (time.perf_counter() - start))
    return {
        name: {**facts, "best_per_s": max(rates[name]), "median_per_s": float(np.median(rates[name]))}
        for name, (_, facts) in benches.items()
    }


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


def bench_papillarray(n_packets: int, read_size: int) -> Bench:
    """Packets through PacketParser, fed in reads of ``read_size`` bytes."""
    stream = papillarray_stream(n_packets, np.random.default_rng(1))
    chunks = [stream[i : i + read_size] for i in range(0, len(stream), read_size)]

    def run() -> int:
        parser = PacketParser()
        count = 0
        for chunk in chunks:
            count += len(parser.feed(chunk))
        assert count == n_packets and parser.bytes_dropped == 0
        return count

    return run, {"bytes_per_packet": len(stream) / n_packets, "read_size_bytes": read_size, "items": n_packets}


def bench_uskin_can(n_frames: int) -> Bench:
    """Frames (24 taxel messages each) through FrameAssembler."""
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

    return run, {"messages_per_frame": 24, "items": n_frames}


def bench_xela_server(n_messages: int, as_hex: bool) -> Bench:
    """One-sensor (24 taxel) xela_server JSON messages through decode_message."""
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

    return run, {"bytes_per_msg": sum(map(len, texts)) / n_messages, "items": n_messages}


# name -> (chart label, unit of one item, device peak rate in items/s)
CASES: dict[str, tuple[str, str, float]] = {
    "papillarray_4k_reads": ("PapillArray\n4 KiB reads\n(peak 1000 packets/s)", "packets", 1000.0),
    "papillarray_64b_reads": ("PapillArray\n64 B reads\n(peak 1000 packets/s)", "packets", 1000.0),
    "uskin_can": ("uSkin CAN\nFrameAssembler\n(~100 frames/s)", "frames", 100.0),
    "xela_server_hex": ("xela_server JSON\nhex data\n(~100 msg/s)", "msgs", 100.0),
    "xela_server_list": ("xela_server JSON\nint-list data\n(~100 msg/s)", "msgs", 100.0),
}


def plot(results: dict[str, dict[str, float]], path: Path) -> None:
    names = list(CASES)
    multiples = [results[name]["x_device_peak"] for name in names]
    fig = new_figure(10.5, 5.4, dpi=120, layout="tight")
    ax = fig.subplots()
    colors = ["#3b7dd8", "#7fa7e3", "#2a9d8f", "#c0462a", "#b5651d"]
    bars = ax.bar([CASES[name][0] for name in names], multiples, color=colors, edgecolor="black", linewidth=0.6)
    ax.set_yscale("log")
    ax.axhline(TARGET_MULTIPLE, color="black", linestyle="--", linewidth=1.2, label=f"target {TARGET_MULTIPLE:.0f}x")
    ax.axhline(1.0, color="dimgrey", linestyle=":", linewidth=1.2, label="device peak rate (1x)")
    ax.legend(loc="upper right", fontsize=10, framealpha=0.95)
    for bar, name, multiple in zip(bars, names, multiples, strict=True):
        x = bar.get_x() + bar.get_width() / 2
        rate = f"{results[name]['best_per_s'] / 1000:,.0f}k {CASES[name][1]}/s"
        ax.text(x, multiple * 1.12, f"{multiple:,.0f}x", ha="center", va="bottom", fontsize=12, fontweight="bold")
        ax.text(x, 1.6, rate, ha="center", va="bottom", fontsize=10, color="white", fontweight="bold")
    ax.set_ylim(0.5, max(multiples) * 8)
    ax.set_ylabel("decode throughput / device peak rate (log scale)", fontsize=11)
    ax.set_title("Wire codec decode throughput, one Python thread (best of repeats)", fontsize=13)
    ax.tick_params(axis="x", labelsize=10)
    save_figure(fig, path)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="fewer items and repeats (smoke run)")
    parser.add_argument("--repeats", type=int, default=9, help="timed runs per case, interleaved (default 9)")
    parser.add_argument("--out", type=Path, default=default_out_dir(), help="folder for the JSON and PNG")
    args = parser.parse_args()
    scale, repeats = (0.1, 2) if args.quick else (1.0, args.repeats)
    host = machine_info()

    benches = {
        "papillarray_4k_reads": bench_papillarray(int(10_000 * scale), read_size=4096),
        "papillarray_64b_reads": bench_papillarray(int(10_000 * scale), read_size=64),
        "uskin_can": bench_uskin_can(int(5_000 * scale)),
        "xela_server_hex": bench_xela_server(int(5_000 * scale), as_hex=True),
        "xela_server_list": bench_xela_server(int(5_000 * scale), as_hex=False),
    }
    results = measure(benches, repeats)
    for name, (_, unit, peak) in CASES.items():
        results[name]["unit"] = unit  # type: ignore[assignment]
        results[name]["device_peak_per_s"] = peak
        results[name]["x_device_peak"] = results[name]["best_per_s"] / peak
        results[name]["x_device_peak_median"] = results[name]["median_per_s"] / peak
    host["load_average_1min_after"] = round(os.getloadavg()[0], 2) if hasattr(os, "getloadavg") else None
    report = {
        "command": "python benchmarks/bench_codecs.py" + (" --quick" if args.quick else ""),
        "machine": host,
        "target_multiple": TARGET_MULTIPLE,
        "repeats": repeats,
        "results": results,
    }
    json_path = write_json(report, args.out / "bench_codecs.json")
    plot(results, args.out / "bench_codecs.png")

    print(f"machine: {host['cpu_model']}, {host['cpus']} logical CPUs, load average {host['load_average_1min']}")
    print(f"{'case':<24}{'best/s':>12}{'median/s':>12}{'best x peak':>13}{'median x peak':>15}")
    for name, (_, unit, peak) in CASES.items():
        row = results[name]
        print(
            f"{name:<24}{row['best_per_s']:>12,.0f}{row['median_per_s']:>12,.0f}"
            f"{row['x_device_peak']:>12,.0f}x{row['x_device_peak_median']:>14,.0f}x   ({unit}, peak {peak:,.0f}/s)"
        )
    print(f"wrote {json_path} and {args.out / 'bench_codecs.png'}")


if __name__ == "__main__":
    main()
