"""SHA-256 checksums that travel with the data: every press group's arrays and attributes, and a session file's root
attributes, carry a digest from the moment they are recorded, so a flipped bit anywhere is caught on the next read.

A press group carries ``checksums`` (JSON): ``{"algorithm": "sha256", "arrays": {"robot/t_s": hex, ...}, "attrs":
hex}``. An array's digest covers its dtype, shape and bytes as written (events: their values as canonical JSON); the
``attrs`` digest covers the attributes of the group and of everything inside it (``write_complete`` and
``checksums`` excepted), as canonical JSON, so it survives the journal -> session file copy unchanged. The digests
are computed from the in-memory arrays when the press is first written (to the journal) and verified whenever a copy
is read; a copy is only ever made from a verified read, so the digests of a press never change after recording,
except the extraction's (``unitac-rig extract`` verifies the raw arrays, then recomputes the extraction and seals it
again). A session file's root carries ``attrs_sha256`` over its root attributes and the sorted list of its press
ids, so a press link removed, added or renamed is damage too.
A press's identity (object, sensor, session id, press id, angle) is in its attributes, so its seal covers it; the
checks that a press is in its right place are :func:`unitac_rig.storage.integrity.press_identity_problem`'s.
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
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
    return dict(json.loads(raw.decode() if isinstance(raw, bytes) else str(raw))["arrays"])


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
        return PressCheck("damaged", f"attributes unreadable ({_short(exc)})")
    if raw is None:
        return PressCheck("damaged", "it has no checksums")
    try:
        document = json.loads(raw.decode() if isinstance(raw, bytes) else str(raw))
        expected = dict(document["arrays"])
        expected_attrs = str(document["attrs"])
        if document.get("algorithm") != ALGORITHM:
            return PressCheck("damaged", f"unknown checksum algorithm {document.get('algorithm')!r}")
    except (ValueError, KeyError, TypeError, AttributeError) as exc:
        return PressCheck("damaged", f"checksums attribute unreadable ({_short(exc)})")
    try:
        present = dataset_paths(group)
    except Exception as exc:
        return PressCheck("damaged", f"group index unreadable ({_short(exc)})")
    for path in sorted(set(expected) | set(present)):
        if path not in present:
            return PressCheck("damaged", f"{path} is missing")
        if path not in expected:
            return PressCheck("damaged", f"{path} is not in its checksums")
        try:
            data = group[path][()]
        except Exception as exc:  # a damaged chunk fails decompression (OSError) or worse
            return PressCheck("damaged", f"{path} is unreadable ({_short(exc)})")
        if array_digest(data) != expected[path]:
            return PressCheck("damaged", f"{path} differs from its checksum")
    try:
        if attrs_digest(_group_attr_items(group)) != expected_attrs:
            return PressCheck("damaged", "its attributes differ from their checksum")
    except Exception as exc:
        return PressCheck("damaged", f"attributes unreadable ({_short(exc)})")
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
        expected = expected.decode() if isinstance(expected, bytes) else str(expected)
        if attrs_digest(_root_sealed_items(f)) != expected:
            return PressCheck("damaged", "its root attributes or press list differ from their checksum")
    except Exception as exc:
        return PressCheck("damaged", f"its root attributes are unreadable ({_short(exc)})")
    return PressCheck("ok")


def _short(exc: BaseException) -> str:
    text = " ".join(str(exc).split())
    return (text[:120] + "…") if len(text) > 120 else (text or type(exc).__name__)
