"""``unitac-rig probe``: read a few frames from one device to check it is wired up (or try a simulated one).

``probe uskin --can-interface socketcan --can-channel can0``, ``probe uskin --xela-server ws://HOST:5000`` and
``probe papillarray --port /dev/ttyACM0`` print a taxel map of the last frame, or one JSON object per frame with
``--json``. ``--simulated`` starts the matching simulated device with a synthetic press, so a newcomer can try the
command with no hardware. A port that is not there, or a device that sends nothing within ``--timeout``, ends with
one error line and exit status 1.
"""

from __future__ import annotations

import contextlib
import itertools
import json
from collections.abc import Iterator
from typing import Any

import numpy as np
import typer
from rich.console import Console
from rich.table import Table

from drivers.frames import TactileFrame
from drivers.layouts import PAPILLARRAY, USKIN, SensorLayout
from drivers.sensor import SensorHealth
from unitac_rig.errors import UsageError

probe_app = typer.Typer(
    name="probe",
    help="Read a few frames from one device (uSkin, PapillArray, UR5e) to check it is connected.",
    no_args_is_help=True,
)

_sim_channels = itertools.count(1)

FRAMES_OPTION = typer.Option(10, "--frames", min=1, help="How many frames to read.")
JSON_OPTION = typer.Option(False, "--json", help="Print one JSON object per frame instead of a taxel map.")
TIMEOUT_OPTION = typer.Option(5.0, "--timeout", min=0.1, help="Give up when the frames have not arrived (s).")
SIMULATED_OPTION = typer.Option(False, "--simulated", help="Probe a simulated device with a synthetic press.")


def frame_json(frame: TactileFrame, layout: SensorLayout) -> dict[str, Any]:
    """One frame as the ``--json`` line: host time (s; frames that arrived in one read share it), the device's own
    sample time (s; null where the wire has none), device counter, values in wire order and their units."""
    record: dict[str, Any] = {
        "sensor": frame.sensor,
        "t": frame.host_t_ns / 1e9,
        "device_t": None if frame.device_t_us is None else frame.device_t_us / 1e6,
        "seq": frame.seq,
        "values": np.asarray(frame.values).tolist(),
        "units": layout.units,
    }
    if layout.has_displacement:
        record["displacement"] = None if frame.displacement_mm is None else frame.displacement_mm.tolist()
    return record


def frame_rate(frames: list[TactileFrame]) -> str:
    """``about 100 Hz (device clock)``: from the device's sample times where it sends them (frames that arrive in one
    read share a host time, so two or three frames can span no host time at all), else from the host times."""
    device = [f.device_t_us for f in frames]
    if len(frames) > 1 and all(t is not None for t in device):
        span_s = (device[-1] - device[0]) / 1e6  # type: ignore[operator]
        clock = "device clock"
    else:
        span_s = (frames[-1].host_t_ns - frames[0].host_t_ns) / 1e9
        clock = "host clock"
    if len(frames) < 2:
        return "one frame: no rate (read more with --frames)"
    if span_s <= 0:
        return f"{len(frames)} frames in one read: no rate (read more with --frames)"
    return f"about {(len(frames) - 1) / span_s:.0f} Hz ({clock})"


def _cell(values: np.ndarray, units: str, displacement: np.ndarray | None) -> str:
    if units == "counts":
        return "\n".join(f"{axis} {int(v):>5d}" for axis, v in zip("xyz", values, strict=True))
    text = "\n".join(f"F{axis} {v:+6.2f}" for axis, v in zip("xyz", values, strict=True))
    if displacement is not None:
        text += f"\nDz {displacement[2]:+5.2f}mm"
    return text


def _print_map(console: Console, frames: list[TactileFrame], layout: SensorLayout, health: SensorHealth) -> None:
    last = frames[-1]
    title = f"{layout.model}: last of {len(frames)} frames ({layout.units}), {frame_rate(frames)}"
    table = Table(title=title, show_lines=True)
    table.add_column("row")
    for col in range(layout.cols):
        table.add_column(f"col {col}", justify="right")
    values = layout.to_grid(np.asarray(last.values))
    displacement = None if last.displacement_mm is None else layout.to_grid(np.asarray(last.displacement_mm))
    stale = None if last.stale_mask is None else np.asarray(last.stale_mask).reshape(layout.rows, layout.cols)
    for row in range(layout.rows):
        cells = []
        for col in range(layout.cols):
            cell = _cell(values[row, col], layout.units, None if displacement is None else displacement[row, col])
            if stale is not None and stale[row, col]:
                cell = f"[red]{cell}\nSTALE[/red]"
            cells.append(cell)
        table.add_row(str(row), *cells)
    console.print(table)
    seq = "none on this wire" if last.seq is None else str(last.seq)
    console.print(
        f"seq {seq}; invalid frames {health.invalid_frames}, sequence gaps {health.sequence_gaps}, "
        f"checksum errors {health.checksum_errors}, bytes dropped {health.bytes_dropped}, stalls {health.stalls}"
    )
    if health.saturated_taxels:
        console.print(f"[yellow]saturated taxels: {health.saturated_taxels}[/yellow]")


def _run_probe(driver: Any, layout: SensorLayout, n_frames: int, as_json: bool, timeout_s: float) -> None:
    driver.connect()
    try:
        frames = driver.wait_frames(n_frames, timeout_s)
        health = driver.health()
    finally:
        driver.disconnect()
    if as_json:
        for frame in frames:
            typer.echo(json.dumps(frame_json(frame, layout)))
    else:
        _print_map(Console(), frames, layout, health)


# ---- uSkin ---------------------------------------------------------------------------------------------------------


@contextlib.contextmanager
def _simulated_uskin(
    can_interface: str | None, xela_server: str | None, controller_id: int, sensor_number: int
) -> Iterator[tuple[str | None, str | None, str | None]]:
    """Start the simulated device for ``probe uskin --simulated``; yields (can interface, channel, server url)."""
    from unitac_rig.sim.devices import SimSlcanAdapter, SimXelaController
    from unitac_rig.sim.devices.xela_server import SimXelaServer
    from unitac_rig.sim.synthetic_sources import synthetic_press

    source = synthetic_press(USKIN.name)
    if xela_server is not None:
        with SimXelaServer(source=source, sensor_number=sensor_number) as server:
            yield None, None, server.url
        return
    can_channel = f"unitac-probe-sim-{next(_sim_channels)}"
    with SimXelaController(can_channel, controller_id=controller_id, source=source):
        if can_interface == "slcan":
            with SimSlcanAdapter(can_channel) as adapter:
                yield "slcan", adapter.url, None
        else:
            yield "virtual", can_channel, None


@probe_app.command("uskin")
def probe_uskin(
    can_interface: str | None = typer.Option(
        None, "--can-interface", help="python-can interface: socketcan, slcan, pcan, virtual..."
    ),
    can_channel: str | None = typer.Option(None, "--can-channel", help="CAN channel: can0, /dev/ttyUSB0, ..."),
    controller_id: int = typer.Option(1, "--controller-id", min=0, max=15, help="XELA controller id (0..15)."),
    xela_server: str | None = typer.Option(
        None, "--xela-server", help="Read through xela_server instead of CAN, e.g. ws://127.0.0.1:5000."
    ),
    sensor_number: int = typer.Option(1, "--sensor-number", min=1, help="Sensor number in xela_server's data."),
    frames: int = FRAMES_OPTION,
    as_json: bool = JSON_OPTION,
    timeout: float = TIMEOUT_OPTION,
    simulated: bool = SIMULATED_OPTION,
) -> None:
    """Read frames from a XELA uSkin uSPa46 over CAN or xela_server (raw counts)."""
    from drivers.uskin import UskinCanDriver, UskinXelaServerDriver, open_can_bus

    if xela_server is not None and (can_interface is not None or can_channel is not None):
        raise UsageError("give either --xela-server or --can-interface/--can-channel, not both")
    if not simulated and xela_server is None and (can_interface is None or can_channel is None):
        raise UsageError(
            "probe uskin needs --can-interface and --can-channel, or --xela-server",
            hint="e.g. --can-interface socketcan --can-channel can0, or add --simulated to try it without hardware",
        )
    with contextlib.ExitStack() as stack:
        if simulated:
            can_interface, can_channel, xela_server = stack.enter_context(
                _simulated_uskin(can_interface, xela_server, controller_id, sensor_number)
            )
        if xela_server is not None:
            driver: Any = UskinXelaServerDriver(
                xela_server, sensor_number=sensor_number, connect_timeout_s=min(timeout, 5.0)
            )
        else:
            assert can_interface is not None and can_channel is not None
            options = {"sleep_after_open": 0} if simulated and can_interface == "slcan" else {}
            bus = open_can_bus(can_interface, can_channel, **options)
            driver = UskinCanDriver(bus, controller_id=controller_id, owns_bus=True)
            stack.callback(driver.disconnect)  # shuts the bus down even if connect() fails
        _run_probe(driver, USKIN, frames, as_json, timeout)


# ---- PapillArray ---------------------------------------------------------------------------------------------------


@probe_app.command("papillarray")
def probe_papillarray(
    port: str | None = typer.Option(None, "--port", help="Serial port or pyserial URL, e.g. /dev/ttyACM0."),
    slot: int = typer.Option(0, "--slot", min=0, max=1, help="Sensor port on the hub (0 or 1)."),
    rate_hz: int = typer.Option(100, "--rate-hz", help="Sampling rate to set: 100, 250, 500 or 1000 Hz."),
    frames: int = FRAMES_OPTION,
    as_json: bool = JSON_OPTION,
    timeout: float = TIMEOUT_OPTION,
    simulated: bool = SIMULATED_OPTION,
) -> None:
    """Read frames from a Contactile PapillArray (pillar forces in N, displacements in mm)."""
    from drivers.papillarray import PapillArrayDriver

    if port is None and not simulated:
        raise UsageError("probe papillarray needs --port", hint="e.g. --port /dev/ttyACM0, or --simulated")
    with contextlib.ExitStack() as stack:
        if simulated:
            from unitac_rig.sim.devices import SimPapillArrayHub
            from unitac_rig.sim.synthetic_sources import synthetic_press

            hub = stack.enter_context(SimPapillArrayHub(source=synthetic_press(PAPILLARRAY.name), slot=slot))
            port = hub.url
        assert port is not None
        driver = PapillArrayDriver(port, slot=slot, rate_hz=rate_hz)
        _run_probe(driver, PAPILLARRAY, frames, as_json, timeout)


def register(app: typer.Typer) -> None:
    """Add ``probe`` and its device subcommands to the root app."""
    app.add_typer(probe_app, name="probe")


from unitac_rig.cli.probe_ur5e import register_ur5e  # noqa: E402

register_ur5e(probe_app)
