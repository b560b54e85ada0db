"""The numbers of a `stream` line: any float32 frame, latent or profile becomes valid JSON that reads back to within
float32's 6 significant digits (non-finite values as null, which JSON can carry)."""

from __future__ import annotations

import json

import numpy as np
from hypothesis import given
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from unitac_rig.learning.live import json_numbers

shapes = st.one_of(st.tuples(st.integers(1, 20)), st.tuples(st.integers(1, 30), st.just(3)))


@given(arrays(np.float32, shapes, elements=st.floats(width=32, allow_nan=True, allow_infinity=True)))
def test_any_float32_array_reads_back_as_json_within_six_digits(values: np.ndarray) -> None:
    parsed = json.loads(json_numbers(values))
    back = np.array(parsed, dtype=object)
    assert back.shape == values.shape
    finite = np.isfinite(values)
    assert all(x is None for x in back[~finite])
    got = np.array(back[finite].tolist(), dtype=np.float64)
    expected = values[finite].astype(np.float64)
    np.testing.assert_allclose(got, expected, rtol=5e-6, atol=0)
