"""A training run on disk: ``RUN/checkpoint.pt`` (everything needed to resume, evaluate or translate), the test rows
in ``RUN/test_set.npz``, plus human-readable ``config.json``, ``metrics.json``, ``report.md`` and ``figures/*.png``.

The checkpoint holds the model configuration, every member's parameters, the optimizer state and random streams,
the normalisation statistics, the split, the dataset's content hash, the per-epoch history, and provenance
(package version, git commit, torch version). It is written atomically (temporary file, then rename).
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path
from typing import Any

import numpy as np
import torch

from unitac_rig.errors import ModelError, UsageError
from unitac_rig.learning.data import PairedDataset
from unitac_rig.provenance import git_commit, package_version

CHECKPOINT_NAME = "checkpoint.pt"
TEST_SET_NAME = "test_set.npz"
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


def _test_subset_path(run_dir: Path) -> Path:
    return Path(run_dir) / TEST_SET_NAME


def save_test_set(run_dir: Path, test: PairedDataset) -> None:
    """The test rows (every sensor's frames and the keys), so evaluation, reports and geometry need no --data."""
    arrays: dict[str, np.ndarray] = {
        "sensors": np.array(test.sensors, dtype=str),
        "object_id": test.object_id.astype(str),
        "rotation_deg": test.rotation_deg,
        "angle_deg": test.angle_deg,
        "target_n": test.target_n,
        "simulated": np.array(test.simulated),
    }
    for sensor in test.sensors:
        arrays[f"values__{sensor}"] = test.values[sensor]
        arrays[f"force_n__{sensor}"] = test.force_n[sensor]
    tmp = Path(run_dir) / (TEST_SET_NAME + ".tmp.npz")
    np.savez_compressed(tmp, **arrays)  # type: ignore[arg-type]
    os.replace(tmp, _test_subset_path(run_dir))


def load_test_set(run_dir: Path) -> PairedDataset:
    path = _test_subset_path(run_dir)
    if not path.is_file():
        raise UsageError(f"{run_dir} has no {TEST_SET_NAME}", hint="it is written by `unitac-rig train`; retrain")
    with np.load(path, allow_pickle=False) as data:
        sensors = tuple(str(s) for s in data["sensors"])
        return PairedDataset(
            sensors=sensors,
            object_id=data["object_id"].astype(str),
            rotation_deg=data["rotation_deg"],
            angle_deg=data["angle_deg"],
            target_n=data["target_n"],
            values={s: data[f"values__{s}"] for s in sensors},
            force_n={s: data[f"force_n__{s}"] for s in sensors},
            simulated=bool(data["simulated"]),
        )
