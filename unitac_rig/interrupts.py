"""Interrupts that cannot be lost.

Python raises KeyboardInterrupt at the next bytecode after SIGINT arrives. When that bytecode belongs to code that
clears exceptions (h5py's compiled object clean-up is one: measured, a Ctrl-C during a tight HDF5 read loop was
dropped in 8 of 60 tries), the interrupt is lost and a collection carries on as if nobody had pressed Ctrl-C.

So the CLI's signal handlers also *note* every interrupt here, and the loops that run for long (each control period
of a press or a transit move, each press of a session, each refresh of ``inspect --watch``) call
:func:`raise_if_interrupted`: an interrupt that was swallowed is raised again within one control period. This module
imports nothing from the project, so every layer may call it.
"""

from __future__ import annotations

import signal

_noted: list[int] = []


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
    """Raise the noted interrupt again (a process that was interrupted stays interrupted); else do nothing."""
    if _noted:
        raise interrupt_for(_noted[-1])


def forget_interrupts() -> None:
    """Clear the noted interrupts (tests, and a handler scope that ends without one)."""
    _noted.clear()
