"""Verifying what was recorded: the SHA-256 checksums that travel with the data, and the check of a session file
against them (read-only; docs/dataset.md, "Integrity").

A press group carries ``checksums`` (JSON): ``{"algorithm": "sha256", "arrays": {"robot/t_s": hex, ...}, "attrs":
hex}``. An array's digest covers its dtype, shape and bytes as written (events: their values as canonical JSON); the
``attrs`` digest covers the attributes of the group and of everything inside it (``write_complete`` and
``checksums`` excepted) as canonical JSON, so it survives a copy unchanged. Digests are computed from the in-memory
arrays when a press is first written and never change afterwards, except the extraction's (``unitac-rig extract``
verifies the raw arrays, then seals the new extraction). A session file's root carries ``attrs_sha256`` over its
root attributes and sorted press ids, so a press link removed, added or renamed is damage too. A press's identity
(object, sensor, session id, press id, angle) is among its sealed attributes (:func:`press_identity_problem`).

:func:`check_session` reads every array of every press and never raises for damage; what to do about it is the
caller's: the recorder repairs from the journal, the readers repair or refuse
(:func:`unitac_rig.storage.reader.verified_session`).
"""

from __future__ import annotations

import hashlib
import json
import os
from collections.abc import Container, Iterable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import h5py
import numpy as np

ALGORITHM = "sha256"
PRESS_ATTR = "checksums"  # on every press group (journal entry or session file)
ROOT_ATTR = "attrs_sha256"  # on a session file's root
_UNSEALED_ATTRS = frozenset({"write_complete", PRESS_ATTR, ROOT_ATTR})


def _plain(value: Any) -> Any:
    """A stored value as plain JSON-able Python, the same whatever width or container HDF5 gave back."""
    if isinstance(value, bytes):
        return value.decode("utf-8")  # a flipped bit that breaks UTF-8 raises: the caller counts it as damage
    if isinstance(value, np.ndarray):
        return [_plain(v) for v in value.tolist()]
    if isinstance(value, np.generic):
        return _plain(value.item())
    if isinstance(value, list | tuple):
        return [_plain(v) for v in value]
    return value


def _canonical(value: Any) -> bytes:
    return json.dumps(value, sort_keys=True, separators=(",", ":"), allow_nan=True).encode("utf-8")


def array_digest(array: np.ndarray) -> str:
    """Hex SHA-256 of an array's dtype, shape and little-endian bytes (structured/object arrays: canonical JSON)."""
    a = np.asarray(array)
    digest = hashlib.sha256()
    if a.dtype.names is not None or a.dtype.hasobject:
        digest.update(b"json:" + _canonical(_plain(a.tolist())))
    else:
        a = np.ascontiguousarray(a)
        if a.dtype.byteorder == ">":
            a = a.astype(a.dtype.newbyteorder("<"))
        digest.update(f"{a.dtype.str}:{a.shape}:".encode())
        digest.update(a.tobytes())
    return digest.hexdigest()


def attrs_digest(items: Iterable[tuple[str, Any]]) -> str:
    """Hex SHA-256 of (path@name, value) attribute pairs as canonical JSON."""
    plain = {key: _plain(value) for key, value in items}
    return hashlib.sha256(_canonical(plain)).hexdigest()


def _group_attr_items(group: h5py.Group) -> list[tuple[str, Any]]:
    """Every attribute of ``group`` and of the groups and datasets inside it, keyed ``path@name``."""
    items = [(f"@{k}", v) for k, v in group.attrs.items() if k not in _UNSEALED_ATTRS]

    def visit(name: str, obj: Any) -> None:
        items.extend((f"{name}@{k}", v) for k, v in obj.attrs.items())

    group.visititems(visit)
    return items


def dataset_paths(group: h5py.Group) -> list[str]:
    paths: list[str] = []
    group.visititems(lambda name, obj: paths.append(name) if isinstance(obj, h5py.Dataset) else None)
    return sorted(paths)


def seal_press_group(group: h5py.Group, arrays: Mapping[str, str]) -> None:
    """Store the array digests (computed by the writer from what it wrote) and the digest of the attributes now."""
    document = {"algorithm": ALGORITHM, "arrays": dict(sorted(arrays.items()))}
    group.attrs[PRESS_ATTR] = json.dumps({**document, "attrs": attrs_digest(_group_attr_items(group))})


def sealed_arrays(group: h5py.Group) -> dict[str, str]:
    """The array digests a (verified) press group carries."""
    raw = group.attrs[PRESS_ATTR]
    return dict(json.loads(as_str(raw))["arrays"])


@dataclass(frozen=True)
class PressCheck:
    """The outcome of verifying one press group or a root: ``ok`` or ``damaged`` (why: ``detail``)."""

    state: str
    detail: str = ""

    @property
    def damaged(self) -> bool:
        return self.state == "damaged"


def check_press_group(group: h5py.Group) -> PressCheck:
    """Read every array of a press group and compare it with the digests it carries. Never raises for damage: an
    unreadable chunk, a missing or extra dataset, a changed byte or attribute all come back as ``damaged``."""
    try:
        raw = group.attrs.get(PRESS_ATTR)
    except Exception as exc:  # h5py raises many types for damaged metadata
        return PressCheck("damaged", f"attributes unreadable ({_one_line(exc)})")
    if raw is None:
        return PressCheck("damaged", "it has no checksums")
    try:
        document = json.loads(as_str(raw))
        expected = dict(document["arrays"])
        expected_attrs = str(document["attrs"])
        if document.get("algorithm") != ALGORITHM:
            return PressCheck("damaged", f"unknown checksum algorithm {document.get('algorithm')!r}")
    except (ValueError, KeyError, TypeError, AttributeError) as exc:
        return PressCheck("damaged", f"checksums attribute unreadable ({_one_line(exc)})")
    try:
        present = dataset_paths(group)
    except Exception as exc:
        return PressCheck("damaged", f"group index unreadable ({_one_line(exc)})")
    for path in sorted(set(expected) | set(present)):
        if path not in present:
            return PressCheck("damaged", f"{path} is missing")
        if path not in expected:
            return PressCheck("damaged", f"{path} is not in its checksums")
        try:
            data = group[path][()]
        except Exception as exc:  # a damaged chunk fails decompression (OSError) or worse
            return PressCheck("damaged", f"{path} is unreadable ({_one_line(exc)})")
        if array_digest(data) != expected[path]:
            return PressCheck("damaged", f"{path} differs from its checksum")
    try:
        if attrs_digest(_group_attr_items(group)) != expected_attrs:
            return PressCheck("damaged", "its attributes differ from their checksum")
    except Exception as exc:
        return PressCheck("damaged", f"attributes unreadable ({_one_line(exc)})")
    return PressCheck("ok")


def root_attr_items(f: h5py.File) -> list[tuple[str, Any]]:
    return [(k, v) for k, v in f.attrs.items() if k not in _UNSEALED_ATTRS]


def _root_sealed_items(f: h5py.File) -> list[tuple[str, Any]]:
    """What a root seal covers: the root attributes and the sorted press ids."""
    presses = f.get("presses")
    return [*root_attr_items(f), (" presses", sorted(presses) if presses is not None else [])]


def seal_root(f: h5py.File) -> None:
    f.attrs[ROOT_ATTR] = attrs_digest(_root_sealed_items(f))


def check_root(f: h5py.File) -> PressCheck:
    """Verify a session file's root attributes (and press list) against ``attrs_sha256``; a missing seal is damage
    (a damaged attribute heap can hide it), never "unsealed"."""
    try:
        names = list(f.attrs)
        if ROOT_ATTR not in names:
            return PressCheck("damaged", "its root seal (attrs_sha256) is missing or unreadable")
        expected = f.attrs[ROOT_ATTR]
        expected = as_str(expected)
        if attrs_digest(_root_sealed_items(f)) != expected:
            return PressCheck("damaged", "its root attributes or press list differ from their checksum")
    except Exception as exc:
        return PressCheck("damaged", f"its root attributes are unreadable ({_one_line(exc)})")
    return PressCheck("ok")


#: the one session format: SHA-256 checksums on every press and on the root attributes, every press carrying its
#: identity (IDENTITY_KEYS, press id, angle) under its seal, the root seal covering the list of presses
SCHEMA_VERSION = 3
#: what names the session a press belongs to: in the session's root attributes and in every press's
IDENTITY_KEYS = ("object", "sensor", "session_id")
PRESS_DIR_SUFFIX = ".presses"  # a session's press files: ``<object>__<sensor>.presses/<press_id>-<sha12>.h5``


def as_str(value: Any) -> str:
    """A stored string attribute as text (h5py gives bytes or str)."""
    return value.decode() if isinstance(value, bytes) else str(value)


def canonical_press_id(rotation_deg: float, angle_deg: float) -> str:
    """Stable, sortable name of a press: ``rot090_ang-12``."""
    return f"rot{round(rotation_deg) % 360:03d}_ang{round(angle_deg):+03d}"


def press_identity_problem(group: h5py.Group, pid: str, identity: dict[str, str], link: str | None) -> str | None:
    """Why the press group stored as ``pid`` (through the press file ``link``, relative to the session's folder;
    None for a group inside the file) is not that press of the session ``identity`` names, or None when it is.

    The group's attributes are under its seal, so once its checksums match they say truly which press this is; a
    press intact but in the wrong place (another object's or sensor's file copied over it, two press files or
    journal entries swapped) is caught here."""
    try:
        attrs = {key: as_str(group.attrs[key]) for key in (*IDENTITY_KEYS, "press_id") if key in group.attrs}
        rotation, angle = float(group.attrs["rotation_deg"]), float(group.attrs["angle_deg"])
    except Exception as exc:
        return f"its identity attributes are unreadable ({_one_line(exc)})"
    for key, expected in identity.items():
        if key not in attrs:
            return f"it carries no {key}"
        if attrs[key] != expected:
            return f"it is a press of {key} {attrs[key]!r}, not of {expected!r}: in the wrong place"
    if attrs.get("press_id") != pid:
        return f"it holds press {attrs.get('press_id')!r}, not {pid}: in the wrong place"
    made = canonical_press_id(rotation, angle)
    if pid != made and not pid.startswith(f"{made}_"):  # repeats of one pose carry a suffix
        return f"its rotation {rotation:g} and angle {angle:g} do not make press id {pid}"
    if link is not None:
        target = Path(link)
        stem = f"{identity['object']}__{identity['sensor']}" if "object" in identity and "sensor" in identity else None
        if stem is not None and target.parent.name != f"{stem}{PRESS_DIR_SUFFIX}":
            return f"its link points into {target.parent}, not into {stem}{PRESS_DIR_SUFFIX}"
        if not (target.name.startswith(f"{pid}-") and target.suffix == ".h5"):
            return f"its link names the file {target.name}, not a file of press {pid}"
    return None


def root_identity(f: h5py.File, path: Path) -> tuple[dict[str, str], str | None]:
    """(the session identity a file's verified root names, why it does not fit the file's name or None)."""
    try:
        identity = {key: as_str(f.attrs[key]) for key in IDENTITY_KEYS if key in f.attrs}
    except Exception as exc:
        return {}, f"its identity attributes are unreadable ({_one_line(exc)})"
    missing = [key for key in IDENTITY_KEYS if key not in identity]
    if missing:
        return identity, f"its root attributes carry no {', '.join(missing)}"
    expected = f"{identity['object']}__{identity['sensor']}.h5"
    if Path(path).name != expected and ".broken-" not in Path(path).name:
        return identity, f"it holds the session {expected}, not {Path(path).name}: in the wrong place"
    return identity, None


@dataclass
class SessionCheck:
    """What :func:`check_session` found in one session file."""

    path: Path
    version: int | None = None  # schema_version (None: the attribute is missing, a foreign file)
    file_problem: str | None = None  # the file cannot be used at all (does not open, foreign, index unreadable)
    root_problem: str | None = None  # the root attributes differ from their checksum
    damaged: dict[str, str] = field(default_factory=dict)  # press id -> what is wrong
    identity: dict[str, str] = field(default_factory=dict)  # what the verified root names (IDENTITY_KEYS)
    seals: set[tuple[str, str]] = field(default_factory=set)  # (press id, press_seal) of every verified press
    half_written: list[str] = field(default_factory=list)  # groups without write_complete (readers skip them)
    statuses: dict[str, str] = field(default_factory=dict)  # status of every intact, complete-written press

    @property
    def needs_repair(self) -> bool:
        return bool(self.file_problem or self.root_problem or self.damaged)

    def first_problem(self) -> str:
        """One line naming the file and, where it is one press, the press."""
        if self.file_problem:
            return f"{self.path}: {self.file_problem}"
        if self.root_problem:
            return f"{self.path}: {self.root_problem}"
        pid, what = next(iter(self.damaged.items()))
        more = f" (and {len(self.damaged) - 1} more presses)" if len(self.damaged) > 1 else ""
        return f"{self.path}: press {pid}: {what}{more}"


def check_session(path: Path, known_good: Container[tuple[str, str]] = ()) -> SessionCheck:
    """Verify every press (and the root attributes) of a session file; see :class:`SessionCheck`.

    ``known_good`` holds (press id, :func:`press_seal`) pairs this process verified in an earlier version
    of the same file: those are trusted without reading their arrays again (how ``inspect --watch`` keeps up with
    a collection, whose every press republishes the file).
    """
    path = Path(path)
    check = SessionCheck(path)
    try:
        f = h5py.File(path, "r")
    except OSError as exc:
        check.file_problem = f"could not be opened ({_one_line(exc)})"
        return check
    with f:
        try:
            raw = f.attrs.get("schema_version")
            check.version = None if raw is None else int(raw)
        except Exception as exc:  # a damaged attribute heap
            check.file_problem = f"its attributes could not be read ({_one_line(exc)})"
            return check
        if check.version is None:
            check.file_problem = "is not a unitac-rig session file (no schema_version attribute)"
            return check
        if check.version != SCHEMA_VERSION:
            return check  # another format: not ours to judge (the readers say which version it is)
        root = check_root(f)
        if root.damaged:
            check.root_problem = root.detail
        else:
            check.identity, check.root_problem = root_identity(f, path)
        try:
            presses = f["presses"]
            names = sorted(presses)
        except Exception as exc:
            check.file_problem = f"its press index could not be read ({_one_line(exc)})"
            return check
        for pid in names:
            try:
                link = presses.get(pid, getlink=True)
            except Exception as exc:
                check.damaged[pid] = f"its link could not be read ({_one_line(exc)})"
                continue
            filename = str(link.filename) if isinstance(link, h5py.ExternalLink) else None
            if missing := _missing_press_file(path, filename):
                check.damaged[pid] = missing
                continue
            try:
                g = presses[pid]
                complete = bool(g.attrs.get("write_complete", False))
            except Exception as exc:
                check.damaged[pid] = f"its group could not be opened ({_one_line(exc)})"
                continue
            if not complete:
                check.half_written.append(pid)
                continue
            seal = press_seal(path, presses, pid)
            trusted = seal is not None and (pid, seal) in known_good
            result = PressCheck("ok") if trusted else check_press_group(g)
            if result.damaged:
                check.damaged[pid] = result.detail
            elif check.identity and (wrong := press_identity_problem(g, pid, check.identity, filename)):
                check.damaged[pid] = wrong
            else:
                try:
                    status = g.attrs["status"]
                    check.statuses[pid] = as_str(status)
                except Exception as exc:  # a press trusted from an earlier read whose file changed since
                    check.damaged[pid] = f"its status could not be read ({_one_line(exc)})"
                    continue
                if seal is not None:
                    check.seals.add((pid, seal))
    return check


def press_seal(path: Path, presses: h5py.Group, pid: str) -> str | None:
    """What a verified press is remembered by (``known_good``): its ``checksums`` attribute and, for a press file,
    the file's identity (name, inode, size, mtime), so a press file changed since (damaged, replaced) is read again.
    None when the press has no checksums or its file cannot be looked at."""
    try:
        raw = presses[pid].attrs.get(PRESS_ATTR)
        if raw is None:
            return None
        seal = as_str(raw)
        link = presses.get(pid, getlink=True)
        if isinstance(link, h5py.ExternalLink):
            seal += f"|{link.filename}|{file_stamp(Path(path).parent / str(link.filename))}"
        else:  # a group inside the session file (an export's copy): trusted only while that file is unchanged
            seal += f"|.|{file_stamp(Path(path))}"
    except Exception:  # damaged metadata raises anything: the press is then read in full
        return None
    return seal


def file_stamp(path: Path) -> str:
    """A file's identity and version: device, inode, size, mtime and ctime (ns). Any write, copy or rename-over
    changes it (ctime cannot be set back by ``touch``), so a result remembered for one stamp holds only for it."""
    st = os.stat(path)
    return f"{st.st_dev}:{st.st_ino}:{st.st_size}:{st.st_mtime_ns}:{st.st_ctime_ns}"


def _missing_press_file(path: Path, filename: str | None) -> str | None:
    """Why the press file a press links to (``filename``; None: a group inside the file) cannot be there (missing,
    or outside the session's folder), or None. A session file copied without its ``.presses/`` folder has its presses
    missing: damage to repair from the journal or to refuse, never a silent gap."""
    if filename is None:
        return None
    target = Path(filename)
    if target.is_absolute() or ".." in target.parts:
        return f"it links to {target}, outside the session's folder"
    if not (path.parent / target).is_file():
        return f"its press file {target} is missing"
    return None


def _one_line(exc: BaseException) -> str:
    text = " ".join(str(exc).split())
    return (text[:160] + "…") if len(text) > 160 else (text or type(exc).__name__)
