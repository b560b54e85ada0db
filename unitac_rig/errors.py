"""The application's exception tree (rooted in :class:`protocols.errors.UnitacError`)."""

from typing import Any

from drivers.errors import ArmError as ArmError
from drivers.errors import DeviceError as DeviceError
from drivers.errors import DeviceNotFound as DeviceNotFound
from drivers.errors import DeviceTimeout as DeviceTimeout
from drivers.errors import ProtectiveStop as ProtectiveStop
from protocols.errors import CarriesPressRecord, UnitacError
from protocols.errors import ProtocolError as ProtocolError


class ConfigError(UnitacError):
    """A rig file, object file or option that is malformed or contradictory."""


class UsageError(UnitacError):
    """A command asked for something that does not exist (unknown object, sensor, run...)."""


class DataError(UnitacError):
    """A dataset directory or session file that cannot be used (wrong version, broken, empty join)."""


class SafetyLimit(UnitacError):
    """A force, travel or workspace limit stopped the motion."""


class SessionStopped(UnitacError):
    """A session or campaign ended before its plan was done (nothing pressed, failures in a row): a runtime failure
    (exit 1), resumable by the same command."""


class ModelError(UnitacError):
    """A trained model cannot do what was asked (unknown sensor, incompatible checkpoint)."""


class Interrupted(CarriesPressRecord, KeyboardInterrupt):
    """Ctrl-C during a press, re-raised once the arm stopped, with the press recorded so far (still a
    KeyboardInterrupt: nothing that catches ``Exception`` swallows it)."""


def with_press_record(exc: BaseException, record: Any) -> BaseException:
    """``exc`` carrying ``record`` for its catcher: a project error keeps it in ``press_record``; a Ctrl-C becomes
    :class:`Interrupted` (caused by the original); any other exception is returned unchanged (nobody keeps it)."""
    if isinstance(exc, CarriesPressRecord):
        exc.press_record = record
        return exc
    if isinstance(exc, KeyboardInterrupt):
        interrupted = Interrupted(*exc.args)
        interrupted.press_record = record
        interrupted.__cause__ = exc
        return interrupted
    return exc
