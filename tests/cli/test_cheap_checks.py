"""The tables the CLI checks arguments against before it imports torch are the library's own."""

from __future__ import annotations

from unitac_rig.cli import learn
from unitac_rig.learning.run import CHECKPOINT_NAME


def test_the_cli_checks_against_the_library_tables() -> None:
    assert learn.RUN_MARKER == CHECKPOINT_NAME
