"""Measure why a headline claim of the paper does or does not reproduce on a finished run.

For one run (``benchmarks/run_results.py`` makes one per split) on its seen test contacts, mean over the run's
members, under the run's metric options:

* per channel (x, y, z) NMAE and SSIM of every UniTac-NV direction: which channel a cross direction loses on;
* sensor mixing of the final UniTac-NV latents (all test contacts) at several neighbourhood sizes k: whether the two
  sensors share neighbourhoods only at a coarse scale (the same shape and force) or contact by contact;
* the matched and the unmatched latent L1 after epoch 1 and at the end (from ``metrics.json``): whether a falling raw
  distance is alignment or the latents shrinking.

Writes ``docs/figures/claims_diagnosis.json`` (one entry per run given) and prints a summary.

    python benchmarks/claims_diagnosis.py RUN [RUN ...] [--out docs/figures/claims_diagnosis.json]
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

import numpy as np
import torch

from unitac_rig.learning.evaluate import Evaluator
from unitac_rig.learning.metrics import nmae_per_frame, nmae_scale, sensor_mixing, ssim_per_frame, ssim_scale
from unitac_rig.learning.train import load_run, load_test_set

ROOT = Path(__file__).resolve().parent.parent
CHANNELS = ("x", "y", "z")
MIXING_K = (10, 50, 200)


def per_channel(evaluator: Evaluator, engine: Any, subset: str) -> dict[str, dict[str, float]]:
    """{direction: {"nmae_x".., "ssim_x"..: value}} on one subset, mean over members and frames."""
    mask = evaluator.subsets[subset]
    out: dict[str, dict[str, float]] = {}
    for column, (sensor, frames) in evaluator.reconstructions(engine).items():
        if column.startswith("ae_"):
            continue
        target = evaluator.targets[sensor][mask]
        estimate = frames[:, mask]
        stats = evaluator.stats(sensor)
        nmae_range = torch.broadcast_to(nmae_scale(evaluator.nmae_normaliser, stats, target), (*target.shape[:-2], 3))
        ssim_range = ssim_scale(evaluator.ssim_range, stats)
        nmae, ssim = [], []
        for i in range(len(CHANNELS)):  # the project's own per-frame metrics on one channel at a time
            one = slice(i, i + 1)
            nmae.append(float(nmae_per_frame(target[..., one], estimate[..., one], nmae_range[..., one]).mean()))
            ssim.append(float(ssim_per_frame(target[..., one], estimate[..., one], ssim_range[..., one]).mean()))
        out[column] = {f"nmae_{c}": float(nmae[i]) for i, c in enumerate(CHANNELS)}
        out[column].update({f"ssim_{c}": float(ssim[i]) for i, c in enumerate(CHANNELS)})
    return out


def diagnose(run_dir: Path) -> dict[str, Any]:
    run, test = load_run(run_dir), load_test_set(run_dir)
    evaluator = Evaluator.for_run(run, test)
    with torch.no_grad():
        latents = evaluator.latents(run.engine)
        members = next(iter(latents.values())).shape[0]
        mixing = {
            str(k): float(np.mean([sensor_mixing([z[m] for z in latents.values()], k=k)[0] for m in range(members)]))
            for k in MIXING_K
        }
        expected = float(np.mean([sensor_mixing([z[m] for z in latents.values()])[1] for m in range(members)]))
        channels = per_channel(evaluator, run.engine, "seen")
    metrics = json.loads((run_dir / "metrics.json").read_text(encoding="utf-8"))
    alignment = metrics["alignment"]["per_subset"]["all"]
    distances = {}
    for when in ("first_epoch", "final"):
        matched = np.asarray(alignment["latent_l1"][when])
        ratio = np.asarray(alignment["latent_ratio"][when])
        distances[when] = {"matched_l1": float(matched.mean()), "unmatched_l1": float((matched / ratio).mean())}
    return {
        "run": run_dir.name,
        "members": int(members),
        "metrics": {"nmae_normaliser": run.config.nmae_normaliser, "ssim_range": run.config.ssim_range},
        "seen_per_channel": channels,
        "mixing_by_k": mixing,
        "mixing_expected": expected,
        "latent_distances": distances,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("runs", type=Path, nargs="+")
    parser.add_argument("--out", type=Path, default=ROOT / "docs" / "figures" / "claims_diagnosis.json")
    args = parser.parse_args()
    results = [diagnose(run) for run in args.runs]
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(results, indent=2) + "\n", encoding="utf-8")
    for r in results:
        print(f"{r['run']} ({r['members']} members, {r['metrics']}):")
        for column, values in r["seen_per_channel"].items():
            cells = " ".join(f"{c} {values['nmae_' + c]:.3f}/{values['ssim_' + c]:.3f}" for c in CHANNELS)
            print(f"  {column:28s} NMAE/SSIM per channel: {cells}")
        print(f"  mixing by k: {r['mixing_by_k']} (perfect {r['mixing_expected']:.3f})")
        print(f"  latent L1 (matched, unmatched): {r['latent_distances']}")
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
