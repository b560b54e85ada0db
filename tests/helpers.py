"""Helpers every test folder may use (import them as ``tests.helpers``)."""

from __future__ import annotations

from unitac_rig.cli import main


def cli(args: list[str]) -> int:
    """Exit status of ``unitac-rig ARGS`` run in-process (main returns on success, exits otherwise)."""
    try:
        main(args)
    except SystemExit as exc:
        return int(exc.code or 0)
    return 0
