"""The ``unitac-rig`` command line: one module per command group, registered by :mod:`unitac_rig.cli.app`."""

from unitac_rig.cli.app import app, main

__all__ = ["app", "main"]
