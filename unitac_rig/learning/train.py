"""Training UniTac-NV (and the per-sensor autoencoder baselines) on a paired dataset, with per-epoch test metrics,
atomic checkpoints and resume.

The loop has no per-sample Python: the training rows sit on the device as one tensor, each member gets its own
shuffled index per epoch (one gather), and batches are slices of it; see :mod:`unitac_rig.learning.engine` for the
step itself.

One run's life (start, resume, epoch, evaluation, checkpoint) shares the :class:`TrainingRun` record. What a run
trains is :class:`unitac_rig.learning.config.TrainConfig`, its folder and checkpoint :mod:`unitac_rig.learning.run`,
the scoring of a model on a set of rows :class:`unitac_rig.learning.evaluate.Evaluator`.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
import torch

from unitac_rig.errors import DataError, ModelError, UsageError
from unitac_rig.interrupts import raise_if_interrupted
from unitac_rig.learning.config import CONFIG_TOML, TrainConfig, to_toml
from unitac_rig.learning.data import Normaliser, PairedDataset, Split, split_by_direction
from unitac_rig.learning.engine import StackedAutoencoders, default_groups
from unitac_rig.learning.evaluate import Evaluator
from unitac_rig.learning.run import (
    LoadedRun,
    checkpoint_path,
    computing_on,
    load_checkpoint,
    load_run,
    load_test_set,
    provenance,
    resolve_device,
    save_checkpoint,
    save_test_set,
    save_training_pairs,
    stored_frame_baseline,
    tsne_rows,
    write_config_json,
)

log = logging.getLogger(__name__)


ProgressCallback = Callable[[dict[str, Any]], None]


@dataclass
class TrainingRun:
    """Everything a run carries from epoch to epoch: exactly what its checkpoint stores (and what :func:`train`
    returns)."""

    run_dir: Path
    config: TrainConfig
    dataset_hash: str
    dataset_summary: dict[str, Any]
    split: Split
    normaliser: Normaliser
    engine: StackedAutoencoders
    optimizer: torch.optim.Optimizer
    shuffle_rngs: list[np.random.Generator]  # one per member: the order of its training rows each epoch
    tsne_rows: np.ndarray
    history: list[dict[str, Any]] = field(default_factory=list)
    epochs_done: int = 0
    train_seconds: float = 0.0  # training wall time so far (evaluation excluded)
    first_latents: dict[str, np.ndarray] | None = None  # UniTac-NV latents of the t-SNE rows after epoch 1
    early_stop: dict[str, Any] = field(default_factory=dict)  # best_val_nmae, best_epoch, stopped_epoch (or None)

    def checkpoint(self) -> dict[str, Any]:
        """The checkpoint payload: tensors and plain Python values only (numpy arrays as tensors)."""
        return {
            "config": self.config.to_dict(),
            "engine": self.engine.state(),
            "optimizer": self.optimizer.state_dict(),
            "shuffle_rng": [rng.bit_generator.state for rng in self.shuffle_rngs],
            "normaliser": self.normaliser.to_dict(),
            "split": self.split.to_dict(),
            "test_mask": torch.from_numpy(self.split.test_mask.copy()),
            "val_mask": torch.from_numpy(self.split.validation_mask.copy()),
            "dataset_hash": self.dataset_hash,
            "dataset_summary": self.dataset_summary,
            "epoch": self.epochs_done,
            "history": self.history,
            "train_seconds": self.train_seconds,
            "tsne_rows": torch.from_numpy(self.tsne_rows.astype(np.int64)),
            "latents_first_epoch": (
                None if self.first_latents is None else {s: torch.from_numpy(z) for s, z in self.first_latents.items()}
            ),
            "provenance": provenance(),
            "early_stop": self.early_stop,
        }


def train(
    dataset: PairedDataset,
    run_dir: Path,
    config: TrainConfig | None = None,
    *,
    device: str = "auto",
    threads: int | None = None,
    resume: bool = False,
    epochs: int | None = None,
    progress: ProgressCallback | None = None,
) -> TrainingRun:
    """Train (or resume) a run in ``run_dir``. ``epochs`` on resume extends or keeps the stored budget."""
    run_dir = Path(run_dir)
    if config is not None and config.frame_baseline != dataset.frame_baseline:  # the run must say what it trained on
        raise UsageError(
            f"the training options reference frames to the {config.frame_baseline} baseline, the data was read with "
            f"the {dataset.frame_baseline} one",
            hint=f"read the data with load_sets(DATA, baseline={config.frame_baseline!r})",
        )
    with computing_on(device, threads) as torch_device:
        run = (
            _resume_run(dataset, run_dir, epochs, torch_device)
            if resume
            else _start_run(dataset, run_dir, config, epochs, torch_device)
        )
        train_rows, test_rows = _split_rows(dataset, run.split)
        val_rows = dataset.subset(run.split.validation_mask & dataset.complete_rows())
        x, present = run.normaliser.inputs(train_rows, run.engine.feature_dims)
        train_x = torch.from_numpy(x).to(torch_device)
        train_present = None if train_rows.present is None else torch.from_numpy(present).to(torch_device)
        options = {"nmae_normaliser": run.config.nmae_normaliser, "ssim_range": run.config.ssim_range}
        evaluator = Evaluator(test_rows, run.normaliser, run.split.unseen_objects, torch_device, **options)
        validator = Evaluator(val_rows, run.normaliser, (), torch_device, **options) if len(val_rows) else None
        while run.epochs_done < run.config.epochs and run.early_stop.get("stopped_epoch") is None:
            began = time.perf_counter()
            loss = train_epoch(
                run.engine, run.optimizer, train_x, train_present, run.shuffle_rngs, run.config.batch_size
            )
            run.train_seconds += time.perf_counter() - began
            run.epochs_done += 1
            record: dict[str, Any] = {
                "epoch": run.epochs_done,
                "seconds": run.train_seconds,
                "train_loss": {g.name: loss[i].tolist() for i, g in enumerate(run.engine.groups)},
            }
            done, last = run.epochs_done, run.epochs_done == run.config.epochs
            # per-epoch curves (and any choice made from them) use validation rows; the test rows are scored only
            # after epoch 1 and after the last epoch, for the report's "from epoch 1 to the end" comparisons
            if validator is not None and (done % run.config.eval_every == 0 or last or done == 1):
                record["val"] = validator.summary(run.engine)
                last = _early_stop(run, record["val"]) or last
                if last:
                    record["val_metric_variants"] = validator.metric_variants(run.engine)
            if last or done == 1:
                record["test"] = evaluator.summary(run.engine)
            if done == 1 and run.first_latents is None:
                run.first_latents = {
                    s: z[0, run.tsne_rows].cpu().numpy() for s, z in evaluator.latents(run.engine).items()
                }
            run.history.append(record)
            if progress is not None:
                progress(record)
            saved = done % run.config.checkpoint_every == 0 or last
            if saved:
                save_checkpoint(run.run_dir, run.checkpoint())
            try:
                raise_if_interrupted()  # a Ctrl-C the CLI deferred to here, between two epochs
            except KeyboardInterrupt:
                if not saved:  # keep this finished epoch: --resume goes on from it, nothing is lost
                    save_checkpoint(run.run_dir, run.checkpoint())
                raise
        return run


def _early_stop(run: TrainingRun, val: Mapping[str, Any]) -> bool:
    """Track the best validation NMAE (mean over UniTac-NV's directions and members, seen contacts); True when
    ``config.patience`` epochs have passed without a better one (recorded as ``stopped_epoch``)."""
    subset = val.get("seen") or val.get("all") or {}
    values = [np.mean(cell["nmae"]) for column, cell in subset.items() if "_to_" in column and isinstance(cell, dict)]
    if not values:
        return False
    nmae = float(np.mean(values))
    if nmae < run.early_stop.get("best_val_nmae", np.inf):
        run.early_stop.update(best_val_nmae=nmae, best_epoch=run.epochs_done)
    run.early_stop.setdefault("stopped_epoch", None)
    patience = run.config.patience
    epoch = run.epochs_done
    if patience and epoch - int(run.early_stop["best_epoch"]) >= patience and epoch < run.config.epochs:
        run.early_stop["stopped_epoch"] = epoch
        log.info(
            "early stop at epoch %d: no better validation NMAE since epoch %d", epoch, run.early_stop["best_epoch"]
        )
        return True
    return False


def train_epoch(
    engine: StackedAutoencoders,
    optimizer: torch.optim.Optimizer,
    x: torch.Tensor,
    present: torch.Tensor | None,
    shuffle_rngs: Sequence[np.random.Generator],
    batch: int,
) -> torch.Tensor:
    """One pass over the training rows ``x`` (rows, features) for every member, each in its own order (one gather),
    batches are slices; ``present`` (rows, sensors) masks the loss of contacts some sensors did not record. Returns
    the (groups, members) mean training loss."""
    n_train = x.shape[0]
    order = torch.from_numpy(np.stack([rng.permutation(n_train) for rng in shuffle_rngs])).to(x.device)
    shuffled = x[order]  # (members, n_train, features)
    shuffled_present = None if present is None else present[order]
    loss_sum = torch.zeros(len(engine.groups), engine.members, device=x.device)
    for start in range(0, n_train, batch):
        chunk = shuffled[:, start : start + batch]
        mask = None if shuffled_present is None else shuffled_present[:, start : start + batch]
        loss_sum += engine.train_step(chunk, optimizer, present=mask) * chunk.shape[1]
    return (loss_sum / n_train).cpu()


def _split_rows(dataset: PairedDataset, split: Split) -> tuple[PairedDataset, PairedDataset]:
    """(training rows, test rows); a partial join's contacts that some sensor lacks train (masked loss) but are
    not scored: every test (and validation) contact has every sensor's frame."""
    test_rows = dataset.subset(split.test_mask & dataset.complete_rows())
    if len(test_rows) == 0:
        raise DataError("the split left no test rows", hint="use more approach angles per object")
    return dataset.subset(split.train_mask), test_rows


def _start_run(
    dataset: PairedDataset, run_dir: Path, config: TrainConfig | None, epochs: int | None, device: torch.device
) -> TrainingRun:
    """A new run: split, normalisation, freshly initialised models; writes the test set and config.json."""
    if checkpoint_path(run_dir).exists():
        raise UsageError(f"{run_dir} already holds a run", hint="pass --resume to continue it, or choose another --out")
    config = config or TrainConfig()
    if epochs is not None:
        config = replace(config, epochs=epochs)
    split = split_by_direction(
        dataset,
        config.split_seed,
        config.test_fraction,
        config.unseen_objects,
        config.val_fraction,
        mode=config.split_mode,
    )
    train_rows, test_rows = _split_rows(dataset, split)
    feature_dims = {s: dataset.n_taxels(s) * 3 for s in dataset.sensors}
    groups = default_groups(dataset.sensors, config.baselines)
    engine = StackedAutoencoders(feature_dims, groups, config.seeds, config.shape, device)
    run = TrainingRun(
        run_dir=run_dir,
        config=config,
        dataset_hash=dataset.content_hash(),
        dataset_summary={
            "sensors": list(dataset.sensors),
            "objects": list(dataset.objects),
            "rows": len(dataset),
            "train_rows": len(train_rows),
            "val_rows": int(split.validation_mask.sum()),
            "test_rows": len(test_rows),
            "partial_train_rows": int((~train_rows.complete_rows()).sum()),
            "simulated": dataset.simulated,
        },
        split=split,
        normaliser=Normaliser.fit(dataset, split.train_mask, config.preprocessing),
        engine=engine,
        optimizer=engine.make_optimizer(config.learning_rate),
        shuffle_rngs=[np.random.default_rng([seed, 1]) for seed in config.seeds],
        tsne_rows=tsne_rows(test_rows.object_id, config.tsne_contacts, config.split_seed),
    )
    run_dir.mkdir(parents=True, exist_ok=True)
    save_test_set(run_dir, test_rows)
    save_training_pairs(run_dir, train_rows)
    write_config_json(run_dir, config.to_dict(), split.to_dict(), dataset.sensors, run.dataset_hash)
    (run_dir / CONFIG_TOML).write_text(to_toml(config.to_dict()), encoding="utf-8")
    return run


def _resume_run(dataset: PairedDataset, run_dir: Path, epochs: int | None, device: torch.device) -> TrainingRun:
    """The run in ``run_dir`` as its last checkpoint left it; ``epochs`` extends (never shortens) its budget."""
    loaded = load_run(run_dir, device.type)
    payload = loaded.payload
    if payload.get("extension"):
        raise UsageError(
            f"{run_dir} added a sensor to a trained run: it is trained in one go and cannot be resumed",
            hint="run `unitac-rig train --from RUN --new-sensor NAME` again with more --epochs",
        )
    dataset_hash = dataset.content_hash()
    if payload["dataset_hash"] != dataset_hash:
        raise DataError(
            f"the data differs from the data {run_dir} was trained on (content hash changed)",
            hint="resume with the same --data, or start a new run with another --out",
        )
    config = loaded.config
    if epochs is not None:
        config = replace(config, epochs=max(epochs, int(payload["epoch"])))
    engine = loaded.engine
    run = TrainingRun(
        run_dir=run_dir,
        config=config,
        dataset_hash=dataset_hash,
        dataset_summary=dict(payload["dataset_summary"]),
        split=Split.from_dict(payload["split"], payload["test_mask"], payload["val_mask"]),
        normaliser=loaded.normaliser,
        engine=engine,
        optimizer=engine.make_optimizer(config.learning_rate),
        shuffle_rngs=[_restored_rng(state) for state in payload["shuffle_rng"]],
        tsne_rows=payload["tsne_rows"],
        history=list(payload["history"]),
        epochs_done=int(payload["epoch"]),
        train_seconds=float(payload["train_seconds"]),
        first_latents=payload.get("latents_first_epoch"),
        early_stop=dict(payload.get("early_stop") or {}),
    )
    try:
        run.optimizer.load_state_dict(payload["optimizer"])
    except (ValueError, KeyError, RuntimeError) as exc:
        raise ModelError(f"optimizer state in {run_dir} does not fit the model", hint="retrain") from exc
    if len(run.shuffle_rngs) != engine.members:
        raise ModelError(
            f"checkpoint in {run_dir} has {len(run.shuffle_rngs)} shuffle streams for {engine.members} seeds"
        )
    return run


def trained_on_partial_join(run_dir: Path) -> bool:
    """Whether the run in ``run_dir`` trained on contacts some sensors did not record (so it resumes on a partial
    join too); False when there is no run there."""
    if not checkpoint_path(run_dir).is_file():
        return False
    return int(load_checkpoint(run_dir).get("dataset_summary", {}).get("partial_train_rows", 0)) > 0


def _restored_rng(state: Mapping[str, Any]) -> np.random.Generator:
    rng = np.random.default_rng()
    rng.bit_generator.state = state
    return rng


# what callers outside the learning room (the CLI, export, live, benchmarks) import from here; each is defined once,
# in config.py (TrainConfig) or run.py (the rest)
__all__ = [
    "LoadedRun",
    "TrainConfig",
    "TrainingRun",
    "load_run",
    "load_test_set",
    "resolve_device",
    "stored_frame_baseline",
    "train",
    "trained_on_partial_join",
]
