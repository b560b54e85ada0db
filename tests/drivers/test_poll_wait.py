"""``PumpedSensor.poll_wait``: a live reader (``unitac-rig stream``) is woken by the frame itself, on the reader
thread or on its own thread, and a reader-thread failure reaches it at once instead of after the timeout."""

from __future__ import annotations

import queue
import threading

import numpy as np
import pytest

from drivers.errors import DeviceError
from drivers.frames import TactileFrame
from drivers.layouts import PAPILLARRAY
from drivers.sensor_base import PumpedSensor

LONG_S = 120.0  # how long a poll_wait may wait; a reader not woken by the frame is still waiting at LONG_S / 2


class QueueDriver(PumpedSensor):
    """Delivers what the test puts in ``feed``: a frame, or an exception to raise (a port that went away)."""

    def __init__(self) -> None:
        super().__init__(
            PAPILLARRAY,
            clock=None,
            stall_timeout_s=600.0,
            thread_name="queue-driver",
            is_saturated=lambda v: np.zeros(len(v), bool),
        )
        self.feed: queue.Queue[object] = queue.Queue()

    def _open(self) -> None:
        pass

    def _close(self) -> None:
        pass

    def _pump(self, wait_s: float) -> list[TactileFrame]:
        try:
            item = self.feed.get(timeout=wait_s) if wait_s > 0 else self.feed.get_nowait()
        except queue.Empty:
            return []
        if isinstance(item, BaseException):
            raise item
        assert isinstance(item, int)
        return [TactileFrame(sensor="papillarray", host_t_ns=self.clock.now_ns(), values=np.zeros((9, 3)), seq=item)]


@pytest.fixture
def driver() -> QueueDriver:
    sensor = QueueDriver()
    sensor.connect()
    yield sensor  # type: ignore[misc]
    sensor.disconnect()


def test_with_a_reader_thread_the_waiting_reader_gets_each_frame_when_it_is_queued(driver: QueueDriver) -> None:
    driver.start_reader()
    got: list[int] = []
    for seq in range(20):
        driver.feed.put(seq)
        frames = driver.poll_wait(LONG_S)
        while not frames:  # never: a wait ends with the frame that woke it
            frames = driver.poll_wait(LONG_S)
        got += [f.seq for f in frames if f.seq is not None]
    assert got == list(range(20))


def test_a_reader_waiting_on_an_empty_queue_is_woken_by_the_next_frame(driver: QueueDriver) -> None:
    driver.start_reader()
    result: list[list[TactileFrame]] = []
    waiting = threading.Thread(target=lambda: result.append(driver.poll_wait(LONG_S)), name="waiting-reader")
    waiting.start()
    driver.feed.put(7)
    waiting.join(LONG_S / 2)
    assert not waiting.is_alive(), "poll_wait slept through the frame"
    assert [f.seq for f in result[0]] == [7]


def test_without_a_reader_thread_it_pumps_on_the_callers_thread(driver: QueueDriver) -> None:
    driver.feed.put(3)
    assert [f.seq for f in driver.poll_wait(LONG_S)] == [3]
    assert driver.poll_wait(0.0) == []
    assert driver.health().frames == 1


def test_a_failing_reader_thread_wakes_the_waiting_reader_with_its_error(driver: QueueDriver) -> None:
    driver.start_reader()
    errors: list[BaseException] = []

    def wait() -> None:
        try:
            for _ in range(3):  # the error may land between two waits; it is never lost
                driver.poll_wait(LONG_S)
        except DeviceError as exc:
            errors.append(exc)

    waiting = threading.Thread(target=wait, name="waiting-reader")
    waiting.start()
    driver.feed.put(DeviceError("port went away"))
    waiting.join(LONG_S / 2)
    assert not waiting.is_alive(), "poll_wait slept through the reader's failure"
    assert [str(e) for e in errors] == ["port went away"]
