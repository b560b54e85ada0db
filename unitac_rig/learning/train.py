"""Training UniTac-NV (and the per-sensor autoencoder baselines) on a paired dataset, with per-epoch test metrics,
atomic checkpoints and resume.

The loop has no per-sample Python: the training rows sit on the device as one tensor, each member gets its own
shuffled index per epoch (one gather), and batches are slices of it; see :mod:`unitac_rig.learning.engine` for the
step itself.

Why one module of ~530 lines: one run's life (start, resume, epoch, evaluation, checkpoint) shares the ``_Run``
record. The scoring of a model on a set of rows is :class:`unitac_rig.learning.evaluate.Evaluator`.
"""

from __future__ import annotations

import json
import logging
import time
from collections.abc import Callable, Mapping
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
import torch

from unitac_rig.errors import DataError, ModelError, UsageError
from unitac_rig.interrupts import raise_if_interrupted
from unitac_rig.learning.config import CONFIG_TOML, to_toml
from unitac_rig.learning.data import PREPROCESSING, Normaliser, PairedDataset, Split, split_by_direction
from unitac_rig.learning.engine import ModelShape, StackedAutoencoders, default_groups
from unitac_rig.learning.evaluate import Evaluator
from unitac_rig.learning.evaluate import direction_name as direction_name  # where reports look for it
from unitac_rig.learning.metrics import NMAE_NORMALISERS, SSIM_RANGES
from unitac_rig.learning.run import (
    checkpoint_path,
    load_checkpoint,
    provenance,
    save_checkpoint,
    save_test_set,
    save_training_pairs,
)
from unitac_rig.learning.run import load_test_set as load_test_set  # where reports and geometry look for it

log = logging.getLogger(__name__)


# What runs from before the validation split and the preprocessing / metric options did (their checkpoints lack
# these keys).
_LEGACY_DEFAULTS: dict[str, Any] = {
    "val_fraction": 0.0,
    "preprocessing": "channel_z",
    "nmae_normaliser": "channel_range",
    "ssim_range": "channel_range",
    "patience": 0,
}


@dataclass(frozen=True)
class TrainConfig:
    """What a run trains; the defaults are the paper's (Adam 5e-4, batch 64, 1000 epochs, dropout 0.007) where the
    paper gives a value. Where it is silent (validation split, preprocessing constants, metric normalisers) the
    choice and its reason are in docs/learning.md. Files: :mod:`unitac_rig.learning.config`."""

    epochs: int = 1000
    batch_size: int = 64
    learning_rate: float = 5e-4
    seeds: tuple[int, ...] = (0,)
    split_seed: int = 0  # which directions are test / validation data; apart from the model seeds
    split_mode: str = "random"  # data.SPLIT_MODES: the paper's random directions, or blocked rays (docs/learning.md)
    test_fraction: float = 0.1
    val_fraction: float = 0.1  # of each seen object's directions, taken from the training side (paper: none)
    baselines: bool = True
    shape: ModelShape = field(default_factory=ModelShape)
    eval_every: int = 1  # epochs between validation evaluations (epoch 1 and the last epoch are always evaluated)
    checkpoint_every: int = 50  # epochs between checkpoints (the last epoch is always saved)
    unseen_objects: tuple[str, ...] | None = None  # None: the object catalogue decides (irregular prism)
    tsne_contacts: int = 600  # test contacts whose latents are kept for the t-SNE figures
    preprocessing: str = "sensor_scale"  # data.PREPROCESSING
    nmae_normaliser: str = "channel_range"  # metrics.NMAE_NORMALISERS; why this default: docs/learning.md
    ssim_range: str = "sensor_range"  # metrics.SSIM_RANGES
    # early stopping: epochs without a better validation NMAE (mean over UniTac-NV's directions and members, seen
    # validation contacts, checked at every validation evaluation) before training stops; 0: run all ``epochs``
    patience: int = 0

    def __post_init__(self) -> None:
        if self.patience < 0:
            raise UsageError(f"patience must be 0 (off) or a number of epochs, got {self.patience}")
        if self.epochs < 1 or self.batch_size < 1 or self.eval_every < 1 or self.checkpoint_every < 1:
            raise UsageError("epochs, batch size, eval interval and checkpoint interval must be at least 1")
        if not self.seeds:
            raise UsageError("give at least one seed")
        if len(set(self.seeds)) != len(self.seeds):
            raise UsageError(f"seeds must differ, got {list(self.seeds)}")
        if not self.learning_rate > 0.0:
            raise UsageError(f"the learning rate must be positive, got {self.learning_rate}")
        for name, value, known in (
            ("preprocessing", self.preprocessing, PREPROCESSING),
            ("NMAE normaliser", self.nmae_normaliser, NMAE_NORMALISERS),
            ("SSIM range", self.ssim_range, SSIM_RANGES),
        ):
            if value not in known:
                raise UsageError(f"unknown {name} {value!r}", hint=f"use one of {', '.join(known)}")
        if not 0.0 <= self.val_fraction < 1.0 - self.test_fraction:
            raise UsageError(
                f"the validation fraction must be in [0, {1.0 - self.test_fraction:g}), got {self.val_fraction}"
            )

    def to_dict(self) -> dict[str, Any]:
        d = asdict(self)
        d["seeds"] = list(self.seeds)
        d["shape"] = self.shape.to_dict()
        d["unseen_objects"] = None if self.unseen_objects is None else list(self.unseen_objects)
        return d

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> TrainConfig:
        """A stored config; keys a run from before the tuning options lacks take what that run did."""
        kwargs = {**_LEGACY_DEFAULTS, **d}
        kwargs["seeds"] = tuple(int(s) for s in kwargs["seeds"])
        kwargs["shape"] = ModelShape.from_dict(kwargs["shape"])
        if kwargs.get("unseen_objects") is not None:
            kwargs["unseen_objects"] = tuple(kwargs["unseen_objects"])
        return cls(**kwargs)

    def updated(self, flat: Mapping[str, Any]) -> TrainConfig:
        """A copy with ``flat`` applied: ``TrainConfig`` field names, ``shape.<field>`` for the model's (what
        :func:`unitac_rig.learning.config.parse_config` returns, or CLI options)."""
        shape = {k[6:]: v for k, v in flat.items() if k.startswith("shape.")}
        top = {k: v for k, v in flat.items() if not k.startswith("shape.")}
        unknown = set(top) - set(self.to_dict()) | set(shape) - set(self.shape.to_dict())
        if unknown:
            raise UsageError(f"unknown training option(s) {', '.join(sorted(unknown))}")
        if "seeds" in top:
            top["seeds"] = tuple(int(s) for s in top["seeds"])
        if top.get("unseen_objects") is not None:
            top["unseen_objects"] = tuple(top["unseen_objects"])
        for key in ("encoder_hidden", "decoder_hidden"):
            if key in shape:
                shape[key] = tuple(int(w) for w in shape[key])
        return replace(self, **top, shape=replace(self.shape, **shape))


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


@dataclass
class TrainOutcome:
    run_dir: Path
    engine: StackedAutoencoders
    normaliser: Normaliser
    split: Split
    config: TrainConfig
    history: list[dict[str, Any]]
    train_seconds: float
    epochs_done: int


ProgressCallback = Callable[[dict[str, Any]], None]


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
) -> TrainOutcome:
    """Train (or resume) a run in ``run_dir``. ``epochs`` on resume extends or keeps the stored budget."""
    run_dir = Path(run_dir)
    torch_device = resolve_device(device)
    previous_threads = torch.get_num_threads()
    if torch_device.type == "cpu":
        torch.set_num_threads(threads or default_threads())
    try:
        return _train(dataset, run_dir, config, torch_device, resume, epochs, progress)
    finally:
        torch.set_num_threads(previous_threads)


@dataclass
class _Run:
    """Everything a run carries from epoch to epoch: exactly what its checkpoint stores."""

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
    epoch: int = 0  # epochs done
    seconds: float = 0.0  # training wall time so far (evaluation excluded)
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
            "epoch": self.epoch,
            "history": self.history,
            "train_seconds": self.seconds,
            "tsne_rows": torch.from_numpy(self.tsne_rows.astype(np.int64)),
            "latents_first_epoch": (
                None if self.first_latents is None else {s: torch.from_numpy(z) for s, z in self.first_latents.items()}
            ),
            "provenance": provenance(),
            "early_stop": self.early_stop,
        }


def _train(
    dataset: PairedDataset,
    run_dir: Path,
    config: TrainConfig | None,
    device: torch.device,
    resume: bool,
    epochs: int | None,
    progress: ProgressCallback | None,
) -> TrainOutcome:
    run = (
        _resume_run(dataset, run_dir, epochs, device)
        if resume
        else _start_run(dataset, run_dir, config, epochs, device)
    )
    train_rows, test_rows = _split_rows(dataset, run.split)
    val_rows = dataset.subset(run.split.validation_mask & dataset.complete_rows())
    train_x, train_present = _training_inputs(train_rows, run.normaliser, device)
    options = {"nmae_normaliser": run.config.nmae_normaliser, "ssim_range": run.config.ssim_range}
    evaluator = Evaluator(test_rows, run.normaliser, run.split.unseen_objects, device, **options)
    validator = Evaluator(val_rows, run.normaliser, (), device, **options) if len(val_rows) else None
    while run.epoch < run.config.epochs and run.early_stop.get("stopped_epoch") is None:
        record = _train_epoch(run, train_x, train_present)
        done, last = run.epoch, run.epoch == run.config.epochs
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
            run.first_latents = {s: z[0, run.tsne_rows].cpu().numpy() for s, z in evaluator.latents(run.engine).items()}
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
    return TrainOutcome(
        run.run_dir, run.engine, run.normaliser, run.split, run.config, run.history, run.seconds, run.epoch
    )


def _early_stop(run: _Run, val: Mapping[str, Any]) -> bool:
    """Track the best validation NMAE (mean over UniTac-NV's directions and members, seen contacts); True when
    ``config.patience`` epochs have passed without a better one (recorded as ``stopped_epoch``)."""
    subset = val.get("seen") or val.get("all") or {}
    values = [np.mean(cell["nmae"]) for column, cell in subset.items() if "_to_" in column and isinstance(cell, dict)]
    if not values:
        return False
    nmae = float(np.mean(values))
    if nmae < run.early_stop.get("best_val_nmae", np.inf):
        run.early_stop.update(best_val_nmae=nmae, best_epoch=run.epoch)
    run.early_stop.setdefault("stopped_epoch", None)
    patience = run.config.patience
    if patience and run.epoch - int(run.early_stop["best_epoch"]) >= patience and run.epoch < run.config.epochs:
        run.early_stop["stopped_epoch"] = run.epoch
        log.info(
            "early stop at epoch %d: no better validation NMAE since epoch %d", run.epoch, run.early_stop["best_epoch"]
        )
        return True
    return False


def _training_inputs(
    rows: PairedDataset, normaliser: Normaliser, device: torch.device
) -> tuple[torch.Tensor, torch.Tensor | None]:
    """The normalised training rows (M, sum of features) in sensor order on the device, and for a partial join the
    (M, sensors) presence the masked loss needs (missing frames are zeros there, never seen by the loss)."""
    if rows.present is None:
        x = np.concatenate([normaliser.normalise(s, rows.values[s]) for s in rows.sensors], axis=1)
        return torch.from_numpy(x).to(device), None
    blocks = []
    for sensor in rows.sensors:
        block = np.zeros((len(rows), rows.n_taxels(sensor) * 3), dtype=np.float32)
        has = rows.has(sensor)
        block[has] = normaliser.normalise(sensor, rows.values[sensor][has])
        blocks.append(block)
    present = np.stack([rows.has(s) for s in rows.sensors], axis=1).astype(np.float32)
    return torch.from_numpy(np.concatenate(blocks, axis=1)).to(device), torch.from_numpy(present).to(device)


def _train_epoch(run: _Run, train_x: torch.Tensor, present: torch.Tensor | None = None) -> dict[str, Any]:
    """One pass over the training rows for every member (its own order: one gather), batches are slices;
    ``present`` (rows, sensors) masks the loss of contacts some sensors did not record."""
    began = time.perf_counter()
    engine, n_train, batch = run.engine, train_x.shape[0], run.config.batch_size
    order = torch.from_numpy(np.stack([rng.permutation(n_train) for rng in run.shuffle_rngs])).to(train_x.device)
    shuffled = train_x[order]  # (members, n_train, features)
    shuffled_present = None if present is None else present[order]
    loss_sum = torch.zeros(len(engine.groups), engine.members, device=train_x.device)
    for start in range(0, n_train, batch):
        chunk = shuffled[:, start : start + batch]
        mask = None if shuffled_present is None else shuffled_present[:, start : start + batch]
        loss_sum += engine.train_step(chunk, run.optimizer, present=mask) * chunk.shape[1]
    train_loss = (loss_sum / n_train).cpu()
    run.seconds += time.perf_counter() - began
    run.epoch += 1
    return {
        "epoch": run.epoch,
        "seconds": run.seconds,
        "train_loss": {g.name: train_loss[i].tolist() for i, g in enumerate(engine.groups)},
    }


def _split_rows(dataset: PairedDataset, split: Split) -> tuple[PairedDataset, PairedDataset]:
    """(training rows, test rows); a partial join's contacts that some sensor lacks train (masked loss) but are
    not scored: every test (and validation) contact has every sensor's frame."""
    test_rows = dataset.subset(split.test_mask & dataset.complete_rows())
    if len(test_rows) == 0:
        raise DataError("the split left no test rows", hint="use more approach angles per object")
    return dataset.subset(split.train_mask), test_rows


def _start_run(
    dataset: PairedDataset, run_dir: Path, config: TrainConfig | None, epochs: int | None, device: torch.device
) -> _Run:
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
    run = _Run(
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
        tsne_rows=_tsne_rows(test_rows.object_id, config.tsne_contacts, config.split_seed),
    )
    run_dir.mkdir(parents=True, exist_ok=True)
    save_test_set(run_dir, test_rows)
    save_training_pairs(run_dir, train_rows)
    readable = {
        "config": config.to_dict(),
        "split": split.to_dict(),
        "sensors": list(dataset.sensors),
        "dataset_hash": run.dataset_hash,
        "provenance": provenance(),
    }
    (run_dir / "config.json").write_text(json.dumps(readable, indent=2) + "\n", encoding="utf-8")
    (run_dir / CONFIG_TOML).write_text(to_toml(config.to_dict()), encoding="utf-8")
    return run


def _resume_run(dataset: PairedDataset, run_dir: Path, epochs: int | None, device: torch.device) -> _Run:
    """The run in ``run_dir`` as its last checkpoint left it; ``epochs`` extends (never shortens) its budget."""
    payload = _readable(load_checkpoint(run_dir))
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
    config = TrainConfig.from_dict(payload["config"])
    if epochs is not None:
        config = replace(config, epochs=max(epochs, int(payload["epoch"])))
    engine = StackedAutoencoders.from_state(payload["engine"], device)
    run = _Run(
        run_dir=run_dir,
        config=config,
        dataset_hash=dataset_hash,
        dataset_summary=dict(payload["dataset_summary"]),
        split=_stored_split(payload),
        normaliser=Normaliser.from_dict(payload["normaliser"]),
        engine=engine,
        optimizer=engine.make_optimizer(config.learning_rate),
        shuffle_rngs=[_restored_rng(state) for state in payload["shuffle_rng"]],
        tsne_rows=payload["tsne_rows"],
        history=list(payload["history"]),
        epoch=int(payload["epoch"]),
        seconds=float(payload["train_seconds"]),
        first_latents=payload.get("latents_first_epoch"),
        early_stop=dict(payload.get("early_stop") or {}),
    )
    optimizer_state = payload["optimizer"]
    if int(payload["version"]) < 2:  # one flat parameter then
        optimizer_state = engine.optimizer_state_from_flat(optimizer_state)
    try:
        run.optimizer.load_state_dict(optimizer_state)
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


def _stored_split(payload: Mapping[str, Any]) -> Split:
    info = payload["split"]
    val_mask = payload.get("val_mask")
    return Split(
        np.asarray(payload["test_mask"], dtype=bool),
        int(info["seed"]),
        float(info["test_fraction"]),
        tuple(info["unseen_objects"]),
        {k: [tuple(d) for d in v] for k, v in info["test_directions"].items()},
        None if val_mask is None else np.asarray(val_mask, dtype=bool),
        float(info.get("val_fraction", 0.0)),
        {k: [tuple(d) for d in v] for k, v in info.get("val_directions", {}).items()},
        str(info.get("mode", "random")),
        float(info.get("gap_deg", 0.0)),
        tuple(info.get("not_held_out", ())),
    )


def _readable(payload: dict[str, Any]) -> dict[str, Any]:
    """The checkpoint with its arrays as numpy, whether stored as tensors (version 2) or as numpy (version 1)."""
    out = dict(payload)
    out["test_mask"] = _numpy(payload["test_mask"])
    if payload.get("val_mask") is not None:
        out["val_mask"] = _numpy(payload["val_mask"])
    out["tsne_rows"] = _numpy(payload.get("tsne_rows", np.zeros(0, dtype=np.int64)))
    first = payload.get("latents_first_epoch")
    out["latents_first_epoch"] = None if first is None else {s: _numpy(z) for s, z in first.items()}
    return out


def _numpy(value: Any) -> np.ndarray:
    return value.numpy() if isinstance(value, torch.Tensor) else np.asarray(value)


def _tsne_rows(object_ids: np.ndarray, wanted: int, seed: int) -> np.ndarray:
    """Up to ``wanted`` test rows, the same number from every object (the unseen object would swamp a plain
    random pick: it is most of the test set)."""
    rng = np.random.default_rng([seed, 3])
    objects = sorted(set(object_ids.tolist()))
    per_object = max(1, wanted // max(1, len(objects)))
    picked = []
    for object_id in objects:
        rows = np.flatnonzero(object_ids == object_id)
        picked.append(rng.choice(rows, size=min(per_object, rows.size), replace=False))
    return np.sort(np.concatenate(picked)) if picked else np.zeros(0, dtype=int)


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
        payload = _readable(load_checkpoint(run_dir))
        config = TrainConfig.from_dict(payload["config"])
        engine = StackedAutoencoders.from_state(payload["engine"], resolve_device(device))
        normaliser = Normaliser.from_dict(payload["normaliser"])
    except (KeyError, TypeError, ValueError) as exc:
        raise ModelError(f"checkpoint in {run_dir} is incomplete ({exc})", hint="retrain") from exc
    return LoadedRun(Path(run_dir), payload, config, engine, normaliser)
