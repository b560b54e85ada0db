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


def train_command(
    ctx: typer.Context,
    data: list[Path] = typer.Option(
        ..., "--data", help="Directory of session files (collect/campaign/import output); repeat to pool several."
    ),
    out: Path = typer.Option(..., "--out", help="Run directory to create (or to continue with --resume)."),
    from_run: Path = typer.Option(None, "--from", help="A trained run to add --new-sensor to (it is not modified)."),
    new_sensor: str = typer.Option(
        None, "--new-sensor", help="With --from: train only this sensor's encoder and output layer (docs/learning.md)."
    ),
    config_file: Path = typer.Option(
        None, "--config", help="TOML file with any training keys (docs/learning.md); options given here win."
    ),
    epochs: int = typer.Option(None, "--epochs", help="Training epochs (the paper: 1000); with --resume, extends."),
    seed: int = typer.Option(None, "--seed", help="Seed of the first model (initialisation, shuffling, dropout)."),
    n_seeds: int = typer.Option(None, "--n-seeds", help="Train seeds SEED..SEED+N-1 together in one batched run."),
    split_seed: int = typer.Option(None, "--split-seed", help="Seed of the test/validation split (default 0)."),
    learning_rate: float = typer.Option(None, "--lr", help="Adam learning rate (the paper: 5e-4)."),
    batch_size: int = typer.Option(None, "--batch-size", help="Batch size (the paper: 64)."),
    dropout: float = typer.Option(None, "--dropout", help="Dropout after every layer (the paper: 0.007)."),
    encoder_hidden: str = typer.Option(None, "--encoder-hidden", help="Encoder hidden widths (the paper: 64,48)."),
    latent_dim: int = typer.Option(None, "--latent-dim", help="Latent size (the paper: 16)."),
    decoder_hidden: str = typer.Option(None, "--decoder-hidden", help="Decoder hidden widths (the paper: 64,96)."),
    align_weight: float = typer.Option(
        None, "--align-weight", help="Weight of a scale-free latent alignment term (beyond the paper; default 0)."
    ),
    test_fraction: float = typer.Option(None, "--test-fraction", help="Share of directions held out for test."),
    val_fraction: float = typer.Option(None, "--val-fraction", help="Share of directions for validation (0.1)."),
    preprocessing: str = typer.Option(
        None, "--preprocessing", help="channel_z, sensor_minmax, sensor_scale (default) or raw."
    ),
    nmae_normaliser: str = typer.Option(
        None, "--nmae-normaliser", help="channel_range (default), sensor_range, channel_std or frame_range."
    ),
    ssim_range: str = typer.Option(
        None, "--ssim-range", help="SSIM data range: channel_range, sensor_range (default) or z_range."
    ),
    baselines: bool = typer.Option(None, "--baselines/--no-baselines", help="Also train per-sensor autoencoders."),
    device: str = typer.Option("auto", "--device", help="auto, cpu or cuda."),
    threads: int = typer.Option(0, "--threads", help="CPU threads (0: one, fastest for these small layers)."),
    resume: bool = typer.Option(False, "--resume", help="Continue the run in --out from its last checkpoint."),
    eval_every: int = typer.Option(None, "--eval-every", help="Epochs between validation evaluations (1)."),
    checkpoint_every: int = typer.Option(None, "--checkpoint-every", help="Epochs between checkpoints (50)."),
    tsne_contacts: int = typer.Option(None, "--tsne-contacts", help="Test contacts kept for the t-SNE (600)."),
    report: bool = typer.Option(True, "--report/--no-report", help="Write metrics.json, report.md and figures."),
    partial: bool = typer.Option(
        False,
        "--partial/--complete-only",
        help="Also train on contacts only some sensors recorded (at least two; masked loss). Test and validation "
        "use contacts every sensor recorded.",
    ),
) -> None:
    """Train UniTac-NV (and the baselines) on paired data; writes RUN/checkpoint.pt, config.toml, metrics.json,
    report.md."""
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
    dataset = build_paired_dataset(load_sets(data), partial=partial)
    console.print(
        f"paired dataset: {len(dataset)} contacts, sensors {', '.join(dataset.sensors)}, "
        f"objects {', '.join(dataset.objects)}"
    )
    total = epochs if config is None else config.epochs
    with Progress(
        TextColumn("[bold]train"),
        BarColumn(),
        TextColumn("epoch {task.completed}/{task.total}"),
        TextColumn("{task.fields[status]}"),
        TimeRemainingColumn(),
        console=console,
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
        console.print("evaluating and drawing the report (t-SNE takes a little while)...")
        path = write_report(out, run=load_run(out))
        _print_table(console, out)
        console.print(f"report: {path}")


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
    run: Path = typer.Argument(..., help="Run directory."),
    figures: bool = typer.Option(True, "--figures/--no-figures", help="Redraw the figures too."),
    nmae_normaliser: str = typer.Option(
        None, "--nmae-normaliser", help="Score under another NMAE normaliser (default: the run's)."
    ),
    ssim_range: str = typer.Option(None, "--ssim-range", help="Score under another SSIM range (default: the run's)."),
) -> None:
    """Recompute RUN/metrics.json and rewrite RUN/report.md (and its figures)."""
    from rich.console import Console

    from unitac_rig.learning.report import write_report

    console = Console()
    path = write_report(run, figures=figures, nmae_normaliser=nmae_normaliser, ssim_range=ssim_range)
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
    predict: Path = typer.Option(
        None, "--predict", help="Apply the saved estimator to these frames (.npy/.npz or a session .h5) instead."
    ),
    sensor: str = typer.Option(None, "--sensor", help="With --predict: the sensor that recorded the frames."),
    trained_on: str = typer.Option(
        None, "--trained-on", help="With --predict: use the MLP trained on this sensor's latents (default: --sensor)."
    ),
    out: Path = typer.Option(None, "--out", help="With --predict: output .npz (default: FRAMES_geometry.npz)."),
) -> None:
    """Downstream contact geometry on the unseen object: N x N train/test-sensor scenarios, RUN/geometry.json and
    the saved estimator; with --predict, the estimator's profiles for new frames."""
    from rich.console import Console
    from rich.table import Table

    from unitac_rig.learning.contact_geometry import ESTIMATOR_PT, GeometryConfig, geometry_for_run, predict_file
    from unitac_rig.learning.report import write_report

    console = Console()
    if predict is not None:
        if not sensor:
            raise UsageError("--predict needs --sensor (the sensor that recorded the frames)")
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
    console.print(f"{json_path}\n{png_path}\n{Path(run) / ESTIMATOR_PT} (apply it: --predict FRAMES --sensor S)")


def export_model_command(
    run: Path = typer.Argument(..., help="Run directory."),
    fmt: str = typer.Option(
        "safetensors",
        "--format",
        help="safetensors (default: model.safetensors + config.json), torchscript, onnx, state-dict.",
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
