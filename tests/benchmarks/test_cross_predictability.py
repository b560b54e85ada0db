"""The cross-sensor ceiling's measuring code: R^2 per channel on a hand-worked case, and an MLP that finds a target
its input determines and not one independent of it. (That both sensors' scenes share the object's placement is
tested with the simulated rig in tests/scene/test_scene_fidelity_terms.py.)"""

from __future__ import annotations

import math

import numpy as np
import pytest

from cross_predictability import channel_r2, fit_and_predict


def test_channel_r2_on_a_hand_worked_case() -> None:
    # channel x: target 1, 2, 3 (mean 2, SST 2), estimate 1, 2, 4 (SSE 1) -> 0.5; channel y: a perfect estimate -> 1;
    # channel z: constant, nothing to explain -> NaN
    target = np.array([[1.0, 5.0, 7.0], [2.0, 6.0, 7.0], [3.0, 9.0, 7.0]])
    estimate = np.array([[1.0, 5.0, 7.0], [2.0, 6.0, 7.0], [4.0, 9.0, 7.0]])
    x, y, z = channel_r2(target, estimate)
    assert x == pytest.approx(0.5) and y == pytest.approx(1.0) and math.isnan(z)
    # the mean itself scores 0, and a worse-than-mean estimate goes negative
    assert channel_r2(target[:, :1], np.full((3, 1), 2.0)) == [pytest.approx(0.0)]
    assert channel_r2(target[:, :1], np.array([[3.0], [2.0], [1.0]]))[0] == pytest.approx(1 - 8 / 2)


def test_the_mlp_finds_a_determined_target_and_not_an_independent_one() -> None:
    rng = np.random.default_rng(0)
    source = rng.standard_normal((600, 4, 3))
    determined = np.stack([source[:, :, 0] * 2 + source[:, :, 1], source[:, :, 2] ** 2, source[:, :, 0]], axis=-1)
    independent = rng.standard_normal((600, 4, 3))
    test = np.arange(600) % 5 == 0
    good = channel_r2(determined[test], fit_and_predict(source, determined, test, steps=400))
    bad = channel_r2(independent[test], fit_and_predict(source, independent, test, steps=400))
    assert min(good) > 0.9
    assert max(bad) < 0.1
