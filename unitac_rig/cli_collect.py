"""Placeholder: commands for this area are added by its own work item."""

import typer


def register(app: typer.Typer) -> None:
    """Add this area's commands to the root app."""
