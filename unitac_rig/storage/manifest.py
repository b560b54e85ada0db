"""What every export shares: building it in a hidden sibling folder and publishing it whole (:func:`staging_for`,
:func:`publish_when_done`), what it says about its maker and sensors, and ``manifest.json``: every file of the export
but itself (path, bytes, SHA-256) plus what the exporter describes. :func:`verify_manifest` re-hashes them, stops at
the first that is missing or differs, and refuses files the manifest does not list.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import logging
import os
import shutil
import sys
from collections.abc import Iterable, Iterator, Mapping
from dataclasses import dataclass
from pathlib import Path, PurePosixPath
from typing import Any

import numpy as np

from unitac_rig.errors import DataError
from unitac_rig.provenance import git_commit, package_version

log = logging.getLogger(__name__)

MANIFEST_NAME = "manifest.json"
MANIFEST_VERSION = 1
HASH_CHUNK_BYTES = 1 << 20


def sha256_file(path: Path) -> str:
    """Hex SHA-256 of a file's bytes. A published session file is never changed in place (the recorder swaps in a
    new file), so one open reads one consistent version even while a collection runs."""
    digest = hashlib.sha256()
    with open(path, "rb") as fh:
        while chunk := fh.read(HASH_CHUNK_BYTES):
            digest.update(chunk)
    return digest.hexdigest()


def write_manifest(root: Path, document: Mapping[str, Any], files: Iterable[str]) -> Path:
    """Write ``root/manifest.json``: ``document`` plus ``manifest_version`` and the ``files`` list (hashed now)."""
    root = Path(root)
    body = {"manifest_version": MANIFEST_VERSION, **document}
    body["files"] = [
        {"path": rel, "bytes": (root / rel).stat().st_size, "sha256": sha256_file(root / rel)} for rel in sorted(files)
    ]
    path = root / MANIFEST_NAME
    tmp = path.with_name(f".{MANIFEST_NAME}.tmp")
    tmp.write_text(json.dumps(body, indent=1, sort_keys=False) + "\n", encoding="utf-8")
    os.replace(tmp, path)
    return path


def read_manifest(root: Path) -> dict[str, Any]:
    path = Path(root) / MANIFEST_NAME
    try:
        document = json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise DataError(f"{path} does not exist", hint="pass a directory written by `unitac-rig export`") from None
    except RecursionError:
        raise DataError(f"{path} is not a manifest (nested too deeply to be one)") from None
    except (OSError, ValueError) as exc:
        raise DataError(f"{path} is not readable JSON ({exc})") from exc
    if not isinstance(document, dict) or not isinstance(document.get("files"), list):
        raise DataError(f"{path} has no 'files' list", hint="pass a directory written by `unitac-rig export`")
    version = document.get("manifest_version")
    if version != MANIFEST_VERSION:
        raise DataError(f"{path} has manifest version {version!r}; this unitac-rig reads {MANIFEST_VERSION}")
    return document


@dataclass(frozen=True)
class VerifyReport:
    files: int
    bytes: int


def _safe_relative(root: Path, relative: object) -> Path:
    """The listed path under ``root``; a manifest may not point outside its directory."""
    if not isinstance(relative, str) or not relative:
        raise DataError(f"{root / MANIFEST_NAME} lists a file without a path")
    pure = PurePosixPath(relative)
    if pure.is_absolute() or ".." in pure.parts:
        raise DataError(f"{root / MANIFEST_NAME} lists {relative!r}, which is outside the export directory")
    return root / pure


def verify_manifest(root: Path) -> VerifyReport:
    """Check every listed file's size and SHA-256; DataError naming the first file that does not match, or a file
    that is there but not listed."""
    root = Path(root)
    document = read_manifest(root)
    total = 0
    listed: set[str] = set()
    for entry in document["files"]:
        if not isinstance(entry, dict):
            raise DataError(f"{root / MANIFEST_NAME} has a malformed file entry: {repr(entry)[:80]}")
        path = _safe_relative(root, entry.get("path"))
        listed.add(str(entry["path"]))
        if not path.is_file():
            raise DataError(f"{path}: listed in the manifest but missing", hint="copy the export again")
        size = path.stat().st_size
        if size != entry.get("bytes"):
            raise DataError(
                f"{path}: {size} bytes, the manifest says {entry.get('bytes')}", hint="copy the export again"
            )
        digest = sha256_file(path)
        if digest != entry.get("sha256"):
            raise DataError(
                f"{path}: SHA-256 {digest[:16]}… differs from the manifest's {str(entry.get('sha256'))[:16]}…",
                hint="the file changed after export: copy the export again",
            )
        total += size
    unlisted = tuple(
        sorted(
            rel
            for rel in (p.relative_to(root).as_posix() for p in root.rglob("*") if not p.is_dir())
            if rel not in listed and rel != MANIFEST_NAME
        )
    )
    if unlisted:
        more = f" and {len(unlisted) - 1} more" if len(unlisted) > 1 else ""
        raise DataError(
            f"{root / unlisted[0]}{more}: not in the manifest (added after export)",
            hint="remove what was added, or copy the export again",
        )
    return VerifyReport(files=len(listed), bytes=total)


def sensor_layout_info(sensor: str, n_taxels: int = 0) -> dict[str, Any]:
    """A sensor's taxel grid for manifests and cards (model, rows, cols, n_taxels, pitch_mm, units); a sensor the
    registry does not know is one column of ``n_taxels``."""
    from unitac_rig.rig.sensors import SENSORS

    keys = ("model", "rows", "cols", "n_taxels", "pitch_mm", "units")
    spec = SENSORS.get(sensor)
    if spec is None:
        return dict(zip(keys, ("unknown", n_taxels, 1, n_taxels, None, "sensor units"), strict=True))
    return {key: getattr(spec.layout, key) for key in keys}


def frames_array(values: np.ndarray) -> Any:
    """(M, n_taxels, 3) frames -> an Arrow list<list<float32>> array of M frames, without Python loops."""
    import pyarrow as pa

    values = np.ascontiguousarray(values, dtype=np.float32)
    m, n = int(values.shape[0]), int(values.shape[1])
    inner = pa.ListArray.from_arrays(
        pa.array(np.arange(0, m * n * 3 + 1, 3, dtype=np.int32)), pa.array(values.reshape(-1))
    )
    return pa.ListArray.from_arrays(pa.array(np.arange(0, m * n + 1, n, dtype=np.int32)), inner)


def exported_by() -> dict[str, str]:
    """Which unitac-rig wrote an export, and the command line that asked for it."""
    command = " ".join([Path(sys.argv[0]).name, *sys.argv[1:]]) if sys.argv else ""
    return {"package_version": package_version(), "git_commit": git_commit(), "command": command}


def staging_for(out: Path) -> Path:
    """A fresh hidden sibling of ``out`` to build an export in (renamed into place when complete, so ``out`` is
    complete or absent); refuses an ``out`` that exists and is not an empty directory."""
    if out.exists() and (not out.is_dir() or any(out.iterdir())):
        raise DataError(
            f"{out} already exists and is not an empty directory",
            hint="choose a new --out directory (an export is never merged into another one)",
        )
    out.parent.mkdir(parents=True, exist_ok=True)
    remove_dead_staging(out.parent)
    staging = out.parent / f".{out.name}.partial-{os.getpid()}"
    if staging.exists():
        shutil.rmtree(staging)
    staging.mkdir(parents=True)
    return staging


def _pid_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except OSError:  # EPERM: it exists, run by someone else
        return True
    return True


def remove_dead_staging(folder: Path) -> list[Path]:
    """Remove the half-built exports (``.<out>.partial-<pid>``) in ``folder`` whose process is gone (killed during
    an export): a staging folder never outlives the process that built it by more than the next export's start.
    Returns what was removed."""
    removed = []
    for staging in folder.glob(".*.partial-*"):
        pid = staging.name.rsplit("-", 1)[-1]
        if staging.is_dir() and pid.isdigit() and not _pid_alive(int(pid)):
            shutil.rmtree(staging, ignore_errors=True)
            removed.append(staging)
            log.info("removed %s, left by an export that was killed (pid %s)", staging, pid)
    return removed


@contextlib.contextmanager
def publish_when_done(staging: Path, out: Path) -> Iterator[Path]:
    """Build an export in ``staging`` inside the block; when it ends, rename ``staging`` to ``out`` (an empty ``out``
    directory is replaced), and when it raises, remove ``staging``: ``out`` is complete or absent, never half-written.
    Every export (Parquet, LeRobot, a trained model) publishes through this."""
    try:
        yield staging
        if out.exists():
            out.rmdir()  # empty: the caller refused anything else before building
        os.replace(staging, out)
    except BaseException:
        shutil.rmtree(staging, ignore_errors=True)
        raise
