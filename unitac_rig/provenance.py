"""Where a result came from: the package version and the git commit, stored in every session file, checkpoint and
report."""

from __future__ import annotations

import subprocess
from functools import lru_cache
from pathlib import Path

import unitac_rig


@lru_cache(maxsize=1)
def git_commit() -> str:
    """The project's git commit, or "unknown" outside a checkout (an installed wheel, no git)."""
    try:
        out = subprocess.run(
            ["git", "rev-parse", "HEAD"],
            cwd=Path(unitac_rig.__file__).resolve().parent.parent,
            capture_output=True,
            text=True,
            timeout=5,
            check=False,
        )
    except (OSError, subprocess.SubprocessError):
        return "unknown"
    return out.stdout.strip() or "unknown"


def package_version() -> str:
    return unitac_rig.__version__
