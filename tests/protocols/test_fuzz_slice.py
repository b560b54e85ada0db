"""A seeded slice of benchmarks/fuzz.py's campaign in the default suite: 2,000 inputs per codec (the benchmark runs
100,000). No crash, no wrong decode, no decoder that keeps growing; hangs are the benchmark's to measure (CPU time is
not a test's to judge on a shared box)."""

from __future__ import annotations

import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from fuzz import (
    MAX_MEMORY_GROWTH_BYTES,
    TARGETS,
    markdown_table,
    rebuild,
    run_campaign,
    run_target,
)

SLICE_INPUTS = 2_000
SEED = 28  # the benchmark's default seed: these are the first 2,000 inputs of its campaign


@pytest.mark.parametrize("target", list(TARGETS))
def test_a_slice_of_the_campaign_finds_nothing(target: str) -> None:
    report = run_target(target, SLICE_INPUTS, SEED, hang_ms=math.inf)
    assert report.inputs == SLICE_INPUTS and len(report.kinds) >= 4  # every kind of input was drawn
    assert (report.crashes, report.wrong_decodes) == (0, 0), report.examples
    assert report.valid_recovered == report.valid_embedded
    assert report.memory["growth_bytes"] < MAX_MEMORY_GROWTH_BYTES


@settings(max_examples=5, deadline=None)
@given(st.integers(0, 2**32 - 1))
def test_any_campaign_seed_finds_nothing(seed: int) -> None:
    result = run_campaign(40, seed, hang_ms=math.inf, memory_inputs=0)
    assert result["totals"]["crashes"] == result["totals"]["wrong_decodes"] == 0, result["targets"]


def test_an_input_is_rebuilt_from_its_numbers_and_the_table_has_a_row_per_codec() -> None:
    first, again = rebuild("papillarray", 7, 123), rebuild("papillarray", 7, 123)
    assert (first.kind, first.data) == (again.kind, again.data)
    result = run_campaign(5, 1, hang_ms=math.inf, memory_inputs=0)
    table = markdown_table(result).splitlines()
    assert len(table) == 2 + len(TARGETS) and all(f"`{name}`" in "\n".join(table) for name in TARGETS)
