"""The sensor registry: ONE table of the tactile sensors the application knows, in the order collection mounts them.

Everything keyed by a sensor's name comes from here: its layout (taxel grid, pitch, units), the rig-file tables it
accepts, the hardware driver those open, and its simulated device on the fast twin. Adding a sensor is one module next
to :mod:`~unitac_rig.rig.sensors.uskin` (its config tables, driver factory and a :class:`SensorSpec` named ``SENSOR``)
and one entry in :data:`SENSORS`; see docs/architecture.md, "Adding a sensor".
"""

from __future__ import annotations

import functools
from typing import Annotated, Any, Union

from pydantic import Field, TypeAdapter

from drivers.layouts import SensorLayout
from unitac_rig.errors import UsageError
from unitac_rig.rig.sensors import papillarray, uskin
from unitac_rig.rig.sensors.base import DriverFactory, SensorConfigBase, SensorSpec, SyntheticResponse

__all__ = [
    "SENSORS",
    "DriverFactory",
    "SensorConfigBase",
    "SensorSpec",
    "SyntheticResponse",
    "get_sensor",
    "parse_sensor_config",
    "sensor_layout",
    "sensor_names",
]

#: sensor name -> spec. The order is the collection order: a simulated ``collect`` without ``--sensor`` mounts the
#: first sensor whose session is incomplete, and a campaign runs them in this order (the uSkin first, as the paper).
SENSORS: dict[str, SensorSpec] = {spec.name: spec for spec in (uskin.SENSOR, papillarray.SENSOR)}


def sensor_names() -> list[str]:
    """Every registered sensor, in collection order."""
    return list(SENSORS)


def get_sensor(name: str) -> SensorSpec:
    """The registered sensor called ``name``; a usage error listing the known ones otherwise."""
    try:
        return SENSORS[name]
    except KeyError:
        raise UsageError(f"unknown sensor {name!r}", hint=f"use one of: {', '.join(SENSORS)}") from None


def sensor_layout(name: str) -> SensorLayout:
    """The taxel layout of the registered sensor ``name``."""
    return get_sensor(name).layout


@functools.lru_cache(maxsize=8)
def _config_adapter(types: tuple[type[SensorConfigBase], ...]) -> TypeAdapter[Any]:
    if len(types) == 1:
        return TypeAdapter(types[0])
    union: Any = Union[types]  # noqa: UP007 - built at run time from the registry
    return TypeAdapter(Annotated[union, Field(discriminator="type")])


def parse_sensor_config(value: Any) -> SensorConfigBase:
    """Validate one ``[sensors.<name>]`` table against every registered sensor's tables (told apart by ``type``).

    Whether the table's type fits the sensor it is filed under is the rig file's check (it knows the name).
    """
    if isinstance(value, SensorConfigBase):
        return value
    types = tuple(t for spec in SENSORS.values() for t in spec.config_types)
    by_type = {t.model_fields["type"].default: t for t in types}
    tag = value.get("type") if isinstance(value, dict) else None
    if isinstance(tag, str) and tag in by_type:  # its own table alone: an error names sensors.<name>.<field>, not
        types = (by_type[tag],)  # the union's tag as well (sensors.papillarray.papillarray.port)
    result: SensorConfigBase = _config_adapter(types).validate_python(value)
    return result
