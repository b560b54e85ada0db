"""Crash-safe HDF5 session recording (docs/dataset.md, "Crash safety" and "Storage layout").

A session is ``DATA/<object>__<sensor>.h5`` (root attributes and one external link per press, republished by a
private copy renamed over it), one immutable file per press under ``<object>__<sensor>.presses/<press_id>-<sha12>.h5``
(``sha12``: the start of its SHA-256, so a new version gets a new name) and the journal
``DATA/.journal/<object>__<sensor>/<press_id>.h5`` (fsynced, renamed: what makes a press durable, and its repair
copy). A press is journalled, then written to its press file, then published by the session file's rename, so a
kill loses at most the press in progress and the same command resumes. Every open checks the session file, its press
files and the journal against their checksums and repairs each from the other. No published file is ever opened for
writing, so readers never disturb the writer; one process at a time writes a session (:mod:`.lease`).
"""

from __future__ import annotations

import contextlib
import dataclasses
import errno
import itertools
import logging
import os
import time
import uuid
from collections.abc import Mapping
from pathlib import Path
from typing import Any, Literal

import h5py

from unitac_rig.errors import DataError
from unitac_rig.storage.integrity import (
    IDENTITY_KEYS,
    PRESS_DIR_SUFFIX,
    ROOT_ATTR,
    SCHEMA_VERSION,
    SessionCheck,
    as_str,
    check_root,
    check_session,
    seal_root,
)
from unitac_rig.storage.journal import (
    PRESS_GROUP,
    journal_dir,
    journal_entry_check,
    private_copy_path,
    read_journal_header,
    reextracted,
    root_as_header,
    session_header,
    session_journal,
    session_path,
    session_stem,
    settings_of,
    write_header,
    write_journal_entry,
)
from unitac_rig.storage.lease import SessionLease, lease_holder
from unitac_rig.storage.manifest import sha256_file
from unitac_rig.storage.press_record import (
    FINISHED_STATUSES,
    PressRecord,
    attr_value,
    read_press_group,
    record_nbytes,
    write_press_group,
)

log = logging.getLogger(__name__)


#: root attributes that say which rig recorded a session: a session is never continued from another one
RIG_IDENTITY_KEYS = ("simulated", "rig", "source")
#: room claimed per press link when the session file is republished (an external link and its name), bytes
LINK_BYTES = 256


def press_dir(path: Path) -> Path:
    """The folder holding the press files of the session file ``path`` (``<object>__<sensor>.presses``)."""
    path = Path(path)
    return path.with_name(f"{path.stem}{PRESS_DIR_SUFFIX}")


def remove_stale_copies(path: Path, journal: Path) -> None:
    """Delete private copies of the session file, its press files, its journal entries and journal header left by a
    killed writer or ``extract`` (call only while holding the session's lease: no live process writes them then)."""
    leftovers = [
        *path.parent.glob(f".{path.name}.*.tmp"),
        *journal.glob(".*.tmp"),  # private copies of journal entries, of the journal header, of _verified.json
        *journal.glob("*.h5.tmp"),  # a journal entry being written
        *press_dir(path).glob(".*.tmp"),
    ]
    for leftover in leftovers:
        leftover.unlink(missing_ok=True)


def write_press_file(folder: Path, rec: PressRecord) -> str:
    """Write one immutable press file into ``folder`` (the group ``press``, checksums computed from memory) under a
    private name, renamed to ``<press_id>-<sha12>.h5`` (the start of its SHA-256). Returns the file name.

    Not fsynced: the journal entry is the durable copy, and a press file torn by a power cut is rewritten from it on
    the next open.
    """
    folder.mkdir(exist_ok=True)
    tmp = folder / f".{rec.press_id}.{os.getpid()}.tmp"
    try:
        with h5py.File(tmp, "w") as pf:
            write_press_group(pf, rec, name=PRESS_GROUP)
        name = f"{rec.press_id}-{sha256_file(tmp)[:12]}.h5"
        os.replace(tmp, folder / name)
    finally:
        tmp.unlink(missing_ok=True)
    return name


def session_layout(f: h5py.File) -> tuple[dict[str, str], list[str]]:
    """(press id -> linked press file, relative to the session file's folder; press ids stored as groups inside the
    session file itself: an export's self-contained copy) of an open session file."""
    links: dict[str, str] = {}
    groups: list[str] = []
    presses = f.get("presses")
    if presses is None:
        return links, groups
    for pid in sorted(presses):
        link = presses.get(pid, getlink=True)
        if isinstance(link, h5py.ExternalLink):
            links[pid] = str(link.filename)
        else:
            groups.append(pid)
    return links, groups


def _holds_groups(path: Path) -> bool:
    """Whether the session file ``path`` stores presses inside it (an export's copy); False when it does not open
    (the writer's checks say what is wrong with it)."""
    try:
        with h5py.File(path, "r") as f:
            return bool(session_layout(f)[1])
    except Exception:
        return False


def write_session_file(path: Path, root: Mapping[str, Any], links: Mapping[str, str]) -> Path:
    """Write a session file (``root`` attributes, sealed, and one external link per press) under a private name
    beside ``path`` and return that name; the caller renames it over ``path``."""
    tmp = private_copy_path(path)
    try:
        with h5py.File(tmp, "w") as f:
            for key, value in root.items():
                f.attrs[key] = value
            presses = f.create_group("presses")
            for pid in sorted(links):
                presses[pid] = h5py.ExternalLink(links[pid], f"/{PRESS_GROUP}")
            seal_root(f)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    return tmp


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


def keep_aside(path: Path) -> Path:
    """Move ``path`` to a new, unused name beside it (``<stem>.broken-<time>[-n]<suffix>``) and return it; never
    overwrites: a second one in the same second gets ``-2``, and so on. A hard link then an unlink where the
    filesystem has them, else a rename (we hold the session's lease: nobody creates the target meanwhile)."""
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
            os.rename(path, target)
            return target
        path.unlink()
        return target
    raise AssertionError("unreachable")


def _describe_rig(attrs: Mapping[str, Any]) -> str:
    if attrs.get("source"):
        return f"imported data ({attrs['source']})"
    kind = "the simulated rig" if attrs.get("simulated") else "a hardware rig"
    return f"{kind} {attrs['rig']!r}" if attrs.get("rig") else kind


def check_same_rig(existing: Mapping[str, Any], new: Mapping[str, Any], where: Path) -> str | None:
    """DataError when ``existing`` (a session's attributes) says another rig recorded it than ``new`` describes
    (simulated or not, the rig file's ``name``, imported or recorded); a note instead when ``existing`` names no
    rig (a script started it) and cannot tell. A writer that claims no identity at all (a script) is not checked."""
    if not any(k in new for k in RIG_IDENTITY_KEYS):
        return None
    if "simulated" not in existing and "source" not in existing:
        return (
            f"{where.name} does not record which rig it was recorded on (a script started it naming none): collecting "
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
    """Appends presses to one session, durably (see the module docstring).

    Opening it verifies the session file, its press files and the journal against their checksums and repairs each
    from the other (:meth:`_reconcile_with_journal`). A press damaged in both copies is dropped from the session
    (``unrepairable="drop"``: collect presses it again; the damaged versions are kept aside) or refused
    (``"refuse"``: the readers' repair, :func:`repair_session`, which must never lose a press).
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
        self.press_dir = press_dir(self.path)
        self.journal = journal_dir(self.data_dir, object_id, sensor)
        self.root_attrs = dict(root_attrs)
        self.unrepairable = unrepairable
        self.recovery_notes: list[str] = []
        # True when this writer started the session (no file, no journal yet): see discard_if_unused()
        self.created = not self.path.exists() and not (self.journal / "_session.json").exists()
        if not self.created and _holds_groups(self.path):
            raise DataError(
                f"{self.path} holds its presses inside it: an export's read-only copy of a session",
                hint="collect into the --data directory it was exported from, or into a new one",
            )
        self._presses_written = 0
        # what the published session file holds: its root attributes (as stored, schema_version included) and the
        # press file each press links to (relative to the data directory)
        self._root: dict[str, Any] = {}
        self._links: dict[str, str] = {}
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
            self._remove_unlinked_press_files()
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
        """Check the journal header against this writer's session, or write it: from the session file's verified
        root when a header went missing beside an existing session (noted), else new, with a new session id."""
        header = self.journal / "_session.json"
        if not header.exists():
            rebuilt = root_as_header(self.path)
            if rebuilt is not None:
                self._note(f"the journal header {header.name} was missing; rewritten from {self.path.name}")
            attrs = rebuilt if rebuilt is not None else dict(self.root_attrs)
            attrs.setdefault("session_id", uuid.uuid4().hex)  # names this session in every press it records
            write_header(self.journal, attrs)
        existing = read_journal_header(self.journal)
        for key in ("object", "sensor"):
            if existing.get(key) != self.root_attrs.get(key):
                raise DataError(
                    f"{self.path.name}: the journal belongs to {key}={existing.get(key)!r}, "
                    f"not {self.root_attrs.get(key)!r}"
                )
        note = check_same_rig(existing, self.root_attrs, self.path)
        if note:
            self._note(note)
        if "session_id" not in existing:
            raise DataError(f"{self.journal / header.name} names no session_id: it is not a unitac-rig 0.1 journal")
        self.identity = {key: str(existing[key]) for key in IDENTITY_KEYS}

    def _stamped(self, rec: PressRecord) -> PressRecord:
        """``rec`` carrying this session's identity in its attributes (under its seal once written)."""
        if all(rec.attrs.get(key) == value for key, value in self.identity.items()):
            return rec
        return dataclasses.replace(rec, attrs={**rec.attrs, **self.identity})

    def _journal_press_files(self) -> dict[str, Path]:
        return {p.stem: p for p in sorted(self.journal.glob("*.h5")) if ".broken-" not in p.name}

    def _header_root(self) -> dict[str, Any]:
        """Root attributes from the journal header (the session file's are rebuilt from it when damaged)."""
        root = {key: attr_value(value) for key, value in read_journal_header(self.journal).items()}
        root["schema_version"] = SCHEMA_VERSION
        return root

    def _press_file(self, pid: str) -> Path:
        return self.data_dir / self._links[pid]

    def _new_press_file(self, rec: PressRecord) -> str:
        """Write a press file for ``rec`` and return the link to it (relative to the data directory)."""
        return f"{self.press_dir.name}/{write_press_file(self.press_dir, rec)}"

    def _publish(self) -> None:
        """Publish a new version of the session file: its root attributes and one link per press, written under a
        private name and renamed over the published one."""
        tmp = private_copy_path(self.path)
        root_bytes = sum(len(str(value)) for value in self._root.values())
        self._room(tmp, root_bytes + LINK_BYTES * len(self._links), shown=self.path)
        os.replace(write_session_file(self.path, self._root, self._links), self.path)

    def _load(self) -> None:
        """Read what the published session file holds (see ``_root``, ``_links``)."""
        with h5py.File(self.path, "r") as f:
            self._links = session_layout(f)[0]
            try:
                self._root = {key: f.attrs[key] for key in f.attrs if key != ROOT_ATTR}
            except Exception:  # a damaged attribute heap: the check reports it, the journal header replaces them
                self._root = self._header_root()

    def _unusable(self) -> str | None:
        """Why the session file must be set aside and rebuilt from the journal (it does not open, or it is not a
        session file at all), or None. A file that is readable but not this session's raises instead."""
        try:
            with h5py.File(self.path, "r") as f:
                raw = f.attrs.get("schema_version")
                if raw is None:
                    return "is not a unitac-rig session file (no schema_version attribute)"
                version = int(raw)
                if version != SCHEMA_VERSION:
                    raise DataError(
                        f"{self.path} has schema version {version}; this unitac-rig writes {SCHEMA_VERSION}",
                        hint="collect into a new --data directory",
                    )
                if as_str(f.attrs.get("object", "")) != self.object_id:
                    raise DataError(f"{self.path} is not a session of {self.object_id}")
                # which rig recorded it, unless the root attributes are damaged (then the journal header says)
                trusted = not check_root(f).damaged
                attrs = {k: f.attrs[k] for k in RIG_IDENTITY_KEYS if k in f.attrs and trusted}
                session_layout(f)  # reading the press index and every link proves the file is readable
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
                broken = keep_aside(self.path)
                self._note(f"{self.path.name} {problem}; moved aside to {broken.name} and rebuilt from the journal")
        if self.path.exists():
            self._load()
        else:
            self._root, self._links = self._header_root(), {}
            self._publish()
        self._reconcile_with_journal()

    def _reconcile_with_journal(self) -> None:
        """Make the session and the journal agree, each verified against its checksums, each repaired from the other.

        In the session: a half-written press is dropped, and replaced from the journal when it has a copy there; a
        damaged or missing press file is replaced by its intact journal copy; a journalled press the
        session file does not link (a kill between the writes) is added; damaged root attributes are rewritten from
        the journal header. In the journal: a torn or damaged entry whose press the session holds intact is
        rewritten from it. The session file is republished only when something changes.
        """
        check = check_session(self.path)
        if check.file_problem:  # the index went bad since _unusable() looked (or a race with a disk error)
            broken = keep_aside(self.path)
            self._note(f"{self.path.name} {check.file_problem}; moved aside to {broken.name}, rebuilt from the journal")
            self._root, self._links = self._header_root(), {}
            self._publish()
            check = check_session(self.path)
        if check.root_problem:
            self._root = self._header_root()
        # the session file's extraction settings are the newer side: extract renames it before the journal's copies
        settings = settings_of(self._root.get("extraction_settings"))
        journal = self._journal_press_files()
        restore, journal_fix, lost, broken_entries = self._triage(check, journal, settings)
        if lost and self.unrepairable == "refuse":
            pid, why = next(iter(lost.items()))
            more = f" (and {len(lost) - 1} more presses)" if len(lost) > 1 else ""
            raise DataError(
                f"{self.path}: press {pid} is damaged: {why}{more}",
                hint="run `unitac-rig collect` for this session to drop it and press it again (the damaged copies "
                "are kept aside), or restore the file from a backup",
            )
        kept_as: dict[str, str] = {}
        for pid in lost:
            ours = pid in self._links and self._press_file(pid).parent == self.press_dir  # never a file elsewhere
            if ours and self._press_file(pid).is_file():
                kept_as[pid] = keep_aside(self._press_file(pid)).name
        for entry_path in broken_entries:
            keep_aside(entry_path)
        restore = [self._stamped(r) for r in restore]
        if settings is not None:  # a journal copy older than the session's extraction is re-extracted
            stale = {
                r.press_id
                for r in restore
                if r.extraction is not None and settings_of(r.extraction.settings.to_dict()) != settings
            }
            restore = [reextracted(r, settings) if r.press_id in stale else r for r in restore]
            journal_fix.update({pid: "held an older extraction than the session file" for pid in stale})
        gone = set(check.half_written) | set(lost) | set(check.damaged) | {rec.press_id for rec in restore}
        for pid in gone:
            self._links.pop(pid, None)
        for rec in restore:
            self._links[rec.press_id] = self._new_press_file(rec)
        if gone or check.root_problem:
            self._publish()
        for pid, why in lost.items():
            aside = f" (the damaged copy is kept as {kept_as[pid]})" if pid in kept_as else ""
            self._note(f"press {pid} was damaged ({why}): dropped, it will be pressed again{aside}")
        if check.root_problem:
            self._note(f"{self.path.name}: {check.root_problem}; rewritten from the journal header")
        restored = {rec.press_id: rec for rec in restore}
        for pid, why in journal_fix.items():
            if pid in restored:
                rec = restored[pid]
            else:
                with h5py.File(self.path, "r") as f:
                    rec = self._stamped(read_press_group(f["presses"][pid]))
            write_journal_entry(self.journal, rec)
            self._note(
                f"journal entry {pid}.h5 {why}; rewritten from the {'journal' if pid in restored else 'session file'}"
            )
        self._align_header(settings)
        self.recovery_notes.extend(f"press {pid} was half written; dropped" for pid in check.half_written)
        for rec in restore:
            what = "damaged in the session file; replaced by" if rec.press_id in check.damaged else "restored from"
            self._note(f"press {rec.press_id} ({rec.status}) {what} the journal")

    def _triage(
        self, check: SessionCheck, journal: dict[str, Path], settings: dict[str, Any] | None
    ) -> tuple[list[PressRecord], dict[str, str], dict[str, str], list[Path]]:
        """What the session and journal need: (presses to restore from the journal, press id -> why its journal
        entry is rewritten, press id -> why it cannot be repaired, journal entries damaged with their press)."""
        restore: list[PressRecord] = []
        journal_fix: dict[str, str] = {}  # press id -> why its journal entry is rewritten from the session file
        lost: dict[str, str] = {}  # press id -> why it cannot be repaired
        broken_entries: list[Path] = []
        entries = {pid: journal_entry_check(path, self.identity) for pid, path in journal.items()}
        # an intact entry under another press's name (two entries swapped): still a good copy of the press it holds
        spare = {e.holds: journal[pid] for pid, e in entries.items() if e.holds and e.holds != pid and e.status}
        for pid, path in journal.items():
            entry = entries[pid]
            state, detail = entry.state, entry.detail
            if pid in check.statuses:  # intact in the session
                if state == "damaged":
                    journal_fix[pid] = f"was damaged ({detail})"
                elif check.statuses[pid] not in FINISHED_STATUSES and entry.status != check.statuses[pid]:
                    restore.append(self._read_journal(path))  # e.g. aborted in the session, finished in the journal
                elif settings is not None and entry.settings is not None and entry.settings != settings:
                    journal_fix[pid] = "held an older extraction than the session file"
                continue
            if state == "damaged" and pid in spare:
                restore.append(self._read_journal(spare[pid]))
                journal_fix[pid] = f"was damaged ({detail})"
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
            if pid in journal:
                continue
            if pid in spare:
                restore.append(self._read_journal(spare[pid]))
                journal_fix[pid] = "was missing"
            else:
                lost[pid] = f"{what}, and it has no journal copy"
        for pid in check.statuses:
            if pid not in journal and pid not in journal_fix:
                journal_fix[pid] = "was missing (the press had no repair copy)"
        return restore, journal_fix, lost, broken_entries

    def _align_header(self, settings: dict[str, Any] | None) -> None:
        """The journal header's extraction settings follow the session file's (a kill between extract's renames)."""
        if settings is None:
            return
        header = read_journal_header(self.journal)
        if settings_of(header.get("extraction_settings")) != settings:
            header["extraction_settings"] = settings
            write_header(self.journal, header)
            self._note("the journal header held an older extraction than the session file; brought in step")

    def _remove_unlinked_press_files(self) -> None:
        """Delete press files the published session file does not link: versions superseded by an earlier command
        (a redone press, a re-extraction, a repair) and a killed writer's last press file (its journal entry was
        written first and restored it). Files kept aside (``.broken-``) stay."""
        if not self.press_dir.is_dir():
            return
        linked = {Path(target).name for target in self._links.values()}
        for path in self.press_dir.glob("*.h5"):
            if path.name not in linked and ".broken-" not in path.name:
                path.unlink(missing_ok=True)

    def _read_journal(self, path: Path) -> PressRecord:
        with h5py.File(path, "r") as jf:
            return read_press_group(jf[PRESS_GROUP])

    def _room(self, path: Path, nbytes: int, what: str = "the session", shown: Path | None = None) -> None:
        try:
            ensure_room(path, nbytes)
        except OSError as exc:
            raise DataError(
                f"no room to record {what} in {shown or path}: {exc.strerror or exc}",
                hint="free disk space (or raise the quota / file-size limit); rerun the same command to resume",
            ) from exc

    # -- public API -------------------------------------------------------------------------------------------------
    def finished_press_ids(self) -> set[str]:
        with h5py.File(self.path, "r") as f:
            return {pid for pid, g in f["presses"].items() if as_str(g.attrs.get("status", "")) in FINISHED_STATUSES}

    def update_root_attrs(self, attrs: Mapping[str, Any]) -> None:
        """Merge attributes into the session (e.g. sensor identity once connected). A sensor whose serial number
        differs from the one the session was recorded with is refused (when both are known)."""
        header = read_journal_header(self.journal)
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
        write_header(self.journal, header)

        for key, value in attrs.items():
            self._root[key] = attr_value(value)
        try:
            self._publish()
        except OSError as exc:
            raise DataError(f"could not update {self.path}: {exc}", hint="check free disk space") from exc

    def write_press(self, rec: PressRecord) -> None:
        """Make ``rec`` durable (journal), write its press file, then publish it in the session file."""
        tmp = self.journal / f"{rec.press_id}.h5.tmp"
        nbytes = record_nbytes(rec)
        self._room(tmp, 2 * nbytes, f"press {rec.press_id}")  # the journal entry and the press file
        try:
            rec = self._stamped(rec)
            write_journal_entry(self.journal, rec)
            self._presses_written += 1
            # durable from here on: a failure below only delays the press file and its link to the next open
            self._links[rec.press_id] = self._new_press_file(rec)
            self._publish()
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
        with contextlib.suppress(OSError):
            self.press_dir.rmdir()  # only when empty
        for leftover in ("_session.json", "_verified.json"):
            (self.journal / leftover).unlink(missing_ok=True)
        self._lease.release(unlink=True)
        for folder in (self.journal, self.journal.parent, self.data_dir):
            try:
                folder.rmdir()  # only when empty
            except OSError:
                break


def repair_session(path: Path, problem: str) -> list[str]:
    """Repair a damaged session file from its journal for a reader (never drops a press); returns what was done.

    ``problem`` is what the check found (one line naming the file and press). DataError when the repair cannot be
    done: no journal, the session being written by another process right now, or a press damaged in both copies.
    """
    path = Path(path)
    journal = session_journal(path)
    attrs = session_header(path)
    if attrs is None:
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
    object_id, sensor = str(attrs["object"]), str(attrs["sensor"])
    if session_path(path.parent, object_id, sensor) != path:
        raise DataError(f"{path} and its journal header name another session ({object_id}/{sensor})")
    with SessionWriter(path.parent, object_id, sensor, attrs, unrepairable="refuse") as writer:
        return list(writer.recovery_notes)


def session_bytes(path: Path) -> int:
    """Bytes a session holds on disk: its session file and every press file it links (bytes)."""
    path = Path(path)
    total = path.stat().st_size
    with h5py.File(path, "r") as f:
        links = session_layout(f)[0]
    return total + sum((path.parent / target).stat().st_size for target in links.values())
