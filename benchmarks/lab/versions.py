"""Two versions of the code in one measurement: an older commit checked out beside this one, and a worker process
that imports only the version it is given (what the before/after benchmarks share)."""

from __future__ import annotations

import contextlib
import json
import os
import shutil
import subprocess
import sys
import tempfile
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[2]


@contextlib.contextmanager
def checkout(ref: str) -> Iterator[Path]:
    """A detached ``git worktree`` of ``ref`` in a temporary folder, removed afterwards."""
    folder = Path(tempfile.mkdtemp(prefix="unitac-before-")) / "tree"
    subprocess.run(["git", "-C", str(ROOT), "worktree", "add", "--detach", "-q", str(folder), ref], check=True)
    try:
        yield folder
    finally:
        subprocess.run(["git", "-C", str(ROOT), "worktree", "remove", "--force", str(folder)], check=False)
        shutil.rmtree(folder.parent, ignore_errors=True)


def short_commit(ref: str = "HEAD") -> str:
    """``ref`` as a short commit id of this checkout."""
    done = subprocess.run(["git", "-C", str(ROOT), "rev-parse", "--short", ref], capture_output=True, text=True)
    return done.stdout.strip()


def run_worker(code: Path, argv: Sequence[str], timeout: float | None = None) -> dict[str, Any]:
    """Run ``python ARGV`` in a fresh process that imports the version in ``code`` (first on ``PYTHONPATH``, then
    benchmarks/ for the scripts' shared code) from a neutral folder; the JSON object on its last stdout line."""
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(code), str(ROOT / "benchmarks")])}
    done = subprocess.run(
        [sys.executable, *argv], env=env, cwd=tempfile.gettempdir(), capture_output=True, text=True, timeout=timeout
    )
    if done.returncode != 0:
        raise SystemExit(f"{' '.join(argv[:3])} on {code} failed:\n{done.stderr[-2000:]}")
    result: dict[str, Any] = json.loads(done.stdout.strip().splitlines()[-1])
    return result
