"""Fault injector and synthetic sources: seeded, deterministic, and doing what the plan says."""

from __future__ import annotations

import numpy as np
import pytest

from drivers.layouts import PAPILLARRAY, USKIN
from unitac_rig.sim.faults import FaultInjector, FaultPlan
from unitac_rig.sim.sensor_models import PapillArrayParams
from unitac_rig.sim.synthetic_sources import PressSource, press_load_n


def _run(plan: FaultPlan, n: int = 200) -> list[bytes | None]:
    injector = FaultInjector(plan)
    return [injector.mangle(bytes(range(16))) for _ in range(n)]


def test_same_seed_same_damage_and_other_seed_differs() -> None:
    plan = FaultPlan(seed=7, drop_message_prob=0.2, corrupt_prob=0.2, garbage_prob=0.1, drop_byte_prob=0.01)
    assert _run(plan) == _run(plan)
    assert _run(plan) != _run(FaultPlan(**{**plan.__dict__, "seed": 8}))


def test_no_plan_passes_messages_untouched() -> None:
    assert all(m == bytes(range(16)) for m in _run(FaultPlan()))


def test_drop_and_corrupt_are_counted_as_they_happen() -> None:
    injector = FaultInjector(FaultPlan(seed=1, drop_message_prob=0.25, corrupt_prob=0.5))
    original = bytes(range(16))
    out = [injector.mangle(original) for _ in range(400)]
    dropped = [i for i, m in enumerate(out) if m is None]
    changed = [i for i, m in enumerate(out) if m is not None and m != original]
    assert dropped == injector.counts.dropped_indices
    assert changed == injector.counts.corrupted_indices
    assert 60 < len(dropped) < 140  # 25 % of 400, loosely
    # a corruption is exactly one flipped bit
    for i in changed:
        message = out[i]
        assert message is not None
        assert sum(bin(a ^ b).count("1") for a, b in zip(message, original, strict=True)) == 1


def test_garbage_goes_in_front_of_an_intact_message() -> None:
    injector = FaultInjector(FaultPlan(seed=3, garbage_prob=1.0))
    message = injector.mangle(b"PAYLOAD")
    assert message is not None and message.endswith(b"PAYLOAD") and 1 <= len(message) - 7 <= 16
    assert injector.counts.garbage_bytes == len(message) - 7


def test_windows_count_from_the_device_start() -> None:
    injector = FaultInjector(FaultPlan(stall_windows_s=((1.0, 0.5),), disconnect_windows_s=((3.0, 1.0),)))
    assert not injector.is_stalled(10**9)  # not started: no window applies
    injector.start(2 * 10**9)
    assert not injector.is_stalled(int(2.9e9))
    assert injector.is_stalled(int(3.2e9)) and not injector.is_stalled(int(3.5e9))
    assert injector.is_disconnected(int(5.5e9)) and not injector.is_disconnected(int(6.0e9))
    injector.force_disconnect()
    assert injector.is_disconnected(0)


def test_split_chunks_stay_within_bounds() -> None:
    injector = FaultInjector(FaultPlan(seed=2, split_max_bytes=5))
    sizes = [injector.chunk_size(100) for _ in range(200)]
    assert min(sizes) == 1 and max(sizes) == 5
    assert FaultInjector().chunk_size(100) == 100


def test_bad_plans_are_rejected() -> None:
    with pytest.raises(ValueError):
        FaultPlan(drop_message_prob=1.5)
    with pytest.raises(ValueError):
        FaultPlan(split_max_bytes=0)


def test_press_load_rests_then_peaks_mid_bump() -> None:
    # period 2 s, first half unloaded, sin^2 bump peaking at 1.5 s
    assert press_load_n(int(0.5e9), period_s=2.0, peak_load_n=10.0, rest_fraction=0.5) == 0.0
    assert press_load_n(int(1.5e9), period_s=2.0, peak_load_n=10.0, rest_fraction=0.5) == pytest.approx(10.0)
    assert press_load_n(int(1.25e9), period_s=2.0, peak_load_n=10.0, rest_fraction=0.5) == pytest.approx(5.0)


def test_uskin_source_is_a_function_of_time_with_plausible_counts() -> None:
    source = PressSource(USKIN, seed=4)
    a, b = source.sample(123_000_000), source.sample(123_000_000)
    assert np.array_equal(a.values, b.values)
    rest = source.sample(int(0.5e9)).values
    assert rest.shape == USKIN.frame_shape
    assert not np.array_equal(rest, source.sample(int(0.5e9) + 1).values)  # fresh noise at another instant
    # the uSkin output model's per-taxel baselines (~33 k +- thousands) with ~8 counts of noise
    assert np.abs(rest - source.model.baseline_counts).max() < 60
    assert np.ptp(source.model.baseline_counts) > 1_000
    pressed = source.sample(int(1.5e9)).values
    # the press adds thousands of counts under the centre taxels
    assert (pressed[:, 2] - rest[:, 2]).max() > 1_000


def test_papillarray_source_centre_pillar_carries_most_and_displacement_follows_force() -> None:
    quiet = PapillArrayParams(noise_mm=0.0, offset_sd_mm=0.0)
    sample = PressSource(PAPILLARRAY, seed=1, params=quiet).sample(int(1.5e9))
    assert sample.values.shape == PAPILLARRAY.frame_shape
    assert int(np.argmax(sample.values[:, 2])) == 4
    assert sample.values[:, 2].sum() == pytest.approx(10.0, abs=0.01)  # read in 1 mN steps
    assert sample.displacement_mm is not None
    assert sample.displacement_mm[4, 2] == pytest.approx(sample.values[4, 2] / 6.0, abs=1e-3)  # 6 N/mm axial
