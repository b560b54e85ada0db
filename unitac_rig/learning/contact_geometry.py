"""Downstream contact geometry (paper Section IV): predict the local surface profile under the pad from the 16-d
UniTac-NV latent, train on one sensor's latents, test on every sensor's.

Ground truth, cut from the object's outline (CAD frame, mm) as the paper describes:

1. the ray from the object's centre toward the pad (approach angle, object rotation) meets the outline at the
   contact origin;
2. the outline is turned about that origin so the press runs along -y (the pad sits on the +y side); the new x axis
   is the pad's column direction (tool x), i.e. ``(u_y, -u_x)`` for the pad-side direction ``u``;
3. 11 points evenly over 14 mm of x, centred on the origin; at each, the depth (mm, >= 0 on a convex object) is
   how far the outline's pad-facing surface lies below the contact origin along the press direction (-y): measured
   from the line through the origin across the pad (the pad's plane), not from the outline's tangent there, so a
   face pressed at an angle has a sloped profile.

Model: MLP 16 -> 64 -> 128 -> 64 -> 32 -> 11, ReLU and dropout (the sensor's registered ``geometry_dropout``: 0.2
for uSkin latents, 0.3 for PapillArray) between layers, Adam lr 5e-5, weight decay 1e-3, L1 loss (mm), 80 epochs,
batch 64. Split: 10% of the object's approach rays go to test with all their forces, drawn at random (the paper's) or
as one contiguous block (``GeometryConfig.split_mode``, :func:`unitac_rig.learning.data.hold_out_rays`); two
(rotation, angle) keys of one physical ray are one unit, and the split's seed is its own (``split_seed``), apart from
the MLPs' seed.

The trained MLPs are kept in the run (``geometry_estimator.pt``: tensors and plain metadata, read with
``weights_only=True``; ``geometry_estimator.json`` for people) and applied to new frames by :func:`predict_geometry`
(``unitac-rig geometry RUN --predict FRAMES --sensor S``).

Why one module: ground-truth profiles, the estimator's training, its saved form and prediction share
the profile layout.
"""

from __future__ import annotations

import hashlib
import itertools
import json
import logging
import os
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import torch
from torch import nn

from unitac_rig.errors import DataError, ModelError, UsageError
from unitac_rig.learning.data import DEFAULT_GAP_DEG, PairedDataset, hold_out_rays, object_symmetry
from unitac_rig.learning.network import UNITAC_GROUP, StackedLinear, linear_layers, mlp, stacked_mlp
from unitac_rig.learning.paper import PAPER_GEOMETRY_MAE_MM
from unitac_rig.learning.run import (
    LoadedRun,
    computing_on,
    load_run,
    load_test_set,
    safe_torch_load,
    stored_frame_baseline,
)
from unitac_rig.learning.translate import Translator, read_frames

log = logging.getLogger(__name__)

GEOMETRY_JSON = "geometry.json"
GEOMETRY_PNG = "geometry.png"


def profile_offsets_mm(points: int = 11, span_mm: float = 14.0) -> np.ndarray:
    """Where the profile is sampled across the pad, mm from the contact origin (11 points over 14 mm)."""
    return np.linspace(-span_mm / 2.0, span_mm / 2.0, points)


def surface_frame(direction: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(x_hat, u): unit vectors of the profile frame in object coordinates; ``u`` points from the object toward
    the pad (profile +y), ``x_hat = (u_y, -u_x)`` runs across the pad (the sensor's columns)."""
    u = np.asarray(direction, dtype=np.float64)
    u = u / np.linalg.norm(u)
    return np.array([u[1], -u[0]]), u


def local_depth_profile(
    outline_mm: np.ndarray, direction: np.ndarray, origin_mm: np.ndarray, offsets_mm: np.ndarray
) -> np.ndarray:
    """Depths (mm) of the pad-facing surface below the origin at each lateral offset.

    ``outline_mm``: (N, 2) closed polygon; ``direction``: toward the pad; ``origin_mm``: the contact origin on the
    outline. Where a line across misses the outline (past the object's edge) the depth is NaN.
    """
    x_hat, u = surface_frame(direction)
    points = np.asarray(outline_mm, dtype=np.float64) - np.asarray(origin_mm, dtype=np.float64)
    local = np.stack([points @ x_hat, points @ u], axis=1)  # (N, 2): across, toward the pad
    a, b = local, np.roll(local, -1, axis=0)  # each edge of the outline, (N, 2) x2
    x = np.asarray(offsets_mm, dtype=np.float64)[:, None]  # (K, 1) against every edge
    lo, hi = np.minimum(a[:, 0], b[:, 0]), np.maximum(a[:, 0], b[:, 0])
    crossing = (lo <= x + 1e-9) & (hi >= x - 1e-9) & (hi - lo > 1e-12)  # (K, N)
    with np.errstate(divide="ignore", invalid="ignore"):  # a vertical edge crosses no line across
        y = np.where(crossing, a[:, 1] + (x - a[:, 0]) / (b[:, 0] - a[:, 0]) * (b[:, 1] - a[:, 1]), -np.inf)
    return np.where(crossing.any(axis=1), -y.max(axis=1), np.nan)


DirectionFn = Callable[[float, float], np.ndarray]


@dataclass(frozen=True)
class OutlineGeometry:
    """An object's outline plus the rig's convention for where the pad comes from (catalogue by default)."""

    outline_mm: np.ndarray
    outline_hit: Callable[[np.ndarray], np.ndarray]
    pad_direction: DirectionFn

    @classmethod
    def from_catalogue(cls, object_id: str) -> OutlineGeometry:
        from unitac_rig.rig.objects import get_object, pad_side_direction

        spec = get_object(object_id)
        return cls(np.asarray(spec.outer_mm), spec.outline_hit, pad_side_direction)

    def contact(self, angle_deg: float, rotation_deg: float) -> tuple[np.ndarray, np.ndarray]:
        """(direction toward the pad, contact origin) in object coordinates, mm."""
        u = np.asarray(self.pad_direction(angle_deg, rotation_deg), dtype=np.float64)
        return u, np.asarray(self.outline_hit(u), dtype=np.float64)

    def profiles(self, angle_deg: np.ndarray, rotation_deg: np.ndarray, offsets_mm: np.ndarray) -> np.ndarray:
        """(M, K) depth profiles for each (angle, rotation); computed once per distinct direction."""
        cache: dict[tuple[float, float], np.ndarray] = {}
        out = np.empty((len(angle_deg), len(offsets_mm)))
        for i, (angle, rotation) in enumerate(zip(angle_deg, rotation_deg, strict=True)):
            key = (float(angle), float(rotation))
            if key not in cache:
                u, origin = self.contact(*key)
                cache[key] = local_depth_profile(self.outline_mm, u, origin, offsets_mm)
            out[i] = cache[key]
        return out


@dataclass(frozen=True)
class GeometryConfig:
    """The paper's downstream model and training settings."""

    hidden: tuple[int, ...] = (64, 128, 64, 32)
    learning_rate: float = 5e-5
    weight_decay: float = 1e-3
    epochs: int = 80
    batch_size: int = 64
    test_fraction: float = 0.1
    points: int = 11
    span_mm: float = 14.0
    dropout: dict[str, float] = field(default_factory=dict)  # per sensor, over its registered geometry_dropout
    other_dropout: float = 0.2  # a sensor the registry does not know
    split_mode: str = "random"  # "random" (the paper's), "blocked" or "corner" (data.hold_out_rays)
    gap_deg: float = DEFAULT_GAP_DEG  # blocked / corner: guard band around the test rays, out of training
    val_fraction: float = 0.0  # validation rays (for choices), taken from the training side

    def dropout_for(self, sensor: str) -> float:
        from unitac_rig.rig.sensors import SENSORS

        spec = SENSORS.get(sensor)
        return float(self.dropout.get(sensor, spec.geometry_dropout if spec is not None else self.other_dropout))


class StackedProfileMLP(nn.Module):
    """K independent profile MLPs (one per training sensor), the package's MLP run stacked
    (:func:`~unitac_rig.learning.network.stacked_mlp`): member ``k`` is latent -> hidden... -> outputs with ReLU and
    dropout ``dropouts[k]`` after every hidden layer, initialised like ``nn.Linear`` (uniform +-1/sqrt(fan_in))."""

    def __init__(
        self,
        members: int,
        latent_dim: int,
        outputs: int,
        hidden: Sequence[int],
        dropouts: Sequence[float],
        generator: torch.Generator,
    ) -> None:
        super().__init__()
        widths = [latent_dim, *hidden, outputs]
        self.linears = [StackedLinear(members, i, o) for i, o in itertools.pairwise(widths)]
        self.layers = nn.ModuleList(self.linears)  # registers them (parameters, state_dict)
        with torch.no_grad():
            for fan_in, layer in zip(widths, self.linears, strict=False):
                bound = 1.0 / fan_in**0.5
                layer.weight.uniform_(-bound, bound, generator=generator)
                layer.bias.uniform_(-bound, bound, generator=generator)
        self.keep = 1.0 - torch.tensor(list(dropouts), dtype=torch.float32).view(members, 1, 1)
        self.generator = generator

    def forward(self, z: torch.Tensor) -> torch.Tensor:
        """(members, B, latent) -> (members, B, outputs)."""
        return stacked_mlp(self.linears, z, dropout=self._dropout if self.training else None)

    def _dropout(self, index: int, h: torch.Tensor) -> torch.Tensor:
        if index == len(self.linears) - 1:
            return h
        noise = torch.rand(h.shape, generator=self.generator)
        return h * (noise < self.keep) / self.keep


def fit_profile_mlps(
    latents: Sequence[np.ndarray],
    profiles_mm: np.ndarray,
    config: GeometryConfig,
    dropouts: Sequence[float],
    seed: int,
    on_epoch: Callable[[int, StackedProfileMLP], None] | None = None,
) -> StackedProfileMLP:
    """Train one MLP per latent set (L1 loss in mm) on the same targets (M, K), all at once; each member sees
    its own shuffles. Batches are index slices of tensors already in memory (no DataLoader). ``on_epoch(epoch,
    model)`` hears after every epoch (the model in eval mode; it is set back to training after)."""
    generator = torch.Generator().manual_seed(seed)
    members = len(latents)
    model = StackedProfileMLP(members, latents[0].shape[1], profiles_mm.shape[1], config.hidden, dropouts, generator)
    optimizer = torch.optim.Adam(
        model.parameters(), lr=config.learning_rate, weight_decay=config.weight_decay, foreach=True
    )
    x = torch.as_tensor(np.stack(latents), dtype=torch.float32)  # (members, M, latent)
    y = torch.as_tensor(profiles_mm, dtype=torch.float32)
    rows = x.shape[1]
    model.train()
    for epoch in range(config.epochs):
        order = torch.stack([torch.randperm(rows, generator=generator) for _ in range(members)])
        xs = torch.gather(x, 1, order.unsqueeze(-1).expand(-1, -1, x.shape[2]))
        ys = y[order]
        for start in range(0, rows, config.batch_size):
            predicted = model(xs[:, start : start + config.batch_size])
            # mean over each member's batch, summed over members: each member's own L1 loss
            loss = (predicted - ys[:, start : start + config.batch_size]).abs().mean(dim=(1, 2)).sum()
            optimizer.zero_grad(set_to_none=True)
            loss.backward()
            optimizer.step()
        if on_epoch is not None:
            model.eval()
            on_epoch(epoch + 1, model)
            model.train()
    model.eval()
    return model


@dataclass
class GeometryResult:
    object_id: str
    member: int
    seed: int
    offsets_mm: np.ndarray
    scenarios: dict[str, dict[str, Any]]  # "<train>_to_<test>" -> errors
    test_rows: np.ndarray  # indices into the object's rows
    predictions: dict[str, np.ndarray]  # scenario -> (T, K) predicted depths, mm
    truth_mm: np.ndarray  # (T, K)
    angle_deg: np.ndarray  # (T,)
    rotation_deg: np.ndarray  # (T,)
    config: GeometryConfig
    model: StackedProfileMLP | None = None  # the trained MLPs, one per training sensor (``sensors`` order)
    sensors: tuple[str, ...] = ()
    unseen: bool = True  # the object was held out of the autoencoder's training (the paper's numbers are on one)

    def to_json(self) -> dict[str, Any]:
        return {
            "object": self.object_id,
            "member": self.member,
            "seed": self.seed,
            "offsets_mm": self.offsets_mm.tolist(),
            "test_contacts": len(self.test_rows),
            "scenarios": self.scenarios,
            "mean_mae_mm": float(np.mean([s["mae_mm"] for s in self.scenarios.values()])),
            "unseen_in_training": self.unseen,
            "paper_mean_mae_mm": float(np.mean(list(PAPER_GEOMETRY_MAE_MM.values()))) if self.unseen else None,
            "config": asdict(self.config),
        }


def contact_profiles(
    test_set: PairedDataset,
    rows: np.ndarray,
    object_id: str,
    config: GeometryConfig,
    outline: OutlineGeometry | None = None,
) -> tuple[PairedDataset, np.ndarray, np.ndarray, list[tuple[int, int]]]:
    """The contacts ``rows`` of ``object_id``: their subset, true depth profiles (M, points) in mm, which profiles lie
    wholly on the object, and each contact's (rotation, angle) direction in whole degrees."""
    subset = test_set.subset(rows)
    outline = outline or OutlineGeometry.from_catalogue(object_id)
    truth = outline.profiles(subset.angle_deg, subset.rotation_deg, profile_offsets_mm(config.points, config.span_mm))
    valid = ~np.isnan(truth).any(axis=1)
    if not valid.all():
        log.warning("%d contacts have profile points off the object and are left out", int((~valid).sum()))
    directions = list(
        zip(
            np.round(subset.rotation_deg).astype(int).tolist(),
            np.round(subset.angle_deg).astype(int).tolist(),
            strict=True,
        )
    )
    return subset, truth, valid, directions


def geometry_object(run: LoadedRun, test_set: PairedDataset, object_id: str | None = None) -> tuple[str, np.ndarray]:
    """(object id, its rows in ``test_set``): the given object, else the run's first unseen object."""
    if object_id is None:
        unseen = [o for o in run.unseen_objects if o in set(test_set.object_id.tolist())]
        if not unseen:
            raise DataError(
                "the run's test data holds no unseen object to estimate geometry on",
                hint="collect the irregular prism (irregular_pla) with every sensor",
            )
        object_id = unseen[0]
    rows = np.flatnonzero(test_set.object_id == object_id)
    if rows.size == 0:
        raise DataError(
            f"no test contacts of object {object_id!r} in this run",
            hint=f"objects in the run's test data: {', '.join(test_set.objects)}",
        )
    return object_id, rows


def corner_rays_deg(outline: OutlineGeometry) -> list[float]:
    """The CAD-frame direction (deg) from the centre to each corner of the outline (interior angle < 170 deg)."""
    from unitac_rig.rig.objects import CORNER_MAX_INTERIOR_DEG, interior_angles_deg

    vertices = np.asarray(outline.outline_mm, dtype=np.float64)
    corners = vertices[interior_angles_deg(vertices) < CORNER_MAX_INTERIOR_DEG]
    return [float(np.degrees(np.arctan2(v[1], v[0])) % 360.0) for v in corners]


@dataclass(frozen=True)
class GeometrySplit:
    """Per contact of the object: which side of the geometry split it is on (guard contacts are on none)."""

    train: np.ndarray  # (M,) bool
    val: np.ndarray
    test: np.ndarray
    rays: np.ndarray  # (M,) int, each contact's physical ray (deg, CAD frame)


def geometry_split(
    subset: PairedDataset,
    valid: np.ndarray,
    object_id: str,
    split_seed: int,
    config: GeometryConfig,
    outline: OutlineGeometry,
) -> GeometrySplit:
    """The geometry split of one object's contacts by physical ray, seeded by ``split_seed`` alone."""
    rays = np.array(
        [
            round(float(np.degrees(np.arctan2(*outline.pad_direction(a, r)[::-1])))) % 360
            for a, r in zip(subset.angle_deg.tolist(), subset.rotation_deg.tolist(), strict=True)
        ],
        dtype=int,
    )
    centres = corner_rays_deg(outline) if config.split_mode == "corner" else ()
    held = hold_out_rays(
        rays.tolist(),
        object_id,
        split_seed,
        config.test_fraction,
        config.val_fraction,
        mode=config.split_mode,
        gap_deg=config.gap_deg,
        centres_deg=centres,
        stream=3,
        symmetry=object_symmetry(object_id) if config.split_mode == "blocked" else None,
    )
    test = np.isin(rays, list(held.test)) & valid
    val = np.isin(rays, list(held.val)) & valid
    train = ~np.isin(rays, list(held.test | held.val | held.guard)) & valid
    if not test.any() or not train.any():
        raise DataError(f"object {object_id} has too few approach directions to split for geometry")
    return GeometrySplit(train, val, test, rays)


def member_latents(run: LoadedRun, member: int, frames: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """One member's UniTac-NV latents (M, latent) of each sensor's frames (M, n_taxels, 3), sensor units."""
    run.check_member(member)
    translator = Translator(run.engine.member(member, groups=[UNITAC_GROUP]), run.normaliser)
    return {s: translator.encode(frames[s], s) for s in frames}


def fit_single_thread(*args: Any, **kwargs: Any) -> StackedProfileMLP:
    """:func:`fit_profile_mlps` on one CPU thread (tiny layers: one thread is fastest, see run.default_threads)."""
    with computing_on("cpu", 1):
        return fit_profile_mlps(*args, **kwargs)


def run_geometry(
    run: LoadedRun,
    test_set: PairedDataset,
    object_id: str | None = None,
    *,
    member: int = 0,
    config: GeometryConfig | None = None,
    outline: OutlineGeometry | None = None,
    seed: int | None = None,
    split_seed: int | None = None,
    on_stage: Callable[[str], None] | None = None,
) -> GeometryResult:
    """The four (N x N) scenarios on one object's contacts (default: the run's unseen object). The paper's errors
    are given beside ours only on an unseen object: on one the autoencoder trained on they are not comparable.
    ``seed`` seeds the MLPs (default: the member's model seed), ``split_seed`` the geometry split (default:
    ``seed``, as before the split had its own seed; a study over members should give each its own)."""
    config = config or GeometryConfig()
    object_id, rows = geometry_object(run, test_set, object_id)
    run.check_member(member)
    seed = run.engine.seeds[member] if seed is None else seed
    outline = outline or OutlineGeometry.from_catalogue(object_id)
    subset, truth, valid, _ = contact_profiles(test_set, rows, object_id, config, outline)
    split = geometry_split(subset, valid, object_id, int(seed if split_seed is None else split_seed), config, outline)
    held_out = object_id in set(run.unseen_objects)
    if on_stage is not None:
        on_stage(
            f"training the profile MLPs on {object_id} ({int(split.train.sum())} contacts, {config.epochs} epochs; "
            f"{'unseen' if held_out else 'seen'} in training)"
        )
    latents = member_latents(run, member, subset.values)
    sensors = run.sensors
    model = fit_single_thread(
        [latents[s][split.train] for s in sensors],
        truth[split.train],
        config,
        [config.dropout_for(s) for s in sensors],
        seed,
    )
    scenarios: dict[str, dict[str, Any]] = {}
    predictions: dict[str, np.ndarray] = {}
    with torch.no_grad():  # every training sensor's MLP on each sensor's test latents, (train sensors, T, K)
        by_test = {t: model(torch.from_numpy(np.stack([latents[t][split.test]] * len(sensors)))) for t in sensors}
    for k, train_sensor in enumerate(sensors):
        for test_sensor in sensors:
            predicted = by_test[test_sensor][k].numpy()
            name = f"{train_sensor}_to_{test_sensor}"
            errors = np.abs(predicted - truth[split.test])
            scenarios[name] = {
                "train_sensor": train_sensor,
                "test_sensor": test_sensor,
                "mae_mm": float(errors.mean()),
                "per_point_mae_mm": errors.mean(axis=0).tolist(),
                "paper_mae_mm": PAPER_GEOMETRY_MAE_MM.get(name) if held_out else None,
                "dropout": config.dropout_for(train_sensor),
            }
            predictions[name] = predicted
    return GeometryResult(
        object_id=object_id,
        member=member,
        seed=seed,
        offsets_mm=profile_offsets_mm(config.points, config.span_mm),
        scenarios=scenarios,
        test_rows=rows[split.test],
        predictions=predictions,
        truth_mm=truth[split.test],
        angle_deg=subset.angle_deg[split.test],
        rotation_deg=subset.rotation_deg[split.test],
        config=config,
        model=model,
        sensors=tuple(sensors),
        unseen=held_out,
    )


def plot_geometry(result: GeometryResult, outline: OutlineGeometry, sensors: Sequence[str], path: Path) -> Path:
    """The paper's picture: predicted local profiles put back around the outline (columns = training sensor, rows =
    test sensor; the measured profiles thin black under them); below it, three test contacts' profiles across the pad
    (best, median and worst), where errors of a fraction of a millimetre are visible at page size."""
    from matplotlib.collections import LineCollection

    from unitac_rig.plotting import new_figure, save_figure

    n = len(sensors)
    fig = new_figure(3.4 * n + 1.2, 3.4 * n + 3.0, layout="constrained")
    parts: Any = fig.subfigures(2, 1, height_ratios=[3.4 * n, 2.8])  # an array of two subfigures
    top, bottom = parts[0], parts[1]
    axes = top.subplots(n, n, squeeze=False)
    closed = np.vstack([outline.outline_mm, outline.outline_mm[:1]])

    def placed(profiles: np.ndarray) -> list[np.ndarray]:
        segments = []
        for i in range(len(profiles)):
            u, origin = outline.contact(float(result.angle_deg[i]), float(result.rotation_deg[i]))
            x_hat, u = surface_frame(u)
            segments.append(origin + np.outer(result.offsets_mm, x_hat) - np.outer(profiles[i], u))
        return segments

    truth_segments = placed(result.truth_mm)
    lines = None
    for col, train_sensor in enumerate(sensors):
        for row, test_sensor in enumerate(sensors):
            ax = axes[row][col]
            name = f"{train_sensor}_to_{test_sensor}"
            predicted = result.predictions[name]
            colours = np.abs(predicted - result.truth_mm).mean(axis=1)
            ax.plot(closed[:, 0], closed[:, 1], color="0.6", lw=1.0, ls="--")
            ax.add_collection(LineCollection(truth_segments, colors="black", linewidths=0.6))
            lines = LineCollection(placed(predicted), array=colours, cmap="viridis_r", linewidths=2.2)
            lines.set_clim(0.0, 1.0)
            ax.add_collection(lines)
            ax.set_aspect("equal")
            ax.set_title(
                f"train {train_sensor} / test {test_sensor}: MAE {result.scenarios[name]['mae_mm']:.3f} mm", fontsize=9
            )
            ax.tick_params(labelsize=8)
            ax.set_xlabel("x (mm)", fontsize=8)
            ax.set_ylabel("y (mm)", fontsize=8)
    if lines is not None:
        top.colorbar(lines, ax=axes, shrink=0.8, label="profile error (mm; darkest: 1 mm or more)", extend="max")
    top.suptitle(
        f"Contact geometry on {result.object_id}: predicted 14 mm profiles on the outline (measured: thin black)",
        fontsize=10,
    )

    # three contacts across the pad: best, median and worst by the mean error over every scenario
    mean_error = np.mean([np.abs(p - result.truth_mm).mean(axis=1) for p in result.predictions.values()], axis=0)
    order = np.argsort(mean_error, kind="stable")
    picks = dict.fromkeys(int(order[k]) for k in (0, len(order) // 2, len(order) - 1))
    panels = bottom.subplots(1, 3, squeeze=False)[0]
    for ax, (label, i) in zip(panels, zip(("best", "median", "worst"), picks, strict=False), strict=False):
        ax.plot(result.offsets_mm, -result.truth_mm[i], color="black", lw=2.5, label="measured")
        for name, predicted in result.predictions.items():
            ax.plot(result.offsets_mm, -predicted[i], lw=1.2, label=name.replace("_to_", " → "))
        ax.set_title(
            f"{label}: error {mean_error[i]:.2f} mm\nrotation {result.rotation_deg[i]:.0f}°, angle "
            f"{result.angle_deg[i]:+.0f}°",
            fontsize=9,
        )
        ax.set_xlabel("across the pad (mm)", fontsize=8)
        ax.set_ylabel("surface height (mm)", fontsize=8)
        ax.tick_params(labelsize=8)
        ax.grid(alpha=0.3)
    for ax in panels[len(picks) :]:
        ax.set_visible(False)
    panels[0].legend(fontsize=7, title="train → test sensor", title_fontsize=7)
    return save_figure(fig, path)


def geometry_for_run(
    run_dir: Path,
    object_id: str | None = None,
    *,
    member: int = 0,
    config: GeometryConfig | None = None,
    outline: OutlineGeometry | None = None,
    on_stage: Callable[[str], None] | None = None,
) -> tuple[GeometryResult, Path, Path]:
    """Run the downstream task for a trained run; writes ``RUN/geometry.json``, ``RUN/figures/geometry.png`` and
    the trained estimator (``RUN/geometry_estimator.pt`` and ``.json``, for ``geometry --predict``). ``on_stage``
    hears when the training starts (after the run is checked to hold the object)."""
    run = load_run(run_dir)
    test_set = load_test_set(run_dir)
    result = run_geometry(run, test_set, object_id, member=member, config=config, outline=outline, on_stage=on_stage)
    if on_stage is not None:
        on_stage("drawing the profiles and saving the estimator")
    outline = outline or OutlineGeometry.from_catalogue(result.object_id)
    json_path = Path(run_dir) / GEOMETRY_JSON
    json_path.write_text(json.dumps(result.to_json(), indent=2) + "\n", encoding="utf-8")
    png_path = plot_geometry(result, outline, run.sensors, Path(run_dir) / "figures" / GEOMETRY_PNG)
    save_estimator(run, result)
    return result, json_path, png_path


# ---- the saved estimator -------------------------------------------------------------------------------------
ESTIMATOR_PT = "geometry_estimator.pt"
ESTIMATOR_JSON = "geometry_estimator.json"
ESTIMATOR_FORMAT = "unitac-rig/geometry-estimator"
ESTIMATOR_VERSION = 1


def encoder_fingerprint(run: LoadedRun, member: int) -> str:
    """SHA-256 of one member's UniTac-NV encoder weights: the estimator reads their latents, so a run trained on
    (resumed) or replaced after the estimator was fitted is caught at prediction time."""
    digest = hashlib.sha256()
    for key, (weight, bias) in sorted(run.engine.layer_parameters(UNITAC_GROUP, member).items()):
        if key.startswith("enc_"):
            digest.update(key.encode())
            digest.update(np.ascontiguousarray(weight, dtype=np.float32).tobytes())
            digest.update(np.ascontiguousarray(bias, dtype=np.float32).tobytes())
    return digest.hexdigest()


def save_estimator(run: LoadedRun, result: GeometryResult) -> tuple[Path, Path]:
    """``RUN/geometry_estimator.pt`` (the MLPs' tensors and plain metadata; loads with ``weights_only=True``) and
    the same metadata as ``RUN/geometry_estimator.json`` for people."""
    if result.model is None:
        raise ModelError("this geometry result carries no trained estimator")
    meta = {
        "object": result.object_id,
        "member": result.member,
        "seed": result.seed,
        "train_sensors": list(result.sensors),
        "latent_dim": int(result.model.linears[0].weight.shape[1]),
        "hidden": list(result.config.hidden),
        "offsets_mm": result.offsets_mm.tolist(),
        "points": result.config.points,
        "span_mm": result.config.span_mm,
        "epochs": result.config.epochs,
        "dropout": {s: result.config.dropout_for(s) for s in result.sensors},
        "test_mae_mm": {name: scenario["mae_mm"] for name, scenario in result.scenarios.items()},
        "run_epoch": int(run.payload["epoch"]),
        "encoder_sha256": encoder_fingerprint(run, result.member),
        "profile": "depth (mm, >= 0 below the contact origin) of the surface under the pad at offsets_mm across it",
    }
    payload = {
        "format": ESTIMATOR_FORMAT,
        "version": ESTIMATOR_VERSION,
        "weights": [layer.weight.detach().cpu().clone() for layer in result.model.linears],
        "biases": [layer.bias.detach().cpu().clone() for layer in result.model.linears],
        "meta": meta,
    }
    pt_path, json_path = run.run_dir / ESTIMATOR_PT, run.run_dir / ESTIMATOR_JSON
    tmp = pt_path.with_suffix(".pt.tmp")
    torch.save(payload, tmp)
    os.replace(tmp, pt_path)
    json_path.write_text(json.dumps(meta, indent=2) + "\n", encoding="utf-8")
    return pt_path, json_path


@dataclass(frozen=True)
class GeometryEstimator:
    """A saved estimator: one MLP per training sensor, read back without unpickling anything but tensors."""

    weights: list[torch.Tensor]  # (train sensors, in, out) per layer
    biases: list[torch.Tensor]  # (train sensors, 1, out)
    meta: dict[str, Any]

    @classmethod
    def load(cls, run_dir: Path) -> GeometryEstimator:
        path = Path(run_dir) / ESTIMATOR_PT
        if not path.is_file():
            raise UsageError(
                f"{run_dir} has no saved geometry estimator ({ESTIMATOR_PT})",
                hint=f"train it first: unitac-rig geometry {run_dir}",
            )
        payload = safe_torch_load(path, what="geometry estimator")
        if not isinstance(payload, dict) or payload.get("format") != ESTIMATOR_FORMAT:
            raise ModelError(f"{path} is not a unitac-rig geometry estimator", hint="rerun `unitac-rig geometry RUN`")
        if int(payload.get("version", -1)) > ESTIMATOR_VERSION:
            raise ModelError(f"{path} was written by a newer unitac-rig", hint="upgrade unitac-rig")
        try:
            return cls(list(payload["weights"]), list(payload["biases"]), dict(payload["meta"]))
        except (KeyError, TypeError) as exc:
            raise ModelError(f"{path} is incomplete ({exc})", hint="rerun `unitac-rig geometry RUN`") from exc

    @property
    def train_sensors(self) -> tuple[str, ...]:
        return tuple(self.meta["train_sensors"])

    def check_fits(self, run: LoadedRun, member: int) -> None:
        """ModelError unless it was fitted to the latents of ``run``'s member ``member`` as its encoders are now (a
        run trained on (resumed) or replaced since is caught here)."""
        if int(self.meta["member"]) != member or encoder_fingerprint(run, member) != self.meta.get("encoder_sha256"):
            raise ModelError(
                f"the geometry estimator in {run.run_dir} was fitted to other encoder weights than member {member} "
                f"has now (run epoch {self.meta.get('run_epoch')} then, {run.payload['epoch']} now)",
                hint=f"refit it (unitac-rig geometry {run.run_dir}), or use --member {self.meta['member']}",
            )

    def trained_on(self, sensor: str) -> str:
        """The training sensor whose MLP reads ``sensor``'s latents by default: ``sensor`` itself when an MLP was
        trained on it (the paper's within-sensor case), else the first training sensor."""
        return sensor if sensor in self.train_sensors else self.train_sensors[0]

    def head(self, trained_on: str) -> nn.Sequential:
        """The MLP trained on ``trained_on``'s latents as the plain :func:`~unitac_rig.learning.network.mlp`
        (eval mode): latents (M, latent) -> profile depths (M, points), mm."""
        if trained_on not in self.train_sensors:
            raise UsageError(
                f"no geometry MLP was trained on {trained_on!r}", hint=f"choose one of {', '.join(self.train_sensors)}"
            )
        k = self.train_sensors.index(trained_on)
        net = mlp([self.weights[0].shape[1], *(weight.shape[2] for weight in self.weights)])
        with torch.no_grad():
            for linear, weight, bias in zip(linear_layers(net), self.weights, self.biases, strict=True):
                linear.weight.copy_(weight[k].T)
                linear.bias.copy_(bias[k, 0])
        return net.eval()

    def predict(self, latents: np.ndarray, trained_on: str) -> np.ndarray:
        """(M, latent) -> (M, points) profile depths in mm, with the MLP trained on ``trained_on``'s latents."""
        with torch.no_grad():
            return self.head(trained_on)(torch.as_tensor(np.asarray(latents, dtype=np.float32))).numpy()


@dataclass
class GeometryPrediction:
    profiles_mm: np.ndarray  # (M, points)
    offsets_mm: np.ndarray  # (points,)
    sensor: str  # whose frames
    trained_on: str  # whose latents the MLP was trained on
    meta: dict[str, Any]


def predict_geometry(
    run_dir: Path, frames: np.ndarray, sensor: str, trained_on: str | None = None
) -> GeometryPrediction:
    """Local surface profiles under the pad for ``frames`` (M, n_taxels, 3) of ``sensor`` (sensor units): encoded
    by the run member the estimator was trained with, then its MLP for ``trained_on`` (default: ``sensor`` itself
    when an MLP was trained on it, the paper's within-sensor case; else the first training sensor)."""
    estimator = GeometryEstimator.load(run_dir)
    member = int(estimator.meta["member"])
    run = load_run(run_dir)
    estimator.check_fits(run, member)
    chosen = trained_on or estimator.trained_on(sensor)
    frames = np.asarray(frames, dtype=np.float32).reshape(-1, *np.shape(frames)[-2:])
    profiles = estimator.predict(member_latents(run, member, {sensor: frames})[sensor], chosen)
    return GeometryPrediction(
        profiles, np.asarray(estimator.meta["offsets_mm"], dtype=np.float64), sensor, chosen, estimator.meta
    )


def predict_file(
    run_dir: Path, input_path: Path, sensor: str, trained_on: str | None = None, output_path: Path | None = None
) -> tuple[GeometryPrediction, Path]:
    """Profiles for the frames in ``input_path`` (as ``translate`` reads them); writes ``<input>_geometry.npz``
    (``profiles_mm``, ``offsets_mm``, sensors, and the input's keys) or ``output_path``."""
    data = read_frames(Path(input_path), sensor, stored_frame_baseline(run_dir))
    prediction = predict_geometry(run_dir, data.frames, sensor, trained_on)
    out = Path(output_path) if output_path else Path(input_path).with_name(f"{Path(input_path).stem}_geometry.npz")
    arrays = {
        "profiles_mm": prediction.profiles_mm,
        "offsets_mm": prediction.offsets_mm,
        "sensor": np.array(sensor),
        "trained_on": np.array(prediction.trained_on),
        **data.keys,
    }
    np.savez_compressed(out, **arrays)  # type: ignore[arg-type]
    return prediction, out
