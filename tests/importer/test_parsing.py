"""Reading their raw CSVs: fast column parsing that agrees with Python's own reading; bad rows named, not guessed."""

from __future__ import annotations

import ast
import csv
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from tests.importer.unitac_nv_fixtures import USKIN_GRID, Press, write_raw_csv
from unitac_rig.errors import DataError
from unitac_rig.importer.parsing import parse_number_column, parse_times, read_raw_csv

finite = st.floats(min_value=-1e6, max_value=1e6, allow_nan=False, allow_infinity=False)
counts = st.integers(min_value=0, max_value=65535)


@settings(max_examples=40, deadline=None)
@given(
    st.lists(
        st.one_of(arrays(np.float64, (3, 3, 3), elements=finite), arrays(np.int64, (3, 3, 3), elements=counts)),
        min_size=1,
        max_size=8,
    )
)
def test_vectorised_parse_equals_python_literal_reading(matrices: list[np.ndarray]) -> None:
    cells = [str(m.tolist()) for m in matrices]
    values, ok = parse_number_column(cells, (3, 3, 3))
    assert ok.all()
    expected = np.array([ast.literal_eval(c) for c in cells], dtype=np.float64)
    np.testing.assert_array_equal(values, expected)


@settings(max_examples=30, deadline=None)
@given(
    st.lists(arrays(np.float64, (6,), elements=finite), min_size=2, max_size=6),
    st.data(),
)
def test_one_broken_row_is_named_and_the_others_survive(rows: list[np.ndarray], data: st.DataObject) -> None:
    cells = [str(r.tolist()) for r in rows]
    broken = data.draw(st.integers(0, len(cells) - 1))
    damage = data.draw(st.sampled_from(["drop_value", "word", "truncate"]))
    if damage == "drop_value":
        cells[broken] = str(rows[broken].tolist()[:5])
    elif damage == "word":  # right number of commas, so it takes the fast path and must be found after
        cells[broken] = "[None" + cells[broken][cells[broken].index(",") :]
    else:
        cells[broken] = cells[broken][: len(cells[broken]) // 2]
    values, ok = parse_number_column(cells, (6,), check_brackets=False)
    assert not ok[broken]
    assert ok.sum() == len(cells) - 1
    for i in np.nonzero(ok)[0]:
        np.testing.assert_array_equal(values[i], rows[i])


def test_bracket_structure_must_fit_the_sensor_grid() -> None:
    good = str(np.zeros((3, 3, 3)).tolist())
    same_count_other_shape = str(np.zeros((9, 3)).tolist())  # 27 numbers, but not 3 x 3 x 3
    _, ok = parse_number_column([good, same_count_other_shape], (3, 3, 3))
    assert ok.tolist() == [True, False]


def test_time_strings_with_and_without_microseconds() -> None:
    micros, ok = parse_times(["2025-02-03 15:44:24.250000", "2025-02-03 15:44:25", "03/02/2025 15:44"])
    assert ok.tolist() == [True, True, False]
    assert micros[1] - micros[0] == 750_000


def _damage(path: Path, edits: dict[int, list[str]]) -> None:
    with open(path, newline="") as fh:
        rows = list(csv.reader(fh))
    for data_row, row in edits.items():
        rows[data_row + 1] = row
    with open(path, "w", newline="") as fh:
        csv.writer(fh).writerows(rows)


def test_raw_file_is_read_with_bad_rows_reported(tmp_path: Path) -> None:
    path = tmp_path / "hexagonal_PLA" / "xela" / "sensor_data_20250203_154424.csv"
    rec = write_raw_csv(path, "uskin", [Press(0.0)])
    with open(path, newline="") as fh:
        row_20 = list(csv.reader(fh))[21]
    _damage(
        path,
        {
            3: row_20[:4],  # cut short: 4 columns
            5: [row_20[0], row_20[1], row_20[2].replace("32000.0", "oops"), *row_20[3:]],
            6: ["not a time", *row_20[1:]],
        },
    )
    raw = read_raw_csv(path, USKIN_GRID, read_displacement=False)
    assert [row for row, _ in raw.bad_rows] == [3, 5, 6]
    assert "4 columns" in raw.bad_rows[0][1]
    assert "force matrix" in raw.bad_rows[1][1]
    assert "time" in raw.bad_rows[2][1]
    assert raw.total_rows == rec["force_n"].size
    assert raw.rows.size == rec["force_n"].size - 3
    assert 5 not in raw.rows.tolist()
    # row 200 is inside the press: values exactly as written, time 10 ms per row since row 0
    i = int(np.nonzero(raw.rows == 200)[0][0])
    np.testing.assert_array_equal(raw.force[i], rec["matrices"][200])
    np.testing.assert_array_equal(raw.ft[i], rec["ft"][200])
    assert raw.time_s[i] == pytest.approx(2.0)
    assert raw.seq[i] == 1200


def test_matrices_of_the_other_sensor_are_refused(tmp_path: Path) -> None:
    path = tmp_path / "hexagonal_PLA" / "papillarray" / "sensor_data_20250203_154424.csv"
    write_raw_csv(path, "uskin", [Press(0.0)])  # a uSkin file filed under papillarray
    with pytest.raises(DataError, match=r"shape \(4, 6, 3\)"):
        read_raw_csv(path, (3, 3), read_displacement=True)
