"""Learning commands: ``train``, ``report``, ``translate`` and ``geometry``."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import typer

from unitac_rig.errors import UsageError


def _parse_seeds(seed: int, n_seeds: int) -> tuple[int, ...]:
    if n_seeds < 1:
        raise UsageError("--n-seeds must be at least 1")
    return tuple(range(seed, seed + n_seeds))


def train_command(
    data: Path = typer.Option(..., "--data", help="Directory of session files (collect/campaign/import output)."),
    out: Path = typer.Option(..., "--out", help="Run directory to create (or to continue with --resume)."),
    epochs: int = typer.Option(1000, "--epochs", help="Training epochs (the paper: 1000)."),
    seed: int = typer.Option(0, "--seed", help="Seed of the first model; also seeds the train/test split."),
    n_seeds: int = typer.Option(1, "--n-seeds", help="Train seeds SEED..SEED+N-1 together in one batched run."),
    baselines: bool = typer.Option(True, "--baselines/--no-baselines", help="Also train per-sensor autoencoders."),
    device: str = typer.Option("auto", "--device", help="auto, cpu or cuda."),
    threads: int = typer.Option(0, "--threads", help="CPU threads (0: one, fastest for these small layers)."),
    resume: bool = typer.Option(False, "--resume", help="Continue the run in --out from its last checkpoint."),
    eval_every: int = typer.Option(1, "--eval-every", help="Epochs between test-set evaluations."),
    checkpoint_every: int = typer.Option(50, "--checkpoint-every", help="Epochs between checkpoints."),
    report: bool = typer.Option(True, "--report/--no-report", help="Write metrics.json, report.md and figures."),
) -> None:
    """Train UniTac-NV (and the baselines) on paired data; writes RUN/checkpoint.pt, metrics.json, report.md."""
    from rich.console import Console
    from rich.progress import BarColumn, Progress, TextColumn, TimeRemainingColumn

    from unitac_rig.learning.data import build_paired_dataset, load_sets
    from unitac_rig.learning.report import write_report
    from unitac_rig.learning.train import TrainConfig, load_run, resolve_device, train

    resolve_device(device)  # a bad --device fails before the data is read
    console = Console()
    dataset = build_paired_dataset(load_sets(data))
    console.print(
        f"paired dataset: {len(dataset)} contacts, sensors {', '.join(dataset.sensors)}, "
        f"objects {', '.join(dataset.objects)}"
    )
    config = TrainConfig(
        epochs=epochs,
        seeds=_parse_seeds(seed, n_seeds),
        split_seed=seed,
        baselines=baselines,
        eval_every=eval_every,
        checkpoint_every=checkpoint_every,
    )
    with Progress(
        TextColumn("[bold]train"),
        BarColumn(),
        TextColumn("epoch {task.completed}/{task.total}"),
        TextColumn("{task.fields[status]}"),
        TimeRemainingColumn(),
        console=console,
    ) as progress:
        task = progress.add_task("train", total=epochs, status="")

        def on_epoch(record: dict[str, Any]) -> None:
            status = ""
            seen = record.get("test", {}).get("seen") or record.get("test", {}).get("all")
            if seen:
                crosses = [v["nmae"][0] for k, v in seen.items() if "_to_" in k]
                status = f"test NMAE {sum(crosses) / len(crosses):.4f}"
                if "latent_l1" in seen:
                    status += f", latent L1 {seen['latent_l1'][0]:.2f}"
            progress.update(task, completed=record["epoch"], status=status)

        outcome = train(
            dataset,
            out,
            None if resume else config,
            device=device,
            threads=threads or None,
            resume=resume,
            epochs=epochs,
            progress=on_epoch,
        )
    console.print(f"trained {outcome.epochs_done} epochs in {outcome.train_seconds:.1f} s -> {out}")
    if report:
        console.print("evaluating and drawing the report (t-SNE takes a little while)...")
        path = write_report(out, run=load_run(out))
        _print_table(console, out)
        console.print(f"report: {path}")


def report_command(
    run: Path = typer.Argument(..., help="Run directory."),
    figures: bool = typer.Option(True, "--figures/--no-figures", help="Redraw the figures too."),
) -> None:
    """Recompute RUN/metrics.json and rewrite RUN/report.md (and its figures)."""
    from rich.console import Console

    from unitac_rig.learning.report import write_report

    console = Console()
    path = write_report(run, figures=figures)
    _print_table(console, run)
    console.print(f"report: {path}")


def _short_sensor_names(sensors: list[str]) -> dict[str, str]:
    """Each sensor's shortest prefix that no other sensor shares (uskin -> u, papillarray -> p), for table headers."""
    short = {}
    for name in sensors:
        others = [o for o in sensors if o != name]
        short[name] = next((name[:k] for k in range(1, len(name)) if not any(o.startswith(name[:k]) for o in others)),
                           name)  # fmt: skip
    return short


def _print_table(console: Any, run: Path) -> None:
    """Table I for the terminal: short headers with a legend, and the columns split over as many tables as the
    terminal's width needs, so no cell is ever cut (the full table is in RUN/report.md and RUN/metrics.json)."""
    import json

    from rich.measure import Measurement
    from rich.table import Table

    from unitac_rig.learning.paper import PAPER_TABLE1

    metrics = json.loads((Path(run) / "metrics.json").read_text(encoding="utf-8"))
    rows = metrics["table1"]
    columns = list(next(iter(rows.values())).keys())
    sensors = list(metrics.get("sensors") or [])
    short = _short_sensor_names(sensors)

    def header(column: str) -> str:
        if column.startswith("ae_"):
            return "AE " + short.get(column[3:], column[3:])
        source, _, target = column.partition("_to_")
        return f"{short.get(source, source)}→{short.get(target, target)}"

    def cell(pair: Any) -> str:
        return "–" if pair is None else f"{pair[0]:.3f}/{pair[1]:.3f}"

    def build(chunk: list[str]) -> Table:
        table = Table(box=None, pad_edge=False)
        table.add_column("row", overflow="fold")
        for column in chunk:
            table.add_column(header(column), justify="right", overflow="fold")
        for row, cells in rows.items():
            ours = [cells.get(c) for c in chunk]
            table.add_row(row, *(cell(None if v is None else (v["nmae"], v["ssim"])) for v in ours))
            if row in PAPER_TABLE1:
                table.add_row("  paper", *(cell(PAPER_TABLE1[row].get(c)) for c in chunk), style="dim")
        return table

    unbounded = console.options.update_width(10_000)  # measure a table's natural width, not the terminal's
    fits = 1  # how many columns fit beside the row names; then chunks of even size (3 + 3 rather than 5 + 1)
    while (
        fits < len(columns) and Measurement.get(console, unbounded, build(columns[: fits + 1])).maximum <= console.width
    ):
        fits += 1
    size = -(-len(columns) // -(-len(columns) // fits))
    chunks = [columns[i : i + size] for i in range(0, len(columns), size)]
    console.print("Test NMAE/SSIM (the paper's values dim below its rows)", style="bold")
    for index, chunk in enumerate(chunks):
        if index:
            console.print()
        console.print(build(chunk))
    legend = [f"{s} = {name}" for name, s in short.items() if s != name]
    legend.append("AE = the sensor's own autoencoder (baseline); a→b = encode a, decode b")
    console.print("; ".join(legend), style="dim")
    latent = metrics["latent_l1"]
    if latent["final"] is not None:
        console.print(f"latent L1 between matched contacts: {latent['first_epoch']:.3f} -> {latent['final']:.3f}")


def translate_command(
    run: Path = typer.Argument(..., help="Run directory."),
    input_path: Path = typer.Argument(..., metavar="INPUT", help="Session .h5, or frames as .npy/.npz (M, n, 3)."),
    source: str = typer.Option(..., "--from", help="Sensor that recorded INPUT."),
    target: str = typer.Option(..., "--to", help="Sensor to translate into."),
    out: Path = typer.Option(None, "--out", help="Output .npz (default: INPUT_to_<sensor>.npz beside INPUT)."),
) -> None:
    """Translate one sensor's frames into another sensor's format."""
    from rich.console import Console

    from unitac_rig.learning.translate import translate_file

    summary = translate_file(run, source, target, input_path, out)
    console = Console()
    console.print(
        f"translated {summary['frames']} frames {source} {tuple(summary['input_shape'][1:])} -> "
        f"{target} {tuple(summary['output_shape'][1:])}: {summary['output']}"
    )
    mean = ", ".join(f"{v:.3g}" for v in summary["mean_abs_per_channel"])
    console.print(f"mean |value| per channel (x, y, z): {mean}")
    latency = summary["latency_ms"]
    console.print(f"single-frame latency: median {latency['median_ms']:.3f} ms, p90 {latency['p90_ms']:.3f} ms (CPU)")


def geometry_command(
    run: Path = typer.Argument(..., help="Run directory."),
    object_id: str = typer.Option(None, "--object", help="Object to estimate (default: the run's unseen object)."),
    member: int = typer.Option(0, "--member", help="Which seed of a multi-seed run (index)."),
    epochs: int = typer.Option(80, "--epochs", help="MLP training epochs (the paper: 80)."),
) -> None:
    """Downstream contact geometry on the unseen object: N x N train/test-sensor scenarios, RUN/geometry.json."""
    from rich.console import Console
    from rich.table import Table

    from unitac_rig.learning.contact_geometry import GeometryConfig, geometry_for_run
    from unitac_rig.learning.report import write_report

    console = Console()
    console.print("training the profile MLPs...")
    result, json_path, png_path = geometry_for_run(run, object_id, member=member, config=GeometryConfig(epochs=epochs))
    table = Table(title=f"Contact geometry on {result.object_id}: mean profile error (mm)")
    for column in ("train sensor", "test sensor", "ours", "paper"):
        table.add_column(column, justify="right")
    for s in result.scenarios.values():
        paper = "–" if s["paper_mae_mm"] is None else f"{s['paper_mae_mm']:.3f}"
        table.add_row(s["train_sensor"], s["test_sensor"], f"{s['mae_mm']:.3f}", paper)
    console.print(table)
    write_report(run, figures=False)
    console.print(f"{json_path}\n{png_path}")


def register(app: typer.Typer) -> None:
    """Add this area's commands to the root app."""
    app.command("train")(train_command)
    app.command("report")(report_command)
    app.command("translate")(translate_command)
    app.command("geometry")(geometry_command)
