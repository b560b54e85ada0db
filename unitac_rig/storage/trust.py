"""Verify once, trust what is unchanged: what the readers verified, remembered across processes.

Verifying a session reads and hashes every press (docs/dataset.md, "Integrity"); ``inspect`` on a lab's dataset did
that on every call. A press verified once is remembered in its journal folder (``.journal/<session>/_verified.json``)
by its ``checksums`` and its press file's stamp (device, inode, size, mtime and ctime in ns: any write, copy, rename
over or ``touch`` changes one of them), and a journal entry by its stamp. A later reader trusts exactly those, and
reads in full anything whose stamp changed. The file is only a cache: unreadable or missing, everything is verified
again; a folder without a journal (an export's copy) is verified in full every time.
"""

from __future__ import annotations

import json
import logging
import os
from collections.abc import Iterable, Mapping
from pathlib import Path

log = logging.getLogger(__name__)

TRUST_NAME = "_verified.json"
TRUST_VERSION = 1


def trust_path(session: Path) -> Path:
    session = Path(session)
    return session.parent / ".journal" / session.stem / TRUST_NAME


def load_trust(session: Path) -> tuple[set[tuple[str, str]], dict[str, str]]:
    """(press id, press seal) pairs and journal entry name -> stamp that an earlier reader verified (empty when
    nothing is remembered or the record is unreadable)."""
    try:
        document = json.loads(trust_path(session).read_text())
        if document.get("version") != TRUST_VERSION:
            return set(), {}
        presses = {(str(pid), str(seal)) for pid, seal in document["presses"]}
        journal = {str(k): str(v) for k, v in dict(document["journal"]).items()}
    except (OSError, ValueError, KeyError, TypeError, AttributeError):
        return set(), {}
    return presses, journal


def save_trust(session: Path, presses: Iterable[tuple[str, str]], journal: Mapping[str, str]) -> None:
    """Remember what was just verified (only where the session has a journal folder); never raises: a read-only
    dataset is simply verified in full again next time."""
    path = trust_path(session)
    if not path.parent.is_dir():
        return
    document = {"version": TRUST_VERSION, "presses": sorted(presses), "journal": dict(sorted(journal.items()))}
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    try:
        tmp.write_text(json.dumps(document))
        os.replace(tmp, path)
    except OSError as exc:
        log.debug("could not remember verified presses in %s: %s", path, exc)
        tmp.unlink(missing_ok=True)
