"""Synthetic sensor signals (:class:`~unitac_rig.sim.sensor_signals.SignalSource`): repeating presses with noise.

They stand in for the press scene when a simulated device needs *something* to send (tests, ``probe --simulated``).
Every sample is a pure function of ``(seed, t_ns)``, so a device that samples the same instants sends the same values
whatever thread or timing mode it runs in.

Numbers (from the hardware and scene fact sheets): uSkin raw counts rest around 32 000-36 000 per axis and differ per
taxel by thousands, idle noise is a few to ~25 counts, a 10 N press moves a taxel-axis by roughly 1-5 k counts.
PapillArray pillars read N and mm, axial stiffness ~6 N/mm, lateral ~4 N/mm, noise ~0.02 N, centre pillar proud so it
takes the largest share of a flat press; an unbiased hub shows small offsets (drift) until it is biased.
"""

from __future__ import annotations

import math
import threading
from dataclasses import dataclass

import numpy as np

from drivers.layouts import PAPILLARRAY, USKIN
from unitac_rig.sim.sensor_signals import SensorSample, SignalSource

PILLAR_AXIAL_STIFFNESS_N_PER_MM = 6.0
PILLAR_LATERAL_STIFFNESS_N_PER_MM = 4.0


def press_load_n(t_ns: int, *, period_s: float, peak_load_n: float, rest_fraction: float) -> float:
    """Total normal load (N) of a repeating press: ``rest_fraction`` of each period unloaded, then a sin^2 bump."""
    if peak_load_n <= 0 or period_s <= 0:
        return 0.0
    phase = (t_ns / 1e9 / period_s) % 1.0
    if phase < rest_fraction:
        return 0.0
    bump_phase = (phase - rest_fraction) / (1.0 - rest_fraction)
    return peak_load_n * math.sin(math.pi * bump_phase) ** 2


def _noise_rng(seed: int, t_ns: int) -> np.random.Generator:
    return np.random.default_rng([seed, t_ns])


@dataclass(frozen=True)
class UskinPressSource:
    """uSPa46 raw counts: per-taxel baselines, a Gaussian footprint of counts per newton around the pad centre.

    ``peak_load_n=0`` gives an unloaded, noisy sensor (for tare tests and idle probes).
    """

    seed: int = 0
    period_s: float = 2.0
    peak_load_n: float = 10.0
    rest_fraction: float = 0.5
    noise_counts: float = 8.0
    z_counts_per_n: float = 900.0  # counts per N of load under a taxel
    shear_ratio: float = 0.15  # tangential counts per normal count (a slightly off-axis press)
    footprint_sigma_mm: float = 7.0

    def _baseline(self) -> np.ndarray:
        rng = np.random.default_rng([self.seed, 0xBA5E])
        xy = rng.uniform(16_400, 16_800, size=(USKIN.n_taxels, 2))
        z = rng.uniform(31_900, 37_000, size=(USKIN.n_taxels, 1))
        return np.concatenate([xy, z], axis=1)

    def _footprint(self) -> np.ndarray:
        xy = USKIN.taxel_xy_mm()
        weights = np.exp(-0.5 * np.sum(xy**2, axis=1) / self.footprint_sigma_mm**2)
        return weights / weights.sum()

    def sample(self, t_ns: int) -> SensorSample:
        load = press_load_n(
            t_ns, period_s=self.period_s, peak_load_n=self.peak_load_n, rest_fraction=self.rest_fraction
        )
        dz = load * self.z_counts_per_n * self._footprint() * USKIN.n_taxels / 4.0
        delta = np.stack([self.shear_ratio * dz, -0.5 * self.shear_ratio * dz, dz], axis=1)
        noise = _noise_rng(self.seed, t_ns).normal(0.0, self.noise_counts, size=USKIN.frame_shape)
        return SensorSample(values=self._baseline() + delta + noise)


@dataclass(frozen=True)
class PapillArrayPressSource:
    """PapillArray pillar forces (N) and tip displacements (mm) of a flat press, centre pillar proud.

    ``offset_n`` is the drift an unbiased hub shows on every pillar's z force (removed by the device bias).
    """

    seed: int = 0
    period_s: float = 2.0
    peak_load_n: float = 10.0
    rest_fraction: float = 0.5
    noise_n: float = 0.02
    offset_n: float = 0.15
    shear_ratio: float = 0.1

    def sample(self, t_ns: int) -> SensorSample:
        load = press_load_n(
            t_ns, period_s=self.period_s, peak_load_n=self.peak_load_n, rest_fraction=self.rest_fraction
        )
        share = np.full(PAPILLARRAY.n_taxels, 0.6 / 8.0)
        share[PAPILLARRAY.n_taxels // 2] = 0.4  # the proud centre pillar carries the most
        fz = load * share
        forces = np.stack([self.shear_ratio * fz, -0.5 * self.shear_ratio * fz, fz], axis=1)
        rng = _noise_rng(self.seed, t_ns)
        forces = forces + rng.normal(0.0, self.noise_n, size=PAPILLARRAY.frame_shape)
        forces[:, 2] += self.offset_n
        stiffness = np.array(
            [PILLAR_LATERAL_STIFFNESS_N_PER_MM, PILLAR_LATERAL_STIFFNESS_N_PER_MM, PILLAR_AXIAL_STIFFNESS_N_PER_MM]
        )
        return SensorSample(values=forces, displacement_mm=forces / stiffness)


class RecordingSource:
    """Wraps a source and keeps every ``(t_ns, sample)`` it handed out, so tests can compare what was sent."""

    def __init__(self, inner: SignalSource) -> None:
        self.inner = inner
        self._lock = threading.Lock()
        self._samples: list[tuple[int, SensorSample]] = []

    def sample(self, t_ns: int) -> SensorSample:
        result = self.inner.sample(t_ns)
        with self._lock:
            self._samples.append((t_ns, result))
        return result

    @property
    def samples(self) -> list[tuple[int, SensorSample]]:
        with self._lock:
            return list(self._samples)
