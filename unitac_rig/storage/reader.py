"""Reading sessions: listing them, reading presses, and the force-matched frames learning trains on.

Every reader goes through here (docs/dataset.md, "Session file"): a session file whose presses are links to press
files, or an export's self-contained copy of one (every press a group inside it, :func:`snapshot_session`); h5py
reads both the same way. :func:`session_files` names the files a session is stored in and :func:`session_digest`
identifies its content in either (pooling).
"""

from __future__ import annotations

import hashlib
import json
import logging
import os
import threading
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import h5py
import numpy as np

from unitac_rig.errors import DataError
from unitac_rig.rig.sensors import SENSORS
from unitac_rig.storage.integrity import (
    PRESS_ATTR,
    SCHEMA_VERSION,
    SessionCheck,
    as_str,
    attrs_digest,
    check_session,
    root_attr_items,
)
from unitac_rig.storage.journal import journal_problems, session_journal
from unitac_rig.storage.lease import lease_holder
from unitac_rig.storage.press_record import (
    PressRecord,
    decode_attr,
    iter_press_groups,
    read_extraction,
    read_press_group,
)
from unitac_rig.storage.recorder import private_copy_path, repair_session, session_layout

log = logging.getLogger(__name__)


# Verify once, trust what is unchanged (docs/dataset.md): what a reader verified is remembered in the journal folder
# (``_verified.json``): each press by its seal (:func:`press_seal`: its checksums and its press file's stamp) and each
# journal entry by its stamp, so a later reader reads in full only what changed. Only a cache: unreadable or missing,
# everything is verified again; a folder without a journal (an export's copy) is verified in full every time.
TRUST_NAME = "_verified.json"
TRUST_VERSION = 1


def load_trust(session: Path) -> tuple[set[tuple[str, str]], dict[str, str]]:
    """(press id, press seal) pairs and journal entry name -> stamp that an earlier reader verified (empty when
    nothing is remembered or the record is unreadable)."""
    try:
        document = json.loads((session_journal(session) / TRUST_NAME).read_text())
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
    path = session_journal(session) / TRUST_NAME
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


@dataclass(frozen=True)
class SessionInfo:
    path: Path
    object_id: str
    sensor: str
    simulated: bool
    attrs: dict[str, Any]
    integrity: str = "verified"  # or why not (see Verified.integrity); "repaired: ..." when a read repaired it
    repairs: tuple[str, ...] = field(default_factory=tuple)


@dataclass(frozen=True)
class MatchedSet:
    """Every force-matched frame of one (object, sensor) session that hit its target (misses and failed presses out).

    ``values`` are tare-subtracted, in the sensor's units (uSkin counts, PapillArray N), shape (M, n_taxels, 3): each
    press's own tare (``baseline`` "press"), or the tare at the start of its recording ("recording", see
    :func:`recording_shifts`).
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
    baseline: str = "press"  # what ``values`` are referenced to (:data:`FRAME_BASELINES`)

    def __len__(self) -> int:
        return int(self.target_n.size)


@dataclass(frozen=True)
class Verified:
    """A session file version that passed :func:`verified_session` (and what it took)."""

    check: SessionCheck
    repairs: tuple[str, ...] = ()

    @property
    def integrity(self) -> str:
        described = "damaged" if self.check.needs_repair else "verified"
        return f"repaired from the journal, {described}" if self.repairs else described


_VERIFIED: dict[tuple[Any, ...], Verified] = {}
_VERIFIED_GUARD = threading.Lock()
_PRESSES_OK: dict[str, set[tuple[str, str]]] = {}  # file -> (press id, checksums) verified by this process


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
    process verified and has not changed since is trusted, see ``TRUST_NAME``), and that each press still has its
    repair copy in the journal; repair from the journal what is damaged or missing, and raise a DataError naming the
    file and press when it cannot be repaired. A file of another schema version is left to the caller's version
    check. A journal that cannot be mended never blocks intact data: it is only warned about.
    """
    path = Path(path)
    key = _version_key(path)
    with _VERIFIED_GUARD:
        cached = _VERIFIED.get(key) if key else None
    if cached is not None:
        return cached
    stored, stored_journal = load_trust(path)

    def journal_issues(check: SessionCheck) -> tuple[dict[str, str], dict[str, str]]:
        """Which intact presses lost their repair copy (:func:`journal_problems`), and the entries verified intact."""
        return journal_problems(path, sorted(check.statuses), check.identity, stored_journal)

    with _VERIFIED_GUARD:
        known = set(_PRESSES_OK.get(str(path.resolve()), ())) | stored
    check = check_session(path, known)
    damaged = check.needs_repair
    repairs: tuple[str, ...] = ()
    issues, good = ({}, {}) if damaged else journal_issues(check)
    if issues and lease_holder(session_journal(path)) is not None:
        for issue in issues.values():  # the collection writing it now recreates it when it next opens the session
            log.warning("%s: %s (the session is being written now; rerun later to restore it)", path, issue)
    elif damaged or issues:
        problem = check.first_problem() if damaged else f"{path}: {next(iter(issues.values()))}"
        try:
            repairs = tuple(repair_session(path, problem))
        except DataError as exc:
            if damaged:
                raise
            log.warning("%s: %s; the journal could not be mended: %s", path, "; ".join(issues.values()), exc)
        for note in repairs:
            log.warning("%s: %s", path, note)
        check = check_session(path, known)
        if damaged and check.needs_repair:
            raise DataError(check.first_problem(), hint="restore the file from a backup")
        issues, good = journal_issues(check)
        for issue in issues.values() if repairs or damaged else ():
            log.warning("%s: %s", path, issue)
    result = Verified(check, repairs)
    save_trust(path, check.seals, good)
    key = _version_key(path)
    with _VERIFIED_GUARD:
        _PRESSES_OK.setdefault(str(path.resolve()), set()).update(check.seals)
        if key is not None:
            _VERIFIED[key] = result
    return result


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
    if version is None or int(version) != SCHEMA_VERSION:
        f.close()
        raise DataError(
            f"{path} has session schema version {'none' if version is None else int(version)}, this unitac-rig "
            f"reads version {SCHEMA_VERSION}",
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


def read_presses(path: Path) -> list[PressRecord]:
    with _open(path) as f:
        return [read_press_group(g) for _, g in iter_press_groups(f)]


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


def press_counts(attrs: dict[str, Any], presses: list[dict[str, Any]]) -> dict[str, int]:
    """A session's presses planned (its ``planned_presses``; without them, those it holds), complete, failed and
    aborted, from its root attributes and :func:`press_summaries`."""
    counts = {"planned": len(attrs.get("planned_presses") or []) or len(presses)}
    return counts | {
        status: sum(p["status"] == status for p in presses) for status in ("complete", "failed", "aborted")
    }


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


#: one press's force-matched targets, misses dropped: (rotation_deg, angle_deg, target_n, frames, force_n, error_n)
PressMatches = tuple[float, float, np.ndarray, np.ndarray, np.ndarray, np.ndarray]


#: What a matched frame is referenced to. "press": the tare each press takes in free air just before it (what the
#: recorder stores; the sensor's drift since the session began is gone). "recording": the tare at the start of the
#: press's recording, as the paper's preprocessing subtracts one baseline (the first 100 samples) per recorded file;
#: the paper recorded each object rotation as its own file, so a recording is one rotation of one session, and the
#: drift since its start stays in every frame (docs/learning.md, "Frame baseline").
FRAME_BASELINES = ("press", "recording")


@dataclass(frozen=True)
class PressTare:
    """When a press began (host s), its rotation and its tare: what :func:`recording_shifts` needs of every press."""

    start_s: float
    rotation_deg: float
    tare: np.ndarray  # (n_taxels, 3), sensor units


def recording_shifts(tares: list[PressTare]) -> list[np.ndarray]:
    """Per press, what moves its frames from its own tare to its recording's: its tare minus the tare of the first
    press (by start time) of the same rotation. Every press counts, failed ones too: the recording began with it."""
    first: dict[float, PressTare] = {}
    for tare in tares:
        known = first.get(tare.rotation_deg)
        if known is None or tare.start_s < known.start_s:
            first[tare.rotation_deg] = tare
    return [np.asarray(t.tare, np.float64) - np.asarray(first[t.rotation_deg].tare, np.float64) for t in tares]


def check_frame_baseline(baseline: str) -> None:
    """DataError unless ``baseline`` is one of :data:`FRAME_BASELINES` (readers call it before reading anything)."""
    if baseline not in FRAME_BASELINES:
        raise DataError(f"unknown frame baseline {baseline!r}", hint=f"one of {', '.join(FRAME_BASELINES)}")


def frame_shifts(baseline: str, tares: list[PressTare], matched: list[int]) -> list[np.ndarray] | None:
    """What :func:`matched_set` adds to each matched press's frames for ``baseline``: None for "press" (the frames
    as stored), :func:`recording_shifts` of every press, picked for the ``matched`` ones (indices into ``tares``), for
    "recording". DataError for any other name. The one rule the session reader and the LeRobot read-back share."""
    check_frame_baseline(baseline)
    if baseline == "press":
        return None
    every = recording_shifts(tares)
    return [every[i] for i in matched]


def matched_set(
    object_id: str,
    sensor: str,
    simulated: bool,
    presses: list[PressMatches],
    n_taxels: int,
    rig: str = "",
    shifts: list[np.ndarray] | None = None,
) -> MatchedSet:
    """A MatchedSet of ``presses`` in order (the one way a session and a LeRobot export both build one); ``shifts``
    (one per press, from :func:`recording_shifts`) re-reference each press's frames to its recording's tare."""

    def cat(i: int, shape: tuple[int, ...] = ()) -> np.ndarray:
        parts = [np.full(len(p[2]), p[i]) if i < 2 else np.asarray(p[i]) for p in presses]
        return np.concatenate(parts) if parts else np.zeros((0, *shape))

    if shifts is not None:
        presses = [
            (p[0], p[1], p[2], np.asarray(p[3], np.float64) + shift, p[4], p[5])
            for p, shift in zip(presses, shifts, strict=True)
        ]
    values = cat(3, (n_taxels, 3)).astype(np.float32)
    baseline = "press" if shifts is None else "recording"
    return MatchedSet(object_id, sensor, simulated, cat(0), cat(1), cat(2), values, cat(4), cat(5), rig, baseline)


def load_matched_set(path: Path, baseline: str = "press") -> MatchedSet:
    """The session's force-matched frames, referenced to ``baseline`` (one of :data:`FRAME_BASELINES`)."""
    check_frame_baseline(baseline)
    info = read_session_info(path)
    presses: list[PressMatches] = []
    tares: list[PressTare] = []  # every press's, in file order ("recording" only: "press" needs none)
    used: list[int] = []  # which of them the matched presses are
    with _open(path) as f:
        for index, (_, g) in enumerate(iter_press_groups(f)):
            rotation, angle = float(g.attrs["rotation_deg"]), float(g.attrs["angle_deg"])
            if baseline == "recording":
                times = g["tactile/t_s"]
                start_s = float(times[0]) if times.shape[0] else float("inf")  # no frames: it cannot have begun one
                tares.append(PressTare(start_s, rotation, g["tare_baseline"][()]))
            if as_str(g.attrs["status"]) != "complete" or (ex := read_extraction(g)) is None:
                continue
            used.append(index)
            extraction, frames = ex
            keep = ~extraction.miss
            presses.append(
                (
                    rotation,
                    angle,
                    extraction.targets_n[keep],
                    frames[keep],
                    extraction.force_at_frame_n[keep],
                    extraction.error_n[keep],
                )
            )
    spec = SENSORS.get(info.sensor)
    n_taxels = spec.layout.n_taxels if spec else (presses[0][3].shape[1] if presses else 0)
    shifts = frame_shifts(baseline, tares, used)
    return matched_set(info.object_id, info.sensor, info.simulated, presses, n_taxels, rig_label(info.attrs), shifts)


def load_matched_sets(data_dir: Path, baseline: str = "press") -> list[MatchedSet]:
    """One MatchedSet per session in ``data_dir``; raises DataError when there is none."""
    sessions = list_sessions(data_dir)
    if not sessions:
        raise DataError(f"no session files (*__*.h5) in {data_dir}", hint="run `unitac-rig collect` first")
    return [load_matched_set(s.path, baseline) for s in sessions]


def session_files(path: Path) -> list[Path]:
    """The files a session is stored in: the session file and every press file it links (none in an export's
    self-contained copy). Copy all of them (or use :func:`snapshot_session`) to move a session elsewhere."""
    path = Path(path)
    with _open(path) as f:
        links = session_layout(f)[0]
    return [path, *(path.parent / target for _, target in sorted(links.items()))]


def session_digest(path: Path) -> str:
    """Hex SHA-256 of a session's content: its root attributes and every press's checksums. The same for a session
    and its export's snapshot, different as soon as one press or attribute differs; what pooling calls one session."""
    digest = hashlib.sha256()
    with _open(path) as f:
        digest.update(attrs_digest((k, v) for k, v in root_attr_items(f)).encode())
        for pid, group in iter_press_groups(f):
            digest.update(f"\n{pid}\n{as_str(group.attrs[PRESS_ATTR])}".encode())
    return digest.hexdigest()


def snapshot_session(path: Path, dest: Path) -> None:
    """Write the session ``path`` to ``dest`` as one self-contained HDF5 file (every press a group inside it,
    checksums as recorded): what an export ships. Read from one version of the session file, so a collection writing
    it meanwhile changes nothing in the copy; a snapshot of a snapshot is the same content."""
    path, dest = Path(path), Path(dest)
    tmp = private_copy_path(dest)
    try:
        with _open(path) as f, h5py.File(tmp, "w") as out:
            for key, value in f.attrs.items():
                out.attrs[key] = value
            presses = out.create_group("presses")
            for pid, group in iter_press_groups(f):
                f.copy(group, presses, pid)
        os.replace(tmp, dest)
    except OSError as exc:
        raise DataError(f"could not copy {path} to {dest}: {exc}") from exc
    finally:
        tmp.unlink(missing_ok=True)
