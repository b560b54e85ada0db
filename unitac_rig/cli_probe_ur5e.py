"""Placeholder for ``probe ur5e``: the UR5e work item replaces this file with the real command."""

import typer


def register_ur5e(probe_app: typer.Typer) -> None:
    """Add ``probe ur5e`` to the probe sub-app (nothing yet)."""
