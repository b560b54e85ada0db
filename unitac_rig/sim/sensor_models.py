"""Sensor output models: from what each taxel feels (:class:`~unitac_rig.sim.scene.TaxelLoads`, N) to wire units.

* uSkin uSPa46: raw 16-bit counts per taxel and axis = per-taxel baseline (~33 k +- a few k, seeded) + per-taxel
  gain x (skin-spread load; on x/y also the skin's bulge, see the scene) + axis cross-talk + white noise, clipped to
  0..65535. The sensor ships uncalibrated, so gains are fitted to the recorded pooled extremes (issue 12,
  benchmarks/fidelity.py), not taken from a datasheet.
* PapillArray: per-pillar tip displacement (mm) + an unbiased offset (removed by the hub's bias) + white noise,
  and the force (N) the sensor computes from that displacement through its calibration, so the force carries the
  same noise and offset scaled by the pillar's stiffness; quantised to 1 mN and 1 um.

The skin's load spreading itself lives in the scene (it needs the continuous pressure profile); these models only
turn each taxel's load into what its transducer reports. Static parts (baselines, gains, cross-talk, offsets) are
drawn once from ``rng``; noise is drawn from the same generator per sample, so a lockstep run is reproducible.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from drivers.layouts import PAPILLARRAY, USKIN, SensorLayout
from unitac_rig.sim.ft_noise import NormalBlocks
from unitac_rig.sim.scene import SceneParams, TaxelLoads
from unitac_rig.sim.signals import SensorSample

COUNTS_MAX = 65535  # 16-bit unsigned per axis [S: XELA controller version 3]


@dataclass(frozen=True)
class UskinParams:
    """uSkin transducer parameters: [S] stated by a source, [I] inferred or fitted."""

    baseline_mean_counts: float = 33_000.0  # [S] resting values ~32 000-36 000 (xela-server README examples)
    baseline_sd_counts: float = 2_000.0  # [S/I] differs per taxel/axis by thousands
    gain_normal_counts_per_n: float = 1_100.0  # [I] fitted to the recorded pooled maxima (issue 12): a circle at
    # ~10.4 N puts ~1.3 N on each of two taxels (recorded max 1.6-1.8 k counts), a corner up to ~2.4 N on one
    # (hexagon 3.9-4.2 k); the previous 2 500 gave 2.1-2.3x the circles' maxima
    gain_shear_counts_per_n: float = 5_000.0  # [I] fitted with the skin bulge and skin friction to the recorded
    # minima (-1.2 k..-3.1 k counts): Hall lateral sensitivity is ~1/2 of normal per mm of magnet motion, and a
    # bonded, incompressible skin is ~10x softer in shear than in compression, so ~5x the normal gain per N
    gain_sd_fraction: float = 0.10  # [I] uncalibrated taxels differ in gain
    crosstalk_sd: float = 0.05  # [I] 3-axis cross-talk ~5-10 % (Tomo et al. 2016/2018, qualitative)
    noise_counts: float = 8.0  # [I] idle noise peaks ~25 counts on one taxel (tactile_UR5) -> ~8 RMS


def _scene_pillar_stiffness() -> tuple[float, float, float]:
    scene = SceneParams()
    return (scene.pillar_lateral_n_per_mm, scene.pillar_lateral_n_per_mm, scene.pillar_axial_n_per_mm)


@dataclass(frozen=True)
class PapillArrayParams:
    """PapillArray pillar read-out parameters: [S] stated by a source, [I] inferred.

    The sensor senses each tip's 3-D displacement optically and computes the force from it through a factory
    calibration [S: PTS spec 2.1], so noise and offsets enter once, on the displacement, and reach the force
    through the calibration; a pooled force minimum and displacement minimum move together, as recorded (ratios
    1.1-1.4 N/mm on every object)."""

    noise_mm: float = 0.005  # [S] displacement resolution < +-0.01 mm (1 sigma)
    calibration_n_per_mm: tuple[float, float, float] = field(default_factory=_scene_pillar_stiffness)  # [I] force
    # per mm of tip displacement (x, y, z): the scene's pillar stiffness (lateral, lateral, axial), so a noise-free
    # reading keeps force = k * displacement. Force noise 0.006 N lateral and 0.03 N axial (the stated per-pillar
    # 0.01-0.03 N RMS)
    force_quantum_n: float = 0.001  # [I] 1 mN steps (the wire carries float32)
    displacement_quantum_mm: float = 0.001  # [I] 1 um steps
    offset_sd_mm: float = 0.02  # [I] an unbiased hub reads small offsets until the 'z' bias command (temperature,
    # light): ~0.1 N on z through the calibration


class UskinModel:
    """Taxel loads (N) -> uSkin raw counts (float; the device encoder rounds)."""

    def __init__(
        self, params: UskinParams | None = None, rng: np.random.Generator | None = None, *, layout: SensorLayout = USKIN
    ) -> None:
        self.params = p = params or UskinParams()
        self.layout = layout
        self.rng = rng if rng is not None else np.random.default_rng(0)
        n = layout.n_taxels
        self.baseline_counts = np.clip(
            self.rng.normal(p.baseline_mean_counts, p.baseline_sd_counts, (n, 3)), 0.0, COUNTS_MAX
        )
        nominal = np.array([p.gain_shear_counts_per_n, p.gain_shear_counts_per_n, p.gain_normal_counts_per_n])
        self.gain_counts_per_n = nominal * (1.0 + p.gain_sd_fraction * self.rng.standard_normal((n, 1)))
        mix = p.crosstalk_sd * self.rng.standard_normal((n, 3, 3))
        mix[:, np.arange(3), np.arange(3)] = 1.0
        self.crosstalk = mix  # (n, out axis, in axis)
        # every sample's noise from here on: the same normals rng.normal drew one sample at a time, a block at once
        self._normals = NormalBlocks(self.rng)

    def signal_counts(self, forces_n: np.ndarray) -> np.ndarray:
        """Noise-free counts above the baseline for taxel forces (..., n, 3) N: per-taxel gain, then cross-talk."""
        return np.einsum("nij,...nj->...ni", self.crosstalk, self.gain_counts_per_n * np.asarray(forces_n))

    def expected_counts(self, loads: TaxelLoads) -> np.ndarray:
        """Noise-free counts (n, 3) for these loads, before clipping."""
        return self.baseline_counts + self.signal_counts(loads.forces_n)

    def sample(self, loads: TaxelLoads) -> SensorSample:
        # nothing pressing (the approach, the transits): the signal is zero and the expected counts the baseline
        expected = self.expected_counts(loads) if np.count_nonzero(loads.forces_n) else self.baseline_counts
        noise = self.params.noise_counts * self._normals.take(3 * self.layout.n_taxels).reshape(self.layout.frame_shape)
        counts = expected + noise  # rng.normal(0, s, shape) is s x the next standard normals, to the bit
        return SensorSample(values=np.clip(counts, 0.0, COUNTS_MAX))


class PapillArrayModel:
    """Pillar loads (N) and tip displacements (mm) -> PapillArray readings in N and mm."""

    def __init__(
        self,
        params: PapillArrayParams | None = None,
        rng: np.random.Generator | None = None,
        *,
        layout: SensorLayout = PAPILLARRAY,
    ) -> None:
        self.params = p = params or PapillArrayParams()
        self.layout = layout
        self.rng = rng if rng is not None else np.random.default_rng(0)
        self.calibration = np.asarray(p.calibration_n_per_mm, dtype=np.float64)  # (3,) N per mm, x y z
        self.offset_mm = self.rng.normal(0.0, p.offset_sd_mm, layout.frame_shape)
        self.offset_n = self.offset_mm * self.calibration  # the same offset, as the force it reads as
        self._normals = NormalBlocks(self.rng)  # every sample's noise from here on (see UskinModel)

    def sample(self, loads: TaxelLoads) -> SensorSample:
        p = self.params
        shape = self.layout.frame_shape
        error_mm = self.offset_mm + p.noise_mm * self._normals.take(3 * self.layout.n_taxels).reshape(shape)
        disp = np.zeros(shape) if loads.displacement_mm is None else np.asarray(loads.displacement_mm)
        disp = disp + error_mm
        forces = np.asarray(loads.forces_n) + error_mm * self.calibration
        return SensorSample(
            values=_quantise(forces, p.force_quantum_n), displacement_mm=_quantise(disp, p.displacement_quantum_mm)
        )


def _quantise(values: np.ndarray, step: float) -> np.ndarray:
    return np.rint(values / step) * step if step > 0 else values  # np.round to 0 decimals is rint


def model_for(layout: SensorLayout, rng: np.random.Generator | None = None) -> UskinModel | PapillArrayModel:
    """The default output model for a sensor layout (uSkin counts or PapillArray N/mm)."""
    if layout.units == "counts":
        return UskinModel(rng=rng, layout=layout)
    return PapillArrayModel(rng=rng, layout=layout)
