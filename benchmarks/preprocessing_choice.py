"""Which preprocessing to train with: the same model and seeds trained under each preprocessing option, scored on
the validation contacts only (the test set is never looked at for this choice).

The paper feeds raw readings (no per-channel z-score); ``raw`` itself leaves uSkin counts ~1000 times the
PapillArray's newtons in the summed loss, so the candidates are the per-sensor scalings beside the per-channel
z-score the project used before. For each option: validation NMAE / SSIM per direction under one common metric
reading (``sensor_range`` for both, so the options are compared on the same scale), the SSIM of each PapillArray
channel predicted from the uSkin, and the latent alignment (scale-free ratio, sensor mixing). Writes
``docs/figures/preprocessing_choice.json``; docs/learning.md argues the default from it.

    python benchmarks/preprocessing_choice.py --data DATA [--epochs 150] [--seeds 2] [--only MODE] [--render-only]
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path
from typing import Any

import numpy as np
import torch

from unitac_rig.bench import write_json
from unitac_rig.learning.data import PREPROCESSING, build_paired_dataset, load_sets
from unitac_rig.learning.engine import UNITAC_GROUP
from unitac_rig.learning.evaluate import Evaluator
from unitac_rig.learning.metrics import ssim_per_frame, ssim_scale
from unitac_rig.learning.run import checkpoint_path
from unitac_rig.learning.train import TrainConfig, load_run, train

ROOT = Path(__file__).resolve().parent.parent
RESULT = "choice.json"
DIRECTIONS = ("uskin_to_uskin", "uskin_to_papillarray", "papillarray_to_papillarray", "papillarray_to_uskin")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--data", type=Path)
    parser.add_argument("--out", type=Path, default=ROOT / "runs" / "preprocessing")
    parser.add_argument("--epochs", type=int, default=150)
    parser.add_argument("--seeds", type=int, default=2)
    parser.add_argument("--only", action="append", default=None, choices=PREPROCESSING)
    parser.add_argument("--render-only", action="store_true")
    parser.add_argument("--docs", type=Path, default=ROOT / "docs")
    args = parser.parse_args()
    if not args.render_only:
        dataset = build_paired_dataset(load_sets(args.data))
        for mode in args.only or PREPROCESSING:
            run_mode(dataset, args.out / mode, mode, args)
    found = {
        m: json.loads((args.out / m / RESULT).read_text()) for m in PREPROCESSING if (args.out / m / RESULT).exists()
    }
    doc = {"epochs": args.epochs, "seeds": args.seeds, "split": 0, "modes": found}
    write_json(doc, args.docs / "figures" / "preprocessing_choice.json")
    for line in table(doc):
        print(line)


def run_mode(dataset: Any, run_dir: Path, mode: str, args: argparse.Namespace) -> None:
    if (run_dir / RESULT).exists():
        return
    config = TrainConfig(
        epochs=args.epochs,
        seeds=tuple(range(args.seeds)),
        baselines=False,
        eval_every=max(1, args.epochs // 5),
        checkpoint_every=10**6,
        preprocessing=mode,
        nmae_normaliser="sensor_range",
        ssim_range="sensor_range",
    )
    began = time.process_time()
    if checkpoint_path(run_dir).exists():
        train(dataset, run_dir, None, resume=True, epochs=args.epochs, device="cpu")
    else:
        train(dataset, run_dir, config, device="cpu")
    cpu = time.process_time() - began
    run = load_run(run_dir)
    validation = dataset.subset(run.payload["val_mask"])
    evaluator = Evaluator.for_run(run, validation)
    summary = evaluator.summary(run.engine)["seen"]
    reconstructions = evaluator.reconstructions(run.engine)
    per_channel = {}
    for column in ("uskin_to_papillarray", "papillarray_to_papillarray"):
        target, frames = reconstructions[column]
        truth = evaluator.targets[target]
        scale = ssim_scale("channel_range", evaluator.stats(target))
        per_channel[column] = {
            axis: float(ssim_per_frame(truth[..., c : c + 1], frames[..., c : c + 1], scale[c : c + 1]).mean())
            for c, axis in enumerate("xyz")
        }
    result = {
        "mode": mode,
        "train_cpu_seconds": cpu,
        "validation": {c: {m: float(np.mean(summary[c][m])) for m in ("nmae", "ssim")} for c in DIRECTIONS},
        "papillarray_channel_ssim_own_range": per_channel,
        "latent_ratio": float(np.mean(summary["latent_ratio"])),
        "mixing": float(np.mean(summary["mixing"])),
        "mixing_expected": float(np.mean(summary["mixing_expected"])),
        "latent_scale": float(
            torch.stack([z.abs().mean() for z in evaluator.latents(run.engine.member(0, [UNITAC_GROUP])).values()])
            .mean()
            .item()
        ),
    }
    write_json(result, run_dir / RESULT)


def table(doc: dict[str, Any]) -> list[str]:
    """The markdown table docs/learning.md quotes."""
    lines = [
        "| preprocessing | val NMAE / SSIM u→u | u→p | p→p | p→u | PapillArray y SSIM from uSkin (own range) "
        "| matched/unmatched L1 | sensor mixing (perfect) |",
        "|---|---|---|---|---|---:|---:|---|",
    ]
    for mode, r in doc["modes"].items():
        cells = " | ".join(f"{r['validation'][c]['nmae']:.3f} / {r['validation'][c]['ssim']:.3f}" for c in DIRECTIONS)
        lines.append(
            f"| `{mode}` | {cells} | {r['papillarray_channel_ssim_own_range']['uskin_to_papillarray']['y']:.3f} | "
            f"{r['latent_ratio']:.3f} | {r['mixing']:.3f} ({r['mixing_expected']:.3f}) |"
        )
    return lines


if __name__ == "__main__":
    main()
