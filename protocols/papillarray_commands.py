"""Contactile PapillArray Controller v2.0 commands (PTS v2.0 protocol): the host's ASCII lines to the controller.

Host -> controller, ASCII, newline-terminated: ``z`` bias (tare, takes up to 2 s, sensors unloaded), ``S`` start slip
detection, ``s`` stop and reset slip detection, ``f100`` / ``f250`` / ``f500`` / ``f1000`` set the sampling rate in Hz
(1000 Hz after power-up). The controller's binary stream packets are in :mod:`protocols.papillarray`.

Sources: Contactile PTSCOM 2.0 spec (commands), as summarised in the project's hardware facts (section 2).
Pure codec: no I/O, threads or clocks.
"""

from __future__ import annotations

import enum
import numbers
from dataclasses import dataclass

from protocols.errors import ProtocolError

VALID_RATES_HZ = (100, 250, 500, 1000)


class Command(enum.Enum):
    """Host -> controller commands (ASCII line without the newline; SET_RATE adds the rate in Hz)."""

    BIAS = "z"
    START_SLIP = "S"
    STOP_SLIP = "s"
    SET_RATE = "f"


@dataclass(frozen=True)
class HubCommand:
    """A parsed command line; ``rate_hz`` is set for SET_RATE only."""

    command: Command
    rate_hz: int | None = None


def encode_command(command: Command | HubCommand, rate_hz: int | None = None) -> bytes:
    """Bytes to write to the controller, e.g. ``b"z\\n"`` for BIAS, ``b"f500\\n"`` for SET_RATE at 500 Hz."""
    if isinstance(command, HubCommand):
        if rate_hz is None:
            rate_hz = command.rate_hz
        command = command.command
    if command is Command.SET_RATE:
        # an int, not a float or bool that compares equal: 250.0 would go out as "f250.0", which no hub reads
        if isinstance(rate_hz, bool) or not isinstance(rate_hz, numbers.Integral) or rate_hz not in VALID_RATES_HZ:
            raise ProtocolError(
                f"sampling rate {rate_hz!r} Hz is not supported", hint=f"use one of {VALID_RATES_HZ} Hz"
            )
        return f"f{int(rate_hz)}\n".encode("ascii")
    if rate_hz is not None:
        raise ProtocolError(f"{command.name} takes no rate", hint="pass rate_hz only with SET_RATE")
    return f"{command.value}\n".encode("ascii")


_LINES: dict[bytes, HubCommand] = {
    b"z": HubCommand(Command.BIAS),
    b"S": HubCommand(Command.START_SLIP),
    b"s": HubCommand(Command.STOP_SLIP),
    **{f"f{rate}".encode("ascii"): HubCommand(Command.SET_RATE, rate) for rate in VALID_RATES_HZ},
}


class CommandParser:
    """Splits the host's byte stream into commands (used by the simulated hub).

    Lines end with ``\\n`` (a ``\\r`` before it is ignored); empty lines are skipped; any other line, including an
    unsupported rate, is counted in ``unknown_lines`` and dropped. A line longer than ``max_line_len`` bytes without
    a newline is dropped as unknown so garbage cannot grow the buffer.
    """

    def __init__(self, max_line_len: int = 32) -> None:
        self.max_line_len = max_line_len
        self._pending = bytearray()
        self._discarding = False  # inside an over-long line: drop until its newline
        self.commands = 0
        self.unknown_lines = 0

    def feed(self, data: bytes | bytearray | memoryview) -> list[HubCommand]:
        """Append received bytes; return the commands whose lines they completed."""
        self._pending += data
        out: list[HubCommand] = []
        *lines, rest = self._pending.split(b"\n")
        for raw in lines:
            if self._discarding:
                self._discarding = False
                continue
            line = bytes(raw).rstrip(b"\r")
            if not line:
                continue
            command = _LINES.get(line)
            if command is None:
                self.unknown_lines += 1
            else:
                self.commands += 1
                out.append(command)
        if len(rest) > self.max_line_len:
            if not self._discarding:
                self.unknown_lines += 1
            self._discarding = True
            rest = bytearray()
        self._pending = bytearray(rest)
        return out
