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
(``robot/*``, ``tactile/*``, ``events``), the tare, and ``extraction/*`` (force-matched frames).
"""

from __future__ import annotations

import contextlib
import errno
import json
import logging
import os
import shutil
import time
from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import h5py
import numpy as np

from unitac_rig.errors import DataError
from unitac_rig.storage.extraction import Extraction, ExtractionSettings
from unitac_rig.storage.lease import SessionLease

log = logging.getLogger(__name__)

SCHEMA_VERSION = 1
FINISHED_STATUSES = ("complete", "failed")  # never redone on resume; "aborted" presses are redone


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


def press_id(rotation_deg: float, angle_deg: float) -> str:
    """Stable, sortable name of a press: ``rot090_ang-12``."""
    return f"rot{round(rotation_deg) % 360:03d}_ang{round(angle_deg):+03d}"


@dataclass
class PressRecord:
    """Everything recorded for one press. Times are host-clock seconds (monotonic on hardware, virtual in sim)."""

    press_id: str
    rotation_deg: float
    angle_deg: float
    status: str  # complete | failed | aborted
    reason: str  # force | travel | hard_limit | protective_stop | stall | interrupted | ...
    robot_t_s: np.ndarray  # (K,)
    robot_force: np.ndarray  # (K, 6) N, N*m, base axes (after the F/T zero)
    robot_pose: np.ndarray  # (K, 6) m, rad
    press_force_n: np.ndarray  # (K,) force along the press direction, N
    tactile_t_s: np.ndarray  # (M,) host time
    tactile_values: np.ndarray  # (M, n_taxels, 3) raw, layout units
    tactile_seq: np.ndarray  # (M,) int64, -1 where the device has no counter
    tactile_device_t_us: np.ndarray  # (M,) int64, -1 where the device has no clock
    tactile_valid: np.ndarray  # (M,) bool
    tare_baseline: np.ndarray  # (n_taxels, 3) subtracted from raw values for extraction and learning
    tactile_displacement_mm: np.ndarray | None = None  # (M, n_taxels, 3), PapillArray only
    events: list[tuple[float, str, str]] = field(default_factory=list)
    attrs: dict[str, Any] = field(default_factory=dict)  # strategy, speed, threshold, tare info, F/T zero, ...
    extraction: Extraction | None = None

    @property
    def finished(self) -> bool:
        return self.status in FINISHED_STATUSES


# ---------------------------------------------------------------------------------------------------------------------
# low-level HDF5 helpers


def _attr_value(value: Any) -> Any:
    if isinstance(value, dict | list | tuple) and not (
        isinstance(value, list | tuple) and value and all(isinstance(v, int | float) for v in value)
    ):
        return json.dumps(value, default=_json_default)
    if value is None:
        return "null"
    return value


def _json_default(obj: Any) -> Any:
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, Path):
        return str(obj)
    raise TypeError(f"cannot serialise {type(obj).__name__}")


def write_extraction(group: h5py.Group, extraction: Extraction, tared_values: np.ndarray) -> None:
    """(Re)write ``group/extraction`` from an Extraction and the press's tare-subtracted frames."""
    if "extraction" in group:
        del group["extraction"]
    ex = group.create_group("extraction")
    ex.attrs["settings"] = json.dumps(extraction.settings.to_dict())
    ex["targets_n"] = extraction.targets_n
    ex["crossing_t_s"] = extraction.crossing_t_s
    ex["frame_index"] = extraction.frame_index
    ex["frame_t_s"] = extraction.frame_t_s
    ex["force_at_frame_n"] = extraction.force_at_frame_n
    ex["error_n"] = extraction.error_n
    ex["miss"] = extraction.miss
    n_taxels = tared_values.shape[1] if tared_values.ndim == 3 else 0
    frames = np.full((extraction.targets_n.size, n_taxels, 3), np.nan, dtype=np.float32)
    chosen = extraction.frame_index >= 0
    if chosen.any() and tared_values.size:
        frames[chosen] = tared_values[extraction.frame_index[chosen]]
    ex["values"] = frames


def read_extraction(group: h5py.Group) -> tuple[Extraction, np.ndarray] | None:
    if "extraction" not in group:
        return None
    ex = group["extraction"]
    extraction = Extraction(
        targets_n=ex["targets_n"][()],
        crossing_t_s=ex["crossing_t_s"][()],
        frame_index=ex["frame_index"][()],
        frame_t_s=ex["frame_t_s"][()],
        force_at_frame_n=ex["force_at_frame_n"][()],
        error_n=ex["error_n"][()],
        miss=ex["miss"][()].astype(bool),
        settings=ExtractionSettings.from_dict(json.loads(ex.attrs["settings"])),
    )
    return extraction, ex["values"][()]


def write_press_group(parent: h5py.Group, rec: PressRecord, name: str | None = None) -> h5py.Group:
    """Write one press under ``parent/<name or press_id>``; the ``write_complete`` attribute is set last."""
    name = name or rec.press_id
    if name in parent:
        del parent[name]
    g = parent.create_group(name)
    g.attrs["press_id"] = rec.press_id
    g.attrs["rotation_deg"] = float(rec.rotation_deg)
    g.attrs["angle_deg"] = float(rec.angle_deg)
    g.attrs["status"] = rec.status
    g.attrs["reason"] = rec.reason
    for key, value in rec.attrs.items():
        g.attrs[key] = _attr_value(value)
    robot = g.create_group("robot")
    robot.create_dataset("t_s", data=np.asarray(rec.robot_t_s, np.float64))
    robot.create_dataset("force", data=np.asarray(rec.robot_force, np.float32).reshape(-1, 6))
    robot.create_dataset("tcp_pose", data=np.asarray(rec.robot_pose, np.float64).reshape(-1, 6))
    robot.create_dataset("press_force_n", data=np.asarray(rec.press_force_n, np.float32))
    tac = g.create_group("tactile")
    tac.create_dataset("t_s", data=np.asarray(rec.tactile_t_s, np.float64))
    values = np.asarray(rec.tactile_values, np.float32)
    tac.create_dataset(
        "values",
        data=values,
        compression="gzip",
        compression_opts=1,
        shuffle=True,
        chunks=True if values.size else None,
    )
    tac.create_dataset("seq", data=np.asarray(rec.tactile_seq, np.int64))
    tac.create_dataset("device_t_us", data=np.asarray(rec.tactile_device_t_us, np.int64))
    tac.create_dataset("valid", data=np.asarray(rec.tactile_valid, bool))
    if rec.tactile_displacement_mm is not None:
        disp = np.asarray(rec.tactile_displacement_mm, np.float32)
        tac.create_dataset(
            "displacement_mm",
            data=disp,
            compression="gzip",
            compression_opts=1,
            shuffle=True,
            chunks=True if disp.size else None,
        )
    g.create_dataset("tare_baseline", data=np.asarray(rec.tare_baseline, np.float64))
    ev_dtype = np.dtype([("t_s", np.float64), ("kind", h5py.string_dtype()), ("detail", h5py.string_dtype())])
    g.create_dataset("events", data=np.array([(t, k, d) for t, k, d in rec.events], dtype=ev_dtype))
    if rec.extraction is not None:
        write_extraction(g, rec.extraction, values - np.asarray(rec.tare_baseline, np.float32)[None])
    g.attrs["write_complete"] = True
    return g


def read_press_group(g: h5py.Group) -> PressRecord:
    attrs = {k: _decode_attr(v) for k, v in g.attrs.items()}
    for key in ("press_id", "rotation_deg", "angle_deg", "status", "reason", "write_complete"):
        attrs.pop(key, None)
    tac = g["tactile"]
    ex = read_extraction(g)
    events = [(float(e["t_s"]), _as_str(e["kind"]), _as_str(e["detail"])) for e in g["events"][()]]
    return PressRecord(
        press_id=_as_str(g.attrs.get("press_id", g.name.rsplit("/", 1)[-1])),
        rotation_deg=float(g.attrs["rotation_deg"]),
        angle_deg=float(g.attrs["angle_deg"]),
        status=_as_str(g.attrs["status"]),
        reason=_as_str(g.attrs["reason"]),
        robot_t_s=g["robot/t_s"][()],
        robot_force=g["robot/force"][()],
        robot_pose=g["robot/tcp_pose"][()],
        press_force_n=g["robot/press_force_n"][()],
        tactile_t_s=tac["t_s"][()],
        tactile_values=tac["values"][()],
        tactile_seq=tac["seq"][()],
        tactile_device_t_us=tac["device_t_us"][()],
        tactile_valid=tac["valid"][()].astype(bool),
        tactile_displacement_mm=tac["displacement_mm"][()] if "displacement_mm" in tac else None,
        tare_baseline=g["tare_baseline"][()],
        events=events,
        attrs=attrs,
        extraction=ex[0] if ex else None,
    )


def _as_str(value: Any) -> str:
    return value.decode() if isinstance(value, bytes) else str(value)


def _decode_attr(value: Any) -> Any:
    if isinstance(value, bytes | str):
        value = _as_str(value)
        if value[:1] in ("[", "{") or value == "null":
            try:
                return json.loads(value)
            except json.JSONDecodeError:
                return value
        return value
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, np.generic):
        return value.item()
    return value


ROOM_MARGIN_BYTES = 64 * 1024  # HDF5 metadata (object headers, B-trees, heaps) on top of the raw data, bytes


def record_nbytes(rec: PressRecord) -> int:
    """Uncompressed size of a press's arrays (bytes): an upper bound on what writing it adds to a file."""
    arrays = [rec.robot_t_s, rec.robot_force, rec.robot_pose, rec.press_force_n, rec.tactile_t_s, rec.tactile_values,
              rec.tactile_seq, rec.tactile_device_t_us, rec.tactile_valid, rec.tare_baseline]  # fmt: skip
    if rec.tactile_displacement_mm is not None:
        arrays.append(rec.tactile_displacement_mm)
    total = sum(np.asarray(a).nbytes for a in arrays)
    frame_bytes = int(np.prod(np.shape(rec.tactile_values)[1:])) * 4
    total += 32 * (8 * 6 + frame_bytes)  # extraction: ~25 targets x (6 per-target numbers + one float32 frame)
    return int(total) + 200 * len(rec.events)


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
        tmp.write_text(json.dumps(self.root_attrs, default=_json_default, indent=1))
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
                f.attrs[key] = _attr_value(value)
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
                    if _as_str(f.attrs.get("object", "")) != self.object_id:
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
            status = {pid: _as_str(presses[pid].attrs.get("status", "")) for pid in names if pid not in half}
        restore: list[PressRecord] = []
        for pid, path in self._journal_press_files().items():
            if status.get(pid) in FINISHED_STATUSES:
                continue
            try:
                with h5py.File(path, "r") as jf:
                    if pid in status and _as_str(jf["press"].attrs.get("status", "")) == status[pid]:
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
            return {pid: _as_str(g.attrs.get("status", "")) for pid, g in f["presses"].items()}

    def finished_press_ids(self) -> set[str]:
        return {pid for pid, status in self.press_statuses().items() if status in FINISHED_STATUSES}

    def update_root_attrs(self, attrs: Mapping[str, Any]) -> None:
        """Merge attributes into the session (e.g. sensor identity once connected)."""
        header = self._journal_header()
        header.update(attrs)
        tmp = self.journal / "_session.tmp"
        tmp.write_text(json.dumps(header, default=_json_default, indent=1))
        os.replace(tmp, self.journal / "_session.json")

        def apply(f: h5py.File) -> None:
            for key, value in attrs.items():
                f.attrs[key] = _attr_value(value)

        self._rewrite(apply, len(json.dumps(dict(attrs), default=_json_default)))

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


def iter_press_groups(f: h5py.File) -> Iterator[tuple[str, h5py.Group]]:
    presses = f.get("presses")
    if presses is None:
        return
    for pid in sorted(presses):
        g = presses[pid]
        if g.attrs.get("write_complete", False):
            yield pid, g


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
        tmp.write_text(json.dumps(data, default=_json_default, indent=1))
        os.replace(tmp, header)
    return result
