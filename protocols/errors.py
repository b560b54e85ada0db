"""Root of the project's one exception tree.

Every error the project raises on purpose derives from :class:`UnitacError`, so the CLI can turn any of them into
one clear line. It lives in ``protocols`` because that is the bottom layer every other layer may import.
"""

from typing import Any


class CarriesPressRecord:
    """An exception that hands its catcher what was recorded before it was raised.

    The press routine stops the arm, then re-raises with the aborted press's record
    (``unitac_rig.storage.press_record.PressRecord``) here, so the session can still save it. None when nothing was
    recorded. Every :class:`UnitacError` has it; ``unitac_rig.errors.Interrupted`` is the Ctrl-C that does.
    """

    press_record: Any = None


class UnitacError(CarriesPressRecord, Exception):
    """Base class for all errors raised by unitac-rig on purpose.

    ``hint`` is an optional short sentence telling the user what to do about it.
    """

    def __init__(self, message: str, *, hint: str | None = None) -> None:
        super().__init__(message)
        self.hint = hint

    def one_line(self) -> str:
        text = str(self)
        return f"{text} ({self.hint})" if self.hint else text


class ProtocolError(UnitacError):
    """Bytes or messages that do not follow a device's wire format."""
