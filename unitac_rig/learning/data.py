"""The paired dataset: every sensor's force-matched frames joined on (object, rotation, angle, target force).

Also the paper's leakage-safe split (per object, a seeded 10% of approach directions go to test with all their
forces; objects kept out of autoencoder training are all test) and the per-sensor normalisation the model sees.

Nothing here assumes two sensors: a key is kept when *every* sensor of the dataset has it.
"""

from __future__ import annotations

import hashlib
import logging
import zlib
from collections.abc import Collection, Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Protocol

import numpy as np

from unitac_rig.errors import DataError, UnitacError
from unitac_rig.learning.paper import PAPER_UNSEEN_OBJECTS

log = logging.getLogger(__name__)

# A join key: (object id, rotation in whole degrees, approach angle in whole degrees, target force in centi-newtons).
JoinKey = tuple[str, int, int, int]


class MatchedSetLike(Protocol):
    """What the learning side reads from one (object, sensor) session (``unitac_rig.storage.reader.MatchedSet``)."""

    @property
    def object_id(self) -> str: ...
    @property
    def sensor(self) -> str: ...
    @property
    def simulated(self) -> bool: ...
    @property
    def rotation_deg(self) -> np.ndarray: ...
    @property
    def angle_deg(self) -> np.ndarray: ...
    @property
    def target_n(self) -> np.ndarray: ...
    @property
    def values(self) -> np.ndarray: ...
    @property
    def force_n(self) -> np.ndarray: ...
    @property
    def error_n(self) -> np.ndarray: ...


def load_sets(data_dir: Path) -> list[MatchedSetLike]:
    """Every force-matched set under ``data_dir`` (one per session file), via the session reader."""
    from unitac_rig.storage.reader import load_matched_sets

    data_dir = Path(data_dir)
    if not data_dir.is_dir():
        raise DataError(f"data directory {data_dir} does not exist", hint="pass the --data folder `collect` wrote")
    return list(load_matched_sets(data_dir))


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

    ``values[s]``: (M, n_taxels_s, 3) float32, tare-subtracted, sensor units (uSkin counts, PapillArray N).
    ``force_n[s]``: (M,) wrist force at sensor ``s``'s matched frame, N.
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

    def __len__(self) -> int:
        return int(self.object_id.shape[0])

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
        return digest.hexdigest()


def build_paired_dataset(sets: Sequence[MatchedSetLike], sensors: Sequence[str] | None = None) -> PairedDataset:
    """Join the sets on (object, rotation, angle, target). Keeps only keys that every sensor has.

    Where one sensor has the same key twice (two sessions of one object), the frame with the smaller matching error
    wins. Raises :class:`DataError` when fewer than two sensors are present or no key is shared by all of them.
    """
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

    # per sensor: key -> (|error| N, set index, row)
    best: dict[str, dict[JoinKey, tuple[float, int, int]]] = {s: {} for s in chosen}
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

    shared = set.intersection(*(set(table) for table in best.values()))
    if not shared:
        described = "; ".join(f"{s}: {', '.join(sorted({k[0] for k in best[s]})) or 'nothing'}" for s in chosen)
        raise DataError(
            f"no joined pairs: no (object, rotation, angle, target) is present for every sensor ({described})",
            hint="record the same objects, angles and targets with each sensor",
        )
    keys = sorted(shared)
    dropped = {s: len(best[s]) - len(keys) for s in chosen}
    for sensor, count in dropped.items():
        if count:
            log.info("%s: %d matched frames have no partner in every other sensor and are left out", sensor, count)

    values_out: dict[str, np.ndarray] = {}
    force_out: dict[str, np.ndarray] = {}
    for sensor in chosen:
        rows = [best[sensor][k] for k in keys]
        values_out[sensor] = np.stack([np.asarray(sets[i].values[r], dtype=np.float32) for _, i, r in rows])
        force_out[sensor] = np.array([float(sets[i].force_n[r]) for _, i, r in rows], dtype=np.float64)
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
    )


def default_unseen_objects(object_ids: Iterable[str]) -> tuple[str, ...]:
    """Objects that stay out of autoencoder training: the catalogue's ``in_autoencoder_training`` flag where the
    catalogue knows the object, else the paper's list (the irregular prism)."""
    unseen: list[str] = []
    for object_id in sorted(set(object_ids)):
        flag = _catalogue_training_flag(object_id)
        if flag is False or (flag is None and object_id in PAPER_UNSEEN_OBJECTS):
            unseen.append(object_id)
    return tuple(unseen)


def _catalogue_training_flag(object_id: str) -> bool | None:
    from unitac_rig.rig.objects import get_object

    try:
        return bool(get_object(object_id).in_autoencoder_training)
    except UnitacError:  # an id the catalogue does not know (imported or synthetic data)
        return None


@dataclass(frozen=True)
class Split:
    """Which rows are test data. The unit of the split is an approach direction (object, rotation, angle), so all
    forces of one press are on the same side and near-identical frames never cross."""

    test_mask: np.ndarray  # (M,) bool
    seed: int
    test_fraction: float
    unseen_objects: tuple[str, ...]
    test_directions: dict[str, list[tuple[int, int]]]  # object -> [(rotation_deg, angle_deg)] held out

    @property
    def train_mask(self) -> np.ndarray:
        return ~self.test_mask

    def to_dict(self) -> dict[str, Any]:
        return {
            "seed": self.seed,
            "test_fraction": self.test_fraction,
            "unseen_objects": list(self.unseen_objects),
            "test_directions": {k: [list(d) for d in v] for k, v in self.test_directions.items()},
        }


def held_out_directions(directions: Sequence[tuple[int, int]], object_id: str, seed: int, fraction: float) -> list:
    """A seeded ``fraction`` (at least one, never all) of an object's directions; depends only on the seed, the
    object id and the directions, so adding objects to a dataset does not reshuffle the others."""
    units = sorted(set(directions))
    if len(units) < 2:
        return []
    n_test = min(len(units) - 1, max(1, round(fraction * len(units))))
    rng = np.random.default_rng([seed, zlib.crc32(object_id.encode())])
    picked = rng.choice(len(units), size=n_test, replace=False)
    return sorted(units[int(i)] for i in picked)


def split_by_direction(
    dataset: PairedDataset,
    seed: int,
    test_fraction: float = 0.1,
    unseen_objects: Collection[str] | None = None,
) -> Split:
    """The paper's split: per seen object ``test_fraction`` of its approach directions (seeded) with all their
    forces; every row of an unseen object is test data."""
    if not 0.0 < test_fraction < 1.0:
        raise DataError(f"test fraction must be between 0 and 1, got {test_fraction}")
    unseen = tuple(sorted(unseen_objects)) if unseen_objects is not None else default_unseen_objects(dataset.objects)
    rotation = np.round(dataset.rotation_deg).astype(int)
    angle = np.round(dataset.angle_deg).astype(int)
    test_mask = np.zeros(len(dataset), dtype=bool)
    test_directions: dict[str, list[tuple[int, int]]] = {}
    for object_id in dataset.objects:
        rows = dataset.object_id == object_id
        if object_id in unseen:
            test_mask |= rows
            continue
        directions = list(zip(rotation[rows].tolist(), angle[rows].tolist(), strict=True))
        held = held_out_directions(directions, object_id, seed, test_fraction)
        test_directions[object_id] = held
        held_set = set(held)
        in_test = np.array([d in held_set for d in directions], dtype=bool)
        test_mask[np.flatnonzero(rows)[in_test]] = True
    if not (~test_mask).any():
        raise DataError(
            "every row is test data: no object is left to train on",
            hint="the data needs at least one object used for autoencoder training (not only the irregular prism)",
        )
    return Split(test_mask, seed, test_fraction, unseen, test_directions)


@dataclass(frozen=True)
class Normaliser:
    """Per sensor and force channel (x, y, z): ``(value - mean) / std``, statistics over all training frames and
    taxels, in sensor units. ``data_range`` (max - min over the same values) is the NMAE/SSIM normaliser.

    A per-channel (not per-taxel) scale keeps the taxels' relative magnitudes, which is what carries contact shape,
    and puts uSkin counts and PapillArray newtons on the same footing in the summed loss.
    """

    mean: dict[str, np.ndarray]  # (3,)
    std: dict[str, np.ndarray]  # (3,)
    data_range: dict[str, np.ndarray]  # (3,)

    @classmethod
    def fit(cls, dataset: PairedDataset, rows: np.ndarray) -> Normaliser:
        mean, std, data_range = {}, {}, {}
        for sensor in dataset.sensors:
            channels = dataset.values[sensor][rows].reshape(-1, 3).astype(np.float64)
            if channels.shape[0] == 0:
                raise DataError("no training rows to fit the normalisation on")
            mean[sensor] = channels.mean(axis=0)
            spread = channels.std(axis=0)
            std[sensor] = np.where(spread > 1e-9, spread, 1.0)
            extent = channels.max(axis=0) - channels.min(axis=0)
            data_range[sensor] = np.where(extent > 1e-9, extent, 1.0)
        return cls(mean, std, data_range)

    def normalise(self, sensor: str, frames: np.ndarray) -> np.ndarray:
        """(..., n_taxels, 3) sensor units -> (..., n_taxels * 3) float32, taxel-major."""
        self._check(sensor)
        frames = np.asarray(frames, dtype=np.float64)
        scaled = (frames - self.mean[sensor]) / self.std[sensor]
        return scaled.reshape(*frames.shape[:-2], -1).astype(np.float32)

    def denormalise(self, sensor: str, flat: np.ndarray) -> np.ndarray:
        """(..., n_taxels * 3) -> (..., n_taxels, 3) in sensor units (float32)."""
        self._check(sensor)
        flat = np.asarray(flat, dtype=np.float64)
        frames = flat.reshape(*flat.shape[:-1], -1, 3)
        return (frames * self.std[sensor] + self.mean[sensor]).astype(np.float32)

    def _check(self, sensor: str) -> None:
        if sensor not in self.mean:
            from unitac_rig.errors import ModelError

            raise ModelError(f"no normalisation for sensor {sensor!r}", hint=f"known: {', '.join(self.mean)}")

    def to_dict(self) -> dict[str, dict[str, list[float]]]:
        return {
            s: {"mean": self.mean[s].tolist(), "std": self.std[s].tolist(), "data_range": self.data_range[s].tolist()}
            for s in self.mean
        }

    @classmethod
    def from_dict(cls, d: dict[str, dict[str, list[float]]]) -> Normaliser:
        return cls(
            {s: np.asarray(v["mean"], dtype=np.float64) for s, v in d.items()},
            {s: np.asarray(v["std"], dtype=np.float64) for s, v in d.items()},
            {s: np.asarray(v["data_range"], dtype=np.float64) for s, v in d.items()},
        )


def object_shape_material(object_id: str) -> tuple[str, str]:
    """(shape, material) of an object: from the catalogue where it knows the id, else from ``<shape>_<material>``."""
    from unitac_rig.rig.objects import get_object

    try:
        spec = get_object(object_id)
        return str(spec.shape), str(spec.material).upper()
    except UnitacError:
        shape, _, material = object_id.rpartition("_")
        return (shape or object_id), (material.upper() or "unknown")
