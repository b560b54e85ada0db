"""Force-matched extraction on hand-made streams with known answers."""

import numpy as np
import pytest

from unitac_rig.storage.extraction import (
    ExtractionSettings,
    default_targets_n,
    extract_press,
    first_upward_crossings,
    smooth,
)


def test_paper_targets():
    targets = default_targets_n()
    assert targets.size == 25
    assert targets[0] == 4.0 and targets[-1] == 10.0
    assert np.allclose(np.diff(targets), 0.25)


def test_crossing_is_interpolated_between_samples():
    # force 0, 2, 4, 6 N at t = 0, 1, 2, 3 s: 5 N is crossed half way between t=2 and t=3
    t = np.array([0.0, 1.0, 2.0, 3.0])
    f = np.array([0.0, 2.0, 4.0, 6.0])
    assert first_upward_crossings(t, f, np.array([5.0, 4.0, 7.0]))[:2] == pytest.approx([2.5, 2.0])
    assert np.isnan(first_upward_crossings(t, f, np.array([7.0]))[0])


def test_crossings_ignore_the_unloading_side():
    t = np.arange(7.0)
    f = np.array([0, 3, 6, 9, 6, 3, 0.0])  # peak at t=3
    assert first_upward_crossings(t, f, np.array([4.5]))[0] == pytest.approx(1.5)


def test_linear_ramp_matches_nearest_frame_with_known_error():
    # robot at 500 Hz, force rises 10 N/s from t=0; tactile at 100 Hz offset by 3 ms
    robot_t = np.arange(0, 1.2, 0.002)
    force = 10.0 * robot_t
    tactile_t = np.arange(0.003, 1.2, 0.01)
    ex = extract_press(robot_t, force, tactile_t, settings=ExtractionSettings(smoothing_samples=1))
    # target 4.00 N is crossed at 0.400 s; frames at ...0.393, 0.403 -> nearest 0.403 -> force 4.03 N
    assert ex.crossing_t_s[0] == pytest.approx(0.4)
    assert tactile_t[ex.frame_index[0]] == pytest.approx(0.403)
    assert ex.error_n[0] == pytest.approx(0.03, abs=1e-9)
    assert not ex.miss.any()
    assert np.all(np.abs(ex.error_n) <= 0.05 + 1e-9)  # at most half a frame period * 10 N/s


def test_targets_above_the_peak_are_misses():
    robot_t = np.arange(0, 1, 0.002)
    force = np.minimum(8.0, 20 * robot_t)
    ex = extract_press(robot_t, force, np.arange(0, 1, 0.01))
    reached = ex.targets_n <= 8.0
    assert not ex.miss[reached].any()
    assert ex.miss[~reached].all()
    assert (ex.frame_index[~reached] == -1).all()


def test_steep_ramp_beyond_tolerance_is_flagged():
    # 200 N/s at 10 Hz tactile: nearest frames can be 0.05 s away -> up to 10 N error -> misses, not silent
    robot_t = np.arange(0, 0.2, 0.002)
    force = 200 * robot_t
    ex = extract_press(robot_t, force, np.arange(0, 0.2, 0.1), settings=ExtractionSettings(smoothing_samples=1))
    assert ex.miss.sum() > 20


def test_invalid_frames_are_not_matched():
    robot_t = np.arange(0, 1.2, 0.002)
    tactile_t = np.arange(0, 1.2, 0.01)
    valid = np.ones(tactile_t.size, bool)
    valid[40] = False  # the frame at 0.40 s that target 4.0 N would pick
    ex = extract_press(robot_t, 10 * robot_t, tactile_t, valid, ExtractionSettings(smoothing_samples=1))
    assert ex.miss[0]
    assert not ex.miss[1:].any()


def test_smoothing_keeps_length_and_linear_signals():
    x = np.arange(20.0)
    assert np.allclose(smooth(x, 5)[2:-2], x[2:-2])
    assert smooth(x, 5).shape == x.shape


def test_target_only_the_raw_peak_reaches_is_matched_on_the_raw_force():
    # a ramp to exactly 10.2 N then a drop: a 15-sample average peaks below 10.2, the raw force crosses 10.1 N
    robot_t = np.arange(0, 1.0, 0.002)
    force = np.where(robot_t <= 0.51, 20 * robot_t, 0.0)
    settings = ExtractionSettings(targets_n=(5.0, 10.1), smoothing_samples=15)
    ex = extract_press(robot_t, force, np.arange(0.0, 1.0, 0.001), settings=settings)
    assert ex.crossing_t_s[1] == pytest.approx(0.505, abs=1e-9)
    assert not ex.miss.any()
    assert abs(ex.error_n[1]) <= 0.02 + 1e-9
