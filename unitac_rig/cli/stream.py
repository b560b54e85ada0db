"""``unitac-rig stream RUN``: the trained model on the mounted sensor (the rig file's, or the real-time twin's
started here), live, as JSON lines on stdout or to one client on 127.0.0.1; a summary on stderr at the end, also after
Ctrl-C, SIGTERM or SIGHUP (exit 130, 143, 129). The lines: docs/use-your-model-on-the-robot.md.
"""

from __future__ import annotations

import contextlib
import json
import socket
import sys
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import typer

from unitac_rig.errors import UsageError
from unitac_rig.interrupts import interrupt_for, stop_on_signals

RATE_WARNING = 0.9  # warn when the steady-state rate falls below this share of --rate


def _listen_address(text: str) -> tuple[str, int]:
    host, _, port = text.rpartition(":")
    host = host or "127.0.0.1"
    if host not in ("127.0.0.1", "localhost") or not port.isdigit():
        raise UsageError(
            f"--listen {text!r}: stream serves on 127.0.0.1 only",
            hint="use --listen 127.0.0.1:PORT (forward it with ssh if another machine needs it)",
        )
    return "127.0.0.1", int(port)


@contextlib.contextmanager
def _socket_writer(address: tuple[str, int], stop: threading.Event) -> Iterator[Callable[[bytes], None]]:
    """Wait for one client on ``address`` (127.0.0.1), then hand out a writer that sends it each line."""
    server = socket.create_server(address)
    server.settimeout(0.2)
    typer.echo(f"stream: waiting for a client on {address[0]}:{server.getsockname()[1]}", err=True)
    try:
        client = None
        while client is None and not stop.is_set():
            with contextlib.suppress(TimeoutError):
                client, _ = server.accept()
        if client is None:
            raise KeyboardInterrupt
        client.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        client.settimeout(None)
        try:
            yield client.sendall
        finally:
            client.close()
    finally:
        server.close()


def _write_stdout(line: bytes) -> None:
    sys.stdout.buffer.write(line)
    sys.stdout.buffer.flush()


@contextlib.contextmanager
def _mounted_sensor(
    rig_file: Path | None,
    simulated: bool,
    sensor: str | None,
    object_id: str,
    rate_hz: int | None,
    run_sensors: tuple[str, ...],
) -> Iterator[tuple[Any, str]]:
    """(the connected driver, its sensor name), from the rig file or the real-time twin started here."""
    from unitac_rig.rig.config import load_rig_config, parse_rig_config
    from unitac_rig.rig.hardware import HardwareRig

    with contextlib.ExitStack() as stack:  # closes the sensor, then the rig, then the twin
        if simulated:
            import tomllib

            from unitac_rig.sim.twin import first_free_loopback
            from unitac_rig.sim.twin.rig import RigTwin

            name = sensor or next(s for s in ("papillarray", "uskin") if s in run_sensors)
            twin = stack.enter_context(RigTwin(object_id, sensor=name, host=first_free_loopback(211, 239)))
            config = parse_rig_config(tomllib.loads(twin.rig_file()))
            sensor = twin.sensor
        else:
            assert rig_file is not None
            config = load_rig_config(rig_file)
        if rate_hz is not None:  # every sensor table with a sample rate (rate_hz) takes it: the PapillArray's
            rated = [n for n, table in config.sensors.items() if "rate_hz" in type(table).model_fields]
            if not rated:
                raise UsageError("--rate sets a sensor's sample rate, and no sensor of the rig has one (rate_hz)")
            for n in rated:
                config.sensors[n] = config.sensors[n].model_copy(update={"rate_hz": rate_hz})
        rig = HardwareRig(config)
        stack.callback(rig.close)
        name = sensor if sensor is not None else rig.detect_sensor()
        driver = rig.open_sensor(name)
        stack.callback(driver.disconnect)
        yield driver, name


def stream_command(
    run: Path = typer.Argument(..., help="Run directory (trained on the mounted sensor and others)."),
    rig_file: Path = typer.Option(None, "--rig", help="Rig file with the mounted sensor (e.g. the twin's)."),
    simulated: bool = typer.Option(False, "--simulated", help="Start the real-time twin here and read its sensor."),
    sensor: str = typer.Option(None, "--sensor", help="Mounted sensor (default: detected; --simulated: papillarray)."),
    object_id: str = typer.Option("circle_pla", "--object", help="With --simulated: the object in front of the pad."),
    rate_hz: int = typer.Option(None, "--rate", help="PapillArray sample rate, Hz (100, 250, 500 or 1000)."),
    member: int = typer.Option(0, "--member", help="Which seed of a multi-seed run (index)."),
    tare_frames: int = typer.Option(50, "--tare-frames", min=1, help="Frames to tare on (median) before streaming."),
    frames: int = typer.Option(None, "--frames", help="Stop after this many frames."),
    duration: float = typer.Option(None, "--duration", help="Stop after this many seconds of streaming."),
    listen: str = typer.Option(None, "--listen", help="Serve the lines to one client on 127.0.0.1:PORT."),
    summary_path: Path = typer.Option(None, "--summary", help="Also write the summary (JSON) here."),
    geometry: bool = typer.Option(True, "--geometry/--no-geometry", help="Add the run's geometry estimate."),
) -> None:
    """Stream the mounted sensor through the run live: latent, translations (and geometry) per frame, JSON lines.

    Each line also carries the tared frame, its time on the monotonic (host_t_ns) and the wall clock (unix_t_ns),
    and "warmup": true on the backlog of the first lines (docs/use-your-model-on-the-robot.md). The summary
    (stderr, --summary) gives the rate achieved, with a warning under 90 % of --rate. Ctrl-C ends the stream
    after its summary, exit 130.
    """
    from unitac_rig.learning.live import LiveModel, live_sensor, stream_frames

    if (rig_file is None) == (not simulated):
        raise UsageError("stream needs --rig RIG.toml or --simulated (one of them)")
    address = _listen_address(listen) if listen is not None else None
    from unitac_rig.learning.engine import UNITAC_GROUP
    from unitac_rig.learning.train import load_run

    run_sensors = tuple(load_run(run).engine.group(UNITAC_GROUP).sensors)
    try:
        with (
            stop_on_signals() as stop,
            _mounted_sensor(rig_file, simulated, sensor, object_id, rate_hz, run_sensors) as (driver, name),
        ):
            model = LiveModel(run, name, member=member, geometry=geometry)
            extra = (
                f", geometry from the MLP trained on {model.geometry_meta['trained_on']}" if model.geometry_meta else ""
            )
            typer.echo(
                f"stream: {name} -> latent {model.latent_dim}, "
                f"{', '.join(model.targets) or 'no other sensor'}{extra}; taring on {tare_frames} frames "
                "(keep the pad unloaded)",
                err=True,
            )
            with contextlib.ExitStack() as stack:
                write = stack.enter_context(_socket_writer(address, stop)) if address else _write_stdout
                try:
                    stats = stream_frames(
                        live_sensor(driver),
                        model,
                        write,
                        tare_frames=tare_frames,
                        max_frames=frames,
                        duration_s=duration,
                        should_stop=stop.is_set,
                    )
                except (BrokenPipeError, ConnectionError):
                    raise UsageError(
                        "the reader of the stream went away", hint="stream stops with its reader"
                    ) from None
            health = driver.health().as_dict() if hasattr(driver, "health") else {}
    except KeyboardInterrupt:
        typer.echo("stream: stopped before the first frame, nothing written; run the same command to start", err=True)
        raise
    summary = {
        "run": str(run),
        "sensor": name,
        "targets": list(model.targets),
        **stats.summary(),
        "driver": health,
        "asked_rate_hz": rate_hz,
        "finished_unix": time.time(),
    }
    for line in summary_lines(summary):
        typer.echo(line, err=True)
    if summary_path is not None:
        summary_path.write_text(json.dumps(summary, indent=1) + "\n", encoding="utf-8")
    if stop.signal_number is not None:
        kept = f"; the summary is in {summary_path}" if summary_path is not None else ""
        lines = summary["frames_out"]
        typer.echo(f"stream: stopped after {lines} lines{kept}; run the same command to go on", err=True)
        raise interrupt_for(stop.signal_number)


def summary_lines(summary: dict[str, Any]) -> list[str]:
    """The summary on stderr: frames, the rate achieved (a warning under 90 % of ``--rate``), the steady-state
    latency, and the warm-up backlog apart."""
    latency, warmup, rate = summary["latency_ms"], summary["warmup"], summary["rate_hz"]
    asked = summary.get("asked_rate_hz")
    rate_text = "-" if rate is None else f"{rate:.0f} Hz"
    lines = [
        f"stream: {summary['frames_out']} frames in {summary['seconds']:.1f} s at {rate_text}"
        + (f" (asked {asked} Hz)" if asked else "")
        + f", {summary['seq_gaps']} lost by the device counter; latency after the warm-up (host ms, frame stamped "
        f"-> line written) median {_ms(latency['median'])}, p99 {_ms(latency['p99'])}, max {_ms(latency['max'])}",
        f'stream: warm-up backlog {warmup["frames"]} lines in {warmup["seconds"]:.2f} s (marked "warmup": true), '
        f"latency max {_ms(warmup['latency_ms']['max'])} ms",
    ]
    if asked and rate is not None and rate < RATE_WARNING * asked:
        lines.append(
            f"warning: the sensor delivered {rate:.0f} Hz, {100 * rate / asked:.0f} % of the {asked} Hz asked (the "
            "device, its link or this host cannot keep up; see the driver's health in --summary)"
        )
    return lines


def _ms(value: float | None) -> str:
    return "-" if value is None else f"{value:.3f}"
