"""Path checks every command makes before any work: a usage error (exit 2, one line naming the option) rather than
an "unexpected OSError" after minutes of work, or a run written into the wrong place.
"""

from __future__ import annotations

import contextlib
import os
import tempfile
from pathlib import Path

import typer

from unitac_rig.errors import UsageError


def path_text(value: str | Path) -> Path:
    """A path option or argument as typed (typer's ``parser=``); an empty one (``--data ""``) is a usage error, where
    ``Path("")`` would quietly mean the current directory."""
    if isinstance(value, Path):  # the option's default
        return value
    if not value.strip():
        raise typer.BadParameter("an empty path (name a folder, e.g. data)")
    return Path(value)


def require_directory(path: Path, option: str, hint: str | None = None) -> None:
    """``path`` exists and is a folder, else a usage error naming ``option`` (``DATA`` for an argument)."""
    if path.is_dir():
        return
    what = "is a file, not a folder" if path.exists() else "does not exist"
    raise UsageError(f"{option} {path} {what}", hint=hint)


def require_data_folder(path: Path, option: str = "--data") -> None:
    """A folder to collect into: it may not exist yet, but nothing on the way may be a file and it must be
    creatable (checked before the arm moves)."""
    if path.exists() and not path.is_dir():
        raise UsageError(f"{option} {path} is a file, not a folder", hint="name a folder to collect into")
    if not path.exists():
        require_writable_output(path, option)


def require_empty_output(path: Path, option: str, taken: str, hint: str) -> None:
    """An output folder a command will create or fill (``export --out``, ``train --out``): new or empty (else a
    usage error saying it is ``taken``), and writable (:func:`require_writable_output`)."""
    if path.exists() and (not path.is_dir() or any(path.iterdir())):
        raise UsageError(f"{option} {path} {taken}", hint=hint)
    require_writable_output(path, option)


def require_writable_output(path: Path, option: str) -> None:
    """``path`` can be created (or filled, when it is an existing folder) by this process, else a usage error: every
    existing part of it is a folder and the deepest one accepts a probe folder, removed at once (permission bits do
    not tell root, read-only mounts or /proc)."""
    existing = path.absolute()
    while not existing.exists() and existing != existing.parent:
        existing = existing.parent
    if not existing.is_dir():
        raise UsageError(f"{option} {path}: {existing} is a file, not a folder", hint=f"choose another {option}")
    try:
        probe = tempfile.mkdtemp(prefix=".unitac-rig-probe-", dir=existing)
    except OSError as exc:
        reason = exc.strerror or str(exc)
        raise UsageError(
            f"{option} {path} cannot be created in {existing} ({reason})", hint=f"choose another {option}"
        ) from None
    with contextlib.suppress(OSError):
        os.rmdir(probe)
