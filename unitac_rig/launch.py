"""The ``unitac-rig`` entry point, kept light so that Ctrl-C during start-up is handled like any other.

Importing the application takes ~0.4 s (seconds on a loaded box). A KeyboardInterrupt raised by Python's own handler
inside an importing module ends in a traceback, and one raised inside code run through ``PyRun_String`` by a compiled
extension leaves the interpreter marked as killed by SIGINT, so the process dies with -2 even after the CLI printed
its line and chose 130. Here the handler only notes the Ctrl-C while the application is imported; after the import
it ends the command the usual way: one line, exit 130.
"""

from __future__ import annotations

import signal
import sys
from types import FrameType


def main() -> None:
    """Import the CLI with Ctrl-C noted rather than raised, then run it (see :func:`unitac_rig.cli.app.main`)."""
    noted: list[int] = []

    def note(signal_number: int, frame: FrameType | None) -> None:
        noted.append(signal_number)

    previous = signal.signal(signal.SIGINT, note)
    try:
        from unitac_rig.cli.app import main as run_cli
    finally:
        signal.signal(signal.SIGINT, previous)
    if noted:
        sys.stderr.write("interrupted\n")
        sys.exit(130)
    run_cli()
