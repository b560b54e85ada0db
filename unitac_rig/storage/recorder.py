"""Crash-safe HDF5 session recording: one file per (object, sensor) session, one group per press.

Durability rule: killing the process at any moment loses at most the press in progress, the session file stays
readable, and the same command resumes without duplicating a finished press. How:

1. A finished press is first written to its own small HDF5 file in the session's *journal*
   (``DATA/.journal/<object>__<sensor>/<press_id>.h5``): written under a temporary name, fsynced, then atomically
   renamed. A press is durable from that rename on.
2. The press is then added to the session file by *copy-on-write*: the writer copies the published file to a private
   hidden name, appends the press there (the group's ``write_complete`` attribute set last), and atomically renames
   the copy over the published name.
3. On every open, the session file is checked against the journal: a file that no longer opens is moved aside
   (``*.broken-<time>.h5``) and rebuilt from the journal; a press group without ``write_complete`` is replaced from the
   journal; a journalled press missing from the file (a kill between steps 1 and 2) is copied in.

Readers never disturb the writer, and the writer never disturbs readers: a published session file is never opened
for writing, so ``inspect``, ``train``, ``extract``'s reader path or a notebook's plain ``h5py.File(path, "r")``
can open it at any moment, take HDF5's shared lock and keep it open as long as they like. They see a complete
snapshot (the file as of the last finished press: a rename is atomic, a reader holding the old file keeps reading
the old inode), and the writer's next rename is unaffected by their locks. One process at a time may *write* a
session: see :mod:`unitac_rig.storage.lease`. The cost is one file copy per press (measured in docs/dataset.md).

Schema (see docs/dataset.md): root attributes describe the session; ``/presses/<press_id>`` holds the raw streams
(``robot/*``, ``tactile/*``, ``events``), the tare, and ``extraction/*`` (force-matched frames): the group's format is
:mod:`unitac_rig.storage.press_record`.
"""

from __future__ import annotations

import contextlib
import errno
import json
import logging
import os
import shutil
import time
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

import h5py
import numpy as np

from unitac_rig.errors import DataError
from unitac_rig.storage.extraction import Extraction, ExtractionSettings
from unitac_rig.storage.lease import SessionLease
from unitac_rig.storage.press_record import (
    FINISHED_STATUSES,
    PressRecord,
    as_str,
    attr_value,
    iter_press_groups,
    json_default,
    read_press_group,
    record_nbytes,
    write_extraction,
    write_press_group,
)

log = logging.getLogger(__name__)

SCHEMA_VERSION = 1


def session_stem(object_id: str, sensor: str) -> str:
    return f"{object_id}__{sensor}"


def session_path(data_dir: Path, object_id: str, sensor: str) -> Path:
    return Path(data_dir) / f"{session_stem(object_id, sensor)}.h5"


def journal_dir(data_dir: Path, object_id: str, sensor: str) -> Path:
    return Path(data_dir) / ".journal" / session_stem(object_id, sensor)


def private_copy_path(path: Path) -> Path:
    """Where a process builds the next version of ``path`` before renaming it over ``path``.

    Hidden and ending in ``.tmp``, so no session glob (``*__*.h5``) ever lists it; the pid keeps two processes apart.
    """
    return path.with_name(f".{path.name}.{os.getpid()}.tmp")


def remove_stale_copies(path: Path, journal: Path) -> None:
    """Delete private copies of the session file and its journal entries left by a killed writer or ``extract``
    (call only while holding the session's lease)."""
    for leftover in [*path.parent.glob(f".{path.name}.*.tmp"), *journal.glob(".*.h5.*.tmp")]:
        leftover.unlink(missing_ok=True)


def replace_by_copy(path: Path, change: Callable[[h5py.File], None], *, create: bool = False) -> None:
    """Copy-on-write: apply ``change`` to a private copy of ``path`` (a new file when ``create``), then atomically
    rename the copy over ``path``. A reader that has ``path`` open keeps its complete old version; on any error
    ``path`` is left as it was."""
    tmp = private_copy_path(path)
    try:
        if not create:
            shutil.copyfile(path, tmp)
        with h5py.File(tmp, "w" if create else "a") as f:
            change(f)
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)


ROOM_MARGIN_BYTES = 64 * 1024  # HDF5 metadata (object headers, B-trees, heaps) on top of the raw data, bytes


def ensure_room(path: Path, extra_bytes: int) -> None:
    """Raise OSError (ENOSPC, EDQUOT, EFBIG) unless ``path`` can grow by ``extra_bytes`` right now.

    HDF5 does not survive a failed write: the failed flush leaves its metadata cache inconsistent and a later flush
    or close can crash the whole process (seen with a file-size limit). So the room is claimed first with
    ``posix_fallocate``, which fails cleanly, and handed back by truncating to the old size. Filesystems without
    fallocate skip the check.
    """
    existed = path.exists()
    size = path.stat().st_size if existed else 0
    fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)
    try:
        os.posix_fallocate(fd, size, max(1, extra_bytes + ROOM_MARGIN_BYTES))
    except OSError as exc:
        if exc.errno not in (errno.EOPNOTSUPP, errno.EINVAL, errno.ENOSYS):
            raise
    finally:
        try:
            os.ftruncate(fd, size)
        finally:
            os.close(fd)
            if not existed:
                path.unlink(missing_ok=True)


def _fsync_dir(path: Path) -> None:
    try:
        fd = os.open(path, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


# ---------------------------------------------------------------------------------------------------------------------
# the writer


class SessionWriter:
    """Appends presses to one session file, durably (see the module docstring)."""

    def __init__(self, data_dir: Path, object_id: str, sensor: str, root_attrs: Mapping[str, Any]) -> None:
        self.data_dir = Path(data_dir)
        self.object_id = object_id
        self.sensor = sensor
        self.path = session_path(self.data_dir, object_id, sensor)
        self.journal = journal_dir(self.data_dir, object_id, sensor)
        self.root_attrs = dict(root_attrs)
        self.recovery_notes: list[str] = []
        # True when this writer started the session (no file, no journal yet): see discard_if_unused()
        self.created = not self.path.exists() and not (self.journal / "_session.json").exists()
        self._presses_written = 0
        try:
            self.journal.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise DataError(f"cannot create the dataset directory {self.data_dir}: {exc.strerror}") from exc
        self._lease = SessionLease(self.journal, session_stem(object_id, sensor))
        self._lease.acquire()
        try:
            remove_stale_copies(self.path, self.journal)
            self._write_journal_header()
            self._open_or_recover()
        except BaseException:
            self.close()
            raise

    def close(self) -> None:
        """Give up the right to write this session (also done when the writer is garbage collected)."""
        lease = getattr(self, "_lease", None)
        if lease is not None:
            lease.release()

    def __enter__(self) -> SessionWriter:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def __del__(self) -> None:
        with contextlib.suppress(Exception):  # interpreter shutdown: the kernel drops the lock with the process
            self.close()

    # -- set-up / recovery ------------------------------------------------------------------------------------------
    def _write_journal_header(self) -> None:
        header = self.journal / "_session.json"
        if header.exists():
            existing = self._journal_header()
            for key in ("object", "sensor"):
                if existing.get(key) != self.root_attrs.get(key):
                    raise DataError(
                        f"{self.path.name}: the journal belongs to {key}={existing.get(key)!r}, "
                        f"not {self.root_attrs.get(key)!r}"
                    )
            return
        tmp = header.with_suffix(".tmp")
        tmp.write_text(json.dumps(self.root_attrs, default=json_default, indent=1))
        os.replace(tmp, header)

    def _journal_header(self) -> dict[str, Any]:
        header = self.journal / "_session.json"
        try:
            data: dict[str, Any] = json.loads(header.read_text())
        except (OSError, ValueError) as exc:
            raise DataError(
                f"{header} is unreadable ({exc})",
                hint="restore it from a backup, or move the session aside and collect into a new --data directory",
            ) from exc
        return data

    def _journal_press_files(self) -> dict[str, Path]:
        return {p.stem: p for p in sorted(self.journal.glob("*.h5"))}

    def _create_file(self, path: Path) -> None:
        self._room(private_copy_path(path), 0, shown=path)
        attrs = self._journal_header()
        attrs["schema_version"] = SCHEMA_VERSION

        def create(f: h5py.File) -> None:
            for key, value in attrs.items():
                f.attrs[key] = attr_value(value)
            f.create_group("presses")

        replace_by_copy(path, create, create=True)

    def _rewrite(self, change: Callable[[h5py.File], None], extra_bytes: int, what: str = "the session") -> None:
        """Publish a new version of the session file with ``change`` applied (see ``replace_by_copy``)."""
        size = self.path.stat().st_size
        self._room(private_copy_path(self.path), size + extra_bytes, what, shown=self.path)
        replace_by_copy(self.path, change)

    def _open_or_recover(self) -> None:
        if self.path.exists():
            try:
                with h5py.File(self.path, "r") as f:
                    version = int(f.attrs.get("schema_version", -1))
                    if version != SCHEMA_VERSION:
                        raise DataError(
                            f"{self.path} has schema version {version}; this unitac-rig writes {SCHEMA_VERSION}",
                            hint="collect into a new --data directory",
                        )
                    if as_str(f.attrs.get("object", "")) != self.object_id:
                        raise DataError(f"{self.path} is not a session of {self.object_id}")
                    _ = f.get("presses")  # touching the index proves the file is readable
            except OSError as exc:
                if "unable to lock file" in str(exc):  # someone opened it for writing (e.g. h5py mode "a")
                    raise DataError(
                        f"{self.path} is held open for writing by another program ({exc})",
                        hint="close it there (readers must open session files with mode 'r'), then rerun",
                    ) from exc
                broken = self.path.with_name(f"{self.path.stem}.broken-{time.strftime('%Y%m%d-%H%M%S')}.h5")
                os.replace(self.path, broken)
                self.recovery_notes.append(
                    f"{self.path.name} could not be opened ({exc}); moved aside to {broken.name} and rebuilt "
                    "from the journal"
                )
                log.warning(self.recovery_notes[-1])
        if not self.path.exists():
            self._create_file(self.path)
        self._reconcile_with_journal()

    def _reconcile_with_journal(self) -> None:
        """Make the file agree with the journal; rewrites it only when something is missing or half written."""
        with h5py.File(self.path, "r") as f:
            presses = f.get("presses")
            names = list(presses) if presses is not None else []
            half = [pid for pid in names if not presses[pid].attrs.get("write_complete", False)]
            status = {pid: as_str(presses[pid].attrs.get("status", "")) for pid in names if pid not in half}
        restore: list[PressRecord] = []
        for pid, path in self._journal_press_files().items():
            if status.get(pid) in FINISHED_STATUSES:
                continue
            try:
                with h5py.File(path, "r") as jf:
                    if pid in status and as_str(jf["press"].attrs.get("status", "")) == status[pid]:
                        continue  # the same unfinished (aborted) press in both: nothing to restore
                    rec = read_press_group(jf["press"])
            except (OSError, KeyError) as exc:
                self.recovery_notes.append(f"journal entry {path.name} unreadable ({exc}); ignored")
                continue
            restore.append(rec)
        if presses is None or half or restore:

            def apply(f: h5py.File) -> None:
                group = f.require_group("presses")
                for pid in half:
                    del group[pid]
                for rec in restore:
                    write_press_group(group, rec)

            self._rewrite(apply, sum(record_nbytes(rec) for rec in restore))
        self.recovery_notes.extend(f"press {pid} was half written; dropped" for pid in half)
        self.recovery_notes.extend(f"press {rec.press_id} ({rec.status}) restored from the journal" for rec in restore)

    def _room(self, path: Path, nbytes: int, what: str = "the session", shown: Path | None = None) -> None:
        try:
            ensure_room(path, nbytes)
        except OSError as exc:
            raise DataError(
                f"no room to record {what} in {shown or path}: {exc.strerror or exc}",
                hint="free disk space (or raise the quota / file-size limit); rerun the same command to resume",
            ) from exc

    # -- public API -------------------------------------------------------------------------------------------------
    def press_statuses(self) -> dict[str, str]:
        with h5py.File(self.path, "r") as f:
            return {pid: as_str(g.attrs.get("status", "")) for pid, g in f["presses"].items()}

    def finished_press_ids(self) -> set[str]:
        return {pid for pid, status in self.press_statuses().items() if status in FINISHED_STATUSES}

    def update_root_attrs(self, attrs: Mapping[str, Any]) -> None:
        """Merge attributes into the session (e.g. sensor identity once connected)."""
        header = self._journal_header()
        header.update(attrs)
        tmp = self.journal / "_session.tmp"
        tmp.write_text(json.dumps(header, default=json_default, indent=1))
        os.replace(tmp, self.journal / "_session.json")

        def apply(f: h5py.File) -> None:
            for key, value in attrs.items():
                f.attrs[key] = attr_value(value)

        self._rewrite(apply, len(json.dumps(dict(attrs), default=json_default)))

    def write_press(self, rec: PressRecord) -> None:
        """Make ``rec`` durable (journal), then add it to the session file."""
        final = self.journal / f"{rec.press_id}.h5"
        tmp = self.journal / f"{rec.press_id}.h5.tmp"
        nbytes = record_nbytes(rec)
        self._room(tmp, nbytes, f"press {rec.press_id}")
        try:
            with h5py.File(tmp, "w") as jf:
                write_press_group(jf, rec, name="press")
            with open(tmp, "rb+") as fh:
                os.fsync(fh.fileno())
            os.replace(tmp, final)
            _fsync_dir(self.journal)
            self._presses_written += 1
            # durable from here on: a failure below only delays the copy into the session file to the next open
            self._rewrite(lambda f: write_press_group(f["presses"], rec), nbytes,
                          f"press {rec.press_id} (it is safe in the journal)")  # fmt: skip
        except OSError as exc:
            tmp.unlink(missing_ok=True)
            raise DataError(
                f"could not record press {rec.press_id} in {self.path}: {exc}",
                hint="check free disk space; rerun the same command to resume",
            ) from exc

    def discard_if_unused(self) -> None:
        """Remove the session file and journal this writer created when no press was ever written to them.

        Called when the session cannot start (no sensor on the port, no arm), so a failed start leaves the dataset
        directory as it was instead of holding an empty session that ``inspect`` would list.
        """
        if not self.created or self._presses_written or self._journal_press_files():
            return
        self.path.unlink(missing_ok=True)
        for leftover in ("_session.json", "_session.tmp"):
            (self.journal / leftover).unlink(missing_ok=True)
        self._lease.release(unlink=True)
        for folder in (self.journal, self.journal.parent, self.data_dir):
            try:
                folder.rmdir()  # only when empty
            except OSError:
                break


def _reextract_group(g: h5py.Group, settings: ExtractionSettings) -> Extraction:
    from unitac_rig.storage.extraction import extract_press

    values = g["tactile/values"][()]
    extraction = extract_press(
        g["robot/t_s"][()], g["robot/press_force_n"][()], g["tactile/t_s"][()], g["tactile/valid"][()], settings
    )
    write_extraction(g, extraction, values - g["tare_baseline"][()].astype(np.float32)[None])
    return extraction


def _rewrite_atomically(path: Path, settings: ExtractionSettings, root_group: str | None) -> tuple[int, int]:
    """Copy ``path``, recompute every extraction in the copy, fsync, and swap it in; returns (presses, matched)."""
    tmp = private_copy_path(path)
    shutil.copy2(path, tmp)
    presses = matched = 0
    try:
        with h5py.File(tmp, "a") as f:
            groups = [("press", f["press"])] if root_group == "press" else list(iter_press_groups(f))
            for _, g in groups:
                presses += 1
                matched += _reextract_group(g, settings).n_matched
            if root_group is None:
                f.attrs["extraction_settings"] = json.dumps(settings.to_dict())
        with open(tmp, "rb+") as fh:
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)
    return presses, matched


def reextract_session(path: Path, settings: ExtractionSettings) -> tuple[int, int]:
    """Recompute the force-matched extraction of every press from the raw streams with ``settings``.

    The session file and its journal are rewritten atomically (copy, modify, rename), so a crash leaves either the
    old or the new extraction, never a mix within a file. Returns (presses, targets matched).
    """
    path = Path(path)
    stem = path.stem
    journal = path.parent / ".journal" / stem
    lease = SessionLease(journal, stem)
    if journal.is_dir():  # a session being collected is refused (a session without a journal has no writer)
        lease.acquire(wait_s=0.5, hint="rerun extract when that collection has finished")
    try:
        return _reextract_locked(path, journal, settings)
    finally:
        lease.release()


def _reextract_locked(path: Path, journal: Path, settings: ExtractionSettings) -> tuple[int, int]:
    result = _rewrite_atomically(path, settings, None)
    for entry in sorted(journal.glob("*.h5")) if journal.is_dir() else []:
        _rewrite_atomically(entry, settings, "press")
    header = journal / "_session.json"
    if header.exists():
        data = json.loads(header.read_text())
        data["extraction_settings"] = settings.to_dict()
        tmp = journal / "_session.tmp"
        tmp.write_text(json.dumps(data, default=json_default, indent=1))
        os.replace(tmp, header)
    return result
