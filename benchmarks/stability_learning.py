"""Where the learned representation fails, for a trained run (the learning half of "stability where methods fail").

1. Per outline feature of the unseen irregular prism (each of its six corners, 80..160 deg interior angle, and
   "face" when the contact origin is more than --face-mm from every corner): reconstruction NMAE / SSIM of every
   UniTac-NV direction (self and cross) and baseline, latent distance, and contact-geometry profile error (mm, from
   a --folds-fold cross-validation over approach directions, so every contact is predicted once by a model that
   did not see its direction). The paper says geometry estimation is ambiguous at the 80 deg corner.
2. PLA against TPU: per shape printed in both materials and pooled over shapes, with TPU - PLA.
3. Spread over seeds: mean +- std, min and max of every Table I cell over the run's seeds (train with --n-seeds).

    python benchmarks/stability_learning.py --run RUN [--out docs/figures] [--folds 10] [--face-mm 3]

Writes OUT/stability_learning.json and OUT/stability_learning_{corners,materials,seeds}.png and prints a summary.
Cost: the geometry folds dominate (each trains the paper's MLP for every seed and training sensor at once, 80
epochs); --folds 0 skips them.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path
from typing import Any

from lab.stability import (
    DEFAULT_GEOMETRY_FOLDS,
    FACE_DISTANCE_MM,
    STABILITY_JSON,
    stability_report,
)
from unitac_rig.learning.contact_geometry import GeometryConfig

ROOT = Path(__file__).resolve().parent.parent


def _fmt(cell: dict[str, Any] | None) -> str:
    if cell is None or cell.get("mean") is None:
        return "-"
    return f"{cell['mean']:.3f}±{cell['std']:.3f}"


def print_summary(report: dict[str, Any]) -> None:
    columns = report["columns"]
    print(f"\nobject {report['object']}, seeds {report['seeds']}, {report['epochs']} epochs")
    print("\nreconstruction NMAE by feature (mean±std over seeds):")
    print(f"{'feature':<18}{'contacts':>9}  " + "  ".join(f"{c:>24}" for c in columns))
    contacts = {f["name"]: f["test_contacts"] for f in report["features"]}
    for name, entry in report["reconstruction"].items():
        if entry is None:
            continue
        cells = "  ".join(f"{_fmt(entry[c]['nmae']):>24}" for c in columns)
        print(f"{name:<18}{contacts.get(name, sum(contacts.values())):>9}  {cells}")
    geometry = report["geometry"]
    if geometry is not None:
        print(f"\ncontact-geometry profile MAE (mm) by feature, {geometry['folds']}-fold:")
        scenarios = geometry["scenarios"]
        print(f"{'feature':<18}{'|depth|':>7}{'no-latent':>10}  " + "  ".join(f"{s:>26}" for s in scenarios))
        rows = {**geometry["per_feature"], "whole object": geometry["whole_object"]}
        for name, entry in rows.items():
            if entry is None:
                continue
            cells = "  ".join(f"{_fmt(entry[s]):>26}" for s in scenarios)
            print(f"{name:<18}{entry['mean_abs_depth_mm']:>7.2f}{entry['mean_profile_mae_mm']:>10.3f}  {cells}")
    pooled = report["materials"]["pooled"]
    if pooled is not None:
        print("\nPLA vs TPU (pooled seen objects' held-out angles), NMAE:")
        for c in columns:
            cell = pooled[c]["nmae"]
            paper = cell["paper"]
            paper_text = "" if paper is None else f"   paper {paper['PLA']:.3f} vs {paper['TPU']:.3f}"
            print(
                f"  {c:<28} PLA {_fmt(cell['PLA'])}  TPU {_fmt(cell['TPU'])}  diff {_fmt(cell['tpu_minus_pla'])}"
                f"{paper_text}"
            )
    widest = max(
        (
            ((cell["nmae"]["max"] - cell["nmae"]["min"]) / cell["nmae"]["mean"], row, column)
            for row, cells in report["seed_spread"].items()
            for column, cell in cells.items()
            if cell["nmae"]["mean"]
        ),
        default=None,
    )
    if widest is not None:
        share, row, column = widest
        print(f"\nwidest seed spread of a Table I NMAE cell: {100 * share:.1f}% of its mean ({row}, {column})")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--run", type=Path, required=True, help="a `unitac-rig train` output folder")
    parser.add_argument("--out", type=Path, default=ROOT / "docs" / "figures")
    parser.add_argument("--object", default=None, help="object to break down (default: the run's unseen object)")
    parser.add_argument("--folds", type=int, default=DEFAULT_GEOMETRY_FOLDS, help="geometry folds (0: skip)")
    parser.add_argument("--face-mm", type=float, default=FACE_DISTANCE_MM, help="corner radius of a feature (mm)")
    parser.add_argument("--geometry-epochs", type=int, default=GeometryConfig().epochs)
    parser.add_argument("--nmae-normaliser", default=None, help="NMAE normaliser (default: the run's)")
    parser.add_argument("--ssim-range", default=None, help="SSIM range (default: the run's)")
    args = parser.parse_args()

    began = time.perf_counter()
    report = stability_report(
        args.run,
        object_id=args.object,
        face_distance_mm=args.face_mm,
        geometry_folds=args.folds,
        geometry_config=GeometryConfig(epochs=args.geometry_epochs),
        figures_dir=args.out,
        nmae_normaliser=args.nmae_normaliser,
        ssim_range=args.ssim_range,
    )
    report["wall_seconds"] = time.perf_counter() - began
    args.out.mkdir(parents=True, exist_ok=True)
    json_path = args.out / STABILITY_JSON
    json_path.write_text(json.dumps(report, indent=2) + "\n", encoding="utf-8")
    print_summary(report)
    print(f"\n{report['wall_seconds']:.0f} s; wrote {json_path} and {', '.join(report['figures'].values())}")


if __name__ == "__main__":
    main()
