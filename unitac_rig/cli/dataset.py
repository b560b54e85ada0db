"""CLI: ``inspect`` (also ``--watch`` while a collection runs), ``export`` and ``verify``.

Tables are laid out for an 80-column terminal: short headers explained in a caption, no cell ever cut with an
ellipsis (long values fold onto a second line). The full numbers are in ``inspect --json``.
"""

from __future__ import annotations

import contextlib
import json
import math
import shlex
import time
from pathlib import Path
from typing import Any

import typer
from rich.console import Group, RenderableType
from rich.live import Live
from rich.table import Table
from rich.text import Text

from unitac_rig.cli.output import console
from unitac_rig.cli.paths import path_text, require_directory, require_empty_output
from unitac_rig.errors import DataError, UsageError
from unitac_rig.interrupts import raise_if_interrupted, termination_as_interrupt

_DATA_HINT = "pass the --data folder you collected into"


def _num(value: float | None, fmt: str, scale: float = 1.0) -> str:
    return "-" if value is None else format(value * scale, fmt)


def inspect_tables(report: dict[str, Any], data: Path) -> RenderableType:
    """The ``inspect`` tables: one row per session, then the cross-sensor join per object (fits 80 columns)."""
    sessions = report["sessions"]
    if not sessions:
        return Text(f"no sessions in {data} yet")
    table = Table(box=None, pad_edge=False)
    for name in ("object", "sensor", "presses", "targets", "|err| mN", "peak N", "time s"):
        table.add_column(name, justify="left" if name in ("object", "sensor") else "right", overflow="fold")
    for s in sessions:
        e, p = s["match_error_n"], s["peak_force_n"]
        sensor = s["sensor"] + ("*" if s["simulated"] else "") + (" ●" if s.get("writer") else "")
        table.add_row(
            s["object"],
            sensor,
            f"{s['presses_complete']}/{s['presses_failed']}/{s['presses_planned']}",
            f"{s['targets_matched']}/{s['targets_missed']}",
            "/".join(_num(e[k], ".0f", 1000.0) for k in ("median", "p95", "max")),
            "/".join(_num(p[k], ".1f") for k in ("median", "max")),
            f"{s['duration_s']:.0f}",
        )
    notes = [
        "presses: complete/failed/planned   targets: matched/missed   time: pressing",
        "|err|: force-matching error median/p95/max   peak: press force median/max",
    ]
    if any(s["simulated"] for s in sessions):
        notes.append("* simulated rig")
    rigs = sorted({s.get("rig", "") for s in sessions} - {""})
    if len(rigs) > 1:  # pairs join only within one rig: say which session is whose
        for rig in rigs:
            notes.append(
                f"{rig}: " + ", ".join(f"{s['object']}/{s['sensor']}" for s in sessions if s.get("rig") == rig)
            )
        notes.append("pairs join only within one rig: train and export one rig's --data at a time")
    elif rigs:
        notes.append(f"recorded on: {rigs[0]}")
    unverified = [s for s in sessions if s.get("integrity", "verified") != "verified"]
    notes.extend(f"{s['object']}/{s['sensor']}: {s['integrity']}" for s in unverified)
    notes.extend(_resume_note(data, s) for s in sessions if _unfinished(s) and not s.get("writer"))
    writers = [s for s in sessions if s.get("writer")]
    if writers:
        notes.append(
            "● being written now: "
            + ", ".join(f"{s['object']}/{s['sensor']} (pid {s['writer'].get('pid', '?')})" for s in writers)
        )
    pairs = Table(box=None, pad_edge=False)
    pairs.add_column("object", overflow="fold")
    pairs.add_column("pairs", justify="right")
    for obj_id, count in report["pairs"].items():
        pairs.add_row(obj_id, str(count))
    heading = Text("pairs joined across sensors on (rotation, angle, target)", style="italic")
    notes_text = Text("\n".join(notes), style="dim")
    return Group(Text(f"sessions in {data}", style="italic"), table, notes_text, Text(""), heading, pairs)


def _unfinished(session: dict[str, Any]) -> bool:
    """Fewer presses finished (complete or failed) than the session planned: an interrupted collection."""
    return session["presses_complete"] + session["presses_failed"] < session["presses_planned"]


def _resume_note(data: Path, session: dict[str, Any]) -> str:
    """``hex_tpu/uskin: incomplete (13 of 91 presses finished); resume: unitac-rig collect ...``: the command that
    plans the same presses again (the angle count it was collected with; the rig file when not simulated)."""
    from unitac_rig.storage.reader import read_session_info

    finished = session["presses_complete"] + session["presses_failed"]
    command = (
        f"unitac-rig collect --object {session['object']} --sensor {session['sensor']} --data {shlex.quote(str(data))}"
    )
    try:  # verified already by inspect in this process: only the attributes are read again
        attrs = read_session_info(data / session["file"]).attrs
        angles = attrs.get("config", {}).get("press", {}).get("angle_count")
        rotations = attrs.get("rotations_deg") or []
    except Exception:  # the file's damage is reported in its integrity note
        angles, rotations = None, []
    if angles is not None:
        command += f" --angles {angles}"
    if len(rotations) == 1 and len(_catalogue_rotations(session["object"])) != 1:  # collect --rotation R
        command += f" --rotation {float(rotations[0]):g}"
    if not session["simulated"]:
        command += " --rig RIG.toml"
    name, planned = f"{session['object']}/{session['sensor']}", session["presses_planned"]
    return f"{name}: incomplete ({finished} of {planned} presses finished); resume: {command}"


def _catalogue_rotations(object_id: str) -> tuple[float, ...]:
    """The rotations the catalogue sweeps ``object_id`` at (none known for an object from another file)."""
    from unitac_rig.rig.objects import get_object

    try:
        return tuple(get_object(object_id).rotations_deg)
    except UsageError:
        return ()


def _watch(data: Path, interval: float, as_json: bool) -> None:
    """Redraw every ``interval`` seconds until Ctrl-C. Reading never disturbs a running collection (see
    docs/dataset.md); a refresh that fails (directory not created yet) shows why and tries again."""
    from unitac_rig.storage.summary import inspect_dataset

    def frame() -> RenderableType:
        stamp = time.strftime("%H:%M:%S")
        try:
            report = inspect_dataset(data)
        except DataError as exc:
            if as_json:
                return Text(json.dumps({"time": stamp, "error": exc.one_line()}))
            return Text(f"{stamp}  {exc.one_line()} (retrying every {interval:g} s)")
        if as_json:
            return Text(json.dumps({"time": stamp, **report}))
        head = Text(f"{stamp}  refreshing every {interval:g} s, Ctrl-C to stop", style="bold")
        return Group(head, inspect_tables(report, data))

    with contextlib.suppress(KeyboardInterrupt), termination_as_interrupt(defer=False):  # read-only: raising at once
        if as_json or not console.is_terminal:  # a pipe or a log: one refresh after the other (JSON: one per line)
            while True:
                raise_if_interrupted()  # a Ctrl-C swallowed inside an HDF5 read ends the watch all the same
                rendered = frame()
                if as_json:
                    typer.echo(rendered.plain if isinstance(rendered, Text) else "")
                else:
                    console.print(rendered)
                    console.print()
                time.sleep(interval)
        with Live(frame(), console=console, auto_refresh=False) as live:
            while True:
                time.sleep(interval)
                raise_if_interrupted()
                live.update(frame(), refresh=True)


def inspect(
    data: Path = typer.Argument(..., help="Dataset directory.", parser=path_text),
    as_json: bool = typer.Option(False, "--json", help="Print one JSON object instead of tables."),
    watch: bool = typer.Option(
        False, "--watch", help="Refresh until Ctrl-C; safe while a collection writes the directory."
    ),
    interval: float = typer.Option(2.0, "--interval", help="Seconds between refreshes with --watch."),
) -> None:
    """Per session: presses, matched targets, matching error, peak force; per object: pairs joined across sensors."""
    from unitac_rig.storage.summary import inspect_dataset

    if watch:
        if not (math.isfinite(interval) and interval > 0):
            raise UsageError(f"--interval must be a positive number of seconds, got {interval:g}")
        if data.exists() and not data.is_dir():  # a folder not created yet is waited for
            require_directory(data, "DATA")
        _watch(data, interval, as_json)
        return
    require_directory(data, "DATA", hint=_DATA_HINT)
    report = inspect_dataset(data)
    if as_json:
        typer.echo(json.dumps(report, indent=1))
        return
    console.print(inspect_tables(report, data))


def export(
    data: list[Path] = typer.Argument(
        ..., help="Dataset directories to pool (each one a collect/campaign --data).", parser=path_text
    ),
    out: Path = typer.Option(
        ..., "--out", help="New directory to write the export into (must not hold files).", parser=path_text
    ),
    fmt: str = typer.Option(
        "parquet",
        "--format",
        help="parquet (the paired dataset), lerobot (every press, LeRobotDataset v3) or rosbag2 "
        "(each session as a ROS 2 bag, MCAP).",
    ),
) -> None:
    """Write the force-matched paired dataset as Parquet, the raw sessions, a dataset card and manifest.json
    (--format lerobot: one LeRobotDataset v3 per sensor, a press per episode, or rosbag2: a ROS 2 bag per session,
    see docs/share-your-data.md)."""
    if fmt not in ("parquet", "lerobot", "rosbag2"):
        raise UsageError(f"--format {fmt}: unknown export format", hint="use parquet, lerobot or rosbag2")
    for folder in data:
        require_directory(folder, "DATA", hint=_DATA_HINT)
    require_empty_output(out, "--out", "already exists and is not an empty directory", hint="choose a new --out")
    if fmt == "rosbag2":
        from unitac_rig.storage.rosbag import export_rosbag2

        bags = export_rosbag2(data, out)
        for name, topics in bags.bags.items():
            console.print(f"{out / name}: " + ", ".join(f"{t} {n}" for t, n in topics.items()), soft_wrap=True)
        console.print(f"{len(bags.bags)} bags (MCAP), {bags.bytes / 1e6:.1f} MB; open with ros2 bag info or Foxglove")
        return
    if fmt == "lerobot":
        from unitac_rig.storage.lerobot import export_lerobot

        robot = export_lerobot(data, out)
        for sensor, counts in robot.sensors.items():
            console.print(
                f"{sensor}: {counts['episodes']} presses, {counts['frames']} frames at {counts['fps']} fps -> "
                f"{robot.out / sensor}"
            )
        console.print(f"{robot.files} files, {robot.bytes / 1e6:.1f} MB from {robot.sessions} sessions")
    else:
        from unitac_rig.storage.export import export_dataset

        console.print(f"copying and pairing the sessions of {', '.join(map(str, data))} into {out}...", soft_wrap=True)
        summary = export_dataset(data, out)
        console.print(
            f"exported {summary.contacts} contacts x {len(summary.sensors)} sensors ({', '.join(summary.sensors)}) = "
            f"{summary.rows} rows from {summary.sessions} sessions, objects {', '.join(summary.objects)}"
        )
        if summary.incomplete:
            console.print(
                f"[yellow]incomplete sessions (presses finished/planned):[/] {', '.join(summary.incomplete)} "
                "(listed under incomplete_sessions in manifest.json)"
            )
        console.print(f"{summary.files} files, {summary.bytes / 1e6:.1f} MB -> {summary.out}")
    console.print(f"check a copy with: unitac-rig verify {out}")


def verify(
    directory: Path = typer.Argument(
        ..., metavar="DIR", help="An export directory (holds manifest.json).", parser=path_text
    ),
) -> None:
    """Check every file of an export against manifest.json (size and SHA-256); exit 1 at the first mismatch or at
    a file the manifest does not list."""
    from unitac_rig.storage.manifest import verify_manifest

    require_directory(directory, "DIR", hint="pass a directory written by `unitac-rig export`")
    report = verify_manifest(directory)
    console.print(f"ok: {report.files} files, {report.bytes / 1e6:.1f} MB match {directory / 'manifest.json'}")
