"""Encode, decode and translate latency of a trained UniTac-NV model against the 1 ms a 1000 Hz stream leaves.

Uses the public learning API (:class:`unitac_rig.learning.translate.Translator`): ``encode`` (frames in sensor units
-> 16-d latent), decode (latent -> the other sensor's frame in its units: the shared decoder plus the
de-normalisation, as ``translate`` does it) and ``translate`` (both). Each is timed for one frame and for batches,
on the CPU, with torch at one thread (what the project's training uses for small matrices) and at torch's default.

Budget: a PapillArray streams at up to 1000 Hz, so per-frame work must stay under 1 ms to keep up (the uSkin at
100 Hz leaves 10 ms). Reported as ratios: budget / single-frame latency, and batch throughput / 1000 frames/s. A
batch of B frames also adds B ms of waiting for the frames to arrive; that trade (throughput against delay) is the
chart.

With no ``run_dir`` a tiny model is trained inside the benchmark on synthetic force-matched sets (its accuracy is
beside the point here: the network's size, not its weights, decides the latency).
"""

from __future__ import annotations

import statistics
import tempfile
import time
from collections.abc import Callable
from dataclasses import dataclass
from functools import partial
from pathlib import Path
from typing import Any

import numpy as np

BUDGET_MS = 1.0  # one frame period at 1000 Hz
STREAM_HZ = 1000.0


@dataclass(frozen=True)
class InferencePlan:
    batch_sizes: tuple[int, ...] = (1, 4, 16, 64, 256, 1024)
    min_repeats: int = 50
    min_seconds: float = 0.3  # time each case for at least this long (wall)
    train_epochs: int = 5


def full_plan() -> InferencePlan:
    return InferencePlan()


def quick_plan() -> InferencePlan:
    return InferencePlan(batch_sizes=(1, 64, 1024), min_repeats=20, min_seconds=0.05, train_epochs=1)


def train_tiny_run(run_dir: Path, epochs: int) -> Path:
    """Train UniTac-NV (no baselines) for ``epochs`` on synthetic sets of three objects x 11 angles x 5 targets."""
    from drivers.layouts import PAPILLARRAY, USKIN
    from unitac_rig.learning.data import build_paired_dataset
    from unitac_rig.learning.synthetic_data import synthetic_matched_sets
    from unitac_rig.learning.train import TrainConfig, train

    sets = synthetic_matched_sets(
        ("circle_pla", "hex_tpu", "irregular_pla"),
        (USKIN, PAPILLARRAY),
        angles_deg=tuple(float(a) for a in range(-45, 46, 9)),
        targets_n=(4.0, 5.5, 7.0, 8.5, 10.0),
    )
    dataset = build_paired_dataset(sets)
    config = TrainConfig(epochs=epochs, baselines=False, eval_every=epochs, checkpoint_every=epochs, tsne_contacts=0)
    train(dataset, run_dir, config, device="cpu")
    return run_dir


def _time_call(call: Callable[[], object], min_repeats: int, min_seconds: float) -> list[float]:
    """Wall times (ms) of ``call`` after a warm-up: at least ``min_repeats`` calls and ``min_seconds``."""
    for _ in range(5):
        call()
    times: list[float] = []
    began = time.perf_counter()
    while len(times) < min_repeats or time.perf_counter() - began < min_seconds:
        t0 = time.perf_counter()
        call()
        times.append((time.perf_counter() - t0) * 1e3)
    return times


def _stats(times_ms: list[float], batch: int) -> dict[str, float]:
    ordered = sorted(times_ms)
    median = statistics.median(ordered)
    return {
        "batch": batch,
        "calls": len(ordered),
        "median_ms": median,
        "p99_ms": ordered[min(len(ordered) - 1, int(0.99 * len(ordered)))],
        "per_frame_ms": median / batch,
        "frames_per_s": 1e3 * batch / median,
        "stream_headroom": (1e3 * batch / median) / STREAM_HZ,
    }


def measure_latency(translator: Any, plan: InferencePlan, rng: np.random.Generator) -> dict[str, Any]:
    """Per operation (encode/decode/translate, both sensors) and batch size: latency and throughput."""
    import torch

    from unitac_rig.learning.engine import UNITAC_GROUP

    sensors = list(translator.sensors)
    frames = {
        s: rng.normal(0.0, 1.0, (max(plan.batch_sizes), translator.engine.feature_dims[s] // 3, 3)).astype(np.float32)
        for s in sensors
    }
    for s in sensors:  # realistic magnitudes: de-normalised random frames
        frames[s] = translator.normaliser.denormalise(s, frames[s].reshape(frames[s].shape[0], -1)).astype(np.float32)

    def decode_call(z: np.ndarray, target: str) -> Callable[[], object]:
        def call() -> object:
            with torch.no_grad():
                out = translator.engine.decode(UNITAC_GROUP, torch.from_numpy(z)[None])[target][0].cpu().numpy()
            return translator.normaliser.denormalise(target, out)

        return call

    results: dict[str, list[dict[str, float]]] = {}
    for source in sensors:
        target = next(s for s in sensors if s != source)
        for batch in plan.batch_sizes:
            x = frames[source][:batch] if batch > 1 else frames[source][0]
            z = np.asarray(translator.encode(frames[source][:batch], source), dtype=np.float32)
            cases: dict[str, Callable[[], object]] = {
                f"encode {source}": partial(translator.encode, x, source),
                f"decode to {target}": decode_call(z, target),
                f"translate {source} -> {target}": partial(translator.translate, x, source, target),
            }
            for name, call in cases.items():
                results.setdefault(name, []).append(_stats(_time_call(call, plan.min_repeats, plan.min_seconds), batch))
    return results


def run_inference_benchmark(plan: InferencePlan, run_dir: Path | None = None) -> dict[str, Any]:
    """Load ``run_dir`` (or train a tiny run in a temporary folder) and time it at 1 thread and torch's default."""
    import torch

    from unitac_rig.bench import machine_info
    from unitac_rig.learning.run import computing_on
    from unitac_rig.learning.translate import Translator

    host = machine_info()
    rng = np.random.default_rng(0)
    with tempfile.TemporaryDirectory(prefix="bench-inference-") as tmp:
        trained_here = run_dir is None
        began = time.perf_counter()
        source_dir = train_tiny_run(Path(tmp) / "run", plan.train_epochs) if run_dir is None else Path(run_dir)
        train_s = time.perf_counter() - began
        translator = Translator.load(source_dir)
        default_threads = torch.get_num_threads()
        by_threads = {}
        for threads in sorted({1, default_threads}):
            with computing_on("cpu", threads):
                by_threads[str(threads)] = measure_latency(translator, plan, rng)
    single = {name: rows[0]["median_ms"] for name, rows in by_threads["1"].items() if rows and rows[0]["batch"] == 1}
    worst_single = max(single.values())
    return {
        "benchmark": "inference",
        "machine": host,
        "torch": torch.__version__,
        "torch_default_threads": default_threads,
        "run": "tiny synthetic run trained here" if trained_here else str(run_dir),
        "train_s": train_s if trained_here else None,
        "sensors": list(translator.sensors),
        "feature_dims": dict(translator.engine.feature_dims),
        "budget_ms": BUDGET_MS,
        "plan": {"batch_sizes": list(plan.batch_sizes), "min_repeats": plan.min_repeats},
        "by_threads": by_threads,
        "single_frame_median_ms": single,
        "worst_single_frame_ms": worst_single,
        "single_frame_budget_ratio": BUDGET_MS / worst_single,
        "within_budget": worst_single < BUDGET_MS,
    }


def plot_inference_benchmark(doc: dict[str, Any], path: Path) -> Path:
    """Per-frame cost and the delay a batch adds: where each operation sits against the 1 ms budget."""
    from unitac_rig.plotting import new_figure, save_figure  # matplotlib loads slowly: only when drawing

    fig = new_figure(12.5, 4.8, dpi=100, layout="tight")
    ax, ax2 = fig.subplots(1, 2)
    results = doc["by_threads"]["1"]
    styles = {"encode": "-", "decode": "--", "translate": ":"}
    for name, rows in results.items():
        batches = [r["batch"] for r in rows]
        style = styles[name.split(" ", 1)[0]]
        ax.plot(batches, [r["per_frame_ms"] for r in rows], style, marker="o", ms=3, label=name)
        # a batch of B frames at 1000 Hz waits B ms for its frames, then computes
        ax2.plot(
            [r["median_ms"] + r["batch"] * 1e3 / STREAM_HZ for r in rows],
            [r["frames_per_s"] / STREAM_HZ for r in rows],
            style,
            marker="o",
            ms=3,
            label=name,
        )
    default = str(doc["torch_default_threads"])
    if default != "1":
        for name, rows in doc["by_threads"][default].items():
            if name.startswith("translate"):
                ax.plot(
                    [r["batch"] for r in rows],
                    [r["per_frame_ms"] for r in rows],
                    color="grey",
                    lw=0.8,
                    marker="x",
                    ms=3,
                    label=f"{name}, torch {default} threads",
                )
    ax.axhline(doc["budget_ms"], color="red", ls=":", lw=1, label="1 ms (1000 Hz frame period)")
    ax.set_xscale("log", base=2)
    ax.set_yscale("log")
    ax.set_xlabel("frames per call (batch)")
    ax.set_ylabel("wall time per frame (ms, median)")
    ax.set_title("per-frame cost (CPU; coloured: torch 1 thread)", fontsize=10)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7)
    ax2.axhline(1.0, color="red", ls=":", lw=1, label="keeps up with 1000 Hz")
    ax2.set_xscale("log")
    ax2.set_yscale("log")
    ax2.set_xlabel("delay of a batch's oldest frame: B frames arriving at 1 kHz + compute (ms)")
    ax2.set_ylabel("throughput / 1000 frames/s")
    ax2.set_title("batching: throughput against added delay (torch 1 thread)", fontsize=10)
    ax2.grid(True, which="both", alpha=0.3)
    ax2.legend(fontsize=7)
    fig.suptitle(f"UniTac-NV inference ({doc['run']}); {doc['machine']['cpus']} CPUs", fontsize=10)
    return save_figure(fig, path)


def summary_lines(doc: dict[str, Any]) -> list[str]:
    lines = [f"model: {doc['run']}; sensors {doc['sensors']}; torch {doc['torch']}"]
    for threads, results in doc["by_threads"].items():
        lines.append(f"-- torch threads: {threads}")
        lines.append(
            f"{'operation':36s} {'batch':>6s} {'median ms':>10s} {'p99 ms':>8s} {'ms/frame':>9s} {'x 1 kHz':>8s}"
        )
        for name, rows in results.items():
            for r in rows:
                lines.append(
                    f"{name:36s} {r['batch']:6d} {r['median_ms']:10.3f} {r['p99_ms']:8.3f} "
                    f"{r['per_frame_ms']:9.4f} {r['stream_headroom']:8.1f}"
                )
    lines.append(
        f"worst single-frame median {doc['worst_single_frame_ms']:.3f} ms: {doc['single_frame_budget_ratio']:.1f}x "
        f"inside the {doc['budget_ms']:g} ms budget"
        if doc["within_budget"]
        else f"worst single-frame median {doc['worst_single_frame_ms']:.3f} ms: OVER the {doc['budget_ms']:g} ms budget"
    )
    return lines
