"""``unitac-rig probe``: read a few frames from one device to check it is wired up (or try a simulated one).

Every registered sensor (:mod:`unitac_rig.rig.sensors`) is a ``probe <sensor>`` command whose options are the
fields of its rig-file tables (``probe uskin --can-channel can0``, ``probe papillarray --port /dev/ttyACM0``): it opens
the driver the rig file would, and a new sensor is probed with no edit here.
"""

from __future__ import annotations

import contextlib
import functools
import inspect
import json
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, Literal, get_args, get_origin

import numpy as np
import typer
from pydantic import ValidationError
from pydantic.fields import FieldInfo
from rich.console import Console
from rich.table import Table
from typer.models import CommandInfo

from drivers.frames import TactileFrame
from drivers.layouts import SensorLayout
from drivers.sensor import SensorHealth
from unitac_rig.cli.help import PlainCommand, field_bounds, field_flag
from unitac_rig.cli.output import console
from unitac_rig.cli.probe_ur5e import register_ur5e
from unitac_rig.errors import UsageError
from unitac_rig.rig.sensors import SENSORS, SensorConfigBase, SensorSpec

FRAMES_OPTION = typer.Option(10, "--frames", min=1, help="How many frames to read.")
JSON_OPTION = typer.Option(False, "--json", help="Print one JSON object per frame instead of a taxel map.")
TIMEOUT_OPTION = typer.Option(
    5.0, "--timeout", min=0.1, help="Give up when the sensor has not answered or its frames have not arrived (s)."
)
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
    if hasattr(driver, "connect_timeout_s"):  # a networked sensor (xela_server): --timeout bounds finding it too
        driver.connect_timeout_s = timeout_s
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
        _print_map(console, frames, layout, health)


# ---- one command per registered sensor -------------------------------------------------------------------------


@dataclass(frozen=True)
class ProbeOption:
    """One field of a sensor's rig-file tables as a probe option: ``--can-channel``, or the field's ``cli`` name."""

    field: str
    info: FieldInfo
    tables: tuple[type[SensorConfigBase], ...]  # the tables that have this field

    @property
    def flag(self) -> str:
        return str(field_flag(self.field, self.info))

    def parameter(self) -> inspect.Parameter:
        """The option, unset by default (the table's own default applies), grouped under its table's ``type``; the
        field's ge / le are the range the help shows and typer checks."""
        annotation: Any = self.info.annotation
        if get_origin(annotation) is Literal:
            annotation = type(get_args(annotation)[0])
        kind: Any = annotation if annotation in (str, int, float, bool) else str
        bounds = field_bounds(self.info)
        default = None if self.info.is_required() else self.info.default
        option = typer.Option(
            None,
            self.flag,
            help=self.info.description or "",
            show_default=False if default is None else str(default),
            rich_help_panel=None if len(self.tables) > 1 else str(self.tables[0].model_fields["type"].default),
            min=bounds.get("ge"),
            max=bounds.get("le"),
        )
        return inspect.Parameter(self.field, inspect.Parameter.KEYWORD_ONLY, default=option, annotation=kind | None)


def probe_options(spec: SensorSpec) -> dict[str, ProbeOption]:
    """The probe options of a sensor: every field of every rig-file table it accepts (``type`` aside), by name."""
    tables: dict[str, list[type[SensorConfigBase]]] = {}
    for table in spec.config_types:
        for name in table.model_fields:
            if name != "type":
                tables.setdefault(name, []).append(table)
    return {name: ProbeOption(name, found[0].model_fields[name], tuple(found)) for name, found in tables.items()}


def _choose_table(spec: SensorSpec, given: Mapping[str, Any], simulated: bool) -> type[SensorConfigBase] | None:
    """The rig-file table the given options describe: the one holding all of them. None when several would do and
    the device is simulated (its simulated side reads the options itself)."""
    options = probe_options(spec)
    tables = [t for t in spec.config_types if set(given) <= set(t.model_fields)]
    routes = " or ".join("/".join(o.flag for o in options.values() if t in o.tables) for t in spec.config_types)
    if not tables:
        raise UsageError(f"give the options of one {spec.name} connection, not of two", hint=f"use {routes}")
    if len(tables) == 1:
        return tables[0]
    if simulated:
        return None
    raise UsageError(
        f"probe {spec.name} needs {routes}", hint="name the connection, or add --simulated to try it without hardware"
    )


def _config(spec: SensorSpec, table: type[SensorConfigBase], given: Mapping[str, Any]) -> SensorConfigBase:
    """The rig-file table the options describe, validated as the rig file is (a bad value names its option)."""
    options = probe_options(spec)
    try:
        return table.model_validate({"type": table.model_fields["type"].default, **given})
    except ValidationError as exc:
        error = exc.errors()[0]
        option = options.get(str(error["loc"][0])) if error["loc"] else None
        flag = option.flag if option is not None else str(error["loc"])
        if error["type"] == "missing":
            raise UsageError(
                f"probe {spec.name} needs {flag}", hint="or add --simulated to try it without hardware"
            ) from None
        raise UsageError(f"{flag}: {error['msg']}") from None


def probe_sensor(
    spec: SensorSpec, given: Mapping[str, Any], frames: int, as_json: bool, timeout: float, simulated: bool
) -> None:
    """Read ``frames`` frames from the sensor the options (fields of its rig-file tables) point at, or from its
    simulated device; print them as a taxel map or JSON lines."""
    from drivers.clock import MonotonicClock

    table = _choose_table(spec, given, simulated)
    with contextlib.ExitStack() as stack:
        if simulated:  # the real driver on the simulated device, streaming a synthetic press (sim/fast_sensors.py)
            probe = getattr(spec.simulated_device(), "probe", None)
            if not callable(probe):
                raise UsageError(f"sensor {spec.name!r} has no simulated device to probe", hint="probe the hardware")
            driver = probe(given, stack)  # set up as the options given say; the stack closes the device
        else:
            assert table is not None
            driver = spec.open_driver(_config(spec, table, given), MonotonicClock())
            stack.callback(driver.disconnect)  # closes the transport even if connect() fails
        _run_probe(driver, spec.layout, frames, as_json, timeout)


class _SensorProbeInfo(CommandInfo):
    """A ``probe <sensor>`` command built from the sensor registry (told apart from the fixed device commands)."""


@functools.lru_cache(maxsize=32)
def sensor_probe_command(spec: SensorSpec) -> CommandInfo:
    """``probe <sensor>``: its options are the fields of the sensor's rig-file tables, plus the common ones."""
    options = probe_options(spec)

    def command(frames: int, as_json: bool, timeout: float, simulated: bool, **values: Any) -> None:
        given = {name: value for name, value in values.items() if value is not None}
        probe_sensor(spec, given, frames, as_json, timeout, simulated)

    keyword = inspect.Parameter.KEYWORD_ONLY
    parameters = [
        *(option.parameter() for option in options.values()),
        inspect.Parameter("frames", keyword, default=FRAMES_OPTION, annotation=int),
        inspect.Parameter("as_json", keyword, default=JSON_OPTION, annotation=bool),
        inspect.Parameter("timeout", keyword, default=TIMEOUT_OPTION, annotation=float),
        inspect.Parameter("simulated", keyword, default=SIMULATED_OPTION, annotation=bool),
    ]
    command.__signature__ = inspect.Signature(parameters)  # type: ignore[attr-defined]
    command.__annotations__ = {p.name: p.annotation for p in parameters}
    layout = spec.layout
    tables = " or ".join(f"[{t.model_fields['type'].default}]" for t in spec.config_types)
    units = "raw counts" if layout.units == "counts" else f"forces in {layout.units}"
    units += ", displacements in mm" if layout.has_displacement else ""
    text = (
        f"Read frames from a {layout.model} ({units}). The options are those of its rig-file table "
        f"[sensors.{spec.name}], one connection: {tables}."
    )
    return _SensorProbeInfo(name=spec.name, callback=command, cls=PlainCommand, help=text)


class _ProbeApp(typer.Typer):
    """The ``probe`` group: a command per registered sensor, read from the registry whenever the CLI is built (so a
    sensor added to the registry is probed with no edit here), then the device commands registered on it
    (``ur5e``)."""

    @property
    def registered_commands(self) -> list[CommandInfo]:
        devices = [c for c in self._commands if not isinstance(c, _SensorProbeInfo)]
        self._commands[:] = [*(sensor_probe_command(spec) for spec in SENSORS.values()), *devices]
        return self._commands

    @registered_commands.setter
    def registered_commands(self, value: list[CommandInfo]) -> None:
        self._commands = value


probe_app = _ProbeApp(
    name="probe",
    help="Read a few frames from one device (a registered tactile sensor, or the UR5e) to check it is connected.",
    no_args_is_help=True,
)

register_ur5e(probe_app)
