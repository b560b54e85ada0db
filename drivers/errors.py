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


class ControlScriptStopped(ArmError):
    """The control program on the robot controller is not running, so it refuses every command.

    It stops when the RTDE watchdog sees no write from the host in time (a stalled or dead host), after a protective
    or emergency stop, or when someone stops it on the teach pendant.
    """


class RobotStateLost(ArmError, DeviceTimeout):
    """The robot's state stream (RTDE) stalled or dropped: the host can no longer see what the arm does."""
