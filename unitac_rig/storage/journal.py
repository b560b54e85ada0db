"""The journal: each press's durable log and repair copy (``DATA/.journal/<object>__<sensor>/<press_id>.h5``) and
the session's header (``_session.json``), checked like the data they protect (docs/dataset.md, "The journal is
checked like the data it protects"). The writer that repairs both sides is
:class:`unitac_rig.storage.recorder.SessionWriter`.
"""

from __future__ import annotations

import dataclasses
import json
import os
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any

import h5py

from unitac_rig.errors import DataError
from unitac_rig.storage.extraction import ExtractionSettings, extract_press
from unitac_rig.storage.integrity import (
    ROOT_ATTR,
    as_str,
    check_press_group,
    check_root,
    file_stamp,
    press_identity_problem,
)
from unitac_rig.storage.press_record import PressRecord, decode_attr, json_default, write_press_group

#: the group that holds the press in a press file and in a journal entry
PRESS_GROUP = "press"


def session_stem(object_id: str, sensor: str) -> str:
    return f"{object_id}__{sensor}"


def session_path(data_dir: Path, object_id: str, sensor: str) -> Path:
    return Path(data_dir) / f"{session_stem(object_id, sensor)}.h5"


def journal_dir(data_dir: Path, object_id: str, sensor: str) -> Path:
    return Path(data_dir) / ".journal" / session_stem(object_id, sensor)


def session_journal(path: Path) -> Path:
    """The journal folder of the session file ``path``."""
    return Path(path).parent / ".journal" / Path(path).stem


def private_copy_path(path: Path) -> Path:
    """Where a process builds the next version of ``path`` before renaming it over ``path``.

    Hidden and ending in ``.tmp``, so no session glob (``*__*.h5``) ever lists it; the pid keeps two processes apart.
    """
    return path.with_name(f".{path.name}.{os.getpid()}.tmp")


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


def write_journal_entry(journal: Path, rec: PressRecord) -> Path:
    """Make ``rec`` durable as ``journal/<press_id>.h5``: temporary name, fsync, atomic rename, fsync the folder."""
    final = journal / f"{rec.press_id}.h5"
    tmp = journal / f"{rec.press_id}.h5.tmp"
    try:
        with h5py.File(tmp, "w") as jf:
            write_press_group(jf, rec, name="press")
        with open(tmp, "rb+") as fh:
            os.fsync(fh.fileno())
        os.replace(tmp, final)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    _fsync_dir(journal)
    return final


@dataclasses.dataclass(frozen=True)
class JournalEntry:
    """What one journal entry holds: ``state`` ``ok``/``unsealed``/``damaged`` (why: ``detail``), the press status,
    the press it really holds (``holds``: another id when two entries were swapped) and its extraction settings."""

    state: str
    detail: str = ""
    status: str = ""
    holds: str | None = None
    settings: dict[str, Any] | None = None


def journal_entry_check(path: Path, identity: Mapping[str, str]) -> JournalEntry:
    """Verify the journal entry ``path`` (``<press_id>.h5``) against its checksums and, when ``identity`` (the
    session's object, sensor, session id) is given, that it holds that session's press of its name."""
    try:
        with h5py.File(path, "r") as jf:
            group = jf[PRESS_GROUP]
            result = check_press_group(group)
            if result.damaged:
                return JournalEntry("damaged", result.detail)
            holds = as_str(group.attrs.get("press_id", ""))
            settings = settings_of(group["extraction"].attrs["settings"]) if "extraction" in group else None
            status = as_str(group.attrs["status"])
            if identity:
                wrong = press_identity_problem(group, holds, dict(identity), None)
                if wrong:
                    return JournalEntry("damaged", wrong)
            if holds != path.stem:
                return JournalEntry("damaged", f"it holds press {holds}, not {path.stem}", status, holds, settings)
            return JournalEntry(result.state, "", status, holds, settings)
    except Exception as exc:  # a torn file does not open; damaged metadata raises anything
        return JournalEntry("damaged", f"unreadable ({' '.join(str(exc).split())[:160]})")


def journal_problems(
    path: Path, presses: Iterable[str], identity: Mapping[str, str], trusted: Mapping[str, str]
) -> tuple[dict[str, str], dict[str, str]]:
    """For a reader: which of the session file ``path``'s intact ``presses`` have lost their repair copy (journal
    entry missing, damaged, holding another press) and whether the journal header is missing, as (what -> why,
    entry name -> stamp of the entries verified intact). ``trusted`` (entry name -> stamp) are not read again.
    Nothing when the session has no journal folder (an export's copy, files copied without ``.journal/``)."""
    journal = session_journal(path)
    problems: dict[str, str] = {}
    good: dict[str, str] = {}
    if not journal.is_dir():
        return problems, good
    if not (journal / "_session.json").is_file():
        problems["_session.json"] = "the journal header _session.json is missing"
    else:
        try:
            read_journal_header(journal)
        except DataError as exc:
            problems["_session.json"] = f"the journal header is damaged: {exc}"
    for pid in presses:
        entry = journal / f"{pid}.h5"
        try:
            stamp = file_stamp(entry)
        except OSError:
            problems[pid] = f"press {pid} has lost its repair copy: its journal entry {entry.name} is missing"
            continue
        if trusted.get(entry.name) == stamp:
            good[entry.name] = stamp
            continue
        checked = journal_entry_check(entry, identity)
        if checked.state == "damaged":
            problems[pid] = f"press {pid} has lost its repair copy: its journal entry is damaged ({checked.detail})"
        else:
            good[entry.name] = stamp
    return problems, good


def settings_of(value: Any) -> dict[str, Any] | None:
    """Extraction settings as stored in a session's root attributes, a journal header or a press (JSON text or a
    dict), as plain JSON values (tuples as lists), so two copies of the same settings compare equal."""
    if value is None:
        return None
    if isinstance(value, bytes | str):
        try:
            value = json.loads(as_str(value))
        except ValueError:
            return None
    return json.loads(json.dumps(value, default=json_default)) if isinstance(value, dict) else None


def reextracted(rec: PressRecord, settings: Mapping[str, Any]) -> PressRecord:
    """``rec`` with its extraction recomputed under ``settings`` (the raw streams are unchanged)."""
    extraction = extract_press(
        rec.robot_t_s,
        rec.press_force_n,
        rec.tactile_t_s,
        rec.tactile_valid,
        ExtractionSettings.from_dict(dict(settings)),
    )
    return dataclasses.replace(rec, extraction=extraction)


def write_header(journal: Path, attrs: Mapping[str, Any], publish: bool = True) -> Path:
    """Write ``journal/_session.json`` under a private name and rename it into place; with ``publish`` False, return
    the private copy instead (``extract`` renames every copy at once)."""
    header = journal / "_session.json"
    tmp = private_copy_path(header)
    try:
        tmp.write_text(json.dumps(dict(attrs), default=json_default, indent=1))
        if publish:
            os.replace(tmp, header)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    return tmp


def root_as_header(path: Path) -> dict[str, Any] | None:
    """A session file's root attributes as a journal header, when the file's root is intact and sealed (None
    otherwise): how a deleted ``_session.json`` is rebuilt."""
    try:
        with h5py.File(path, "r") as f:
            if check_root(f).state != "ok":
                return None
            attrs = {k: decode_attr(v) for k, v in f.attrs.items() if k not in (ROOT_ATTR, "schema_version")}
    except Exception:
        return None
    return attrs if "object" in attrs and "sensor" in attrs else None


def read_journal_header(journal: Path) -> dict[str, Any]:
    """A journal's ``_session.json`` (the session's root attributes); DataError when it is unreadable."""
    header = journal / "_session.json"
    try:
        data = json.loads(header.read_text())
        if not isinstance(data, dict) or "object" not in data or "sensor" not in data:
            raise ValueError("not a session header")
    except (OSError, ValueError, RecursionError) as exc:
        raise DataError(
            f"{header} is unreadable ({exc})",
            hint="restore it from a backup, or move the session aside and collect into a new --data directory",
        ) from exc
    return data


def session_header(path: Path) -> dict[str, Any] | None:
    """The journal header of the session file ``path``; when the header is gone but its journal folder is there,
    the session file's verified root attributes (what the writer rewrites the header from); None: no journal."""
    journal = session_journal(path)
    if (journal / "_session.json").is_file():
        return read_journal_header(journal)
    return root_as_header(Path(path)) if journal.is_dir() else None
