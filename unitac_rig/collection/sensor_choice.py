"""Which sensor a collect run uses: the one the operator names, the one that answers on hardware, or, on the
simulated rig (which can mount any of them), the first sensor in registry order whose session is not complete yet."""

from __future__ import annotations

import logging
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

from unitac_rig.errors import UsageError
from unitac_rig.rig.base import Rig
from unitac_rig.rig.sensors import SENSORS, get_sensor
from unitac_rig.storage.press_record import FINISHED_STATUSES
from unitac_rig.storage.reader import press_summaries, read_session_info
from unitac_rig.storage.recorder import session_path

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class SensorChoice:
    """The sensor to collect with, and how it was chosen (the CLI tells the operator)."""

    name: str
    how: Literal["named", "detected", "next-incomplete"]


def collection_order(rig: Rig) -> list[str]:
    """The rig's sensors in registry order (a campaign mounts them in this order)."""
    available = set(rig.sensor_names())
    return [name for name in SENSORS if name in available]


def session_presses(data_dir: Path, object_id: str, sensor: str) -> tuple[set[str], list[str]] | None:
    """(the finished presses' ids, the planned ones) of a session, read back from its file; None when there is no
    readable file (none yet, or mid-recovery: the journal keeps what was pressed and the next collect repairs it)."""
    path = session_path(data_dir, object_id, sensor)
    if not path.exists():
        return None
    try:
        presses = press_summaries(path)
        planned = list(read_session_info(path).attrs.get("planned_presses", []))
    except Exception as exc:
        log.info("%s cannot be read yet: %s", path, exc)
        return None
    return {p["press_id"] for p in presses if p["status"] in FINISHED_STATUSES}, planned


def session_complete(data_dir: Path, object_id: str, sensor: str) -> bool:
    """True when the session file holds a finished press for every press it planned."""
    found = session_presses(data_dir, object_id, sensor)
    return found is not None and bool(found[1]) and set(found[1]) <= found[0]


def choose_sensor(rig: Rig, object_id: str, sensor: str | None, data_dir: Path) -> SensorChoice:
    """The sensor to collect ``object_id`` with; a usage error when the named one is unknown or not on this rig.

    On hardware a named sensor must be the one streaming (checked before the arm moves), and an unnamed one is
    detected; the simulated rig mounts the first sensor without a complete session in ``data_dir``.
    """
    if sensor is not None:
        get_sensor(sensor)  # unknown names fail here, listing the registered ones
        if sensor not in rig.sensor_names():
            raise UsageError(
                f"sensor {sensor!r} is not configured on this rig",
                hint=f"configured: {', '.join(rig.sensor_names())}",
            )
        if not rig.simulated:
            rig.check_sensor(sensor)
        return SensorChoice(sensor, "named")
    if not rig.simulated:
        return SensorChoice(rig.detect_sensor(), "detected")
    for name in collection_order(rig):
        if not session_complete(data_dir, object_id, name):
            return SensorChoice(name, "next-incomplete")
    raise UsageError(
        f"every simulated sensor already has a complete session for {object_id} in {data_dir}",
        hint="use --sensor to redo one into another --data directory, or run `unitac-rig inspect`",
    )
