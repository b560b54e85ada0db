"""A new sensor on a trained model: train only its encoder and its own decoder output layer (head) against the
frozen decoder trunk, on the contacts it shares with any trained sensor (the HTT recipe for a new taxel sensor).

What stays fixed: every layer of the trained run (encoders, decoder trunk and output layer, baselines) is copied and
frozen (:meth:`unitac_rig.learning.engine.StackedAutoencoders.with_new_sensor`), and so are the trained sensors'
normalisation statistics. What is learned, per member (seed) of the run: the new sensor's encoder
``n_taxels*3 -> ... -> latent`` and head ``decoder's last hidden width -> n_taxels*3``. The loss is the model's own
(sum over (source, target) pairs of the MAE), restricted to the pairs that touch the new sensor (new -> trained,
trained -> new, new -> new) and masked per contact: a contact recorded by the new sensor and only some trained
sensors teaches the pairs it has (``train_step(present=...)``).

The split keeps the trained run's promise: for an object the run knew, the test contacts are its held-out approach
directions (never seen in training, by either model); objects the run kept unseen stay all test; a new object gets
its own seeded held-out directions. Evaluation: NMAE and SSIM (each channel's training range, as the paper's table)
of every direction involving the new sensor, on the test contacts that have both sensors, for the untrained new
layers (the baseline any learning must beat) and the trained ones.

The result is a new run directory (the trained run is never modified): a checkpoint the translator, ``export-model``
and ``geometry`` read like any other, ``extension.json`` with the above, and a ``test_set.npz`` of the test contacts
that every sensor recorded (so ``report`` works when there are any).
"""

from __future__ import annotations

import json
import logging
import time
import zlib
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
import torch

from unitac_rig.errors import DataError, ModelError, UsageError
from unitac_rig.learning.data import (
    Normaliser,
    PairedDataset,
    build_paired_dataset,
    hold_out_rays,
    ray_deg,
)
from unitac_rig.learning.engine import UNITAC_GROUP, StackedAutoencoders
from unitac_rig.learning.evaluate import Evaluator, direction_name
from unitac_rig.learning.run import (
    LoadedRun,
    checkpoint_path,
    computing_on,
    load_run,
    provenance,
    save_checkpoint,
    save_test_set,
    tsne_rows,
    write_config_json,
)
from unitac_rig.learning.train import train_epoch
from unitac_rig.storage.reader import MatchedSet

log = logging.getLogger(__name__)

EXTENSION_JSON = "extension.json"
ProgressCallback = Callable[[dict[str, Any]], None]


@dataclass(frozen=True)
class ExtendConfig:
    """Training of the new sensor's layers; ``None`` takes the trained run's own setting."""

    epochs: int | None = None
    batch_size: int | None = None
    learning_rate: float | None = None

    def resolved(self, run: LoadedRun) -> dict[str, Any]:
        """The settings, checked as the run's :class:`~unitac_rig.learning.config.TrainConfig` checks them."""
        config = run.config.updated({k: v for k, v in asdict(self).items() if v is not None})
        return {"epochs": config.epochs, "batch_size": config.batch_size, "learning_rate": config.learning_rate}


@dataclass
class ExtendOutcome:
    run_dir: Path
    engine: StackedAutoencoders
    normaliser: Normaliser
    summary: dict[str, Any]  # what extension.json holds
    complete_test_rows: int  # test contacts every sensor recorded (what `report` evaluates)
    history: list[dict[str, Any]] = field(default_factory=list)


def extension_dataset(sets: Sequence[MatchedSet], trained: Sequence[str], new_sensor: str) -> PairedDataset:
    """The contacts the new sensor shares with at least one trained sensor (partial join; sensors neither trained
    nor new are ignored)."""
    present = {s.sensor for s in sets}
    if new_sensor not in present:
        raise DataError(
            f"the data holds no frames of the new sensor {new_sensor!r}",
            hint=f"it holds {', '.join(sorted(present))}; record the new sensor on some of the trained objects",
        )
    shared = [s for s in trained if s in present]
    if not shared:
        raise DataError(
            f"the data holds no frames of a trained sensor ({', '.join(trained)}) to pair {new_sensor} with",
            hint="pass the --data of the trained run too (repeat --data to pool directories)",
        )
    dataset = build_paired_dataset(sets, [*shared, new_sensor], partial=True)
    rows = dataset.has(new_sensor) & np.logical_or.reduce([dataset.has(s) for s in shared])
    if not rows.any():
        raise DataError(
            f"no contact of {new_sensor} is shared with a trained sensor (same object, rotation, angle, target)",
            hint="press the same objects, angles and targets with the new sensor",
        )
    return dataset.subset(rows)


def _test_mask(dataset: PairedDataset, split: dict[str, Any]) -> np.ndarray:
    """Test rows: the trained run's held-out directions for the objects it knew, all rows of its unseen objects,
    and a seeded share of a new object's approach rays (the run's random split)."""
    unseen = set(split["unseen_objects"])
    held = {obj: {(int(d[0]), int(d[1])) for d in dirs} for obj, dirs in split["test_directions"].items()}
    rotation = np.round(dataset.rotation_deg).astype(int)
    angle = np.round(dataset.angle_deg).astype(int)
    mask = np.zeros(len(dataset), dtype=bool)
    for object_id in dataset.objects:
        rows = np.flatnonzero(dataset.object_id == object_id)
        directions = list(zip(rotation[rows].tolist(), angle[rows].tolist(), strict=True))
        if object_id in unseen:
            mask[rows] = True
        elif object_id in held:
            mask[rows] = [d in held[object_id] for d in directions]
        else:
            rays = [ray_deg(r, a) for r, a in directions]
            test = hold_out_rays(rays, object_id, int(split["seed"]), float(split["test_fraction"])).test
            mask[rows] = [ray in test for ray in rays]
    return mask


def evaluate_new_sensor(
    engine: StackedAutoencoders,
    normaliser: Normaliser,
    test: PairedDataset,
    new_sensor: str,
    nmae_normaliser: str = "channel_range",
    ssim_range: str = "channel_range",
) -> dict[str, dict[str, Any]]:
    """``<src>_to_<dst>`` for every direction involving ``new_sensor``: per-member mean of every frame metric (NMAE
    and SSIM) over the test contacts that have both sensors, and how many there are; scored by the run's
    :class:`~unitac_rig.learning.evaluate.Evaluator` under the base run's NMAE normaliser and SSIM range, so the
    numbers read like the run's own report."""
    out: dict[str, dict[str, Any]] = {}
    sensors = [s for s in engine.sensors if s in test.values]
    for source in sensors:
        for target in sensors:
            rows = test.has(source) & test.has(target)
            if new_sensor not in (source, target) or not rows.any():
                continue
            both = test.subset(rows)
            evaluator = Evaluator(both, normaliser, (), engine.device, nmae_normaliser, ssim_range)
            with torch.no_grad():
                latent = engine.encode(UNITAC_GROUP, source, evaluator.inputs[source])
                estimate = evaluator.to_frames(target, engine.decode(UNITAC_GROUP, latent)[target])
            scores = evaluator.score_frames(target, estimate)
            out[direction_name(source, target)] = {
                **{name: values.mean(dim=-1).tolist() for name, values in scores.items()},
                "contacts": int(rows.sum()),
            }
    return out


def add_sensor(
    base_run: Path,
    sets: Sequence[MatchedSet],
    new_sensor: str,
    out: Path,
    config: ExtendConfig | None = None,
    *,
    device: str = "auto",
    threads: int | None = None,
    progress: ProgressCallback | None = None,
) -> ExtendOutcome:
    """Train ``new_sensor`` into the run ``base_run`` (read only) and write the extended run to ``out``."""
    base_run, out = Path(base_run), Path(out)
    if out.resolve() == base_run.resolve():
        raise UsageError(
            "--out must be a new directory: the trained run is never modified", hint="choose another --out"
        )
    if checkpoint_path(out).exists():
        raise UsageError(f"{out} already holds a run", hint="choose another --out")
    with computing_on(device, threads) as torch_device:
        run = load_run(base_run, torch_device.type)
        if new_sensor in run.sensors:
            raise ModelError(
                f"the run in {base_run} already has sensor {new_sensor!r}", hint=f"it has {', '.join(run.sensors)}"
            )
        settings = (config or ExtendConfig()).resolved(run)
        dataset = extension_dataset(sets, run.sensors, new_sensor)
        _check_layouts(run, dataset)
        test_mask = _test_mask(dataset, run.payload["split"])
        train_rows, test_rows = dataset.subset(~test_mask), dataset.subset(test_mask)
        if len(train_rows) == 0:
            raise DataError("every shared contact is test data: nothing left to train the new sensor on")
        if len(test_rows) == 0:
            log.warning("no shared contact falls in the run's test directions: the new sensor is not evaluated")

        # the run's normaliser plus the new sensor's statistics from its training frames, with the run's preprocessing
        fitted = Normaliser.fit(
            dataset, ~test_mask & dataset.has(new_sensor), run.normaliser.mode, sensors=[new_sensor]
        )
        normaliser = Normaliser.from_dict({**run.normaliser.to_dict(), **fitted.to_dict()})
        engine = run.engine.with_new_sensor(new_sensor, dataset.n_taxels(new_sensor) * 3)
        before = evaluate_new_sensor(
            engine, normaliser, test_rows, new_sensor, run.config.nmae_normaliser, run.config.ssim_range
        )

        x, present = (torch.from_numpy(a).to(torch_device) for a in normaliser.inputs(train_rows, engine.feature_dims))
        optimizer = engine.make_optimizer(settings["learning_rate"])
        history = _train_new_sensor(engine, optimizer, x, present, new_sensor, settings, progress)
        seconds = history[-1]["seconds"] if history else 0.0
        after = evaluate_new_sensor(
            engine, normaliser, test_rows, new_sensor, run.config.nmae_normaliser, run.config.ssim_range
        )

        summary = {
            "new_sensor": new_sensor,
            "trained_sensors": list(run.sensors),
            "from_run": str(base_run),
            "from_dataset_hash": run.payload["dataset_hash"],
            "from_epoch": int(run.payload["epoch"]),
            "frozen_layers": sorted(engine.frozen),
            "trained_layers": sorted(k for k in engine.weights if k not in engine.frozen),
            "settings": settings,
            "contacts": {
                "train": len(train_rows),
                "test": len(test_rows),
                "train_shared_with": {s: int(train_rows.has(s).sum()) for s in run.sensors if s in train_rows.values},
                "test_shared_with": {s: int(test_rows.has(s).sum()) for s in run.sensors if s in test_rows.values},
            },
            "metric": f"NMAE ({run.config.nmae_normaliser}) and SSIM ({run.config.ssim_range}), the run's own "
            "readings, on test contacts that have both sensors",
            "untrained": before,
            "trained": after,
            "train_seconds": seconds,
            "dataset_hash": dataset.content_hash(),
            "provenance": provenance(),
        }
        complete = _write_run(run, out, engine, normaliser, dataset, test_mask, summary, history, optimizer)
        return ExtendOutcome(out, engine, normaliser, summary, complete, history)


def _check_layouts(run: LoadedRun, dataset: PairedDataset) -> None:
    """Refuse frames of a trained sensor whose taxel count differs from the run's (DataError)."""
    for sensor in run.sensors:
        if sensor in dataset.values and dataset.n_taxels(sensor) * 3 != run.engine.feature_dims[sensor]:
            raise DataError(
                f"{sensor} frames have {dataset.n_taxels(sensor)} taxels, the run was trained on "
                f"{run.engine.feature_dims[sensor] // 3}",
                hint="one sensor id must always mean one layout",
            )


def _train_new_sensor(
    engine: StackedAutoencoders,
    optimizer: torch.optim.Optimizer,
    x: torch.Tensor,
    present: torch.Tensor,
    new_sensor: str,
    settings: dict[str, Any],
    progress: ProgressCallback | None,
) -> list[dict[str, Any]]:
    """Train the new sensor's layers (the rest frozen) for ``settings["epochs"]``; one history record per epoch
    (``seconds``: training wall time so far, s). Each seed shuffles with its own stream, salted by the sensor's name."""
    salt = zlib.crc32(new_sensor.encode())
    shuffles = [np.random.default_rng([seed, 1, salt]) for seed in engine.seeds]
    history: list[dict[str, Any]] = []
    seconds = 0.0
    unitac = [g.name for g in engine.groups].index(UNITAC_GROUP)
    for epoch in range(1, settings["epochs"] + 1):
        began = time.perf_counter()
        loss = train_epoch(engine, optimizer, x, present, shuffles, settings["batch_size"])
        seconds += time.perf_counter() - began
        record = {
            "epoch": epoch,
            "epochs": settings["epochs"],
            "seconds": seconds,
            "train_loss": loss[unitac].tolist(),
        }
        history.append(record)
        if progress is not None:
            progress(record)
    return history


def _write_run(
    run: LoadedRun,
    out: Path,
    engine: StackedAutoencoders,
    normaliser: Normaliser,
    dataset: PairedDataset,
    test_mask: np.ndarray,
    summary: dict[str, Any],
    history: list[dict[str, Any]],
    optimizer: torch.optim.Optimizer,
) -> int:
    """The extended run: checkpoint (the trained run's config, split and history, the grown engine, the merged
    normaliser, ``extension``), extension.json, config.json and the complete test contacts."""

    sensors = engine.sensors
    complete = dataset.subset(test_mask & dataset.complete_rows())
    ordered = replace(  # in the engine's sensor order
        complete,
        sensors=sensors,
        values={s: complete.values[s] for s in sensors if s in complete.values},
        force_n={s: complete.force_n[s] for s in sensors if s in complete.force_n},
        present=None,
    )
    out.mkdir(parents=True, exist_ok=True)
    base = run.payload
    tsne_contacts = int(base["config"].get("tsne_contacts", 600))
    if len(ordered.values) == len(sensors):
        save_test_set(out, ordered)
    else:
        log.warning("the new data does not hold every trained sensor: no complete test contacts for `report`")
    payload = {
        "config": base["config"],
        "engine": engine.state(),
        "optimizer": optimizer.state_dict(),
        "shuffle_rng": base["shuffle_rng"],
        "normaliser": normaliser.to_dict(),
        "split": base["split"],
        "test_mask": torch.from_numpy(test_mask.copy()),  # over the extension's contacts
        "dataset_hash": summary["dataset_hash"],
        "dataset_summary": {
            "sensors": list(sensors),
            "objects": list(dataset.objects),
            "rows": len(dataset),
            "test_rows": int(test_mask.sum()),
            "complete_test_rows": len(ordered),
            "simulated": dataset.simulated,
        },
        "epoch": int(base["epoch"]),
        "history": base["history"],
        "train_seconds": float(base["train_seconds"]),
        "tsne_rows": torch.from_numpy(tsne_rows(ordered.object_id, tsne_contacts, int(base["split"]["seed"]))),
        "latents_first_epoch": None,
        "provenance": provenance(),
        "extension": {**summary, "history": history},
    }
    save_checkpoint(out, payload)
    (out / EXTENSION_JSON).write_text(json.dumps(summary, indent=2) + "\n", encoding="utf-8")
    extension = {k: v for k, v in summary.items() if k not in ("untrained", "trained", "provenance")}
    write_config_json(out, base["config"], base["split"], sensors, summary["dataset_hash"], extension=extension)
    return len(ordered)
