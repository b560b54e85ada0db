"""A training run on disk: ``RUN/checkpoint.pt`` (everything needed to resume, evaluate or translate), the test rows
in ``RUN/test_set.npz``, plus human-readable ``config.json``, ``metrics.json``, ``report.md`` and ``figures/*.png``.

The checkpoint holds the model configuration, every member's parameters, the optimizer state and random streams,
the normalisation statistics, the split, the dataset's content hash, the per-epoch history, and provenance
(package version, git commit, torch version). It is written atomically (temporary file, then rename).

Every checkpoint is read with ``torch.load(..., weights_only=True)`` (:func:`safe_torch_load`): unpickling may only
build tensors, plain Python containers and numbers, and plain numeric numpy arrays (version 1 stored a few), so a run
directory from someone else cannot run code on the machine that opens it. A file that needs anything else is refused
with a :class:`ModelError` naming what it holds, before any of it is built.
"""

from __future__ import annotations

import os
import pickle
import re
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
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
TRAINING_PAIRS = "seen_pairs"  # folder in a run: its complete training pairs (the simple baselines, linear maps)
CHECKPOINT_VERSION = 3  # 3: the model's state_dict; 2: one tensor per layer; 1: one flat parameter vector (both read)


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
    payload = safe_torch_load(path, what="checkpoint")
    if not isinstance(payload, dict) or payload.get("format") != CHECKPOINT_FORMAT:
        raise ModelError(
            f"{path} is not a unitac-rig UniTac-NV checkpoint ({describe_foreign(payload)})",
            hint="a run directory is what `unitac-rig train --out RUN` writes; to hand a model over, use "
            "`unitac-rig export-model`",
        )
    version = payload.get("version")
    if not isinstance(version, int) or version < 1:
        raise ModelError(
            f"{path} is a unitac-rig checkpoint of an unknown version ({version!r})",
            hint="retrain with `unitac-rig train`",
        )
    if version > CHECKPOINT_VERSION:
        raise ModelError(
            f"{path} was written by a newer unitac-rig (checkpoint version {version})", hint="upgrade unitac-rig"
        )
    check_finite(payload, path)
    return payload


def _numpy_array_globals() -> list[Any]:
    """What unpickling a plain numeric/bool/str numpy array needs (numpy's documented reconstruct path). An object
    array would still need its elements' classes, which stay forbidden."""
    dtypes = [type(np.dtype(code)) for code in "?bBhHiIlLqQefdgFDGU"]
    return [np._core.multiarray._reconstruct, np.ndarray, np.dtype, *dtypes]  # type: ignore[attr-defined]


@contextmanager
def _allow_numpy_arrays() -> Iterator[None]:
    with torch.serialization.safe_globals(_numpy_array_globals()):
        yield


def safe_torch_load(path: Path, *, what: str) -> Any:
    """``torch.load(path, weights_only=True)`` on the CPU, numeric numpy arrays allowed; a :class:`ModelError` that
    says what the file is and what to do when it holds anything else, is damaged or is not a torch file at all.

    ``what`` names the file in messages ("checkpoint", "geometry estimator").
    """
    path = Path(path)
    try:
        with _allow_numpy_arrays():
            return torch.load(path, map_location="cpu", weights_only=True)
    except pickle.UnpicklingError as exc:
        unsafe = _unsafe_globals(path) or sorted(set(re.findall(r"GLOBAL ([\w.]+)", str(exc))))
        if unsafe:
            listed = ", ".join(unsafe[:4]) + (", ..." if len(unsafe) > 4 else "")
            raise ModelError(
                f"{path} was not loaded: this {what} holds pickled Python objects ({listed}), not only tensors and "
                "plain values, and unpickling them could run code",
                hint="it is an old unitac-rig file (from before checkpoint version 2) or not one of ours: retrain "
                "with this unitac-rig, or ask its author for a fresh run",
            ) from exc
        # never torch's own text here: it advises loading with weights_only=False, i.e. switching the safety off
        raise ModelError(
            f"{path} was not loaded: this {what} holds something other than tensors and plain values, or is damaged",
            hint="retrain with this unitac-rig, or ask its author for a fresh run",
        ) from exc
    except Exception as exc:  # torch raises many unrelated types (IndexError, RuntimeError...) for a damaged file
        raise ModelError(
            f"{path} cannot be read as a {what}: not a PyTorch file or damaged ({_first_line(exc)})",
            hint="retrain, or restore the file from a backup",
        ) from exc


def _unsafe_globals(path: Path) -> list[str]:
    """The classes and functions a file's pickle would import, read from its opcodes (nothing is executed)."""
    try:
        names = torch.serialization.get_unsafe_globals_in_checkpoint(path)
    except Exception:  # a legacy (non-zip) or damaged file: no listing, the caller says so without it
        return []
    allowed = {f"{g.__module__}.{g.__qualname__}" for g in _numpy_array_globals()}
    return sorted(n for n in names if n not in allowed)


def _first_line(exc: BaseException) -> str:
    """The first line of an error, without torch's advice to reload with ``weights_only=False``."""
    text = str(exc).strip().splitlines()
    first = text[0][:200] if text else type(exc).__name__
    if "weights_only" in str(exc) or "Weights only" in first:
        return type(exc).__name__
    return first


def check_finite(payload: dict[str, Any], path: Path) -> None:
    """ModelError unless every parameter and normalisation statistic of a checkpoint is a finite number: a NaN
    weight turns every translation into NaN (a diverged run, or a damaged file)."""

    def walk(value: Any, where: str) -> None:
        if isinstance(value, torch.Tensor):
            bad = value.is_floating_point() and not bool(torch.isfinite(value).all())
        elif isinstance(value, np.ndarray):
            bad = value.dtype.kind == "f" and not bool(np.isfinite(value).all())
        elif isinstance(value, float):
            bad = not np.isfinite(value)
        elif isinstance(value, dict):
            for key, item in value.items():
                walk(item, f"{where}.{key}")
            return
        elif isinstance(value, list | tuple):
            for i, item in enumerate(value):
                walk(item, f"{where}[{i}]")
            return
        else:
            return
        if bad:
            raise ModelError(
                f"{path} holds NaN or infinite values in {where.lstrip('.')}: its model cannot be used",
                hint="the run diverged or the file is damaged: retrain (or restore the file from a backup)",
            )

    engine = payload.get("engine")
    if isinstance(engine, dict):
        walk({k: engine[k] for k in ("state_dict", "parameters", "theta") if k in engine}, "engine")
    walk(payload.get("normaliser"), "normaliser")


def describe_foreign(payload: Any) -> str:
    """A few words on what a file that is not our checkpoint holds, for the error message."""
    if isinstance(payload, dict):
        if payload and all(isinstance(v, torch.Tensor) for v in payload.values()):
            return f"a plain PyTorch state dict of {len(payload)} tensors"
        keys = ", ".join(sorted(str(k) for k in payload)[:6])
        return f"a dict with keys {keys}" if keys else "an empty dict"
    return f"a {type(payload).__name__}"


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


def save_training_pairs(run_dir: Path, train: PairedDataset) -> None:
    """The run's training contacts that have every sensor's frame (``RUN/seen_pairs/``): what the simple baselines
    and the geometry study's linear maps fit on, so they see exactly the rows the model trained on."""
    folder = Path(run_dir) / TRAINING_PAIRS
    folder.mkdir(parents=True, exist_ok=True)
    save_test_set(folder, train.subset(train.complete_rows()))


def load_training_pairs(run_dir: Path) -> PairedDataset | None:
    """The pairs :func:`save_training_pairs` kept; None for a run from before they were kept."""
    folder = Path(run_dir) / TRAINING_PAIRS
    return load_test_set(folder) if _test_subset_path(folder).is_file() else None


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
