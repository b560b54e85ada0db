"""Suite-wide fixtures: every test must leave no thread, CAN bus, serial port or socket behind."""

from __future__ import annotations

import threading
import time
from collections.abc import Iterator

import pytest


def _live_threads() -> set[threading.Thread]:
    return {t for t in threading.enumerate() if t is not threading.main_thread() and t.is_alive()}


@pytest.fixture(autouse=True)
def no_leaked_threads() -> Iterator[None]:
    """Fail a test that leaves a reader thread, simulator thread or server running."""
    before = _live_threads()
    yield
    deadline = time.monotonic() + 2.0
    leaked = _live_threads() - before
    while leaked and time.monotonic() < deadline:
        time.sleep(0.02)
        leaked = {t for t in leaked if t.is_alive()}
    # Threads owned by libraries' global pools are not ours to judge.
    leaked = {t for t in leaked if not t.name.startswith(("asyncio_", "ThreadPoolExecutor", "pydevd"))}
    assert not leaked, f"test left threads running: {sorted(t.name for t in leaked)}"
