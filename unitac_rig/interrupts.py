"""Interrupts that cannot be lost, and that never land inside someone else's lock.

Python raises KeyboardInterrupt at the next bytecode after SIGINT arrives. That bytecode may belong to any code:

* code that clears exceptions (h5py's compiled object clean-up is one: measured, a Ctrl-C during a tight HDF5 read
  loop was dropped in 8 of 60 tries), so the interrupt is lost and a collection carries on;
* a library between taking a lock and entering the block that releases it (``queue.Queue`` under python-can's
  virtual bus is one: measured, 1 of 24 Ctrl-Cs at random moments left its lock held, and the arm-stop path then
  waited on it forever, so the process hung instead of exiting).

So while a command moves the arm the CLI's handlers *defer*: they note the interrupt here and return, and the loops
that run for long (each control period of a press or a transit move, each press of a session, each reconnection
poll) call :func:`raise_if_interrupted`, which raises it at a point of our own, within one control period. Two
exceptions make it raise at once: inside :func:`immediate_interrupts` (a blocking prompt, which polls nothing), and
on a second signal while the first is still noted (something between two polls is stuck: the operator's second
Ctrl-C always gets through). This module imports nothing from the project, so every layer may call it.

The handlers live here too (the CLI opens their scopes). Python turns SIGINT into KeyboardInterrupt, so every
``finally`` runs and the arm is stopped, but SIGTERM (``kill``, a service manager, a batch system) and SIGHUP (the
SSH session or terminal closed) end the process at once by default: no ``finally``, no stop command, the partial press
lost. Inside :func:`termination_as_interrupt` both become :class:`Terminated`, a KeyboardInterrupt in the main
thread, so they take exactly the Ctrl-C path; :func:`stop_on_signals` turns all three into an event for serving loops
that move no arm. (``unitac_rig.launch``, the console entry point, notes a Ctrl-C while the application imports.)
"""

from __future__ import annotations

import contextlib
import signal
import threading
from collections.abc import Callable, Iterator
from types import FrameType

_noted: list[int] = []
_acknowledged = [0]  # how many of the noted interrupts are being handled (see acknowledged_interrupts)
_immediate_depth = [0]  # how many immediate_interrupts() scopes are open (a list: mutable without `global`)


class Terminated(KeyboardInterrupt):
    """SIGTERM or SIGHUP arrived; ``signal_number`` says which (the CLI exits with 128 + it)."""

    def __init__(self, signal_number: int) -> None:
        super().__init__(f"terminated by {signal.Signals(signal_number).name}")
        self.signal_number = signal_number


def note_interrupt(signal_number: int) -> None:
    """Remember that ``signal_number`` (SIGINT, SIGTERM, SIGHUP) arrived; called by the CLI's handlers."""
    _noted.append(signal_number)


def interrupt_for(signal_number: int) -> KeyboardInterrupt:
    """The exception an interrupt is raised as: KeyboardInterrupt for SIGINT, :class:`Terminated` otherwise."""
    return KeyboardInterrupt() if signal_number == signal.SIGINT else Terminated(signal_number)


def raise_if_interrupted() -> None:
    """Raise the noted interrupt again (a process that was interrupted stays interrupted); else do nothing.

    Inside :func:`acknowledged_interrupts` only an interrupt noted after entry raises."""
    if len(_noted) > _acknowledged[0]:
        raise interrupt_for(_noted[-1])


@contextlib.contextmanager
def acknowledged_interrupts() -> Iterator[None]:
    """The interrupts noted so far are being handled for the duration: polls do not raise them again.

    For the clean-up an interrupt asks for (the arm pulling the pad off the object before the process exits): its
    moves poll :func:`raise_if_interrupted` like any other, and a *new* interrupt (the operator's second Ctrl-C)
    still raises, at once, and ends the clean-up with the arm stopped."""
    saved = _acknowledged[0]
    _acknowledged[0] = len(_noted)
    try:
        yield
    finally:
        _acknowledged[0] = saved


def forget_interrupts() -> None:
    """Clear the noted interrupts (tests, and a handler scope that ends without one)."""
    _noted.clear()
    _acknowledged[0] = 0


@contextlib.contextmanager
def immediate_interrupts() -> Iterator[None]:
    """Interrupts raise the moment they arrive for the duration (a prompt waiting for the operator polls nothing);
    one noted before entry is raised on entry."""
    raise_if_interrupted()
    _immediate_depth[0] += 1
    try:
        yield
    finally:
        _immediate_depth[0] -= 1


TERMINATION_SIGNALS = (signal.SIGTERM, signal.SIGHUP)

_received: list[int] = []  # termination signals this process received (typer hides the exception: see app.main)
_deferring = [False]  # whether the open termination_as_interrupt scope defers (a list: mutable without `global`)


def _on_signal(signal_number: int, frame: FrameType | None) -> None:
    """Note the interrupt; raise it here only when not deferring, inside :func:`immediate_interrupts` (a prompt), or
    when an earlier interrupt is still noted (a repeated Ctrl-C: something between two polls is stuck)."""
    if signal_number != signal.SIGINT:
        _received.append(signal_number)
    note_interrupt(signal_number)  # also when raised: in case the exception gets swallowed
    if not _deferring[0] or _immediate_depth[0] > 0 or len(_noted) > 1:
        raise interrupt_for(signal_number)


@contextlib.contextmanager
def _handled_by(handler: Callable[[int, FrameType | None], None]) -> Iterator[None]:
    """``handler`` takes SIGINT, SIGTERM and SIGHUP for the duration; the previous handlers are restored after."""
    previous = {sig: signal.signal(sig, handler) for sig in (signal.SIGINT, *TERMINATION_SIGNALS)}
    try:
        yield
    finally:
        for sig, old in previous.items():
            signal.signal(sig, old)


def last_termination_signal() -> int | None:
    """The last SIGTERM / SIGHUP received inside :func:`termination_as_interrupt`, if any."""
    return _received[-1] if _received else None


@contextlib.contextmanager
def termination_as_interrupt(*, defer: bool = True) -> Iterator[None]:
    """Turn SIGTERM and SIGHUP into :class:`Terminated` for the duration, and note SIGINT, so
    :func:`raise_if_interrupted` raises them at the control loop's next poll (``defer``; a
    command that moves the arm) or so it can raise one that compiled code swallowed (not ``defer``: raised at once,
    as Python does). Main thread only; elsewhere a no-op."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    was_deferring, _deferring[0] = _deferring[0], defer
    try:
        with _handled_by(_on_signal):
            yield
            raise_if_interrupted()  # one that arrived after the last poll still ends the command as interrupted
    finally:
        _deferring[0] = was_deferring
        forget_interrupts()  # the interrupt (if any) has propagated; nothing after the scope may see it again


class StopRequest(threading.Event):
    """Set by the first Ctrl-C, SIGTERM or SIGHUP; ``signal_number`` says which (None while unset)."""

    signal_number: int | None = None


@contextlib.contextmanager
def stop_on_signals() -> Iterator[StopRequest]:
    """An event that Ctrl-C, SIGTERM and SIGHUP set for the duration, instead of raising: a serving loop that moves
    no arm (``twin``, ``stream``) polls it and ends cleanly, closing what it opened, and may then end the command
    as interrupted (``raise interrupt_for(stop.signal_number)``: exit 130, or 128 + the signal). Main thread only."""
    stop = StopRequest()

    def on_signal(signal_number: int, frame: FrameType | None) -> None:
        if stop.signal_number is None:
            stop.signal_number = signal_number
            if signal_number != signal.SIGINT:
                _received.append(signal_number)  # the CLI's exit status names it (see app.main)
        stop.set()

    with _handled_by(on_signal):
        yield stop


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
