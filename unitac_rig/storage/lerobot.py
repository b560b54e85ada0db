"""``unitac-rig export --format lerobot``: the recorded presses as LeRobotDataset v3.0 datasets, and the way back.

One press is one episode and one tactile frame one row; each sensor is its own dataset in ``OUT/<sensor>/`` at that
sensor's rate, with the arm's nearest sample at each frame (docs/dataset.md, "Export for LeRobot"). The layout's
facts are taken from the standalone ``lerobot-dataset`` package (0.4.4), whose ``LeRobotDataset`` loads what is
written here (``tests/storage/test_lerobot_export.py``); nothing of it is imported: the files are written with
pyarrow. :func:`load_matched_sets` reads an export back into the force-matched sets ``train`` joins.
"""

from __future__ import annotations

import json
import time
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from unitac_rig.errors import DataError
from unitac_rig.storage.cards import lerobot_card, lerobot_sensor_card
from unitac_rig.storage.extraction import nearest_index
from unitac_rig.storage.manifest import exported_by, frames_array, sensor_layout_info, write_manifest
from unitac_rig.storage.pooling import PooledSession, pooled_export
from unitac_rig.storage.press_record import PressRecord
from unitac_rig.storage.reader import (
    MatchedSet,
    PressMatches,
    PressTare,
    check_frame_baseline,
    frame_shifts,
    matched_set,
    read_presses,
)

CODEBASE_VERSION = "v3.0"  # LeRobotDataset format version (lerobot-dataset 0.4.x reads v3.0)
CHUNKS_SIZE = 1000  # files per chunk directory (LeRobot's default)
DATA_FILE_SIZE_MB = 100  # a data file is closed once it holds about this much (LeRobot's default)
DATA_PATH = "data/chunk-{chunk_index:03d}/file-{file_index:03d}.parquet"
EPISODES_PATH = "meta/episodes/chunk-{chunk_index:03d}/file-{file_index:03d}.parquet"
QUANTILES = (0.01, 0.10, 0.50, 0.90, 0.99)  # the quantiles LeRobot's stats carry (q01 ... q99)
EXPORT_FORMAT = "unitac-rig press dataset (LeRobotDataset v3.0, one dataset per sensor)"
CARD_NAME = "README.md"
ARRAY2D = "datasets.features.features.Array2DExtensionType"  # how `datasets` tags a fixed 2-D feature in Parquet


@dataclass(frozen=True)
class LeRobotExportSummary:
    out: Path
    sensors: dict[str, dict[str, int]]  # sensor -> episodes, frames, fps
    sessions: int
    files: int
    bytes: int


@dataclass(frozen=True)
class _Feature:
    name: str
    dtype: str  # LeRobot dtype: float32, int64, bool, string
    description: str
    unit: str = ""
    shape: tuple[int, ...] = (1,)
    names: list[str] | None = None

    def info(self) -> dict[str, Any]:
        """Its ``meta/info.json`` entry: dtype, shape, names, unit, description."""
        return {
            "dtype": self.dtype,
            "shape": list(self.shape),
            "names": self.names,
            "unit": self.unit,
            "description": self.description,
        }


def _tactile_key(sensor: str) -> str:
    return f"observation.tactile.{sensor}"


def _features(sensor: str, layout: dict[str, Any], targets: Sequence[float], displacement: bool) -> list[_Feature]:
    """Every column of one sensor's dataset: the tactile frame, its validity, counter and device clock (and the
    PapillArray's displacements), then the arm's nearest sample, the press's annotations and LeRobot's indices."""
    key, rows, cols = _tactile_key(sensor), layout["rows"], layout["cols"]
    frame = ((int(layout["n_taxels"]), 3), ["taxel", "channel"])
    grid = f"taxel k at row k // {cols}, column k % {cols} of the {rows} x {cols} grid"
    nearest = "(nearest arm sample)"
    return [
        _Feature(
            key,
            "float32",
            f"tare-subtracted tactile frame: {grid}; channels x, y, z in the sensor's frame",
            str(layout["units"]),
            *frame,
        ),
        _Feature(f"{key}.valid", "bool", "false where a taxel was missing or stale"),
        _Feature(f"{key}.seq", "int64", "the device's frame counter (-1: the protocol has none)"),
        _Feature(f"{key}.device_t_us", "int64", "the device's own clock (-1: none)", "us"),
        *(
            [_Feature(f"{key}.displacement_mm", "float32", "pillar displacement x, y, z (PapillArray)", "mm", *frame)]
            if displacement
            else []
        ),
        _Feature(
            "observation.wrench",
            "float32",
            f"wrist wrench on the tool, base axes, after the press's F/T zero {nearest}",
            "N, N m",
            (6,),
            ["fx", "fy", "fz", "tx", "ty", "tz"],
        ),
        _Feature(
            "observation.tcp_pose",
            "float32",
            f"TCP pose in the base frame, rotation vector {nearest}",
            "m, rad",
            (6,),
            ["x", "y", "z", "rx", "ry", "rz"],
        ),
        _Feature(
            "observation.press_force_n",
            "float32",
            f"wrist force along the press direction, positive while pressing {nearest}",
            "N",
        ),
        _Feature(
            "observation.arm_dt_s",
            "float32",
            "host time of the arm sample used minus the tactile frame's host time",
            "s",
        ),
        _Feature("annotation.object", "string", "object id (see `unitac-rig objects`)"),
        _Feature("annotation.rotation_deg", "float32", "rotation of the object on its mount", "deg"),
        _Feature("annotation.angle_deg", "float32", "approach angle of the press", "deg"),
        _Feature(
            "annotation.matched_targets",
            "bool",
            "true for each target force this frame was force-matched to (the press's extraction; misses "
            "false): the frames the paired dataset is built from",
            "",
            (len(targets),),
            [f"{t:.2f} N" for t in targets],
        ),
        _Feature(
            "timestamp",
            "float32",
            "host time of the tactile frame minus that of the episode's first frame (measured, not index/fps)",
            "s",
        ),
        _Feature("frame_index", "int64", "frame number within the episode"),
        _Feature("episode_index", "int64", "episode (press) number"),
        _Feature("index", "int64", "frame number within the dataset"),
        _Feature("task_index", "int64", "row of meta/tasks.parquet"),
    ]


# ---------------------------------------------------------------------------------------------------------------
# statistics, as LeRobot computes them: over frames; a (n, 3) feature per channel (over frames and taxels)


def feature_stats(values: np.ndarray) -> dict[str, np.ndarray]:
    """min, max, mean, std, count and the q01..q99 quantiles of ``values`` (frames first), LeRobot's shapes:
    (1,) for a scalar feature, (k,) for a vector, (channels,) for a (n, channels) array."""
    array = np.asarray(values)
    count = int(array.shape[0])
    if array.ndim == 1:
        flat = array.reshape(-1, 1)
    elif array.ndim == 2:
        flat = array
    else:
        flat = array.reshape(-1, array.shape[-1])
    numbers = flat.astype(np.float64)
    stats: dict[str, np.ndarray] = {
        "min": flat.min(axis=0),
        "max": flat.max(axis=0),
        "mean": numbers.mean(axis=0),
        "std": numbers.std(axis=0),
        "count": np.array([count], dtype=np.int64),
    }
    for q, value in zip(QUANTILES, np.quantile(numbers, QUANTILES, axis=0), strict=True):
        stats[f"q{round(q * 100):02d}"] = value
    return stats


# ---------------------------------------------------------------------------------------------------------------
# Arrow helpers (pyarrow is imported lazily, as in storage/export.py)


def _column(feature: _Feature, values: Any) -> tuple[Any, Any]:
    """(pyarrow array, pyarrow field) in the layout `datasets` reads as the feature's type."""
    import pyarrow as pa

    if feature.dtype == "string":
        return pa.array(list(values), pa.string()), pa.field(feature.name, pa.string())
    value_type = {"float32": pa.float32(), "int64": pa.int64(), "bool": pa.bool_()}[feature.dtype]
    array = np.ascontiguousarray(values, dtype=bool if feature.dtype == "bool" else np.dtype(feature.dtype))
    if feature.shape == (1,):
        return pa.array(array.reshape(-1), value_type), pa.field(feature.name, value_type)
    if len(feature.shape) == 1:
        list_type = pa.list_(value_type, feature.shape[0])
        flat = pa.array(array.reshape(-1), value_type)
        return pa.FixedSizeListArray.from_arrays(flat, feature.shape[0]), pa.field(feature.name, list_type)
    metadata = {
        b"ARROW:extension:name": ARRAY2D.encode(),
        b"ARROW:extension:metadata": json.dumps([list(feature.shape), feature.dtype]).encode(),
    }
    return frames_array(array), pa.field(feature.name, pa.list_(pa.list_(value_type)), metadata=metadata)


def _hf_features(features: Sequence[_Feature]) -> dict[str, Any]:
    """The ``huggingface`` schema metadata `datasets` writes beside the data (so a plain ``load_dataset`` of the
    Parquet gets the same types)."""
    out: dict[str, Any] = {}
    for f in features:
        if f.shape == (1,):
            out[f.name] = {"dtype": f.dtype, "_type": "Value"}
        elif len(f.shape) == 1:
            out[f.name] = {"feature": {"dtype": f.dtype, "_type": "Value"}, "length": f.shape[0], "_type": "List"}
        else:
            out[f.name] = {"shape": list(f.shape), "dtype": f.dtype, "_type": "Array2D"}
    return {"info": {"features": out}}


def _list_array(rows: Sequence[Any], value_type: Any) -> Any:
    import pyarrow as pa

    return pa.array([np.asarray(r).tolist() for r in rows], pa.list_(value_type))


# ---------------------------------------------------------------------------------------------------------------
# one press -> one episode


@dataclass
class _Episode:
    columns: dict[str, np.ndarray]  # feature name -> (length, ...) values (frame-wise, without the index columns)
    meta: dict[str, Any]  # unitac/* and extraction/* columns of meta/episodes
    task: str
    length: int


def _episode(
    rec: PressRecord, session: dict[str, Any], sensor: str, targets: Sequence[float], displacement: bool
) -> _Episode:
    t = np.asarray(rec.tactile_t_s, dtype=np.float64)
    m = int(t.size)
    key = _tactile_key(sensor)
    tare = np.asarray(rec.tare_baseline, dtype=np.float64)
    # the recorder's own rule (storage/recorder.py): float32 frames minus the float32 baseline
    tared = np.asarray(rec.tactile_values, np.float32) - tare.astype(np.float32)[None]
    robot_t = np.asarray(rec.robot_t_s, dtype=np.float64)
    if robot_t.size:
        arm = nearest_index(robot_t, t)
        wrench = np.asarray(rec.robot_force, np.float32).reshape(-1, 6)[arm]
        pose = np.asarray(rec.robot_pose, np.float64).reshape(-1, 6)[arm].astype(np.float32)
        press = np.asarray(rec.press_force_n, np.float32)[arm]
        arm_dt = (robot_t[arm] - t).astype(np.float32)
    else:
        wrench = pose = np.full((m, 6), np.nan, np.float32)
        press = arm_dt = np.full(m, np.nan, np.float32)
    column_of = {round(float(x) * 100): i for i, x in enumerate(targets)}
    matched = np.zeros((m, len(targets)), dtype=bool)
    ex = rec.extraction
    if ex is not None:
        for k in np.flatnonzero(~np.asarray(ex.miss, bool)):
            if int(ex.frame_index[k]) >= 0:
                matched[int(ex.frame_index[k]), column_of[round(float(ex.targets_n[k]) * 100)]] = True
    columns: dict[str, np.ndarray] = {
        key: tared,
        f"{key}.valid": np.asarray(rec.tactile_valid, bool),
        f"{key}.seq": np.asarray(rec.tactile_seq, np.int64),
        f"{key}.device_t_us": np.asarray(rec.tactile_device_t_us, np.int64),
        "observation.wrench": wrench,
        "observation.tcp_pose": pose,
        "observation.press_force_n": press,
        "observation.arm_dt_s": arm_dt,
        "annotation.object": np.array([session["object"]] * m, dtype=object),
        "annotation.rotation_deg": np.full(m, rec.rotation_deg, np.float32),
        "annotation.angle_deg": np.full(m, rec.angle_deg, np.float32),
        "annotation.matched_targets": matched,
        "timestamp": (t - t[0]).astype(np.float32),
    }
    if displacement:
        columns[f"{key}.displacement_mm"] = np.asarray(rec.tactile_displacement_mm, np.float32)
    threshold = rec.attrs.get("threshold_n")
    meta: dict[str, Any] = {
        "unitac/object": session["object"],
        "unitac/sensor": sensor,
        "unitac/press_id": rec.press_id,
        "unitac/rotation_deg": float(rec.rotation_deg),
        "unitac/angle_deg": float(rec.angle_deg),
        "unitac/status": rec.status,
        "unitac/reason": rec.reason,
        "unitac/threshold_n": float(threshold) if isinstance(threshold, int | float) else float("nan"),
        "unitac/session": session["file"],
        "unitac/simulated": bool(session["simulated"]),
        "unitac/t0_host_s": float(t[0]),
        "unitac/tare_baseline": tare.reshape(-1),
    }
    if ex is not None:  # every per-target array but frame_t_s (the frame's row gives its time)
        kept = ("targets_n", "crossing_t_s", "frame_index", "force_at_frame_n", "error_n", "miss")
        meta |= {f"extraction/{name}": np.asarray(getattr(ex, name)) for name in kept}
        meta["extraction/settings"] = json.dumps(ex.settings.to_dict())
    shape = session.get("shape")
    material = session.get("material")
    what = f" ({' '.join(str(x) for x in (shape, material) if x)})" if shape or material else ""
    force = f" to {threshold:g} N" if isinstance(threshold, int | float) else ""
    return _Episode(columns, meta, f"press the {session['object']} object{what} onto the tactile pad{force}", m)


# ---------------------------------------------------------------------------------------------------------------
# one sensor -> one LeRobot dataset


def _sessions_of(pooled: Sequence[PooledSession], sensor: str) -> Iterator[tuple[dict[str, Any], list[PressRecord]]]:
    for item in pooled:
        if item.info.sensor == sensor:
            yield item.described(), [p for p in read_presses(item.info.path) if len(p.tactile_t_s) > 0]


class _DataFiles:
    """The dataset's ``data/chunk-XXX/file-YYY.parquet`` files, written in order: a new file once one passes
    ``DATA_FILE_SIZE_MB``, a new chunk every ``CHUNKS_SIZE`` files (LeRobot v3's layout)."""

    def __init__(self, root: Path) -> None:
        self.root = root
        self.chunk, self.file_index, self.file_bytes = 0, 0, 0
        self.writer: Any = None

    def write(self, table: Any) -> tuple[int, int]:
        """Append one episode's table; returns the (chunk, file) index it went to."""
        import pyarrow.parquet as pq

        if self.writer is not None and self.file_bytes + table.nbytes > DATA_FILE_SIZE_MB * 1024 * 1024:
            self.close()
            self.file_index += 1
            if self.file_index == CHUNKS_SIZE:
                self.chunk, self.file_index = self.chunk + 1, 0
        if self.writer is None:
            path = self.root / DATA_PATH.format(chunk_index=self.chunk, file_index=self.file_index)
            path.parent.mkdir(parents=True, exist_ok=True)
            self.writer = pq.ParquetWriter(path, table.schema, compression="zstd")
            self.file_bytes = 0
        self.writer.write_table(table)
        self.file_bytes += table.nbytes
        return self.chunk, self.file_index

    def close(self) -> None:
        if self.writer is not None:
            self.writer.close()
            self.writer = None


def _info_json(
    d: dict[str, Any], features: Sequence[_Feature], targets: list[float], sessions: list[dict[str, Any]]
) -> dict[str, Any]:
    """``meta/info.json``: LeRobot's dataset description, with this export's own block under ``unitac_rig``."""
    return {
        "codebase_version": CODEBASE_VERSION,
        "robot_type": "ur5e (simulated rig)" if d["simulated"] else "ur5e",
        "total_episodes": d["episodes"],
        "total_frames": d["frames"],
        "total_tasks": d["tasks"],
        "chunks_size": CHUNKS_SIZE,
        "data_files_size_in_mb": DATA_FILE_SIZE_MB,
        "video_files_size_in_mb": 200,
        "fps": d["fps"],
        "splits": {"train": f"0:{d['episodes']}"},
        "data_path": DATA_PATH,
        "video_path": None,
        "features": {f.name: f.info() for f in features},
        "unitac_rig": {
            "format": EXPORT_FORMAT,
            "sensor": d["sensor"],
            "layout": d["layout"],
            "fps_is": "the sensor's nominal rate (1 / median frame interval); timestamps are measured host times",
            "targets_n": targets,
            "simulated": d["simulated"],
            "sessions": [{k: s[k] for k in ("object", "file", "sha256", "source", "simulated")} for s in sessions],
        },
    }


def _write_sensor_dataset(root: Path, sensor: str, pooled: Sequence[PooledSession]) -> dict[str, Any]:
    """Write ``root`` as one LeRobotDataset v3.0; returns a summary for the card and manifest."""
    import pyarrow as pa

    sessions = list(_sessions_of(pooled, sensor))
    presses = [p for _, ps in sessions for p in ps]
    if not presses:
        raise DataError(f"no presses with tactile frames for {sensor}")
    n_taxels = int(np.asarray(presses[0].tactile_values).shape[1])
    layout = sensor_layout_info(sensor, n_taxels)
    targets = sorted({round(float(x), 2) for p in presses if p.extraction is not None for x in p.extraction.targets_n})
    displacement = all(p.tactile_displacement_mm is not None for p in presses)
    intervals = np.concatenate([np.diff(np.asarray(p.tactile_t_s, np.float64)) for p in presses])
    intervals = intervals[intervals > 0]
    fps = max(1, round(1.0 / float(np.median(intervals)))) if intervals.size else 1
    features = _features(sensor, layout, targets, displacement)
    by_name = {f.name: f for f in features}
    schema_meta = {b"huggingface": json.dumps(_hf_features(features)).encode()}

    tasks: dict[str, int] = {}
    episode_rows: list[dict[str, Any]] = []
    all_columns: dict[str, list[np.ndarray]] = {f.name: [] for f in features if f.dtype != "string"}
    files = _DataFiles(root)
    total = 0
    try:
        for session, records in sessions:
            for rec in records:
                episode = _episode(rec, session, sensor, targets, displacement)
                index = len(episode_rows)
                task_index = tasks.setdefault(episode.task, len(tasks))
                cols = dict(episode.columns)
                cols["frame_index"] = np.arange(episode.length, dtype=np.int64)
                cols["episode_index"] = np.full(episode.length, index, np.int64)
                cols["index"] = np.arange(total, total + episode.length, dtype=np.int64)
                cols["task_index"] = np.full(episode.length, task_index, np.int64)
                arrays, fields = zip(*(_column(f, cols[f.name]) for f in features), strict=True)
                table = pa.Table.from_arrays(list(arrays), schema=pa.schema(list(fields), metadata=schema_meta))
                chunk, file_index = files.write(table)
                stats = {f.name: feature_stats(cols[f.name]) for f in features if f.dtype != "string"}
                for name in all_columns:
                    all_columns[name].append(cols[name])
                episode_rows.append(
                    {
                        "episode_index": index,
                        "tasks": [episode.task],
                        "length": episode.length,
                        "data/chunk_index": chunk,
                        "data/file_index": file_index,
                        "dataset_from_index": total,
                        "dataset_to_index": total + episode.length,
                        **{f"stats/{name}/{stat}": value for name, s in stats.items() for stat, value in s.items()},
                        "meta/episodes/chunk_index": 0,
                        "meta/episodes/file_index": 0,
                        **episode.meta,
                    }
                )
                total += episode.length
    finally:
        files.close()

    dataset_stats = {name: feature_stats(np.concatenate(parts)) for name, parts in all_columns.items()}
    _write_episodes(root, episode_rows, by_name)
    _write_tasks(root, tasks)
    stats_json = {k: {stat: np.asarray(v).tolist() for stat, v in st.items()} for k, st in dataset_stats.items()}
    (root / "meta" / "stats.json").write_text(json.dumps(stats_json, indent=1) + "\n", encoding="utf-8")
    summary = {
        "episodes": len(episode_rows),
        "frames": total,
        "fps": int(fps),
        "objects": sorted({s["object"] for s, _ in sessions}),
        "tasks": len(tasks),
        "layout": layout,
        "simulated": all(bool(s["simulated"]) for s, _ in sessions),
        "displacement": displacement,
        "sessions": [s["file"] for s, _ in sessions],
    }
    info = _info_json({**summary, "sensor": sensor}, features, targets, [s for s, _ in sessions])
    (root / "meta" / "info.json").write_text(json.dumps(info, indent=1) + "\n", encoding="utf-8")
    return summary


def _write_episodes(root: Path, rows: list[dict[str, Any]], features: dict[str, _Feature]) -> None:
    import pyarrow as pa
    import pyarrow.parquet as pq

    names = list(dict.fromkeys(k for row in rows for k in row))
    arrays = []
    for name in names:
        values = [row.get(name) for row in rows]
        if name.startswith("stats/"):
            feature = features[name.split("/")[1]]
            stat = name.rsplit("/", 1)[1]
            if stat == "count":
                value_type = pa.int64()
            elif stat in ("min", "max") and feature.dtype in ("int64", "bool"):
                value_type = pa.int64() if feature.dtype == "int64" else pa.bool_()
            else:
                value_type = pa.float64()
            arrays.append(_list_array(values, value_type))
        elif name == "tasks":
            arrays.append(pa.array(values, pa.list_(pa.string())))
        elif isinstance(values[0], np.ndarray):
            value_type = {"f": pa.float64(), "i": pa.int64(), "b": pa.bool_()}[values[0].dtype.kind]
            arrays.append(_list_array(values, value_type))
        else:
            arrays.append(pa.array(values))
    path = root / EPISODES_PATH.format(chunk_index=0, file_index=0)
    path.parent.mkdir(parents=True, exist_ok=True)
    pq.write_table(pa.Table.from_arrays(arrays, names=names), path, compression="zstd")


def _write_tasks(root: Path, tasks: dict[str, int]) -> None:
    """``meta/tasks.parquet``: LeRobot reads it with pandas as a frame indexed by the task string, so the index is
    declared in the ``pandas`` schema metadata the way pandas itself writes it (pandas is not needed to write it)."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    def column(name: str | None, field: str | None, kind: str, metadata: Any = None) -> dict[str, Any]:
        numpy_type = "int64" if kind == "int64" else "object"
        return {"name": name, "field_name": field, "pandas_type": kind, "numpy_type": numpy_type, "metadata": metadata}

    ordered = sorted(tasks, key=tasks.__getitem__)
    pandas_meta = {
        "index_columns": ["__index_level_0__"],
        "column_indexes": [column(None, None, "unicode", {"encoding": "UTF-8"})],
        "columns": [column("task_index", "task_index", "int64"), column(None, "__index_level_0__", "unicode")],
        "attributes": {},
        "creator": {"library": "pyarrow", "version": pa.__version__},
        "pandas_version": "2.2.0",
    }
    schema = pa.schema(
        [pa.field("task_index", pa.int64()), pa.field("__index_level_0__", pa.string())],
        metadata={b"pandas": json.dumps(pandas_meta).encode()},
    )
    table = pa.Table.from_arrays([pa.array([tasks[t] for t in ordered], pa.int64()), pa.array(ordered)], schema=schema)
    pq.write_table(table, root / "meta" / "tasks.parquet")


# ---------------------------------------------------------------------------------------------------------------
# the export


def export_lerobot(data_dirs: Sequence[Path], out: Path) -> LeRobotExportSummary:
    """Pool ``data_dirs`` and write one LeRobotDataset v3.0 per sensor into ``out/<sensor>/``, with a card and a
    manifest. Built in a hidden sibling directory and renamed into place, so ``out`` is complete or absent."""
    from unitac_rig.rig.sensors import SENSORS

    with pooled_export(data_dirs, out) as (pooled, staging):
        present = {item.info.sensor for item in pooled}
        sensors = [s for s in SENSORS if s in present] + sorted(present - set(SENSORS))  # the registry's order
        summaries = {s: _write_sensor_dataset(staging / s, s, pooled) for s in sensors}
        document = {
            "format": EXPORT_FORMAT,
            "created_unix": time.time(),
            "exported_by": exported_by(),
            "lerobot_codebase_version": CODEBASE_VERSION,
            "datasets": {s: dict(summary) for s, summary in summaries.items()},
            "sessions": [
                {
                    "file": item.info.path.name,
                    "object": item.info.object_id,
                    "sensor": item.info.sensor,
                    "sha256": item.sha256,
                    "source": str(item.source),
                }
                for item in pooled
            ],
        }
        (staging / CARD_NAME).write_text(lerobot_card(document), encoding="utf-8")
        for sensor, summary in summaries.items():
            (staging / sensor / CARD_NAME).write_text(lerobot_sensor_card(sensor, summary, document), encoding="utf-8")
        files = sorted(str(p.relative_to(staging)) for p in staging.rglob("*") if p.is_file())
        write_manifest(staging, document, files)
    total = sum((out / rel).stat().st_size for rel in files)
    return LeRobotExportSummary(
        out,
        {s: {"episodes": v["episodes"], "frames": v["frames"], "fps": v["fps"]} for s, v in summaries.items()},
        len(pooled),
        len(files) + 1,
        total,
    )


def is_lerobot_export(directory: Path) -> bool:
    """True when ``directory`` is an export written by :func:`export_lerobot`."""
    return any(_export_info(p) is not None for p in Path(directory).glob("*/meta/info.json"))


def _export_info(path: Path) -> dict[str, Any] | None:
    try:
        info = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    marker = info.get("unitac_rig") if isinstance(info, dict) else None
    return info if isinstance(marker, dict) and marker.get("format") == EXPORT_FORMAT else None


def load_matched_sets(directory: Path, baseline: str = "press") -> list[MatchedSet]:
    """The force-matched sets of a LeRobot export (one per object and sensor, the presses in session order): each
    complete press's matched targets, their frames (the rows its extraction picked), forces and errors; ``baseline``
    as :func:`unitac_rig.storage.reader.load_matched_set` takes it (every episode keeps its start and its tare)."""
    import pyarrow.parquet as pq

    check_frame_baseline(baseline)
    directory = Path(directory)
    infos = [
        (p.parents[1], info)
        for p in sorted(directory.glob("*/meta/info.json"))
        if (info := _export_info(p)) is not None
    ]
    if not infos:
        raise DataError(
            f"{directory} holds no unitac-rig LeRobot export (no <sensor>/meta/info.json of one)",
            hint="pass the --out directory of `unitac-rig export --format lerobot`",
        )
    sets: list[MatchedSet] = []
    for root, info in infos:
        sensor = str(info["unitac_rig"]["sensor"])
        key = _tactile_key(sensor)
        n_taxels = int(info["features"][key]["shape"][0])
        episodes = pq.read_table(sorted((root / "meta" / "episodes").glob("*/*.parquet"))).to_pylist()
        frames_by_file: dict[tuple[int, int], Any] = {}
        parts: dict[str, tuple[list[PressMatches], list[bool]]] = {}
        tares: dict[str, tuple[list[PressTare], list[int]]] = {}  # per object: every episode's, the matched ones
        for ep in sorted(episodes, key=lambda e: e["episode_index"]):
            every, used = tares.setdefault(str(ep["unitac/object"]), ([], []))
            tare = np.asarray(ep["unitac/tare_baseline"], np.float64).reshape(n_taxels, 3)
            every.append(PressTare(float(ep["unitac/t0_host_s"]), float(ep["unitac/rotation_deg"]), tare))
            if ep.get("unitac/status") != "complete" or ep.get("extraction/miss") is None:
                continue
            used.append(len(every) - 1)
            where = (int(ep["data/chunk_index"]), int(ep["data/file_index"]))
            if where not in frames_by_file:
                table = pq.read_table(
                    root / DATA_PATH.format(chunk_index=where[0], file_index=where[1]), columns=["index", key]
                )
                flat = table.column(key).combine_chunks().flatten().flatten().to_numpy(zero_copy_only=False)
                frames_by_file[where] = (table.column("index").to_numpy(), flat.reshape(-1, n_taxels, 3))
            index, frames = frames_by_file[where]
            keep = ~np.asarray(ep["extraction/miss"], bool)
            rows = int(ep["dataset_from_index"]) + np.asarray(ep["extraction/frame_index"], np.int64)[keep]
            picked = frames[np.searchsorted(index, rows)]
            press = (
                float(ep["unitac/rotation_deg"]),
                float(ep["unitac/angle_deg"]),
                np.asarray(ep["extraction/targets_n"], np.float64)[keep],
                picked.astype(np.float32),
                np.asarray(ep["extraction/force_at_frame_n"], np.float64)[keep],
                np.asarray(ep["extraction/error_n"], np.float64)[keep],
            )
            presses, simulated = parts.setdefault(str(ep["unitac/object"]), ([], []))
            presses.append(press)
            simulated.append(bool(ep["unitac/simulated"]))
        for object_id, (presses, simulated) in sorted(parts.items()):
            shifts = frame_shifts(baseline, *tares[object_id])
            sets.append(matched_set(object_id, sensor, all(simulated), presses, n_taxels, shifts=shifts))
    return sets
