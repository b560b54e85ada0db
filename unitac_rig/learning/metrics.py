"""Reconstruction and alignment metrics on frames of shape (..., n_taxels, 3), with the constants the paper leaves
open as explicit options.

NMAE (normalised mean absolute error), per force channel c:
    NMAE_c = mean over taxels |X_c - X̂_c| / R_c,   NMAE = mean over c in (x, y, z), then mean over frames.
The paper does not state its normaliser R; :data:`NMAE_NORMALISERS` are the readings offered (all from *training*
frames, in sensor units, stored with the model, except ``frame_range``):

* ``channel_range``: the range (max - min) of that sensor's channel c;
* ``sensor_range``: the range of the whole sensor (all taxels and axes pooled), one number per sensor;
* ``channel_std``: the standard deviation of channel c (the NMAE is then the MAE in z-score units);
* ``frame_range``: the range (max - min over taxels and axes) of the true frame itself.

SSIM per channel with global statistics over the taxel grid (one window = the whole grid), per frame:
    SSIM_c = (2 mu_x mu_y + C1)(2 cov_xy + C2) / ((mu_x^2 + mu_y^2 + C1)(var_x + var_y + C2))
with population (1/n) variances and covariance, C1 = (0.01 L)^2, C2 = (0.03 L)^2 (the constants of Wang et al.
2004); SSIM = mean over c, then mean over frames. The paper does not state the data range L either; the options
(:data:`SSIM_RANGES`): ``channel_range`` (channel c's own training range), ``sensor_range`` (the whole sensor's),
``z_range`` (the sensor's normal channel's range, for all three channels). A larger L raises C2, which lifts the
score of a channel whose variance is small next to L (a noise-only shear axis scores ~0 under its own range and ~1
under the sensor's).

Latent alignment:

* raw (the paper's): the Manhattan (L1) distance between the latents two sensors give for the same contact,
  averaged over contacts; it changes with the latents' scale, which training also changes;
* scale-free: that mean divided by the mean L1 distance between *unmatched* pairs (sensor a's latent of contact i
  against sensor b's of contact j != i): 1 means a contact's partner is no closer than any other contact, 0 means
  the two encoders agree exactly;
* sensor mixing: pool both sensors' latents; for each point, the fraction of its k nearest neighbours (Euclidean)
  that come from the other sensor, averaged over points, beside its expected value if sensor labels were assigned
  at random (n_other / (n - 1)); their ratio is 1 for perfectly mixed sensors and 0 for separate islands.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np
import torch

from unitac_rig.learning.config import NMAE_NORMALISERS, SSIM_RANGES

SSIM_K1 = 0.01
SSIM_K2 = 0.03


# rows of the unmatched-pair and neighbour computations (all pairs of a subset this size; beyond it a seeded subset)
MAX_PAIR_ROWS = 2048
MIXING_K = 10


def nmae_per_frame(target: torch.Tensor, estimate: torch.Tensor, data_range: torch.Tensor) -> torch.Tensor:
    """(..., n, 3) x2 and normaliser broadcastable to (..., 3) -> (...) NMAE of each frame (dimensionless)."""
    per_channel = (estimate - target).abs().mean(dim=-2) / data_range
    return per_channel.mean(dim=-1)


def ssim_per_frame(target: torch.Tensor, estimate: torch.Tensor, data_range: torch.Tensor) -> torch.Tensor:
    """(..., n, 3) x2 and range (3,) -> (...) SSIM of each frame, global statistics over the n taxels."""
    c1 = (SSIM_K1 * data_range) ** 2
    c2 = (SSIM_K2 * data_range) ** 2
    mu_x = target.mean(dim=-2)
    mu_y = estimate.mean(dim=-2)
    dx = target - mu_x.unsqueeze(-2)
    dy = estimate - mu_y.unsqueeze(-2)
    var_x = (dx * dx).mean(dim=-2)
    var_y = (dy * dy).mean(dim=-2)
    cov = (dx * dy).mean(dim=-2)
    per_channel = ((2 * mu_x * mu_y + c1) * (2 * cov + c2)) / ((mu_x**2 + mu_y**2 + c1) * (var_x + var_y + c2))
    return per_channel.mean(dim=-1)


def nmae_scale(option: str, stats: Mapping[str, torch.Tensor], target: torch.Tensor) -> torch.Tensor:
    """The NMAE normaliser R for ``option``, broadcastable against (..., 3) per-channel errors.

    ``stats``: the sensor's training statistics ``channel_range`` (3,), ``channel_std`` (3,), ``sensor_range`` ()
    in sensor units; ``target``: the true frames (..., n, 3), used by ``frame_range``.
    """
    if option == "channel_range":
        return stats["channel_range"]
    if option == "channel_std":
        return stats["channel_std"]
    if option == "sensor_range":
        return stats["sensor_range"].expand(3)
    if option == "frame_range":
        flat = target.flatten(start_dim=-2)
        extent = flat.amax(dim=-1) - flat.amin(dim=-1)
        return extent.clamp_min(1e-9).unsqueeze(-1)
    raise ValueError(f"unknown NMAE normaliser {option!r} (known: {', '.join(NMAE_NORMALISERS)})")


def ssim_scale(option: str, stats: Mapping[str, torch.Tensor]) -> torch.Tensor:
    """The SSIM data range L (3,) for ``option``; ``stats`` as in :func:`nmae_scale`."""
    if option == "channel_range":
        return stats["channel_range"]
    if option == "sensor_range":
        return stats["sensor_range"].expand(3)
    if option == "z_range":
        return stats["channel_range"][2].expand(3)
    raise ValueError(f"unknown SSIM range {option!r} (known: {', '.join(SSIM_RANGES)})")


def latent_l1_per_pair(z_a: torch.Tensor, z_b: torch.Tensor) -> torch.Tensor:
    """(..., d) x2 -> (...) Manhattan distance between matched latents."""
    return (z_a - z_b).abs().sum(dim=-1)


def _pair_rows(n: int, max_rows: int, seed: int) -> torch.Tensor | None:
    """None (use every row) when ``n <= max_rows``, else a seeded sorted subset of ``max_rows`` rows."""
    if n <= max_rows:
        return None
    rng = np.random.default_rng(seed)
    return torch.from_numpy(np.sort(rng.choice(n, size=max_rows, replace=False)))


def unmatched_l1(z_a: torch.Tensor, z_b: torch.Tensor, max_rows: int = MAX_PAIR_ROWS, seed: int = 0) -> torch.Tensor:
    """(..., M, d) x2 -> (...) mean Manhattan distance between a's latent of contact i and b's of contact j != i,
    over all such pairs of (a seeded subset of ``max_rows``) contacts."""
    rows = _pair_rows(z_a.shape[-2], max_rows, seed)
    if rows is not None:
        z_a, z_b = z_a[..., rows, :], z_b[..., rows, :]
    m = z_a.shape[-2]
    if m < 2:
        return torch.full(z_a.shape[:-2], float("nan"), dtype=z_a.dtype)
    lead = z_a.shape[:-2]
    a = z_a.reshape(-1, m, z_a.shape[-1])
    b = z_b.reshape(-1, m, z_b.shape[-1])
    out = torch.empty(a.shape[0], dtype=z_a.dtype)
    for i in range(a.shape[0]):  # one (M, M) distance matrix at a time
        distances = torch.cdist(a[i : i + 1].double(), b[i : i + 1].double(), p=1)[0]
        out[i] = (distances.sum() - distances.diagonal().sum()) / (m * (m - 1))
    return out.reshape(lead)


def alignment_ratio(z_a: torch.Tensor, z_b: torch.Tensor, max_rows: int = MAX_PAIR_ROWS, seed: int = 0) -> torch.Tensor:
    """(..., M, d) x2 -> (...) scale-free alignment: mean matched L1 / mean unmatched L1 (same rows for both)."""
    rows = _pair_rows(z_a.shape[-2], max_rows, seed)
    if rows is not None:
        z_a, z_b = z_a[..., rows, :], z_b[..., rows, :]
    matched = latent_l1_per_pair(z_a, z_b).double().mean(dim=-1)
    return (matched / unmatched_l1(z_a, z_b, max_rows=z_a.shape[-2])).to(z_a.dtype)


def sensor_mixing(
    latents: Sequence[torch.Tensor], k: int = MIXING_K, max_rows: int = MAX_PAIR_ROWS, seed: int = 0
) -> tuple[float, float]:
    """(observed, expected) nearest-neighbour sensor mixing of one member's latents, one (M_s, d) tensor per sensor.

    Observed: for every point, the fraction of its ``k`` nearest neighbours (Euclidean, itself excluded) whose
    sensor differs, averaged over points; expected: the same fraction if the sensor labels were shuffled,
    ``(n - n_own) / (n - 1)`` averaged over points. Each sensor contributes at most ``max_rows`` points (seeded).
    """
    points, labels = [], []
    for label, z in enumerate(latents):
        rows = _pair_rows(z.shape[0], max_rows, seed)
        chosen = z if rows is None else z[rows]
        points.append(chosen.float())
        labels.append(torch.full((chosen.shape[0],), label))
    x = torch.cat(points)
    y = torch.cat(labels)
    n = x.shape[0]
    if n < 2 or len(latents) < 2:
        return float("nan"), float("nan")
    k = min(k, n - 1)
    distances = torch.cdist(x.unsqueeze(0), x.unsqueeze(0))[0]
    distances.fill_diagonal_(float("inf"))
    neighbours = distances.topk(k, largest=False).indices  # (n, k)
    observed = (y[neighbours] != y.unsqueeze(1)).double().mean()
    own = torch.bincount(y).double()[y]
    expected = ((n - own) / (n - 1)).mean()
    return float(observed), float(expected)


def _as_tensors(*arrays: np.ndarray) -> list[torch.Tensor]:
    return [torch.as_tensor(np.asarray(a, dtype=np.float64)) for a in arrays]


def nmae(target: np.ndarray, estimate: np.ndarray, data_range: np.ndarray) -> float:
    """Mean NMAE over frames; ``target``/``estimate`` (M, n, 3) or (n, 3), ``data_range`` (3,) in sensor units."""
    t, e, r = _as_tensors(target, estimate, data_range)
    return float(nmae_per_frame(t, e, r).mean())


def latent_mixing(latents: Sequence[np.ndarray], k: int = MIXING_K) -> tuple[float, float]:
    """:func:`sensor_mixing` of one (M_s, d) array per sensor."""
    return sensor_mixing(_as_tensors(*latents), k=k)


# ---- the metric table's entries ------------------------------------------------------------------------------------
# Every metric that training, evaluation, the report and the CLI show is a :class:`Metric`; the table that lists them
# is :data:`unitac_rig.learning.metric_table.METRICS`.


@dataclass(frozen=True)
class FrameScoring:
    """What a frame metric scores: the true frames ``target`` (M, n_taxels, 3) in sensor units, the sensor's training
    statistics ``stats`` (see :func:`nmae_scale`) and the run's metric options (``TrainConfig`` field -> value)."""

    target: torch.Tensor
    stats: Mapping[str, torch.Tensor]
    options: Mapping[str, str]


@dataclass
class LatentPairs:
    """What an alignment metric scores: per sensor pair, each sensor's latents (members, M, d) of the same contacts;
    ``cache`` lets metrics computed together (sensor mixing and its expected value) share one computation."""

    pairs: list[tuple[torch.Tensor, torch.Tensor]]
    cache: dict[str, Any] = field(default_factory=dict)


@dataclass(frozen=True)
class Metric:
    """One metric: its name in metrics.json and the training history, how the report and the terminal label it,
    whether higher or lower is better, its units, and its function.

    ``scope`` "frame": ``score(estimate (members, M, n, 3), FrameScoring, variant) -> (members, M)``, one value per
    reconstructed frame (``variant`` None: the run's option, see ``option``); "alignment": ``score(LatentPairs) ->
    (members,)``, averaged over sensor pairs. ``option``/``variants``: the ``TrainConfig`` field that picks how this
    metric is read and the readings offered (the validation's metric-variant table scores every one)."""

    name: str
    label: str
    direction: Literal["lower", "higher"]
    units: str
    scope: Literal["frame", "alignment"]
    score: Callable[..., torch.Tensor]
    description: str
    option: str | None = None
    variants: tuple[str, ...] = ()
    reference_for: str | None = None  # this is the value another metric would have at its best (shown beside it)

    def better(self, a: float, b: float) -> bool:
        """Whether ``a`` is a better value than ``b``."""
        return a < b if self.direction == "lower" else a > b


def _nmae(estimate: torch.Tensor, scoring: FrameScoring, variant: str | None = None) -> torch.Tensor:
    option = variant or scoring.options.get("nmae_normaliser", "channel_range")
    return nmae_per_frame(scoring.target, estimate, nmae_scale(option, scoring.stats, scoring.target))


def _ssim(estimate: torch.Tensor, scoring: FrameScoring, variant: str | None = None) -> torch.Tensor:
    option = variant or scoring.options.get("ssim_range", "channel_range")
    return ssim_per_frame(scoring.target, estimate, ssim_scale(option, scoring.stats))


def _latent_l1(latents: LatentPairs) -> torch.Tensor:
    return torch.stack([latent_l1_per_pair(a, b).mean(dim=-1) for a, b in latents.pairs]).mean(dim=0)


def _latent_ratio(latents: LatentPairs) -> torch.Tensor:
    return torch.stack([alignment_ratio(a.cpu(), b.cpu()) for a, b in latents.pairs]).mean(dim=0)


def _mixing_both(latents: LatentPairs) -> tuple[torch.Tensor, torch.Tensor]:
    """(observed, expected) per member, averaged over sensor pairs; computed once for both metrics."""
    if "mixing" not in latents.cache:
        members = latents.pairs[0][0].shape[0]
        per_member = [[sensor_mixing([a[m].cpu(), b[m].cpu()]) for a, b in latents.pairs] for m in range(members)]
        observed = torch.tensor([float(np.mean([p[0] for p in pairs])) for pairs in per_member], dtype=torch.float64)
        expected = torch.tensor([float(np.mean([p[1] for p in pairs])) for pairs in per_member], dtype=torch.float64)
        latents.cache["mixing"] = (observed, expected)
    result: tuple[torch.Tensor, torch.Tensor] = latents.cache["mixing"]
    return result


NMAE = Metric(
    "nmae",
    "NMAE",
    "lower",
    "dimensionless (error / a training range)",
    "frame",
    _nmae,
    "mean |error| per channel over a training range (the run's nmae_normaliser), mean over channels",
    option="nmae_normaliser",
    variants=NMAE_NORMALISERS,
)
SSIM = Metric(
    "ssim",
    "SSIM",
    "higher",
    "dimensionless (1 = identical)",
    "frame",
    _ssim,
    "structural similarity over the taxel grid per channel (the run's ssim_range), mean over channels",
    option="ssim_range",
    variants=SSIM_RANGES,
)
LATENT_L1 = Metric(
    "latent_l1",
    "matched L1 (paper's)",
    "lower",
    "latent units",
    "alignment",
    _latent_l1,
    "mean Manhattan distance between the two sensors' latents of the same test contact (the paper's alignment "
    "measure; it also changes with the latents' scale)",
)
LATENT_RATIO = Metric(
    "latent_ratio",
    "matched / unmatched L1",
    "lower",
    "dimensionless (1 = chance, 0 = identical)",
    "alignment",
    _latent_ratio,
    "mean matched L1 / mean L1 between one sensor's latent of contact i and the other's of contact j != i "
    "(scale-free: 1 = no closer than any other contact, 0 = identical)",
)
MIXING = Metric(
    "mixing",
    f"sensor mixing ({MIXING_K} NN)",
    "higher",
    "fraction of neighbours",
    "alignment",
    lambda latents: _mixing_both(latents)[0],
    f"fraction of each latent's {MIXING_K} nearest neighbours (Euclidean, both sensors pooled) that come from the "
    "other sensor, averaged over latents",
)
MIXING_EXPECTED = Metric(
    "mixing_expected",
    "perfect mixing",
    "higher",
    "fraction of neighbours",
    "alignment",
    lambda latents: _mixing_both(latents)[1],
    "the same fraction with the sensor labels shuffled (perfect mixing)",
    reference_for="mixing",
)
