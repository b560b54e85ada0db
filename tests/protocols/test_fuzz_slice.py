"""Seeded fuzzing of every wire codec and the drivers' decode paths in the default suite: 2,000 inputs per codec,
the first 2,000 of the retired 100,000-input campaign recorded in docs/reliability.md (same seed, same draws). No
crash, no wrong decode, no decoder that keeps growing; CPU time per input (hangs) was the campaign's to measure, not
a test's to judge on a shared box."""

from __future__ import annotations

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tests.protocols.fuzz_oracles import MAX_MEMORY_GROWTH_BYTES, TARGETS, run_target

SLICE_INPUTS = 2_000
SEED = 28  # the campaign's seed: these are the first 2,000 inputs of each codec's 100,000
MEMORY_INPUTS = 200  # fed back to back to one long-lived decoder, as the campaign's smallest memory phase


@pytest.mark.parametrize("target", list(TARGETS))
def test_a_slice_of_the_campaign_finds_nothing(target: str) -> None:
    report = run_target(target, SLICE_INPUTS, SEED, memory_inputs=MEMORY_INPUTS)
    assert report.inputs == SLICE_INPUTS and len(report.kinds) >= 4  # every kind of input was drawn
    assert (report.crashes, report.wrong_decodes) == (0, 0), report.examples
    assert report.valid_embedded > 0 and report.valid_recovered == report.valid_embedded
    assert report.memory_growth_bytes < MAX_MEMORY_GROWTH_BYTES


@settings(max_examples=5, deadline=None)
@given(st.integers(0, 2**32 - 1))
def test_any_seed_finds_nothing(seed: int) -> None:
    for target in TARGETS:
        report = run_target(target, 40, seed)
        assert (report.crashes, report.wrong_decodes) == (0, 0), (target, report.examples)
