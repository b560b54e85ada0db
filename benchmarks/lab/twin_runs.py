"""What the scripts that run ``unitac-rig collect`` against the real-time twin share (fault_matrix.py,
control_loop_load.py): the command line, and the loaded host issue 37 names ("two busy processes per core plus a
writer doing fsync")."""

from __future__ import annotations

import os
import subprocess
import sys
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path

_FSYNC_WRITER = """
import os, sys
block = os.urandom(1 << 20)
with open(sys.argv[1], "wb") as fh:
    while True:
        for _ in range(64):
            fh.write(block); fh.flush(); os.fsync(fh.fileno())
        fh.seek(0); fh.truncate()
"""


def collect_command(
    rig_file: Path, data: Path, object_id: str, angles: int, *extra: str, prefix: Sequence[str] = ()
) -> list[str]:
    """``unitac-rig collect --rig RIG_FILE`` in a process of its own, with no live view; ``prefix`` runs it under
    another command (e.g. ``chrt -f 5``)."""
    return [
        *prefix,
        *(sys.executable, "-m", "unitac_rig", "collect", "--rig", str(rig_file), "--object", object_id),
        *("--angles", str(angles), "--data", str(data), "--no-live", *extra),
    ]


@contextmanager
def host_load(scratch: Path, busy_per_cpu: int = 2) -> Iterator[int]:
    """``busy_per_cpu`` busy processes per CPU and one writing 1 MiB blocks to ``scratch`` with an fsync after each,
    until the block ends (all killed then); yields how many processes."""
    busy = [sys.executable, "-c", "while True: pass"]
    procs = [subprocess.Popen(busy) for _ in range(busy_per_cpu * (os.cpu_count() or 1))]
    procs.append(subprocess.Popen([sys.executable, "-c", _FSYNC_WRITER, str(scratch / "fsync.bin")]))
    try:
        yield len(procs)
    finally:
        for proc in procs:
            proc.kill()
        for proc in procs:
            proc.wait()
