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
import itertools
import json
import logging
import os
import shutil
import time
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any, Literal

import h5py
import numpy as np

from unitac_rig.errors import DataError
from unitac_rig.storage.checksums import check_press_group, check_root, seal_root
from unitac_rig.storage.extraction import Extraction, ExtractionSettings
from unitac_rig.storage.integrity import READABLE_SCHEMA_VERSIONS, SCHEMA_VERSION, SessionCheck, check_session
from unitac_rig.storage.lease import SessionLease, lease_holder
from unitac_rig.storage.press_record import (
    FINISHED_STATUSES,
    PressRecord,
    as_str,
    attr_value,
    iter_press_groups,
    json_default,
    read_press_group,
    record_nbytes,
    reseal_extraction,
    write_extraction,
    write_press_group,
)

log = logging.getLogger(__name__)


#: root attributes that say which rig recorded a session: a session is never continued from another one
RIG_IDENTITY_KEYS = ("simulated", "rig", "source")


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


def keep_aside(path: Path, *, move: bool) -> Path:
    """Give the current version of ``path`` a new, unused name beside it (``<stem>.broken-<time>[-n]<suffix>``) and
    return it; never overwrites: a second one in the same second gets ``-2``, and so on.

    ``move``: the original name is freed (the file is rebuilt there); otherwise both names hold the file until the
    caller replaces ``path`` (copy-on-write), so the damaged version survives that replacement. A hard link where
    the filesystem has them, else a rename (``move``) or a copy.
    """
    stamp = time.strftime("%Y%m%d-%H%M%S")
    for n in itertools.count(1):
        target = path.with_name(f"{path.stem}.broken-{stamp}{'' if n == 1 else f'-{n}'}{path.suffix}")
        try:
            os.link(path, target)
        except FileExistsError:
            continue
        except OSError:  # no hard links here (FAT, some network filesystems)
            if target.exists():
                continue
            if move:
                os.rename(path, target)  # we hold the session's lease: nobody creates ``target`` meanwhile
            else:
                shutil.copyfile(path, target)
            return target
        if move:
            path.unlink()
        return target
    raise AssertionError("unreachable")


def write_journal_entry(journal: Path, rec: PressRecord) -> Path:
    """Make ``rec`` durable as ``journal/<press_id>.h5``: temporary name, fsync, atomic rename, fsync the folder."""
    final = journal / f"{rec.press_id}.h5"
    tmp = journal / f"{rec.press_id}.h5.tmp"
    try:
        with h5py.File(tmp, "w") as jf:
            write_press_group(jf, rec, name="press")
        with open(tmp, "rb+") as fh:
            os.fsync(fh.fileno())
        os.replace(tmp, final)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    _fsync_dir(journal)
    return final


def _journal_check(path: Path) -> tuple[str, str]:
    """(state, status or detail) of a journal entry: ``ok``/``unsealed`` with the press status, or ``damaged``."""
    try:
        with h5py.File(path, "r") as jf:
            result = check_press_group(jf["press"])
            if result.damaged:
                return "damaged", result.detail
            return result.state, as_str(jf["press"].attrs["status"])
    except Exception as exc:  # a torn file does not open; damaged metadata raises anything
        return "damaged", f"unreadable ({' '.join(str(exc).split())[:160]})"


def _describe_rig(attrs: Mapping[str, Any]) -> str:
    if attrs.get("source"):
        return f"imported data ({attrs['source']})"
    kind = "the simulated rig" if attrs.get("simulated") else "a hardware rig"
    return f"{kind} {attrs['rig']!r}" if attrs.get("rig") else kind


def check_same_rig(existing: Mapping[str, Any], new: Mapping[str, Any], where: Path) -> str | None:
    """DataError when ``existing`` (a session's attributes) says another rig recorded it than ``new`` describes
    (simulated or not, the rig file's ``name``, imported or recorded); a note instead when ``existing`` predates
    rig identities and cannot tell. A writer that claims no identity at all (a script) is not checked."""
    if not any(k in new for k in RIG_IDENTITY_KEYS):
        return None
    if "simulated" not in existing and "source" not in existing:
        return (
            f"{where.name} does not record which rig it was recorded on (written by an older unitac-rig): collecting "
            f"into it from {_describe_rig(new)} is not checked"
        )
    differs = existing.get("source") != new.get("source") or any(
        k in existing and k in new and existing[k] != new[k] for k in ("simulated", "rig")
    )
    if differs:
        raise DataError(
            f"{where} was recorded on {_describe_rig(existing)}, not on {_describe_rig(new)} that this command uses",
            hint="collect into another --data directory (a session holds the presses of one rig only)",
        )
    return None


# ---------------------------------------------------------------------------------------------------------------------
# the writer


class SessionWriter:
    """Appends presses to one session file, durably (see the module docstring).

    Opening it verifies the file and the journal against their checksums and repairs each from the other
    (:meth:`_reconcile_with_journal`). A press damaged in both copies is dropped from the session (``unrepairable=
    "drop"``: collect presses it again; the damaged versions are kept aside) or refused (``"refuse"``: the readers'
    repair, :func:`repair_session`, which must never lose a press).
    """

    def __init__(
        self,
        data_dir: Path,
        object_id: str,
        sensor: str,
        root_attrs: Mapping[str, Any],
        *,
        unrepairable: Literal["drop", "refuse"] = "drop",
    ) -> None:
        self.data_dir = Path(data_dir)
        self.object_id = object_id
        self.sensor = sensor
        self.path = session_path(self.data_dir, object_id, sensor)
        self.journal = journal_dir(self.data_dir, object_id, sensor)
        self.root_attrs = dict(root_attrs)
        self.unrepairable = unrepairable
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
    def _note(self, text: str) -> None:
        self.recovery_notes.append(text)
        log.info("%s", text)  # collect prints the notes; a reader's repair logs them as warnings

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
            note = check_same_rig(existing, self.root_attrs, self.path)
            if note:
                self._note(note)
            return
        tmp = header.with_suffix(".tmp")
        tmp.write_text(json.dumps(self.root_attrs, default=json_default, indent=1))
        os.replace(tmp, header)

    def _journal_header(self) -> dict[str, Any]:
        return read_journal_header(self.journal)

    def _journal_press_files(self) -> dict[str, Path]:
        return {p.stem: p for p in sorted(self.journal.glob("*.h5")) if ".broken-" not in p.name}

    def _root_attr_values(self) -> dict[str, Any]:
        attrs = self._journal_header()
        attrs["schema_version"] = SCHEMA_VERSION
        return attrs

    def _create_file(self, path: Path) -> None:
        self._room(private_copy_path(path), 0, shown=path)
        attrs = self._root_attr_values()

        def create(f: h5py.File) -> None:
            for key, value in attrs.items():
                f.attrs[key] = attr_value(value)
            f.create_group("presses")
            seal_root(f)

        replace_by_copy(path, create, create=True)

    def _rewrite(self, change: Callable[[h5py.File], None], extra_bytes: int, what: str = "the session") -> None:
        """Publish a new version of the session file with ``change`` applied (see ``replace_by_copy``)."""
        size = self.path.stat().st_size
        self._room(private_copy_path(self.path), size + extra_bytes, what, shown=self.path)
        replace_by_copy(self.path, change)

    def _unusable(self) -> str | None:
        """Why the session file must be set aside and rebuilt from the journal (it does not open, or it is not a
        session file at all), or None. A file that is readable but not this session's raises instead."""
        try:
            with h5py.File(self.path, "r") as f:
                raw = f.attrs.get("schema_version")
                if raw is None:
                    return "is not a unitac-rig session file (no schema_version attribute)"
                version = int(raw)
                if version not in READABLE_SCHEMA_VERSIONS:
                    raise DataError(
                        f"{self.path} has schema version {version}; this unitac-rig writes {SCHEMA_VERSION}",
                        hint="collect into a new --data directory",
                    )
                if as_str(f.attrs.get("object", "")) != self.object_id:
                    raise DataError(f"{self.path} is not a session of {self.object_id}")
                # which rig recorded it, unless the root attributes are damaged (then the journal header says)
                trusted = not check_root(f).damaged
                attrs = {k: f.attrs[k] for k in RIG_IDENTITY_KEYS if k in f.attrs and trusted}
                _ = list(f["presses"])  # touching the index proves the file is readable
        except DataError:
            raise
        except OSError as exc:
            if "unable to lock file" in str(exc):  # someone opened it for writing (e.g. h5py mode "a")
                raise DataError(
                    f"{self.path} is held open for writing by another program ({exc})",
                    hint="close it there (readers must open session files with mode 'r'), then rerun",
                ) from exc
            return f"could not be opened ({exc})"
        except Exception as exc:  # damaged metadata raises KeyError, ValueError, RuntimeError...
            return f"could not be read ({' '.join(str(exc).split())[:160]})"
        plain = {k: bool(v) if k == "simulated" else as_str(v) for k, v in attrs.items()}
        if plain:
            check_same_rig(plain, self.root_attrs, self.path)
        return None

    def _open_or_recover(self) -> None:
        if self.path.exists():
            problem = self._unusable()
            if problem is not None:
                broken = keep_aside(self.path, move=True)
                self._note(f"{self.path.name} {problem}; moved aside to {broken.name} and rebuilt from the journal")
        if not self.path.exists():
            self._create_file(self.path)
        self._reconcile_with_journal()

    def _reconcile_with_journal(self) -> None:
        """Make the file and the journal agree, each verified against its checksums, each repaired from the other.

        In the file: a half-written press is replaced from the journal (or dropped); a damaged press is replaced by
        its intact journal copy; a journalled press missing from the file (a kill between the two writes) is copied
        in; damaged root attributes are rewritten from the journal header. In the journal: a torn or damaged entry
        whose press the file holds intact is rewritten from the file. The file is rewritten only when something
        changes.
        """
        check = check_session(self.path)
        if check.file_problem:  # the index went bad since _unusable() looked (or a race with a disk error)
            broken = keep_aside(self.path, move=True)
            self._note(f"{self.path.name} {check.file_problem}; moved aside to {broken.name}, rebuilt from the journal")
            self._create_file(self.path)
            check = check_session(self.path)
        restore: list[PressRecord] = []
        journal_fix: list[str] = []
        lost: dict[str, str] = {}  # press id -> why it cannot be repaired
        broken_entries: list[Path] = []
        journal = self._journal_press_files()
        for pid, path in journal.items():
            state, detail = _journal_check(path)
            if pid in check.statuses:  # intact in the file
                if state == "damaged":
                    journal_fix.append(pid)
                elif check.statuses[pid] not in FINISHED_STATUSES and detail != check.statuses[pid]:
                    restore.append(self._read_journal(path))  # e.g. aborted in the file, finished in the journal
                continue
            if state == "damaged":
                if pid in check.damaged:
                    lost[pid] = f"{check.damaged[pid]}, and its journal copy is damaged too ({detail})"
                    broken_entries.append(path)
                else:
                    self._note(f"journal entry {path.name} is damaged ({detail}); ignored")
                continue
            restore.append(self._read_journal(path))
        for pid, what in check.damaged.items():
            if pid not in journal:
                lost[pid] = f"{what}, and it has no journal copy"
        if lost and self.unrepairable == "refuse":
            pid, why = next(iter(lost.items()))
            more = f" (and {len(lost) - 1} more presses)" if len(lost) > 1 else ""
            raise DataError(
                f"{self.path}: press {pid} is damaged: {why}{more}",
                hint="run `unitac-rig collect` for this session to drop it and press it again (the damaged copies "
                "are kept aside), or restore the file from a backup",
            )
        drop = list(check.half_written) + list(lost)
        root_attrs = self._root_attr_values() if check.root_problem else None
        if drop or restore or root_attrs is not None:
            if lost:
                aside = keep_aside(self.path, move=False)  # the damaged version survives the rewrite below
                for entry in broken_entries:
                    keep_aside(entry, move=True)

            def apply(f: h5py.File) -> None:
                group = f.require_group("presses")
                for pid in drop:
                    if pid in group:
                        del group[pid]
                for rec in restore:
                    write_press_group(group, rec)
                if root_attrs is not None:
                    for key in list(f.attrs):
                        del f.attrs[key]
                    for key, value in root_attrs.items():
                        f.attrs[key] = attr_value(value)
                    seal_root(f)

            extra = sum(record_nbytes(rec) for rec in restore)
            if check.damaged or check.root_problem:
                self._rebuild(check, restore, extra)
            else:
                self._rewrite(apply, extra)
            for pid, why in lost.items():
                self._note(f"press {pid} was damaged ({why}): dropped, it will be pressed again (the damaged session "
                           f"file is kept as {aside.name})")  # fmt: skip
        if check.root_problem:
            self._note(f"{self.path.name}: {check.root_problem}; rewritten from the journal header")
        for pid in journal_fix:
            with h5py.File(self.path, "r") as f:
                rec = read_press_group(f["presses"][pid])
            write_journal_entry(self.journal, rec)
            self._note(f"journal entry {pid}.h5 was damaged; rewritten from the session file")
        self.recovery_notes.extend(f"press {pid} was half written; dropped" for pid in check.half_written)
        for rec in restore:
            what = "damaged in the session file; replaced by" if rec.press_id in check.damaged else "restored from"
            self._note(f"press {rec.press_id} ({rec.status}) {what} the journal")

    def _rebuild(self, check: SessionCheck, restore: list[PressRecord], extra_bytes: int) -> None:
        """Publish a fresh session file: root attributes from the journal header, every press that verified copied
        from the damaged file as it is (its checksums with it), and ``restore`` written from the journal.

        A damaged HDF5 file is never written to: its broken metadata (free-space lists, heaps) can corrupt what is
        added to it, so the intact presses move into a new file instead.
        """
        restored = {rec.press_id for rec in restore}
        keep = [pid for pid in check.statuses if pid not in restored]
        attrs = self._root_attr_values()
        attrs["schema_version"] = check.version or SCHEMA_VERSION  # a schema-1 file stays one (unsealed presses)

        def build(f: h5py.File) -> None:
            for key, value in attrs.items():
                f.attrs[key] = attr_value(value)
            presses = f.create_group("presses")
            with h5py.File(self.path, "r") as src:
                for pid in keep:
                    src.copy(src["presses"][pid], presses, name=pid)
            for rec in restore:
                write_press_group(presses, rec)
            if attrs["schema_version"] >= 2:
                seal_root(f)

        self._room(private_copy_path(self.path), self.path.stat().st_size + extra_bytes, shown=self.path)
        replace_by_copy(self.path, build, create=True)

    def _read_journal(self, path: Path) -> PressRecord:
        with h5py.File(path, "r") as jf:
            return read_press_group(jf["press"])

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
        """Merge attributes into the session (e.g. sensor identity once connected). A sensor whose serial number
        differs from the one the session was recorded with is refused (when both are known)."""
        header = self._journal_header()
        identity = attrs.get("sensor_identity")
        serial = identity.get("serial") if isinstance(identity, dict) else None
        recorded = header.get("sensor_serial")
        if serial is not None and recorded is not None and str(serial) != str(recorded):
            raise DataError(
                f"{self.path} was recorded with {self.sensor} serial {recorded}, not with serial {serial} mounted now",
                hint="collect into another --data directory (a session holds the presses of one sensor only)",
            )
        if serial is not None and recorded is None:
            attrs = {**attrs, "sensor_serial": str(serial)}  # the first serial a driver reported stays the session's
        header.update(attrs)
        tmp = self.journal / "_session.tmp"
        tmp.write_text(json.dumps(header, default=json_default, indent=1))
        os.replace(tmp, self.journal / "_session.json")

        def apply(f: h5py.File) -> None:
            for key, value in attrs.items():
                f.attrs[key] = attr_value(value)
            if int(f.attrs.get("schema_version", 0)) >= 2:  # a schema-1 file stays unsealed (its past is unknown)
                seal_root(f)

        self._rewrite(apply, len(json.dumps(dict(attrs), default=json_default)))

    def write_press(self, rec: PressRecord) -> None:
        """Make ``rec`` durable (journal), then add it to the session file."""
        tmp = self.journal / f"{rec.press_id}.h5.tmp"
        nbytes = record_nbytes(rec)
        self._room(tmp, nbytes, f"press {rec.press_id}")
        try:
            write_journal_entry(self.journal, rec)
            self._presses_written += 1
            # durable from here on: a failure below only delays the copy into the session file to the next open
            self._rewrite(lambda f: write_press_group(f["presses"], rec), nbytes,
                          f"press {rec.press_id} (it is safe in the journal)")  # fmt: skip
        except OSError as exc:
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


def read_journal_header(journal: Path) -> dict[str, Any]:
    """A journal's ``_session.json`` (the session's root attributes); DataError when it is unreadable."""
    header = journal / "_session.json"
    try:
        data = json.loads(header.read_text())
        if not isinstance(data, dict) or "object" not in data or "sensor" not in data:
            raise ValueError("not a session header")
    except (OSError, ValueError, RecursionError) as exc:
        raise DataError(
            f"{header} is unreadable ({exc})",
            hint="restore it from a backup, or move the session aside and collect into a new --data directory",
        ) from exc
    return data


def repair_session(path: Path, problem: str) -> list[str]:
    """Repair a damaged session file from its journal for a reader (never drops a press); returns what was done.

    ``problem`` is what the check found (one line naming the file and press). DataError when the repair cannot be
    done: no journal, the session being written by another process right now, or a press damaged in both copies.
    """
    path = Path(path)
    journal = path.parent / ".journal" / path.stem
    header = journal / "_session.json"
    if not header.is_file():
        raise DataError(
            f"{problem}; there is no journal to repair it from (.journal/{path.stem})",
            hint="restore the file from a backup, or move it aside and collect the session again",
        )
    holder = lease_holder(journal)
    if holder is not None:
        raise DataError(
            f"{problem}; the session is being written right now (pid {holder.get('pid', '?')}), so it cannot be "
            "repaired now",
            hint="rerun when that collection has finished (collect repairs it from the journal when it next opens "
            "the session)",
        )
    attrs = read_journal_header(journal)
    object_id, sensor = str(attrs["object"]), str(attrs["sensor"])
    if session_path(path.parent, object_id, sensor) != path:
        raise DataError(f"{path} and its journal header name another session ({object_id}/{sensor})")
    with SessionWriter(path.parent, object_id, sensor, attrs, unrepairable="refuse") as writer:
        return list(writer.recovery_notes)


def _reextract_group(g: h5py.Group, settings: ExtractionSettings) -> Extraction:
    from unitac_rig.storage.extraction import extract_press

    values = g["tactile/values"][()]
    extraction = extract_press(
        g["robot/t_s"][()], g["robot/press_force_n"][()], g["tactile/t_s"][()], g["tactile/valid"][()], settings
    )
    digests = write_extraction(g, extraction, values - g["tare_baseline"][()].astype(np.float32)[None])
    reseal_extraction(g, digests)  # the raw arrays were verified before (reextract_sessions)
    return extraction


def _reextract_copy(path: Path, settings: ExtractionSettings, journal_entry: bool) -> tuple[Path, int, int]:
    """A fsynced private copy of ``path`` with every extraction recomputed: (the copy, presses, targets matched)."""
    tmp = private_copy_path(path)
    shutil.copy2(path, tmp)
    presses = matched = 0
    with h5py.File(tmp, "a") as f:
        groups = [("press", f["press"])] if journal_entry else list(iter_press_groups(f))
        for _, g in groups:
            presses += 1
            matched += _reextract_group(g, settings).n_matched
        if not journal_entry:
            f.attrs["extraction_settings"] = json.dumps(settings.to_dict())
            if int(f.attrs.get("schema_version", 0)) >= 2:
                seal_root(f)
    with open(tmp, "rb+") as fh:
        os.fsync(fh.fileno())
    return tmp, presses, matched


def reextract_sessions(paths: list[Path], settings: ExtractionSettings) -> list[tuple[Path, int, int]]:
    """Recompute the force-matched extraction of every press of every session in ``paths`` with ``settings``: all
    or nothing. Returns (session file, presses, targets matched) per session.

    1. Every session's lease is taken (a session being collected refuses the whole run), then every session and
       journal is verified and repaired from the other copy (a press damaged in both refuses the whole run);
    2. every new file is built as a private copy (room for all of them is claimed first) and fsynced;
    3. only then are the copies renamed over the originals, one rename each. Any failure before step 3 removes the
       copies and leaves the dataset as it was; step 3 cannot fail short of a crash between two renames, which
       leaves each file either old or new, never a mix within a file.
    """
    problems = settings.problems()
    if problems:
        name, why = problems[0]
        raise DataError(f"extraction setting {name}: {why}")
    hint = "rerun extract when that collection has finished"
    leases: list[SessionLease] = []
    writers: list[SessionWriter] = []
    copies: list[tuple[Path, Path]] = []  # (private copy, the file it replaces)
    try:
        plans: list[tuple[Path, list[Path]]] = []
        for path in paths:
            journal = path.parent / ".journal" / path.stem
            if (journal / "_session.json").is_file():
                lease = SessionLease(journal, path.stem)
                lease.acquire(wait_s=0.5, hint=hint)
                leases.append(lease)
        for path in paths:
            journal = path.parent / ".journal" / path.stem
            if (journal / "_session.json").is_file():
                header = read_journal_header(journal)
                writer = SessionWriter(path.parent, str(header["object"]), str(header["sensor"]), header,
                                       unrepairable="refuse")  # fmt: skip
                writers.append(writer)
                entries = [p for p in writer._journal_press_files().values() if _journal_check(p)[0] != "damaged"]
            else:
                check = check_session(path)
                if check.needs_repair:
                    raise DataError(f"{check.first_problem()}; there is no journal to repair it from")
                entries = []
            plans.append((path, entries))
        needed = sum(p.stat().st_size + sum(e.stat().st_size for e in entries) for p, entries in plans)
        try:
            ensure_room(private_copy_path(paths[0]), needed)
        except OSError as exc:
            raise DataError(
                f"no room for extract's copies ({needed / 1e6:.1f} MB) in {paths[0].parent}: {exc.strerror or exc}",
                hint="free disk space; nothing was changed",
            ) from exc
        results = []
        for path, entries in plans:
            tmp, presses, matched = _reextract_copy(path, settings, journal_entry=False)
            copies.append((tmp, path))
            for entry in entries:
                copies.append((_reextract_copy(entry, settings, journal_entry=True)[0], entry))
            header_path = path.parent / ".journal" / path.stem / "_session.json"
            if header_path.exists():
                data = json.loads(header_path.read_text())
                data["extraction_settings"] = settings.to_dict()
                tmp = private_copy_path(header_path)
                tmp.write_text(json.dumps(data, default=json_default, indent=1))
                copies.append((tmp, header_path))
            results.append((path, presses, matched))
        for tmp, target in copies:  # the commit
            os.replace(tmp, target)
        copies.clear()
        return results
    except (OSError, ValueError, KeyError) as exc:
        raise DataError(f"extract could not finish ({exc}); nothing was changed") from exc
    finally:
        for tmp, _ in copies:
            tmp.unlink(missing_ok=True)
        for writer in writers:
            writer.close()
        for lease in leases:
            lease.release()


def reextract_session(path: Path, settings: ExtractionSettings) -> tuple[int, int]:
    """One session (see :func:`reextract_sessions`); returns (presses, targets matched)."""
    ((_, presses, matched),) = reextract_sessions([Path(path)], settings)
    return presses, matched
