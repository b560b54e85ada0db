"""Interrupts while a command moves the arm (unitac_rig/interrupts.py).

* Deferred: a Ctrl-C (or SIGTERM) is noted and raised at the next check of the control loop, never inside whatever
  the main thread is running (raised inside python-can's virtual-bus queue it once left a lock held and the stop
  path hung); a second one, or one during a prompt, raises at once.
* Not lost: h5py drops a KeyboardInterrupt raised inside some of its calls (measured: 8 of 60 Ctrl-Cs into a tight
  HDF5 read loop were lost); one swallowed there is raised again at the next check.
"""

from __future__ import annotations

import os
import signal
import time

import pytest

from unitac_rig.interrupts import Terminated, immediate_interrupts, raise_if_interrupted, termination_as_interrupt


def _deliver(sig: int) -> None:
    """Send ``sig`` to this process and give the handler time to run (it runs at the next bytecode)."""
    os.kill(os.getpid(), sig)
    time.sleep(0.05)


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
    with pytest.raises(KeyboardInterrupt), termination_as_interrupt(defer=False):
        _swallowed(signal.SIGINT)
        with pytest.raises(KeyboardInterrupt) as caught:
            raise_if_interrupted()
        assert not isinstance(caught.value, Terminated)
        with pytest.raises(KeyboardInterrupt):  # and at every later check: an interrupted process stays interrupted
            raise_if_interrupted()
        # leaving the scope with the interrupt still noted raises it once more
    raise_if_interrupted()  # outside the scope nothing is left over (tests calling the CLI in-process)


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGHUP])
def test_a_swallowed_termination_signal_comes_back_as_terminated_with_its_number(sig: signal.Signals) -> None:
    with pytest.raises(Terminated) as at_exit, termination_as_interrupt(defer=False):
        _swallowed(sig)
        with pytest.raises(Terminated) as caught:
            raise_if_interrupted()
    assert caught.value.signal_number == at_exit.value.signal_number == sig  # the CLI exits with 128 + it


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM])
def test_while_the_arm_moves_an_interrupt_waits_for_the_next_check(sig: signal.Signals) -> None:
    reached = []
    with pytest.raises(KeyboardInterrupt) as caught, termination_as_interrupt():
        _deliver(sig)
        reached.append("after the signal")  # not raised where the main thread happened to be
        raise_if_interrupted()  # the control loop's check
        reached.append("after the check")
    assert reached == ["after the signal"]
    assert isinstance(caught.value, Terminated) == (sig == signal.SIGTERM)


def test_a_second_ctrl_c_gets_through_at_once() -> None:
    # the first one is waiting for a check that does not come (something between two checks is stuck)
    reached = []
    with pytest.raises(KeyboardInterrupt), termination_as_interrupt():
        _deliver(signal.SIGINT)
        reached.append("first deferred")
        _deliver(signal.SIGINT)
        reached.append("second deferred")
    assert reached == ["first deferred"]


def test_a_prompt_is_interrupted_at_once_and_an_earlier_interrupt_on_entering_it() -> None:
    reached = []
    with pytest.raises(KeyboardInterrupt), termination_as_interrupt(), immediate_interrupts():
        _deliver(signal.SIGINT)
        reached.append("inside the prompt")
    assert reached == []
    with pytest.raises(KeyboardInterrupt), termination_as_interrupt():
        _deliver(signal.SIGINT)
        with immediate_interrupts():
            reached.append("entered")
    assert reached == []


def test_an_interrupt_after_the_last_check_still_ends_the_scope() -> None:
    # e.g. Ctrl-C while the session's summary is written: the command must still end as interrupted
    with pytest.raises(KeyboardInterrupt), termination_as_interrupt():
        _deliver(signal.SIGINT)
    raise_if_interrupted()  # and nothing is left over after it
