"""What learning does with the paired dataset: the paper's leakage-safe split (per object, a seeded 10% of approach
directions go to test with all their forces; objects kept out of autoencoder training are all test) and the
per-sensor normalisation the model sees.

The join itself (:class:`PairedDataset`, :func:`build_paired_dataset`, :func:`load_sets`) lives in
:mod:`unitac_rig.storage.paired`, below both learning and ``unitac-rig export``; it is imported here so the learning
code reads the dataset from one module.
"""

from __future__ import annotations

import functools
import logging
import zlib
from collections.abc import Callable, Collection, Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from unitac_rig.errors import DataError, ModelError, UnitacError
from unitac_rig.learning.config import PREPROCESSING
from unitac_rig.learning.paper import PAPER_UNSEEN_OBJECTS
from unitac_rig.storage.paired import (
    JoinKey,
    PairedDataset,
    build_paired_dataset,
    join_key,
    load_sets,
    sensor_order,
)

__all__ = [
    "PREPROCESSING",
    "JoinKey",
    "Normaliser",
    "PairedDataset",
    "Split",
    "build_paired_dataset",
    "default_unseen_objects",
    "fold_ray",
    "folded_distance_deg",
    "join_key",
    "load_sets",
    "object_shape_material",
    "object_symmetry",
    "sensor_order",
    "split_by_direction",
]

if TYPE_CHECKING:  # the catalogue is imported lazily (it pulls in the rig's geometry)
    from unitac_rig.rig.objects import ObjectSpec, Symmetry

log = logging.getLogger(__name__)


def default_unseen_objects(object_ids: Iterable[str]) -> tuple[str, ...]:
    """Objects that stay out of autoencoder training: the catalogue's ``in_autoencoder_training`` flag where the
    catalogue knows the object, else the paper's list (the irregular prism)."""
    specs = {object_id: _catalogued(object_id) for object_id in sorted(set(object_ids))}
    return tuple(
        object_id
        for object_id, spec in specs.items()
        if (object_id in PAPER_UNSEEN_OBJECTS if spec is None else not spec.in_autoencoder_training)
    )


def _catalogued(object_id: str) -> ObjectSpec | None:
    """The catalogue's entry for an object; None for an id it does not know (imported or synthetic data)."""
    from unitac_rig.rig.objects import get_object

    try:
        return get_object(object_id)
    except UnitacError:
        return None


@dataclass(frozen=True)
class Split:
    """Which rows are test data and which validation data. The unit of the split is an approach direction (object,
    rotation, angle), so all forces of one press are on the same side and near-identical frames never cross.

    Validation directions are drawn from the seen objects' directions that are not test data; per-epoch curves and
    every choice (options, model size) are made on them, never on the test rows.
    """

    test_mask: np.ndarray  # (M,) bool
    seed: int
    test_fraction: float
    unseen_objects: tuple[str, ...]
    test_directions: dict[str, list[tuple[int, int]]]  # object -> [(rotation_deg, angle_deg)] held out
    val_mask: np.ndarray | None = None  # (M,) bool, disjoint from test_mask; None: no validation rows
    val_fraction: float = 0.0
    val_directions: dict[str, list[tuple[int, int]]] = field(default_factory=dict)
    mode: str = "random"  # SPLIT_MODES
    gap_deg: float = 0.0  # blocked: the guard band around held-out rays (its rows are validation rows)
    # blocked: seen objects whose cross-section looks the same at every angle (a circle): no angle can be held out,
    # so they are not in the seen-object test (every row trains)
    not_held_out: tuple[str, ...] = ()

    @property
    def validation_mask(self) -> np.ndarray:
        return np.zeros_like(self.test_mask) if self.val_mask is None else self.val_mask

    @property
    def train_mask(self) -> np.ndarray:
        return ~self.test_mask & ~self.validation_mask

    def to_dict(self) -> dict[str, Any]:
        return {
            "seed": self.seed,
            "test_fraction": self.test_fraction,
            "unseen_objects": list(self.unseen_objects),
            "test_directions": {k: [list(d) for d in v] for k, v in self.test_directions.items()},
            "val_fraction": self.val_fraction,
            "val_directions": {k: [list(d) for d in v] for k, v in self.val_directions.items()},
            "mode": self.mode,
            "gap_deg": self.gap_deg,
            "not_held_out": list(self.not_held_out),
        }

    @classmethod
    def from_dict(cls, info: Mapping[str, Any], test_mask: np.ndarray, val_mask: np.ndarray | None) -> Split:
        """The split :meth:`to_dict` described, with its row masks (a checkpoint keeps them apart, as tensors)."""

        def directions(key: str) -> dict[str, list[tuple[int, int]]]:
            return {k: [(int(d[0]), int(d[1])) for d in v] for k, v in info[key].items()}

        return cls(
            np.asarray(test_mask, dtype=bool),
            int(info["seed"]),
            float(info["test_fraction"]),
            tuple(info["unseen_objects"]),
            directions("test_directions"),
            np.asarray(val_mask, dtype=bool),
            float(info["val_fraction"]),
            directions("val_directions"),
            str(info["mode"]),
            float(info["gap_deg"]),
            tuple(info["not_held_out"]),
        )


SPLIT_MODES: tuple[str, ...] = ("random", "blocked")
DEFAULT_GAP_DEG = 3  # blocked split: no training ray within this many degrees of a held-out one


def ray_deg(rotation_deg: float, angle_deg: float) -> int:
    """The physical ray a press comes along, whole degrees in [0, 360) in the object's CAD frame: the direction of
    :func:`unitac_rig.rig.objects.pad_side_direction`, ``angle - rotation - 90``. Two (rotation, angle) keys of one
    ray (on the irregular prism (0, -45) and (90, 45), (0, 45) and (270, -45), ...) press the same spot of the
    outline, so a split treats them as one unit."""
    return (round(float(angle_deg)) - round(float(rotation_deg)) - 90) % 360


def ray_distance_deg(a: float, b: float) -> float:
    """Angle between two rays (deg, 0..180)."""
    d = abs(float(a) - float(b)) % 360.0
    return min(d, 360.0 - d)


def arc_order(values: Collection[float], period: float = 360) -> tuple[list[float], bool]:
    """(``values`` (rays, or folded rays on a ring of ``period`` deg) in order along their arc, whether they close a
    ring). A partial arc (a seen object's -45..45 deg) starts after its widest gap, so a block never joins its two
    ends; a ring (the irregular prism's four rotations cover all 360 deg) may wrap."""
    units = sorted(set(values))
    n = len(units)
    if n < 2:
        return units, False
    gaps = [(units[(i + 1) % n] - units[i]) % period for i in range(n)]
    widest = int(np.argmax(gaps))
    order = units[widest + 1 :] + units[: widest + 1]
    return order, max(gaps) <= 2 * min(gaps)


def pick_block(
    order: Sequence[float],
    ring: bool,
    size: int,
    rng: np.random.Generator,
    avoid: Collection[float] = (),
    centre_deg: float | None = None,
) -> list[float]:
    """One contiguous block of ``size`` rays along ``order`` that holds none of ``avoid``: a seeded one, or the one
    whose middle ray is nearest ``centre_deg``. Raises DataError when no such block exists."""
    n = len(order)
    avoided = set(avoid)
    starts = range(n) if ring else range(n - size + 1)
    blocks = [[order[(s + k) % n] for k in range(size)] for s in starts]
    blocks = [b for b in blocks if not avoided.intersection(b)]
    if not blocks or size < 1:
        raise DataError(f"no contiguous block of {size} approach directions is free to hold out")
    if centre_deg is not None:
        return min(blocks, key=lambda b: ray_distance_deg(b[size // 2], centre_deg))
    return blocks[int(rng.integers(len(blocks)))]


def within_gap(
    values: Collection[float], held: Collection[float], gap_deg: float, distance: Callable[[float, float], float]
) -> set[float]:
    """The values (not held) within ``gap_deg`` of a held one by ``distance``: the guard band that neither trains
    nor tests."""
    held_set = set(held)
    return {v for v in values if v not in held_set and any(distance(v, h) <= gap_deg + 1e-9 for h in held_set)}


def object_symmetry(object_id: str) -> Symmetry:
    """The catalogue's symmetry of an object's cross-section (:attr:`unitac_rig.rig.objects.ObjectSpec.symmetry`);
    an object the catalogue does not know (imported or synthetic data) is taken as having none."""
    from unitac_rig.rig.objects import Symmetry

    spec = _catalogued(object_id)
    return Symmetry(order=1) if spec is None else spec.symmetry


def fold_ray(ray: float, symmetry: Symmetry) -> float:
    """A ray (deg, CAD frame) folded by the cross-section's symmetry: every ray a turn or a mirror of the outline
    maps onto it has the same folded value. Rotational order n: the angle modulo ``360 / n`` from a mirror line;
    with mirrors, the distance to the nearest mirror line, in ``[0, 180 / n]``; no symmetry: the ray itself."""
    if symmetry.continuous:
        return 0.0
    period = 360.0 / symmetry.order
    t = (float(ray) - (symmetry.mirror_axis_deg or 0.0)) % period
    return round(min(t, period - t) if symmetry.mirror_axis_deg is not None else t, 6)


def folded_distance_deg(a: float, b: float, symmetry: Symmetry) -> float:
    """The smallest angle between ray ``a`` and any image of ray ``b`` under the symmetry (deg): 0 when the outline
    looks the same from both. On folded values: plain difference with mirrors (an interval), ring distance
    without."""
    if symmetry.continuous:
        return 0.0
    return _folded_value_distance(fold_ray(a, symmetry), fold_ray(b, symmetry), symmetry)


def _folded_value_distance(fa: float, fb: float, symmetry: Symmetry) -> float:
    d = abs(fa - fb)
    if symmetry.mirror_axis_deg is not None:
        return d
    period = 360.0 / symmetry.order
    return min(d % period, period - d % period)


@dataclass(frozen=True)
class RayHoldOut:
    """Which rays of one object are test, validation and guard-band rays (the rest train)."""

    test: frozenset[int]
    val: frozenset[int]
    guard: frozenset[int]


def hold_out_rays(
    rays: Collection[int],
    object_id: str,
    seed: int,
    test_fraction: float,
    val_fraction: float = 0.0,
    *,
    mode: str = "random",
    gap_deg: float = DEFAULT_GAP_DEG,
    centres_deg: Sequence[float] = (),
    stream: int = 0,
    symmetry: Symmetry | None = None,
) -> RayHoldOut:
    """Test, validation and guard rays of one object, seeded by (``seed``, the object id, ``stream``).

    ``random`` (the paper's): ``test_fraction`` of the rays drawn at random, then ``val_fraction`` (of all) of the
    rest; no guard (on an object pressed at one rotation: the paper's split of its approach angles). ``blocked``: one
    contiguous block of rays for test and one for validation, with every other ray within ``gap_deg`` of either a
    guard ray (held out of training, scored on neither side), so no training ray lies within ``gap_deg`` of a test or
    validation ray. ``corner``: as blocked,
    the test block centred on one of ``centres_deg`` (a corner's ray), chosen by the seed.

    ``symmetry`` (blocked only): the cross-section's symmetry. The blocks are then drawn in the folded angle
    (:func:`fold_ray`) and the gap measured there (:func:`folded_distance_deg`), so no training ray is within
    ``gap_deg`` of a turned or mirrored image of a test ray. A continuous symmetry (a circle) cannot be held out by
    angle: nothing is held out (every ray trains), and :func:`split_by_direction` lists the object as such."""
    if mode not in (*SPLIT_MODES, "corner"):
        raise DataError(f"unknown split mode {mode!r}", hint=f"use one of {', '.join((*SPLIT_MODES, 'corner'))}")
    units = sorted(set(int(r) % 360 for r in rays))
    empty = RayHoldOut(frozenset(), frozenset(), frozenset())
    if len(units) < 2:
        return empty
    key = [seed, zlib.crc32(object_id.encode())] + ([stream] if stream else [])
    if mode == "random":
        n_test, n_val = _block_sizes(len(units), test_fraction, val_fraction)
        rng = np.random.default_rng(key)
        tested = {units[int(i)] for i in rng.choice(len(units), size=n_test, replace=False)}
        rest = [u for u in units if u not in tested]
        picked: set[int] = set()
        if n_val > 0 and len(rest) >= 2:
            val_rng = np.random.default_rng([*key[:2], 1, *key[2:]])
            picked = {rest[int(i)] for i in val_rng.choice(len(rest), size=min(n_val, len(rest) - 1), replace=False)}
        return RayHoldOut(frozenset(tested), frozenset(picked), frozenset())
    rng = np.random.default_rng([*key, 2])
    value_of = {u: float(u) for u in units}  # the value a block is drawn in: the ray, or the folded ray
    order, ring = arc_order(list(value_of.values()))
    distance: Callable[[float, float], float] = ray_distance_deg
    if mode == "blocked" and symmetry is not None and (symmetry.order != 1 or symmetry.mirror_axis_deg is not None):
        sym = symmetry
        value_of = {u: fold_ray(u, sym) for u in units}
        if sym.continuous or len(set(value_of.values())) < 2:
            return empty
        values = sorted(set(value_of.values()))
        # with mirrors the folded values lie on an interval [0, 180 / n], without on a ring of 360 / n
        order, ring = (values, False) if sym.mirror_axis_deg is not None else arc_order(values, 360.0 / sym.order)
        distance = functools.partial(_folded_value_distance, symmetry=sym)
    n_test, n_val = _block_sizes(len(order), test_fraction, val_fraction)
    centre = None
    if mode == "corner":
        if not centres_deg:
            raise DataError(f"{object_id} has no corner to hold out", hint="use the blocked split for it")
        centre = float(centres_deg[int(rng.integers(len(centres_deg)))])
    test = set(pick_block(order, ring, n_test, rng, centre_deg=centre))
    guard = within_gap(order, test, gap_deg, distance)
    val: set[float] = set()
    if n_val > 0:
        val = set(pick_block(order, ring, n_val, rng, avoid=test | guard))
        guard |= within_gap(order, val, gap_deg, distance) - test
    if not set(order) - test - val - guard:
        raise DataError(f"{object_id}: the blocked split leaves no approach direction to train on")
    return RayHoldOut(*(frozenset(u for u in units if value_of[u] in side) for side in (test, val, guard)))


def _block_sizes(n_units: int, test_fraction: float, val_fraction: float) -> tuple[int, int]:
    """(test, validation) units: the fractions of ``n_units``, at least one each (validation only when asked),
    always leaving one."""
    n_test = min(n_units - 1, max(1, round(test_fraction * n_units)))
    n_val = min(n_units - 1 - n_test, max(1, round(val_fraction * n_units))) if val_fraction > 0 else 0
    return n_test, n_val


def split_by_direction(
    dataset: PairedDataset,
    seed: int,
    test_fraction: float = 0.1,
    unseen_objects: Collection[str] | None = None,
    val_fraction: float = 0.0,
    *,
    mode: str = "random",
    gap_deg: float = DEFAULT_GAP_DEG,
) -> Split:
    """The paper's split (``mode="random"``): per seen object ``test_fraction`` of its approach rays (seeded) with
    all their forces; every row of an unseen object is test data. With ``val_fraction`` > 0, a further seeded
    fraction of each seen object's rays is validation data (so training keeps 1 - test - val of them).

    ``mode="blocked"`` holds out one contiguous block of rays per seen object for test and one for validation
    (:func:`hold_out_rays`): a test of extrapolation to approach directions the model never saw near, not of
    interpolation between 1-degree neighbours. The guard band's contacts (within ``gap_deg`` of a held-out ray)
    are added to the validation rows, so they are never trained on. A unit is a physical ray
    (:func:`ray_deg`): two (rotation, angle) keys of one ray are always on the same side. The blocks and the gap
    are in the angle folded by each object's symmetry (:func:`fold_ray`, from the catalogue): a square's ray and
    the same ray turned by 90 deg or mirrored press the same geometry, so they go to the same side. An object that
    looks the same at every angle (a circle) cannot be held out by angle: it trains on every ray, is not in the
    seen-object test and is listed in ``Split.not_held_out``."""
    if mode not in SPLIT_MODES:
        raise DataError(f"unknown split mode {mode!r}", hint=f"use one of {', '.join(SPLIT_MODES)}")
    if not 0.0 < test_fraction < 1.0:
        raise DataError(f"test fraction must be between 0 and 1, got {test_fraction}")
    if not 0.0 <= val_fraction < 1.0 - test_fraction:
        raise DataError(f"validation fraction must be in [0, {1.0 - test_fraction:g}), got {val_fraction}")
    unseen = tuple(sorted(unseen_objects)) if unseen_objects is not None else default_unseen_objects(dataset.objects)
    rotation = np.round(dataset.rotation_deg).astype(int)
    angle = np.round(dataset.angle_deg).astype(int)
    test_mask = np.zeros(len(dataset), dtype=bool)
    val_mask = np.zeros(len(dataset), dtype=bool)
    test_directions: dict[str, list[tuple[int, int]]] = {}
    val_directions: dict[str, list[tuple[int, int]]] = {}
    not_held_out: list[str] = []
    for object_id in dataset.objects:
        rows = dataset.object_id == object_id
        if object_id in unseen:
            test_mask |= rows
            continue
        directions = list(zip(rotation[rows].tolist(), angle[rows].tolist(), strict=True))
        rays = [ray_deg(r, a) for r, a in directions]
        symmetry = object_symmetry(object_id) if mode == "blocked" else None
        if symmetry is not None and symmetry.continuous:
            not_held_out.append(object_id)
        held = hold_out_rays(
            rays, object_id, seed, test_fraction, val_fraction, mode=mode, gap_deg=gap_deg, symmetry=symmetry
        )
        in_test = np.array([r in held.test for r in rays], dtype=bool)
        in_val = np.array([r in held.val or r in held.guard for r in rays], dtype=bool)
        test_directions[object_id] = sorted(set(d for d, t in zip(directions, in_test, strict=True) if t))
        test_mask[np.flatnonzero(rows)[in_test]] = True
        if in_val.any():
            val_directions[object_id] = sorted(set(d for d, v in zip(directions, in_val, strict=True) if v))
            val_mask[np.flatnonzero(rows)[in_val]] = True
    if not (~test_mask).any():
        raise DataError(
            "every row is test data: no object is left to train on",
            hint="the data needs at least one object used for autoencoder training (not only the irregular prism)",
        )
    return Split(
        test_mask,
        seed,
        test_fraction,
        unseen,
        test_directions,
        val_mask if val_fraction > 0.0 or val_mask.any() else None,
        val_fraction,
        val_directions,
        mode,
        float(gap_deg) if mode != "random" else 0.0,
        tuple(not_held_out),
    )


@dataclass(frozen=True)
class Normaliser:
    """What the network sees of a frame: per sensor and force channel (x, y, z), ``(value - mean) / std``, where
    ``mean`` and ``std`` are the offset and scale of the preprocessing ``mode`` (statistics over all training
    frames and taxels, in sensor units):

    * ``channel_z``: each channel's own mean and standard deviation (a per-channel z-score). It scales a channel that
      holds only noise up to unit variance, so that noise weighs as much in the loss as the normal force;
    * ``sensor_minmax``: one offset and scale per sensor, the minimum and range of all its values pooled over taxels
      and axes, so values fall in [0, 1] and the channels keep their recorded proportions (the authors publish
      exactly these pooled min/max statistics per session);
    * ``sensor_scale``: no offset, one scale per sensor (the pooled standard deviation): raw readings up to a
      constant, which only balances the two sensors' units in the summed loss;
    * ``raw``: no offset, no scale (uSkin counts and PapillArray newtons as recorded).

    Also kept, for the metrics' normalisers: ``data_range`` (each channel's training range), ``channel_std`` and
    ``sensor_range`` (the whole sensor's training range).
    """

    mean: dict[str, np.ndarray]  # (3,) offset
    std: dict[str, np.ndarray]  # (3,) scale
    data_range: dict[str, np.ndarray]  # (3,) each channel's training range
    mode: str
    channel_std: dict[str, np.ndarray]  # (3,)
    sensor_range: dict[str, float]

    @classmethod
    def fit(
        cls, dataset: PairedDataset, rows: np.ndarray, mode: str = "channel_z", sensors: Sequence[str] | None = None
    ) -> Normaliser:
        """The statistics of ``sensors`` (default: all of the dataset's) over the training ``rows``."""
        if mode not in PREPROCESSING:
            raise DataError(f"unknown preprocessing {mode!r}", hint=f"use one of {', '.join(PREPROCESSING)}")
        mean, std, data_range, channel_std, sensor_range = {}, {}, {}, {}, {}
        for sensor in dataset.sensors if sensors is None else sensors:
            channels = dataset.values[sensor][rows].reshape(-1, 3).astype(np.float64)
            channels = channels[~np.isnan(channels).any(axis=1)]  # a partial join's missing frames are NaN
            if channels.shape[0] == 0:
                raise DataError("no training rows to fit the normalisation on")
            spread = channels.std(axis=0)
            channel_std[sensor] = np.where(spread > 1e-9, spread, 1.0)
            extent = channels.max(axis=0) - channels.min(axis=0)
            data_range[sensor] = np.where(extent > 1e-9, extent, 1.0)
            lowest, whole = float(channels.min()), float(channels.max() - channels.min())
            sensor_range[sensor] = whole if whole > 1e-9 else 1.0
            pooled = float(channels.std())
            if mode == "channel_z":
                mean[sensor], std[sensor] = channels.mean(axis=0), channel_std[sensor]
            elif mode == "sensor_minmax":
                mean[sensor], std[sensor] = np.full(3, lowest), np.full(3, sensor_range[sensor])
            elif mode == "sensor_scale":
                mean[sensor], std[sensor] = np.zeros(3), np.full(3, pooled if pooled > 1e-9 else 1.0)
            else:  # raw
                mean[sensor], std[sensor] = np.zeros(3), np.ones(3)
        return cls(mean, std, data_range, mode, channel_std, sensor_range)

    def metric_stats(self, sensor: str) -> dict[str, np.ndarray]:
        """The training statistics the metrics' normalisers use (``unitac_rig.learning.metrics.nmae_scale``)."""
        self._check(sensor)
        return {
            "channel_range": np.asarray(self.data_range[sensor], dtype=np.float64),
            "channel_std": np.asarray(self.channel_std[sensor], dtype=np.float64),
            "sensor_range": np.asarray(self.sensor_range[sensor], dtype=np.float64),
        }

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

    def inputs(self, rows: PairedDataset, feature_dims: Mapping[str, int]) -> tuple[np.ndarray, np.ndarray]:
        """What the model trains on: (M, sum of ``feature_dims``) float32, the normalised frames of those sensors side
        by side in that order, a frame a contact lacks as zeros (the masked loss never sees it), and the (M, sensors)
        float32 presence."""
        blocks, present = [], []
        for sensor, width in feature_dims.items():
            has = rows.has(sensor) if sensor in rows.values else np.zeros(len(rows), dtype=bool)
            block = np.zeros((len(rows), width), dtype=np.float32)
            if has.any():
                block[has] = self.normalise(sensor, rows.values[sensor][has])
            blocks.append(block)
            present.append(has)
        return np.concatenate(blocks, axis=1), np.stack(present, axis=1).astype(np.float32)

    def _check(self, sensor: str) -> None:
        if sensor not in self.mean:
            raise ModelError(f"no normalisation for sensor {sensor!r}", hint=f"known: {', '.join(self.mean)}")

    def to_dict(self) -> dict[str, dict[str, Any]]:
        return {
            s: {
                "mean": self.mean[s].tolist(),
                "std": self.std[s].tolist(),
                "data_range": self.data_range[s].tolist(),
                "mode": self.mode,
                "channel_std": self.channel_std[s].tolist(),
                "sensor_range": float(self.sensor_range[s]),
            }
            for s in self.mean
        }

    @classmethod
    def from_dict(cls, d: dict[str, dict[str, Any]]) -> Normaliser:
        modes = {str(v["mode"]) for v in d.values()}
        if len(modes) != 1:
            raise DataError(f"a normaliser needs one preprocessing mode, not {sorted(modes)}")

        def arrays(key: str) -> dict[str, np.ndarray]:
            return {s: np.asarray(v[key], dtype=np.float64) for s, v in d.items()}

        sensor_range = {s: float(v["sensor_range"]) for s, v in d.items()}
        return cls(
            arrays("mean"), arrays("std"), arrays("data_range"), modes.pop(), arrays("channel_std"), sensor_range
        )


def object_shape_material(object_id: str) -> tuple[str, str]:
    """(shape, material) of an object: from the catalogue where it knows the id, else from ``<shape>_<material>``."""
    spec = _catalogued(object_id)
    if spec is not None:
        return str(spec.shape), str(spec.material).upper()
    shape, _, material = object_id.rpartition("_")
    return (shape or object_id), (material.upper() or "unknown")
