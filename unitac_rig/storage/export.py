"""``unitac-rig export``: the force-matched paired dataset as Parquet, with a manifest and a dataset card.

An export directory holds:

* ``pairs.parquet``: one row per joined contact and sensor (object, rotation, angle, target, the wrist force at that
  sensor's matched frame, its error, and the frame), units in the schema's field metadata. pandas and
  ``datasets.load_dataset("parquet", ...)`` read it as it is (plain Arrow types, nested lists for the frames).
* ``raw/<object>__<sensor>.h5``: the sessions it was built from, each one self-contained HDF5 file (every press a group
  in it, checksums as recorded; docs/dataset.md).
* ``README.md``: the dataset card (what, how to load, columns and units, sessions, limits).
* ``manifest.json``: schema, units, counts, every session's provenance and the SHA-256 of every file
  (:mod:`unitac_rig.storage.manifest`; ``unitac-rig verify DIR`` checks it).

The join (which contacts every sensor recorded) is :func:`unitac_rig.storage.paired.build_paired_dataset`, the one
``train`` reads too, so an export holds exactly the pairs ``train`` would use.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from unitac_rig.storage.lease import lease_holder
from unitac_rig.storage.manifest import (
    MANIFEST_NAME,
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
    press_summaries,
    read_session_info,
    session_digest,
    snapshot_session,
)
from unitac_rig.storage.recorder import journal_dir

log = logging.getLogger(__name__)

PARQUET_NAME = "pairs.parquet"
RAW_DIR = "raw"
CARD_NAME = "README.md"
METADATA_KEY = b"unitac_rig"

# name, unit ("" for none), description; the Arrow types are in _arrow_schema
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


def _arrow_schema(sensors: Sequence[str], extra: dict[str, Any]) -> Any:
    import json

    import pyarrow as pa

    types = {
        "contact": pa.int64(),
        "object": pa.string(),
        "shape": pa.string(),
        "material": pa.string(),
        "rotation_deg": pa.float64(),
        "angle_deg": pa.float64(),
        "target_n": pa.float64(),
        "sensor": pa.string(),
        "force_n": pa.float64(),
        "error_n": pa.float64(),
        "frame": pa.list_(pa.list_(pa.float32())),
        "frame_unit": pa.string(),
        "session": pa.string(),
        "simulated": pa.bool_(),
    }
    fields = [pa.field(name, types[name], metadata={"unit": unit, "description": text}) for name, unit, text in COLUMNS]
    metadata = {
        "units": {name: unit for name, unit, _ in COLUMNS if unit},
        "frame_layout": "frame[k][c]: taxel k (row k // cols, column k % cols of the sensor's grid), channel c "
        "(0 x, 1 y, 2 z in the sensor's frame); tare-subtracted",
        "sensors": {s: sensor_layout_info(s) for s in sensors},
        **extra,
    }
    return pa.schema(fields, metadata={METADATA_KEY: json.dumps(metadata).encode("utf-8")})


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
    planned = attrs.get("planned_presses") or []
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
        "presses": {
            "planned": len(planned) if planned else len(presses),
            "complete": sum(p["status"] == "complete" for p in presses),
            "failed": sum(p["status"] == "failed" for p in presses),
            "aborted": sum(p["status"] == "aborted" for p in presses),
        },
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
        sensors = tuple(paired.sensors)
        by_key = {
            (i.info.object_id, i.info.sensor): {**i.described(), "file": f"{RAW_DIR}/{i.info.path.name}"}
            for i in pooled
        }
        simulated = all(bool(e["simulated"]) for e in provenance if e["sensor"] in sensors)
        objects = tuple(sorted(set(np.asarray(paired.object_id).astype(str).tolist())))
        counts = {
            "contacts": len(paired),
            "rows": len(paired) * len(sensors),
            "sensors": {s: len(paired) for s in sensors},
            "contacts_per_object": {o: int(np.sum(np.asarray(paired.object_id).astype(str) == o)) for o in objects},
            "matched_frames_without_partner": {s: int(n) for s, n in paired.dropped_per_sensor.items()},
            "sessions": len(provenance),
        }
        incomplete = _incomplete_sessions(provenance)
        schema = _arrow_schema(sensors, {"join": ["object", "rotation_deg", "angle_deg", "target_n"]})
        table = paired_table(paired, by_key, simulated).cast(schema)
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
                for f in schema
            ],
            "units": {name: unit for name, unit, _ in COLUMNS if unit},
            "sensors": {s: sensor_layout_info(s) for s in sensors},
            "simulated": simulated,
            "counts": counts,
            "incomplete_sessions": incomplete,  # collected only in part: resume them with the same collect command
            "sessions": provenance,
        }
        (staging / CARD_NAME).write_text(render_card(document), encoding="utf-8")
        files = [PARQUET_NAME, CARD_NAME, *(entry["file"] for entry in provenance)]
        write_manifest(staging, document, files)
    total = sum((out / rel).stat().st_size for rel in files)
    partial = tuple(f"{e['object']}/{e['sensor']} {e['finished']}/{e['planned']}" for e in incomplete)
    return ExportSummary(
        out, len(paired), len(paired) * len(sensors), len(provenance), len(files) + 1, total, sensors, objects, partial
    )


def render_card(doc: dict[str, Any]) -> str:
    """The dataset card (README.md): YAML front matter a dataset hub reads, then what a colleague needs to know."""
    exported = doc["exported_by"]
    lines = [
        *_card_intro(doc),
        *_card_tables(doc),
        *_card_limits(doc),
        "",
        f"Exported by unitac-rig {exported['package_version']} (commit `{str(exported['git_commit'])[:12]}`) on "
        f"{time.strftime('%Y-%m-%d %H:%M', time.localtime(doc['created_unix']))}; `{MANIFEST_NAME}` lists every file "
        "with its SHA-256.",
        "",
    ]
    return "\n".join(lines)


def _card_intro(doc: dict[str, Any]) -> list[str]:
    """The card's front matter, what the dataset is, and how to load it."""
    counts = doc["counts"]
    sensors = list(doc["sensors"])
    kind = "the simulated rig (the project's twin)" if doc["simulated"] else "a UR5e press rig"
    return [
        "---",
        "pretty_name: unitac-rig paired tactile dataset",
        "tags: [tactile, robotics, cross-sensor, unitac-rig]",
        "configs:",
        "- config_name: default",
        "  data_files:",
        "  - split: train",
        f"    path: {PARQUET_NAME}",
        "---",
        "",
        "# Paired tactile dataset (unitac-rig export)",
        "",
        f"{counts['contacts']} contacts, each recorded by every one of {len(sensors)} sensors ({', '.join(sensors)}): "
        f"{counts['rows']} rows in `{PARQUET_NAME}`, from {counts['sessions']} sessions recorded on {kind}. "
        "Every contact is one press of an object at one rotation and approach angle, at one target force; each "
        "sensor's row holds its tactile frame at the moment the wrist force crossed that target.",
        "",
        "## Load it",
        "",
        "```python",
        "import pandas as pd",
        f'df = pd.read_parquet("{PARQUET_NAME}")',
        "import numpy as np",
        'frame = np.stack(df.loc[0, "frame"])            # (n_taxels, 3), in the unit of df.loc[0, "frame_unit"]',
        "",
        "import datasets",
        f'ds = datasets.load_dataset("parquet", data_files="{PARQUET_NAME}")["train"]',
        "```",
        "",
        "Check the copy first: `unitac-rig verify .` (every file's SHA-256 against `manifest.json`).",
        "",
    ]


def _card_tables(doc: dict[str, Any]) -> list[str]:
    """The card's tables: columns, sensors, contacts per object, sessions."""
    return [
        "## Columns",
        "",
        "| column | unit | meaning |",
        "|---|---|---|",
        *(f"| `{c['name']}` | {c['unit'] or ''} | {c['description']} |" for c in doc["schema"]),
        "",
        "Rows of one `contact` share object, rotation, angle and target: pivot on `contact` to get the pairs. "
        "Units are also in the Parquet schema (each field's `unit` metadata).",
        "",
        "## Sensors",
        "",
        "| sensor | model | taxel grid | frame unit |",
        "|---|---|---|---|",
        *(
            f"| {s} | {info.get('model', '?')} | {info.get('rows', '?')} x {info.get('cols', '?')} "
            f"| {info.get('units', '?')} |"
            for s, info in doc["sensors"].items()
        ),
        "",
        "## Contacts per object",
        "",
        "| object | contacts |",
        "|---|---:|",
        *(f"| {o} | {n} |" for o, n in doc["counts"]["contacts_per_object"].items()),
        "",
        "## Sessions (raw recordings, HDF5, under `raw/`)",
        "",
        "| file | presses complete/planned | simulated | SHA-256 |",
        "|---|---|---|---|",
        *(
            f"| `{s['file']}` | {s['presses']['complete']}/{s['presses']['planned']} | "
            f"{'yes' if s['simulated'] else 'no'} | `{s['sha256'][:16]}…` |"
            for s in doc["sessions"]
        ),
        "",
        "The session format (raw arm and tactile streams, tare, events, the extraction) is documented in "
        "unitac-rig's docs/dataset.md; full provenance of each session (rig, software version, commit, sensor "
        "identity, extraction settings) is in `manifest.json`.",
        "",
    ]


def _card_limits(doc: dict[str, Any]) -> list[str]:
    """How the pairs were made and what they cannot be used for."""
    lines = [
        "## How it was made, and limits",
        "",
        "- Frames are force-matched: the tactile frame nearest the moment the smoothed wrist force first crossed "
        "each target on the loading ramp, kept only when within the extraction tolerance (`error_n`).",
        "- A contact is kept only when every sensor has it (join on object, rotation, angle, target); matched frames "
        "without a partner are left out ("
        + ", ".join(f"{s}: {n}" for s, n in doc["counts"]["matched_frames_without_partner"].items())
        + ").",
        "- Frames are tare-subtracted, in each sensor's own unit (uSkin raw counts are not newtons).",
        "- No train/test split is given. Do not split rows at random: the forces of one press are near-identical "
        "frames. Split by approach direction (object, rotation, angle), as unitac-rig's `train` does.",
    ]
    if doc["simulated"]:
        lines.append(
            "- **Simulated.** Recorded on the project's simulated rig: contact mechanics and sensor responses are "
            "models, not measurements; do not report results on it as real-sensor results."
        )
    return lines
