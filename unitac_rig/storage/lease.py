"""Who writes a session right now: an advisory ``flock`` on ``.journal/<object>__<sensor>/_writer.lock``.

Readers need no lock (the writer never changes a published file in place); every process that changes a session
(``collect``, ``campaign``, the importer, ``extract``) holds this one exclusively while it may write, since two
writers would each publish a copy without the other's latest press. The kernel drops it when the process dies, so
a crash never leaves a stale lease; the file's text (pid, host, command, start time) only serves the error message.
Inside one process a second writer of the same session takes the lease over from the first.
"""

from __future__ import annotations

import errno
import fcntl
import json
import logging
import os
import socket
import sys
import threading
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from unitac_rig.errors import DataError

log = logging.getLogger(__name__)

LEASE_NAME = "_writer.lock"
# A reader that probes the lease holds it (shared) for microseconds; a writer retries this long before it concludes
# that another writer holds the session, so a probe can never make a writer fail.
ACQUIRE_WAIT_S = 2.0
_RETRY_S = 0.02


@dataclass
class _Held:
    fd: int
    owner: object


_HELD: dict[str, _Held] = {}  # lock file path -> the lease this process holds on it
_GUARD = threading.Lock()


def _describe(info: dict[str, Any] | None) -> str:
    if not info:
        return "another process"
    since = time.strftime("%H:%M:%S", time.localtime(float(info.get("since_unix", 0.0))))
    return f"pid {info.get('pid', '?')} on {info.get('host', '?')}: {info.get('command', '?')}, since {since}"


def _read_info(fd: int) -> dict[str, Any] | None:
    try:
        raw = os.pread(fd, 4096, 0)
        info = json.loads(raw.decode("utf-8")) if raw else None
    except (OSError, ValueError):
        return None
    return info if isinstance(info, dict) else None


class SessionLease:
    """The exclusive right to change one session (its file and journal) while held."""

    def __init__(self, journal: Path, session: str) -> None:
        self.path = Path(journal) / LEASE_NAME
        self.session = session
        self._owner = object()

    def acquire(self, wait_s: float = ACQUIRE_WAIT_S, hint: str | None = None) -> None:
        """Take the lease, waiting up to ``wait_s`` seconds; raise DataError naming the holder if it stays taken."""
        key = str(self.path)
        with _GUARD:
            entry = _HELD.get(key)
            if entry is not None:  # this process already holds it through an older writer: take it over
                entry.owner = self._owner
                return
        deadline = time.monotonic() + wait_s
        while True:
            try:
                fd = os.open(self.path, os.O_RDWR | os.O_CREAT, 0o644)
            except OSError as exc:
                raise DataError(f"cannot create the session lock {self.path}: {exc.strerror or exc}") from exc
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except OSError as exc:
                if exc.errno not in (errno.EWOULDBLOCK, errno.EAGAIN, errno.EACCES):
                    os.close(fd)
                    raise DataError(f"cannot lock {self.path}: {exc.strerror or exc}") from exc
                holder = _read_info(fd)
                os.close(fd)
                if time.monotonic() >= deadline:
                    raise DataError(
                        f"session {self.session} is being written by another process ({_describe(holder)})",
                        hint=hint or "two processes must not write one session: wait for the other one to finish",
                    ) from None
                time.sleep(_RETRY_S)
                continue
            # discard_if_unused() may have removed the file between our open and flock: lock the live file only
            try:
                same = os.fstat(fd).st_ino == os.stat(self.path).st_ino
            except FileNotFoundError:
                same = False
            if not same:
                os.close(fd)
                continue
            break
        info = {
            "pid": os.getpid(),
            "host": socket.gethostname(),
            "command": " ".join([Path(sys.argv[0]).name, *sys.argv[1:4]]) if sys.argv else "python",
            "since_unix": time.time(),
        }
        os.ftruncate(fd, 0)
        os.pwrite(fd, json.dumps(info).encode("utf-8"), 0)
        with _GUARD:
            _HELD[key] = _Held(fd, self._owner)

    def release(self, unlink: bool = False) -> None:
        """Give the lease back (a no-op unless this object holds it); ``unlink`` also removes the lock file."""
        key = str(self.path)
        with _GUARD:
            entry = _HELD.get(key)
            if entry is None or entry.owner is not self._owner:
                return
            del _HELD[key]
            if unlink:
                self.path.unlink(missing_ok=True)  # while still locked, so no one locks the old file meanwhile
            try:
                fcntl.flock(entry.fd, fcntl.LOCK_UN)
            finally:
                os.close(entry.fd)


def lease_holder(journal: Path) -> dict[str, Any] | None:
    """Who holds the session's lease now (pid, host, command, since_unix), or None when nobody writes it.

    Never blocks and never disturbs a writer (see ACQUIRE_WAIT_S). A lease held by this very process counts too.
    """
    path = Path(journal) / LEASE_NAME
    with _GUARD:
        entry = _HELD.get(str(path))
        if entry is not None:
            return _read_info(entry.fd) or {"pid": os.getpid()}
    try:
        fd = os.open(path, os.O_RDONLY)
    except OSError:
        return None
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_SH | fcntl.LOCK_NB)
        except OSError as exc:
            if exc.errno in (errno.EWOULDBLOCK, errno.EAGAIN, errno.EACCES):
                return _read_info(fd) or {}
            return None
        fcntl.flock(fd, fcntl.LOCK_UN)
        return None
    finally:
        os.close(fd)
