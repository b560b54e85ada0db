"""Metric definitions on cases worked by hand."""

from __future__ import annotations

import numpy as np
import pytest

from unitac_rig.learning.metrics import latent_l1, nmae, ssim


def frame(x: list[float], y: list[float], z: list[float]) -> np.ndarray:
    """(n_taxels, 3) from per-channel taxel values."""
    return np.stack([x, y, z], axis=1).astype(np.float64)


def test_nmae_divides_each_channel_by_its_range_then_averages_channels() -> None:
    target = frame([0, 2], [0, 0], [4, 0])
    estimate = frame([1, 2], [0, 0], [2, 0])
    # x: mean |err| 0.5 / range 2 = 0.25; y: 0; z: mean |err| 1 / range 4 = 0.25 -> (0.25 + 0 + 0.25) / 3
    assert nmae(target, estimate, np.array([2.0, 1.0, 4.0])) == pytest.approx(1 / 6)


def test_nmae_of_a_perfect_reconstruction_is_zero_and_averages_over_frames() -> None:
    target = np.stack([frame([0, 2], [0, 0], [4, 0]), frame([1, 1], [1, 1], [1, 1])])
    estimate = target.copy()
    estimate[1, :, 0] += 2.0  # second frame: x off by 2 everywhere -> 2 / 2 / 3 channels = 1/3
    assert nmae(target, estimate, np.array([2.0, 1.0, 4.0])) == pytest.approx((0 + 1 / 3) / 2)


def test_ssim_uses_global_grid_statistics_with_c1_c2_from_the_data_range() -> None:
    # L = 2: C1 = (0.01 * 2)^2 = 0.0004, C2 = (0.03 * 2)^2 = 0.0036; population (1/n) variances.
    # x: identical -> 1.
    # y: [0, 2] vs [2, 0]: mu 1, 1; var 1, 1; cov -1
    #    -> (2 + C1)(-2 + C2) / ((2 + C1)(2 + C2)) = -1.9964 / 2.0036
    # z: [0, 2] vs [1, 3]: mu 1, 2; var 1, 1; cov 1
    #    -> (4 + C1)(2 + C2) / ((5 + C1)(2 + C2)) = 4.0004 / 5.0004
    target = frame([1, 3], [0, 2], [0, 2])
    estimate = frame([1, 3], [2, 0], [1, 3])
    expected = (1.0 + (-1.9964 / 2.0036) + 4.0004 / 5.0004) / 3
    assert ssim(target, estimate, np.array([2.0, 2.0, 2.0])) == pytest.approx(expected, rel=1e-9)


def test_ssim_of_identical_flat_frames_is_one() -> None:
    flat = frame([0, 0, 0], [5, 5, 5], [1, 1, 1])
    assert ssim(flat, flat, np.array([1.0, 1.0, 1.0])) == pytest.approx(1.0)


def test_latent_l1_is_the_mean_manhattan_distance_between_matched_latents() -> None:
    z_a = np.array([[0.0, 1.0], [2.0, 2.0]])
    z_b = np.array([[1.0, 1.0], [0.0, 0.0]])
    assert latent_l1(z_a, z_b) == pytest.approx((1.0 + 4.0) / 2)
