"""Reconstruction and alignment metrics, as the paper defines them, on frames of shape (..., n_taxels, 3).

NMAE (normalised mean absolute error), per force channel c:
    NMAE_c = mean over taxels |X_c - X̂_c| / R_c,   NMAE = mean over c in (x, y, z), then mean over frames.
R_c is the normaliser: the range (max - min) of that sensor's channel c over the *training* frames, in sensor
units, stored with the model, so every row of a table shares one scale.

SSIM per channel with global statistics over the taxel grid (one window = the whole grid), per frame:
    SSIM_c = (2 mu_x mu_y + C1)(2 cov_xy + C2) / ((mu_x^2 + mu_y^2 + C1)(var_x + var_y + C2))
with population (1/n) variances and covariance, C1 = (0.01 L_c)^2, C2 = (0.03 L_c)^2 and data range L_c = R_c
(the constants of Wang et al. 2004); SSIM = mean over c, then mean over frames.

Latent alignment: the Manhattan (L1) distance between the latents two sensors give for the same contact, averaged
over contacts.
"""

from __future__ import annotations

import numpy as np
import torch

SSIM_K1 = 0.01
SSIM_K2 = 0.03


def nmae_per_frame(target: torch.Tensor, estimate: torch.Tensor, data_range: torch.Tensor) -> torch.Tensor:
    """(..., n, 3) x2 and range (3,) -> (...) NMAE of each frame (dimensionless)."""
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


def latent_l1_per_pair(z_a: torch.Tensor, z_b: torch.Tensor) -> torch.Tensor:
    """(..., d) x2 -> (...) Manhattan distance between matched latents."""
    return (z_a - z_b).abs().sum(dim=-1)


def _as_tensors(*arrays: np.ndarray) -> list[torch.Tensor]:
    return [torch.as_tensor(np.asarray(a, dtype=np.float64)) for a in arrays]


def nmae(target: np.ndarray, estimate: np.ndarray, data_range: np.ndarray) -> float:
    """Mean NMAE over frames; ``target``/``estimate`` (M, n, 3) or (n, 3), ``data_range`` (3,) in sensor units."""
    t, e, r = _as_tensors(target, estimate, data_range)
    return float(nmae_per_frame(t, e, r).mean())


def ssim(target: np.ndarray, estimate: np.ndarray, data_range: np.ndarray) -> float:
    """Mean SSIM over frames; shapes as :func:`nmae`."""
    t, e, r = _as_tensors(target, estimate, data_range)
    return float(ssim_per_frame(t, e, r).mean())


def latent_l1(z_a: np.ndarray, z_b: np.ndarray) -> float:
    """Mean Manhattan distance between matched latents (M, d) x2."""
    a, b = _as_tensors(z_a, z_b)
    return float(latent_l1_per_pair(a, b).mean())
