"""The import run: discover files, group them into sessions, convert each file once, write presses, report.

Resumable and idempotent: each session file's root attribute ``source_files`` maps the SHA-256 of every source file
already imported to what came of it, and is updated only after all of that file's presses are written. A re-run skips
those files; a run killed mid-file resumes it (presses already written from the same file are not rewritten).
"""

from __future__ import annotations

import functools
import logging
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from drivers.layouts import SensorLayout
from unitac_rig.errors import ConfigError, DataError, UnitacError
from unitac_rig.importer.conventions import AUTHORS_PROCESSED_STEPS, ImportConventions
from unitac_rig.importer.discovery import SourceFile, discover
from unitac_rig.importer.parsing import file_sha256, read_processed_npz, read_raw_csv
from unitac_rig.importer.presses import (
    PressCandidate,
    Streams,
    build_presses,
    resolve_duplicates,
    streams_from_processed,
    streams_from_raw,
)
from unitac_rig.rig.objects import get_object
from unitac_rig.rig.sensors import sensor_layout
from unitac_rig.storage.reader import press_summaries, read_session_info
from unitac_rig.storage.recorder import SessionWriter, journal_dir, session_path

log = logging.getLogger(__name__)

SOURCE_TAG = "unitac-nv-import"


@dataclass
class FileReport:
    """What became of one source file."""

    relative: str
    kind: str
    object_id: str
    sensor: str
    outcome: str = "pending"  # imported | already-imported | skipped | failed
    message: str = ""
    sha256: str = ""
    rows: int = 0
    bad_rows: list[tuple[int, str]] = field(default_factory=list)
    presses_found: int = 0
    complete: int = 0
    written: int = 0
    already_written: int = 0
    targets_matched: int = 0
    duplicates: list[str] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)


@dataclass
class SessionReport:
    """One (object, sensor) session after the run, counted from the session file itself."""

    object_id: str
    sensor: str
    path: Path
    files: list[FileReport] = field(default_factory=list)
    presses: int = 0
    complete: int = 0
    targets_matched: int = 0
    targets_total: int = 0


@dataclass
class ImportReport:
    sessions: list[SessionReport]
    ignored: list[str]
    superseded: list[str]
    conventions: ImportConventions

    @property
    def files(self) -> list[FileReport]:
        return [f for s in self.sessions for f in s.files]


def canonical_object_id(object_id: str) -> str:
    """Our catalogue's id for ``object_id`` (an id or alias); ConfigError when the catalogue does not know it."""
    try:
        return get_object(object_id).id
    except UnitacError as exc:
        raise ConfigError(
            f"object {object_id!r} (from the import conventions) is not in the object catalogue: {exc.one_line()}",
            hint="fix [object_shapes] / arbitrary_material in the --conventions file",
        ) from exc


def _root_attrs(object_id: str, sensor: str, conv: ImportConventions, source: Path) -> dict[str, Any]:
    settings = conv.extraction.to_settings()
    return {
        "object": object_id,
        "sensor": sensor,
        "simulated": False,
        "source": SOURCE_TAG,
        "source_root": str(source),
        "conventions": conv.model_dump(mode="json"),
        "source_files": {},
        "config": {
            "importer": "unitac-nv",
            "object": {"center_m": list(conv.object_centre_m)},
            "press": {"threshold_n": conv.complete_peak_n},
            "extraction": settings.to_dict(),
            "sample_rate_hz_nominal": 100.0,
        },
    }


def _load_streams(src: SourceFile, layout: SensorLayout, conv: ImportConventions, report: FileReport) -> Streams:
    grid = (layout.rows, layout.cols)
    if src.kind == "raw":
        raw = read_raw_csv(src.path, grid, read_displacement=layout.has_displacement)
        report.rows = raw.total_rows
        report.bad_rows = raw.bad_rows
        try:
            return streams_from_raw(raw, layout, conv)
        except ValueError as exc:
            raise DataError(f"{src.relative}: {exc}", hint="is the file complete?") from exc
    arrays = read_processed_npz(src.path, grid)
    report.rows = int(arrays.time_s.size)
    report.notes.append(
        "processed file: the authors' script already dropped 10 rows, subtracted the baseline, rotated the F/T "
        "45 deg and flipped PapillArray x/y; raw counts are not recoverable (tare stored as 0)"
    )
    return streams_from_processed(arrays, layout, conv)


def _check_against_selected(streams: Streams, cands: list[PressCandidate], report: FileReport) -> None:
    """Processed files carry the authors' own press peaks: say where our segmentation disagrees."""
    if streams.authors_selected is None or streams.authors_angle is None:
        return
    ours = {c.run.peak: c for c in cands}
    theirs = dict(zip(streams.authors_selected.tolist(), streams.authors_angle.tolist(), strict=False))
    missing = sorted(set(theirs) - set(ours))
    extra = sorted(set(ours) - set(theirs))
    angle_diff = [p for p in set(ours) & set(theirs) if int(ours[p].record.angle_deg) != int(theirs[p])]
    if missing or extra or angle_diff:
        report.notes.append(
            f"differs from the authors' 'selected': {len(missing)} of their peaks not found, {len(extra)} extra, "
            f"{len(angle_diff)} with another angle"
        )


def _import_file(
    src: SourceFile,
    writer: Callable[[], SessionWriter],
    conv: ImportConventions,
    layout: SensorLayout,
    existing: dict[str, dict[str, Any]],
    imported: dict[str, Any],
    report: FileReport,
) -> None:
    """Convert one file and write its presses, then its ``source_files`` entry (a file imported before, by its
    SHA-256, is not; nor one of another kind than the session already holds)."""
    report.sha256 = file_sha256(src.path)
    if report.sha256 in imported:
        previous = imported[report.sha256]
        report.outcome = "already-imported"
        report.message = f"already imported (as {previous.get('path', '?')})"
        report.presses_found = int(previous.get("presses_found", 0))
        return
    kinds = {entry.get("kind") for entry in imported.values()}
    if kinds and src.kind not in kinds:
        report.outcome = "skipped"
        report.message = f"the session already holds {', '.join(sorted(map(str, kinds)))} imports; not mixing kinds"
        return
    streams = _load_streams(src, layout, conv, report)
    assert src.rotation_deg is not None
    source_attrs: dict[str, object] = {
        "source": SOURCE_TAG,
        "source_file": src.relative,
        "source_sha256": report.sha256,
        "source_kind": src.kind,
        "rotation_from": (
            f"arbitrary_rotation_deg[{src.arbitrary_index}] (assumed, see docs/import.md)"
            if src.arbitrary_index is not None
            else "single orientation"
        ),
    }
    cands = build_presses(streams, layout, src.rotation_deg, conv, source_attrs)
    _check_against_selected(streams, cands, report)
    report.presses_found = len(cands)
    kept, dropped = resolve_duplicates(cands)
    for cand in dropped:
        report.duplicates.append(f"{cand.describe(streams.rows)}: duplicate angle, a closer press was kept")
    for cand in kept:
        pid = cand.press_id
        previous = existing.get(pid)
        if previous is not None:
            if previous.get("source_sha256") == report.sha256:
                report.already_written += 1  # resuming a file that was cut short
                _count(cand, report)
                continue
            report.duplicates.append(
                f"{cand.describe(streams.rows)}: already in the session from {previous.get('source_file', '?')}"
            )
            continue
        writer().write_press(cand.record)
        existing[pid] = dict(cand.record.attrs)
        report.written += 1
        _count(cand, report)
    imported[report.sha256] = {
        "path": src.relative,
        "kind": src.kind,
        "rows": report.rows,
        "bad_rows": len(report.bad_rows),
        "presses_found": report.presses_found,
        "presses_written": report.written + report.already_written,
        "duplicates_dropped": len(report.duplicates),
        "rotation_deg": src.rotation_deg,
        "tare_baseline": streams.tare_baseline.tolist(),
        "sample_rate_hz": _rate_hz(streams.t_s),
        **({"authors_processing": AUTHORS_PROCESSED_STEPS} if src.kind == "processed" else {}),
    }
    writer().update_root_attrs({"source_files": imported})
    report.outcome = "imported"


def _count(cand: PressCandidate, report: FileReport) -> None:
    if cand.record.status == "complete":
        report.complete += 1
        if cand.record.extraction is not None:
            report.targets_matched += cand.record.extraction.n_matched


def _rate_hz(t_s: np.ndarray) -> float:
    steps = np.diff(t_s)
    steps = steps[steps > 0]
    return float(1.0 / np.median(steps)) if steps.size else float("nan")


def _session_counts(session: SessionReport, n_targets: int) -> None:
    summaries = press_summaries(session.path)
    session.presses = len(summaries)
    session.complete = sum(1 for s in summaries if s["status"] == "complete")
    session.targets_total = session.complete * n_targets
    session.targets_matched = sum(
        s["extraction"].n_matched for s in summaries if s["status"] == "complete" and s["extraction"] is not None
    )


def import_unitac_nv(
    source: Path,
    data_dir: Path,
    conv: ImportConventions | None = None,
    mode: str = "auto",
    on_file: Callable[[FileReport], None] | None = None,
) -> ImportReport:
    """Import every UniTac-NV file under ``source`` into session files in ``data_dir``.

    Files that cannot be used are reported (``outcome`` failed/skipped) and the run goes on; configuration problems
    (unknown names, conventions that differ from an existing session's) raise.
    """
    conv = conv or ImportConventions()
    source = Path(source)
    if not source.exists():
        raise DataError(f"{source} does not exist", hint="pass the folder you unzipped the UniTac-NV download into")
    found = discover(source, conv, mode)
    canonical = {object_id: canonical_object_id(object_id) for object_id in {f.object_id for f in found.files}}
    groups: dict[tuple[str, str], list[SourceFile]] = {}
    for src in found.files:
        groups.setdefault((canonical[src.object_id], src.sensor), []).append(src)
    n_targets = len(conv.extraction.targets_n)
    sessions = []
    for (object_id, sensor), files in sorted(groups.items()):
        session = SessionReport(object_id, sensor, session_path(Path(data_dir), object_id, sensor))
        sessions.append(session)
        _import_session(session, files, Path(data_dir), conv, source, on_file)
        if session.path.exists():
            _session_counts(session, n_targets)
    return ImportReport(
        sessions=sessions,
        ignored=found.ignored,
        superseded=[f.relative for f in found.superseded],
        conventions=conv,
    )


def _import_session(
    session: SessionReport,
    files: list[SourceFile],
    data_dir: Path,
    conv: ImportConventions,
    source: Path,
    on_file: Callable[[FileReport], None] | None,
) -> None:
    object_id, sensor = session.object_id, session.sensor
    layout = sensor_layout(sensor)
    # opened only when something is written, so a file that fails leaves no empty session behind
    writer = functools.cache(
        lambda: SessionWriter(data_dir, object_id, sensor, _root_attrs(object_id, sensor, conv, source))
    )
    imported: dict[str, Any] = {}
    existing: dict[str, dict[str, Any]] = {}
    files = sorted(files, key=lambda src: src.rotation_deg is not None)  # the ones we cannot place reported first
    placed = any(src.rotation_deg is not None for src in files)
    if placed and (session.path.exists() or (journal_dir(data_dir, object_id, sensor) / "_session.json").exists()):
        opened = writer()  # recovers a half-written session from its journal first
        info = read_session_info(opened.path)
        _check_session(info.attrs, conv, opened.path)
        imported = dict(info.attrs.get("source_files") or {})
        existing = {s["press_id"]: s for s in press_summaries(opened.path)}
    for src in files:
        report = FileReport(src.relative, src.kind, object_id, sensor)
        session.files.append(report)
        try:
            if src.rotation_deg is None:  # not even opened: no session file for files we cannot place
                report.outcome = "skipped"
                report.message = (
                    f"arbitrary file {src.arbitrary_index} has no rotation in the conventions "
                    f"(add it under [arbitrary_rotation_deg] in a --conventions file)"
                )
            else:
                _import_file(src, writer, conv, layout, existing, imported, report)
        except DataError as exc:
            report.outcome = "failed"
            report.message = exc.one_line()
            log.warning("%s", report.message)
        if on_file is not None:
            on_file(report)


def _check_session(attrs: dict[str, Any], conv: ImportConventions, path: Path) -> None:
    """An existing session must have come from this importer, with the same conventions."""
    if attrs.get("source") != SOURCE_TAG:
        raise DataError(
            f"{path} was not written by the UniTac-NV import (source={attrs.get('source')!r})",
            hint="import into a --data directory of its own",
        )
    stored = attrs.get("conventions")
    try:
        same = isinstance(stored, dict) and ImportConventions.model_validate(stored) == conv
    except ValueError:
        same = False
    if not same:
        raise DataError(
            f"{path} was imported with other conventions",
            hint="import into a new --data directory, or pass the same --conventions file as before",
        )
