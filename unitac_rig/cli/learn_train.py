"""``unitac-rig train``: the command's options, and the thin layer that turns them into a :class:`TrainRequest` and
runs :func:`unitac_rig.learning.train.train` (or :func:`unitac_rig.learning.extend.add_sensor`) with a progress bar.

The options that set a training hyper-parameter are generated from the fields of
:mod:`unitac_rig.learning.config` (flag, help, default, range and validation all come from the field); the few
written here say where the data and the run are and how to run. Every value is checked before any work: a usage error
(exit 2) names the option as typed, or the key of the --config file.
"""

from __future__ import annotations

import inspect
import typing
from dataclasses import dataclass, field
from pathlib import Path
from typing import Annotated, Any

import typer
from pydantic import ValidationError
from pydantic.fields import FieldInfo

from unitac_rig.cli.help import field_bounds, field_flag
from unitac_rig.cli.learn import DEVICES, RUN_MARKER, kept_run_line, report_with_table
from unitac_rig.cli.output import EveryFewSeconds, Pace, console
from unitac_rig.cli.paths import require_empty_output
from unitac_rig.errors import UsageError
from unitac_rig.interrupts import termination_as_interrupt
from unitac_rig.learning import config as train_config
from unitac_rig.rig.config import read_toml

# Help headings of `train` (the options are many: grouped, as git groups its own), and of each config section's.
_RUN = "Data and run"
_TRAINING = "Training"
_MODEL = "Model (the paper's shape by default)"
_SPLIT = "Split, preprocessing and metrics"
_REPORT = "Evaluation and report"
_SEEDS = train_config.TrainingSection.model_fields["seeds"].default  # --seed and --n-seeds start from these
_PANELS = dict(model=_MODEL, training=_TRAINING, split=_SPLIT, preprocessing=_SPLIT, metrics=_SPLIT, evaluation=_REPORT)


@dataclass(frozen=True)
class ConfigOption:
    """One ``train`` option generated from a field of the training configuration."""

    section: str  # of the config file
    key: str  # in that section
    flag: str  # as typed: --lr, --baselines/--no-baselines
    info: FieldInfo

    @property
    def name(self) -> str:
        """The command's parameter: the flat TrainConfig key without ``shape.`` (learning_rate, latent_dim)."""
        return train_config.flat_key(self.section, self.key).removeprefix("shape.")

    def typed(self, value: Any) -> str:
        """The option as it was typed (``--test-fraction 1.5``, ``--no-baselines``)."""
        if isinstance(value, bool):
            on, _, off = self.flag.partition("/")
            return on if value or not off else off
        return f"{self.flag} {value}"

    def parameter(self) -> inspect.Parameter:
        """The typer parameter: None unless given, help, default and range from the field."""
        info = self.info
        choices = typing.get_args(info.annotation) if typing.get_origin(info.annotation) is typing.Literal else ()
        bounds = field_bounds(info)
        default = info.default
        paper = isinstance(info.json_schema_extra, dict) and info.json_schema_extra.get("paper")
        if isinstance(default, bool):
            kind: Any = bool
            shown = self.typed(default)
        elif isinstance(default, tuple):  # layer widths
            kind, shown = str, ",".join(map(str, default))
        else:
            kind = str if choices else type(default)
            shown = f"{default:g}" if isinstance(default, float) else str(default)
        help_text = info.description or ""
        if choices:
            help_text += f" One of: {', '.join(choices)}."
        open_bounds = [f"above {bounds['gt']:g}"] if "gt" in bounds else []
        open_bounds += [f"below {bounds['lt']:g}"] if "lt" in bounds else []
        if open_bounds:
            help_text = f"{help_text.rstrip('.')} ({', '.join(open_bounds)})."
        option = typer.Option(
            *self.flag.split(" "),
            metavar="W,W" if isinstance(default, tuple) else ("NAME" if choices else None),
            min=bounds.get("ge"),
            max=bounds.get("le"),
            show_default=shown + (", as in the paper" if paper else ""),
            help=help_text,
            rich_help_panel=_PANELS[self.section],
        )
        return inspect.Parameter(
            self.name, inspect.Parameter.KEYWORD_ONLY, default=None, annotation=Annotated[kind | None, option]
        )


def config_options() -> dict[str, ConfigOption]:
    """Every field of the training configuration that is a ``train`` option, by parameter name."""
    options = {}
    for (section, key), info in train_config.fields().items():
        name = train_config.flat_key(section, key).removeprefix("shape.")
        flag = field_flag(name, info)
        if flag is not None:
            options[name] = ConfigOption(section, key, flag, info)
    return options


@dataclass(frozen=True)
class TrainRequest:
    """One ``train`` call as its options gave it (None: not given): where the data and the run are, how to run, and
    the options that set a training hyper-parameter (``options``, by parameter name)."""

    data: list[Path]
    out: Path
    resume: bool = False
    config_file: Path | None = None
    partial: bool = False
    from_run: Path | None = None
    new_sensor: str | None = None
    seed: int | None = None
    n_seeds: int | None = None
    device: str = "auto"
    threads: int = 0
    report: bool = True
    options: dict[str, Any] = field(default_factory=dict)

    @classmethod
    def from_params(cls, params: dict[str, Any]) -> TrainRequest:
        """The request of a parsed command line (``typer.Context.params``)."""
        generated = config_options()
        options = {name: params.get(name) for name in generated}
        own = {name: value for name, value in params.items() if name not in generated}
        return cls(**own, options=options)

    @property
    def extends(self) -> bool:
        """``--from RUN --new-sensor NAME``: add a sensor to a trained run."""
        return self.from_run is not None or self.new_sensor is not None

    @property
    def epochs(self) -> int | None:
        return self.options.get("epochs")

    def check(self) -> None:
        """What this call can be refused for before torch is imported or the data read (importing torch alone takes
        seconds on a loaded box): a usage error naming the option."""
        if self.device not in DEVICES:
            raise UsageError(f"--device {self.device!r} is not a device", hint=f"use one of: {', '.join(DEVICES)}")
        if self.extends or self.resume:  # only the options given are checked (the run keeps its configuration)
            self.settings(with_file=False)
            return
        for directory in self.data:
            if not directory.is_dir():
                raise UsageError(
                    f"--data {directory} is not a directory", hint="pass the --data folder `collect` wrote"
                )
        if self.config_file is not None and not self.config_file.is_file():
            raise UsageError(f"--config {self.config_file} does not exist")
        if (self.out / RUN_MARKER).exists():
            hint = "pass --resume to continue it, or choose another --out"
            raise UsageError(f"--out {self.out} already holds a run", hint=hint)
        hint = "a run writes a folder of its own: choose a new --out"  # /proc/x, a read-only disk: refused before
        require_empty_output(self.out, "--out", "is not empty and holds no run", hint=hint)  # minutes of training
        self.settings()

    def refuse_options(self, allowed: set[str], refusal: str, hint: str) -> None:
        """A usage error ``refusal; drop --x, --y`` when options outside ``allowed`` (parameter names) were given."""
        generated = config_options()
        given = {name: generated[name].typed(v).split(" ")[0] for name, v in self.options.items() if v is not None}
        own = {"resume": "--resume", "partial": "--partial", "config_file": "--config", "seed": "--seed"}
        for name, flag in (own | {"n_seeds": "--n-seeds"}).items():
            if getattr(self, name) is not None and getattr(self, name) is not False:  # given (0 is a --seed)
                given[name] = flag
        dropped = sorted(flag for name, flag in given.items() if name not in allowed)
        if dropped:
            raise UsageError(f"{refusal}; drop {', '.join(dropped)}", hint=hint)

    def settings(self, *, with_file: bool = True) -> train_config.ConfigFile:
        """The complete configuration this call asks for: the defaults, then the --config file's keys, then the
        options given. A bad value is a usage error naming the option as typed (or the file's key)."""
        sections: dict[str, dict[str, Any]] = {}
        if with_file and self.config_file is not None:
            data = read_toml(self.config_file, "config file")
            train_config.parse_config(data, source=str(self.config_file))  # the file alone names its bad key
            sections = {name: dict(values) for name, values in data.items()}
        generated = config_options()
        given = {}
        for name, value in self.options.items():
            if value is not None:
                option = generated[name]
                sections.setdefault(option.section, {})[option.key] = value
                given[option.section, option.key] = option.typed(value)
        if self.seed is not None or self.n_seeds is not None:
            first = self.seed if self.seed is not None else int(sections.get("training", {}).get("seeds", _SEEDS)[0])
            sections.setdefault("training", {})["seeds"] = list(range(first, first + (self.n_seeds or 1)))
            given["training", "seeds"] = f"--seed {first} --n-seeds {self.n_seeds or 1}"
        try:
            return train_config.validate(sections)
        except ValidationError as exc:
            error = exc.errors()[0]
            where = tuple(str(part) for part in error["loc"][:2])
            message = str(error["msg"]).removeprefix("Value error, ").replace("Input should be", "should be")
            if where in given:
                raise UsageError(f"{given[where]}: {message}") from None
            raise UsageError(f"{self.config_file}: {'.'.join(where)}: {message}") from None

    def train_config(self) -> Any:
        """The TrainConfig of a new run (defaults, then the --config file, then the options), or None to resume
        (which refuses every option but --epochs: the run keeps its stored configuration)."""
        from unitac_rig.learning.train import TrainConfig

        if self.resume:
            self.refuse_options(
                {"resume", "partial", "epochs"},
                "--resume continues a run with its stored configuration",
                hint="only --epochs (to extend the budget) goes with --resume",
            )
            return None
        settings = self.settings()
        flat = {
            train_config.flat_key(section, key): getattr(getattr(settings, section), key)
            for section, key in train_config.fields()
        }
        return TrainConfig().updated(flat)


def _train(
    ctx: typer.Context,
    data: list[Path] = typer.Option(
        ...,
        "--data",
        metavar="DIR",
        help="Directory of session files (collect, campaign or import output); repeat to pool several.",
        rich_help_panel=_RUN,
    ),
    out: Path = typer.Option(
        ..., "--out", metavar="RUN", help="New run directory (or the run to --resume).", rich_help_panel=_RUN
    ),
    resume: bool = typer.Option(
        False, "--resume", help="Continue the run in --out from its last checkpoint.", rich_help_panel=_RUN
    ),
    config_file: Path | None = typer.Option(
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
    from_run: Path | None = typer.Option(
        None,
        "--from",
        metavar="RUN",
        help="A trained run to add --new-sensor to (it is not modified).",
        rich_help_panel=_RUN,
    ),
    new_sensor: str | None = typer.Option(
        None,
        "--new-sensor",
        metavar="SENSOR",
        help="With --from: train only this sensor's encoder and output layer (docs/learning.md).",
        rich_help_panel=_RUN,
    ),
    seed: int | None = typer.Option(
        None,
        "--seed",
        show_default=str(_SEEDS[0]),
        help="Seed of the first model (initialisation, shuffling, dropout).",
        rich_help_panel=_TRAINING,
    ),
    n_seeds: int | None = typer.Option(
        None,
        "--n-seeds",
        min=1,
        show_default=str(len(_SEEDS)),
        help="Train seeds SEED..SEED+N-1 together in one batched run.",
        rich_help_panel=_TRAINING,
    ),
    device: str = typer.Option(
        "auto", "--device", metavar="NAME", help="auto, cpu or cuda.", rich_help_panel=_TRAINING
    ),
    threads: int = typer.Option(
        0, "--threads", min=0, help="CPU threads (0: one, fastest for these small layers).", rich_help_panel=_TRAINING
    ),
    report: bool = typer.Option(
        True, "--report/--no-report", help="Write metrics.json, report.md and figures.", rich_help_panel=_REPORT
    ),
    **options: Any,
) -> None:
    """Train UniTac-NV (and the baselines) on paired data; writes RUN/checkpoint.pt, config.toml, metrics.json,
    report.md and figures."""
    request = TrainRequest.from_params(ctx.params)
    request.check()
    run_train(request)


def build_train_command() -> Any:
    """``train`` as typer reads it: the options written above, then one per training configuration field."""

    def train_command(ctx: typer.Context, **params: Any) -> None:
        _train(ctx, **params)

    own = [p for p in inspect.signature(_train).parameters.values() if p.kind != p.VAR_KEYWORD]
    own = own[:1] + [p.replace(kind=p.KEYWORD_ONLY) for p in own[1:]]
    generated = [option.parameter() for option in config_options().values()]
    ordered = own[:-1] + generated + own[-1:]  # --report last, after the evaluation options
    train_command.__signature__ = inspect.Signature(ordered)  # type: ignore[attr-defined]
    train_command.__annotations__ = {p.name: p.annotation for p in ordered}
    train_command.__doc__ = _train.__doc__
    return train_command


train_command = build_train_command()


def run_train(request: TrainRequest) -> None:
    """Run a checked request: a new or resumed run (then its report), or a sensor added to a trained run."""
    from unitac_rig.learning.train import load_run, resolve_device, train

    resolve_device(request.device)  # a bad --device fails before the data is read
    if request.extends:
        _train_new_sensor(request)
        return
    config = request.train_config()
    dataset = _paired_dataset(request, config)
    total = request.epochs if config is None else config.epochs
    try:
        # Ctrl-C / SIGTERM wait for the end of the epoch (train() then checkpoints it); a second one stops at once
        with _progress("[bold]train") as progress, termination_as_interrupt():
            task = progress.add_task("train", total=total, status="")
            outcome = train(
                dataset,
                request.out,
                config,
                device=request.device,
                threads=request.threads or None,
                resume=request.resume,
                epochs=request.epochs if request.resume else None,
                progress=_epoch_printer(progress, task, total),
            )
            progress.update(task, total=outcome.epochs_done)
    except KeyboardInterrupt:
        typer.echo(kept_run_line(request.out, request.data), err=True)
        raise
    console.print(f"trained {outcome.epochs_done} epochs in {outcome.train_seconds:.1f} s -> {request.out}")
    if request.report:
        report_with_table(request.out, run=load_run(request.out))


def _paired_dataset(request: TrainRequest, config: Any) -> Any:
    """The paired dataset of --data, partial when asked or when the resumed run trained on a partial join, its
    frames referenced as the run asks (``config``; None: as the resumed run did)."""
    from unitac_rig.learning.data import build_paired_dataset, load_sets
    from unitac_rig.learning.train import stored_frame_baseline, trained_on_partial_join

    partial = request.partial or (request.resume and trained_on_partial_join(request.out))
    baseline = config.frame_baseline if config is not None else stored_frame_baseline(request.out)
    console.print(f"reading the sessions in {', '.join(map(str, request.data))}...")
    sets = load_sets(request.data, baseline)
    dataset = build_paired_dataset(sets, partial=partial)
    console.print(
        f"paired dataset: {len(dataset)} contacts, sensors {', '.join(dataset.sensors)}, "
        f"objects {', '.join(dataset.objects)}"
    )
    for line in dropped_sessions(sets, dataset.objects):
        console.print(f"[yellow]left out:[/] {line}", soft_wrap=True)
    return dataset


def _progress(label: str, *, log_lines: bool = True) -> Any:
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


def _epoch_printer(progress: Any, task: Any, total: int | None) -> Any:
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
            left = pace.left_text(total - record["epoch"]) if total else ""  # at this run's pace
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


def _train_new_sensor(request: TrainRequest) -> None:
    """``train --from RUN --new-sensor NAME``: the new sensor's encoder and output layer against the frozen model."""
    from rich.table import Table

    from unitac_rig.learning.data import load_sets
    from unitac_rig.learning.extend import EXTENSION_JSON, ExtendConfig, add_sensor
    from unitac_rig.learning.train import stored_frame_baseline

    from_run, new_sensor, out = request.from_run, request.new_sensor, request.out
    if from_run is None or not new_sensor:
        raise UsageError("--from and --new-sensor go together", hint="train --from RUN --new-sensor NAME --data DATA")
    request.refuse_options(
        {"epochs", "learning_rate", "batch_size"},
        "--new-sensor keeps the trained run's settings",
        hint="only --epochs, --lr, --batch-size, --device and --threads go with --new-sensor",
    )
    sets = load_sets(request.data, stored_frame_baseline(from_run))  # the new sensor's frames as the run's were read
    with _progress(f"[bold]train {new_sensor}", log_lines=False) as progress:
        task = progress.add_task("extend", total=None, status="")

        def on_epoch(record: dict[str, Any]) -> None:
            loss = sum(record["train_loss"]) / len(record["train_loss"])
            progress.update(task, completed=record["epoch"], total=record["epochs"], status=f"train loss {loss:.4f}")

        settings = {name: request.options.get(name) for name in ("epochs", "batch_size", "learning_rate")}
        outcome = add_sensor(
            from_run,
            sets,
            new_sensor,
            out,
            ExtendConfig(**settings),
            device=request.device,
            threads=request.threads or None,
            progress=on_epoch,
        )
    summary, contacts = outcome.summary, outcome.summary["contacts"]
    shared = ", ".join(f"{s} {n}" for s, n in contacts["train_shared_with"].items())
    console.print(
        f"trained {new_sensor} into {from_run} -> {out}: {contacts['train']} training contacts (shared with {shared}), "
        f"{contacts['test']} test contacts, {summary['settings']['epochs']} epochs in {summary['train_seconds']:.1f} s"
    )
    table = Table(title=f"Test NMAE/SSIM of {new_sensor}'s directions (untrained layers -> trained)", box=None)
    for column in ("direction", "contacts", "untrained", "trained"):
        table.add_column(column, justify="right", overflow="fold")

    def scores(entry: dict[str, list[float]]) -> str:
        return f"{sum(entry['nmae']) / len(entry['nmae']):.3f}/{sum(entry['ssim']) / len(entry['ssim']):.3f}"

    for name, after in summary["trained"].items():
        table.add_row(
            name.replace("_to_", "→"), str(after["contacts"]), scores(summary["untrained"][name]), scores(after)
        )
    console.print(table)
    console.print(f"{out / EXTENSION_JSON}")
    if request.report and outcome.complete_test_rows:
        report_with_table(out)
    elif request.report:
        console.print("no test contact was recorded by every sensor: no report.md (see extension.json)")
