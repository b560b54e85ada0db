"""Reading sessions: listing them, reading presses, and the force-matched frames learning trains on.

Every reader goes through here, so it reads both storage layouts (docs/dataset.md, "Storage layout"): a session file
whose presses are links to press files, and the older single file holding every press. :func:`session_files` names
the files a session is stored in, :func:`session_digest` identifies its content whatever the layout (pooling), and
:func:`snapshot_session` writes it as one self-contained file (export).
"""

from __future__ import annotations

import hashlib
import json
import logging
import os
import shutil
import threading
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import h5py
import numpy as np

from unitac_rig.errors import DataError
from unitac_rig.rig.sensors import SENSORS
from unitac_rig.storage.checksums import attrs_digest, content_seal, root_attr_items
from unitac_rig.storage.integrity import (
    IDENTITY_KEYS,
    READABLE_SCHEMA_VERSIONS,
    SCHEMA_VERSION,
    SessionCheck,
    check_session,
    press_seal,
)
from unitac_rig.storage.journal import journal_problems
from unitac_rig.storage.lease import lease_holder
from unitac_rig.storage.press_record import (
    PressRecord,
    as_str,
    decode_attr,
    iter_press_groups,
    read_extraction,
    read_press_group,
)
from unitac_rig.storage.recorder import private_copy_path, repair_session, session_layout
from unitac_rig.storage.trust import load_trust, save_trust

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class SessionInfo:
    path: Path
    object_id: str
    sensor: str
    simulated: bool
    attrs: dict[str, Any]
    integrity: str = "verified"  # or why not (see SessionCheck.describe); "repaired: ..." when a read repaired it
    repairs: tuple[str, ...] = field(default_factory=tuple)


@dataclass(frozen=True)
class MatchedSet:
    """Every force-matched frame of one (object, sensor) session that hit its target (misses and failed presses out).

    ``values`` are tare-subtracted, in the sensor's units (uSkin counts, PapillArray N), shape (M, n_taxels, 3).
    """

    object_id: str
    sensor: str
    simulated: bool
    rotation_deg: np.ndarray
    angle_deg: np.ndarray
    target_n: np.ndarray
    values: np.ndarray
    force_n: np.ndarray
    error_n: np.ndarray
    rig: str = ""  # which rig recorded it (:func:`rig_label`); "" when the session does not say

    def __len__(self) -> int:
        return int(self.target_n.size)


@dataclass(frozen=True)
class Verified:
    """A session file version that passed :func:`verified_session` (and what it took)."""

    check: SessionCheck
    repairs: tuple[str, ...] = ()

    @property
    def integrity(self) -> str:
        described = self.check.describe()
        return f"repaired from the journal, {described}" if self.repairs else described


_VERIFIED: dict[tuple[Any, ...], Verified] = {}
_VERIFIED_GUARD = threading.Lock()
_PRESSES_OK: dict[str, set[tuple[str, str]]] = {}  # file -> (press id, checksums) verified by this process
_WARNED_UNSEALED: set[str] = set()


def _version_key(path: Path) -> tuple[Any, ...] | None:
    """Identifies one version of a session: the recorder never changes a published file in place (it renames a new
    file over it), so the (inode, size, mtime) of the session file and of every press file it links change with
    every version, and with any change made behind the recorder's back (a deleted or damaged press file)."""
    try:
        st = os.stat(path)
        with h5py.File(path, "r") as f:
            links = session_layout(f)[0]
        files = []
        for target in sorted(links.values()):
            try:
                pst = os.stat(Path(path).parent / target)
                files.append((target, pst.st_ino, pst.st_size, pst.st_mtime_ns))
            except OSError:
                files.append((target, -1, -1, -1))
    except Exception:  # a file that does not open or list: never cached, the check says why
        return None
    return (str(Path(path).resolve()), st.st_dev, st.st_ino, st.st_size, st.st_mtime_ns, tuple(files))


def verified_session(path: Path) -> Verified:
    """Verify every press of ``path`` against its checksums and identity (once per file version: what an earlier
    process verified and has not changed since is trusted, :mod:`unitac_rig.storage.trust`), and that each press
    still has its repair copy in the journal; repair from the journal what is damaged or missing, and raise a
    DataError naming the file and press when it cannot be repaired.

    A file without checksums (schema 1) is read unverified and says so (a warning, and ``integrity`` in
    ``inspect`` and export manifests); a file of another schema version is left to the caller's version check.
    """
    path = Path(path)
    key = _version_key(path)
    with _VERIFIED_GUARD:
        cached = _VERIFIED.get(key) if key else None
    if cached is not None:
        return cached
    stored, stored_journal = load_trust(path)
    with _VERIFIED_GUARD:
        known = set(_PRESSES_OK.get(str(path.resolve()), ())) | stored
    check = check_session(path, known)
    repairs: tuple[str, ...] = ()
    issues, good = ({}, {}) if check.needs_repair else _journal_issues(path, check, stored_journal)
    journal = path.parent / ".journal" / path.stem
    if not check.needs_repair and issues and lease_holder(journal) is not None:
        for issue in issues.values():  # the collection writing it now recreates it when it next opens the session
            log.warning("%s: %s (the session is being written now; rerun later to restore it)", path, issue)
    elif issues and not check.needs_repair:  # the data is intact: a journal that cannot be mended never blocks it
        try:
            repairs = tuple(repair_session(path, f"{path}: {next(iter(issues.values()))}"))
        except DataError as exc:
            log.warning("%s: %s; the journal could not be mended: %s", path, "; ".join(issues.values()), exc)
        for note in repairs:
            log.warning("%s: %s", path, note)
        check = check_session(path, known)
        issues, good = _journal_issues(path, check, stored_journal)
        for issue in issues.values() if repairs else ():
            log.warning("%s: %s", path, issue)
    elif check.needs_repair:
        problem = check.first_problem()
        repairs = tuple(repair_session(path, problem))
        for note in repairs:
            log.warning("%s: %s", path, note)
        check = check_session(path, known)
        if check.needs_repair:
            raise DataError(check.first_problem(), hint="restore the file from a backup")
        issues, good = _journal_issues(path, check, stored_journal)
        for issue in issues.values():
            log.warning("%s: %s", path, issue)
    if check.unsealed and str(path) not in _WARNED_UNSEALED:
        _WARNED_UNSEALED.add(str(path))
        log.warning("%s: %s: read without verification", path, check.describe())
    result = Verified(check, repairs)
    seals = _press_seals(path, check.verified)
    save_trust(path, seals, good)
    key = _version_key(path)
    with _VERIFIED_GUARD:
        _PRESSES_OK.setdefault(str(path.resolve()), set()).update(seals)
        if key is not None:
            _VERIFIED[key] = result
    return result


def _journal_issues(path: Path, check: SessionCheck, trusted: dict[str, str]) -> tuple[dict[str, str], dict[str, str]]:
    """:func:`journal_problems` for an intact session file: its identity (schema 3) from its verified root."""
    identity: dict[str, str] = {}
    if check.version is not None and check.version >= 3:
        with h5py.File(path, "r") as f:
            identity = {k: as_str(f.attrs[k]) for k in IDENTITY_KEYS}
    return journal_problems(path, sorted(check.statuses), identity, trusted)


def _press_seals(path: Path, pids: list[str]) -> set[tuple[str, str]]:
    """(press id, :func:`press_seal`) of the verified presses: what a later version may trust (``known_good``)."""
    seals: set[tuple[str, str]] = set()
    with h5py.File(path, "r") as f:
        for pid in pids:
            seal = press_seal(path, f["presses"], pid)
            if seal is not None:
                seals.add((pid, seal))
    return seals


def _open(path: Path) -> h5py.File:
    verified_session(path)
    try:
        f = h5py.File(path, "r")
    except OSError as exc:
        raise DataError(
            f"{path} is not a readable session file ({exc})",
            hint="rerun the collect command on that directory to rebuild it from the journal",
        ) from exc
    version = f.attrs.get("schema_version")
    if version is None or int(version) not in READABLE_SCHEMA_VERSIONS:
        f.close()
        raise DataError(
            f"{path} has session schema version {'none' if version is None else int(version)}, this unitac-rig "
            f"reads versions {READABLE_SCHEMA_VERSIONS[0]} to {SCHEMA_VERSION}",
            hint="re-collect or re-import the data with this version",
        )
    return f


def read_session_info(path: Path) -> SessionInfo:
    with _open(path) as f:
        attrs = {k: decode_attr(v) for k, v in f.attrs.items()}
    verified = verified_session(path)
    return SessionInfo(
        path=Path(path),
        object_id=str(attrs.get("object", "")),
        sensor=str(attrs.get("sensor", "")),
        simulated=bool(attrs.get("simulated", False)),
        attrs=attrs,
        integrity=verified.integrity,
        repairs=verified.repairs,
    )


def list_sessions(data_dir: Path) -> list[SessionInfo]:
    """Every session file directly in ``data_dir`` (broken copies set aside by recovery are skipped)."""
    data_dir = Path(data_dir)
    if not data_dir.is_dir():
        raise DataError(f"{data_dir} is not a directory", hint="pass the --data directory you collected into")
    paths = sorted(p for p in data_dir.glob("*__*.h5") if ".broken-" not in p.name)
    paths += _rebuild_vanished(data_dir, paths)
    return [read_session_info(p) for p in sorted(paths)]


def _rebuild_vanished(data_dir: Path, present: list[Path]) -> list[Path]:
    """Session files that are gone while the journal still holds their presses: rebuilt from the journal (a
    warning says so) or refused in one line, never left out (a vanished session would drop all its pairs)."""
    rebuilt: list[Path] = []
    names = {p.name for p in present}
    for journal in sorted((data_dir / ".journal").glob("*__*")):
        path = data_dir / f"{journal.name}.h5"
        entries = [p for p in journal.glob("*.h5") if ".broken-" not in p.name]
        if path.name in names or not entries or not journal.is_dir():
            continue
        if lease_holder(journal) is not None:
            log.info("%s: being created by a collection now; not listed yet", path)
            continue
        problem = (
            f"{path}: the session file is missing, but its journal .journal/{journal.name} holds {len(entries)} presses"
        )
        for note in repair_session(path, problem):
            log.warning("%s: %s", path, note)
        log.warning("%s was missing; rebuilt from its journal (%d presses)", path, len(entries))
        rebuilt.append(path)
    return rebuilt


def read_presses(path: Path, *, with_streams: bool = True) -> list[PressRecord]:
    with _open(path) as f:
        return [read_press_group(g) for _, g in iter_press_groups(f)] if with_streams else []


def press_summaries(path: Path) -> list[dict[str, Any]]:
    """Per-press attributes and extraction arrays without loading the raw streams."""
    out = []
    with _open(path) as f:
        for pid, g in iter_press_groups(f):
            item = {k: decode_attr(v) for k, v in g.attrs.items()}
            item["press_id"] = pid
            item["status"] = as_str(g.attrs["status"])
            ex = read_extraction(g)
            item["extraction"] = ex[0] if ex else None
            item["tactile_frames"] = int(g["tactile/t_s"].shape[0])
            item["robot_samples"] = int(g["robot/t_s"].shape[0])
            out.append(item)
    return out


def rig_label(attrs: dict[str, Any]) -> str:
    """Which rig recorded a session, from its root attributes: ``imported from <source>``, ``simulated rig '<rig
    name>'`` or ``hardware rig '<rig name>'``; "" when it names no rig (written by a script). Pairs join only within
    one label."""
    if attrs.get("source"):
        return f"imported from {attrs['source']}"
    if not attrs.get("rig"):  # a script's session names no rig: it cannot be told apart, so it is not checked
        return ""
    kind = "simulated" if attrs.get("simulated") else "hardware"
    return f"{kind} rig '{attrs['rig']}'"


def load_matched_set(path: Path) -> MatchedSet:
    info = read_session_info(path)
    rot, ang, tgt, vals, force, err = [], [], [], [], [], []
    with _open(path) as f:
        for _, g in iter_press_groups(f):
            if as_str(g.attrs["status"]) != "complete":
                continue
            ex = read_extraction(g)
            if ex is None:
                continue
            extraction, frames = ex
            keep = ~extraction.miss
            k = int(keep.sum())
            rot.append(np.full(k, float(g.attrs["rotation_deg"])))
            ang.append(np.full(k, float(g.attrs["angle_deg"])))
            tgt.append(extraction.targets_n[keep])
            vals.append(frames[keep])
            force.append(extraction.force_at_frame_n[keep])
            err.append(extraction.error_n[keep])
    spec = SENSORS.get(info.sensor)
    layout = spec.layout if spec else None
    n_taxels = layout.n_taxels if layout else (vals[0].shape[1] if vals else 0)

    def cat(parts: list[np.ndarray], shape: tuple[int, ...] = ()) -> np.ndarray:
        return np.concatenate(parts) if parts else np.zeros((0, *shape))

    return MatchedSet(
        object_id=info.object_id,
        sensor=info.sensor,
        simulated=info.simulated,
        rotation_deg=cat(rot),
        angle_deg=cat(ang),
        target_n=cat(tgt),
        values=cat(vals, (n_taxels, 3)).astype(np.float32),
        force_n=cat(force),
        error_n=cat(err),
        rig=rig_label(info.attrs),
    )


def load_matched_sets(data_dir: Path) -> list[MatchedSet]:
    """One MatchedSet per session in ``data_dir``; raises DataError when there is none."""
    sessions = list_sessions(data_dir)
    if not sessions:
        raise DataError(f"no session files (*__*.h5) in {data_dir}", hint="run `unitac-rig collect` first")
    return [load_matched_set(s.path) for s in sessions]


def root_config(path: Path) -> dict[str, Any]:
    with _open(path) as f:
        raw = f.attrs.get("config", "{}")
    value = json.loads(as_str(raw)) if isinstance(raw, bytes | str) else {}
    return value if isinstance(value, dict) else {}


def session_files(path: Path) -> list[Path]:
    """The files a session is stored in: the session file and every press file it links (none in the older
    single-file layout). Copy all of them (or use :func:`snapshot_session`) to move a session elsewhere."""
    path = Path(path)
    with _open(path) as f:
        links = session_layout(f)[0]
    return [path, *(path.parent / target for _, target in sorted(links.items()))]


def session_digest(path: Path) -> str:
    """Hex SHA-256 of a session's content: its root attributes and every press's checksums (computed for presses
    recorded without). The same for two copies of one session whatever their layout (single file, press files, an
    export's snapshot), different as soon as one press or attribute differs; what pooling calls one session."""
    digest = hashlib.sha256()
    with _open(path) as f:
        digest.update(attrs_digest((k, v) for k, v in root_attr_items(f)).encode())
        for pid, group in iter_press_groups(f):
            digest.update(f"\n{pid}\n{content_seal(group)}".encode())
    return digest.hexdigest()


def snapshot_session(path: Path, dest: Path) -> None:
    """Write the session ``path`` to ``dest`` as one self-contained HDF5 file (every press a group inside it, checksums
    as recorded): what an export ships. A single-file session is copied byte for byte; a session with press files is
    read from one version of its session file, so a collection writing it meanwhile changes nothing in the copy."""
    path, dest = Path(path), Path(dest)
    tmp = private_copy_path(dest)
    try:
        for _ in range(3):  # a single-file session may be moved into press files (by a writer) between two reads
            with _open(path) as f:
                if session_layout(f)[0]:
                    with h5py.File(tmp, "w") as out:
                        for key, value in f.attrs.items():
                            out.attrs[key] = value
                        presses = out.create_group("presses")
                        for pid, group in iter_press_groups(f):
                            f.copy(group, presses, pid)
                    break
            shutil.copyfile(path, tmp)
            with h5py.File(tmp, "r") as copied:
                if not session_layout(copied)[0]:
                    break
        os.replace(tmp, dest)
    except OSError as exc:
        raise DataError(f"could not copy {path} to {dest}: {exc}") from exc
    finally:
        tmp.unlink(missing_ok=True)
