"""``unitac-rig train``: the command's options, and the thin layer that turns them into a :class:`TrainRequest` and
runs :func:`unitac_rig.learning.train.train` (or :func:`unitac_rig.learning.extend.add_sensor`) with a progress bar.

Every option is one ``Annotated`` alias below (its flag, help and help panel), so the command's signature is one line
per option and its body one call; the request object does the rest (checks, the configuration, the data).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Annotated, Any

import typer

from unitac_rig.cli.learn import (
    DEVICES,
    NMAE_NORMALISER_NAMES,
    PREPROCESSING_NAMES,
    RUN_MARKER,
    SSIM_RANGE_NAMES,
    _print_table,
    kept_run_line,
    report_interrupted_line,
    stage_printer,
)
from unitac_rig.cli.pace import Pace
from unitac_rig.cli.signals import termination_as_interrupt
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


# Help headings of `train` (the options are many: grouped, as git groups its own).
_RUN = "Data and run"
_TRAINING = "Training"
_MODEL = "Model (the paper's shape by default)"
_SPLIT = "Split, preprocessing and metrics"
_REPORT = "Evaluation and report"


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


_Data = Annotated[
    list[Path],
    typer.Option(
        "--data",
        metavar="DIR",
        help="Directory of session files (collect, campaign or import output); repeat to pool several.",
        rich_help_panel=_RUN,
    ),
]
_Out = Annotated[
    Path,
    typer.Option(
        "--out",
        metavar="RUN",
        help="Run directory to create (or to continue with --resume).",
        rich_help_panel=_RUN,
    ),
]
_Resume = Annotated[
    bool,
    typer.Option(
        "--resume",
        help="Continue the run in --out from its last checkpoint.",
        rich_help_panel=_RUN,
    ),
]
_ConfigFile = Annotated[
    Path | None,
    typer.Option(
        "--config",
        metavar="FILE",
        help="TOML file with any training keys (docs/learning.md); options given here win.",
        rich_help_panel=_RUN,
    ),
]
_Partial = Annotated[
    bool,
    typer.Option(
        "--partial/--complete-only",
        help="Also train on contacts only some sensors recorded (at least two; masked loss). Test and validation "
        "use contacts every sensor recorded.",
        rich_help_panel=_RUN,
    ),
]
_FromRun = Annotated[
    Path | None,
    typer.Option(
        "--from",
        metavar="RUN",
        help="A trained run to add --new-sensor to (it is not modified).",
        rich_help_panel=_RUN,
    ),
]
_NewSensor = Annotated[
    str | None,
    typer.Option(
        "--new-sensor",
        metavar="SENSOR",
        help="With --from: train only this sensor's encoder and output layer (docs/learning.md).",
        rich_help_panel=_RUN,
    ),
]
_Epochs = Annotated[
    int | None,
    typer.Option(
        "--epochs",
        min=1,
        show_default="1000, as in the paper",
        help="Training epochs; with --resume, the new total.",
        rich_help_panel=_TRAINING,
    ),
]
_Seed = Annotated[
    int | None,
    typer.Option(
        "--seed",
        show_default="0",
        help="Seed of the first model (initialisation, shuffling, dropout).",
        rich_help_panel=_TRAINING,
    ),
]
_NSeeds = Annotated[
    int | None,
    typer.Option(
        "--n-seeds",
        min=1,
        show_default="1",
        help="Train seeds SEED..SEED+N-1 together in one batched run.",
        rich_help_panel=_TRAINING,
    ),
]
_LearningRate = Annotated[
    float | None,
    typer.Option(
        "--lr",
        show_default="5e-4, as in the paper",
        help="Adam learning rate.",
        rich_help_panel=_TRAINING,
    ),
]
_BatchSize = Annotated[
    int | None,
    typer.Option(
        "--batch-size",
        min=1,
        show_default="64, as in the paper",
        help="Batch size.",
        rich_help_panel=_TRAINING,
    ),
]
_Device = Annotated[
    str,
    typer.Option(
        "--device",
        metavar="NAME",
        help="auto, cpu or cuda.",
        rich_help_panel=_TRAINING,
    ),
]
_Threads = Annotated[
    int,
    typer.Option(
        "--threads",
        min=0,
        help="CPU threads (0: one, fastest for these small layers).",
        rich_help_panel=_TRAINING,
    ),
]
_Dropout = Annotated[
    float | None,
    typer.Option(
        "--dropout",
        show_default="0.007",
        help="Dropout after every layer.",
        rich_help_panel=_MODEL,
    ),
]
_EncoderHidden = Annotated[
    str | None,
    typer.Option(
        "--encoder-hidden",
        metavar="W,W",
        show_default="64,48",
        help="Encoder hidden widths.",
        rich_help_panel=_MODEL,
    ),
]
_LatentDim = Annotated[
    int | None,
    typer.Option(
        "--latent-dim",
        min=1,
        show_default="16",
        help="Latent size.",
        rich_help_panel=_MODEL,
    ),
]
_DecoderHidden = Annotated[
    str | None,
    typer.Option(
        "--decoder-hidden",
        metavar="W,W",
        show_default="64,96",
        help="Decoder hidden widths.",
        rich_help_panel=_MODEL,
    ),
]
_AlignWeight = Annotated[
    float | None,
    typer.Option(
        "--align-weight",
        show_default="0",
        help="Weight of a scale-free latent alignment term (beyond the paper).",
        rich_help_panel=_MODEL,
    ),
]
_SplitSeed = Annotated[
    int | None,
    typer.Option(
        "--split-seed",
        show_default="0",
        help="Seed of the test/validation split.",
        rich_help_panel=_SPLIT,
    ),
]
_TestFraction = Annotated[
    float | None,
    typer.Option(
        "--test-fraction",
        show_default="0.1",
        help="Share of directions held out for test.",
        rich_help_panel=_SPLIT,
    ),
]
_ValFraction = Annotated[
    float | None,
    typer.Option(
        "--val-fraction",
        show_default="0.1",
        help="Share of directions for validation.",
        rich_help_panel=_SPLIT,
    ),
]
_Preprocessing = Annotated[
    str | None,
    typer.Option(
        "--preprocessing",
        metavar="NAME",
        show_default="sensor_scale",
        help="channel_z, sensor_minmax, sensor_scale or raw.",
        rich_help_panel=_SPLIT,
    ),
]
_NmaeNormaliser = Annotated[
    str | None,
    typer.Option(
        "--nmae-normaliser",
        metavar="NAME",
        show_default="channel_range",
        help="channel_range, sensor_range, channel_std or frame_range.",
        rich_help_panel=_SPLIT,
    ),
]
_SsimRange = Annotated[
    str | None,
    typer.Option(
        "--ssim-range",
        metavar="NAME",
        show_default="sensor_range",
        help="SSIM data range: channel_range, sensor_range or z_range.",
        rich_help_panel=_SPLIT,
    ),
]
_Baselines = Annotated[
    bool | None,
    typer.Option(
        "--baselines/--no-baselines",
        show_default="--baselines",
        help="Also train per-sensor autoencoders.",
        rich_help_panel=_REPORT,
    ),
]
_EvalEvery = Annotated[
    int | None,
    typer.Option(
        "--eval-every",
        min=1,
        show_default="1",
        help="Epochs between validation evaluations.",
        rich_help_panel=_REPORT,
    ),
]
_CheckpointEvery = Annotated[
    int | None,
    typer.Option(
        "--checkpoint-every",
        min=1,
        show_default="50",
        help="Epochs between checkpoints.",
        rich_help_panel=_REPORT,
    ),
]
_TsneContacts = Annotated[
    int | None,
    typer.Option(
        "--tsne-contacts",
        min=0,
        show_default="600",
        help="Test contacts kept for the t-SNE.",
        rich_help_panel=_REPORT,
    ),
]
_Report = Annotated[
    bool,
    typer.Option(
        "--report/--no-report",
        help="Write metrics.json, report.md and figures.",
        rich_help_panel=_REPORT,
    ),
]

# the options that set a TrainConfig field, by flat TrainConfig key (``shape.`` for the model's)
_CONFIG_OPTIONS = {
    "split_seed": "split_seed",
    "learning_rate": "learning_rate",
    "batch_size": "batch_size",
    "dropout": "shape.dropout",
    "encoder_hidden": "shape.encoder_hidden",
    "latent_dim": "shape.latent_dim",
    "decoder_hidden": "shape.decoder_hidden",
    "align_weight": "shape.align_weight",
    "test_fraction": "test_fraction",
    "val_fraction": "val_fraction",
    "preprocessing": "preprocessing",
    "nmae_normaliser": "nmae_normaliser",
    "ssim_range": "ssim_range",
    "baselines": "baselines",
    "eval_every": "eval_every",
    "checkpoint_every": "checkpoint_every",
    "tsne_contacts": "tsne_contacts",
}


@dataclass(frozen=True)
class TrainRequest:
    """One ``train`` call as its options gave it (None: not given): where the data and the run are, how to run, and
    the TrainConfig keys it sets (``options``)."""

    data: list[Path]
    out: Path
    resume: bool = False
    config_file: Path | None = None
    partial: bool = False
    from_run: Path | None = None
    new_sensor: str | None = None
    epochs: int | None = None
    seed: int | None = None
    n_seeds: int | None = None
    device: str = "auto"
    threads: int = 0
    report: bool = True
    options: dict[str, Any] = field(default_factory=dict)  # flat TrainConfig key -> value given (or None)

    @classmethod
    def from_params(cls, params: dict[str, Any]) -> TrainRequest:
        """The request of a parsed command line (``typer.Context.params``)."""
        options = {key: params.get(name) for name, key in _CONFIG_OPTIONS.items()}
        own = {name: value for name, value in params.items() if name not in _CONFIG_OPTIONS}
        return cls(**own, options=options)

    @property
    def extends(self) -> bool:
        """``--from RUN --new-sensor NAME``: add a sensor to a trained run."""
        return self.from_run is not None or self.new_sensor is not None

    def check(self) -> None:
        """What this call can be refused for before torch is imported or the data read."""
        learning_rate = self.options.get("learning_rate")
        if learning_rate is not None and not learning_rate > 0:
            raise UsageError(f"--lr must be positive, got {learning_rate:g}")
        if not self.extends:
            choices = {k: self.options.get(k) for k in ("preprocessing", "nmae_normaliser", "ssim_range")}
            check_train_arguments(self.data, self.out, self.resume, self.device, self.config_file, choices)

    def train_config(self) -> Any:
        """The TrainConfig of a new run (defaults, then the --config file, then the options), or None to resume
        (which refuses every option but --epochs: the run keeps its stored configuration)."""
        from unitac_rig.learning.train import TrainConfig

        if self.resume:
            given = [_option_name(k) for k, v in self.options.items() if v is not None] + [
                name
                for name, v in (("--config", self.config_file), ("--seed", self.seed), ("--n-seeds", self.n_seeds))
                if v is not None
            ]
            if given:
                raise UsageError(
                    f"--resume continues a run with its stored configuration; drop {', '.join(sorted(given))}",
                    hint="only --epochs (to extend the budget) goes with --resume",
                )
            return None
        flat = training_overrides(self.config_file, self.options, self.seed, self.n_seeds)
        if self.epochs is not None:
            flat["epochs"] = self.epochs
        return TrainConfig().updated(flat)


def train_command(
    ctx: typer.Context,
    data: _Data,
    out: _Out,
    resume: _Resume = False,
    config_file: _ConfigFile = None,
    partial: _Partial = False,
    from_run: _FromRun = None,
    new_sensor: _NewSensor = None,
    epochs: _Epochs = None,
    seed: _Seed = None,
    n_seeds: _NSeeds = None,
    learning_rate: _LearningRate = None,
    batch_size: _BatchSize = None,
    device: _Device = "auto",
    threads: _Threads = 0,
    dropout: _Dropout = None,
    encoder_hidden: _EncoderHidden = None,
    latent_dim: _LatentDim = None,
    decoder_hidden: _DecoderHidden = None,
    align_weight: _AlignWeight = None,
    split_seed: _SplitSeed = None,
    test_fraction: _TestFraction = None,
    val_fraction: _ValFraction = None,
    preprocessing: _Preprocessing = None,
    nmae_normaliser: _NmaeNormaliser = None,
    ssim_range: _SsimRange = None,
    baselines: _Baselines = None,
    eval_every: _EvalEvery = None,
    checkpoint_every: _CheckpointEvery = None,
    tsne_contacts: _TsneContacts = None,
    report: _Report = True,
) -> None:
    """Train UniTac-NV (and the baselines) on paired data; writes RUN/checkpoint.pt, config.toml, metrics.json,
    report.md and figures."""
    request = TrainRequest.from_params(ctx.params)
    request.check()
    run_train(ctx, request)


def run_train(ctx: typer.Context, request: TrainRequest) -> None:
    """Run a checked request: a new or resumed run (then its report), or a sensor added to a trained run."""
    from rich.console import Console

    from unitac_rig.learning.report import write_report
    from unitac_rig.learning.train import load_run, resolve_device, train

    resolve_device(request.device)  # a bad --device fails before the data is read
    if request.extends:
        _train_new_sensor(ctx, request.data, request.out, request.from_run, request.new_sensor)
        return
    config = request.train_config()
    console = Console()
    dataset = _paired_dataset(request, console)
    total = request.epochs if config is None else config.epochs
    try:
        # Ctrl-C / SIGTERM wait for the end of the epoch (train() then checkpoints it); a second one stops at once
        with _progress(console, "[bold]train") as progress, termination_as_interrupt():
            task = progress.add_task("train", total=total, status="")
            outcome = train(
                dataset,
                request.out,
                config,
                device=request.device,
                threads=request.threads or None,
                resume=request.resume,
                epochs=request.epochs if request.resume else None,
                progress=_epoch_printer(console, progress, task, total),
            )
            progress.update(task, total=outcome.epochs_done)
    except KeyboardInterrupt:
        typer.echo(kept_run_line(request.out, request.data), err=True)
        raise
    console.print(f"trained {outcome.epochs_done} epochs in {outcome.train_seconds:.1f} s -> {request.out}")
    if request.report:
        try:
            path = write_report(request.out, run=load_run(request.out), on_stage=stage_printer(console))
        except KeyboardInterrupt:  # the run is trained and checkpointed: only its report is missing
            typer.echo(report_interrupted_line(request.out), err=True)
            raise
        _print_table(console, request.out)
        console.print(f"report: {path}")


def _paired_dataset(request: TrainRequest, console: Any) -> Any:
    """The paired dataset of --data, partial when asked or when the resumed run trained on a partial join."""
    from unitac_rig.learning.data import build_paired_dataset, load_sets
    from unitac_rig.learning.train import trained_on_partial_join

    partial = request.partial or (request.resume and trained_on_partial_join(request.out))
    console.print(f"reading the sessions in {', '.join(map(str, request.data))}...")
    sets = load_sets(request.data)
    dataset = build_paired_dataset(sets, partial=partial)
    console.print(
        f"paired dataset: {len(dataset)} contacts, sensors {', '.join(dataset.sensors)}, "
        f"objects {', '.join(dataset.objects)}"
    )
    for line in dropped_sessions(sets, dataset.objects):
        console.print(f"[yellow]left out:[/] {line}", soft_wrap=True)
    return dataset


def _progress(console: Any, label: str, *, log_lines: bool = True) -> Any:
    """A progress bar on a terminal; in a log (``log_lines``) none, the epoch printer writes a line now and then."""
    from rich.progress import BarColumn, Progress, TextColumn, TimeRemainingColumn

    return Progress(
        TextColumn(label),
        BarColumn(),
        TextColumn("epoch {task.completed}/{task.total}"),
        TextColumn("{task.fields[status]}"),
        TimeRemainingColumn(),
        console=console,
        disable=log_lines and not console.is_terminal,
    )


def _epoch_printer(console: Any, progress: Any, task: Any, total: int | None) -> Any:
    """The ``progress`` callback of ``train()``: the bar's status (the primary frame metric of the cross-sensor
    directions and the latent alignment), and a line every few seconds when the output is a log."""
    from unitac_rig.learning.metric_table import METRICS, frame_metrics

    primary, lines, pace = frame_metrics()[0], EveryFewSeconds(), Pace()

    def on_epoch(record: dict[str, Any]) -> None:
        pace.update(record["epoch"])
        status = ""
        scored = record.get("val") or record.get("test") or {}
        seen = scored.get("seen") or scored.get("all")
        if seen:
            crosses = [v[primary.name][0] for k, v in seen.items() if "_to_" in k]
            status = f"{'val' if 'val' in record else 'test'} {primary.label} {sum(crosses) / len(crosses):.4f}"
            if "latent_l1" in seen and "latent_l1" in METRICS:
                status += f", latent L1 {seen['latent_l1'][0]:.2f}"
            if "latent_ratio" in seen and "latent_ratio" in METRICS:
                status += f" (ratio {seen['latent_ratio'][0]:.2f})"
        progress.update(task, completed=record["epoch"], status=status)
        if not console.is_terminal and lines.due(last=record["epoch"] == total):
            left = pace.left_text(total) if total else ""  # at this run's pace (the bar shows its own)
            line = f"train: epoch {record['epoch']}/{total} {status}".rstrip() + (f", {left}" if left else "")
            console.print(line, soft_wrap=True)

    return on_epoch


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
