"""Shared helpers for the robustness tests: run the CLI and read its one-line errors, hash a dataset directory."""

from __future__ import annotations

import hashlib
from pathlib import Path

import pytest

from unitac_rig.cli import main
from unitac_rig.config import parse_rig_config

FEW_ANGLES = {"press": {"angle_count": 3}}


def few_angles(count: int = 3, **sections: dict[str, object]):  # type: ignore[no-untyped-def]
    """A simulated-rig config with ``count`` approach angles and any other sections merged in."""
    data: dict[str, object] = {"press": {"angle_count": count}}
    for key, value in sections.items():
        merged = dict(data.get(key, {}))  # type: ignore[call-overload]
        merged.update(value)
        data[key] = merged
    return parse_rig_config(data)


def cli(args: list[str]) -> int:
    """Exit status of ``unitac-rig ARGS`` run in-process (main returns on success, exits otherwise)."""
    try:
        main(args)
    except SystemExit as exc:
        return int(exc.code or 0)
    return 0


def one_error_line(capsys: pytest.CaptureFixture[str]) -> str:
    """The captured stderr, asserted to be exactly one line starting with ``error:`` (no traceback)."""
    err = capsys.readouterr().err
    lines = [line for line in err.splitlines() if line.strip()]
    assert len(lines) == 1, f"expected one line on stderr, got:\n{err}"
    assert lines[0].startswith("error: "), lines[0]
    assert "Traceback" not in err
    return lines[0]


def tree_hashes(root: Path) -> dict[str, str]:
    """sha256 of every file under ``root`` (relative path -> digest): proves a failed command touched nothing."""
    return {
        str(path.relative_to(root)): hashlib.sha256(path.read_bytes()).hexdigest()
        for path in sorted(root.rglob("*"))
        if path.is_file()
    }
