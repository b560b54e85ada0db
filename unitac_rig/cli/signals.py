"""Termination signals handled like Ctrl-C while a command moves the arm.

Python turns SIGINT into KeyboardInterrupt, so every ``finally`` runs and the arm is stopped, but SIGTERM (``kill``,
a service manager, a batch system) and SIGHUP (the SSH session or terminal closed) end the process at once by default:
no ``finally``, no stop command, the partial press lost. Only the controller's watchdog would stop the arm then.
Inside :func:`termination_as_interrupt` both raise :class:`Terminated`, a KeyboardInterrupt, where the main thread is,
so they take exactly the Ctrl-C path: the arm is stopped, what was recorded is kept, the same command resumes.
"""

from __future__ import annotations

import contextlib
import signal
import threading
from collections.abc import Iterator
from types import FrameType

from unitac_rig.interrupts import Terminated, forget_interrupts, note_interrupt

TERMINATION_SIGNALS = (signal.SIGTERM, signal.SIGHUP)

_received: list[int] = []  # termination signals this process received (typer hides the exception: see app.main)


def _raise_terminated(signal_number: int, frame: FrameType | None) -> None:
    _received.append(signal_number)
    note_interrupt(signal_number)
    raise Terminated(signal_number)


def _raise_keyboard_interrupt(signal_number: int, frame: FrameType | None) -> None:
    note_interrupt(signal_number)  # Python's own handler, plus a note in case the exception gets swallowed
    raise KeyboardInterrupt


def last_termination_signal() -> int | None:
    """The last SIGTERM / SIGHUP received inside :func:`termination_as_interrupt`, if any."""
    return _received[-1] if _received else None


@contextlib.contextmanager
def termination_as_interrupt() -> Iterator[None]:
    """Turn SIGTERM and SIGHUP into :class:`Terminated` for the duration, and note SIGINT as well as raising it, so
    :func:`unitac_rig.interrupts.raise_if_interrupted` can raise an interrupt that compiled code swallowed (main
    thread only; elsewhere a no-op)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = {sig: signal.signal(sig, _raise_terminated) for sig in TERMINATION_SIGNALS}
    previous[signal.SIGINT] = signal.signal(signal.SIGINT, _raise_keyboard_interrupt)
    try:
        yield
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)
        forget_interrupts()  # the interrupt (if any) has propagated; nothing after the scope may see it again


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
