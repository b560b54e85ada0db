"""Finding the UniTac-NV files under a SOURCE folder (the layouts of docs/import.md, names compared
case-insensitively) and naming them in this project's terms; anything else (their flattened CSV copies, notebooks,
CAD) is listed as ignored."""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

from unitac_rig.errors import ConfigError
from unitac_rig.importer.conventions import ImportConventions

_RAW_FOLDER = re.compile(r"^(?P<shape>[a-z]+)_(?P<material>pla|tpu)$", re.IGNORECASE)
_RAW_FILE = re.compile(r"^sensor_data_\d{8}_\d{6}\.csv$", re.IGNORECASE)
_ARBITRARY_RAW = re.compile(r"^(?P<sensor>[a-z]+)_arbitrary_(?P<index>\d+)\.csv$", re.IGNORECASE)
_PROCESSED = re.compile(
    r"^(?P<shape>[a-z]+?)(?P<index>\d+)?_(?P<material>pla|tpu)_(?P<sensor>[a-z]+)\.npz$", re.IGNORECASE
)

KINDS = ("raw", "processed")


@dataclass(frozen=True)
class SourceFile:
    """One recognised UniTac-NV file and the session it belongs to."""

    path: Path
    relative: str  # path relative to SOURCE, as stored in the session
    kind: str  # raw | processed
    object_id: str
    sensor: str  # our sensor id
    rotation_deg: float | None  # None: arbitrary file with no rotation in the conventions
    arbitrary_index: int | None = None


def _sensor(conv: ImportConventions, name: str) -> str | None:
    return conv.sensor_names.get(name.lower())


def _rotation(conv: ImportConventions, index: int | None) -> float | None:
    if index is None:
        return 0.0
    return conv.arbitrary_rotation_deg.get(index)


def classify(path: Path, source_root: Path, conv: ImportConventions) -> SourceFile | None:
    """What ``path`` is, or None when it is not a UniTac-NV session file."""
    relative = path.relative_to(source_root).as_posix() if path != source_root else path.name
    name = path.name
    if path.suffix.lower() == ".csv":
        sensor = _sensor(conv, path.parent.name)
        if sensor is None:
            return None
        if _RAW_FILE.match(name):
            folder = _RAW_FOLDER.match(path.parent.parent.name)
            if folder is None:
                return None
            object_id = conv.object_id(folder["shape"], folder["material"])
            return SourceFile(path, relative, "raw", object_id, sensor, 0.0)
        arbitrary = _ARBITRARY_RAW.match(name)
        if arbitrary is not None and _sensor(conv, arbitrary["sensor"]) == sensor:
            index = int(arbitrary["index"])
            object_id = conv.object_id("arbitrary", conv.arbitrary_material)
            return SourceFile(path, relative, "raw", object_id, sensor, _rotation(conv, index), index)
        return None
    if path.suffix.lower() == ".npz":
        match = _PROCESSED.match(name)
        if match is None:
            return None
        sensor = _sensor(conv, match["sensor"])
        if sensor is None:
            return None
        file_index: int | None = int(match["index"]) if match["index"] else None
        if file_index is not None and match["shape"].lower() != "arbitrary":
            return None
        object_id = conv.object_id(match["shape"], match["material"])
        return SourceFile(path, relative, "processed", object_id, sensor, _rotation(conv, file_index), file_index)
    return None


@dataclass
class Discovery:
    files: list[SourceFile]
    ignored: list[str]  # relative paths of files that are not UniTac-NV sessions
    superseded: list[SourceFile]  # processed files not used because raw files of the same session exist


def discover(source: Path, conv: ImportConventions, mode: str = "auto") -> Discovery:
    """Every UniTac-NV file under ``source`` (a folder or one file).

    ``mode``: ``raw`` or ``processed`` keeps only that kind; ``auto`` uses the raw files of a session when there
    are any and its processed files otherwise (raw files keep the raw counts and the authors' dropped rows).
    """
    if mode not in ("auto", *KINDS):
        raise ConfigError(f"unknown import mode {mode!r}", hint="use auto, raw or processed")
    source = Path(source)
    if source.is_file():
        root = source.parent
        candidates = [source]
    else:
        root = source
        candidates = sorted(p for p in source.rglob("*") if p.is_file())
    files, ignored = [], []
    for path in candidates:
        if path.suffix.lower() not in (".csv", ".npz"):
            continue
        found = classify(path, root, conv)
        if found is None:
            ignored.append(path.relative_to(root).as_posix())
        elif mode in ("auto", found.kind):
            files.append(found)
    superseded = []
    if mode == "auto":
        with_raw = {(f.object_id, f.sensor) for f in files if f.kind == "raw"}
        superseded = [f for f in files if f.kind == "processed" and (f.object_id, f.sensor) in with_raw]
        files = [f for f in files if f not in superseded]
    return Discovery(files=files, ignored=ignored, superseded=superseded)
