"""The simulators' child processes (the RTDE server, the controller twin): how a parent stops one."""

from __future__ import annotations

import contextlib
import logging
import subprocess
from typing import Any

logger = logging.getLogger(__name__)


def stop_child(process: subprocess.Popen[Any], what: str, timeout_s: float = 5.0) -> None:
    """Close the child's stdin (EOF is its signal to stop), wait up to ``timeout_s`` (s) for it, kill it if it does
    not stop, and close its stdout. ``what`` names it in the warning."""
    if process.stdin is not None:
        with contextlib.suppress(OSError):
            process.stdin.close()
    try:
        process.wait(timeout=timeout_s)
    except subprocess.TimeoutExpired:  # pragma: no cover - the children poll stdin at least every 50 ms
        logger.warning("%s process did not stop; killing it", what)
        process.kill()
        process.wait(timeout=timeout_s)
    if process.stdout is not None:
        process.stdout.close()
