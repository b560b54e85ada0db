"""The paired dataset: every sensor's force-matched frames joined on (object, rotation, angle, target force).

It lives in storage, below both of its readers: ``unitac-rig export`` writes exactly these pairs as Parquet
(:mod:`unitac_rig.storage.export`), and the learning side (:mod:`unitac_rig.learning.data`) splits, normalises and
trains on them. Nothing here assumes two sensors: a key is kept when *every* sensor of the dataset has it (or, for a
partial join, at least two).
"""

from __future__ import annotations

import hashlib
import logging
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from unitac_rig.errors import DataError
from unitac_rig.storage import lerobot
from unitac_rig.storage.pooling import pool_sessions
from unitac_rig.storage.reader import MatchedSet, load_matched_set, load_matched_sets

log = logging.getLogger(__name__)

# A join key: (object id, rotation in whole degrees, approach angle in whole degrees, target force in centi-newtons).
JoinKey = tuple[str, int, int, int]


def load_sets(data_dir: Path | Sequence[Path], baseline: str = "press") -> list[MatchedSet]:
    """Every force-matched set under ``data_dir`` (one per session file), via the session reader; a LeRobot export
    (``unitac-rig export --format lerobot``) is read back from its episodes. ``baseline``: what the frames are
    referenced to (:data:`unitac_rig.storage.reader.FRAME_BASELINES`).

    Several directories are pooled by :func:`unitac_rig.storage.pooling.pool_sessions` (the rule ``export`` uses): a
    byte-identical copy of a session counts once, two different files for one (object, sensor) are a DataError.
    """
    dirs = [Path(data_dir)] if isinstance(data_dir, str | Path) else [Path(d) for d in data_dir]
    for directory in dirs:
        if not directory.is_dir():
            raise DataError(f"data directory {directory} does not exist", hint="pass the --data folder `collect` wrote")
    if len(dirs) == 1:
        if lerobot.is_lerobot_export(dirs[0]):  # `export --format lerobot` read back: the same matched frames
            return list(lerobot.load_matched_sets(dirs[0], baseline))
        return list(load_matched_sets(dirs[0], baseline))
    pooled = pool_sessions(dirs)
    for item in pooled:
        if item.also_in:
            log.info("%s is also in %s (identical): pooled once", item.info.path, ", ".join(map(str, item.also_in)))
    return [load_matched_set(item.info.path, baseline) for item in pooled]


def sensor_order(names: Iterable[str]) -> tuple[str, ...]:
    """Canonical sensor order: the sensor registry's order first (uskin, papillarray), then the rest by name."""
    from unitac_rig.rig.sensors import SENSORS

    registered = list(SENSORS)
    unique = set(names)
    known = [n for n in registered if n in unique]
    return tuple(known + sorted(unique - set(known)))


def join_key(object_id: str, rotation_deg: float, angle_deg: float, target_n: float) -> JoinKey:
    return (str(object_id), round(float(rotation_deg)) % 360, round(float(angle_deg)), round(float(target_n) * 100))


@dataclass(frozen=True)
class PairedDataset:
    """M joined contacts; row ``i`` of every sensor's ``values`` is the same (object, rotation, angle, target).

    ``values[s]``: (M, n_taxels_s, 3) float32, tare-subtracted (``frame_baseline``: each press's tare, or its
    recording's), sensor units (uSkin counts, PapillArray N).
    ``force_n[s]``: (M,) wrist force at sensor ``s``'s matched frame, N.
    ``present[s]``: (M,) bool, whether sensor ``s`` recorded the contact (a partial join,
    ``build_paired_dataset(..., partial=True)``); a missing frame is NaN. None: every sensor has every row.
    """

    sensors: tuple[str, ...]
    object_id: np.ndarray  # (M,) str
    rotation_deg: np.ndarray  # (M,) float
    angle_deg: np.ndarray  # (M,) float
    target_n: np.ndarray  # (M,) float
    values: dict[str, np.ndarray]
    force_n: dict[str, np.ndarray]
    simulated: bool
    dropped_per_sensor: dict[str, int] = field(default_factory=dict)
    present: dict[str, np.ndarray] | None = None
    frame_baseline: str = "press"  # what the frames are referenced to (reader.FRAME_BASELINES)

    def __len__(self) -> int:
        return int(self.object_id.shape[0])

    def has(self, sensor: str) -> np.ndarray:
        """(M,) bool: the rows where ``sensor`` has a frame."""
        if self.present is None:
            return np.ones(len(self), dtype=bool)
        return self.present[sensor]

    def complete_rows(self) -> np.ndarray:
        """(M,) bool: the rows every sensor recorded."""
        return np.logical_and.reduce([self.has(s) for s in self.sensors]) if self.sensors else np.ones(0, bool)

    @property
    def objects(self) -> tuple[str, ...]:
        return tuple(sorted(set(self.object_id.tolist())))

    def n_taxels(self, sensor: str) -> int:
        return int(self.values[sensor].shape[1])

    def subset(self, mask: np.ndarray) -> PairedDataset:
        """The rows where ``mask`` (bool (M,) or integer indices) selects."""
        return PairedDataset(
            sensors=self.sensors,
            object_id=self.object_id[mask],
            rotation_deg=self.rotation_deg[mask],
            angle_deg=self.angle_deg[mask],
            target_n=self.target_n[mask],
            values={s: v[mask] for s, v in self.values.items()},
            force_n={s: f[mask] for s, f in self.force_n.items()},
            simulated=self.simulated,
            present=None if self.present is None else {s: p[mask] for s, p in self.present.items()},
            frame_baseline=self.frame_baseline,
        )

    def content_hash(self) -> str:
        """SHA-256 over sensors, keys and every value (hex); checkpoints keep it to catch a changed dataset."""
        digest = hashlib.sha256()
        digest.update(repr(self.sensors).encode())
        digest.update("\x00".join(self.object_id.tolist()).encode())
        for array in (self.rotation_deg, self.angle_deg, self.target_n):
            digest.update(np.ascontiguousarray(array, dtype=np.float64).tobytes())
        for sensor in self.sensors:
            digest.update(sensor.encode())
            digest.update(np.ascontiguousarray(self.values[sensor], dtype=np.float32).tobytes())
            if self.present is not None:  # only for a partial join, so a complete dataset hashes as it always did
                digest.update(np.ascontiguousarray(self.present[sensor], dtype=bool).tobytes())
        return digest.hexdigest()


def build_paired_dataset(
    sets: Sequence[MatchedSet], sensors: Sequence[str] | None = None, *, partial: bool = False
) -> PairedDataset:
    """Join the sets on (object, rotation, angle, target). Keeps only keys that every sensor has, or with
    ``partial`` every key that at least two sensors have (the others' frames NaN, ``present`` says which).

    Where one sensor has the same key twice (two sessions of one object), the frame with the smaller matching error
    wins. Raises :class:`DataError` when fewer than two sensors are present or no key is shared by all of them (by
    two of them, with ``partial``).
    """
    chosen = _chosen_sensors(sets, sensors)
    _one_rig(sets, chosen)
    baselines = {s.baseline for s in sets if s.sensor in chosen}
    if len(baselines) > 1:
        raise DataError(f"the sets are referenced to different frame baselines ({', '.join(sorted(baselines))})")
    best, n_taxels = _best_rows(sets, chosen)
    keys = _shared_keys(best, chosen, partial)
    shared = set(keys)
    dropped = {s: len(set(best[s]) - shared) for s in chosen}
    for sensor, count in dropped.items():
        if count:
            log.info("%s: %d matched frames have no partner in every other sensor and are left out", sensor, count)

    values_out: dict[str, np.ndarray] = {}
    force_out: dict[str, np.ndarray] = {}
    has_frame: dict[str, np.ndarray] | None = {} if partial else None
    for sensor in chosen:
        values_out[sensor], force_out[sensor], has = _gather(sets, best[sensor], keys, n_taxels[sensor])
        if has_frame is not None:
            has_frame[sensor] = has
    if has_frame is not None and all(bool(h.all()) for h in has_frame.values()):
        has_frame = None  # nothing missing: the very dataset (and content hash) of the complete join
    return PairedDataset(
        sensors=chosen,
        object_id=np.array([k[0] for k in keys], dtype=str),
        rotation_deg=np.array([k[1] for k in keys], dtype=np.float64),
        angle_deg=np.array([k[2] for k in keys], dtype=np.float64),
        target_n=np.array([k[3] / 100.0 for k in keys], dtype=np.float64),
        values=values_out,
        force_n=force_out,
        simulated=all(bool(s.simulated) for s in sets if s.sensor in chosen),
        dropped_per_sensor=dropped,
        present=has_frame,
        frame_baseline=baselines.pop() if baselines else "press",
    )


def _one_rig(sets: Sequence[MatchedSet], chosen: tuple[str, ...]) -> None:
    """Pairs join only within one rig: two sensors recorded on different rigs (another arm, F/T, mount, or the
    simulator beside hardware) saw different contacts under the same (rotation, angle, target). DataError naming two
    sessions of different rigs; sets that do not say which rig recorded them are not checked."""
    seen: dict[str, MatchedSet] = {}
    for matched in sets:
        if matched.sensor in chosen and matched.rig:
            seen.setdefault(matched.rig, matched)
    if len(seen) > 1:
        (rig_a, a), (rig_b, b) = list(seen.items())[:2]
        raise DataError(
            f"pairs join only within one rig: {a.object_id}/{a.sensor} was recorded on {rig_a}, "
            f"{b.object_id}/{b.sensor} on {rig_b}",
            hint="keep each rig's sessions in their own --data directory and train or export one rig at a time",
        )


def _chosen_sensors(sets: Sequence[MatchedSet], sensors: Sequence[str] | None) -> tuple[str, ...]:
    """The sensors to join (all present ones by default); at least two, each with data."""
    if not sets:
        raise DataError("no force-matched data found", hint="run `unitac-rig collect` (or `campaign`) first")
    present = sensor_order(s.sensor for s in sets)
    chosen = tuple(sensors) if sensors is not None else present
    missing = [s for s in chosen if s not in present]
    if missing:
        raise DataError(
            f"no data for sensor(s) {', '.join(missing)}",
            hint=f"the data holds {', '.join(present)}",
        )
    if len(chosen) < 2:
        raise DataError(
            f"only one sensor in the data ({', '.join(chosen)}): UniTac-NV learns from pairs of sensors",
            hint="record the same objects with a second sensor",
        )
    return chosen


# per sensor: join key -> (|matching error| N, set index, row): the frame that represents the key
BestRows = dict[str, dict[JoinKey, tuple[float, int, int]]]


def _best_rows(sets: Sequence[MatchedSet], chosen: tuple[str, ...]) -> tuple[BestRows, dict[str, int]]:
    """Per chosen sensor, the frame of each key with the smallest matching error; and each sensor's taxel count."""
    best: BestRows = {s: {} for s in chosen}
    n_taxels: dict[str, int] = {}
    for set_index, matched in enumerate(sets):
        if matched.sensor not in best:
            continue
        values = np.asarray(matched.values)
        if values.ndim != 3 or values.shape[2] != 3:
            raise DataError(
                f"{matched.object_id}/{matched.sensor}: values must be (M, n_taxels, 3), got {values.shape}"
            )
        if n_taxels.setdefault(matched.sensor, values.shape[1]) != values.shape[1]:
            raise DataError(
                f"sensor {matched.sensor} has frames of {values.shape[1]} and {n_taxels[matched.sensor]} taxels",
                hint="one sensor id must always mean one layout",
            )
        table = best[matched.sensor]
        errors = np.abs(np.asarray(matched.error_n, dtype=np.float64))
        for row in range(values.shape[0]):
            key = join_key(matched.object_id, matched.rotation_deg[row], matched.angle_deg[row], matched.target_n[row])
            candidate = (float(errors[row]), set_index, row)
            if key not in table or candidate[0] < table[key][0]:
                table[key] = candidate
    return best, n_taxels


def _shared_keys(best: BestRows, chosen: tuple[str, ...], partial: bool) -> list[JoinKey]:
    """The sorted keys every chosen sensor has (with ``partial``: at least two of them); a DataError if none."""
    if partial:
        counts: dict[JoinKey, int] = {}
        for table in best.values():
            for key in table:
                counts[key] = counts.get(key, 0) + 1
        shared = {key for key, n in counts.items() if n >= 2}
    else:
        shared = set.intersection(*(set(table) for table in best.values()))
    if not shared:
        described = "; ".join(f"{s}: {', '.join(sorted({k[0] for k in best[s]})) or 'nothing'}" for s in chosen)
        raise DataError(
            f"no joined pairs: no (object, rotation, angle, target) is present for "
            f"{'two sensors' if partial else 'every sensor'} ({described})",
            hint="record the same objects, angles and targets with each sensor",
        )
    return sorted(shared)


def _gather(
    sets: Sequence[MatchedSet], table: dict[JoinKey, tuple[float, int, int]], keys: list[JoinKey], n_taxels: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """One sensor's (values (M, n_taxels, 3) float32, force (M,) N, has (M,) bool) in ``keys`` order; NaN where the
    sensor has no frame for a key."""
    has = np.array([k in table for k in keys], dtype=bool)
    values = np.full((len(keys), n_taxels, 3), np.nan, dtype=np.float32)
    force = np.full(len(keys), np.nan, dtype=np.float64)
    for index in np.flatnonzero(has).tolist():
        _, i, r = table[keys[index]]
        values[index] = np.asarray(sets[i].values[r], dtype=np.float32)
        force[index] = float(sets[i].force_n[r])
    return values, force, has
