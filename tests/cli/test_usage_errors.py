"""Usage errors through the real console script, as a fresh install runs it: one line on stderr, exit 2, no
traceback (and a traceback with --debug)."""

from __future__ import annotations

import sys

import pytest

from tests.helpers import run_console


@pytest.mark.parametrize(
    ("args", "expected"),
    [
        (["collect", "--objct", "hex_tpu"], "No such option: --objct"),
        (["no-such-command"], "No such command 'no-such-command'"),
        (["collect"], "Missing option '--object'"),
        (["train", "--epochs", "many"], "Invalid value for '--epochs'"),
    ],
)
def test_usage_error_is_one_line_and_exit_2(args: list[str], expected: str) -> None:
    result = run_console(*args)
    assert result.returncode == 2, result.stderr
    lines = [line for line in result.stderr.splitlines() if line.strip()]
    assert len(lines) == 1, result.stderr
    assert lines[0].startswith("error: ")
    assert expected in lines[0]
    assert "Traceback" not in result.stderr
    assert result.stdout == ""


def test_debug_shows_the_traceback_of_a_usage_error() -> None:
    result = run_console("--debug", "collect", "--objct", "hex_tpu")
    assert result.returncode != 0
    assert "Traceback" in result.stderr


def test_help_still_exits_0() -> None:
    result = run_console("--help")
    assert result.returncode == 0
    assert "collect" in result.stdout


def test_a_logged_exception_is_one_line_without_debug_and_a_traceback_with_it() -> None:
    """Library code logs a failed retract with log.exception; the terminal shows its message, not a traceback,
    unless --debug asks for one."""
    import logging

    from unitac_rig.cli.app import LOG_FORMAT, _LogLine

    try:
        raise ValueError("the wrist felt 14.2 N during a transit move")
    except ValueError:
        exc_info = sys.exc_info()
    record = logging.LogRecord(
        "unitac_rig.collection.session",
        logging.ERROR,
        __file__,
        1,
        "retracting after press %s failed",
        ("rot000_ang-45",),
        exc_info,
    )
    line = _LogLine().format(record)
    assert line == (
        "ERROR unitac_rig.collection.session: retracting after press rot000_ang-45 failed "
        "(the wrist felt 14.2 N during a transit move)"
    )
    assert "Traceback" in logging.Formatter(LOG_FORMAT).format(record)
