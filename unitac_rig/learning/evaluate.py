"""Evaluation of a trained model: :class:`Evaluator` scores every model and member on a set of rows (what training
records per epoch on the validation and test rows), and :func:`evaluate_run` makes Table I for a run: every frame
metric of the metric table (:data:`unitac_rig.learning.metric_table.METRICS`; NMAE and SSIM) per test row group (each
object, all seen objects' held-out angles, each unseen object) for every baseline and every UniTac-NV direction, under
the run's metric options; every alignment metric (raw, scale-free and sensor mixing, after epoch 1 and at the end);
``RUN/metrics.json``.

With several members (seeds) the table holds the mean over members, ``table1_std`` the standard deviation and
``table1_members`` each member's values.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import torch

from unitac_rig.learning.data import Normaliser, PairedDataset
from unitac_rig.learning.engine import UNITAC_GROUP, StackedAutoencoders, baseline_name
from unitac_rig.learning.metric_table import METRICS, alignment_metrics, frame_metrics
from unitac_rig.learning.metrics import FrameScoring, LatentPairs, latent_l1_per_pair
from unitac_rig.learning.paper import TABLE1_ROWS
from unitac_rig.learning.run import (
    LoadedRun,
    load_run,
    load_test_set,
    load_training_pairs,
)
from unitac_rig.learning.simple_baselines import SimplePredictions, baseline_columns, predict_simple_baselines

ALL_SEEN = "all_seen"


def direction_name(source: str, target: str) -> str:
    return f"{source}_to_{target}"


class Evaluator:
    """Metrics of every model and member on one set of rows (validation or test): every frame metric of the metric
    table (NMAE and SSIM) per frame in sensor units under the given metric options (:meth:`for_run`: the run's), and
    every alignment metric of the latents (raw L1, scale-free ratio, sensor mixing)."""

    @classmethod
    def for_run(cls, run: LoadedRun, rows: PairedDataset, device: torch.device | None = None) -> Evaluator:
        """An evaluator of ``rows`` scored under the metric options the run was configured with."""
        return cls(
            rows,
            run.normaliser,
            run.unseen_objects,
            device or torch.device("cpu"),
            nmae_normaliser=run.config.nmae_normaliser,
            ssim_range=run.config.ssim_range,
        )

    def __init__(
        self,
        test: PairedDataset,
        normaliser: Normaliser,
        unseen_objects: Sequence[str],
        device: torch.device,
        nmae_normaliser: str = "channel_range",
        ssim_range: str = "channel_range",
    ):
        self.dataset = test
        self.sensors = test.sensors
        self.device = device
        self.options = {"nmae_normaliser": nmae_normaliser, "ssim_range": ssim_range}  # TrainConfig field -> value
        self.inputs = {s: torch.from_numpy(normaliser.normalise(s, test.values[s])).to(device) for s in self.sensors}
        self.targets = {s: torch.from_numpy(test.values[s]).to(device, torch.float32) for s in self.sensors}
        self.mean = {s: torch.tensor(normaliser.mean[s], dtype=torch.float32, device=device) for s in self.sensors}
        self.std = {s: torch.tensor(normaliser.std[s], dtype=torch.float32, device=device) for s in self.sensors}
        self._normaliser = normaliser
        unseen = np.isin(test.object_id, list(unseen_objects))
        self.subsets = {
            "all": torch.ones(len(test), dtype=torch.bool, device=device),
            "seen": torch.from_numpy(~unseen).to(device),
            "unseen": torch.from_numpy(unseen).to(device),
        }

    def stats(self, sensor: str) -> dict[str, torch.Tensor]:
        """The training statistics behind the metric options, as tensors on the device."""
        raw = self._normaliser.metric_stats(sensor)
        return {k: torch.as_tensor(v, dtype=torch.float32, device=self.device) for k, v in raw.items()}

    def to_frames(self, sensor: str, flat: torch.Tensor) -> torch.Tensor:
        """Normalised (..., F) -> (..., n_taxels, 3) in sensor units."""
        return flat.reshape(*flat.shape[:-1], -1, 3) * self.std[sensor] + self.mean[sensor]

    @torch.no_grad()
    def latents(self, engine: StackedAutoencoders) -> dict[str, torch.Tensor]:
        """UniTac-NV latents of every row, per sensor: (members, M, latent)."""
        return {s: engine.encode(UNITAC_GROUP, s, self.inputs[s]) for s in self.sensors}

    @torch.no_grad()
    def reconstructions(
        self, engine: StackedAutoencoders, latents: dict[str, torch.Tensor] | None = None
    ) -> dict[str, tuple[str, torch.Tensor]]:
        """{column: (target sensor, frames (members, M, n_taxels, 3) in sensor units)} for every UniTac-NV direction
        ``<src>_to_<dst>`` and every baseline ``ae_<sensor>`` the run trained (from ``latents`` when they are at
        hand)."""
        out: dict[str, tuple[str, torch.Tensor]] = {}
        latents = latents or self.latents(engine)
        for source in self.sensors:
            decoded = engine.decode(UNITAC_GROUP, latents[source])
            for target in self.sensors:
                out[direction_name(source, target)] = (target, self.to_frames(target, decoded[target]))
        names = {g.name for g in engine.groups}
        for sensor in self.sensors:
            if baseline_name(sensor) in names:
                z = engine.encode(baseline_name(sensor), sensor, self.inputs[sensor])
                frames = self.to_frames(sensor, engine.decode(baseline_name(sensor), z)[sensor])
                out[baseline_name(sensor)] = (sensor, frames)
        return out

    @torch.no_grad()
    def per_frame(
        self, engine: StackedAutoencoders, latents: dict[str, torch.Tensor] | None = None
    ) -> dict[str, dict[str, torch.Tensor]]:
        """{column: {frame metric name: (members, M)}} for every frame metric of the table. Columns:
        ``<src>_to_<dst>`` for UniTac-NV, ``ae_<sensor>`` for baselines the run trained."""
        return {
            column: self.score_frames(target, frames)
            for column, (target, frames) in self.reconstructions(engine, latents).items()
        }

    @torch.no_grad()
    def latent_distance(self, engine: StackedAutoencoders) -> torch.Tensor | None:
        """(members, M): each row's matched-latent L1, the mean over sensor pairs (None for one sensor); the
        ``latent_l1`` metric is its mean over rows."""
        pairs = self.sensor_pairs()
        if not pairs:
            return None
        latents = self.latents(engine)
        return torch.stack([latent_l1_per_pair(latents[a], latents[b]) for a, b in pairs]).mean(dim=0)

    def sensor_pairs(self) -> list[tuple[str, str]]:
        return [(a, b) for i, a in enumerate(self.sensors) for b in self.sensors[i + 1 :]]

    def scoring(self, sensor: str) -> FrameScoring:
        """What a frame metric needs to score reconstructions of ``sensor``'s frames."""
        return FrameScoring(self.targets[sensor], self.stats(sensor), self.options)

    def score_frames(self, sensor: str, estimate: torch.Tensor) -> dict[str, torch.Tensor]:
        """Every frame metric of ``estimate`` (members, M, n_taxels, 3) in sensor units against ``sensor``'s true
        frames: {metric name: (members, M)}."""
        scoring, estimate = self.scoring(sensor), estimate.to(self.device, torch.float32)
        return {metric.name: metric.score(estimate, scoring, None) for metric in frame_metrics()}

    def alignment(self, latents: dict[str, torch.Tensor], mask: torch.Tensor | None = None) -> dict[str, Any]:
        """Per member, over the rows ``mask`` selects (all by default), every alignment metric of the table (the
        paper's raw ``latent_l1``, the scale-free ``latent_ratio``, sensor ``mixing`` and ``mixing_expected``) of
        :meth:`latents`, each averaged over sensor pairs. Empty for one sensor."""
        pairs = self.sensor_pairs()
        if not pairs:
            return {}
        if mask is not None:
            latents = {s: z[:, mask] for s, z in latents.items()}
        scored = LatentPairs([(latents[a], latents[b]) for a, b in pairs])
        return {metric.name: metric.score(scored).tolist() for metric in alignment_metrics()}

    def summary(self, engine: StackedAutoencoders) -> dict[str, Any]:
        """Means over the subsets ("all", "seen" objects' held-out angles, "unseen" objects), per member, with the
        latent alignment of each subset."""
        latents = self.latents(engine)
        scores = self.per_frame(engine, latents)
        summary: dict[str, Any] = {}
        for subset, mask in self.subsets.items():
            if not bool(mask.any()):
                continue
            entry: dict[str, Any] = {
                column: {metric: values[:, mask].mean(dim=1).tolist() for metric, values in metrics.items()}
                for column, metrics in scores.items()
            }
            entry.update(self.alignment(latents, mask))
            summary[subset] = entry
        return summary

    @torch.no_grad()
    def metric_variants(self, engine: StackedAutoencoders, subset: str = "seen") -> dict[str, Any]:
        """Each column's mean of every frame metric that has readings to choose from (NMAE's normalisers, SSIM's
        ranges) under every reading, per member, on one subset: the numbers behind the choice of the metric reading
        (docs/learning.md)."""
        mask = self.subsets[subset]
        if not bool(mask.any()):
            return {}
        out: dict[str, Any] = {"subset": subset}
        reconstructions = self.reconstructions(engine)
        for metric in (m for m in frame_metrics() if m.variants):
            out[metric.name] = {}
            for variant in metric.variants:
                out[metric.name][variant] = {
                    column: metric.score(frames, self.scoring(t), variant)[:, mask].mean(dim=1).tolist()
                    for column, (t, frames) in reconstructions.items()
                }
        return out


def table_rows(test: PairedDataset, unseen: tuple[str, ...]) -> list[tuple[str, np.ndarray]]:
    """(row name, row mask) in the paper's order: seen objects, ``all_seen``, then unseen objects."""
    objects = test.objects
    order = [o for o in TABLE1_ROWS if o in objects] + sorted(o for o in objects if o not in TABLE1_ROWS)
    seen = [o for o in order if o not in unseen]
    rows = [(o, test.object_id == o) for o in seen]
    if seen:
        rows.append((ALL_SEEN, ~np.isin(test.object_id, list(unseen))))
    rows += [(o, test.object_id == o) for o in order if o in unseen]
    return rows


def metric_description(nmae_normaliser: str, ssim_range: str) -> dict[str, str]:
    """One sentence per option choice, for metrics.json, report.md and the terminal."""
    return {
        "nmae_normaliser": nmae_normaliser,
        "ssim_range": ssim_range,
        "nmae": NMAE_TEXT[nmae_normaliser],
        "ssim": f"global grid statistics per channel, C1 = (0.01 L)^2, C2 = (0.03 L)^2, averaged over x, y, z; "
        f"L = {SSIM_TEXT[ssim_range]}",
    }


NMAE_TEXT = {
    "channel_range": "mean |error| per channel divided by that sensor channel's training range (max - min)",
    "sensor_range": "mean |error| per channel divided by the whole sensor's training range (all taxels and axes)",
    "channel_std": "mean |error| per channel divided by that sensor channel's training standard deviation",
    "frame_range": "mean |error| per channel divided by the true frame's own range (max - min, all axes)",
}
SSIM_TEXT = {
    "channel_range": "each sensor channel's training range",
    "sensor_range": "the whole sensor's training range (all taxels and axes)",
    "z_range": "the sensor's normal (z) channel training range, for all three channels",
}
PREPROCESSING_TEXT = {
    "channel_z": "per-channel z-score (each sensor channel's training mean and standard deviation)",
    "sensor_minmax": "per-sensor min-max scaling (one training min and range per sensor, pooled over taxels and axes)",
    "sensor_scale": "per-sensor scale (one pooled training standard deviation per sensor, no shift)",
    "raw": "raw readings (sensor units, no scaling)",
}
FRAME_BASELINE_TEXT = {
    "press": "each press's own tare (taken in free air just before it)",
    "recording": "the tare at the start of each recording (one object rotation of one session), as the paper's "
    "preprocessing subtracts one baseline per recorded file: the sensor's drift since then stays in",
}


def simple_baseline_table(
    evaluator: Evaluator, rows: list[tuple[str, np.ndarray]], predictions: SimplePredictions
) -> dict[str, Any]:
    """The simple baselines' Table I (row -> column -> frame metric, one value: they are deterministic) under the
    evaluator's metric options, with what they chose on the training rows."""
    scores = {
        column: evaluator.score_frames(target, torch.from_numpy(frames)[None])
        for column, (target, frames) in predictions.frames.items()
    }
    table = _cells(_row_means(scores, rows), lambda values: float(values[0]))
    return {"table1": table, "compared_with": baseline_columns(evaluator.sensors), **predictions.info()}


def _row_means(
    scores: dict[str, dict[str, torch.Tensor]], rows: list[tuple[str, np.ndarray]]
) -> dict[str, dict[str, dict[str, np.ndarray]]]:
    """{row: {column: {frame metric: (members,) its mean over the row's contacts}}} of per-frame ``scores``."""
    return {
        row: {
            column: {name: values[:, torch.from_numpy(mask)].mean(dim=1).numpy() for name, values in metrics.items()}
            for column, metrics in scores.items()
        }
        for row, mask in rows
    }


def _cells(means: dict[str, dict[str, dict[str, np.ndarray]]], read: Callable[[np.ndarray], Any]) -> dict[str, Any]:
    """:func:`_row_means` with each cell's per-member values read by ``read`` (their mean, spread, list...)."""
    return {
        row: {c: {n: read(v) for n, v in cell.items()} for c, cell in columns.items()} for row, columns in means.items()
    }


def evaluate_run(run: LoadedRun, test: PairedDataset, simple: SimplePredictions | None = None) -> dict[str, Any]:
    """The metrics.json content (without writing it); with ``simple`` (:func:`simple_predictions`) also the simple
    baselines' Table I (``simple_baselines``)."""
    config = run.config
    evaluator = Evaluator.for_run(run, test)
    latents = evaluator.latents(run.engine)
    scores = evaluator.per_frame(run.engine, latents)
    rows = table_rows(test, run.unseen_objects)
    means = _row_means(scores, rows)

    history = run.history
    first_test = history[0].get("test", {}) if history else {}
    alignment: dict[str, Any] = {}
    for subset, subset_mask in evaluator.subsets.items():
        if not bool(subset_mask.any()) or not evaluator.sensor_pairs():
            continue
        now = evaluator.alignment(latents, subset_mask)
        then = first_test.get(subset, {})
        alignment[subset] = {
            metric.name: {"first_epoch": then.get(metric.name), "final": now[metric.name]}
            for metric in alignment_metrics()
        }
    result: dict[str, Any] = {
        "table1": _cells(means, lambda values: float(values.mean())),
        "alignment": {
            "per_subset": alignment,
            "definition": {metric.name: metric.description for metric in alignment_metrics()},
            "note": "first_epoch values are the test rows scored once after epoch 1 (per member); they are never "
            "used for a choice",
        },
        "epochs": int(run.payload["epoch"]),  # the epoch reached: config.epochs, or where early stopping stopped
        "early_stopping": {
            "patience": int(config.patience),
            "max_epochs": int(config.epochs),
            **dict(run.payload.get("early_stop") or {}),
        },
        "train_seconds": float(run.payload["train_seconds"]),
        "seed": run.engine.seeds[0],
        "seeds": list(run.engine.seeds),
        "split_seed": int(config.split_seed),
        "sensors": list(run.sensors),
        "test_rows": {row: int(mask.sum()) for row, mask in rows},
        "simulated": bool(test.simulated),
        "dataset_hash": run.payload["dataset_hash"],
        "provenance": run.payload.get("provenance", {}),
        "preprocessing": {
            "scaling": config.preprocessing,
            "text": PREPROCESSING_TEXT[config.preprocessing],
            "frame_baseline": config.frame_baseline,
        },
        "metrics": metric_description(config.nmae_normaliser, config.ssim_range),
        "metric_table": {
            m.name: {"label": m.label, "direction": m.direction, "units": m.units, "scope": m.scope}
            for m in METRICS.values()
        },
        "config": config.to_dict(),
    }
    variants = next((h["val_metric_variants"] for h in reversed(history) if "val_metric_variants" in h), None)
    if variants:
        result["validation_metric_variants"] = variants
    if simple is not None:
        result["simple_baselines"] = simple_baseline_table(evaluator, rows, simple)
    if run.engine.members > 1:
        result["table1_std"] = _cells(means, lambda values: float(values.std()))
        result["table1_members"] = _cells(means, lambda values: values.tolist())
    return result


def simple_predictions(run_dir: Path, run: LoadedRun, test: PairedDataset) -> SimplePredictions | None:
    """The simple baselines fitted on the run's kept training pairs (``RUN/seen_pairs``) and predicting ``test``;
    None for a run that kept none (from before issue 38)."""
    train = load_training_pairs(run_dir)
    if train is None:
        return None
    return predict_simple_baselines(train, test, run.normaliser, run.config.shape.latent_dim)


def run_metrics(run_dir: Path, run: LoadedRun | None = None, test: PairedDataset | None = None) -> dict[str, Any]:
    """``metrics.json``'s content for the run in ``run_dir`` (read from disk unless given): :func:`evaluate_run` with
    the simple baselines fitted on the run's training pairs."""
    run = run or load_run(run_dir)
    test = test or load_test_set(run_dir)
    return evaluate_run(run, test, simple_predictions(run_dir, run, test))
