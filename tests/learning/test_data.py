"""Joining sessions into pairs, the paper's split, and the normalisation."""

from __future__ import annotations

import numpy as np
import pytest

from tests.learning.learning_helpers import small_sets
from unitac_rig.errors import DataError
from unitac_rig.learning.data import (
    Normaliser,
    build_paired_dataset,
    hold_out_rays,
    ray_deg,
    split_by_direction,
)
from unitac_rig.storage.reader import MatchedSet


def matched(
    sensor: str,
    keys: list[tuple[float, float]],
    values: list[float],
    errors: list[float] | None = None,
    object_id: str = "circle_pla",
    n_taxels: int = 2,
) -> MatchedSet:
    """A set whose frame i is filled with values[i]; keys are (angle, target)."""
    m = len(keys)
    return MatchedSet(
        object_id=object_id,
        sensor=sensor,
        simulated=True,
        rotation_deg=np.zeros(m),
        angle_deg=np.array([k[0] for k in keys]),
        target_n=np.array([k[1] for k in keys]),
        values=np.stack([np.full((n_taxels, 3), v, dtype=np.float32) for v in values]),
        force_n=np.array([k[1] for k in keys]),
        error_n=np.array(errors if errors is not None else [0.0] * m),
    )


def test_join_keeps_only_keys_every_sensor_has_in_key_order() -> None:
    a = matched("uskin", [(0, 4.0), (1, 4.0), (2, 4.0)], [10, 11, 12])
    b = matched("papillarray", [(2, 4.0), (1, 4.0), (3, 4.0)], [22, 21, 23], n_taxels=1)
    pairs = build_paired_dataset([a, b])
    assert pairs.sensors == ("uskin", "papillarray")
    assert pairs.angle_deg.tolist() == [1.0, 2.0]
    assert pairs.values["uskin"][:, 0, 0].tolist() == [11, 12]
    assert pairs.values["papillarray"][:, 0, 0].tolist() == [21, 22]
    assert pairs.dropped_per_sensor == {"uskin": 1, "papillarray": 1}


def test_targets_join_at_centinewton_resolution_and_duplicates_keep_the_better_match() -> None:
    a1 = matched("uskin", [(0, 4.25)], [1.0], errors=[0.3])
    a2 = matched("uskin", [(0, 4.2500001)], [2.0], errors=[-0.1])  # a second session of the same press
    b = matched("papillarray", [(0, 4.249999)], [5.0])
    pairs = build_paired_dataset([a1, a2, b])
    assert len(pairs) == 1
    assert pairs.target_n.tolist() == [4.25]
    assert pairs.values["uskin"][0, 0, 0] == 2.0


def test_no_shared_key_is_a_data_error_naming_each_sensors_objects() -> None:
    a = matched("uskin", [(0, 4.0)], [1.0], object_id="circle_pla")
    b = matched("papillarray", [(0, 4.0)], [1.0], object_id="hex_tpu")
    with pytest.raises(DataError, match="no joined pairs") as info:
        build_paired_dataset([a, b])
    assert "circle_pla" in str(info.value) and "hex_tpu" in str(info.value)
    assert info.value.hint


def test_a_single_sensor_cannot_be_paired() -> None:
    with pytest.raises(DataError, match="only one sensor"):
        build_paired_dataset([matched("uskin", [(0, 4.0)], [1.0])])


@pytest.fixture(scope="module")
def pairs():  # type: ignore[no-untyped-def]
    return build_paired_dataset(small_sets())


def directions(dataset, mask):  # type: ignore[no-untyped-def]
    return set(zip(dataset.object_id[mask], dataset.rotation_deg[mask], dataset.angle_deg[mask], strict=True))


def test_split_never_puts_one_approach_direction_on_both_sides(pairs) -> None:  # type: ignore[no-untyped-def]
    split = split_by_direction(pairs, seed=3)
    assert not directions(pairs, split.test_mask) & directions(pairs, split.train_mask)
    # every force of a held-out direction is test data: 5 targets each
    for object_id, held in split.test_directions.items():
        assert len(held) == 1  # round(10% of 11 angles)
        rows = (pairs.object_id == object_id) & (pairs.angle_deg == held[0][1])
        assert rows.sum() == 5 and split.test_mask[rows].all()


def test_irregular_object_is_all_test_data(pairs) -> None:  # type: ignore[no-untyped-def]
    split = split_by_direction(pairs, seed=0)
    irregular = pairs.object_id == "irregular_pla"
    assert split.unseen_objects == ("irregular_pla",)
    assert irregular.sum() == 4 * 11 * 5
    assert split.test_mask[irregular].all()
    assert not split.test_mask[~irregular].all()


def test_split_is_seeded_and_per_object_stable(pairs) -> None:  # type: ignore[no-untyped-def]
    assert np.array_equal(split_by_direction(pairs, seed=5).test_mask, split_by_direction(pairs, seed=5).test_mask)
    rays = [ray_deg(0, a) for a in range(-45, 46)]
    held = hold_out_rays(rays, "hex_tpu", 5, 0.1).test
    assert len(held) == 9  # the paper: 10% of 91 angles
    assert held == hold_out_rays(list(reversed(rays)), "hex_tpu", 5, 0.1).test
    others = {hold_out_rays(rays, "hex_tpu", s, 0.1).test for s in range(6)}
    assert len(others) > 1  # the seed matters
    # one object's held-out angles do not depend on which other objects are in the dataset
    only_hex = pairs.subset(pairs.object_id != "circle_pla")
    assert (
        split_by_direction(only_hex, 5).test_directions["hex_tpu"]
        == split_by_direction(pairs, 5).test_directions["hex_tpu"]
    )


def test_normaliser_standardises_each_channel_and_inverts_exactly() -> None:
    a = matched("uskin", [(0, 4.0), (1, 4.0)], [0.0, 2.0])
    b = matched("papillarray", [(0, 4.0), (1, 4.0)], [1.0, 1.0], n_taxels=1)
    pairs = build_paired_dataset([a, b])
    norm = Normaliser.fit(pairs, np.array([True, True]))
    assert norm.mean["uskin"].tolist() == [1.0, 1.0, 1.0]
    assert norm.std["uskin"].tolist() == [1.0, 1.0, 1.0]
    assert norm.data_range["uskin"].tolist() == [2.0, 2.0, 2.0]
    assert norm.std["papillarray"].tolist() == [1.0, 1.0, 1.0]  # a constant channel is not divided by zero
    flat = norm.normalise("uskin", pairs.values["uskin"])
    assert flat.shape == (2, 6)
    assert flat[0].tolist() == [-1.0] * 6
    assert np.allclose(norm.denormalise("uskin", flat), pairs.values["uskin"])
    assert Normaliser.from_dict(norm.to_dict()).to_dict() == norm.to_dict()
