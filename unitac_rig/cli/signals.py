"""Termination signals handled like Ctrl-C while a command moves the arm.

Python turns SIGINT into KeyboardInterrupt, so every ``finally`` runs and the arm is stopped, but SIGTERM (``kill``,
a service manager, a batch system) and SIGHUP (the SSH session or terminal closed) end the process at once by default:
no ``finally``, no stop command, the partial press lost. Only the controller's watchdog would stop the arm then.
Inside :func:`termination_as_interrupt` both become :class:`Terminated`, a KeyboardInterrupt in the main thread, so
they take exactly the Ctrl-C path: the arm is stopped, what was recorded is kept, the same command resumes.

While a command moves the arm the interrupt is deferred to the next poll of the control loop rather than raised
wherever the main thread happens to be (see :mod:`unitac_rig.interrupts`: an exception raised inside a library's
lock can hang the stop path); a second signal, or one during a prompt, raises at once.
"""

from __future__ import annotations

import contextlib
import signal
import threading
from collections.abc import Iterator
from types import FrameType

from unitac_rig.interrupts import (
    forget_interrupts,
    interrupt_for,
    note_interrupt,
    raise_at_once,
    raise_if_interrupted,
)

TERMINATION_SIGNALS = (signal.SIGTERM, signal.SIGHUP)

_received: list[int] = []  # termination signals this process received (typer hides the exception: see app.main)
_deferring = [False]  # whether the open termination_as_interrupt scope defers (a list: mutable without `global`)


def _on_signal(signal_number: int, frame: FrameType | None) -> None:
    """Note the interrupt; raise it here only when not deferring, inside a prompt, or on a repeated signal."""
    if signal_number != signal.SIGINT:
        _received.append(signal_number)
    note_interrupt(signal_number)  # also when raised: in case the exception gets swallowed
    if not _deferring[0] or raise_at_once():
        raise interrupt_for(signal_number)


def last_termination_signal() -> int | None:
    """The last SIGTERM / SIGHUP received inside :func:`termination_as_interrupt`, if any."""
    return _received[-1] if _received else None


@contextlib.contextmanager
def termination_as_interrupt(*, defer: bool = True) -> Iterator[None]:
    """Turn SIGTERM and SIGHUP into :class:`Terminated` for the duration, and note SIGINT, so
    :func:`unitac_rig.interrupts.raise_if_interrupted` raises them at the control loop's next poll (``defer``; a
    command that moves the arm) or so it can raise one that compiled code swallowed (not ``defer``: raised at once,
    as Python does). Main thread only; elsewhere a no-op."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = {sig: signal.signal(sig, _on_signal) for sig in (*TERMINATION_SIGNALS, signal.SIGINT)}
    was_deferring, _deferring[0] = _deferring[0], defer
    try:
        yield
        raise_if_interrupted()  # one that arrived after the last poll still ends the command as interrupted
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)
        _deferring[0] = was_deferring
        forget_interrupts()  # the interrupt (if any) has propagated; nothing after the scope may see it again


class StopRequest(threading.Event):
    """Set by the first Ctrl-C, SIGTERM or SIGHUP; ``signal_number`` says which (None while unset)."""

    signal_number: int | None = None


@contextlib.contextmanager
def stop_on_signals() -> Iterator[StopRequest]:
    """An event that Ctrl-C, SIGTERM and SIGHUP set for the duration, instead of raising: a serving loop that moves
    no arm (``twin``, ``stream``) polls it and ends cleanly, closing what it opened, and may then end the command
    as interrupted (``raise interrupt_for(stop.signal_number)``: exit 130, or 128 + the signal). The previous
    handlers are restored after. Main thread only."""
    stop = StopRequest()

    def on_signal(signal_number: int, frame: FrameType | None) -> None:
        if stop.signal_number is None:
            stop.signal_number = signal_number
            if signal_number != signal.SIGINT:
                _received.append(signal_number)  # the CLI's exit status names it (see app.main)
        stop.set()

    previous = {sig: signal.signal(sig, on_signal) for sig in (signal.SIGINT, *TERMINATION_SIGNALS)}
    try:
        yield stop
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)


def termination_signal(exc: BaseException) -> int | None:
    """The signal number behind an interrupt (also when it was re-raised wrapped, as its cause), else None."""
    seen: BaseException | None = exc
    for _ in range(8):
        if seen is None:
            return None
        number = getattr(seen, "signal_number", None)
        if isinstance(number, int):
            return number
        seen = seen.__cause__ or seen.__context__
    return None
