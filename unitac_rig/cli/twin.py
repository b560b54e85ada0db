"""``unitac-rig twin``: the real-time twin of the whole rig on a loopback address, until Ctrl-C or SIGTERM.

The controller twin (a simulated UR e-Series controller the real ur_rtde clients drive) and the mounted sensor on
loopback transports, from one scene; stdout gets the rig file that points the hardware code path at them (``collect
--rig <that file>`` runs as on the robot), stderr what the controller does. Lines on stdin act as the teach pendant.
"""

from __future__ import annotations

import dataclasses
import sys
import threading
from pathlib import Path
from typing import TYPE_CHECKING

import typer

from unitac_rig.errors import UnitacError, UsageError
from unitac_rig.interrupts import stop_on_signals
from unitac_rig.rig.sensors import sensor_names

if TYPE_CHECKING:  # the twin loads when the command runs, not when the CLI starts
    from unitac_rig.sim.twin import TwinTruth
    from unitac_rig.sim.twin.rig import RigTwin


def _status_line(truth: TwinTruth) -> str:
    program = {1: "stopped", 2: "running", 4: "paused"}.get(truth.runtime_state, str(truth.runtime_state))
    safety = "normal"
    if truth.safety_status_bits & (1 << 7):
        safety = "EMERGENCY STOP"
    elif truth.safety_status_bits & (1 << 2):
        safety = "PROTECTIVE STOP"
    return f"program {program}, safety {safety}, robot mode {truth.robot_mode}, clients {truth.rtde_clients}"


def twin(
    object_id: str = typer.Option(..., "--object", help="Object in front of the arm, e.g. circle_pla."),
    rotation: float | None = typer.Option(None, "--rotation", help="Object rotation (deg); its first by default."),
    sensor: str | None = typer.Option(
        None, "--sensor", help="Mounted sensor (a registered one).", show_default=sensor_names()[0]
    ),
    host: str = typer.Option("127.0.0.210", "--host", help="Loopback address to serve on (127.0.0.x)."),
    seed: int = typer.Option(0, "--seed", help="Seed of the scene and the sensors' noise."),
    uskin_via: str = typer.Option(
        "xela-server",
        "--uskin-via",
        help="uSkin transport in the rig file: xela-server or slcan (both served).",
    ),
    protective_stop_n: float = typer.Option(150.0, "--protective-stop-n", help="Controller force limit (N)."),
    unlock_delay_s: float = typer.Option(5.0, "--unlock-delay", help="Wait before a protective stop unlocks (s)."),
    like: Path | None = typer.Option(
        None, "--like", help="Rehearse this rig file: the object stands where it says; its TCP and payload are set."
    ),
    write_rig: Path | None = typer.Option(None, "--write-rig", help="Also write the rig file here."),
    quiet: bool = typer.Option(False, "--quiet", help="Print the rig file only, no status lines."),
) -> None:
    """Serve the real-time twin of the rig (controller + mounted sensor) until Ctrl-C or SIGTERM."""
    from unitac_rig.sim.twin import ControllerParams
    from unitac_rig.sim.twin.rig import RigTwin

    if not host.startswith("127."):
        raise UsageError(f"the twin serves on loopback only, not {host!r}", hint="use an address like 127.0.0.210")
    params = ControllerParams(protective_stop_n=protective_stop_n, unlock_delay_s=unlock_delay_s)
    placement = None
    tables: dict[str, dict[str, object]] | None = None
    if like is not None:
        from unitac_rig.rig.config import load_rig_config

        config = load_rig_config(like)
        placement = config.object
        tables = {"press": config.press.model_dump(mode="json"), "limits": config.limits.model_dump(mode="json")}
        if config.arm is not None and config.arm.tcp_offset is not None:  # the pad is where that TCP says
            params = dataclasses.replace(params, tool_offset=tuple(config.arm.tcp_offset))
        if config.arm is not None and config.arm.payload_kg is not None:
            params = dataclasses.replace(params, payload_kg=config.arm.payload_kg)

    with (
        stop_on_signals() as stop,
        RigTwin(
            object_id,
            rotation_deg=rotation,
            sensor=sensor,
            host=host,
            seed=seed,
            params=params,
            placement=placement,
            sensor_options={"uskin": {"transport": uskin_via}},  # --uskin-via: which route the rig file names
        ) as rig,
    ):
        text = rig.rig_file(tables)
        if write_rig is not None:
            write_rig.write_text(text)
        typer.echo(text)
        sys.stdout.flush()
        if not quiet:
            typer.echo(
                f"twin: {rig.object_id} at {rig.rotation_deg:g} deg, {rig.sensor} mounted, controller on "
                f"{host} (pid {rig.controller.pid}, {rig.controller.status()['scheduling']}); Ctrl-C stops it; "
                f"{PENDANT_HELP}",
                err=True,
            )
        threading.Thread(target=_pendant, args=(rig, stop), name="twin-pendant", daemon=True).start()
        _watch(rig, stop, quiet)
    if not quiet:
        typer.echo("twin: stopped", err=True)


PENDANT_HELP = "pendant commands: unlock, estop, release, pstop, status"


def _pendant(rig: RigTwin, stop: threading.Event) -> None:
    """Read pendant commands from stdin until it closes or the twin stops (a daemon thread; stdin may be a pipe)."""
    controller = rig.controller
    for line in sys.stdin:
        if stop.is_set():
            return
        command = line.strip().lower()
        try:
            if command == "unlock":
                reply = controller.unlock_protective_stop()
            elif command == "estop":
                controller.emergency_stop()
                reply = "emergency stop pressed"
            elif command == "release":
                controller.release_emergency_stop()
                reply = f"emergency stop released; power on: {controller.power_on()}"
            elif command == "pstop":
                controller.trigger_protective_stop("pendant")
                reply = "protective stop"
            elif command == "status":
                reply = f"{_status_line(controller.truth())}; {controller.status().get('last_error') or 'no error'}"
            elif command:
                reply = PENDANT_HELP
            else:
                continue
        except Exception as exc:  # the twin may be stopping; a pendant line must never kill the command
            reply = f"failed: {exc}"
        typer.echo(f"pendant: {reply}", err=True)


def _watch(rig: RigTwin, stop: threading.Event, quiet: bool) -> None:
    """Wait for a signal; meanwhile report each change of the controller's state (stderr)."""
    last_line = ""
    last_counts = (0, 0, 0)
    while not stop.wait(0.1):
        if not rig.controller.alive:
            raise UnitacError("the controller twin's process ended", hint="see its error output above")  # exit 1
        if quiet:
            continue
        truth = rig.controller.truth()
        line = _status_line(truth)
        counts = (truth.protective_stops, truth.emergency_stops, truth.watchdog_trips)
        if line != last_line or counts != last_counts:
            error = rig.controller.status().get("last_error") if counts != last_counts else ""
            typer.echo(f"twin: {line}" + (f" ({error})" if error else ""), err=True)
            last_line, last_counts = line, counts
