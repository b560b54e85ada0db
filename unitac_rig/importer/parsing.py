"""Reading the UniTac-NV files: raw session CSVs (columns by position: docs/import.md, "Their formats") and the
authors' processed ``.npz`` files.

Parsing is vectorised: a whole column is joined into one string and read by numpy in one call. Rows whose field
counts, bracket structure or numbers are wrong are dropped and reported by data-row number (0 = first row after the
header), never guessed.
"""

from __future__ import annotations

import csv
import hashlib
import json
import warnings
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from unitac_rig.errors import DataError

RAW_COLUMNS = 6
_TO_SPACES = str.maketrans("[](),", "     ")


@dataclass
class RawColumns:
    """A raw CSV read into numbers, before any convention is applied."""

    rows: np.ndarray  # (N,) data-row numbers (0 = first row after the header)
    time_s: np.ndarray  # (N,) seconds since the first good row
    seq: np.ndarray  # (N,) int64
    force: np.ndarray  # (N, rows, cols, 3) their units
    displacement: np.ndarray | None  # (N, rows, cols, 3) or None when not read
    ft: np.ndarray  # (N, 6)
    pose: np.ndarray  # (N, 6)
    bad_rows: list[tuple[int, str]] = field(default_factory=list)  # (data row, reason)
    total_rows: int = 0


def file_sha256(path: Path) -> str:
    """Hex SHA-256 of a file's bytes (what makes a re-import recognise a file it already has)."""
    digest = hashlib.sha256()
    with open(path, "rb") as fh:
        for chunk in iter(lambda: fh.read(1 << 20), b""):
            digest.update(chunk)
    return digest.hexdigest()


def _bracket_count(grid: tuple[int, ...]) -> int:
    """Opening brackets in a Python repr of a nested list of this shape (``(4, 6, 3)`` -> 1 + 4 + 24)."""
    total, level = 0, 1
    for size in grid:
        total += level
        level *= size
    return total


def _numbers(text: str) -> np.ndarray | None:
    """Every number in ``text`` (brackets, parentheses and commas separate them); None when a token is not one."""
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            return np.fromstring(text.translate(_TO_SPACES), sep=" ")
    except (ValueError, DeprecationWarning):
        return None


def parse_number_column(
    cells: list[str], shape: tuple[int, ...], check_brackets: bool = True
) -> tuple[np.ndarray, np.ndarray]:
    """Parse stringified (nested) lists of one shape, vectorised.

    Returns ``(values, ok)``: values has shape ``(len(cells), *shape)`` (NaN rows where ``ok`` is False). A row is
    bad when its number of values differs, when (``check_brackets``) its bracket nesting does not fit ``shape``, or
    when a token is not a number. Rows that pass the cheap comma/bracket checks are parsed in one numpy call; only
    when that call fails (and for rows written without commas) are rows parsed one by one.
    """
    per_row = int(np.prod(shape))
    n = len(cells)
    out = np.full((n, per_row), np.nan)
    ok = np.zeros(n, bool)
    brackets = _bracket_count(shape)
    commas = np.fromiter((c.count(",") for c in cells), dtype=np.int64, count=n)
    opens = np.fromiter((c.count("[") for c in cells), dtype=np.int64, count=n)
    nested = opens == brackets if check_brackets else np.ones(n, bool)
    fast = (commas == per_row - 1) & nested
    fast_idx = np.nonzero(fast)[0]
    one_by_one = np.nonzero(~fast & nested)[0]
    if fast_idx.size:
        values = _numbers(" ".join(cells[i] for i in fast_idx))
        if values is not None and values.size == fast_idx.size * per_row:
            out[fast_idx] = values.reshape(-1, per_row)
            ok[fast_idx] = True
        else:  # some token is not a number: find the rows one by one
            one_by_one = np.concatenate([fast_idx, one_by_one])
    for i in one_by_one:
        parsed = _numbers(cells[i])
        if parsed is not None and parsed.size == per_row:
            out[i] = parsed
            ok[i] = True
    return out.reshape(n, *shape), ok


def _parse_cells(
    cells: list[str], all_at_once: Callable[[list[str]], np.ndarray], one: Callable[[str], int]
) -> tuple[np.ndarray, np.ndarray]:
    """Cells -> (int64 values, ok mask): all in one numpy call, one by one only when that fails."""
    out = np.zeros(len(cells), np.int64)
    ok = np.ones(len(cells), bool)
    try:
        out[:] = all_at_once(cells) if cells else out
    except ValueError:
        for i, cell in enumerate(cells):
            try:
                out[i] = one(cell.strip())
            except ValueError:
                ok[i] = False
    return out, ok


def parse_times(cells: list[str]) -> tuple[np.ndarray, np.ndarray]:
    """Time strings (``%Y-%m-%d %H:%M:%S.%f``) -> (microseconds since the epoch as int64, ok mask)."""
    return _parse_cells(
        cells,
        lambda c: np.array(c, dtype="datetime64[us]").astype(np.int64),
        lambda c: int(np.datetime64(c, "us").astype(np.int64)),
    )


def parse_ints(cells: list[str]) -> tuple[np.ndarray, np.ndarray]:
    return _parse_cells(cells, lambda c: np.array(c).astype(np.int64), int)


def _nested_shape(text: str) -> tuple[int, ...] | None:
    try:
        value = json.loads(text)
    except json.JSONDecodeError:
        return None
    try:
        return tuple(np.shape(np.asarray(value, dtype=np.float64)))
    except ValueError:
        return None


def read_raw_csv(path: Path, grid: tuple[int, int], read_displacement: bool) -> RawColumns:
    """Read one raw UniTac-NV session CSV (see the module docstring).

    ``grid`` is the sensor's ``(rows, cols)``; a file whose matrices have another shape is refused with a DataError.
    """
    path = Path(path)
    columns: list[list[str]] = [[] for _ in range(RAW_COLUMNS)]  # time, seq, force, displacement, F/T, pose
    bad_rows: list[tuple[int, str]] = []
    row_numbers: list[int] = []
    total_rows = 0
    try:
        with open(path, newline="", encoding="utf-8-sig") as fh:
            reader = csv.reader(fh)
            if next(reader, None) is None:
                raise DataError(f"{path} is empty", hint="is this a UniTac-NV session CSV?")
            for number, row in enumerate(reader):
                total_rows += 1 if row else 0
                if len(row) < RAW_COLUMNS:
                    if row:  # blank lines (e.g. a trailing newline) are not data
                        bad_rows.append((number, f"{len(row)} columns, expected {RAW_COLUMNS}"))
                    continue
                row_numbers.append(number)
                for column, cell in zip(columns, row, strict=False):
                    column.append(cell)
    except (OSError, UnicodeDecodeError, csv.Error) as exc:
        raise DataError(f"cannot read {path}: {exc}", hint="check the file is a complete UniTac-NV CSV") from exc
    time_cells, seq_cells, force_cells, disp_cells, ft_cells, pose_cells = columns

    matrix_shape = (grid[0], grid[1], 3)
    if force_cells:
        first_shape = _nested_shape(force_cells[0])
        if first_shape is not None and first_shape != matrix_shape:
            raise DataError(
                f"{path.name}: force matrices have shape {first_shape}, this sensor's are {matrix_shape}",
                hint="check the file sits under the right sensor folder (xela / papillarray)",
            )
    micros, ok_t = parse_times(time_cells)
    seq, ok_s = parse_ints(seq_cells)
    force, ok_f = parse_number_column(force_cells, matrix_shape)
    ft, ok_ft = parse_number_column(ft_cells, (6,), check_brackets=False)
    pose, ok_p = parse_number_column(pose_cells, (6,), check_brackets=False)
    checks = {"time": ok_t, "sequence": ok_s, "force matrix": ok_f, "F/T": ok_ft, "pose": ok_p}
    displacement = None
    if read_displacement:
        displacement, checks["displacement matrix"] = parse_number_column(disp_cells, matrix_shape)
    ok = np.logical_and.reduce(list(checks.values()))
    numbers = np.asarray(row_numbers, np.int64)
    for i in np.nonzero(~ok)[0]:
        bad_rows.append((int(numbers[i]), "unparsable " + ", ".join(k for k, good in checks.items() if not good[i])))
    bad_rows.sort()
    kept_micros = micros[ok]
    time_s = (kept_micros - kept_micros[0]) / 1e6 if kept_micros.size else np.zeros(0)
    return RawColumns(
        rows=numbers[ok],
        time_s=time_s.astype(np.float64),
        seq=seq[ok],
        force=force[ok],
        displacement=displacement[ok] if displacement is not None else None,
        ft=ft[ok],
        pose=pose[ok],
        bad_rows=bad_rows,
        total_rows=total_rows,
    )


# ---------------------------------------------------------------------------------------------------------------------
# processed .npz files

PROCESSED_KEYS = (
    "times",
    "sensor_matrices_force",
    "sensor_matrices_displacement",
    "ft_values",
    "end_effector_poses",
    "selected",
    "angle",
)


@dataclass
class ProcessedArrays:
    """One processed ``.npz`` as the authors wrote it (baseline subtracted, F/T rotated, PapillArray flipped)."""

    time_s: np.ndarray  # (N,) seconds since their first kept row
    force: np.ndarray  # (N, rows, cols, 3)
    displacement: np.ndarray  # (N, rows, cols, 3)
    ft: np.ndarray  # (N, 6)
    pose: np.ndarray  # (N, 6)
    selected: np.ndarray  # (P,) int64 indices of each press's peak
    angle: np.ndarray  # (P,) int64 degrees


def read_processed_npz(path: Path, grid: tuple[int, int]) -> ProcessedArrays:
    """Read and check one processed file; refuse files that cannot carry force-matched extraction."""
    path = Path(path)
    try:
        with np.load(path, allow_pickle=False) as npz:
            missing = [k for k in PROCESSED_KEYS if k not in npz.files]
            if missing:
                raise DataError(
                    f"{path.name} lacks {', '.join(missing)}",
                    hint="is this a file from 'UniTac-NV Dataset Processed'?",
                )
            arrays = {k: np.asarray(npz[k]) for k in PROCESSED_KEYS}
    except (OSError, ValueError) as exc:
        raise DataError(f"cannot read {path}: {exc}", hint="check the .npz file is complete") from exc
    n = arrays["times"].shape[0]
    shape = (n, grid[0], grid[1], 3)
    checks = {
        "sensor_matrices_force": shape,
        "sensor_matrices_displacement": shape,
        "ft_values": (n, 6),
        "end_effector_poses": (n, 6),
    }
    for key, expected in checks.items():
        if arrays[key].shape != expected:
            raise DataError(
                f"{path.name}: {key} has shape {arrays[key].shape}, expected {expected}",
                hint="check the file sits in the folder of its sensor (Xela / PapillArray)",
            )
    selected = arrays["selected"].astype(np.int64).ravel()
    if n and n == selected.size:
        raise DataError(
            f"{path.name} holds only the {n} peak samples (one per press), not the presses' loading ramps; "
            "force-matched extraction at 4..10 N cannot be done from a single frame per press",
            hint="import the raw session CSVs from 'UniTac-NV Dataset' instead",
        )
    if selected.size and (selected.min() < 0 or selected.max() >= n):
        raise DataError(f"{path.name}: 'selected' indexes outside its {n} samples")
    return ProcessedArrays(
        time_s=arrays["times"].astype(np.float64),
        force=arrays["sensor_matrices_force"].astype(np.float64),
        displacement=arrays["sensor_matrices_displacement"].astype(np.float64),
        ft=arrays["ft_values"].astype(np.float64),
        pose=arrays["end_effector_poses"].astype(np.float64),
        selected=selected,
        angle=arrays["angle"].astype(np.int64).ravel(),
    )
