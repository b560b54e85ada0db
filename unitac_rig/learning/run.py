"""A training run on disk: ``RUN/checkpoint.pt`` (everything needed to resume, evaluate or translate), the test rows
in ``RUN/test_set.npz``, the training pairs in ``RUN/seen_pairs/``, plus human-readable ``config.json``,
``config.toml``, ``metrics.json``, ``report.md`` and ``figures/*.png``; and :func:`load_run`, a run read back.

The checkpoint (one format, :data:`CHECKPOINT_VERSION`; any other is refused) holds the model configuration, the
model's ``state_dict``, the optimizer state and random streams, the normalisation statistics, the split, the
dataset's content hash, the per-epoch history, and provenance (package version, git commit, torch version). It and
the text files are written atomically (temporary file, then rename): an interrupted write leaves the old file.

Every checkpoint is read with ``torch.load(..., weights_only=True)`` (:func:`safe_torch_load`): unpickling may only
build tensors and plain Python containers and numbers, so a run directory from someone else cannot run code on the
machine that opens it. A file that needs anything else is refused with a :class:`ModelError` naming what it holds,
before any of it is built.
"""

from __future__ import annotations

import json
import os
import pickle
import re
import tempfile
from collections.abc import Iterator, Mapping, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np
import torch

from unitac_rig.errors import ModelError, UsageError
from unitac_rig.learning.config import TrainConfig
from unitac_rig.learning.data import Normaliser, PairedDataset
from unitac_rig.learning.engine import StackedAutoencoders
from unitac_rig.provenance import git_commit, package_version

CHECKPOINT_NAME = "checkpoint.pt"
TEST_SET_NAME = "test_set.npz"
CHECKPOINT_FORMAT = "unitac-rig/unitac-nv-run"
CHECKPOINT_VERSION = 3  # the model's state_dict; the only version read
TRAINING_PAIRS = "seen_pairs"  # folder in a run: its complete training pairs (the simple baselines, linear maps)
METRICS_JSON = "metrics.json"


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
    if version != CHECKPOINT_VERSION:
        newer = isinstance(version, int) and version > CHECKPOINT_VERSION
        raise ModelError(
            f"{path} is a unitac-rig checkpoint of version {version!r}; this unitac-rig reads version "
            f"{CHECKPOINT_VERSION} only",
            hint="upgrade unitac-rig" if newer else "retrain with `unitac-rig train`",
        )
    check_finite(payload, path)
    return payload


def stored_frame_baseline(run_dir: Path) -> str:
    """The frame baseline the run in ``run_dir`` trained on (what its data is read with to resume it,
    and a session file's frames to feed it); "press" when there is no run there."""
    if not checkpoint_path(run_dir).is_file():
        return "press"
    return TrainConfig.from_dict(load_checkpoint(run_dir)["config"]).frame_baseline


def safe_torch_load(path: Path, *, what: str) -> Any:
    """``torch.load(path, weights_only=True)`` on the CPU; a :class:`ModelError` that
    says what the file is and what to do when it holds anything else, is damaged or is not a torch file at all.

    ``what`` names the file in messages ("checkpoint", "geometry estimator").
    """
    path = Path(path)
    try:
        return torch.load(path, map_location="cpu", weights_only=True)
    except pickle.UnpicklingError as exc:
        unsafe = _unsafe_globals(path) or sorted(set(re.findall(r"GLOBAL ([\w.]+)", str(exc))))
        if unsafe:
            listed = ", ".join(unsafe[:4]) + (", ..." if len(unsafe) > 4 else "")
            raise ModelError(
                f"{path} was not loaded: this {what} holds pickled Python objects ({listed}), not only tensors and "
                "plain values, and unpickling them could run code",
                hint="it is not one of this unitac-rig's files: retrain with this unitac-rig, or ask its author "
                "for a fresh run",
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
        return sorted(torch.serialization.get_unsafe_globals_in_checkpoint(path))
    except Exception:  # a legacy (non-zip) or damaged file: no listing, the caller says so without it
        return []


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
        walk(engine.get("state_dict"), "engine")
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


_CONTACT_KEYS = ("object_id", "rotation_deg", "angle_deg", "target_n")  # a contact's join key, one array each


def save_test_set(run_dir: Path, test: PairedDataset) -> None:
    """The test rows (every sensor's frames and the keys), so evaluation, reports and geometry need no --data."""
    arrays = {"sensors": np.array(test.sensors, dtype=str), "simulated": np.array(test.simulated)}
    arrays["frame_baseline"] = np.array(test.frame_baseline)
    arrays |= {key: getattr(test, key) for key in _CONTACT_KEYS}
    arrays["object_id"] = test.object_id.astype(str)
    for sensor in test.sensors:
        arrays[f"values__{sensor}"] = test.values[sensor]
        arrays[f"force_n__{sensor}"] = test.force_n[sensor]
    tmp = Path(run_dir) / (TEST_SET_NAME + ".tmp.npz")
    np.savez_compressed(tmp, **arrays)  # type: ignore[arg-type]
    os.replace(tmp, Path(run_dir) / TEST_SET_NAME)


def save_training_pairs(run_dir: Path, train: PairedDataset) -> None:
    """The run's training contacts that have every sensor's frame (``RUN/seen_pairs/``): what the simple baselines
    and the geometry study's linear maps fit on, so they see exactly the rows the model trained on."""
    folder = Path(run_dir) / TRAINING_PAIRS
    folder.mkdir(parents=True, exist_ok=True)
    save_test_set(folder, train.subset(train.complete_rows()))


def load_training_pairs(run_dir: Path) -> PairedDataset | None:
    """The pairs :func:`save_training_pairs` kept; None for a run from before they were kept."""
    folder = Path(run_dir) / TRAINING_PAIRS
    return load_test_set(folder) if (folder / TEST_SET_NAME).is_file() else None


def load_test_set(run_dir: Path) -> PairedDataset:
    path = Path(run_dir) / TEST_SET_NAME
    if not path.is_file():
        raise UsageError(f"{run_dir} has no {TEST_SET_NAME}", hint="it is written by `unitac-rig train`; retrain")
    with np.load(path, allow_pickle=False) as data:
        sensors = tuple(str(s) for s in data["sensors"])
        return PairedDataset(
            sensors=sensors,
            **{key: data[key] for key in _CONTACT_KEYS},
            values={s: data[f"values__{s}"] for s in sensors},
            force_n={s: data[f"force_n__{s}"] for s in sensors},
            simulated=bool(data["simulated"]),
            frame_baseline=str(data["frame_baseline"]) if "frame_baseline" in data else "press",  # older runs: press
        )


def save_run_files(run_dir: Path, contents: Mapping[str, str | Mapping[str, Any]]) -> None:
    """Write the run's text files (name -> text, or a mapping written as JSON) together: each beside its file first,
    then each renamed over the old one (microseconds apart), so an interruption (a Ctrl-C during a report's minutes,
    a crash) leaves every one as it was and the run's files in agreement. ``metrics.json`` is written only through it,
    by :func:`unitac_rig.learning.report.write_report`."""
    staged: list[tuple[Path, Path]] = []
    try:
        for name, content in contents.items():
            final = Path(run_dir) / name
            tmp = final.with_name(f".{final.name}.{os.getpid()}.tmp")
            staged.append((tmp, final))
            text = content if isinstance(content, str) else json.dumps(content, indent=2) + "\n"
            tmp.write_text(text, encoding="utf-8")
        for tmp, final in staged:
            os.replace(tmp, final)
    finally:
        for tmp, _ in staged:
            tmp.unlink(missing_ok=True)  # only when a write failed or was interrupted


def write_config_json(
    run_dir: Path,
    config: Mapping[str, Any],
    split: Mapping[str, Any],
    sensors: Sequence[str],
    dataset_hash: str,
    **extra: Any,
) -> None:
    """``RUN/config.json``, for people: what the run trained with, on which data, and by which unitac-rig."""
    readable = {"config": config, "split": split, "sensors": list(sensors), "dataset_hash": dataset_hash, **extra}
    text = json.dumps(readable | {"provenance": provenance()}, indent=2) + "\n"
    (Path(run_dir) / "config.json").write_text(text, encoding="utf-8")


def read_metrics(run_dir: Path) -> dict[str, Any] | None:
    """The run's ``metrics.json``; None before a run was scored."""
    path = Path(run_dir) / METRICS_JSON
    return json.loads(path.read_text(encoding="utf-8")) if path.is_file() else None


def tsne_rows(object_ids: np.ndarray, wanted: int, seed: int) -> np.ndarray:
    """Up to ``wanted`` test rows whose latents a run keeps for the t-SNE, the same number from every object (the
    unseen object would swamp a plain random pick: it is most of the test set)."""
    rng = np.random.default_rng([seed, 3])
    objects = sorted(set(object_ids.tolist()))
    per_object = max(1, wanted // max(1, len(objects)))
    picked = []
    for object_id in objects:
        rows = np.flatnonzero(object_ids == object_id)
        picked.append(rng.choice(rows, size=min(per_object, rows.size), replace=False))
    return np.sort(np.concatenate(picked)) if picked else np.zeros(0, dtype=int)


def resolve_device(name: str) -> torch.device:
    """``auto`` -> CUDA when available, else CPU; ``cuda`` without a GPU is a UsageError."""
    if name == "auto":
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    if name == "cuda" and not torch.cuda.is_available():
        raise UsageError("--device cuda asked for, but torch sees no CUDA device", hint="use --device cpu or auto")
    if name not in ("cpu", "cuda"):
        raise UsageError(f"unknown device {name!r}", hint="use auto, cpu or cuda")
    return torch.device(name)


def default_threads() -> int:
    """CPU threads for training: one. The matrices are tiny (64 x 99), so a second OpenMP thread costs more in
    synchronisation than it saves, and on a shared 2-core box it can be many times slower (benchmarks/)."""
    return 1


@contextmanager
def computing_on(device: str, threads: int | None = None) -> Iterator[torch.device]:
    """The torch device ``device`` names (:func:`resolve_device`), with ``threads`` CPU threads (default:
    :func:`default_threads`) for the block when it is the CPU; torch's thread count is restored after."""
    torch_device = resolve_device(device)
    previous_threads = torch.get_num_threads()
    if torch_device.type == "cpu":
        torch.set_num_threads(threads or default_threads())
    try:
        yield torch_device
    finally:
        torch.set_num_threads(previous_threads)


def readable(payload: dict[str, Any]) -> dict[str, Any]:
    """The checkpoint with its stored tensors of rows and latents as numpy arrays."""
    out = dict(payload)
    out["test_mask"] = payload["test_mask"].numpy()
    if payload.get("val_mask") is not None:
        out["val_mask"] = payload["val_mask"].numpy()
    out["tsne_rows"] = payload["tsne_rows"].numpy()
    first = payload.get("latents_first_epoch")
    out["latents_first_epoch"] = None if first is None else {s: z.numpy() for s, z in first.items()}
    return out


@dataclass
class LoadedRun:
    """A finished (or paused) run read back from disk."""

    run_dir: Path
    payload: dict[str, Any]
    config: TrainConfig
    engine: StackedAutoencoders
    normaliser: Normaliser

    @property
    def sensors(self) -> tuple[str, ...]:
        return self.engine.sensors

    @property
    def history(self) -> list[dict[str, Any]]:
        return list(self.payload["history"])

    @property
    def unseen_objects(self) -> tuple[str, ...]:
        return tuple(self.payload["split"]["unseen_objects"])

    def check_member(self, member: int) -> None:
        """UsageError unless the run has a member (seed) ``member``."""
        if not 0 <= member < self.engine.members:
            raise UsageError(f"member {member} does not exist", hint=f"the run has {self.engine.members} member(s)")

    def scored_under(self, nmae_normaliser: str | None = None, ssim_range: str | None = None) -> LoadedRun:
        """This run with other metric options (they change no weight, only how reports score it); ``None`` keeps
        the run's own."""
        if nmae_normaliser is None and ssim_range is None:
            return self
        config = replace(
            self.config,
            nmae_normaliser=nmae_normaliser or self.config.nmae_normaliser,
            ssim_range=ssim_range or self.config.ssim_range,
        )
        return replace(self, config=config)


def load_run(run_dir: Path, device: str = "cpu") -> LoadedRun:
    """A run read back for evaluation, reports and translation (its arrays as numpy)."""
    try:
        payload = readable(load_checkpoint(run_dir))
        config = TrainConfig.from_dict(payload["config"])
        engine = StackedAutoencoders.from_state(payload["engine"], resolve_device(device))
        normaliser = Normaliser.from_dict(payload["normaliser"])
    except (KeyError, TypeError, ValueError, AttributeError) as exc:
        raise ModelError(f"checkpoint in {run_dir} is incomplete ({exc})", hint="retrain") from exc
    return LoadedRun(Path(run_dir), payload, config, engine, normaliser)
