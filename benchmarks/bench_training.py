"""Training speed and the training-budget / accuracy trade-off for UniTac-NV.

1. Speed: seconds per epoch at the paper's batch size (64) of
   - the plain eager loop (``nn.Module`` + ``DataLoader`` over a ``TensorDataset`` + ``torch.optim.Adam``), at
     torch's default thread count and at one thread;
   - the project's engine (hand-written batched forward/backward, fused Adam) for the same single model;
   - the engine training 5 seeds of UniTac-NV plus both per-sensor baselines together (15 models), per model.
   Each is timed over a few epochs after one warm-up epoch and extrapolated to the paper's 1000 epochs.
2. Budget vs accuracy: one run of the engine (UniTac-NV + baselines) with test NMAE / SSIM (self and cross) every
   few epochs, charted against epochs and wall time.

Data: ``--data DIR`` (session files), else synthetic contacts of the paper's size (7 objects x 91 angles x 25
targets, irregular prism x 4 rotations; ``unitac_rig.learning.synthetic_data``).

    python benchmarks/bench_training.py [--data DIR] [--epochs 300] [--eval-every 5] [--speed-epochs 3]

Writes docs/figures/bench_training.json and docs/figures/bench_training.png and prints a summary.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import tempfile
import time
from pathlib import Path

import numpy as np
import torch

from drivers.layouts import PAPILLARRAY, USKIN
from unitac_rig.learning.data import Normaliser, build_paired_dataset, load_sets, split_by_direction
from unitac_rig.learning.engine import ModelShape, StackedAutoencoders, default_groups
from unitac_rig.learning.reference import UniTacModule, train_plain
from unitac_rig.learning.synthetic_data import synthetic_matched_sets
from unitac_rig.learning.train import TrainConfig, train

PAPER_OBJECTS = ("circle_pla", "square_pla", "hex_pla", "circle_tpu", "square_tpu", "hex_tpu", "irregular_pla")
ROOT = Path(__file__).resolve().parent.parent


def engine_epoch_seconds(
    x: torch.Tensor, feature_dims: dict[str, int], seeds: list[int], baselines: bool, epochs: int
) -> float:
    engine = StackedAutoencoders(feature_dims, default_groups(list(feature_dims), baselines), seeds, ModelShape())
    optimizer = engine.make_optimizer(5e-4)
    rngs = [np.random.default_rng(s) for s in seeds]
    n = x.shape[0]
    times = []
    with torch.no_grad():
        for _ in range(epochs + 1):
            began = time.perf_counter()
            order = torch.from_numpy(np.stack([r.permutation(n) for r in rngs]))
            shuffled = x[order]
            for start in range(0, n, 64):
                engine.train_step(shuffled[:, start : start + 64], optimizer)
            times.append(time.perf_counter() - began)
    return float(np.median(times[1:]))


def plain_epoch_seconds(x: torch.Tensor, feature_dims: dict[str, int], epochs: int) -> float:
    module = UniTacModule(feature_dims, ModelShape())
    inputs = list(torch.split(x, list(feature_dims.values()), dim=1))
    train_plain(module, inputs, 1)  # warm-up
    times = []
    for _ in range(epochs):
        began = time.perf_counter()
        train_plain(module, inputs, 1)
        times.append(time.perf_counter() - began)
    return float(np.median(times))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--data", type=Path, default=None)
    parser.add_argument("--epochs", type=int, default=300, help="epochs of the budget/accuracy run")
    parser.add_argument("--eval-every", type=int, default=5)
    parser.add_argument("--speed-epochs", type=int, default=3)
    parser.add_argument("--out", type=Path, default=ROOT / "docs" / "figures")
    args = parser.parse_args()

    began = time.perf_counter()
    if args.data:
        sets = load_sets(args.data)
        source = str(args.data)
    else:
        sets = synthetic_matched_sets(PAPER_OBJECTS, [USKIN, PAPILLARRAY])
        source = "synthetic (unitac_rig.learning.synthetic_data), paper-sized"
    dataset = build_paired_dataset(sets)
    split = split_by_direction(dataset, 0)
    norm = Normaliser.fit(dataset, split.train_mask)
    train_rows = dataset.subset(split.train_mask)
    x = torch.from_numpy(np.concatenate([norm.normalise(s, train_rows.values[s]) for s in dataset.sensors], axis=1))
    feature_dims = {s: dataset.n_taxels(s) * 3 for s in dataset.sensors}
    print(f"data: {source}: {len(dataset)} pairs, {len(train_rows)} train ({time.perf_counter() - began:.1f} s)")

    default_threads = torch.get_num_threads()
    speed: dict[str, float] = {}
    speed["plain_default_threads"] = plain_epoch_seconds(x, feature_dims, args.speed_epochs)
    torch.set_num_threads(1)
    speed["plain_1_thread"] = plain_epoch_seconds(x, feature_dims, args.speed_epochs)
    speed["engine_1_model"] = engine_epoch_seconds(x, feature_dims, [0], False, args.speed_epochs)
    speed["engine_15_models"] = engine_epoch_seconds(x, feature_dims, [0, 1, 2, 3, 4], True, args.speed_epochs)
    best_plain = min(speed["plain_default_threads"], speed["plain_1_thread"])
    ratio_best = best_plain / speed["engine_1_model"]
    ratio = speed["plain_default_threads"] / speed["engine_1_model"]
    ratio_1t = speed["plain_1_thread"] / speed["engine_1_model"]
    per_model = speed["engine_15_models"] / 15
    print(
        f"seconds per epoch (batch 64, {len(train_rows)} rows): " + ", ".join(f"{k} {v:.3f}" for k, v in speed.items())
    )
    print(
        f"engine vs plain: {ratio:.2f}x (plain at {default_threads} threads), {ratio_1t:.2f}x (plain at 1 thread); "
        f"batched 5 seeds + baselines: {best_plain / per_model:.1f}x per model vs the faster plain setting"
    )
    print(
        f"1000 epochs extrapolated: plain {1000 * best_plain / 60:.1f} min (its faster setting), engine "
        f"{1000 * speed['engine_1_model'] / 60:.1f} min, "
        f"15 models batched {1000 * speed['engine_15_models'] / 60:.1f} min"
    )

    with tempfile.TemporaryDirectory() as tmp:
        outcome = train(
            dataset,
            Path(tmp) / "run",
            TrainConfig(epochs=args.epochs, eval_every=args.eval_every, checkpoint_every=10**6, tsne_contacts=10),
            device="cpu",
        )
    curve = []
    for record in outcome.history:
        if "test" not in record:
            continue
        entry = {"epoch": record["epoch"], "seconds": record["seconds"]}
        for subset in ("seen", "unseen"):
            for column, metrics in record["test"].get(subset, {}).items():
                if column != "latent_l1":
                    entry[f"{subset}/{column}/nmae"] = metrics["nmae"][0]
                    entry[f"{subset}/{column}/ssim"] = metrics["ssim"][0]
            if "latent_l1" in record["test"].get(subset, {}):
                entry[f"{subset}/latent_l1"] = record["test"][subset]["latent_l1"][0]
        curve.append(entry)
    result = {
        "data": source,
        "pairs": len(dataset),
        "train_rows": len(train_rows),
        "batch_size": 64,
        "machine": {
            "cpus": os.cpu_count(),
            "platform": platform.platform(),
            "torch": torch.__version__,
            "default_threads": default_threads,
        },
        "seconds_per_epoch": speed,
        "speedup_vs_best_plain": ratio_best,
        "speedup_vs_plain_default_threads": ratio,
        "speedup_vs_plain_1_thread": ratio_1t,
        "speedup_per_model_batched_15": best_plain / per_model,
        "budget_run": {"epochs": args.epochs, "train_seconds": outcome.train_seconds, "curve": curve},
    }
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "bench_training.json").write_text(json.dumps(result, indent=1) + "\n")
    plot(result, args.out / "bench_training.png")
    final = curve[-1]
    print(
        f"budget run: {args.epochs} epochs (UniTac-NV + 2 baselines) in {outcome.train_seconds:.1f} s; final seen "
        + ", ".join(
            f"{k.split('/')[1]} {v:.4f}" for k, v in final.items() if k.startswith("seen/") and k.endswith("nmae")
        )
    )
    print(f"wrote {args.out / 'bench_training.json'} and {args.out / 'bench_training.png'}")


def plot(result: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    curve = result["budget_run"]["curve"]
    epochs = [c["epoch"] for c in curve]
    seconds = [c["seconds"] for c in curve]
    columns = sorted({k.split("/")[1] for k in curve[0] if k.startswith("seen/") and k.endswith("/nmae")})
    fig, axes = plt.subplots(1, 3, figsize=(16, 4.4))
    for column in columns:
        style = "--" if column.startswith("ae_") else "-"
        label = column.replace("_to_", " → ")
        axes[0].plot(seconds, [c[f"seen/{column}/nmae"] for c in curve], style, label=label)
        axes[1].plot(seconds, [c[f"seen/{column}/ssim"] for c in curve], style, label=label)
    for ax, name in ((axes[0], "test NMAE (seen objects)"), (axes[1], "test SSIM (seen objects)")):
        ax.set_xlabel("training wall time (s, 1 CPU thread)")
        ax.set_ylabel(name)
        ax.grid(alpha=0.3)
        top = ax.secondary_xaxis(
            "top", functions=(lambda s: np.interp(s, seconds, epochs), lambda e: np.interp(e, epochs, seconds))
        )
        top.set_xlabel("epoch")
    axes[0].set_yscale("log")
    axes[0].legend(fontsize=7)
    speed = result["seconds_per_epoch"]
    labels = [
        "plain eager\n(default threads)",
        "plain eager\n(1 thread)",
        "engine\n1 model",
        "engine, 15 models\nper model",
    ]
    values = [
        speed["plain_default_threads"],
        speed["plain_1_thread"],
        speed["engine_1_model"],
        speed["engine_15_models"] / 15,
    ]
    bars = axes[2].bar(labels, values, color=["0.6", "0.75", "tab:blue", "tab:green"])
    for bar, value in zip(bars, values, strict=True):
        axes[2].text(bar.get_x() + bar.get_width() / 2, value, f"{value:.3f}s", ha="center", va="bottom", fontsize=8)
    axes[2].set_ylabel("seconds per epoch (batch 64)")
    axes[2].set_title(f"engine {result['speedup_vs_best_plain']:.2f}x faster than the faster plain setting", fontsize=9)
    axes[2].tick_params(axis="x", labelsize=7)
    fig.suptitle(f"UniTac-NV training on {result['train_rows']} training pairs ({result['data']})", fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


if __name__ == "__main__":
    main()
