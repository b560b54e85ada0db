"""``unitac-rig bench press|recorder|inference``: what a user runs to judge a rig and its host (unitac_rig/bench).

Each prints a summary and writes ``OUT/bench_<name>.json`` and ``OUT/bench_<name>.png`` (OUT defaults to the
checkout's docs/figures, else ./bench-out). ``--quick`` is a smoke run of well under a minute.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from pathlib import Path
from typing import Any

import typer

bench_app = typer.Typer(
    help="Benchmarks: press strategy vs matching error, recorder vs stream rates, inference vs the 1 ms budget.",
    no_args_is_help=True,
)

_QUICK = typer.Option(False, "--quick", help="Smoke run (well under a minute).")
_OUT = typer.Option(None, "--out", help="Folder for the JSON and PNG (default: docs/figures of this checkout).")


def _finish(
    doc: dict[str, Any], plot: Callable[..., Path], summary: Callable[..., list[str]], out: Path | None
) -> None:
    """Write ``OUT/bench_<name>.json`` and ``.png`` for a benchmark's result, then print its summary."""
    from unitac_rig.bench import default_out_dir, write_json

    folder = default_out_dir() if out is None else out
    name = doc["benchmark"]
    json_path = write_json(doc, folder / f"bench_{name}.json")
    png_path = plot(doc, folder / f"bench_{name}.png")
    for line in summary(doc):
        typer.echo(line)
    typer.echo(f"wrote {json_path} and {png_path}")


@bench_app.command("press")
def press_command(
    quick: bool = _QUICK,
    out: Path | None = _OUT,
    jobs: int = typer.Option(os.cpu_count() or 1, "--jobs", help="Processes pressing in parallel."),
) -> None:
    """Press strategies and speeds on the simulated rig: campaign time against force-matching error."""
    from rich.progress import Progress

    from unitac_rig.bench import press_benchmark as press

    with Progress(transient=True) as progress:
        task = progress.add_task("rig sessions", total=None)

        def on_cell(done: int, total: int) -> None:
            progress.update(task, completed=done, total=total)

        doc = press.run_press_benchmark(press.quick_plan() if quick else press.full_plan(), max(1, jobs), on_cell)
    _finish(doc, press.plot_press_benchmark, press.summary_lines, out)


@bench_app.command("recorder")
def recorder_command(
    quick: bool = _QUICK,
    out: Path | None = _OUT,
    work_dir: Path | None = typer.Option(
        None, "--work-dir", help="Where to write the test sessions (default: a temporary folder, removed after)."
    ),
) -> None:
    """Recorder write rate and the live PapillArray path against the hardware's stream rates."""
    from unitac_rig.bench import recorder

    doc = recorder.run_recorder_benchmark(recorder.quick_plan() if quick else recorder.full_plan(), work_dir)
    _finish(doc, recorder.plot_recorder_benchmark, recorder.summary_lines, out)


@bench_app.command("inference")
def inference_command(
    quick: bool = _QUICK,
    out: Path | None = _OUT,
    run: Path | None = typer.Option(None, "--run", help="A trained run (default: train a tiny one on synthetic data)."),
) -> None:
    """Encode / decode / translate latency against the 1 ms a 1000 Hz stream leaves."""
    from unitac_rig.bench import inference
    from unitac_rig.cli.learn import require_run

    if run is not None:
        require_run(run)
    doc = inference.run_inference_benchmark(inference.quick_plan() if quick else inference.full_plan(), run)
    _finish(doc, inference.plot_inference_benchmark, inference.summary_lines, out)
