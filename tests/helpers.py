"""Helpers every test folder may use (import them as ``tests.helpers``).

A test runs the CLI one of two ways: :func:`cli` in-process (fast; the output through pytest's ``capsys``), or the
installed console script in a child process, what a user types (:func:`run_console`, or :func:`start_console` for a
test that signals or kills it), in :func:`console_env`."""

from __future__ import annotations

import os
import shutil
import subprocess
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


def console_env(**extra: str) -> dict[str, str]:
    """The environment of the console script in a test: 80 columns and no colour so the text is stable, output
    unbuffered so a test can wait for a line; ``extra`` adds to it."""
    return {**os.environ, "COLUMNS": "80", "NO_COLOR": "1", "PYTHONUNBUFFERED": "1", **extra}


def run_console(
    *args: str, cwd: Path | None = None, env: dict[str, str] | None = None, timeout: float = 600
) -> subprocess.CompletedProcess[str]:
    """``unitac-rig ARGS`` through the console script, stdout and stderr captured (pipes, not a terminal, as in a
    log or CI), in :func:`console_env` (``env`` adds to it)."""
    return subprocess.run(
        [console_script(), *args],
        capture_output=True,
        text=True,
        timeout=timeout,
        env=console_env(**(env or {})),
        cwd=cwd,
        check=False,
    )


def start_console(*args: str) -> subprocess.Popen[str]:
    """``unitac-rig ARGS`` started through the console script with its output on pipes, for a test that signals it."""
    command = [console_script(), *args]
    return subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=console_env())
