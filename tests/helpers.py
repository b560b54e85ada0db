"""Helpers every test folder may use (import them as ``tests.helpers``)."""

from __future__ import annotations

import shutil
import sys
from pathlib import Path

import pytest

from unitac_rig.cli import main


def cli(args: list[str]) -> int:
    """Exit status of ``unitac-rig ARGS`` run in-process (main returns on success, exits otherwise)."""
    try:
        main(args)
    except SystemExit as exc:
        return int(exc.code or 0)
    return 0


def console_script() -> str:
    """The installed ``unitac-rig`` entry point of the interpreter running the tests (what a user types)."""
    beside = Path(sys.executable).parent / "unitac-rig"
    found = str(beside) if beside.exists() else shutil.which("unitac-rig")
    if found is None:
        pytest.fail("the unitac-rig console script is not installed (pip install -e .)")
    return found
