"""``unitac-rig export``: the force-matched paired dataset as ``pairs.parquet``, the raw sessions (``raw/``, each one
self-contained HDF5 file), a dataset card and ``manifest.json`` (docs/dataset.md, "Export: a dataset to share").

The join is :func:`unitac_rig.storage.paired.build_paired_dataset`, the one ``train`` reads too, so an export holds
exactly the pairs ``train`` would use.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from unitac_rig.storage.cards import PARQUET_NAME, pairs_card
from unitac_rig.storage.lease import lease_holder
from unitac_rig.storage.manifest import (
    exported_by,
    frames_array,
    sensor_layout_info,
    sha256_file,
    write_manifest,
)
from unitac_rig.storage.paired import PairedDataset, build_paired_dataset
from unitac_rig.storage.pooling import PooledSession, pooled_export
from unitac_rig.storage.reader import (
    MatchedSet,
    load_matched_set,
    press_counts,
    press_summaries,
    read_session_info,
    session_digest,
    snapshot_session,
)
from unitac_rig.storage.recorder import journal_dir

log = logging.getLogger(__name__)

RAW_DIR = "raw"
CARD_NAME = "README.md"
METADATA_KEY = b"unitac_rig"

# name, unit ("" for none), description, in the Parquet's column order (paired_table gives the Arrow types)
COLUMNS: tuple[tuple[str, str, str], ...] = (
    ("contact", "", "index of the joined contact: the rows of one contact (one per sensor) share it"),
    ("object", "", "object id (see `unitac-rig objects`)"),
    ("shape", "", "object shape, from the session's object_spec (null when the session has none)"),
    ("material", "", "object material (PLA, TPU), from the session's object_spec (null when none)"),
    ("rotation_deg", "deg", "rotation of the object on its mount"),
    ("angle_deg", "deg", "approach angle of the press"),
    ("target_n", "N", "target press force the frame was matched to"),
    ("sensor", "", "sensor that recorded the frame"),
    ("force_n", "N", "wrist force along the press direction at this sensor's matched frame"),
    ("error_n", "N", "force_n - target_n (the force-matching error)"),
    ("frame", "frame_unit", "tare-subtracted tactile frame, (n_taxels, 3): taxels row-major, channels x, y, z"),
    ("frame_unit", "", "unit of frame: counts (uSkin raw counts) or N (PapillArray)"),
    ("session", "", "the raw session file (under raw/) the frame comes from"),
    ("simulated", "", "true when recorded on the simulated rig"),
)
UNITS = {name: unit for name, unit, _ in COLUMNS if unit}


@dataclass(frozen=True)
class ExportSummary:
    out: Path
    contacts: int
    rows: int
    sessions: int
    files: int
    bytes: int
    sensors: tuple[str, ...]
    objects: tuple[str, ...]
    incomplete: tuple[str, ...] = ()  # "object/sensor finished/planned" of each session with presses still to do


def _described(table: Any, sensors: Sequence[str]) -> Any:
    """``table`` with each column's unit and description in its field metadata, and the units, the frame layout, the
    sensors and the join keys in the schema's (what a reader of the Parquet alone needs)."""
    import json

    import pyarrow as pa

    fields = [table.schema.field(name).with_metadata({"unit": u, "description": text}) for name, u, text in COLUMNS]
    metadata = {
        "units": UNITS,
        "frame_layout": "frame[k][c]: taxel k (row k // cols, column k % cols of the sensor's grid), channel c "
        "(0 x, 1 y, 2 z in the sensor's frame); tare-subtracted",
        "sensors": {s: sensor_layout_info(s) for s in sensors},
        "join": ["object", "rotation_deg", "angle_deg", "target_n"],
    }
    return table.cast(pa.schema(fields, metadata={METADATA_KEY: json.dumps(metadata).encode("utf-8")}))


def paired_table(paired: PairedDataset, sessions: dict[tuple[str, str], dict[str, Any]], simulated: bool) -> Any:
    """The Arrow table: contact-major, one row per sensor of each contact, in ``paired.sensors`` order.

    ``sessions`` maps (object, sensor) to {"file", "shape", "material", "simulated"} of the session it came from.
    """
    import pyarrow as pa

    m = len(paired)
    sensors = list(paired.sensors)
    objects = np.asarray(paired.object_id).astype(str)
    parts = []
    for sensor in sensors:
        info = [sessions.get((str(o), sensor), {}) for o in objects]
        force = np.asarray(paired.force_n[sensor], dtype=np.float64)
        parts.append(
            pa.table(
                {
                    "contact": pa.array(np.arange(m, dtype=np.int64)),
                    "object": pa.array(objects.tolist(), pa.string()),
                    "shape": pa.array([i.get("shape") for i in info], pa.string()),
                    "material": pa.array([i.get("material") for i in info], pa.string()),
                    "rotation_deg": pa.array(np.asarray(paired.rotation_deg, dtype=np.float64)),
                    "angle_deg": pa.array(np.asarray(paired.angle_deg, dtype=np.float64)),
                    "target_n": pa.array(np.asarray(paired.target_n, dtype=np.float64)),
                    "sensor": pa.array([sensor] * m, pa.string()),
                    "force_n": pa.array(force),
                    "error_n": pa.array(force - np.asarray(paired.target_n, dtype=np.float64)),
                    "frame": frames_array(paired.values[sensor]),
                    "frame_unit": pa.array([str(sensor_layout_info(sensor)["units"])] * m, pa.string()),
                    "session": pa.array([i.get("file") for i in info], pa.string()),
                    "simulated": pa.array([bool(i.get("simulated", simulated)) for i in info], pa.bool_()),
                }
            )
        )
    table = pa.concat_tables(parts)
    # interleave: contact 0 of every sensor, then contact 1, ...
    order = (np.arange(len(sensors))[None, :] * m + np.arange(m)[:, None]).reshape(-1)
    return table.take(pa.array(order))


def _session_provenance(item: PooledSession, copy: Path, sha256: str) -> dict[str, Any]:
    copied = read_session_info(copy)  # verifies every press of the copy against its checksums (or refuses)
    attrs = copied.attrs
    presses = press_summaries(copy)
    writer = lease_holder(journal_dir(item.source, item.info.object_id, item.info.sensor))
    keep = (
        "rig",
        "created_unix",
        "package_version",
        "git_commit",
        "sensor_identity",
        "layout",
        "extraction_settings",
        "object_spec",
        "rotations_deg",
    )
    return {
        "file": f"{RAW_DIR}/{copy.name}",
        "object": item.info.object_id,
        "sensor": item.info.sensor,
        "simulated": item.info.simulated,
        "sha256": sha256,
        "bytes": copy.stat().st_size,
        "source": str(item.source),
        "also_in": [str(p) for p in item.also_in],
        "being_collected_at_export": writer is not None,
        # "verified": every press of the copy matched the checksums it was recorded with; else why not
        "integrity": copied.integrity,
        "presses": press_counts(attrs, presses),
        **{key: attrs[key] for key in keep if key in attrs},
    }


def _incomplete_sessions(provenance: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Sessions collected only in part (finished presses fewer than planned): the card and the summary name them."""
    return [
        {
            "file": e["file"],
            "object": e["object"],
            "sensor": e["sensor"],
            "finished": e["presses"]["complete"] + e["presses"]["failed"],
            "planned": e["presses"]["planned"],
        }
        for e in provenance
        if e["presses"]["complete"] + e["presses"]["failed"] < e["presses"]["planned"]
    ]


def export_dataset(data_dirs: Sequence[Path], out: Path) -> ExportSummary:
    """Pool ``data_dirs``, copy the raw sessions, write the Parquet, the card and the manifest into ``out``.

    Built in a hidden sibling directory and renamed into place at the end, so ``out`` is either complete or absent.
    The Parquet is computed from the *copies*, so it, the raw files and the checksums agree even when a source is
    still being collected.
    """
    import pyarrow.parquet as pq

    with pooled_export(data_dirs, out) as (pooled, staging):
        (staging / RAW_DIR).mkdir()
        provenance: list[dict[str, Any]] = []
        sets: list[MatchedSet] = []
        for item in pooled:
            copy = staging / RAW_DIR / item.info.path.name
            snapshot_session(item.info.path, copy)  # one self-contained file, whatever the session's layout
            digest = sha256_file(copy)
            if session_digest(copy) != item.sha256:
                log.warning(
                    "%s changed while it was exported (a collection is running); exported the newer version",
                    item.info.path,
                )
            provenance.append(_session_provenance(item, copy, digest))
            sets.append(load_matched_set(copy))
        paired = build_paired_dataset(sets)
        sensors, objects = paired.sensors, paired.objects
        by_key = {
            (i.info.object_id, i.info.sensor): {**i.described(), "file": f"{RAW_DIR}/{i.info.path.name}"}
            for i in pooled
        }
        simulated = all(bool(e["simulated"]) for e in provenance if e["sensor"] in sensors)
        counts = {
            "contacts": len(paired),
            "rows": len(paired) * len(sensors),
            "sensors": {s: len(paired) for s in sensors},
            "contacts_per_object": {o: int(np.sum(paired.object_id == o)) for o in objects},
            "matched_frames_without_partner": {s: int(n) for s, n in paired.dropped_per_sensor.items()},
            "sessions": len(provenance),
        }
        incomplete = _incomplete_sessions(provenance)
        table = _described(paired_table(paired, by_key, simulated), sensors)
        pq.write_table(table, staging / PARQUET_NAME, compression="zstd")
        document = {
            "format": "unitac-rig paired tactile dataset",
            "created_unix": time.time(),
            "exported_by": exported_by(),
            "paired_content_hash": paired.content_hash(),
            "parquet": PARQUET_NAME,
            "schema": [
                {
                    "name": f.name,
                    "type": str(f.type),
                    "unit": f.metadata[b"unit"].decode(),
                    "description": f.metadata[b"description"].decode(),
                }
                for f in table.schema
            ],
            "units": UNITS,
            "sensors": {s: sensor_layout_info(s) for s in sensors},
            "simulated": simulated,
            "counts": counts,
            "incomplete_sessions": incomplete,  # collected only in part: resume them with the same collect command
            "sessions": provenance,
        }
        (staging / CARD_NAME).write_text(pairs_card(document), encoding="utf-8")
        files = [PARQUET_NAME, CARD_NAME, *(entry["file"] for entry in provenance)]
        write_manifest(staging, document, files)
    total = sum((out / rel).stat().st_size for rel in files)
    partial = tuple(f"{e['object']}/{e['sensor']} {e['finished']}/{e['planned']}" for e in incomplete)
    return ExportSummary(
        out, len(paired), len(paired) * len(sensors), len(provenance), len(files) + 1, total, sensors, objects, partial
    )
