"""Learning commands: ``report``, ``translate``, ``geometry`` and ``export-model`` (``train``, with its option per
hyper-parameter, is :mod:`unitac_rig.cli.learn_train`), and the Table I printer they share with ``train``.
"""

from __future__ import annotations

import shlex
from pathlib import Path
from typing import Any

import typer

from unitac_rig.cli.output import console
from unitac_rig.errors import UsageError

# What the checks before the heavy imports compare with (tests keep them equal to the library's own tables).
RUN_MARKER = "checkpoint.pt"  # learning.run.CHECKPOINT_NAME: a folder holding it is a trained run
DEVICES = ("auto", "cpu", "cuda")
RUN_ARGUMENT = typer.Argument(..., metavar="RUN", help="Run directory.")


def kept_run_line(run: Path, data: list[Path]) -> str:
    """What an interrupted ``train`` kept (its checkpoint's epoch, read back from disk) and the command that goes
    on from there."""
    from unitac_rig.learning.run import checkpoint_path, load_checkpoint

    if not checkpoint_path(run).is_file():
        return "train: interrupted before the first checkpoint, nothing kept; run the same command to start again"
    payload = load_checkpoint(run)
    planned = payload.get("config", {}).get("epochs", "?")
    data_options = " ".join(f"--data {shlex.quote(str(d))}" for d in data)
    command = f"unitac-rig train {data_options} --out {shlex.quote(str(run))} --resume"
    return f"train: interrupted; kept epoch {payload.get('epoch', '?')}/{planned} in {run}; go on with: {command}"


def report_with_table(run_dir: Path, **options: Any) -> None:
    """Write the report of the run in ``run_dir`` (a line per stage: the t-SNE alone can take a minute or two), then
    print its Table I and where the report is. Interrupted, it says what it kept: the run as it was (metrics.json and
    report.md are written together at the end), and the command that writes them."""
    from unitac_rig.learning.report import write_report

    def on_stage(message: str) -> None:
        console.print(f"report: {message}...", highlight=False, soft_wrap=True)

    try:
        path = write_report(run_dir, on_stage=on_stage, **options)
    except KeyboardInterrupt:
        typer.echo(
            f"report: interrupted; {run_dir}/metrics.json and report.md are as they were; "
            f"write them with: unitac-rig report {shlex.quote(str(run_dir))}",
            err=True,
        )
        raise
    _print_table(console, run_dir)
    console.print(f"report: {path}")


def report_command(
    run: Path = RUN_ARGUMENT,
    figures: bool = typer.Option(True, "--figures/--no-figures", help="Redraw the figures too."),
    nmae_normaliser: str = typer.Option(
        None, "--nmae-normaliser", metavar="NAME", show_default="the run's", help="Score under another NMAE normaliser."
    ),
    ssim_range: str = typer.Option(
        None, "--ssim-range", metavar="NAME", show_default="the run's", help="Score under another SSIM range."
    ),
) -> None:
    """Recompute RUN/metrics.json and rewrite RUN/report.md (and its figures)."""
    require_run(run)
    report_with_table(run, figures=figures, nmae_normaliser=nmae_normaliser, ssim_range=ssim_range)


def _short_sensor_names(sensors: list[str]) -> dict[str, str]:
    """Each sensor's shortest prefix that no other sensor shares (uskin -> u, papillarray -> p), for table headers."""
    short = {}
    for name in sensors:
        others = [o for o in sensors if o != name]
        short[name] = next(
            (name[:k] for k in range(1, len(name)) if not any(o.startswith(name[:k]) for o in others)), name
        )
    return short


def _print_table(console: Any, run: Path) -> None:
    """Table I for the terminal: short headers with a legend, and the columns split over as many tables as the
    terminal's width needs, so no cell is ever cut (the full table is in RUN/report.md and RUN/metrics.json)."""
    import json

    from rich.measure import Measurement
    from rich.table import Table

    from unitac_rig.learning.metric_table import frame_metrics
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

    def cell(values: Any) -> str:
        return "–" if values is None else "/".join(f"{v:.3f}" for v in values)

    def ours(value: Any) -> Any:  # every frame metric of the table the run scored, in the table's order
        return None if value is None else [value[m.name] for m in frame_metrics() if m.name in value]

    def build(chunk: list[str]) -> Table:
        table = Table(box=None, pad_edge=False)
        table.add_column("row", overflow="fold")
        for column in chunk:
            table.add_column(header(column), justify="right", overflow="fold")
        for row, cells in rows.items():
            table.add_row(row, *(cell(ours(cells.get(c))) for c in chunk))
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
    labels = "/".join(m.label for m in frame_metrics())
    console.print(f"Test {labels} (the paper's values dim below its rows)", style="bold")
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
    aligned = metrics.get("alignment", {}).get("per_subset", {}).get("all")
    if aligned:  # per member, after epoch 1 and at the end: the means over members

        def mean(values: Any) -> str:
            return "–" if not values else f"{sum(values) / len(values):.3f}"

        def change(name: str) -> str:
            entry = aligned.get(name) or {}
            return f"{mean(entry.get('first_epoch'))} -> {mean(entry.get('final'))}"

        perfect = mean((aligned.get("mixing_expected") or {}).get("final"))
        console.print(
            f"latent L1 between matched contacts: {change('latent_l1')}; matched/unmatched {change('latent_ratio')}; "
            f"sensor mixing {change('mixing')} (perfect {perfect})"
        )


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


def require_run(run: Path) -> None:
    """A cheap check before torch is imported (the same words as :func:`unitac_rig.learning.run.load_checkpoint`)."""
    if not (run / RUN_MARKER).is_file():
        raise UsageError(f"{run} is not a training run (no {RUN_MARKER})", hint="run `unitac-rig train` first")


def translate_command(
    run: Path = RUN_ARGUMENT,
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
    require_run(run)
    source = _sensor_of(input_path, source, "--from")
    out = _output_beside_run(run, "translations", f"{input_path.stem}_to_{target}.npz", out)
    from unitac_rig.learning.translate import translate_file

    summary = translate_file(run, source, target, input_path, out)
    console.print(
        f"translated {summary['frames']} frames {source} {tuple(summary['input_shape'][1:])} -> "
        f"{target} {tuple(summary['output_shape'][1:])}: {summary['output']}"
    )
    mean = ", ".join(f"{v:.3g}" for v in summary["mean_abs_per_channel"])
    console.print(f"mean |value| per channel (x, y, z): {mean}")
    latency = summary["latency_ms"]
    console.print(f"single-frame latency: median {latency['median_ms']:.3f} ms, p90 {latency['p90_ms']:.3f} ms (CPU)")


def geometry_command(
    run: Path = RUN_ARGUMENT,
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
    require_run(run)
    if predict is not None:
        sensor = _sensor_of(predict, sensor, "--sensor")
        out = _output_beside_run(run, "geometry", f"{predict.stem}_geometry.npz", out)
    from rich.table import Table

    from unitac_rig.learning.contact_geometry import ESTIMATOR_PT, GeometryConfig, geometry_for_run, predict_file
    from unitac_rig.learning.report import write_report

    if predict is not None:
        _print_prediction(*predict_file(run, predict, sensor, trained_on, out), sensor)
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


def _print_prediction(prediction: Any, path: Path, sensor: str) -> None:
    """``geometry --predict``'s output: the first few predicted profiles as a table, and where all of them went."""
    from rich.table import Table

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


def export_model_command(
    run: Path = RUN_ARGUMENT,
    fmt: str = typer.Option(
        "safetensors",
        "--format",
        help="safetensors (model.safetensors + config.json), torchscript, onnx or state-dict.",
    ),
    out: Path = typer.Option(..., "--out", help="New directory for the networks, config/model.json and README.md."),
    member: int = typer.Option(0, "--member", help="Which seed of a multi-seed run (index)."),
    push_to_hub: str | None = typer.Option(
        None, "--push-to-hub", metavar="REPO", help="Then upload it to this Hugging Face Hub model repo (safetensors)."
    ),
) -> None:
    """Write each sensor's encoder and decoder (normaliser folded in: sensor units in and out) with a model card."""
    from unitac_rig.learning.export import CARD_NAME, CONFIG_NAME, MODEL_JSON, export_model

    if push_to_hub is not None and fmt != "safetensors":
        raise UsageError("--push-to-hub uploads the Hub layout only", hint="drop --format or use --format safetensors")
    document = export_model(run, out, fmt, member)
    console.print(f"exported {run} (member {member}, seed {document['seed']}) as {fmt} -> {out}")
    for sensor, entry in document["sensors"].items():
        console.print(
            f"  {sensor}: ({entry['n_taxels']}, 3) {entry['units']} <-> latent {document['latent_dim']}: "
            f"{entry['encoder']}, {entry['decoder']}"
        )
    config = CONFIG_NAME if fmt == "safetensors" else MODEL_JSON
    console.print(f"  {config}, {CARD_NAME} (model card: data hash, metrics, intended use, limits, loading)")
    if push_to_hub is not None:
        from unitac_rig.learning.export import push_to_hub as push

        console.print(f"pushed to https://huggingface.co/{push_to_hub}: {push(out, push_to_hub)}")
