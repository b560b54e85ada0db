"""Metric definitions, under each of their options, on cases worked by hand."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from unitac_rig.learning.metrics import (
    alignment_ratio,
    latent_l1_per_pair,
    latent_mixing,
    nmae,
    nmae_per_frame,
    nmae_scale,
    ssim_per_frame,
    ssim_scale,
)


def tensor(array: np.ndarray) -> torch.Tensor:
    return torch.as_tensor(np.asarray(array, dtype=np.float64))


def ssim(target: np.ndarray, estimate: np.ndarray, data_range: np.ndarray) -> float:
    """Mean SSIM over frames."""
    return float(ssim_per_frame(tensor(target), tensor(estimate), tensor(data_range)).mean())


def latent_l1(z_a: np.ndarray, z_b: np.ndarray) -> float:
    return float(latent_l1_per_pair(tensor(z_a), tensor(z_b)).mean())


def latent_alignment_ratio(z_a: np.ndarray, z_b: np.ndarray) -> float:
    return float(alignment_ratio(tensor(z_a), tensor(z_b)))


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


# ---- the metric options (the paper states neither its NMAE normaliser nor its SSIM range) ------------------------


def stats(channel_range: list[float], channel_std: list[float], sensor_range: float) -> dict[str, torch.Tensor]:
    return {
        "channel_range": torch.tensor(channel_range, dtype=torch.float64),
        "channel_std": torch.tensor(channel_std, dtype=torch.float64),
        "sensor_range": torch.tensor(sensor_range, dtype=torch.float64),
    }


# target (2 taxels): x [0, 2], y [0, 0], z [4, 0]; estimate off by 1 on one x taxel and 2 on one z taxel:
# mean |error| per channel = (0.5, 0, 1)
NMAE_TARGET = frame([0, 2], [0, 0], [4, 0])
NMAE_ESTIMATE = frame([1, 2], [0, 0], [2, 0])
TRAINING = stats(channel_range=[2.0, 1.0, 4.0], channel_std=[0.5, 1.0, 2.0], sensor_range=10.0)


@pytest.mark.parametrize(
    ("option", "expected"),
    [
        ("channel_range", (0.5 / 2 + 0 + 1 / 4) / 3),  # each channel's training range
        ("sensor_range", (0.5 / 10 + 0 + 1 / 10) / 3),  # one range for the whole sensor
        ("channel_std", (0.5 / 0.5 + 0 + 1 / 2) / 3),  # MAE in z-score units
        ("frame_range", (0.5 / 4 + 0 + 1 / 4) / 3),  # the true frame's own range: max 4 - min 0
    ],
)
def test_nmae_under_each_normaliser(option: str, expected: float) -> None:
    target, estimate = (torch.as_tensor(a) for a in (NMAE_TARGET, NMAE_ESTIMATE))
    scale = nmae_scale(option, TRAINING, target)
    assert float(nmae_per_frame(target, estimate, scale)) == pytest.approx(expected, rel=1e-12)


def test_frame_range_normalises_every_frame_by_its_own_range() -> None:
    target = torch.as_tensor(np.stack([NMAE_TARGET, 10 * NMAE_TARGET]))
    estimate = torch.as_tensor(np.stack([NMAE_ESTIMATE, 10 * NMAE_ESTIMATE]))
    per_frame = nmae_per_frame(target, estimate, nmae_scale("frame_range", TRAINING, target))
    assert per_frame.tolist() == pytest.approx([0.125, 0.125])  # scale-free per frame


# x and z reconstructed exactly (SSIM 1 under any range); y is a noise-only channel: +-0.1 predicted as 0.
# y: mu 0, 0 -> luminance term C1 / C1 = 1; var 0.01, 0, cov 0 -> contrast-structure term C2 / (0.01 + C2)
SSIM_TARGET = frame([1, 3], [0.1, -0.1], [4, 0])
SSIM_ESTIMATE = frame([1, 3], [0.0, 0.0], [4, 0])
SSIM_TRAINING = stats(channel_range=[2.0, 0.2, 4.0], channel_std=[1.0, 0.1, 2.0], sensor_range=10.0)


@pytest.mark.parametrize(
    ("option", "data_range_y"),
    [("channel_range", 0.2), ("sensor_range", 10.0), ("z_range", 4.0)],
)
def test_ssim_of_a_noise_channel_under_each_data_range(option: str, data_range_y: float) -> None:
    c2 = (0.03 * data_range_y) ** 2
    expected = (1.0 + c2 / (0.01 + c2) + 1.0) / 3
    target, estimate = (torch.as_tensor(a) for a in (SSIM_TARGET, SSIM_ESTIMATE))
    score = float(ssim_per_frame(target, estimate, ssim_scale(option, SSIM_TRAINING)))
    assert score == pytest.approx(expected, rel=1e-9)


def test_the_noise_channel_scores_near_zero_under_its_own_range_and_near_one_under_the_sensors() -> None:
    target, estimate = (torch.as_tensor(a) for a in (SSIM_TARGET, SSIM_ESTIMATE))
    own = float(ssim_per_frame(target, estimate, ssim_scale("channel_range", SSIM_TRAINING)))
    whole = float(ssim_per_frame(target, estimate, ssim_scale("sensor_range", SSIM_TRAINING)))
    assert own == pytest.approx((2 + 0.0036) / 3, abs=1e-3)  # y alone: 0.0036
    assert whole == pytest.approx((2 + 0.9) / 3, abs=1e-9)  # y alone: 0.09 / 0.1


def test_an_unknown_option_is_refused() -> None:
    with pytest.raises(ValueError, match="unknown NMAE normaliser"):
        nmae_scale("range", TRAINING, torch.zeros(2, 3))
    with pytest.raises(ValueError, match="unknown SSIM range"):
        ssim_scale("x_range", TRAINING)


# ---- scale-free alignment and sensor mixing ---------------------------------------------------------------------


def test_alignment_ratio_is_matched_over_unmatched_distance_and_free_of_scale() -> None:
    z_a = np.array([[0.0], [10.0]])
    z_b = np.array([[1.0], [11.0]])
    # matched |0-1|, |10-11| -> 1; unmatched |0-11| = 11, |10-1| = 9 -> 10
    assert latent_alignment_ratio(z_a, z_b) == pytest.approx(0.1)
    assert latent_l1(7 * z_a, 7 * z_b) == pytest.approx(7.0)  # the raw distance grows with the scale...
    assert latent_alignment_ratio(7 * z_a, 7 * z_b) == pytest.approx(0.1)  # ...the ratio does not


def test_alignment_ratio_is_one_for_unrelated_latents_and_zero_for_identical_ones() -> None:
    rng = np.random.default_rng(0)
    z_a, z_b = rng.normal(size=(500, 4)), rng.normal(size=(500, 4))
    assert latent_alignment_ratio(z_a, z_b) == pytest.approx(1.0, abs=0.05)
    assert latent_alignment_ratio(z_a, z_a.copy()) == 0.0


def test_alignment_ratio_per_member_and_over_a_seeded_subset() -> None:
    rng = np.random.default_rng(1)
    z = torch.as_tensor(rng.normal(size=(2, 300, 3)))
    ratios = alignment_ratio(z, torch.stack([z[0], z[1] + 0.1]), max_rows=100)
    assert ratios.shape == (2,) and float(ratios[0]) == 0.0 and 0.0 < float(ratios[1]) < 0.2


def test_mixing_of_interleaved_latents_on_a_line() -> None:
    # A at 0 and 2, B at 1 and 3: every point's nearest neighbour is from the other sensor
    observed, expected = latent_mixing([np.array([[0.0], [2.0]]), np.array([[1.0], [3.0]])], k=1)
    assert observed == 1.0
    assert expected == pytest.approx(2 / 3)  # each point: 2 of the 3 others are from the other sensor


def test_mixing_is_zero_for_separate_islands_and_near_its_expectation_for_mixed_sensors() -> None:
    rng = np.random.default_rng(2)
    a, b = rng.normal(size=(200, 16)), rng.normal(size=(200, 16))
    separated, expected = latent_mixing([a, b + 100.0])
    assert separated == 0.0
    assert expected == pytest.approx(200 / 399)
    mixed, _ = latent_mixing([a, b])
    assert mixed == pytest.approx(expected, abs=0.05)
