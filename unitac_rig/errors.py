"""The application's exception tree (rooted in :class:`protocols.errors.UnitacError`)."""

from drivers.errors import ArmError, DeviceError, DeviceNotFound, DeviceTimeout, ProtectiveStop
from protocols.errors import ProtocolError, UnitacError

__all__ = [
    "ArmError",
    "ConfigError",
    "DataError",
    "DeviceError",
    "DeviceNotFound",
    "DeviceTimeout",
    "ModelError",
    "ProtectiveStop",
    "ProtocolError",
    "SafetyLimit",
    "UnitacError",
    "UsageError",
]


class ConfigError(UnitacError):
    """A rig file, object file or option that is malformed or contradictory."""


class UsageError(UnitacError):
    """A command asked for something that does not exist (unknown object, sensor, run...)."""


class DataError(UnitacError):
    """A dataset directory or session file that cannot be used (wrong version, broken, empty join)."""


class SafetyLimit(UnitacError):
    """A force, travel or workspace limit stopped the motion."""


class ModelError(UnitacError):
    """A trained model cannot do what was asked (unknown sensor, incompatible checkpoint)."""
