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
"""

from __future__ import annotations

import contextlib
import signal
from collections.abc import Iterator

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


def noted_interrupt() -> int | None:
    """The last interrupt noted in this process, if any."""
    return _noted[-1] if _noted else None


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
    still raises, at once (:func:`raise_at_once`), and ends the clean-up with the arm stopped."""
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


def raise_at_once() -> bool:
    """Whether a handler should raise the interrupt it just noted rather than defer it: inside
    :func:`immediate_interrupts`, or when an earlier interrupt is still noted (a repeated Ctrl-C)."""
    return _immediate_depth[0] > 0 or len(_noted) > 1


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
