"""``manifest.json``: what a dataset export holds, and the SHA-256 of every file in it, so a copy can be checked.

The manifest lists every file of the export (relative path, size in bytes, SHA-256) except itself, plus whatever
the exporter describes (schema, units, counts, provenance; see :mod:`unitac_rig.storage.export`).
:func:`verify_manifest` re-hashes the files and stops at the first one that is missing, has another size or
another hash, and refuses a directory holding files the manifest does not list (added after export).
"""

from __future__ import annotations

import hashlib
import json
import os
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path, PurePosixPath
from typing import Any

from unitac_rig.errors import DataError

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


def file_entry(root: Path, relative: str) -> dict[str, Any]:
    path = Path(root) / relative
    return {"path": relative, "bytes": path.stat().st_size, "sha256": sha256_file(path)}


def write_manifest(root: Path, document: Mapping[str, Any], files: Iterable[str]) -> Path:
    """Write ``root/manifest.json``: ``document`` plus ``manifest_version`` and the ``files`` list (hashed now)."""
    root = Path(root)
    body = {"manifest_version": MANIFEST_VERSION, **document}
    body["files"] = [file_entry(root, rel) for rel in sorted(files)]
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
    unlisted: tuple[str, ...]  # files in the directory the manifest does not mention (verify_manifest refuses them)


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
    return VerifyReport(files=len(listed), bytes=total, unlisted=unlisted)
