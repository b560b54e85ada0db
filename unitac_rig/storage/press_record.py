"""One press in a session file: :class:`PressRecord` and its HDF5 group (raw streams, tare, events, the extraction).

Layout of ``/presses/<press_id>`` (see docs/dataset.md): attributes (press id, rotation, angle, status, reason, and
whatever the press routine adds, JSON-encoded when not a plain number or string), ``robot/*`` (t_s, force, tcp_pose,
press_force_n), ``tactile/*`` (t_s, values, seq, device_t_us, valid, displacement_mm for the PapillArray),
``tare_baseline``, ``events`` and ``extraction/*``; ``write_complete`` is set last. How groups reach a session file
durably is :mod:`unitac_rig.storage.recorder`'s job.
"""

from __future__ import annotations

import json
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import h5py
import numpy as np

from unitac_rig.storage.extraction import Extraction, ExtractionSettings
from unitac_rig.storage.integrity import (
    IDENTITY_KEYS,
    array_digest,
    as_str,
    canonical_press_id,
    seal_press_group,
    sealed_arrays,
)

FINISHED_STATUSES = ("complete", "failed")  # never redone on resume; "aborted" presses are redone
#: the per-target arrays of ``extraction/`` (and of :class:`Extraction`), in the order they are written
EXTRACTION_ARRAYS = ("targets_n", "crossing_t_s", "frame_index", "frame_t_s", "force_at_frame_n", "error_n", "miss")


press_id = canonical_press_id  # the press's name, ``rot090_ang-12``: where every reader expects it


@dataclass
class PressRecord:
    """Everything recorded for one press. Times are host-clock seconds (monotonic on hardware, virtual in sim)."""

    press_id: str
    rotation_deg: float
    angle_deg: float
    status: str  # complete | failed | aborted
    reason: str  # force | travel | hard_limit | protective_stop | stall | interrupted | ...
    robot_t_s: np.ndarray  # (K,)
    robot_force: np.ndarray  # (K, 6) N, N*m, base axes (after the F/T zero)
    robot_pose: np.ndarray  # (K, 6) m, rad
    press_force_n: np.ndarray  # (K,) force along the press direction, N
    tactile_t_s: np.ndarray  # (M,) host time
    tactile_values: np.ndarray  # (M, n_taxels, 3) raw, layout units
    tactile_seq: np.ndarray  # (M,) int64, -1 where the device has no counter
    tactile_device_t_us: np.ndarray  # (M,) int64, -1 where the device has no clock
    tactile_valid: np.ndarray  # (M,) bool
    tare_baseline: np.ndarray  # (n_taxels, 3) subtracted from raw values for extraction and learning
    tactile_displacement_mm: np.ndarray | None = None  # (M, n_taxels, 3), PapillArray only
    events: list[tuple[float, str, str]] = field(default_factory=list)
    attrs: dict[str, Any] = field(default_factory=dict)  # strategy, speed, threshold, tare info, F/T zero, ...
    extraction: Extraction | None = None


def attr_value(value: Any) -> Any:
    if isinstance(value, dict | list | tuple) and not (
        isinstance(value, list | tuple) and value and all(isinstance(v, int | float) for v in value)
    ):
        return json.dumps(value, default=json_default)
    if value is None:
        return "null"
    return value


def json_default(obj: Any) -> Any:
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, Path):
        return str(obj)
    raise TypeError(f"cannot serialise {type(obj).__name__}")


def write_extraction(group: h5py.Group, extraction: Extraction, tared_values: np.ndarray) -> dict[str, str]:
    """(Re)write ``group/extraction`` from an Extraction and the press's tare-subtracted frames; returns the digests
    of the arrays written (``extraction/<name>`` -> hex SHA-256) for the group's seal."""
    if "extraction" in group:
        del group["extraction"]
    ex = group.create_group("extraction")
    ex.attrs["settings"] = json.dumps(extraction.settings.to_dict())
    n_taxels = tared_values.shape[1] if tared_values.ndim == 3 else 0
    frames = np.full((extraction.targets_n.size, n_taxels, 3), np.nan, dtype=np.float32)
    chosen = extraction.frame_index >= 0
    if chosen.any() and tared_values.size:
        frames[chosen] = tared_values[extraction.frame_index[chosen]]
    arrays = {name: getattr(extraction, name) for name in EXTRACTION_ARRAYS} | {"values": frames}
    digests = {}
    for name, value in arrays.items():
        data = np.asarray(value)
        ex.create_dataset(name, data=data)
        digests[f"extraction/{name}"] = array_digest(data)
    return digests


def reseal_extraction(group: h5py.Group, digests: dict[str, str]) -> None:
    """After ``write_extraction`` on a sealed press (``unitac-rig extract``, raw arrays verified first): replace the
    extraction's digests in the seal and seal the attributes again."""
    kept = {k: v for k, v in sealed_arrays(group).items() if not k.startswith("extraction/")}
    seal_press_group(group, {**kept, **digests})


def read_extraction(group: h5py.Group) -> tuple[Extraction, np.ndarray] | None:
    if "extraction" not in group:
        return None
    ex = group["extraction"]
    arrays = {name: ex[name][()] for name in EXTRACTION_ARRAYS}
    arrays["miss"] = arrays["miss"].astype(bool)
    extraction = Extraction(**arrays, settings=ExtractionSettings.from_dict(json.loads(ex.attrs["settings"])))
    return extraction, ex["values"][()]


def write_press_group(parent: h5py.Group, rec: PressRecord, name: str | None = None) -> h5py.Group:
    """Write one press under ``parent/<name or press_id>``, sealed with the SHA-256 of every array and attribute
    (:mod:`unitac_rig.storage.integrity`); the ``write_complete`` attribute is set last."""
    name = name or rec.press_id
    if name in parent:
        del parent[name]
    g = parent.create_group(name)
    g.attrs["press_id"] = rec.press_id
    g.attrs["rotation_deg"] = float(rec.rotation_deg)
    g.attrs["angle_deg"] = float(rec.angle_deg)
    g.attrs["status"] = rec.status
    g.attrs["reason"] = rec.reason
    for key, value in rec.attrs.items():
        g.attrs[key] = attr_value(value)
    digests: dict[str, str] = {}

    def put(path: str, data: np.ndarray, frames: bool = False) -> None:
        digests[path] = array_digest(data)  # from memory, before the bytes reach the disk
        if frames:
            _frames_dataset(g, path, data)
        else:
            g.create_dataset(path, data=data)

    put("robot/t_s", np.asarray(rec.robot_t_s, np.float64))
    put("robot/force", np.asarray(rec.robot_force, np.float32).reshape(-1, 6))
    put("robot/tcp_pose", np.asarray(rec.robot_pose, np.float64).reshape(-1, 6))
    put("robot/press_force_n", np.asarray(rec.press_force_n, np.float32))
    put("tactile/t_s", np.asarray(rec.tactile_t_s, np.float64))
    values = np.asarray(rec.tactile_values, np.float32)
    put("tactile/values", values, frames=True)
    put("tactile/seq", np.asarray(rec.tactile_seq, np.int64))
    put("tactile/device_t_us", np.asarray(rec.tactile_device_t_us, np.int64))
    put("tactile/valid", np.asarray(rec.tactile_valid, bool))
    if rec.tactile_displacement_mm is not None:
        put("tactile/displacement_mm", np.asarray(rec.tactile_displacement_mm, np.float32), frames=True)
    put("tare_baseline", np.asarray(rec.tare_baseline, np.float64))
    ev_dtype = np.dtype([("t_s", np.float64), ("kind", h5py.string_dtype()), ("detail", h5py.string_dtype())])
    put("events", np.array([(t, k, d) for t, k, d in rec.events], dtype=ev_dtype))
    if rec.extraction is not None:
        digests.update(write_extraction(g, rec.extraction, values - np.asarray(rec.tare_baseline, np.float32)[None]))
    seal_press_group(g, digests)
    g.attrs["write_complete"] = True
    return g


def _frames_dataset(group: h5py.Group, name: str, frames: np.ndarray) -> None:
    """A (M, n_taxels, 3) float32 stream, gzip level 1 with shuffle (chunked unless empty)."""
    group.create_dataset(
        name, data=frames, compression="gzip", compression_opts=1, shuffle=True, chunks=True if frames.size else None
    )


def read_press_group(g: h5py.Group) -> PressRecord:
    attrs = {k: decode_attr(v) for k, v in g.attrs.items()}
    for key in ("press_id", "rotation_deg", "angle_deg", "status", "reason", "write_complete", *IDENTITY_KEYS):
        attrs.pop(key, None)
    tac = g["tactile"]
    ex = read_extraction(g)
    events = [(float(e["t_s"]), as_str(e["kind"]), as_str(e["detail"])) for e in g["events"][()]]
    return PressRecord(
        press_id=as_str(g.attrs.get("press_id", g.name.rsplit("/", 1)[-1])),
        rotation_deg=float(g.attrs["rotation_deg"]),
        angle_deg=float(g.attrs["angle_deg"]),
        status=as_str(g.attrs["status"]),
        reason=as_str(g.attrs["reason"]),
        robot_t_s=g["robot/t_s"][()],
        robot_force=g["robot/force"][()],
        robot_pose=g["robot/tcp_pose"][()],
        press_force_n=g["robot/press_force_n"][()],
        tactile_t_s=tac["t_s"][()],
        tactile_values=tac["values"][()],
        tactile_seq=tac["seq"][()],
        tactile_device_t_us=tac["device_t_us"][()],
        tactile_valid=tac["valid"][()].astype(bool),
        tactile_displacement_mm=tac["displacement_mm"][()] if "displacement_mm" in tac else None,
        tare_baseline=g["tare_baseline"][()],
        events=events,
        attrs=attrs,
        extraction=ex[0] if ex else None,
    )


def decode_attr(value: Any) -> Any:
    if isinstance(value, bytes | str):
        value = as_str(value)
        if value[:1] in ("[", "{") or value == "null":
            try:
                return json.loads(value)
            except json.JSONDecodeError:
                return value
        return value
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, np.generic):
        return value.item()
    return value


def record_nbytes(rec: PressRecord) -> int:
    """Uncompressed size of a press's arrays (bytes): an upper bound on what writing it adds to a file."""
    arrays = [value for key, value in vars(rec).items() if isinstance(value, np.ndarray | list) and key != "events"]
    total = sum(np.asarray(a).nbytes for a in arrays)
    frame_bytes = int(np.prod(np.shape(rec.tactile_values)[1:])) * 4
    total += 32 * (8 * 6 + frame_bytes)  # extraction: ~25 targets x (6 per-target numbers + one float32 frame)
    return int(total) + 200 * len(rec.events)


def iter_press_groups(f: h5py.File) -> Iterator[tuple[str, h5py.Group]]:
    presses = f.get("presses")
    if presses is None:
        return
    for pid in sorted(presses):
        g = presses[pid]
        if g.attrs.get("write_complete", False):
            yield pid, g
