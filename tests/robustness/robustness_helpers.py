"""Shared helpers for the robustness tests: run the CLI and read its one-line errors, hash a dataset directory."""

from __future__ import annotations

import hashlib
from pathlib import Path

import pytest

from unitac_rig.rig.config import parse_rig_config
from unitac_rig.storage.lease import LEASE_NAME
from unitac_rig.storage.reader import TRUST_NAME

FEW_ANGLES = {"press": {"angle_count": 3}}


def few_angles(count: int = 3, **sections: dict[str, object]):  # type: ignore[no-untyped-def]
    """A simulated-rig config with ``count`` approach angles and any other sections merged in."""
    data: dict[str, object] = {"press": {"angle_count": count}}
    for key, value in sections.items():
        merged = dict(data.get(key, {}))  # type: ignore[call-overload]
        merged.update(value)
        data[key] = merged
    return parse_rig_config(data)


def one_error_line(capsys: pytest.CaptureFixture[str]) -> str:
    """The captured stderr, asserted to be exactly one line starting with ``error:`` (no traceback)."""
    err = capsys.readouterr().err
    lines = [line for line in err.splitlines() if line.strip()]
    assert len(lines) == 1, f"expected one line on stderr, got:\n{err}"
    assert lines[0].startswith("error: "), lines[0]
    assert "Traceback" not in err
    return lines[0]


def tree_hashes(root: Path) -> dict[str, str]:
    """sha256 of every recorded file under ``root`` (relative path -> digest): proves a failed command touched nothing.

    The writer lease (``.journal/*/_writer.lock``) is skipped: it is a lock, not data, and any command that opens a
    session for writing takes it (and notes its pid there) before it can fail.
    """
    return {
        str(path.relative_to(root)): hashlib.sha256(path.read_bytes()).hexdigest()
        for path in sorted(root.rglob("*"))
        if path.is_file() and path.name not in (LEASE_NAME, TRUST_NAME)  # the lease, the readers' cache: no data
    }


def write_synthetic_sessions(data_dir: Path, objects: tuple[str, ...] = ("circle_pla", "irregular_pla")) -> None:
    """Session files (through the real recorder) holding synthetic contacts of both sensors: enough to train on.

    Each press is a 5 N/s ramp at 500 Hz with one tactile frame at each target's crossing (the learning tests'
    :func:`~tests.learning.learning_helpers.write_sessions`, at 11 angles and 4 targets).
    """
    from drivers.layouts import PAPILLARRAY, USKIN
    from tests.learning.learning_helpers import write_sessions
    from unitac_rig.learning.synthetic_data import synthetic_matched_sets

    angles = tuple(float(a) for a in range(-45, 46, 9))
    sets = synthetic_matched_sets(objects, (USKIN, PAPILLARRAY), angles_deg=angles, targets_n=(4.0, 6.0, 8.0, 10.0))
    write_sessions(data_dir, sets)
