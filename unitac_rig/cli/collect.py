"""CLI: ``collect``, ``campaign``, ``extract`` and ``objects`` (``inspect`` is in cli/dataset.py)."""

from __future__ import annotations

import contextlib
import dataclasses
import time
from collections.abc import Mapping
from pathlib import Path

import numpy as np
import typer
from pydantic import ValidationError
from rich.console import Group
from rich.live import Live
from rich.markup import escape
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeRemainingColumn
from rich.table import Table
from rich.text import Text

from unitac_rig.cli.output import EveryFewSeconds, Pace, console, spoken_duration
from unitac_rig.cli.paths import path_text, require_data_folder, require_directory
from unitac_rig.collection.safety_check import TickInfo
from unitac_rig.collection.sensor_choice import choose_sensor, collection_order, session_complete, session_presses
from unitac_rig.collection.session import PressDone, SessionOutcome, collect_session, dry_run
from unitac_rig.collection.transit import PressPlan
from unitac_rig.errors import ConfigError, SessionStopped, UsageError
from unitac_rig.interrupts import immediate_interrupts, termination_as_interrupt
from unitac_rig.rig.backends import open_rig
from unitac_rig.rig.base import Rig
from unitac_rig.rig.config import RigConfig, load_rig_config, parse_rig_config, spoken
from unitac_rig.rig.objects import ObjectSpec, get_object, list_objects
from unitac_rig.rig.sensors import sensor_layout, sensor_names
from unitac_rig.rig.strategies import PRESS_STRATEGIES
from unitac_rig.sim.imperfections import Imperfections
from unitac_rig.storage.extraction import ExtractionSettings
from unitac_rig.storage.reader import list_sessions
from unitac_rig.storage.recorder import session_path
from unitac_rig.storage.reextract import reextract_sessions

DATA_OPTION = typer.Option(
    Path("data"),
    "--data",
    metavar="DIR",
    help="Dataset directory (one HDF5 file per object and sensor).",
    parser=path_text,
)
RIG_OPTION = typer.Option(
    None, "--rig", metavar="FILE", help="Rig file (TOML). Without one, the simulated rig is used."
)
IMPERFECTIONS_OPTION = typer.Option(
    "all",
    "--imperfections",
    metavar="LIST",
    help="Simulated rig: which real-sensor imperfections it has: all, none (the clean twin), all,-creep, or names "
    f"from {', '.join(f.name for f in dataclasses.fields(Imperfections))}.",
)
_PRESS = RigConfig().press  # the rig file's defaults, for the help of the options that override them
ANGLES_OPTION = typer.Option(
    None, "--angles", show_default=f"the rig file's, else {_PRESS.angle_count}", help="Approach angles per sweep."
)
LIVE_OPTION = typer.Option(True, "--live/--no-live", help="Show the live panel.")


# rig-file field -> the command-line option that overrides it (an error in an override names the option typed)
OVERRIDE_OPTIONS = {
    "press.strategy": "--strategy",
    "press.speed_mm_s": "--speed",
    "press.angle_count": "--angles",
}


def _say_if_simulated(config: RigConfig, rig_file: Path | None, what: str) -> None:
    """The banner of a simulated rig, saying why (no rig file, or a rig file without an [arm] table)."""
    if config.simulated:
        why = "no rig file given" if rig_file is None else escape(f"rig file {rig_file} has no [arm]")  # rich markup
        console.print(f"[bold yellow]SIMULATED RIG[/] ({why}): {what}")


def _check_counts(seed: int, max_presses: int | None = None) -> None:
    """A negative seed or press count is a usage error naming the option (numpy refuses negative seeds deep inside
    the rig; a negative --max-presses sliced the plan from the end)."""
    for flag, value, lowest in (("--seed", seed, 0), ("--max-presses", max_presses, 1)):
        if value is not None and value < lowest:
            raise UsageError(f"{flag} must be {lowest} or more, got {value}")


def _configure(
    rig_file: Path | None, strategy: str | None = None, speed: float | None = None, angles: int | None = None
) -> RigConfig:
    """The rig file with the options typed on top (``OVERRIDE_OPTIONS``), validated as one rig file."""
    config = load_rig_config(rig_file)
    if angles is not None and not 1 <= angles <= config.press.max_angle_count():
        raise UsageError(
            f"--angles must be 1 to {config.press.max_angle_count()}, got {angles}",
            hint="press ids are whole degrees: more angles than degrees in the arc would repeat presses",
        )
    typed = dict(zip(OVERRIDE_OPTIONS, (strategy, speed, angles), strict=True))
    given = {field: value for field, value in typed.items() if value is not None}
    if not given:
        return config
    data = config.model_dump(mode="json")
    for field, value in given.items():
        table, key = field.split(".")
        data[table][key] = value
    try:
        return parse_rig_config(data, source="command-line options")
    except ConfigError as exc:
        raise UsageError(_option_error(exc, given)) from exc


def _option_error(exc: ConfigError, given: Mapping[str, object]) -> str:
    """A rig-file validation error caused by an override (``given``: field -> value), named by the option typed
    (``--angles 0: ...``)."""
    cause = exc.__cause__
    errors = cause.errors() if isinstance(cause, ValidationError) else []
    if errors:
        field = ".".join(str(p) for p in errors[0]["loc"])
        message = str(errors[0]["msg"]).removeprefix("Value error, ")
        if field in given:
            return f"{OVERRIDE_OPTIONS[field]} {given[field]}: {message[:1].lower()}{message[1:]}"
    typed = " ".join(f"{OVERRIDE_OPTIONS[field]} {value}" for field, value in given.items())
    return f"{typed}: {exc}"


class LivePanel:
    """Progress over presses with time left, the current force, and a small taxel map (normal channel)."""

    def __init__(self, title: str, planned: int, sensor: str, threshold_n: float) -> None:
        self.layout = sensor_layout(sensor)
        self.threshold_n = threshold_n
        self.progress = Progress(
            TextColumn("[bold]{task.description}"),
            BarColumn(),
            MofNCompleteColumn(),
            TextColumn("presses"),
            TimeRemainingColumn(),
        )
        self.task = self.progress.add_task(title, total=planned)
        self.force = 0.0
        self.phase = ""
        self.press_id = ""
        self.first_frame: np.ndarray | None = None
        self.last_frame: np.ndarray | None = None
        self.last_result = ""
        self._last_draw = 0.0
        self.live = Live(self._render(), console=console, refresh_per_second=8, transient=False)

    def _render(self) -> Group:
        status = Text(f"press {self.press_id} {self.phase:8s} force {self.force:6.2f} N / {self.threshold_n:g} N")
        grid = Text()
        if self.last_frame is not None and self.first_frame is not None:
            z = (self.last_frame - self.first_frame)[:, 2].reshape(self.layout.rows, self.layout.cols)
            scale = max(float(np.abs(z).max()), 1e-9)
            shades = "·.:-=+*#%@"
            for row in z:
                grid.append(" ".join(shades[min(9, int(9 * max(0.0, v) / scale))] * 2 for v in row) + "\n")
        return Group(self.progress, status, grid, Text(self.last_result, style="dim"))

    def on_tick(self, tick: TickInfo) -> None:
        self.force, self.phase = tick.press_force_n, tick.phase
        if tick.press_id != self.press_id:
            self.press_id, self.first_frame = tick.press_id, None
        if tick.latest_frame is not None:
            if self.first_frame is None:
                self.first_frame = tick.latest_frame.values
            self.last_frame = tick.latest_frame.values
        now = time.monotonic()
        if now - self._last_draw > 0.1:
            self._last_draw = now
            self.live.update(self._render())

    def on_press(self, done: PressDone) -> None:
        r = done.record
        self.last_result = (
            f"last: {r.press_id} {r.status} ({r.reason}), peak {r.attrs.get('peak_force_n', 0):.2f} N, "
            f"{done.matched}/25 targets matched"
        )
        self.progress.update(self.task, completed=done.index)
        self.live.update(self._render())


class ProgressLines:
    """Progress for a log or pipe (no terminal to redraw the panel): a line per press, at most one every few
    seconds (the first and the last always), with the time left at this run's pace."""

    def __init__(self, title: str) -> None:
        self.title, self.pace, self.lines = title, Pace(), EveryFewSeconds()

    def on_press(self, done: PressDone) -> None:
        self.pace.update(done.index)
        if not self.lines.due(last=done.index >= done.planned):
            return
        r = done.record
        left = self.pace.left_text(done.planned - done.index)
        console.print(
            f"{self.title}: press {done.index}/{done.planned} {r.status}, peak "
            f"{r.attrs.get('peak_force_n', 0):.2f} N, {done.matched}/25 targets matched"
            + (f", {left}" if left else ""),
            highlight=False,
            soft_wrap=True,  # a log line is one line (a terminal folds it itself)
        )


def _kept_line(data_dir: Path, object_id: str, sensor: str) -> str:
    """What an interrupted session kept, read back from its file: ``kept 12/91 presses in data/...``."""
    found = session_presses(data_dir, object_id, sensor)
    if found is None:  # nothing written yet, or the file is mid-recovery: the journal keeps what was pressed
        return f"{object_id} / {sensor}: the presses recorded so far are kept under {data_dir}"
    path = session_path(data_dir, object_id, sensor)
    return f"{object_id} / {sensor}: kept {len(found[0])}/{len(found[1])} presses in {path}"


def _run_session(
    rig: Rig,
    obj: ObjectSpec,
    sensor: str,
    data_dir: Path,
    rotations: list[float] | None,
    live: bool,
    max_presses: int | None,
) -> SessionOutcome:
    rot = rotations if rotations is not None else list(obj.rotations_deg)
    title = f"{obj.id} / {sensor}"
    # Only a terminal can redraw the panel; piped into a file it was one last frame glued to the summary line.
    panel = None
    if live and console.is_terminal:
        panel = LivePanel(title, len(rot) * rig.config.press.angle_count, sensor, rig.config.press.threshold_n)

    def stop_panel() -> None:
        if panel is not None:
            with contextlib.suppress(OSError):  # after SIGHUP the terminal may be gone; stopping the arm matters
                panel.live.stop()

    def ask(message: str) -> None:
        stop_panel()
        _prompt(message)
        if panel is not None:
            panel.live.start()

    try:
        if panel is not None:
            panel.live.start()
        outcome = collect_session(
            rig,
            obj,
            sensor,
            data_dir,
            rotations=rot,
            on_press=panel.on_press if panel else ProgressLines(title).on_press,
            on_tick=panel.on_tick if panel else None,
            ask_operator=ask,
            max_presses=max_presses,
        )
    except KeyboardInterrupt as exc:  # Ctrl-C, SIGTERM, SIGHUP: the arm has stopped; say what is kept and how to go on
        stop_panel()  # first, or the panel draws over the line
        with contextlib.suppress(OSError):  # after SIGHUP the terminal may be gone
            load = getattr(exc, "load_note", "")  # the load the pad is left under (collection/session.py)
            typer.echo(f"{_kept_line(data_dir, obj.id, sensor)}{load}; run the same command again to resume", err=True)
        raise
    finally:
        stop_panel()
    for note in outcome.recovery_notes:
        console.print(f"[yellow]recovered:[/] {note}")
    done_now = outcome.complete + outcome.failed + outcome.aborted
    console.print(
        f"{obj.id} / {sensor}: {outcome.already_done + outcome.complete + outcome.failed}/{outcome.planned} presses "
        f"finished ({done_now} this run: {outcome.complete} complete, {outcome.failed} failed, "
        f"{outcome.aborted} aborted) -> {outcome.path}"
    )
    return outcome


def collect(
    object_id: str = typer.Option(
        ..., "--object", metavar="ID", help="Object id, e.g. hex_tpu (see `unitac-rig objects`)."
    ),
    sensor: str | None = typer.Option(
        None, "--sensor", metavar="SENSOR", show_default="detected", help=f"{spoken(sensor_names())}."
    ),
    rig_file: Path | None = RIG_OPTION,
    data: Path = DATA_OPTION,
    strategy: str | None = typer.Option(
        None,
        "--strategy",
        metavar="NAME",
        show_default=f"the rig file's, else {_PRESS.strategy}",
        help=f"{spoken(list(PRESS_STRATEGIES))}.",
    ),
    speed: float | None = typer.Option(
        None,
        "--speed",
        metavar="MM_S",
        show_default=f"the rig file's, else {_PRESS.speed_mm_s:g}",
        help="Press speed in mm/s.",
    ),
    rotation: float | None = typer.Option(
        None, "--rotation", metavar="DEG", show_default="every rotation", help="Sweep this object rotation only."
    ),
    seed: int = typer.Option(0, "--seed", help="Simulated rig: random seed (runs are deterministic per seed)."),
    imperfections: str = IMPERFECTIONS_OPTION,
    angles: int | None = ANGLES_OPTION,
    max_presses: int | None = typer.Option(None, "--max-presses", help="Stop after this many presses (resume later)."),
    live: bool = LIVE_OPTION,
    dry_run_only: bool = typer.Option(
        False,
        "--dry-run",
        help="Move through every stand-off and clearance waypoint without pressing or recording (first run on a "
        "new rig, object removed).",
    ),
) -> None:
    """Press one object over the arc with the mounted sensor and record the session (resumes if interrupted).

    SIGTERM and SIGHUP stop the arm and keep what was recorded, like Ctrl-C.
    """
    _check_counts(seed, max_presses)
    config = _configure(rig_file, strategy, speed, angles)
    require_data_folder(data)
    obj = get_object(object_id, extra_files=config.object.objects_files)
    if rotation is not None and rotation not in obj.rotations_deg:
        raise UsageError(
            f"{obj.id} is swept at rotations {list(obj.rotations_deg)}, not {rotation:g}",
            hint="omit --rotation to run every rotation",
        )
    _say_if_simulated(config, rig_file, "every device is simulated, no hardware moves.")
    rotations = [rotation] if rotation is not None else None
    with termination_as_interrupt(), open_rig(config, seed=seed, imperfections=imperfections) as rig:
        if dry_run_only:
            visited = dry_run(rig, obj, rotations=rotations, on_standoff=_show_standoff)
            console.print(
                f"dry run: {visited.standoffs} stand-offs and {visited.waypoints} waypoints visited, nothing pressed"
            )
            return
        choice = choose_sensor(rig, obj.id, sensor, data)
        if choice.how == "detected":
            console.print(f"detected mounted sensor: [bold]{choice.name}[/]")
        elif choice.how == "next-incomplete":
            console.print(f"simulated rig: mounting [bold]{choice.name}[/] (no complete data yet for {obj.id})")
        outcome = _run_session(rig, obj, choice.name, data, rotations, live, max_presses)
    if outcome.stopped:
        raise SessionStopped(f"session stopped early: {outcome.stopped}", hint="rerun the same command to resume")


def _prompt(message: str) -> None:
    """Wait for the operator's Enter; Ctrl-C ends the wait at once (a prompt polls nothing)."""
    with immediate_interrupts():
        typer.prompt(message, default="", show_default=False)


def _ask_operator(rig: Rig, message: str) -> None:
    """:func:`_prompt` with the arm at rest and the controller's watchdog fed meanwhile (the wait may last minutes;
    without the feeding the controller would stop the program, as after a dead host)."""
    with rig.arm.keep_alive():
        _prompt(message)


def _show_standoff(plan: PressPlan, index: int, total: int) -> None:
    x, y, z = (1000 * plan.start_pose[:3]).tolist()
    console.print(f"stand-off {index}/{total}: {plan.press_id} at ({x:.1f}, {y:.1f}, {z:.1f}) mm")


def campaign(
    rig_file: Path | None = RIG_OPTION,
    data: Path = DATA_OPTION,
    seed: int = typer.Option(0, "--seed", help="Simulated rig: random seed."),
    imperfections: str = IMPERFECTIONS_OPTION,
    angles: int | None = ANGLES_OPTION,
    objects: str | None = typer.Option(
        None, "--objects", metavar="ID,ID", show_default="every object", help="Comma-separated object ids."
    ),
    live: bool = LIVE_OPTION,
) -> None:
    """Every object with every sensor: unattended on the simulated rig, operator-guided on hardware."""
    _check_counts(seed)
    config = _configure(rig_file, angles=angles)
    require_data_folder(data)
    catalogue = list_objects(extra_files=config.object.objects_files)
    if objects:
        wanted = [o.strip() for o in objects.split(",") if o.strip()]
        catalogue = [get_object(o, extra_files=config.object.objects_files) for o in wanted]
    _say_if_simulated(config, rig_file, "running the whole campaign unattended.")
    started = time.monotonic()
    with termination_as_interrupt(), open_rig(config, seed=seed, imperfections=imperfections) as rig:
        sensors = collection_order(rig)
        planned = {(obj.id, s): len(obj.rotations_deg) * config.press.angle_count for s in sensors for obj in catalogue}
        progress = CampaignProgress(planned, data)
        for sensor in sensors:
            if not rig.simulated:
                _ask_operator(rig, f"Mount the {sensor} on the arm, then press Enter")
            for obj in catalogue:
                if session_complete(data, obj.id, sensor):
                    progress.done[obj.id, sensor] = progress.planned[obj.id, sensor]
                    console.print(f"{obj.id} / {sensor}: already complete")
                    continue
                console.print(progress.line(obj.id, sensor), style="bold", highlight=False, soft_wrap=True)
                if not rig.simulated:
                    _ask_operator(rig, f"Mount {obj.id} at rotation 0, then press Enter")
                outcome = _run_session(rig, obj, sensor, data, None, live, None)
                progress.finished(obj.id, sensor, outcome)
                if outcome.stopped:
                    raise SessionStopped(
                        f"campaign stopped: {outcome.stopped}", hint="rerun the same command to resume"
                    )
    console.print(f"campaign done in {spoken_duration(time.monotonic() - started)} wall time -> {data}")


class CampaignProgress:
    """The campaign's overall line before each session: which session of how many, presses done, and the time left
    at this run's pace (pressing time per press; operator waits on hardware count too)."""

    def __init__(self, planned: dict[tuple[str, str], int], data: Path) -> None:
        self.planned = planned  # presses per (object, sensor), in campaign order
        self.done: dict[tuple[str, str], int] = {}  # presses finished, by earlier runs too (counted from the start)
        for (obj, sensor), presses in planned.items():
            found = session_presses(data, obj, sensor)
            if found is not None:
                self.done[obj, sensor] = min(len(found[0]), presses)
        self.pace, self.pressed_now = Pace(done_before=0), 0

    def finished(self, obj: str, sensor: str, outcome: SessionOutcome) -> None:
        self.done[(obj, sensor)] = outcome.already_done + outcome.complete + outcome.failed
        self.pressed_now += outcome.complete + outcome.failed + outcome.aborted
        self.pace.update(self.pressed_now)

    def line(self, obj: str, sensor: str) -> str:
        keys, presses, total = list(self.planned), sum(self.done.values()), sum(self.planned.values())
        left = self.pace.left_text(total - presses) or "time left known after the first session"
        return (
            f"campaign: session {keys.index((obj, sensor)) + 1}/{len(keys)} ({obj} / {sensor}), "
            f"{presses}/{total} presses done, {left}"
        )


def extract(
    data: Path = typer.Argument(..., help="Dataset directory.", parser=path_text),
    tolerance: float = typer.Option(0.5, "--tolerance", help="Largest matching error that still counts, N."),
    smoothing: int = typer.Option(15, "--smoothing", help="Moving-average window on the wrist force, samples."),
    latency: float = typer.Option(0.0, "--latency", help="Tactile latency to subtract from frame times, s."),
    force: bool = typer.Option(
        False, "--force", help="Apply settings that lose more than half of the matched targets (refused otherwise)."
    ),
) -> None:
    """Recompute the force-matched frames of every session from the raw streams with other settings.

    All or nothing: the settings are checked first, every session is verified (and repaired from its journal), and
    no file changes until every new one is written. Settings that would keep under half of today's matched targets
    (the count `inspect` shows) change nothing without --force.
    """
    settings = ExtractionSettings(tolerance_n=tolerance, smoothing_samples=smoothing, tactile_latency_s=latency)
    options = {"tolerance_n": "--tolerance", "smoothing_samples": "--smoothing", "tactile_latency_s": "--latency"}
    for name, why in settings.problems():
        raise UsageError(f"{options.get(name, name)} {why}")
    require_directory(data, "DATA", hint="pass the --data folder you collected into")
    sessions = list_sessions(data)
    if not sessions:
        raise UsageError(f"no session files in {data}")
    before = _matched_targets(data)
    typed = f"--tolerance {tolerance:g} --smoothing {smoothing} --latency {latency:g}"

    def accept(results: list[tuple[Path, int, int]]) -> None:
        kept, had = sum(r[2] for r in results), sum(before.get(r[0].name, 0) for r in results)
        if not force and had and kept < LOSS_REFUSED * had:
            raise UsageError(
                f"{typed} would keep {kept} of the {had} matched targets (drop {had - kept}, "
                f"{100 * (had - kept) / had:.0f} %); nothing was changed",
                hint="pass --force to extract with these settings anyway",
            )

    for path, presses, matched in reextract_sessions([info.path for info in sessions], settings, accept):
        was = before.get(path.name)
        change = f" (was {was})" if was is not None and was != matched else ""
        console.print(f"{path.name}: {presses} presses re-extracted, {matched} targets matched{change}")


LOSS_REFUSED = 0.5  # extract refuses (without --force) settings that keep under this share of the matched targets


def _matched_targets(data: Path) -> dict[str, int]:
    """Matched targets of complete presses per session file, as ``inspect`` counts them."""
    from unitac_rig.storage.summary import inspect_dataset

    return {s["file"]: int(s["targets_matched"]) for s in inspect_dataset(data)["sessions"]}


def objects_cmd(
    rig_file: Path | None = RIG_OPTION,
) -> None:
    """List the object catalogue (ids, shape, material, rotations)."""
    config = load_rig_config(rig_file)
    table = Table(title="objects")
    for col in ("id", "shape", "material", "rotations (deg)", "autoencoder training"):
        table.add_column(col)
    for o in list_objects(extra_files=config.object.objects_files):
        table.add_row(
            o.id,
            o.shape,
            o.material,
            ", ".join(f"{r:g}" for r in o.rotations_deg),
            "yes" if o.in_autoencoder_training else "no (test only)",
        )
    console.print(table)
