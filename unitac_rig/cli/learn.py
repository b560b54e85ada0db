"""Learning commands: ``train``, ``report``, ``translate``, ``geometry`` and ``export-model``.

Why one module of ~510 lines: the train command carries one option per hyper-parameter of the model and training
(issue 14) beside report, translate, geometry and export-model.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import typer

from unitac_rig.errors import UsageError


def _parse_seeds(seed: int, n_seeds: int) -> tuple[int, ...]:
    if n_seeds < 1:
        raise UsageError("--n-seeds must be at least 1")
    return tuple(range(seed, seed + n_seeds))


def _parse_widths(text: str, option: str) -> tuple[int, ...]:
    """``"64,48"`` -> (64, 48); a UsageError names the option otherwise."""
    try:
        widths = tuple(int(part) for part in text.replace(" ", "").split(",") if part)
    except ValueError:
        raise UsageError(f"{option} takes comma-separated layer widths, e.g. 64,48; got {text!r}") from None
    if not widths or min(widths) < 1:
        raise UsageError(f"{option} takes comma-separated positive layer widths, got {text!r}")
    return widths


def _option_name(key: str) -> str:
    """The command-line option of a flat TrainConfig key (``shape.latent_dim`` -> ``--latent-dim``)."""
    return "--lr" if key == "learning_rate" else "--" + key.removeprefix("shape.").replace("_", "-")


def training_overrides(
    config_file: Path | None, options: dict[str, Any], seed: int | None, n_seeds: int | None
) -> dict[str, Any]:
    """The flat TrainConfig keys a ``train`` call sets: the --config file's, then every option given on the
    command line over them (options left out stay None and change nothing)."""
    from unitac_rig.learning.config import load_config

    flat = load_config(config_file) if config_file is not None else {}
    for key, value in options.items():
        if value is None:
            continue
        if key in ("shape.encoder_hidden", "shape.decoder_hidden"):
            value = _parse_widths(value, _option_name(key))
        flat[key] = value
    if seed is not None or n_seeds is not None:
        first = seed if seed is not None else int(flat.get("seeds", (0,))[0])
        flat["seeds"] = _parse_seeds(first, n_seeds if n_seeds is not None else 1)
    return flat


# Help headings of `train` (the options are many: grouped, as git groups its own).
_RUN = "Data and run"
_TRAINING = "Training"
_MODEL = "Model (the paper's shape by default)"
_SPLIT = "Split, preprocessing and metrics"
_REPORT = "Evaluation and report"

# What the checks before the heavy imports compare with (tests keep them equal to the library's own tables).
RUN_MARKER = "checkpoint.pt"  # learning.run.CHECKPOINT_NAME: a folder holding it is a trained run
DEVICES = ("auto", "cpu", "cuda")
PREPROCESSING_NAMES = ("channel_z", "sensor_minmax", "sensor_scale", "raw")  # learning.data.PREPROCESSING
NMAE_NORMALISER_NAMES = ("channel_range", "sensor_range", "channel_std", "frame_range")  # metrics.NMAE_NORMALISERS
SSIM_RANGE_NAMES = ("channel_range", "sensor_range", "z_range")  # metrics.SSIM_RANGES


def check_train_arguments(
    data: list[Path], out: Path, resume: bool, device: str, config_file: Path | None, choices: dict[str, str | None]
) -> None:
    """What a ``train`` call can be refused for without torch or the data: a usage error naming the option, in
    well under a second (importing torch alone takes seconds on a loaded box)."""
    if device not in DEVICES:
        raise UsageError(f"--device {device!r} is not a device", hint=f"use one of: {', '.join(DEVICES)}")
    for option, (value, known) in {
        "--preprocessing": (choices.get("preprocessing"), PREPROCESSING_NAMES),
        "--nmae-normaliser": (choices.get("nmae_normaliser"), NMAE_NORMALISER_NAMES),
        "--ssim-range": (choices.get("ssim_range"), SSIM_RANGE_NAMES),
    }.items():
        if value is not None and value not in known:
            raise UsageError(f"{option} {value!r} is not one of: {', '.join(known)}")
    for directory in data:
        if not directory.is_dir():
            raise UsageError(f"--data {directory} is not a directory", hint="pass the --data folder `collect` wrote")
    if config_file is not None and not config_file.is_file():
        raise UsageError(f"--config {config_file} does not exist")
    if resume:
        if not (out / RUN_MARKER).is_file():
            raise UsageError(f"--out {out} holds no run to resume", hint="drop --resume to start a new run there")
    elif (out / RUN_MARKER).exists():
        raise UsageError(
            f"--out {out} already holds a run", hint="pass --resume to continue it, or choose another --out"
        )


def train_command(
    ctx: typer.Context,
    data: list[Path] = typer.Option(
        ...,
        "--data",
        metavar="DIR",
        help="Directory of session files (collect, campaign or import output); repeat to pool several.",
        rich_help_panel=_RUN,
    ),
    out: Path = typer.Option(
        ...,
        "--out",
        metavar="RUN",
        help="Run directory to create (or to continue with --resume).",
        rich_help_panel=_RUN,
    ),
    resume: bool = typer.Option(
        False, "--resume", help="Continue the run in --out from its last checkpoint.", rich_help_panel=_RUN
    ),
    config_file: Path = typer.Option(
        None,
        "--config",
        metavar="FILE",
        help="TOML file with any training keys (docs/learning.md); options given here win.",
        rich_help_panel=_RUN,
    ),
    partial: bool = typer.Option(
        False,
        "--partial/--complete-only",
        help="Also train on contacts only some sensors recorded (at least two; masked loss). Test and validation "
        "use contacts every sensor recorded.",
        rich_help_panel=_RUN,
    ),
    from_run: Path = typer.Option(
        None,
        "--from",
        metavar="RUN",
        help="A trained run to add --new-sensor to (it is not modified).",
        rich_help_panel=_RUN,
    ),
    new_sensor: str = typer.Option(
        None,
        "--new-sensor",
        metavar="SENSOR",
        help="With --from: train only this sensor's encoder and output layer (docs/learning.md).",
        rich_help_panel=_RUN,
    ),
    epochs: int = typer.Option(
        None,
        "--epochs",
        min=1,
        show_default="1000, as in the paper",
        help="Training epochs; with --resume, the new total.",
        rich_help_panel=_TRAINING,
    ),
    seed: int = typer.Option(
        None,
        "--seed",
        show_default="0",
        help="Seed of the first model (initialisation, shuffling, dropout).",
        rich_help_panel=_TRAINING,
    ),
    n_seeds: int = typer.Option(
        None,
        "--n-seeds",
        min=1,
        show_default="1",
        help="Train seeds SEED..SEED+N-1 together in one batched run.",
        rich_help_panel=_TRAINING,
    ),
    learning_rate: float = typer.Option(
        None, "--lr", show_default="5e-4, as in the paper", help="Adam learning rate.", rich_help_panel=_TRAINING
    ),
    batch_size: int = typer.Option(
        None, "--batch-size", min=1, show_default="64, as in the paper", help="Batch size.", rich_help_panel=_TRAINING
    ),
    device: str = typer.Option(
        "auto", "--device", metavar="NAME", help="auto, cpu or cuda.", rich_help_panel=_TRAINING
    ),
    threads: int = typer.Option(
        0, "--threads", min=0, help="CPU threads (0: one, fastest for these small layers).", rich_help_panel=_TRAINING
    ),
    dropout: float = typer.Option(
        None, "--dropout", show_default="0.007", help="Dropout after every layer.", rich_help_panel=_MODEL
    ),
    encoder_hidden: str = typer.Option(
        None,
        "--encoder-hidden",
        metavar="W,W",
        show_default="64,48",
        help="Encoder hidden widths.",
        rich_help_panel=_MODEL,
    ),
    latent_dim: int = typer.Option(
        None, "--latent-dim", min=1, show_default="16", help="Latent size.", rich_help_panel=_MODEL
    ),
    decoder_hidden: str = typer.Option(
        None,
        "--decoder-hidden",
        metavar="W,W",
        show_default="64,96",
        help="Decoder hidden widths.",
        rich_help_panel=_MODEL,
    ),
    align_weight: float = typer.Option(
        None,
        "--align-weight",
        show_default="0",
        help="Weight of a scale-free latent alignment term (beyond the paper).",
        rich_help_panel=_MODEL,
    ),
    split_seed: int = typer.Option(
        None, "--split-seed", show_default="0", help="Seed of the test/validation split.", rich_help_panel=_SPLIT
    ),
    test_fraction: float = typer.Option(
        None,
        "--test-fraction",
        show_default="0.1",
        help="Share of directions held out for test.",
        rich_help_panel=_SPLIT,
    ),
    val_fraction: float = typer.Option(
        None,
        "--val-fraction",
        show_default="0.1",
        help="Share of directions for validation.",
        rich_help_panel=_SPLIT,
    ),
    preprocessing: str = typer.Option(
        None,
        "--preprocessing",
        metavar="NAME",
        show_default="sensor_scale",
        help="channel_z, sensor_minmax, sensor_scale or raw.",
        rich_help_panel=_SPLIT,
    ),
    nmae_normaliser: str = typer.Option(
        None,
        "--nmae-normaliser",
        metavar="NAME",
        show_default="channel_range",
        help="channel_range, sensor_range, channel_std or frame_range.",
        rich_help_panel=_SPLIT,
    ),
    ssim_range: str = typer.Option(
        None,
        "--ssim-range",
        metavar="NAME",
        show_default="sensor_range",
        help="SSIM data range: channel_range, sensor_range or z_range.",
        rich_help_panel=_SPLIT,
    ),
    baselines: bool = typer.Option(
        None,
        "--baselines/--no-baselines",
        show_default="--baselines",
        help="Also train per-sensor autoencoders.",
        rich_help_panel=_REPORT,
    ),
    eval_every: int = typer.Option(
        None,
        "--eval-every",
        min=1,
        show_default="1",
        help="Epochs between validation evaluations.",
        rich_help_panel=_REPORT,
    ),
    checkpoint_every: int = typer.Option(
        None,
        "--checkpoint-every",
        min=1,
        show_default="50",
        help="Epochs between checkpoints.",
        rich_help_panel=_REPORT,
    ),
    tsne_contacts: int = typer.Option(
        None,
        "--tsne-contacts",
        min=0,
        show_default="600",
        help="Test contacts kept for the t-SNE.",
        rich_help_panel=_REPORT,
    ),
    report: bool = typer.Option(
        True, "--report/--no-report", help="Write metrics.json, report.md and figures.", rich_help_panel=_REPORT
    ),
) -> None:
    """Train UniTac-NV (and the baselines) on paired data; writes RUN/checkpoint.pt, config.toml, metrics.json,
    report.md and figures."""
    if learning_rate is not None and not learning_rate > 0:
        raise UsageError(f"--lr must be positive, got {learning_rate:g}")
    if from_run is None and new_sensor is None:
        check_train_arguments(
            data, out, resume, device, config_file,
            {"preprocessing": preprocessing, "nmae_normaliser": nmae_normaliser, "ssim_range": ssim_range},
        )  # fmt: skip
    from rich.console import Console
    from rich.progress import BarColumn, Progress, TextColumn, TimeRemainingColumn

    from unitac_rig.learning.data import build_paired_dataset, load_sets
    from unitac_rig.learning.report import write_report
    from unitac_rig.learning.train import TrainConfig, load_run, resolve_device, train

    resolve_device(device)  # a bad --device fails before the data is read
    if from_run is not None or new_sensor is not None:
        _train_new_sensor(ctx, data, out, from_run, new_sensor)
        return
    options: dict[str, Any] = {
        "split_seed": split_seed,
        "learning_rate": learning_rate,
        "batch_size": batch_size,
        "shape.dropout": dropout,
        "shape.encoder_hidden": encoder_hidden,
        "shape.latent_dim": latent_dim,
        "shape.decoder_hidden": decoder_hidden,
        "shape.align_weight": align_weight,
        "test_fraction": test_fraction,
        "val_fraction": val_fraction,
        "preprocessing": preprocessing,
        "nmae_normaliser": nmae_normaliser,
        "ssim_range": ssim_range,
        "baselines": baselines,
        "eval_every": eval_every,
        "checkpoint_every": checkpoint_every,
        "tsne_contacts": tsne_contacts,
    }
    if resume:
        given = [_option_name(k) for k, v in options.items() if v is not None] + [
            name for name, v in (("--config", config_file), ("--seed", seed), ("--n-seeds", n_seeds)) if v is not None
        ]
        if given:
            raise UsageError(
                f"--resume continues a run with its stored configuration; drop {', '.join(sorted(given))}",
                hint="only --epochs (to extend the budget) goes with --resume",
            )
        config = None
    else:
        flat = training_overrides(config_file, options, seed, n_seeds)
        if epochs is not None:
            flat["epochs"] = epochs
        config = TrainConfig().updated(flat)
    console = Console()
    if resume and not partial:  # a run trained on a partial join resumes on one
        from unitac_rig.learning.run import checkpoint_path, load_checkpoint

        if checkpoint_path(out).is_file():
            partial = int(load_checkpoint(out).get("dataset_summary", {}).get("partial_train_rows", 0)) > 0
    console.print(f"reading the sessions in {', '.join(map(str, data))}...")
    sets = load_sets(data)
    dataset = build_paired_dataset(sets, partial=partial)
    console.print(
        f"paired dataset: {len(dataset)} contacts, sensors {', '.join(dataset.sensors)}, "
        f"objects {', '.join(dataset.objects)}"
    )
    for line in dropped_sessions(sets, dataset.objects):
        console.print(f"[yellow]left out:[/] {line}", soft_wrap=True)
    total = epochs if config is None else config.epochs
    lines = EveryFewSeconds()
    with Progress(
        TextColumn("[bold]train"),
        BarColumn(),
        TextColumn("epoch {task.completed}/{task.total}"),
        TextColumn("{task.fields[status]}"),
        TimeRemainingColumn(),
        console=console,
        disable=not console.is_terminal,  # a log gets a line every few seconds instead (below)
    ) as progress:
        task = progress.add_task("train", total=total, status="")

        def on_epoch(record: dict[str, Any]) -> None:
            status = ""
            scored = record.get("val") or record.get("test") or {}
            seen = scored.get("seen") or scored.get("all")
            if seen:
                crosses = [v["nmae"][0] for k, v in seen.items() if "_to_" in k]
                status = f"{'val' if 'val' in record else 'test'} NMAE {sum(crosses) / len(crosses):.4f}"
                if "latent_l1" in seen:
                    status += f", latent L1 {seen['latent_l1'][0]:.2f}"
                if "latent_ratio" in seen:
                    status += f" (ratio {seen['latent_ratio'][0]:.2f})"
            progress.update(task, completed=record["epoch"], status=status)
            if not console.is_terminal and lines.due(last=record["epoch"] == total):
                console.print(f"train: epoch {record['epoch']}/{total} {status}".rstrip(), soft_wrap=True)

        outcome = train(
            dataset,
            out,
            config,
            device=device,
            threads=threads or None,
            resume=resume,
            epochs=epochs if resume else None,
            progress=on_epoch,
        )
        progress.update(task, total=outcome.epochs_done)
    console.print(f"trained {outcome.epochs_done} epochs in {outcome.train_seconds:.1f} s -> {out}")
    if report:
        path = write_report(out, run=load_run(out), on_stage=stage_printer(console))
        _print_table(console, out)
        console.print(f"report: {path}")


def dropped_sessions(sets: list[Any], paired_objects: tuple[str, ...] | list[str]) -> list[str]:
    """One line per session that gave the paired dataset nothing: no other sensor recorded its object (or none of
    its contacts matched another sensor's). Training on the rest silently would hide a missing partner session."""
    sensors_of: dict[str, list[str]] = {}
    for matched in sets:
        sensors_of.setdefault(matched.object_id, []).append(matched.sensor)
    lines = []
    for matched in sets:
        if matched.object_id in paired_objects:
            continue
        others = [s for s in sensors_of[matched.object_id] if s != matched.sensor]
        why = (
            f"no contact shared with {', '.join(others)}"
            if others
            else "no session of the same object with another sensor"
        )
        lines.append(f"{matched.object_id}/{matched.sensor} ({len(matched)} matched frames): {why}")
    return lines


class EveryFewSeconds:
    """Throttle for progress lines written to a log or pipe (no terminal to redraw a bar): the first call, then one
    every ``seconds``, and the last."""

    def __init__(self, seconds: float = 10.0) -> None:
        self.seconds = seconds
        self._last: float | None = None

    def due(self, *, last: bool = False) -> bool:
        import time

        now = time.monotonic()
        if last or self._last is None or now - self._last >= self.seconds:
            self._last = now
            return True
        return False


def stage_printer(console: Any) -> Any:
    """A report's ``on_stage`` callback: one line per stage (the t-SNE alone can take a minute or two)."""

    def on_stage(message: str) -> None:
        console.print(f"report: {message}...", highlight=False, soft_wrap=True)

    return on_stage


# the options that mean something for `train --from RUN --new-sensor NAME` (the rest are the trained run's own)
_NEW_SENSOR_OPTIONS = frozenset(
    {"data", "out", "from_run", "new_sensor", "epochs", "learning_rate", "batch_size", "device", "threads", "report"}
)


def _train_new_sensor(
    ctx: typer.Context, data: list[Path], out: Path, from_run: Path | None, new_sensor: str | None
) -> None:
    """``train --from RUN --new-sensor NAME``: the new sensor's encoder and output layer against the frozen model."""
    from rich.console import Console
    from rich.progress import BarColumn, Progress, TextColumn, TimeRemainingColumn
    from rich.table import Table

    from unitac_rig.learning.data import load_sets
    from unitac_rig.learning.extend import EXTENSION_JSON, ExtendConfig, add_sensor
    from unitac_rig.learning.report import write_report

    if from_run is None or not new_sensor:
        raise UsageError("--from and --new-sensor go together", hint="train --from RUN --new-sensor NAME --data DATA")
    source = getattr(ctx, "get_parameter_source", None)
    given = [
        name
        for name in ctx.params
        if name not in _NEW_SENSOR_OPTIONS and source is not None and "DEFAULT" not in str(source(name))
    ]
    if given:
        flags = {p.name: (getattr(p, "opts", None) or [p.name])[0] for p in ctx.command.params}
        raise UsageError(
            f"--new-sensor keeps the trained run's settings; drop {', '.join(sorted(flags.get(n, n) for n in given))}",
            hint="only --epochs, --lr, --batch-size, --device and --threads go with --new-sensor",
        )
    params = {name: value for name, value in ctx.params.items() if source is None or "DEFAULT" not in str(source(name))}
    console = Console()
    sets = load_sets(data)
    with Progress(
        TextColumn(f"[bold]train {new_sensor}"),
        BarColumn(),
        TextColumn("epoch {task.completed}/{task.total}"),
        TextColumn("{task.fields[status]}"),
        TimeRemainingColumn(),
        console=console,
    ) as progress:
        task = progress.add_task("extend", total=None, status="")

        def on_epoch(record: dict[str, Any]) -> None:
            loss = sum(record["train_loss"]) / len(record["train_loss"])
            progress.update(task, completed=record["epoch"], total=record["epochs"], status=f"train loss {loss:.4f}")

        config = ExtendConfig(
            epochs=params.get("epochs"), batch_size=params.get("batch_size"), learning_rate=params.get("learning_rate")
        )
        outcome = add_sensor(
            from_run,
            sets,
            new_sensor,
            out,
            config,
            device=ctx.params.get("device") or "auto",
            threads=ctx.params.get("threads") or None,
            progress=on_epoch,
        )
    summary = outcome.summary
    contacts = summary["contacts"]
    shared = ", ".join(f"{s} {n}" for s, n in contacts["train_shared_with"].items())
    console.print(
        f"trained {new_sensor} into {from_run} -> {out}: {contacts['train']} training contacts (shared with {shared}), "
        f"{contacts['test']} test contacts, {summary['settings']['epochs']} epochs in {summary['train_seconds']:.1f} s"
    )
    table = Table(title=f"Test NMAE/SSIM of {new_sensor}'s directions (untrained layers -> trained)", box=None)
    for column in ("direction", "contacts", "untrained", "trained"):
        table.add_column(column, justify="right", overflow="fold")
    for name, after in summary["trained"].items():
        before = summary["untrained"][name]
        table.add_row(
            name.replace("_to_", "→"),
            str(after["contacts"]),
            f"{sum(before['nmae']) / len(before['nmae']):.3f}/{sum(before['ssim']) / len(before['ssim']):.3f}",
            f"{sum(after['nmae']) / len(after['nmae']):.3f}/{sum(after['ssim']) / len(after['ssim']):.3f}",
        )
    console.print(table)
    console.print(f"{out / EXTENSION_JSON}")
    if ctx.params.get("report", True):
        if outcome.complete_test_rows:
            path = write_report(out)
            _print_table(console, out)
            console.print(f"report: {path}")
        else:
            console.print("no test contact was recorded by every sensor: no report.md (see extension.json)")


def report_command(
    run: Path = typer.Argument(..., metavar="RUN", help="Run directory."),
    figures: bool = typer.Option(True, "--figures/--no-figures", help="Redraw the figures too."),
    nmae_normaliser: str = typer.Option(
        None, "--nmae-normaliser", metavar="NAME", show_default="the run's", help="Score under another NMAE normaliser."
    ),
    ssim_range: str = typer.Option(
        None, "--ssim-range", metavar="NAME", show_default="the run's", help="Score under another SSIM range."
    ),
) -> None:
    """Recompute RUN/metrics.json and rewrite RUN/report.md (and its figures)."""
    from rich.console import Console

    from unitac_rig.learning.report import write_report

    _require_run(run)
    console = Console()
    path = write_report(
        run, figures=figures, nmae_normaliser=nmae_normaliser, ssim_range=ssim_range, on_stage=stage_printer(console)
    )
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
    described = metrics.get("metrics")
    if described:
        console.print(
            f"NMAE normaliser {described['nmae_normaliser']}, SSIM range {described['ssim_range']}, "
            f"preprocessing {metrics.get('preprocessing', {}).get('scaling', '?')} (see report.md)",
            style="dim",
        )
    latent = metrics["latent_l1"]
    if latent["final"] is not None:
        first = "–" if latent["first_epoch"] is None else f"{latent['first_epoch']:.3f}"
        line = f"latent L1 between matched contacts: {first} -> {latent['final']:.3f}"
        aligned = metrics.get("alignment", {}).get("per_subset", {}).get("all")
        if aligned:
            ratio, mixing = aligned["latent_ratio"], aligned["mixing"]

            def mean(values: Any) -> str:
                return "–" if values is None else f"{sum(values) / len(values):.3f}"

            line += (
                f"; matched/unmatched {mean(ratio['first_epoch'])} -> {mean(ratio['final'])}; "
                f"sensor mixing {mean(mixing['first_epoch'])} -> {mean(mixing['final'])} "
                f"(perfect {mean(aligned['mixing_expected']['final'])})"
            )
        console.print(line)


def _sensor_of(path: Path, given: str | None, option: str) -> str:
    """The sensor that recorded ``path``: ``given``, else (a session file) the one its file names, as translate does."""
    if given:
        return given
    if path.suffix.lower() in (".h5", ".hdf5"):
        if not path.is_file():
            raise UsageError(f"{path} does not exist")
        from unitac_rig.storage.reader import read_session_info

        return read_session_info(path).sensor
    raise UsageError(f"{path.name} does not say which sensor recorded it: pass {option}", hint=f"e.g. {option} uskin")


def _output_beside_run(run: Path, folder: str, name: str, out: Path | None) -> Path:
    """``--out`` if given, else ``RUN/<folder>/<name>``: outputs go with the run, never into the dataset folder."""
    if out is not None:
        return out
    path = run / folder / name
    path.parent.mkdir(parents=True, exist_ok=True)
    return path


def _require_run(run: Path) -> None:
    """A cheap check before torch is imported (the same words as :func:`unitac_rig.learning.run.load_checkpoint`)."""
    if not (run / RUN_MARKER).is_file():
        raise UsageError(f"{run} is not a training run (no {RUN_MARKER})", hint="run `unitac-rig train` first")


def translate_command(
    run: Path = typer.Argument(..., metavar="RUN", help="Run directory."),
    input_path: Path = typer.Argument(..., metavar="INPUT", help="Session .h5, or frames as .npy/.npz (M, n, 3)."),
    source: str = typer.Option(
        None, "--from", metavar="SENSOR", show_default="the session file's sensor", help="Sensor that recorded INPUT."
    ),
    target: str = typer.Option(..., "--to", metavar="SENSOR", help="Sensor to translate into."),
    out: Path = typer.Option(
        None, "--out", metavar="FILE", show_default="RUN/translations/INPUT_to_SENSOR.npz", help="Output .npz."
    ),
) -> None:
    """Translate one sensor's frames into another sensor's format."""
    _require_run(run)
    source = _sensor_of(input_path, source, "--from")
    out = _output_beside_run(run, "translations", f"{input_path.stem}_to_{target}.npz", out)
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
    run: Path = typer.Argument(..., metavar="RUN", help="Run directory."),
    object_id: str = typer.Option(
        None, "--object", metavar="ID", show_default="the run's unseen object", help="Object to estimate."
    ),
    member: int = typer.Option(0, "--member", min=0, help="Which seed of a multi-seed run (index)."),
    epochs: int = typer.Option(80, "--epochs", min=1, help="MLP training epochs (80 in the paper)."),
    predict: Path = typer.Option(
        None,
        "--predict",
        metavar="FRAMES",
        help="Apply the saved estimator to these frames (.npy/.npz or a session .h5) instead.",
        rich_help_panel="Prediction",
    ),
    sensor: str = typer.Option(
        None,
        "--sensor",
        metavar="SENSOR",
        show_default="the session file's sensor",
        help="With --predict: the sensor that recorded the frames.",
        rich_help_panel="Prediction",
    ),
    trained_on: str = typer.Option(
        None,
        "--trained-on",
        metavar="SENSOR",
        show_default="--sensor",
        help="With --predict: use the MLP trained on this sensor's latents.",
        rich_help_panel="Prediction",
    ),
    out: Path = typer.Option(
        None,
        "--out",
        metavar="FILE",
        show_default="RUN/geometry/FRAMES_geometry.npz",
        help="With --predict: output .npz.",
        rich_help_panel="Prediction",
    ),
) -> None:
    """Downstream contact geometry on the unseen object: N x N train/test-sensor scenarios, RUN/geometry.json and
    the saved estimator; with --predict, the estimator's profiles for new frames."""
    _require_run(run)
    if predict is not None:
        sensor = _sensor_of(predict, sensor, "--sensor")
        out = _output_beside_run(run, "geometry", f"{predict.stem}_geometry.npz", out)
    from rich.console import Console
    from rich.table import Table

    from unitac_rig.learning.contact_geometry import ESTIMATOR_PT, GeometryConfig, geometry_for_run, predict_file
    from unitac_rig.learning.report import write_report

    console = Console()
    if predict is not None:
        prediction, path = predict_file(run, predict, sensor, trained_on, out)
        profiles = prediction.profiles_mm
        title = f"Predicted depth under the pad (mm), {sensor} frames, MLP trained on {prediction.trained_on} latents"
        table = Table(title=title, box=None)
        table.add_column("x mm", justify="right")
        shown = min(5, len(profiles))
        for i in range(shown):
            table.add_column(f"#{i}", justify="right")
        for k, x in enumerate(prediction.offsets_mm):
            table.add_row(f"{x:+.1f}", *(f"{profiles[i, k]:.2f}" for i in range(shown)))
        console.print(table)
        more = f" (first {shown} shown)" if len(profiles) > shown else ""
        console.print(f"{len(profiles)} profiles{more} -> {path}")
        return

    def on_stage(message: str) -> None:
        console.print(f"{message}...", highlight=False, soft_wrap=True)

    result, json_path, png_path = geometry_for_run(
        run, object_id, member=member, config=GeometryConfig(epochs=epochs), on_stage=on_stage
    )
    unseen = result.unseen
    kind = "unseen in training" if unseen else "seen in training"
    table = Table(title=f"Contact geometry on {result.object_id} ({kind}): mean profile error (mm)")
    for column in ("train sensor", "test sensor", "ours", "paper (unseen object)"):
        table.add_column(column, justify="right")
    for s in result.scenarios.values():
        paper = "–" if s["paper_mae_mm"] is None else f"{s['paper_mae_mm']:.3f}"
        table.add_row(s["train_sensor"], s["test_sensor"], f"{s['mae_mm']:.3f}", paper)
    console.print(table)
    if not unseen:
        console.print(
            f"{result.object_id} was seen in training: its errors are not comparable with the paper's, which are on "
            "an object the autoencoder never saw (omit --object for the run's unseen object)",
            style="yellow",
        )
    write_report(run, figures=False)
    console.print(f"{json_path}\n{png_path}\n{Path(run) / ESTIMATOR_PT} (apply it: --predict FRAMES)")


def export_model_command(
    run: Path = typer.Argument(..., metavar="RUN", help="Run directory."),
    fmt: str = typer.Option(
        "safetensors",
        "--format",
        help="safetensors (model.safetensors + config.json), torchscript, onnx or state-dict.",
    ),
    out: Path = typer.Option(..., "--out", help="New directory for the networks, config/model.json and README.md."),
    member: int = typer.Option(0, "--member", help="Which seed of a multi-seed run (index)."),
) -> None:
    """Write each sensor's encoder and decoder (normaliser folded in: sensor units in and out) with a model card."""
    from rich.console import Console

    from unitac_rig.learning.export import CARD_NAME, MODEL_JSON, export_model
    from unitac_rig.learning.safetensors_export import CONFIG_NAME

    document = export_model(run, out, fmt, member)
    console = Console()
    console.print(f"exported {run} (member {member}, seed {document['seed']}) as {fmt} -> {out}")
    for sensor, entry in document["sensors"].items():
        console.print(
            f"  {sensor}: ({entry['n_taxels']}, 3) {entry['units']} <-> latent {document['latent_dim']}: "
            f"{entry['encoder']}, {entry['decoder']}"
        )
    config = CONFIG_NAME if fmt == "safetensors" else MODEL_JSON
    console.print(f"  {config}, {CARD_NAME} (model card: data hash, metrics, intended use, limits, loading)")


def register(app: typer.Typer) -> None:
    """Add this area's commands to the root app."""
    app.command("train")(train_command)
    app.command("report")(report_command)
    app.command("translate")(translate_command)
    app.command("geometry")(geometry_command)
    app.command("export-model")(export_model_command)
