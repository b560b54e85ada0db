"""Device-level errors; all derive from :class:`protocols.errors.UnitacError`."""

from protocols.errors import UnitacError


class DeviceError(UnitacError):
    """A device misbehaved or could not be used."""


class DeviceNotFound(DeviceError):
    """The port, CAN channel or host named in the configuration is not there."""


class DeviceTimeout(DeviceError):
    """A device stopped sending (stall) or did not answer in time."""


class ArmError(DeviceError):
    """The robot arm refused a command or reported a fault."""


class ProtectiveStop(ArmError):
    """The robot controller entered a protective (or emergency) stop."""
