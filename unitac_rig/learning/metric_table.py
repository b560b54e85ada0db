"""The metric table: every metric that training records, ``metrics.json`` holds, the report draws and the terminal
prints, by name. Adding a metric is a new module that defines a :class:`unitac_rig.learning.metrics.Metric` and one
line here (docs/learning.md, "Add a metric").
"""

from __future__ import annotations

from unitac_rig.learning.metrics import LATENT_L1, LATENT_RATIO, MIXING, MIXING_EXPECTED, NMAE, SSIM, Metric

METRICS: dict[str, Metric] = {
    metric.name: metric
    for metric in (
        NMAE,
        SSIM,
        LATENT_L1,
        LATENT_RATIO,
        MIXING,
        MIXING_EXPECTED,
    )
}


def frame_metrics() -> list[Metric]:
    """The metrics of a reconstructed frame (a Table I cell shows them in this order)."""
    return [m for m in METRICS.values() if m.scope == "frame"]


def alignment_metrics() -> list[Metric]:
    """The latent alignment metrics (one value per member, averaged over sensor pairs)."""
    return [m for m in METRICS.values() if m.scope == "alignment"]
