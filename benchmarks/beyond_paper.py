"""Beyond the paper: options the paper lacks, each charted as accuracy against training cost.

(a) Cross-sensor contact geometry (paper: 0.637 / 0.666 mm, against 0.353 / 0.397 mm same-sensor). Options:
    * ``pooled head``: one geometry MLP trained on both sensors' latents (no change to the autoencoder);
    * ``align <w>``: UniTac-NV trained with a scale-free alignment term in its loss (``[model] align_weight``:
      mean matched latent L1 over the L1 to a shifted partner in the batch), paper heads and pooled head on top.
    Target: half the paper's cross-sensor error without hurting self-reconstruction.
(b) The smallest model that keeps the results: encoder/decoder widths and latent size swept, the paper's
    64-48 / 16 / 64-96 as one point. The choice ("keeps the results": every direction's validation SSIM within
    0.005 of the paper-size model's and its NMAE within 10%) is made on validation contacts only; test Table I rows
    and geometry are reported for the chosen and every other size.

Every variant is one run of UniTac-NV alone (no baselines) for ``--seeds`` seeds on split ``--split`` with the same
epochs, so costs compare; cost = process CPU seconds of the training call (one thread; evaluation every
``--eval-every`` epochs included), which a shared machine disturbs less than wall time. Writes
``docs/figures/beyond_paper.json``, ``beyond_geometry.png`` and ``beyond_size.png``; ``run_results.py`` puts the
section into docs/results.md. Finished runs under ``--out`` are reused, so variants can be run in several processes
(``--only NAME``) and the page drawn once all are done (``--render-only``).

    python benchmarks/beyond_paper.py --data DATA [--out runs/beyond] [--epochs 300] [--seeds 3] [--only NAME]
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path
from typing import Any

import numpy as np

from lab.geometry_heads import pooled_geometry
from unitac_rig.bench import write_json
from unitac_rig.learning.contact_geometry import run_geometry
from unitac_rig.learning.data import build_paired_dataset, load_sets
from unitac_rig.learning.engine import UNITAC_GROUP
from unitac_rig.learning.evaluate import evaluate_run
from unitac_rig.learning.paper import PAPER_GEOMETRY_MAE_MM
from unitac_rig.learning.run import checkpoint_path
from unitac_rig.learning.train import TrainConfig, load_run, load_test_set, train
from unitac_rig.plotting import new_figure, save_figure

ROOT = Path(__file__).resolve().parent.parent
RESULT = "beyond_result.json"
DIRECTIONS = ("uskin_to_uskin", "uskin_to_papillarray", "papillarray_to_papillarray", "papillarray_to_uskin")
CROSS = ("uskin_to_papillarray", "papillarray_to_uskin")
SELF = ("uskin_to_uskin", "papillarray_to_papillarray")
PAPER_CROSS_MM = float(np.mean([PAPER_GEOMETRY_MAE_MM[c] for c in CROSS]))
SSIM_KEPT, NMAE_KEPT = 0.005, 0.10  # "keeps the results" against the paper-size model, on validation

# name -> (what, flat TrainConfig overrides)
VARIANTS: dict[str, tuple[str, dict[str, Any]]] = {
    "paper": ("the paper's model (64-48 / 16 / 64-96)", {}),
    "align 0.1": ("alignment term, weight 0.1", {"shape.align_weight": 0.1}),
    "align 1": ("alignment term, weight 1", {"shape.align_weight": 1.0}),
    "latent 8": ("64-48 / 8 / 64-96", {"shape.latent_dim": 8}),
    "latent 4": ("64-48 / 4 / 64-96", {"shape.latent_dim": 4}),
    "latent 2": ("64-48 / 2 / 64-96", {"shape.latent_dim": 2}),
    "half widths": ("32-24 / 16 / 32-48", {"shape.encoder_hidden": (32, 24), "shape.decoder_hidden": (32, 48)}),
    "quarter widths": ("16-12 / 16 / 16-24", {"shape.encoder_hidden": (16, 12), "shape.decoder_hidden": (16, 24)}),
    "quarter widths, latent 4": (
        "16-12 / 4 / 16-24",
        {"shape.encoder_hidden": (16, 12), "shape.decoder_hidden": (16, 24), "shape.latent_dim": 4},
    ),
}
GEOMETRY_VARIANTS = ("paper", "align 0.1", "align 1")
SIZE_VARIANTS = (
    "paper",
    "latent 8",
    "latent 4",
    "latent 2",
    "half widths",
    "quarter widths",
    "quarter widths, latent 4",
)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--data", type=Path)
    parser.add_argument("--out", type=Path, default=ROOT / "runs" / "beyond")
    parser.add_argument("--epochs", type=int, default=300)
    parser.add_argument("--seeds", type=int, default=3)
    parser.add_argument("--split", type=int, default=0)
    parser.add_argument("--eval-every", type=int, default=25)
    parser.add_argument("--only", action="append", default=None, help="run only these variants (repeatable)")
    parser.add_argument("--render-only", action="store_true")
    parser.add_argument("--docs", type=Path, default=ROOT / "docs")
    args = parser.parse_args()

    if not args.render_only:
        dataset = build_paired_dataset(load_sets(args.data))
        base = TrainConfig(
            epochs=args.epochs,
            seeds=tuple(range(args.seeds)),
            split_seed=args.split,
            baselines=False,
            eval_every=args.eval_every,
            checkpoint_every=10**6,
        )
        for name in args.only or list(VARIANTS):
            run_variant(dataset, args.out / name.replace(" ", "_").replace(",", ""), name, base)
    results = {}
    for name in VARIANTS:
        path = args.out / name.replace(" ", "_").replace(",", "") / RESULT
        if path.exists():
            results[name] = json.loads(path.read_text(encoding="utf-8"))
    if not results:
        print("no finished variant to draw")
        return
    doc = summarise(results, args)
    figures = args.docs / "figures"
    write_json(doc, figures / "beyond_paper.json")
    plot_geometry_options(doc, figures / "beyond_geometry.png")
    plot_sizes(doc, figures / "beyond_size.png")
    print(f"wrote {figures / 'beyond_paper.json'} and its figures")


def run_variant(dataset: Any, run_dir: Path, name: str, base: TrainConfig) -> None:
    """Train one variant (unless already done), then score it: validation and test reconstruction, geometry with
    the paper's heads and with the pooled head, costs."""
    if (run_dir / RESULT).exists():
        print(f"{name}: done before, reused", flush=True)
        return
    config = base.updated(VARIANTS[name][1])
    cpu_began, wall_began = time.process_time(), time.perf_counter()
    if checkpoint_path(run_dir).exists():
        train(dataset, run_dir, None, resume=True, epochs=config.epochs, device="cpu")
    else:
        train(dataset, run_dir, config, device="cpu")
    train_cpu, train_wall = time.process_time() - cpu_began, time.perf_counter() - wall_began
    run, test = load_run(run_dir), load_test_set(run_dir)
    metrics = evaluate_run(run, test)
    last_val = next(h["val"] for h in reversed(run.history) if "val" in h)
    heads, pooled = [], []
    for member in range(run.engine.members):
        began = time.process_time()
        result = run_geometry(run, test, member=member)
        heads.append({"scenarios": result.scenarios, "cpu_seconds": time.process_time() - began})
        began = time.process_time()
        pooled_result = pooled_geometry(run, test, member=member)
        pooled.append({**pooled_result, "cpu_seconds": time.process_time() - began})
    record = {
        "name": name,
        "what": VARIANTS[name][0],
        "config": config.to_dict(),
        "parameters": run.engine.parameter_count(UNITAC_GROUP),
        "train_cpu_seconds": train_cpu,
        "train_wall_seconds": train_wall,
        "validation_seen": {c: last_val["seen"][c] for c in DIRECTIONS},
        "validation_alignment": {k: last_val["seen"][k] for k in ("latent_l1", "latent_ratio", "mixing")},
        "test_table": {row: {c: metrics["table1_members"][row][c] for c in DIRECTIONS} for row in metrics["table1"]}
        if "table1_members" in metrics
        else {},
        "test_alignment": metrics["alignment"]["per_subset"],
        "geometry_paper_heads": heads,
        "geometry_pooled_head": pooled,
    }
    write_json(record, run_dir / RESULT)
    print(f"{name}: {train_cpu / 60:.1f} CPU min training", flush=True)


def _geometry(record: dict[str, Any], head: str, scenario: str) -> np.ndarray:
    return np.asarray([h["scenarios"][scenario]["mae_mm"] for h in record[head] if scenario in h["scenarios"]])


def summarise(results: dict[str, dict[str, Any]], args: argparse.Namespace) -> dict[str, Any]:
    """Per variant: cost, validation and test reconstruction, geometry; the size choice made on validation."""
    variants = {}
    for name, r in results.items():
        val = r["validation_seen"]
        entry: dict[str, Any] = {
            "what": r["what"],
            "parameters": r["parameters"],
            "train_cpu_seconds": r["train_cpu_seconds"],
            "geometry_head_cpu_seconds": {
                "paper_heads": float(np.mean([h["cpu_seconds"] for h in r["geometry_paper_heads"]])),
                "pooled_head": float(np.mean([h["cpu_seconds"] for h in r["geometry_pooled_head"]])),
            },
            "validation": {c: {m: float(np.mean(val[c][m])) for m in ("nmae", "ssim")} for c in DIRECTIONS},
            "validation_latent_ratio": float(np.mean(r["validation_alignment"]["latent_ratio"])),
            "test_all_seen": {
                c: {m: float(np.mean(r["test_table"]["all_seen"][c][m])) for m in ("nmae", "ssim")} for c in DIRECTIONS
            },
            "geometry_mm": {},
        }
        for scenario in PAPER_GEOMETRY_MAE_MM:
            values = _geometry(r, "geometry_paper_heads", scenario)
            entry["geometry_mm"][scenario] = {"mean": float(values.mean()), "std": float(values.std())}
        for sensor in ("uskin", "papillarray"):
            values = _geometry(r, "geometry_pooled_head", f"pooled_to_{sensor}")
            entry["geometry_mm"][f"pooled_to_{sensor}"] = {"mean": float(values.mean()), "std": float(values.std())}
        variants[name] = entry
    chosen = None
    if "paper" in variants:
        reference = variants["paper"]["validation"]
        kept = [
            name
            for name in SIZE_VARIANTS
            if name in variants
            and all(
                variants[name]["validation"][c]["ssim"] >= reference[c]["ssim"] - SSIM_KEPT
                and variants[name]["validation"][c]["nmae"] <= reference[c]["nmae"] * (1 + NMAE_KEPT)
                for c in DIRECTIONS
            )
        ]
        chosen = min(kept, key=lambda n: variants[n]["parameters"]) if kept else None
    return {
        "epochs": args.epochs,
        "metrics": {k: next(iter(results.values()))["config"].get(k) for k in ("nmae_normaliser", "ssim_range")},
        "seeds": args.seeds,
        "split": args.split,
        "variants": variants,
        "size_choice": {
            "rule": f"every direction's validation SSIM within {SSIM_KEPT} of the paper-size model's and its "
            f"NMAE within {NMAE_KEPT:.0%}; the fewest parameters among those",
            "chosen": chosen,
        },
        "paper_cross_mm": PAPER_CROSS_MM,
        "target_cross_mm": PAPER_CROSS_MM / 2,
    }


def size_margin_text(doc: dict[str, Any]) -> str:
    """How close the size rule's decision was: for each smaller model, the direction that came nearest to failing
    (or failed) and by how much, from ``--seeds`` seeds on one split; a margin within the seed-to-seed spread is not
    a decision, and the text says so."""
    variants = doc["variants"]
    reference = variants.get("paper", {}).get("validation")
    if reference is None:
        return ""
    parts = []
    for name in SIZE_VARIANTS:
        entry = variants.get(name)
        if name == "paper" or entry is None or entry["parameters"] >= variants["paper"]["parameters"]:
            continue
        # slack > 0: passed by that much of the allowance; < 0: missed by it
        slack = {
            c: min(
                (entry["validation"][c]["ssim"] - (reference[c]["ssim"] - SSIM_KEPT)) / SSIM_KEPT,
                (reference[c]["nmae"] * (1 + NMAE_KEPT) - entry["validation"][c]["nmae"])
                / (reference[c]["nmae"] * NMAE_KEPT),
            )
            for c in DIRECTIONS
        }
        worst = min(slack, key=lambda c: slack[c])
        parts.append(
            f"{name} {'missed' if slack[worst] < 0 else 'passed'} by {abs(slack[worst]):.0%} of the "
            f"allowance on {worst.replace('_to_', ' → ')}"
        )
    return (
        f"Margins ({doc['seeds']} seeds, split {doc['split']}, one validation set, so a margin under about half the "
        "allowance is within what the seeds and the split move and decides nothing): " + "; ".join(parts) + "."
    )


def _cross(entry: dict[str, Any], pooled: bool) -> float:
    if pooled:
        return float(np.mean([entry["geometry_mm"][f"pooled_to_{s}"]["mean"] for s in ("uskin", "papillarray")]))
    return float(np.mean([entry["geometry_mm"][c]["mean"] for c in CROSS]))


def _self(entry: dict[str, Any]) -> float:
    return float(np.mean([entry["geometry_mm"][c]["mean"] for c in SELF]))


def geometry_options(doc: dict[str, Any]) -> list[dict[str, Any]]:
    """One row per (autoencoder variant, geometry head): cost, cross- and same-sensor error, self-reconstruction."""
    rows = []
    for name in GEOMETRY_VARIANTS:
        entry = doc["variants"].get(name)
        if entry is None:
            continue
        self_ssim = float(np.mean([entry["validation"][c]["ssim"] for c in SELF]))
        for pooled in (False, True):
            head = "pooled_head" if pooled else "paper_heads"
            rows.append(
                {
                    "option": f"{name}, {'pooled head (same-sensor)' if pooled else 'paper heads'}",
                    "cpu_seconds": entry["train_cpu_seconds"] + entry["geometry_head_cpu_seconds"][head],
                    # the pooled head trains on the test sensor's latents of the unseen object: a same-sensor error
                    "cross_mm": None if pooled else _cross(entry, False),
                    "same_mm": _cross(entry, True) if pooled else _self(entry),
                    "self_ssim_validation": self_ssim,
                    "self_nmae_validation": float(np.mean([entry["validation"][c]["nmae"] for c in SELF])),
                }
            )
    return rows


def plot_geometry_options(doc: dict[str, Any], path: Path) -> Path:
    """Cross-sensor geometry error and self-reconstruction against training cost for each option."""
    rows = geometry_options(doc)
    fig = new_figure(12, 4.4, layout="tight")
    ax, ax2 = fig.subplots(1, 2)
    for row in rows:
        marker = "s" if "pooled" in row["option"] else "o"
        if row["cross_mm"] is not None:  # the pooled head has no cross-sensor error (it saw the test sensor)
            ax.scatter(row["cpu_seconds"] / 60, row["cross_mm"], marker=marker, s=40)
            ax.annotate(
                row["option"],
                (row["cpu_seconds"] / 60, row["cross_mm"]),
                fontsize=7,
                xytext=(4, 3),
                textcoords="offset points",
            )
        ax2.scatter(row["cpu_seconds"] / 60, row["self_ssim_validation"], marker=marker, s=40)
        # a pooled head shares its autoencoder's SSIM, so its label goes below the paper heads' one
        ax2.annotate(
            row["option"],
            (row["cpu_seconds"] / 60, row["self_ssim_validation"]),
            fontsize=7,
            xytext=(4, -9 if marker == "s" else 3),
            textcoords="offset points",
        )
    ax.axhline(doc["paper_cross_mm"], color="tab:red", ls="--", lw=1, label="paper, cross-sensor (mean)")
    ax.axhline(doc["target_cross_mm"], color="tab:green", ls="--", lw=1, label="half the paper's")
    ax.set_xlabel("training cost (CPU minutes: autoencoder + geometry head)")
    ax.set_ylabel("cross-sensor geometry error (mm, test)")
    ax.set_title(f"(a) cross-sensor geometry, {doc['epochs']} epochs, {doc['seeds']} seeds", fontsize=10)
    ax.legend(fontsize=7)
    ax.grid(alpha=0.3)
    ax2.set_xlabel("training cost (CPU minutes)")
    ax2.set_ylabel("self-reconstruction SSIM (validation, seen)")
    ax2.set_title("(a) self-reconstruction kept?", fontsize=10)
    ax2.grid(alpha=0.3)
    return save_figure(fig, path)


def plot_sizes(doc: dict[str, Any], path: Path) -> Path:
    """Validation reconstruction, cost and test geometry against the number of parameters."""
    names = [n for n in SIZE_VARIANTS if n in doc["variants"]]
    entries = [doc["variants"][n] for n in names]
    params = [e["parameters"] for e in entries]
    fig = new_figure(15, 4.4, layout="tight")
    axes = fig.subplots(1, 3)
    for c in DIRECTIONS:
        axes[0].plot(params, [e["validation"][c]["ssim"] for e in entries], "o", label=c.replace("_to_", " → "))
    axes[0].set_ylabel("validation SSIM (seen)")
    axes[1].plot(params, [e["train_cpu_seconds"] / 60 for e in entries], "o", color="black")
    axes[1].set_ylabel("training cost (CPU minutes)")
    for scenario in PAPER_GEOMETRY_MAE_MM:
        axes[2].plot(
            params, [e["geometry_mm"][scenario]["mean"] for e in entries], "o", label=scenario.replace("_to_", " → ")
        )
    axes[2].set_ylabel("geometry error (mm, test)")
    for ax in axes:
        ax.set_xscale("log")
        ax.set_xlabel("UniTac-NV parameters (one seed)")
        ax.grid(alpha=0.3)
        for name, p, e in zip(names, params, entries, strict=True):
            if ax is axes[1]:
                ax.annotate(
                    name, (p, e["train_cpu_seconds"] / 60), fontsize=7, xytext=(3, 3), textcoords="offset points"
                )
    axes[0].legend(fontsize=7)
    axes[2].legend(fontsize=7)
    chosen = doc["size_choice"]["chosen"]
    fig.suptitle(f"(b) model size, {doc['epochs']} epochs, {doc['seeds']} seeds; chosen on validation: {chosen}")
    return save_figure(fig, path)


def render_section(doc: dict[str, Any]) -> list[str]:
    """The results page's beyond-the-paper section (called by run_results.py)."""
    lines = [
        "## Beyond the paper",
        "",
        f"Every variant: UniTac-NV alone, {doc['seeds']} seeds, split {doc['split']}, {doc['epochs']} epochs (fewer "
        "than the paper's 1000 so that all variants fit the shared 2-core box; the paper-size model at the same "
        "budget is the reference). Costs are process CPU seconds of training (one thread). Made by "
        "`python benchmarks/beyond_paper.py`. Reconstruction scores under the variants' own metric reading "
        f"(NMAE `{doc.get('metrics', {}).get('nmae_normaliser')}`, SSIM `{doc.get('metrics', {}).get('ssim_range')}`).",
        "",
        "### (a) Cross-sensor contact geometry",
        "",
        f"Target: half the paper's cross-sensor error ({doc['paper_cross_mm']:.3f} mm → {doc['target_cross_mm']:.3f} "
        "mm) without hurting self-reconstruction.",
        "",
        "| option | cost (CPU min) | cross-sensor (mm) | same-sensor (mm) | self SSIM (val) | self NMAE (val) |",
        "|---|---:|---:|---:|---:|---:|",
    ]
    for row in geometry_options(doc):
        same = "–" if row["same_mm"] is None else f"{row['same_mm']:.3f}"
        cross = "–" if row["cross_mm"] is None else f"{row['cross_mm']:.3f}"
        lines.append(
            f"| {row['option']} | {row['cpu_seconds'] / 60:.1f} | {cross} | {same} | "
            f"{row['self_ssim_validation']:.3f} | {row['self_nmae_validation']:.4f} |"
        )
    lines += [
        "",
        "![beyond geometry](figures/beyond_geometry.png)",
        "",
        "### (b) The smallest model that keeps the results",
        "",
        f"Rule (validation only): {doc['size_choice']['rule']}. Chosen: **{doc['size_choice']['chosen']}**. "
        f"{size_margin_text(doc)}",
        "",
        "| model | parameters | cost (CPU min) | val SSIM u→u / u→p / p→p / p→u | test all-seen SSIM (same order) "
        "| geometry u→u / p→p / u→p / p→u (mm) |",
        "|---|---:|---:|---|---|---|",
    ]
    for name in SIZE_VARIANTS:
        e = doc["variants"].get(name)
        if e is None:
            continue
        val = " / ".join(f"{e['validation'][c]['ssim']:.3f}" for c in DIRECTIONS)
        test = " / ".join(f"{e['test_all_seen'][c]['ssim']:.3f}" for c in DIRECTIONS)
        geometry = " / ".join(f"{e['geometry_mm'][s]['mean']:.3f}" for s in PAPER_GEOMETRY_MAE_MM)
        lines.append(
            f"| {name} ({e['what']}) | {e['parameters']} | {e['train_cpu_seconds'] / 60:.1f} | {val} | {test} | "
            f"{geometry} |"
        )
    lines += ["", "![beyond size](figures/beyond_size.png)"]
    return lines


if __name__ == "__main__":
    main()
