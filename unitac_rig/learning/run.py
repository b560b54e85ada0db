"""A training run on disk: ``RUN/checkpoint.pt`` (everything needed to resume, evaluate or translate) plus
human-readable ``config.json``, ``metrics.json``, ``report.md`` and ``figures/*.png``.

The checkpoint holds the model configuration, every member's parameters, the optimizer state and random streams,
the normalisation statistics, the split, the dataset's content hash, the per-epoch history, and provenance
(package version, git commit, torch version). It is written atomically (temporary file, then rename).
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path
from typing import Any

import torch

from unitac_rig.errors import ModelError, UsageError
from unitac_rig.provenance import git_commit, package_version

CHECKPOINT_NAME = "checkpoint.pt"
CHECKPOINT_FORMAT = "unitac-rig/unitac-nv-run"
CHECKPOINT_VERSION = 2  # 2: one tensor per layer (autograd engine); 1: one flat parameter vector, still read


def checkpoint_path(run_dir: Path) -> Path:
    return Path(run_dir) / CHECKPOINT_NAME


def save_checkpoint(run_dir: Path, payload: dict[str, Any]) -> Path:
    """Write ``payload`` as the run's checkpoint, atomically."""
    run_dir = Path(run_dir)
    run_dir.mkdir(parents=True, exist_ok=True)
    payload = {"format": CHECKPOINT_FORMAT, "version": CHECKPOINT_VERSION, **payload}
    target = checkpoint_path(run_dir)
    fd, tmp_name = tempfile.mkstemp(prefix=".checkpoint-", suffix=".tmp", dir=run_dir)
    try:
        with os.fdopen(fd, "wb") as handle:
            torch.save(payload, handle)
            handle.flush()
            os.fsync(handle.fileno())
        os.replace(tmp_name, target)
    except BaseException:
        Path(tmp_name).unlink(missing_ok=True)
        raise
    return target


def load_checkpoint(run_dir: Path) -> dict[str, Any]:
    """The run's checkpoint; UsageError when ``run_dir`` is not a run, ModelError when the file is not ours."""
    path = checkpoint_path(run_dir)
    if not Path(run_dir).is_dir():
        raise UsageError(f"{run_dir} does not exist", hint="pass the --out folder of `unitac-rig train`")
    if not path.is_file():
        raise UsageError(f"{run_dir} is not a training run (no {CHECKPOINT_NAME})", hint="run `unitac-rig train` first")
    try:
        payload = torch.load(path, map_location="cpu", weights_only=False)
    except Exception as exc:  # torch raises several unrelated types for a damaged or foreign file
        raise ModelError(f"{path} cannot be read ({exc})", hint="retrain, or restore the file from a backup") from exc
    if not isinstance(payload, dict) or payload.get("format") != CHECKPOINT_FORMAT:
        raise ModelError(f"{path} is not a unitac-rig UniTac-NV checkpoint")
    if int(payload.get("version", -1)) > CHECKPOINT_VERSION:
        raise ModelError(
            f"{path} was written by a newer unitac-rig (checkpoint version {payload['version']})",
            hint="upgrade unitac-rig",
        )
    return payload


def provenance() -> dict[str, str]:
    """Package version, git commit (or "unknown") and torch version, for checkpoints and reports."""
    return {"package_version": package_version(), "git_commit": git_commit(), "torch_version": str(torch.__version__)}
