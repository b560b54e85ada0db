"""docs/results.md's generated block (between ``<!-- generated:start -->`` and ``<!-- generated:end -->``; the
hand-written rest is kept), rendered from the per-split JSON that ``results_full.py`` writes (``docs/results/``)
alone: no data, no checkpoints. Figures drawn from the JSON (curves, alignment, the cross-sensor chart) are redrawn;
the per-run figures (t-SNE, reconstructions, geometry outline) are copied from ``--runs`` when the runs are there.

    python benchmarks/run_results.py [--json docs/results] [--docs docs] [--runs RUNS]
"""

from __future__ import annotations

import argparse
import json
import shutil
from pathlib import Path
from typing import Any

import numpy as np

from unitac_rig.bench import markdown_table, replace_doc_section
from unitac_rig.learning.contact_geometry import GeometryConfig
from unitac_rig.learning.evaluate import FRAME_BASELINE_TEXT, PREPROCESSING_TEXT, metric_description
from unitac_rig.learning.metrics import NMAE_NORMALISERS, SSIM_RANGES
from unitac_rig.learning.paper import PAPER_GEOMETRY_MAE_MM, PAPER_TABLE1
from unitac_rig.learning.report import table_columns
from unitac_rig.plotting import new_figure, save_figure
from unitac_rig.rig.objects import list_objects

ROOT = Path(__file__).resolve().parent.parent
SEEN_DIRECTIONS = ("uskin_to_uskin", "uskin_to_papillarray", "papillarray_to_papillarray", "papillarray_to_uskin")
CROSS = ("uskin_to_papillarray", "papillarray_to_uskin")
MIXED_ENOUGH = 0.5  # "interleaved": the other-sensor share of 10 NN is at least half its perfect-mixing value
PROTOCOL_TITLE = {
    "random": "the paper's random split (1-degree neighbours of every test angle train)",
    "blocked": "blocked split (one contiguous block of approach rays per object, guard band around it)",
}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--json", type=Path, default=ROOT / "docs" / "results", help="the per-split JSON folder")
    parser.add_argument("--docs", type=Path, default=ROOT / "docs")
    parser.add_argument("--runs", type=Path, default=None, help="results_full's runs folder (per-run figures)")
    args = parser.parse_args()
    if write_page(args.json, args.docs / "results.md", args.runs):
        print(f"wrote {args.docs / 'results.md'}")
    else:
        print(f"no split JSON under {args.json}: results.md not written")


def write_page(folder: Path, page: Path, runs: Path | None) -> bool:
    """Render ``page``'s generated block from the JSON under ``folder``, its figures into ``page``'s figures/ folder
    (split 0's run figures copied from ``runs`` when there); a new page starts from the repository's, so its
    hand-written part is kept. False when there is no split JSON."""
    results = load_results(folder)
    if not results:
        return False
    if not page.exists() and (ROOT / "docs" / "results.md").exists():
        page.parent.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(ROOT / "docs" / "results.md", page)
    figures = draw_figures(results, page.parent / "figures", runs)
    replace_doc_section(page, "generated", render(results, figures, load_collection(folder)), ("start", "end"))
    return True


def load_results(folder: Path) -> dict[str, list[dict[str, Any]]]:
    """protocol -> its splits (split seed order), each as the renderer reads it, from ``<protocol>/split-*.json``."""
    out: dict[str, list[dict[str, Any]]] = {}
    for protocol in ("random", "blocked"):
        files = sorted((folder / protocol).glob("split-*.json"), key=lambda p: int(p.stem.split("-")[1]))
        splits = []
        for path in files:
            doc = json.loads(path.read_text(encoding="utf-8"))
            members = doc["geometry"]["members"]
            splits.append(
                {
                    "protocol": protocol,
                    "path": path,
                    "metrics": doc["metrics"],
                    "readings": doc["readings"],
                    "history": doc["history"],
                    "config": doc["config"],
                    "summary": doc["summary"],
                    "split": doc.get("split", {}),
                    "geometry": {
                        "paper_heads": [m["paper_heads"] for m in members],
                        "pooled_head": [m["pooled_head"] for m in members if "pooled_head" in m],
                        "cross": [m["cross_sensor"] for m in members],
                        "members": members,
                        "seconds": {"train_wall": doc["seconds"]["train"], "geometry": doc["seconds"]["geometry_cpu"]},
                    },
                }
            )
        if splits:
            out[protocol] = splits
    return out


def load_collection(folder: Path) -> dict[str, Any] | None:
    """``collection.json`` beside the protocols' folders (results_full writes it), or None."""
    path = folder / "collection.json"
    return json.loads(path.read_text(encoding="utf-8")) if path.exists() else None


def collection_line(collection: dict[str, Any] | None) -> list[str]:
    """The collection's statistics from its JSON; without one, a line saying there is none."""
    if not collection:
        return [
            "",
            "Collection statistics: no `docs/results/collection.json` was committed with these runs, so the page "
            "states none (results_full.py writes it from `unitac-rig inspect` since issue 38).",
        ]
    sessions = collection["sessions"]

    def span(values: list[float], digits: int) -> str:
        return f"{min(values):.{digits}f}-{max(values):.{digits}f}"

    matched = sum(s["targets_matched"] for s in sessions)
    missed = sum(s["targets_missed"] for s in sessions)
    errors = [s["match_error_n"] for s in sessions if s["match_error_n"]["median"] is not None]
    peaks = [s["peak_force_n"] for s in sessions if s["peak_force_n"]["median"] is not None]
    pairs = collection.get("pairs", {})
    text = (
        f"Collection (`docs/results/collection.json`): {len(sessions)} sessions, "
        f"{sum(s['presses_complete'] for s in sessions)} of {sum(s['presses_planned'] for s in sessions)} presses "
        f"complete, {matched} of {matched + missed} force targets matched"
    )
    if errors:
        text += (
            f"; force-matching error per session median {span([1000 * e['median'] for e in errors], 0)} mN, p95 "
            f"{span([1000 * e['p95'] for e in errors], 0)} mN"
        )
    if peaks:
        text += (
            f"; press peak force median {span([p['median'] for p in peaks], 1)} N, max "
            f"{span([p['max'] for p in peaks], 1)} N"
        )
    if pairs:
        text += "; joined pairs per object: " + ", ".join(f"{o} {n}" for o, n in pairs.items())
    return ["", text + "."]


# ---- aggregation ---------------------------------------------------------------------------------------------


def members(splits: list[dict[str, Any]], row: str, column: str, metric: str) -> np.ndarray:
    """Every (split, seed) member's value of one Table I cell."""
    values: list[float] = []
    for split in splits:
        m = split["metrics"]
        per_member = m.get("table1_members", {}).get(row, {}).get(column, {}).get(metric)
        values += per_member if per_member is not None else [m["table1"][row][column][metric]]
    return np.asarray(values, dtype=float)


def split_means(splits: list[dict[str, Any]], row: str, column: str, metric: str) -> np.ndarray:
    return np.asarray([s["metrics"]["table1"][row][column][metric] for s in splits], dtype=float)


def alignment_values(splits: list[dict[str, Any]], subset: str, key: str, when: str) -> np.ndarray:
    """Per member (all splits), one alignment measure on the test contacts after epoch 1 or at the end."""
    values: list[float] = []
    for split in splits:
        entry = split["metrics"]["alignment"]["per_subset"].get(subset, {}).get(key, {}).get(when)
        if entry is not None:
            values += list(entry)
    return np.asarray(values, dtype=float)


def geometry_values(splits: list[dict[str, Any]], scenario: str) -> np.ndarray:
    values = []
    for split in splits:
        for head in split["geometry"]["paper_heads"] + split["geometry"]["pooled_head"]:
            if scenario in head["scenarios"]:
                values.append(head["scenarios"][scenario]["mae_mm"])
    return np.asarray(values, dtype=float)


def _pm(values: np.ndarray, digits: int = 3) -> str:
    return f"{values.mean():.{digits}f} ± {values.std():.{digits}f}"


# ---- claims --------------------------------------------------------------------------------------------------


def claims(splits: list[dict[str, Any]]) -> list[tuple[str, bool, str]]:
    """(claim, reproduced?, the measurement) for each headline claim of the paper."""
    out = []
    seen_ssim = {d: members(splits, "all_seen", d, "ssim") for d in SEEN_DIRECTIONS}
    worst = min(seen_ssim, key=lambda d: seen_ssim[d].mean())
    ok = all(v.mean() > 0.95 for v in seen_ssim.values())
    every = all((v > 0.95).all() for v in seen_ssim.values())
    out.append(
        (
            "Seen objects: SSIM > 0.95 in all four directions",
            ok,
            "all-seen SSIM "
            + ", ".join(f"{_arrow(d)} {seen_ssim[d].mean():.3f} (min {seen_ssim[d].min():.3f})" for d in seen_ssim)
            + f"; lowest {_arrow(worst)}; "
            + ("every member above 0.95" if every else "not every member above 0.95"),
        )
    )
    seen_nmae = {d: members(splits, "all_seen", d, "nmae") for d in SEEN_DIRECTIONS}
    hardest_nmae = max(seen_nmae, key=lambda d: seen_nmae[d].mean())
    hardest_ssim = min(seen_ssim, key=lambda d: seen_ssim[d].mean())
    target = "papillarray_to_uskin"
    out.append(
        (
            "PapillArray → uSkin is the hardest direction on seen objects",
            hardest_nmae == target and hardest_ssim == target,
            f"highest all-seen NMAE: {_arrow(hardest_nmae)} ({seen_nmae[hardest_nmae].mean():.3f}); lowest SSIM: "
            f"{_arrow(hardest_ssim)} ({seen_ssim[hardest_ssim].mean():.3f}); PapillArray → uSkin "
            f"{seen_nmae[target].mean():.3f} / {seen_ssim[target].mean():.3f}",
        )
    )
    rows = list(splits[0]["metrics"]["table1"])
    unseen_rows = rows[rows.index("all_seen") + 1 :] if "all_seen" in rows else []  # the table's order
    if unseen_rows:
        row = unseen_rows[0]
        columns = list(splits[0]["metrics"]["table1"]["all_seen"])
        worse = [
            c
            for c in columns
            if members(splits, row, c, "nmae").mean() > members(splits, "all_seen", c, "nmae").mean()
            and members(splits, row, c, "ssim").mean() < members(splits, "all_seen", c, "ssim").mean()
        ]
        out.append(
            (
                "The unseen object reconstructs worse than the seen ones",
                len(worse) == len(columns),
                f"{row} worse than all-seen in NMAE and SSIM for {len(worse)} of {len(columns)} columns"
                + (
                    ""
                    if len(worse) == len(columns)
                    else f" (not: {', '.join(_arrow(c) for c in columns if c not in worse)})"
                ),
            )
        )
    first = alignment_values(splits, "all", "latent_l1", "first_epoch")
    final = alignment_values(splits, "all", "latent_l1", "final")
    ratio_first = alignment_values(splits, "all", "latent_ratio", "first_epoch")
    ratio_final = alignment_values(splits, "all", "latent_ratio", "final")
    falls = int((ratio_final < ratio_first).sum())
    out.append(
        (
            "Matched latents move closer from epoch 1 to the end (scale-free: matched / unmatched L1)",
            falls == len(ratio_first),
            f"test matched / unmatched latent L1 {ratio_first.mean():.3f} after epoch 1 → {ratio_final.mean():.3f} "
            f"at the end (1 = chance); falls in {falls} of {len(ratio_first)} members. The paper's raw L1 "
            f"({first.mean():.3f} → {final.mean():.3f}, falls in {int((final < first).sum())} of {len(first)}) "
            "also moves with the latents' scale, so it is not the claim",
        )
    )
    tsne_first = [s["metrics"].get("tsne_mixing", {}).get("first_epoch") for s in splits]
    tsne_last = [s["metrics"].get("tsne_mixing", {}).get("last_epoch") for s in splits]
    mix_first = alignment_values(splits, "all", "mixing", "first_epoch")
    mix_final = alignment_values(splits, "all", "mixing", "final")
    expected = alignment_values(splits, "all", "mixing_expected", "final")
    tsne_ok = all(t is not None for t in tsne_last) and all(
        t["mixing"] >= MIXED_ENOUGH * t["mixing_expected"] and t["mixing"] > f["mixing"]
        for t, f in zip(tsne_last, tsne_first, strict=True)
        if t is not None and f is not None
    )
    tsne_text = ", ".join(
        f"{f['mixing']:.2f} → {t['mixing']:.2f}"
        for t, f in zip(tsne_last, tsne_first, strict=True)
        if t is not None and f is not None
    )
    out.append(
        (
            "After training the t-SNE interleaves the sensors",
            tsne_ok,
            f"other-sensor share of each point's 10 nearest neighbours in the t-SNE (member 0 of each split, "
            f"after epoch 1 → at the end): {tsne_text} (perfect mixing ≈ {expected.mean():.2f}; criterion ≥ "
            f"{MIXED_ENOUGH:.0%} of perfect and rising). In the 16-d latents, all test contacts, all members: "
            f"{mix_first.mean():.3f} → {mix_final.mean():.3f}",
        )
    )
    found = []
    ok = True
    for scenario, paper in PAPER_GEOMETRY_MAE_MM.items():
        values = geometry_values(splits, scenario)
        if values.size:
            ok &= bool(values.mean() <= paper)
            found.append(f"{_arrow(scenario)} {values.mean():.3f} (paper {paper:.3f})")
    out.append(("Contact geometry at or below the paper's in all four scenarios", ok, "; ".join(found) + " mm"))
    return out


def _arrow(name: str) -> str:
    return name.replace("_to_", " → ")


# ---- figures -------------------------------------------------------------------------------------------------


def draw_figures(
    results: dict[str, list[dict[str, Any]]], target: Path, runs: Path | None
) -> dict[str, dict[str, str]]:
    """Per protocol: the alignment and validation curves and the cross-sensor chart, drawn from the JSON; split 0's
    run figures copied from ``runs`` when its run is there (else the committed copy under docs/figures is kept)."""
    target.mkdir(parents=True, exist_ok=True)
    out: dict[str, dict[str, str]] = {}
    for protocol, splits in results.items():
        prefix = "results_" if protocol == "random" else f"results_{protocol}_"
        figures = {"alignment": _rel(plot_alignment(splits, target / f"{prefix}alignment.png"))}
        figures["validation curves"] = _rel(plot_validation_nmae(splits, target / f"{prefix}curves.png"))
        figures["cross-sensor"] = _rel(plot_cross_sensor(splits, target / f"{prefix}cross_sensor.png"))
        first = None if runs is None else runs / protocol / f"split-{splits[0]['metrics']['split_seed']}" / "figures"
        for name in ("tsne", "reconstructions_seen", "reconstructions_unseen", "geometry"):
            destination = target / f"{prefix}{name}.png"
            if first is not None and (first / f"{name}.png").exists():
                shutil.copyfile(first / f"{name}.png", destination)
            if destination.exists():
                figures[name] = f"figures/{destination.name}"
        out[protocol] = figures
    return out


def _rel(path: Path) -> str:
    return f"figures/{path.name}"


def _curve(
    splits: list[dict[str, Any]], key: str, subset: str = "all", metric: str | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """(epochs, values (points, members over all splits)) of one validation measure: an alignment ``key`` on
    ``subset``'s contacts, or with ``metric`` a direction's NMAE or SSIM (``key`` the direction, ``subset`` "seen")."""
    per_split = []
    for split in splits:
        points = [h for h in split["history"] if key in h.get("val", {}).get(subset, {})]
        per_split.append(
            {h["epoch"]: h["val"][subset][key] if metric is None else h["val"][subset][key][metric] for h in points}
        )
    epochs = sorted(set.intersection(*(set(p) for p in per_split)))
    values = np.array([[v for p in per_split for v in p[e]] for e in epochs], dtype=float)
    return np.asarray(epochs), values


def plot_alignment(splits: list[dict[str, Any]], path: Path) -> Path:
    """Validation alignment per epoch, all seeds and splits: raw L1 (the paper's measure), the scale-free ratio and
    the sensor mixing; thin lines are members, the thick line their mean."""
    fig = new_figure(15, 4.2, layout="tight")
    axes = fig.subplots(1, 3)
    panels = (
        ("latent_l1", "matched-latent L1 (raw, the paper's)", "mean L1 distance"),
        ("latent_ratio", "matched / unmatched L1 (scale-free)", "ratio (1 = chance)"),
        ("mixing", "sensor mixing: other-sensor share of 10 NN", "share"),
    )
    for ax, (key, title, ylabel) in zip(axes, panels, strict=True):
        epochs, values = _curve(splits, key)
        if len(epochs):
            for m in range(values.shape[1]):
                ax.plot(epochs, values[:, m], color="0.5", alpha=0.35, lw=0.7)
            ax.plot(epochs, values.mean(axis=1), color="black", lw=1.8, label=f"mean of {values.shape[1]} members")
        if key == "mixing":
            e2, expected = _curve(splits, "mixing_expected")
            if len(e2):
                ax.plot(e2, expected.mean(axis=1), "--", color="tab:green", label="perfect mixing")
        if key == "latent_ratio":
            ax.axhline(1.0, ls="--", color="tab:red", lw=1.0, label="chance")
        ax.set_xscale("log")
        ax.set_xlabel("epoch")
        ax.set_ylabel(ylabel)
        ax.set_title(f"{title}\nvalidation contacts, all splits and seeds", fontsize=9)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7)
    return save_figure(fig, path)


def plot_validation_nmae(splits: list[dict[str, Any]], path: Path) -> Path:
    """Validation NMAE and SSIM per direction against epoch, mean over all seeds and splits."""
    fig = new_figure(11, 4.2, layout="tight")
    axes = fig.subplots(1, 2)
    columns = list(splits[0]["metrics"]["table1"]["all_seen"])
    for ax, metric in zip(axes, ("nmae", "ssim"), strict=True):
        for column in columns:
            epochs, values = _curve(splits, column, "seen", metric)
            if len(epochs):
                style = "--" if column.startswith("ae_") else "-"
                ax.plot(epochs, values.mean(axis=1), style, label=_arrow(column), lw=1.3)
        ax.set_xscale("log")
        if metric == "nmae":
            ax.set_yscale("log")
        ax.set_xlabel("epoch")
        ax.set_ylabel(f"validation {metric.upper()} (seen objects)")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7)
    return save_figure(fig, path)


# ---- the page ------------------------------------------------------------------------------------------------


def render(
    results: dict[str, list[dict[str, Any]]],
    figures: dict[str, dict[str, str]],
    collection: dict[str, Any] | None = None,
) -> str:
    """The generated block (without its markers): a header, then per protocol the claims, Table I, the readings,
    alignment, geometry and the figures."""
    splits0 = next(iter(results.values()))
    first, config = splits0[0]["metrics"], splits0[0]["config"]
    sensors = tuple(first["sensors"])
    prov = first.get("provenance", {})
    described = metric_description(config["nmae_normaliser"], config["ssim_range"])
    summary = splits0[0]["summary"]
    shape, seeds = config["shape"], len(config["seeds"])
    lines = [
        "# Results: UniTac-NV reproduced",
        "",
        f"Data: {'the simulated campaign' if first['simulated'] else 'recorded sessions'}, sensors "
        f"{', '.join(sensors)}, objects {', '.join(summary.get('objects', []))} ({summary.get('rows')} joined "
        f"contacts). Per protocol {len(splits0)} splits x {seeds} model seeds (split K trains seeds "
        f"K·{seeds} to K·{seeds}+{seeds - 1}), each run training UniTac-NV and "
        f"both per-sensor baselines together; {epochs_text(results)}, batch {config['batch_size']}, Adam lr "
        f"{config['learning_rate']}, dropout {shape['dropout']}, widths {list(shape['encoder_hidden'])} / "
        f"{shape['latent_dim']} / {list(shape['decoder_hidden'])}. unitac-rig {prov.get('package_version')}, commit "
        f"`{str(prov.get('git_commit', ''))[:12]}`.",
        "",
        f"Preprocessing: {PREPROCESSING_TEXT[config['preprocessing']]} (`{config['preprocessing']}`); frames "
        f"referenced to {FRAME_BASELINE_TEXT[config.get('frame_baseline', 'press')]} "
        f"(`{config.get('frame_baseline', 'press')}`). Default reading: "
        f"NMAE (`{described['nmae_normaliser']}`): {described['nmae']}. SSIM (`{described['ssim_range']}`): "
        f"{described['ssim']}. Why these: docs/learning.md (Preprocessing and metrics); every claim under every "
        "other reading is in its own table below.",
        "",
        "Every number on this page is computed from the per-split JSON files in `docs/results/` "
        "(`python benchmarks/run_results.py` redraws it from them alone). Made by "
        "`python benchmarks/results_full.py` (collection, both protocols, geometry; see docs/learning.md).",
        *collection_line(collection),
    ]
    for protocol, splits in results.items():
        lines += protocol_section(protocol, splits, figures.get(protocol, {}))
    return "\n".join(lines)


def epochs_text(results: dict[str, list[dict[str, Any]]]) -> str:
    """The epochs each run reached (early stopping) against the most it was allowed."""
    reached = [int(s["metrics"]["epochs"]) for splits in results.values() for s in splits]
    stop = next(iter(results.values()))[0]["metrics"].get("early_stopping", {})
    cap, patience = stop.get("max_epochs"), stop.get("patience", 0)
    if not patience:
        if len(set(reached)) == 1:
            return f"{reached[0]} epochs (every run; no early stopping)"
        return f"{', '.join(str(e) for e in reached)} epochs (no early stopping)"
    return (
        f"at most {cap} epochs, stopped after {patience} epochs without a better validation NMAE (mean over "
        f"UniTac-NV's directions): epochs reached per run {', '.join(str(e) for e in reached)}"
    )


def protocol_section(protocol: str, splits: list[dict[str, Any]], figures: dict[str, str]) -> list[str]:
    """One protocol's part of the page."""
    first, config = splits[0]["metrics"], splits[0]["config"]
    table = first["table1"]
    columns = table_columns(tuple(first["sensors"]), {c for row in table.values() for c in row})
    n_members = len(members(splits, "all_seen", columns[0], "nmae"))
    gap = max(float(s["split"].get("gap_deg", 0) or 0) for s in splits)
    recorded = sorted({str(s["split"].get("mode", "?")) for s in splits})
    not_held_out = sorted({o for s in splits for o in s["split"].get("not_held_out", [])})
    per_split = "; ".join(
        f"split {s['metrics']['split_seed']}: {s['summary'].get('train_rows')} / {s['summary'].get('val_rows')} / "
        f"{s['summary'].get('test_rows')}"
        for s in splits
    )
    train_minutes = sum(s["geometry"]["seconds"]["train_wall"] for s in splits) / 60
    geometry_minutes = sum(s["geometry"]["seconds"]["geometry"] for s in splits) / 60
    lines = [
        "",
        f"## {protocol.capitalize()} split: {PROTOCOL_TITLE.get(protocol, protocol)}",
        "",
        f"Training / validation / test contacts, {per_split}"
        + (f" (guard band {gap:g} deg: its contacts are validation rows, never trained on)" if gap else "")
        + f". Split mode recorded in the JSON: {', '.join(recorded)}"
        + (
            f"; not held out by angle (the same cross-section at every angle, so no seen-object test): "
            f"{', '.join(not_held_out)}"
            if not_held_out
            else ""
        )
        + f". Training {train_minutes:.0f} min (sum over splits), geometry {geometry_minutes:.0f} CPU min.",
        "",
        f"### Headline claims ({protocol} split, default reading)",
        "",
        *markdown_table(
            ["claim", "reproduced", "measurement"],
            ["---"] * 3,
            [[claim, "yes" if ok else "**no**", text] for claim, ok, text in claims(splits)],
        ),
    ]
    lines += readings_lines(splits)
    lines += [
        "",
        f"### Table I ({protocol} split): NMAE / SSIM on the test set, mean ± std over {n_members} members "
        f"({len(splits)} splits x {len(config['seeds'])} seeds), paper below",
        "",
    ]
    table_rows = []
    for row in table:
        cells = [row]
        for c in columns:
            n, s = members(splits, row, c, "nmae"), members(splits, row, c, "ssim")
            cells.append(f"{n.mean():.3f}±{n.std():.3f} / {s.mean():.3f}±{s.std():.3f}")
        table_rows.append(cells)
        if row in PAPER_TABLE1:
            paper = PAPER_TABLE1[row]
            table_rows.append(
                ["*paper*", *(f"{paper[c][0]:.3f} / {paper[c][1]:.3f}" if c in paper else "–" for c in columns)]
            )
    lines += markdown_table(["row", *(_arrow(c) for c in columns)], ["---"] * (len(columns) + 1), table_rows)
    lines += unseen_ratio_lines(protocol, splits, columns)
    lines += simple_baselines_lines(protocol, splits)
    lines += [
        "",
        "Spread of the all-seen row: standard deviation of the per-split means (split to split) against the mean "
        "standard deviation over seeds within a split (seed to seed):",
        "",
    ]
    spread = []
    for c in columns:
        cells = [_arrow(c)]
        for metric in ("nmae", "ssim"):
            within = [
                s["metrics"].get("table1_std", {}).get("all_seen", {}).get(c, {}).get(metric, 0.0) for s in splits
            ]
            cells += [f"{split_means(splits, 'all_seen', c, metric).std():.4f}", f"{np.mean(within):.4f}"]
        spread.append(cells)
    header = ["column", "NMAE split-to-split", "NMAE seed-to-seed", "SSIM split-to-split", "SSIM seed-to-seed"]
    lines += markdown_table(header, ["---"] + ["---:"] * 4, spread)
    lines += _variants_lines(splits, columns)
    lines += _consistency_lines(splits, columns)
    lines += [
        "",
        f"### Latent alignment ({protocol} split; test contacts, after epoch 1 → at the end, mean over all members)",
        "",
    ]
    alignment = []
    for subset in ("all", "seen", "unseen"):
        cells = [subset]
        for key in ("latent_l1", "latent_ratio", "mixing"):
            before = alignment_values(splits, subset, key, "first_epoch")
            after = alignment_values(splits, subset, key, "final")
            cells.append(f"{before.mean():.3f} → {after.mean():.3f}" if before.size and after.size else "–")
        expected = alignment_values(splits, subset, "mixing_expected", "final")
        alignment.append([*cells, f"{expected.mean() if expected.size else 0:.3f}"])
    header = ["contacts", "matched L1 (paper's; moves with the latents' scale)"]
    header += ["matched / unmatched L1 (scale-free: the claim)", "sensor mixing (10 NN)", "perfect mixing"]
    lines += markdown_table(header, ["---"] * 5, alignment)
    lines += geometry_lines(protocol, splits, n_members)
    lines += cross_sensor_lines(protocol, splits)
    lines += ["", f"### Figures ({protocol} split)", ""]
    captions = {
        "alignment": "Alignment over training (validation contacts): raw L1, scale-free ratio, sensor mixing",
        "validation curves": "Validation NMAE / SSIM per direction over training (seen objects)",
        "cross-sensor": "Strict cross-sensor geometry against training cost, with the ceiling and the no-latent "
        "baseline",
        "tsne": "t-SNE of the test latents after epoch 1 (top) and at the end (bottom), split 0, member 0",
        "reconstructions_seen": "Reconstructions, seen object (held-out angle)",
        "reconstructions_unseen": "Reconstructions, unseen object: best and worst",
        "geometry": "Contact geometry, split 0, member 0",
    }
    for name, rel in figures.items():
        lines += [f"{captions.get(name, name)}:", "", f"![{protocol} {name}]({rel})", ""]
    return lines


# ---- the simple baselines -----------------------------------------------------------------------------------


RATIO_FACTOR = 1.5  # issue 38's held-out check: each column's unseen/seen NMAE within this factor of the paper's


def unseen_ratio_lines(protocol: str, splits: list[dict[str, Any]], columns: list[str]) -> list[str]:
    """How much harder the unseen object is than the seen ones, per column, beside the paper's: the unseen row's
    mean NMAE over members divided by the all-seen row's (the paper's: its two rows' NMAE, on its random split)."""
    table = splits[0]["metrics"]["table1"]
    held_out = {o.id for o in list_objects() if not o.in_autoencoder_training}
    unseen = [o for o in table if o in PAPER_TABLE1 and o in held_out]
    if not unseen or "all_seen" not in table:
        return []
    row = unseen[0]
    cells, within = [], 0
    for c in columns:
        ours = members(splits, row, c, "nmae").mean() / members(splits, "all_seen", c, "nmae").mean()
        paper = PAPER_TABLE1[row][c][0] / PAPER_TABLE1["all_seen"][c][0]
        ok = 1 / RATIO_FACTOR <= ours / paper <= RATIO_FACTOR
        within += ok
        cells.append(f"{_arrow(c)} {ours:.2f} (paper {paper:.2f}){'' if ok else ' **out**'}")
    return [
        "",
        f"How much harder the unseen object is: {row} / all-seen NMAE (means over members) per column, "
        f"{within} of {len(columns)} within a factor {RATIO_FACTOR:g} of the paper's"
        + ("" if protocol == "random" else " (the paper's are on its random split, where seen test angles are easier)")
        + ": "
        + "; ".join(cells)
        + ".",
    ]


def simple_members(splits: list[dict[str, Any]], row: str, column: str, metric: str) -> np.ndarray:
    """A simple baseline's value per member, aligned with :func:`members`: each split's one value (the baselines
    are deterministic) repeated for each of its model seeds."""
    values: list[float] = []
    for split in splits:
        m = split["metrics"]
        seeds = len(m.get("table1_members", {}).get(row, {}).get(column_of_seeds(m), {}).get(metric, [0]))
        values += [m["simple_baselines"]["table1"][row][column][metric]] * seeds
    return np.asarray(values, dtype=float)


def column_of_seeds(metrics: dict[str, Any]) -> str:
    """Any UniTac-NV column of a split's table (all have one value per seed)."""
    return next(iter(next(iter(metrics["table1"].values()))))


def simple_baselines_lines(protocol: str, splits: list[dict[str, Any]]) -> list[str]:
    """The simple baselines' Table I (mean ± std over splits) and the paired comparison with UniTac-NV over members
    (split x seed, each paired with its split's baseline): where UniTac-NV is better, by how much, in how many."""
    if not all("simple_baselines" in s["metrics"] for s in splits):
        return []
    info = splits[0]["metrics"]["simple_baselines"]
    columns, rows = list(info["compared_with"]), list(info["table1"])
    lines = [
        "",
        f"### Simple baselines ({protocol} split): NMAE / SSIM on the same test contacts, mean ± std over "
        f"{len(splits)} splits",
        "",
        "Fitted on each run's own training contacts ("
        + ", ".join(f"{s['metrics']['simple_baselines']['train_rows']}" for s in splits)
        + " per split), "
        f"scored like UniTac-NV: PCA: {info['definition']['pca']} (k = {info['pca_components']}); ridge: "
        f"{info['definition']['ridge']}; nn: {info['definition']['nn']}.",
        "",
    ]
    table_rows = []
    for row in rows:
        cells = [row]
        for c in columns:
            n = np.asarray([s["metrics"]["simple_baselines"]["table1"][row][c]["nmae"] for s in splits])
            q = np.asarray([s["metrics"]["simple_baselines"]["table1"][row][c]["ssim"] for s in splits])
            cells.append(f"{n.mean():.3f}±{n.std():.3f} / {q.mean():.3f}±{q.std():.3f}")
        table_rows.append(cells)
    header = ["row", *(c.replace("_to_", " → ").replace("_", " ", 1) for c in columns)]
    lines += markdown_table(header, ["---"] * (len(columns) + 1), table_rows)
    lines += [
        "",
        "UniTac-NV against each simple baseline, paired over members (each member with its split's baseline): mean "
        "difference (baseline − UniTac-NV for NMAE, UniTac-NV − baseline for SSIM: positive = UniTac-NV better) and "
        "in how many members UniTac-NV is better.",
        "",
    ]
    paired: list[list[str]] = []
    not_beaten: list[str] = []
    for row in rows[rows.index("all_seen") :] if "all_seen" in rows else rows:  # pooled seen, then unseen
        for baseline in columns:
            ours_columns = [info["compared_with"][baseline]]
            if baseline.startswith("pca_"):
                ours_columns.append("ae_" + baseline[4:])
            for ours in ours_columns:
                if ours not in splits[0]["metrics"]["table1"][row]:
                    continue
                d_nmae = simple_members(splits, row, baseline, "nmae") - members(splits, row, ours, "nmae")
                d_ssim = members(splits, row, ours, "ssim") - simple_members(splits, row, baseline, "ssim")
                count = len(d_nmae)
                wins_n, wins_s = int((d_nmae > 0).sum()), int((d_ssim > 0).sum())
                named = baseline.replace("_to_", " → ").replace("_", " ", 1)
                paired.append([row, _arrow(ours), named, f"{d_nmae.mean():+.4f}", f"{wins_n} of {count}"])
                paired[-1] += [f"{d_ssim.mean():+.4f}", f"{wins_s} of {count}"]
                if 2 * wins_n <= count or 2 * wins_s <= count:
                    not_beaten.append(f"{row}: {_arrow(ours)} vs {baseline.replace('_to_', ' → ')}")
    header = ["row", "UniTac-NV", "baseline", "NMAE difference", "better NMAE", "SSIM difference", "better SSIM"]
    lines += markdown_table(header, ["---"] * 3 + ["---:"] * 4, paired)
    lines += [
        "",
        (
            "Where a simple baseline does as well or better (UniTac-NV better in at most half the members, NMAE or "
            "SSIM): " + "; ".join(not_beaten) + "."
            if not_beaten
            else "UniTac-NV is better than every simple baseline in most members, in NMAE and SSIM, on these rows."
        ),
    ]
    return lines


# ---- every claim under every reading --------------------------------------------------------------------------


def reading_members(splits: list[dict[str, Any]], row: str, column: str, metric: str, option: str) -> np.ndarray:
    """Every member's value of one Table I cell under one NMAE normaliser (``metric`` nmae) or SSIM range (ssim)."""
    values: list[float] = []
    for split in splits:
        for reading in split["readings"].values():
            if reading["nmae_normaliser" if metric == "nmae" else "ssim_range"] == option:
                values += reading["table1_members"].get(row, {}).get(column, {}).get(metric, [])
                break
    return np.asarray(values, dtype=float)


def reading_claims(splits: list[dict[str, Any]], nmae: str, ssim: str) -> list[tuple[str, bool, str]]:
    """The three claims a metric reading can change, under one (NMAE normaliser, SSIM range)."""
    seen_ssim = {d: reading_members(splits, "all_seen", d, "ssim", ssim) for d in SEEN_DIRECTIONS}
    seen_nmae = {d: reading_members(splits, "all_seen", d, "nmae", nmae) for d in SEEN_DIRECTIONS}
    if not all(v.size for v in (*seen_ssim.values(), *seen_nmae.values())):
        return []
    lowest = min(seen_ssim, key=lambda d: seen_ssim[d].mean())
    highest = max(seen_nmae, key=lambda d: seen_nmae[d].mean())
    out = [
        (
            "SSIM > 0.95, all four",
            all(v.mean() > 0.95 for v in seen_ssim.values()),
            f"lowest {_arrow(lowest)} {seen_ssim[lowest].mean():.3f}",
        ),
        (
            "p → u hardest (NMAE and SSIM)",
            lowest == highest == "papillarray_to_uskin",
            f"highest NMAE {_arrow(highest)} {seen_nmae[highest].mean():.4f}; lowest SSIM {_arrow(lowest)}",
        ),
    ]
    rows = list(splits[0]["metrics"]["table1"])
    unseen = rows[rows.index("all_seen") + 1 :] if "all_seen" in rows else []
    if unseen:
        columns = list(splits[0]["metrics"]["table1"]["all_seen"])
        worse = sum(
            reading_members(splits, unseen[0], c, "nmae", nmae).mean()
            > reading_members(splits, "all_seen", c, "nmae", nmae).mean()
            and reading_members(splits, unseen[0], c, "ssim", ssim).mean()
            < reading_members(splits, "all_seen", c, "ssim", ssim).mean()
            for c in columns
        )
        out.append(("unseen worse than seen", worse == len(columns), f"{worse} of {len(columns)} columns"))
    return out


def readings_lines(splits: list[dict[str, Any]]) -> list[str]:
    """The claims a reading can change, under every NMAE normaliser x SSIM range; the default reading marked.
    The latent, t-SNE and geometry claims read no reconstruction metric and are the same under every reading."""
    config = splits[0]["config"]
    nmae_options = [
        o for o in NMAE_NORMALISERS if reading_members(splits, "all_seen", SEEN_DIRECTIONS[0], "nmae", o).size
    ]
    ssim_options = [o for o in SSIM_RANGES if reading_members(splits, "all_seen", SEEN_DIRECTIONS[0], "ssim", o).size]
    rows = []
    for nmae in nmae_options:
        for ssim in ssim_options:
            found = reading_claims(splits, nmae, ssim)
            if not found:
                continue
            default = nmae == config["nmae_normaliser"] and ssim == config["ssim_range"]
            cells = [f"{'yes' if ok else '**no**'} ({text})" for _, ok, text in found]
            rows.append(
                (found, f"| `{nmae}` | `{ssim}` | {'**default**' if default else ''} | " + " | ".join(cells) + " |")
            )
    if not rows:
        return []
    names = [name for name, _, _ in rows[0][0]]
    return [
        "",
        "Under every metric reading (test contacts, seen objects; NMAE normaliser x SSIM range). The latent-distance, "
        "t-SNE and geometry claims read no reconstruction metric and do not change:",
        "",
        "| NMAE | SSIM | | " + " | ".join(names) + " |",
        "|---|---|---|" + "---|" * len(names),
        *[line for _, line in rows],
    ]


# ---- geometry -------------------------------------------------------------------------------------------------


def _member_values(splits: list[dict[str, Any]], pick: Any) -> np.ndarray:
    values = []
    for split in splits:
        for member in split["geometry"]["members"]:
            value = pick(member)
            if value is not None:
                values.append(value)
    return np.asarray(values, dtype=float)


def geometry_lines(protocol: str, splits: list[dict[str, Any]], n_members: int) -> list[str]:
    """The paper's four scenarios with the paper's heads, the no-latent baseline and the pooled same-sensor head."""
    scenarios = list(splits[0]["geometry"]["paper_heads"][0]["scenarios"])
    no_latent = _member_values(splits, lambda m: m["cross_sensor"]["no_latent_mm"])
    lines = [
        "",
        f"### Contact geometry on the unseen object ({protocol} split): mean profile error (mm), mean ± std over "
        f"{n_members} members",
        "",
        "Mean profile error: the mean absolute depth error (mm) over the 11 profile points and the held-out "
        "contacts. Each member draws its own geometry split (its own seed, apart from its model seed); "
        + (
            "random rays, as the paper."
            if protocol == "random"
            else "one contiguous block of rays, guard band around it, as the autoencoder's split."
        )
        + " The no-latent baseline predicts the training rays' mean profile for every contact.",
        "",
    ]
    rows = []
    for name in scenarios:
        paper_mm = PAPER_GEOMETRY_MAE_MM.get(name)
        rows.append([_arrow(name), _pm(geometry_values(splits, name)), "–" if paper_mm is None else f"{paper_mm:.3f}"])
    rows.append(["no latent (the training rays' mean profile)", _pm(no_latent), "–"])
    pooled = [head for split in splits for head in split["geometry"]["pooled_head"]]
    for name in pooled[0]["scenarios"] if pooled else []:
        label = (
            f"{_arrow(name)} (same-sensor option: one head trained on both sensors' latents, the test sensor's "
            f"included; {len(pooled)} member{'s' if len(pooled) != 1 else ''})"
        )
        rows.append([label, _pm(geometry_values(splits, name)), "–"])
    return lines + markdown_table(["train → test", "ours", "paper"], ["---", "---:", "---:"], rows)


def cross_summary(splits: list[dict[str, Any]]) -> dict[str, Any]:
    """Means over members: each method's cross-sensor error per direction and cost, the same-sensor heads, the
    ceiling (the best tuned same-sensor head per sensor, on latents and on raw frames) and the no-latent error."""
    out: dict[str, Any] = {"methods": {}, "ceiling": {}}
    crosses = [c for split in splits for c in split["geometry"]["cross"]]
    for method in crosses[0]["methods"]:
        entry = {
            d: np.mean([c["methods"][method]["cross"][d] for c in crosses])
            for d in crosses[0]["methods"][method]["cross"]
        }
        entry["seconds"] = float(np.mean([c["methods"][method]["seconds"] for c in crosses]))
        out["methods"][method] = entry
    out["same"] = {
        d: float(np.mean([c["methods"]["paper"]["same"][d] for c in crosses]))
        for d in crosses[0]["methods"]["paper"]["same"]
    }
    with_ceiling = [c["ceiling"] for c in crosses if c.get("ceiling")]
    for key in with_ceiling[0] if with_ceiling else []:
        out["ceiling"][key] = {
            "test_mm": float(np.mean([c[key]["test_mm"] for c in with_ceiling])),
            "std": float(np.std([c[key]["test_mm"] for c in with_ceiling])),
            "n": len(with_ceiling),
            "seconds": float(np.mean([c[key]["seconds"] for c in with_ceiling])),
            "choices": sorted(
                {(c[key]["learning_rate"], c[key]["dropout"], int(c[key]["epochs"])) for c in with_ceiling}
            ),
        }
    out["no_latent"] = float(np.mean([c["no_latent_mm"] for c in crosses]))
    out["members"] = len(crosses)
    return out


def cross_sensor_lines(protocol: str, splits: list[dict[str, Any]]) -> list[str]:
    """Strict cross-sensor geometry: every method beside the ceiling and the no-latent baseline, and the verdict
    on halving the paper's cross-sensor errors."""
    summary = cross_summary(splits)
    crosses = [c for split in splits for c in split["geometry"]["cross"]]
    lines = [
        "",
        f"### Strict cross-sensor geometry ({protocol} split): train on sensor A, test on sensor B",
        "",
        "Every head has the paper's architecture and one recipe (the paper's learning rate and epochs, the "
        "sensor's dropout) and is trained on sensor A's inputs of the unseen object's training rays only "
        f"({_contacts_text(crosses)}); sensor B's frames of the unseen object never enter training (the linear map "
        "and the CCA are fitted on the seen objects' training pairs). The paper heads here are the heads of the "
        "table above, fitted among the methods. "
        f"Mean over {summary['members']} members; cost = CPU seconds per head (heads fitted together share the fit "
        "equally) plus the method's own fit.",
        "",
    ]
    described = {
        "paper": "paper: A's latents",
        "translated": "translated: enc_B(dec_B(enc_A(x_A)))",
        "linear_map": "linear map z_A → z_B (ridge, seen pairs)",
        "cca": "CCA on seen pairs (both projected)",
    }
    rows = []
    for method, entry in summary["methods"].items():
        u_p, p_u = entry.get("uskin_to_papillarray", np.nan), entry.get("papillarray_to_uskin", np.nan)
        rows.append([described.get(method, method), f"{u_p:.3f}", f"{p_u:.3f}", f"{(u_p + p_u) / 2:.3f}"])
        rows[-1].append(f"{entry['seconds']:.1f}")
    paper = [f"{PAPER_GEOMETRY_MAE_MM[c]:.3f}" for c in CROSS]
    rows.append(["*paper (Hou et al.)*", *paper, f"{np.mean([PAPER_GEOMETRY_MAE_MM[c] for c in CROSS]):.3f}", "–"])
    header = ["method", "u → p (mm)", "p → u (mm)", "mean", "cost (CPU s)"]
    lines += markdown_table(header, ["---"] + ["---:"] * 4, rows)
    lines += [
        "",
        "Beside it, on the same rays: the same-sensor paper heads "
        + ", ".join(f"{_arrow(d)} {v:.3f}" for d, v in summary["same"].items())
        + f" mm; the no-latent baseline {summary['no_latent']:.3f} mm.",
    ]
    if summary["ceiling"]:
        n = next(iter(summary["ceiling"].values()))["n"]
        lines += [
            "",
            "Ceiling: the same-sensor heads per sensor on test sensor B's own inputs, its latents and its raw "
            f"(normalised) frames; {ceiling_recipe_text(crosses)}; {n} member{'s' if n != 1 else ''} (the first of "
            "each split):",
            "",
        ]
        rows = []
        for key, e in summary["ceiling"].items():
            choices = "; ".join(f"{lr:g}, {d:g}, {n}" for lr, d, n in e["choices"][:5])
            rows.append([key, f"{e['test_mm']:.3f} ± {e['std']:.3f}", choices, f"{e['seconds']:.0f}"])
        header = ["ceiling head", "test (mm)", "recipe (lr, dropout, epochs)", "cost (CPU s)"]
        lines += [*markdown_table(header, ["---", "---:", "---", "---:"], rows), "", halving_verdict(summary)]
    return lines


def ceiling_recipe_text(crosses: list[dict[str, Any]]) -> str:
    """How the JSON's ceiling heads were trained, against the one recipe of the other heads (the paper's): the
    same, or tuned apart (JSON written before issue 38: another learning rate, epochs and dropout chosen on
    validation rays held out of its training rays)."""
    paper = GeometryConfig()
    entries = [e for c in crosses for e in c.get("ceiling", {}).values()]
    same = all(
        e.get("learning_rate") == paper.learning_rate
        and int(e.get("epochs", -1)) == paper.epochs
        and int(e.get("contacts_val", 0)) == 0
        for e in entries
    )
    if same:
        return "the same recipe and the same training rays as every head above (none is tuned apart)"
    rates = sorted({float(e["learning_rate"]) for e in entries})
    held = sorted({int(e.get("contacts_val", 0)) for e in entries})
    return (
        f"**trained with another recipe than the heads above** (learning rate {', '.join(f'{r:g}' for r in rates)} "
        f"against {paper.learning_rate:g}, dropout and epochs chosen on {held[0]}-{held[-1]} validation contacts "
        "held out of its training rays): it measures that recipe as much as its input"
    )


def _contacts_text(crosses: list[dict[str, Any]]) -> str:
    """The geometry split's training / test contacts over the members, as the JSON records them."""
    train = sorted({int(c["contacts"]["train"]) for c in crosses if "contacts" in c})
    test = sorted({int(c["contacts"]["test"]) for c in crosses if "contacts" in c})
    if not train:
        return "contacts not recorded"

    def span(values: list[int]) -> str:
        return f"{values[0]}" if values[0] == values[-1] else f"{values[0]}-{values[-1]}"

    return f"{span(train)} training and {span(test)} test contacts per member"


def halving_verdict(summary: dict[str, Any]) -> str:
    """Whether the ceiling allows halving the paper's cross-sensor errors: a head predicting on sensor B's contacts
    can do no better than the best head trained on B's own contacts, as long as the ceiling is a bound on the data
    (where a strict method reads below it, it is not, and the page says so)."""
    parts, ruled_out, not_bound, room = [], [], [], []
    for direction in CROSS:
        target_sensor = direction.split("_to_")[1]
        best = min((v["test_mm"], k) for k, v in summary["ceiling"].items() if k.endswith(target_sensor))
        half = PAPER_GEOMETRY_MAE_MM[direction] / 2
        best_method = min(summary["methods"], key=lambda m: summary["methods"][m].get(direction, np.inf))
        reached = summary["methods"][best_method][direction]
        parts.append(
            f"{_arrow(direction)}: half the paper's is {half:.3f} mm, the ceiling on {target_sensor}'s own "
            f"contacts {best[0]:.3f} mm ({best[1]}), the best strict method {reached:.3f} ({best_method})"
        )
        if reached < best[0]:
            not_bound.append(_arrow(direction))
        elif best[0] > half:
            ruled_out.append(_arrow(direction))
        else:
            room.append(_arrow(direction))
    verdicts = []
    if not_bound:
        verdicts.append(
            f"For {', '.join(not_bound)} a strict cross-sensor method reads below the ceiling, so under this recipe "
            "the same-sensor heads bound nothing there and decide nothing about halving."
        )
    if ruled_out:
        verdicts.append(
            f"The ceiling rules out halving the paper's error for {', '.join(ruled_out)}: no head on the target "
            "sensor's own contacts gets there, so no cross-sensor head can; the target the data allows is the ceiling."
        )
    if room:
        verdicts.append(
            f"The ceiling leaves room to halve the paper's error for {', '.join(room)} (read it with the recipe "
            "stated above)."
        )
    return "Halving the paper's cross-sensor error: " + "; ".join(parts) + ". " + " ".join(verdicts)


def plot_cross_sensor(splits: list[dict[str, Any]], path: Path) -> Path:
    """Each strict cross-sensor method's error (mean of the two directions, members' mean and spread) against its
    training cost, with the ceiling, the same-sensor heads, the no-latent baseline and the paper's numbers."""
    summary = cross_summary(splits)
    crosses = [c for split in splits for c in split["geometry"]["cross"]]
    fig = new_figure(7.5, 4.6, layout="tight")
    ax = fig.subplots()
    for method, entry in summary["methods"].items():
        per_member = [np.mean([c["methods"][method]["cross"][d] for d in CROSS]) for c in crosses]
        mean = float(np.mean(per_member))
        ax.errorbar(entry["seconds"], mean, yerr=float(np.std(per_member)), fmt="o", capsize=3)
        ax.annotate(method, (entry["seconds"], mean), fontsize=8, xytext=(5, 3), textcoords="offset points")
    if summary["ceiling"]:
        best = np.mean(
            [min(v["test_mm"] for k, v in summary["ceiling"].items() if k.endswith(d.split("_to_")[1])) for d in CROSS]
        )
        ax.axhline(best, color="tab:green", ls="-", lw=1, label="ceiling: best tuned same-sensor head (mean)")
    ax.axhline(summary["no_latent"], color="0.4", ls=":", lw=1, label="no latent (training mean profile)")
    ax.axhline(
        np.mean(list(summary["same"].values())), color="tab:blue", ls="-.", lw=1, label="same-sensor paper heads (mean)"
    )
    paper = float(np.mean([PAPER_GEOMETRY_MAE_MM[c] for c in CROSS]))
    ax.axhline(paper, color="tab:red", ls="--", lw=1, label="paper, cross-sensor (mean)")
    ax.axhline(paper / 2, color="tab:red", ls=":", lw=1, label="half the paper's")
    ax.set_xscale("log")
    ax.set_xlabel("training cost per head (CPU seconds)")
    ax.set_ylabel("cross-sensor profile error (mm, mean of u→p and p→u)")
    ax.set_title(f"strict cross-sensor geometry, {summary['members']} members", fontsize=10)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7)
    return save_figure(fig, path)


def _variants_lines(splits: list[dict[str, Any]], columns: list[str]) -> list[str]:
    """The all-seen NMAE and SSIM under every metric option, on the *validation* contacts (the choice of reading is
    made there), beside the paper's all-seen row, with the geometric mean over columns of ours / the paper's (NMAE)
    and (1 - ours) / (1 - the paper's) (SSIM): 1 where the magnitudes match."""
    variants = [s["metrics"].get("validation_metric_variants") for s in splits]
    if not all(variants):
        return []
    paper = PAPER_TABLE1["all_seen"]
    lines = [
        "",
        "### The same models under every metric reading (validation contacts, seen objects, mean over members)",
        "",
    ]
    rows = []
    for metric, index in (("nmae", 0), ("ssim", 1)):
        for option in variants[0][metric]:
            values = [_variant_mean(variants, metric, option, c) for c in columns]
            # NMAE: ours / paper's; SSIM: (1 - ours) / (1 - paper's), the dissimilarities (SSIM may be negative)
            ratios = [
                v / paper[c][0] if metric == "nmae" else (1.0 - v) / (1.0 - paper[c][1])
                for v, c in zip(values, columns, strict=True)
                if c in paper
            ]
            rows.append([metric.upper(), f"`{option}`", *(f"{v:.3f}" for v in values)])
            rows[-1].append(f"{float(np.exp(np.mean(np.log(ratios)))):.2f}")
        paper_row = [f"{paper[c][index]:.3f}" if c in paper else "–" for c in columns]
        rows.append([metric.upper(), "*paper, all seen (test)*", *paper_row, "1"])
    header = ["metric", "option", *(_arrow(c) for c in columns), "geometric-mean ratio to the paper's"]
    return lines + markdown_table(header, ["---"] * (len(columns) + 2) + ["---:"], rows)


def _variant_mean(variants: list[Any], metric: str, option: str, column: str) -> float:
    """One validation metric under one reading, averaged over every member of every split."""
    return float(np.mean([v for split in variants for v in split[metric][option][column]]))


def _consistency_lines(splits: list[dict[str, Any]], columns: list[str]) -> list[str]:
    """How much SSIM a unit of NMAE costs, (1 - SSIM) / NMAE (geometric mean over the columns), under every pair of
    readings, beside the paper's own pairs. Independent of how large the errors are (the simulated contacts are
    cleaner than recorded ones), it asks which reading makes our NMAE and SSIM relate the way the paper's do."""
    variants = [s["metrics"].get("validation_metric_variants") for s in splits]
    if not all(variants):
        return []
    paper = PAPER_TABLE1["all_seen"]
    shared = [c for c in columns if c in paper]
    paper_slope = float(np.exp(np.mean([np.log((1.0 - paper[c][1]) / paper[c][0]) for c in shared])))

    ssim_options = list(variants[0]["ssim"])
    lines = [
        "",
        f"SSIM lost per unit of NMAE, (1 − SSIM) / NMAE, geometric mean over the columns, divided by the paper's "
        f"({paper_slope:.2f} on its all-seen row): 1 where our two metrics relate as the paper's do, whatever the "
        "size of the errors.",
        "",
    ]
    rows = []
    for nmae_option in variants[0]["nmae"]:
        cells = [f"`{nmae_option}`"]
        for ssim_option in ssim_options:
            slopes = [
                np.log(
                    max(1.0 - _variant_mean(variants, "ssim", ssim_option, c), 1e-6)
                    / _variant_mean(variants, "nmae", nmae_option, c)
                )
                for c in shared
            ]
            cells.append(f"{float(np.exp(np.mean(slopes))) / paper_slope:.2f}")
        rows.append(cells)
    header = ["NMAE normaliser \\ SSIM range", *(f"`{o}`" for o in ssim_options)]
    return lines + markdown_table(header, ["---"] + ["---:"] * len(ssim_options), rows)


if __name__ == "__main__":
    main()
