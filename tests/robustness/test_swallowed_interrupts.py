"""A Ctrl-C (or SIGTERM) that compiled code swallows is raised again at the next check (unitac_rig/interrupts.py).

h5py drops a KeyboardInterrupt raised inside some of its calls (measured: 8 of 60 Ctrl-Cs into a tight HDF5 read
loop were lost); a collection then carried on to the end with exit status 0.
"""

from __future__ import annotations

import os
import signal
import time

import pytest

from unitac_rig.cli.signals import termination_as_interrupt
from unitac_rig.interrupts import Terminated, raise_if_interrupted


def _swallowed(sig: int) -> None:
    """Deliver ``sig`` to this process inside code that drops every exception, as h5py's clean-up does."""
    try:
        os.kill(os.getpid(), sig)
        time.sleep(0.5)  # the handler runs here and raises
    except BaseException:  # the point of the test: the exception is lost here
        pass


def test_nothing_is_raised_without_an_interrupt() -> None:
    with termination_as_interrupt():
        raise_if_interrupted()


def test_a_swallowed_ctrl_c_is_raised_at_the_next_check_and_forgotten_after_the_scope() -> None:
    with termination_as_interrupt():
        _swallowed(signal.SIGINT)
        with pytest.raises(KeyboardInterrupt) as caught:
            raise_if_interrupted()
        assert not isinstance(caught.value, Terminated)
        with pytest.raises(KeyboardInterrupt):  # and at every later check: an interrupted process stays interrupted
            raise_if_interrupted()
    raise_if_interrupted()  # outside the scope nothing is left over (tests calling the CLI in-process)


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGHUP])
def test_a_swallowed_termination_signal_comes_back_as_terminated_with_its_number(sig: signal.Signals) -> None:
    with termination_as_interrupt():
        _swallowed(sig)
        with pytest.raises(Terminated) as caught:
            raise_if_interrupted()
    assert caught.value.signal_number == sig  # the CLI exits with 128 + it
