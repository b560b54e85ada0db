"""Re-extraction of recorded sessions (``unitac-rig extract``): the force-matched frames of every press recomputed
with new settings, all or nothing across sessions (private copies, fsynced, renamed into place only when all are
built). The raw arrays are never rewritten; a press file gets a new name because its content changed."""

from __future__ import annotations

import contextlib
import json
import os
import shutil
from collections.abc import Callable
from pathlib import Path

import h5py
import numpy as np

from unitac_rig.errors import DataError
from unitac_rig.storage.extraction import Extraction, ExtractionSettings, extract_press
from unitac_rig.storage.integrity import ROOT_ATTR, check_session
from unitac_rig.storage.journal import journal_entry_check, read_journal_header, session_journal, write_header
from unitac_rig.storage.lease import SessionLease
from unitac_rig.storage.manifest import sha256_file
from unitac_rig.storage.press_record import iter_press_groups, reseal_extraction, write_extraction
from unitac_rig.storage.recorder import (
    PRESS_GROUP,
    SessionWriter,
    ensure_room,
    press_dir,
    private_copy_path,
    session_bytes,
    session_header,
    session_layout,
    write_session_file,
)


def _reextract_group(g: h5py.Group, settings: ExtractionSettings) -> Extraction:
    values = g["tactile/values"][()]
    extraction = extract_press(
        g["robot/t_s"][()], g["robot/press_force_n"][()], g["tactile/t_s"][()], g["tactile/valid"][()], settings
    )
    digests = write_extraction(g, extraction, values - g["tare_baseline"][()].astype(np.float32)[None])
    reseal_extraction(g, digests)  # the raw arrays were verified before (reextract_sessions)
    return extraction


def _reextract_copy(path: Path, settings: ExtractionSettings) -> tuple[Path, int]:
    """A fsynced private copy of the press file or journal entry ``path`` (group ``press``) with its extraction
    recomputed: (the copy, targets matched)."""
    tmp = private_copy_path(path)
    shutil.copy2(path, tmp)
    with h5py.File(tmp, "a") as f:
        matched = _reextract_group(f[PRESS_GROUP], settings).n_matched
    with open(tmp, "rb+") as fh:
        os.fsync(fh.fileno())
    return tmp, matched


def _reextract_session(path: Path, settings: ExtractionSettings, copies: list[tuple[Path, Path]]) -> tuple[int, int]:
    """Private copies of every press file of the session file ``path`` with the extraction recomputed, and of the
    session file linking them: appended to ``copies`` as (copy, where it goes), the session file last. The presses of
    an export's self-contained copy are copied out into press files first. Returns (presses, targets
    matched in complete presses: the count ``inspect`` shows and training uses).
    """
    folder = press_dir(path)
    folder.mkdir(exist_ok=True)
    presses = matched = 0
    links: dict[str, str] = {}
    with h5py.File(path, "r") as f:
        root = {key: f.attrs[key] for key in f.attrs if key != ROOT_ATTR}
        stored = session_layout(f)[0]
        for pid, group in iter_press_groups(f):
            complete = group.attrs.get("status") in ("complete", b"complete")
            if pid in stored:
                tmp, n = _reextract_copy(path.parent / stored[pid], settings)
            else:  # an export's self-contained copy: the group is copied out into a press file of its own first
                source = folder / f".{pid}.{os.getpid()}.group.tmp"
                try:
                    with h5py.File(source, "w") as pf:
                        f.copy(group, pf, PRESS_GROUP)
                    tmp, n = _reextract_copy(source, settings)
                finally:
                    source.unlink(missing_ok=True)
            target = folder / f"{pid}-{sha256_file(tmp)[:12]}.h5"
            copies.append((tmp, target))
            links[pid] = f"{folder.name}/{target.name}"
            presses += 1
            matched += n if complete else 0
    root["extraction_settings"] = json.dumps(settings.to_dict())
    copies.append((write_session_file(path, root, links), path))
    return presses, matched


def reextract_sessions(
    paths: list[Path], settings: ExtractionSettings, accept: Callable[[list[tuple[Path, int, int]]], None] | None = None
) -> list[tuple[Path, int, int]]:
    """Recompute the force-matched extraction of every press of every session in ``paths`` with ``settings``: all
    or nothing. Returns (session file, presses, targets matched in complete presses) per session, which ``accept``
    sees before anything is renamed (an exception from it changes nothing).

    1. Every session's lease is taken (a session being collected refuses the whole run), then every session and
       journal is verified and repaired from the other copy (a press damaged in both refuses the whole run);
    2. every new press file, journal entry and session file is built as a private copy (room for all of them is
       claimed first) and fsynced;
    3. only then are the copies renamed into place, each session's file last (its rename switches every link at
       once; the new press files have new names, so the old ones stay whole until then). Any failure before step 3
       removes the copies and leaves the dataset as it was; a crash during step 3 leaves each session's file old
       or new, never a mix of presses.
    """
    hint = "rerun extract when that collection has finished"
    leases: list[SessionLease] = []
    writers: list[SessionWriter] = []
    copies: list[tuple[Path, Path]] = []  # (private copy, where it goes)
    try:
        plans: list[tuple[Path, list[Path]]] = []
        for path in paths:
            journal = session_journal(path)
            if journal.is_dir():  # a journal without its header too: the writer below rebuilds the header
                lease = SessionLease(journal, path.stem)
                lease.acquire(wait_s=0.5, hint=hint)
                leases.append(lease)
        for path in paths:
            header = session_header(path)
            if header is not None:
                object_id, sensor = str(header["object"]), str(header["sensor"])
                writer = SessionWriter(path.parent, object_id, sensor, header, unrepairable="refuse")
                writers.append(writer)
                entries = [
                    p for p in writer._journal_press_files().values() if journal_entry_check(p, {}).state != "damaged"
                ]
            else:
                check = check_session(path)
                if check.needs_repair:
                    raise DataError(f"{check.first_problem()}; there is no journal to repair it from")
                entries = []
            plans.append((path, entries))
        needed = sum(session_bytes(p) + sum(e.stat().st_size for e in entries) for p, entries in plans)
        try:
            ensure_room(private_copy_path(paths[0]), needed)
        except OSError as exc:
            raise DataError(
                f"no room for extract's copies ({needed / 1e6:.1f} MB) in {paths[0].parent}: {exc.strerror or exc}",
                hint="free disk space; nothing was changed",
            ) from exc
        results = []
        for path, entries in plans:
            session_copies: list[tuple[Path, Path]] = []
            try:
                presses, matched = _reextract_session(path, settings, session_copies)
            finally:
                copies[:0] = session_copies[:-1]  # press files before every session file
                copies.extend(session_copies[-1:])
            for entry in entries:
                copies.append((_reextract_copy(entry, settings)[0], entry))
            journal = session_journal(path)
            if (journal / "_session.json").exists():
                header = {**read_journal_header(journal), "extraction_settings": settings.to_dict()}
                copies.append((write_header(journal, header, publish=False), journal / "_session.json"))
            results.append((path, presses, matched))
        if accept is not None:
            accept(results)
        for tmp, target in copies:  # the commit
            os.replace(tmp, target)
        copies.clear()
        return results
    except (OSError, ValueError, KeyError) as exc:
        raise DataError(f"extract could not finish ({exc}); nothing was changed") from exc
    finally:
        for tmp, _ in copies:
            tmp.unlink(missing_ok=True)
        for path in paths:
            with contextlib.suppress(OSError):
                press_dir(path).rmdir()  # only when empty: an export's copy that was not rewritten
        for writer in writers:
            writer.close()
        for lease in leases:
            lease.release()
