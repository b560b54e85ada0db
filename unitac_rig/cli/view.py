"""``unitac-rig view``: a session (or every session of a data folder), or a live sensor, in the Rerun viewer."""

from __future__ import annotations

from pathlib import Path

import typer

from unitac_rig.errors import UsageError


def view_command(
    target: Path = typer.Argument(None, metavar="DATA_OR_SESSION", help="A data folder or one session file (.h5)."),
    stream: bool = typer.Option(False, "--stream", help="Show a live sensor instead (with --simulated or --rig)."),
    simulated: bool = typer.Option(False, "--simulated", help="With --stream: start the real-time twin here."),
    rig_file: Path = typer.Option(None, "--rig", help="With --stream: rig file with the mounted sensor."),
    sensor: str = typer.Option(
        None, "--sensor", help="With --stream: the sensor (else detected; --simulated: papillarray)."
    ),
    object_id: str = typer.Option("circle_pla", "--object", help="With --stream --simulated: the object."),
    frames: int = typer.Option(None, "--frames", help="With --stream: stop after this many frames."),
    duration: float = typer.Option(None, "--duration", help="With --stream: stop after this many seconds."),
    tare_frames: int = typer.Option(50, "--tare-frames", min=1, help="With --stream: frames to tare on (median)."),
    save: Path = typer.Option(None, "--save", help="Write a Rerun recording (.rrd) here instead of a viewer."),
) -> None:
    """Show frames (taxel images), wrist force, the pad's pose and matched targets in Rerun (the view extra)."""
    from unitac_rig.viewer import _rerun, log_session, log_stream

    if stream == (target is not None):
        raise UsageError("view needs DATA_OR_SESSION or --stream (one of them)")
    if stream and (rig_file is None) == (not simulated):
        raise UsageError("view --stream needs --rig RIG.toml or --simulated (one of them)")
    rr = _rerun()
    rec = rr.RecordingStream("unitac-rig", make_default=False)
    if save is not None:
        rec.save(str(save))
    else:
        rec.spawn()
    try:
        if stream:
            from unitac_rig.cli.stream import _mounted_sensor
            from unitac_rig.interrupts import stop_on_signals
            from unitac_rig.learning.live import live_sensor

            with (
                stop_on_signals() as stop,
                _mounted_sensor(rig_file, simulated, sensor, object_id, None, ("papillarray", "uskin")) as (
                    driver,
                    name,
                ),
            ):
                typer.echo(f"view: {name} live, taring on {tare_frames} frames (keep the pad unloaded)", err=True)
                n = log_stream(
                    rec,
                    name,
                    live_sensor(driver),
                    tare_frames=tare_frames,
                    max_frames=frames,
                    duration_s=duration,
                    should_stop=stop.is_set,
                )
            typer.echo(f"view: {n} frames of {name}" + (f" -> {save}" if save else ""), err=True)
            return
        sessions = (
            [target] if target.is_file() else sorted(p for p in target.glob("*__*.h5") if ".broken-" not in p.name)
        )
        if not sessions:
            raise UsageError(f"{target} holds no session file (*__*.h5)", hint="pass a --data folder of collect")
        for session in sessions:
            counts = log_session(rec, session)
            typer.echo(f"view: {session.name}: " + ", ".join(f"{v} {k}" for k, v in counts.items()), err=True)
    finally:
        rec.flush()
        if save is not None:
            rec.disconnect()
    if save is not None:
        typer.echo(f"view: wrote {save} ({save.stat().st_size / 1e6:.1f} MB); open it with: rerun {save}", err=True)
