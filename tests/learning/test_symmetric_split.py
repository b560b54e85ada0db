"""The blocked split respects each object's symmetry (issue 38): a square looks the same every 90 deg, a hexagon every
60 deg, both in a mirror, a circle at every angle. Folds worked by hand; the gap checked against every turned and
mirrored image of each training ray, computed here without the code under test."""

from __future__ import annotations

import math

import numpy as np
import pytest

from tests.learning.test_splits import SEEN_ANGLES, directions_dataset
from unitac_rig.learning.data import (
    PairedDataset,
    fold_ray,
    folded_distance_deg,
    ray_deg,
    ray_distance_deg,
    split_by_direction,
)
from unitac_rig.rig.objects import Symmetry, get_object, outline_symmetry

SQUARE = Symmetry(order=4, mirror_axis_deg=0.0)
HEXAGON = Symmetry(order=6, mirror_axis_deg=0.0)
NONE = Symmetry(order=1)


def test_the_catalogue_derives_each_prisms_symmetry_from_its_outline() -> None:
    assert get_object("square_pla").symmetry == SQUARE
    assert get_object("hex_tpu").symmetry == HEXAGON
    assert get_object("circle_pla").symmetry.continuous
    assert get_object("irregular_pla").symmetry == NONE


def test_outline_symmetry_of_hand_made_polygons() -> None:
    rectangle = np.array([[20.0, 10.0], [-20.0, 10.0], [-20.0, -10.0], [20.0, -10.0]])
    assert outline_symmetry([rectangle]) == Symmetry(order=2, mirror_axis_deg=0.0)
    triangle = np.array([[10 * math.cos(math.radians(a)), 10 * math.sin(math.radians(a))] for a in (90, 210, 330)])
    assert outline_symmetry([triangle]) == Symmetry(order=3, mirror_axis_deg=30.0)  # 90 mod 60
    # a pinwheel: a square with one notch per side, turned copies of each other but no mirror line
    pinwheel = np.concatenate([np.array([[10.0, -10.0], [10.0, 2.0], [12.0, 2.0]]) @ _turn(k * 90).T for k in range(4)])
    assert outline_symmetry([pinwheel]) == Symmetry(order=4)
    # a hollow prism is only as symmetric as its inner outline too
    off_centre_hole = rectangle * 0.5 + np.array([1.0, 0.0])
    assert outline_symmetry([rectangle, off_centre_hole]) == Symmetry(order=1, mirror_axis_deg=0.0)


@pytest.mark.parametrize(
    ("symmetry", "ray", "folded"),
    [
        (SQUARE, 10, 10.0),
        (SQUARE, 80, 10.0),  # mirrored across the 90-deg mirror line
        (SQUARE, 100, 10.0),  # turned by 90
        (SQUARE, 350, 10.0),  # mirrored across 0
        (SQUARE, 45, 45.0),  # the diagonal: the far end of the folded interval
        (SQUARE, 225, 45.0),
        (HEXAGON, 40, 20.0),  # 40 mod 60 = 40, 20 from the mirror line at 60
        (HEXAGON, 20, 20.0),
        (HEXAGON, 65, 5.0),
        (HEXAGON, 290, 10.0),  # 290 mod 60 = 50
        (NONE, 290, 290.0),  # the irregular prism: nothing folds
    ],
)
def test_fold_ray_by_hand(symmetry: Symmetry, ray: int, folded: float) -> None:
    assert fold_ray(ray, symmetry) == pytest.approx(folded)


def test_folded_distance_by_hand() -> None:
    assert folded_distance_deg(0, 90, SQUARE) == 0.0
    assert folded_distance_deg(5, 87, SQUARE) == pytest.approx(2.0)  # 87 folds to 3
    assert folded_distance_deg(10, 290, HEXAGON) == 0.0
    assert folded_distance_deg(10, 350, NONE) == pytest.approx(20.0)  # the irregular prism: the plain ray distance
    assert folded_distance_deg(3, 200, Symmetry(order=0)) == 0.0


def _turn(deg: float) -> np.ndarray:
    c, s = math.cos(math.radians(deg)), math.sin(math.radians(deg))
    return np.array([[c, -s], [s, c]])


def _orbit_distance(a: int, b: int, order: int) -> float:
    """Brute force: the smallest angle between ray a and any turn (by 360/order) or mirror (across 0) of ray b."""
    images = [b + k * 360 / order for k in range(order)] + [-b + k * 360 / order for k in range(order)]
    return min(ray_distance_deg(a, i) for i in images)


def _rays(dataset: PairedDataset, mask: np.ndarray, object_id: str) -> set[int]:
    rows = mask & (dataset.object_id == object_id)
    return {ray_deg(r, a) for r, a in zip(dataset.rotation_deg[rows], dataset.angle_deg[rows], strict=True)}


@pytest.mark.parametrize("seed", range(5))
@pytest.mark.parametrize("gap", [3, 5])
def test_no_test_angle_is_within_the_gap_of_a_training_angle_once_folded(seed: int, gap: int) -> None:
    objects = ("circle_pla", "square_pla", "hex_tpu", "irregular_pla")
    dataset = directions_dataset({o: [(0, a) for a in SEEN_ANGLES] for o in objects})
    split = split_by_direction(dataset, seed, 0.1, (), val_fraction=0.1, mode="blocked", gap_deg=gap)
    for object_id, order in (("square_pla", 4), ("hex_tpu", 6), ("irregular_pla", 1)):
        test = _rays(dataset, split.test_mask, object_id)
        train = _rays(dataset, split.train_mask, object_id)
        assert test and train
        if order == 1:  # no symmetry: the plain blocked split, one contiguous block of 9 rays
            assert min(ray_distance_deg(t, a) for t in test for a in train) > gap
            assert len(test) == 9
        else:
            assert min(_orbit_distance(t, a, order) for t in test for a in train) > gap
    # the circle looks the same from every ray: it trains on all of them and is in no seen-object test
    assert split.not_held_out == ("circle_pla",)
    assert not (split.test_mask & (dataset.object_id == "circle_pla")).any()
    assert split.train_mask[dataset.object_id == "circle_pla"].all()
    assert split.to_dict()["not_held_out"] == ["circle_pla"]


def test_the_unfolded_split_would_leak_a_squares_test_rays() -> None:
    """Why the fold: the same square under the plain blocked split (no symmetry) trains on images of its test
    rays; the folded split does not."""
    from unitac_rig.learning.data import hold_out_rays

    rays = [ray_deg(0, a) for a in SEEN_ANGLES]
    leaks = 0
    for seed in range(10):
        plain = hold_out_rays(rays, "square_pla", seed, 0.1, 0.1, mode="blocked", gap_deg=3)
        train = set(rays) - plain.test - plain.val - plain.guard
        leaks += min(_orbit_distance(t, a, 4) for t in plain.test for a in train) <= 3
    assert leaks > 0
