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
from typing import Any

import numpy as np

from drivers.layouts import PAPILLARRAY, USKIN, SensorLayout
from unitac_rig.sim.imperfections import CLEAN, ElastomerMemory, Imperfections, RandomWalk
from unitac_rig.sim.scene import SceneParams, TaxelLoads
from unitac_rig.sim.sensor_signals import SensorSample

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
    # ---- imperfections (sim/imperfections.py; each only where its switch is on) --------------------------------
    full_scale_n: float = 3.0  # [S] "do not exceed 3 N z per cell" (XELA XR1944 manual): a taxel's full scale
    hysteresis_fraction: float = 0.05  # [I] loading and unloading curves differ by 5 % of full scale at half
    # scale. Tomo et al. (Sensors 16(4):491, 2016) measured the uSkin skin's hysteresis and Tomo et al. (RA-L 3(3),
    # 2018) found the 3-D printed silicone of today's uSkin more hysteretic than Ecoflex; their figure is not
    # carried here (docs/simulator.md, "Imperfections")
    creep_fraction: float = 0.05  # [I] under a constant load the reading rises by 5 % of it ...
    creep_tau_s: float = 2.0  # [I] ... 63 % of that within 2 s (a silicone skin's retarded strain)
    drift_counts_per_sqrt_s: float = 10.0  # [D] each channel's zero a random walk of 10 counts/sqrt(s): ~320
    # counts RMS over a 1000 s session, the size of the recorded sessions' midpoint shifts ((max + min) / 2 grew
    # with session length, -133..+1209 counts over 648-1142 s; authors' dataset_info.json, docs/simulator.md)
    gain_axis_sd: float = 0.08  # [S] each taxel-axis its own gain error of sd 8 %: the median per-axis error of
    # a calibrated 3-axis tactile array (2-38 %, median 8.6 %: Sensors 16(6):819, 2016, Table 1), on top of the
    # per-taxel gain_sd_fraction
    neighbour_crosstalk: float = 0.016  # [D] a Hall chip reads a neighbour magnet one pitch away at ~1.6 % of its
    # own (point dipole, magnet 3 mm above the chip, 7.25 mm pitch): each taxel reads 1.6 % of its 4 neighbours


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
    # ---- imperfections (sim/imperfections.py; each only where its switch is on) --------------------------------
    full_scale_n: float = 15.0  # [S] Fz sensing range 15 N per pillar (PTS_2.1_SPEC_JAN25, Table 4.2)
    hysteresis_fraction: float = 0.02  # [I] 2 % of full scale at half scale; the spec asks for >= 1 s unloaded
    # before a bias because of the pillars' hysteresis (PTS spec / PTSDK manual) but states no figure
    creep_fraction: float = 0.03  # [I] the silicone (Shore A40) pillar's retarded strain: +3 % under a constant
    creep_tau_s: float = 1.0  # [I] load, 63 % of it within 1 s
    drift_mm_per_sqrt_s: float = 0.0006  # [I] each tip's zero a random walk: ~0.02 mm RMS over 1000 s, the size of
    # the unbiased offsets above ("temperature variations can cause drift", PTS spec 4.3)
    gain_sd: float = 0.05  # [I] each pillar-axis's factory calibration off by sd 5 % (a calibrated 3-axis array's
    # errors: median 8.6 %, Sensors 16(6):819, 2016, Table 1; the PapillArray's resolution 0.05 N, spec Table 4.2)
    axis_crosstalk_sd: float = 0.03  # [I] each pillar's force axes mix by sd 3 % through its calibration


def elastomer_for(n_taxels: int, params: Any, imperfections: Imperfections) -> ElastomerMemory | None:
    """The elastomer's memory (hysteresis and creep) of a sensor model's ``params`` (its ``full_scale_n``,
    ``hysteresis_fraction``, ``creep_fraction``, ``creep_tau_s``), with the switched-off terms at 0; None when both
    are off, so the clean twin computes nothing for it."""
    if not (imperfections.hysteresis or imperfections.creep):
        return None
    return ElastomerMemory(
        n_taxels,
        full_scale_n=params.full_scale_n,
        hysteresis_fraction=params.hysteresis_fraction if imperfections.hysteresis else 0.0,
        creep_fraction=params.creep_fraction if imperfections.creep else 0.0,
        creep_tau_s=params.creep_tau_s,
    )


class UskinModel:
    """Taxel loads (N) -> uSkin raw counts (float; the device encoder rounds).

    ``imperfections`` (sim/imperfections.py; default none, the model as it was before them): the skin's hysteresis
    and creep on each taxel's load, a per-axis gain spread, the neighbouring magnets' cross-talk and a random walk
    of each channel's zero, with the figures of :class:`UskinParams`. Their static parts are drawn after the
    model's own, so a seed keeps its baselines, gains and cross-talk whichever are on."""

    def __init__(
        self,
        params: UskinParams | None = None,
        rng: np.random.Generator | None = None,
        *,
        layout: SensorLayout = USKIN,
        imperfections: Imperfections = CLEAN,
    ) -> None:
        self.params = p = params or UskinParams()
        self.layout = layout
        self.rng = rng if rng is not None else np.random.default_rng(0)
        self.imperfections = imperfections
        n = layout.n_taxels
        self.baseline_counts = np.clip(
            self.rng.normal(p.baseline_mean_counts, p.baseline_sd_counts, (n, 3)), 0.0, COUNTS_MAX
        )
        nominal = np.array([p.gain_shear_counts_per_n, p.gain_shear_counts_per_n, p.gain_normal_counts_per_n])
        self.gain_counts_per_n = nominal * (1.0 + p.gain_sd_fraction * self.rng.standard_normal((n, 1)))
        mix = p.crosstalk_sd * self.rng.standard_normal((n, 3, 3))
        mix[:, np.arange(3), np.arange(3)] = 1.0
        self.crosstalk = mix  # (n, out axis, in axis)
        if imperfections.gain_spread:
            self.gain_counts_per_n = self.gain_counts_per_n * (1.0 + p.gain_axis_sd * self.rng.standard_normal((n, 3)))
        self.neighbours: np.ndarray | None = None  # (n, n): what share of each other taxel's signal each one reads
        if imperfections.crosstalk and p.neighbour_crosstalk > 0:
            xy = layout.taxel_xy_mm()
            dist = np.linalg.norm(xy[:, None, :] - xy[None, :, :], axis=2)
            pitch = float(np.min(dist[dist > 0]))
            self.neighbours = np.where((dist > 0) & (dist < 1.2 * pitch), p.neighbour_crosstalk, 0.0)
        self.elastomer = elastomer_for(n, p, imperfections)
        self.drift = RandomWalk((n, 3), p.drift_counts_per_sqrt_s) if imperfections.drift else None
        self.noise_rng = self.rng  # the per-sample draws (noise, drift steps); see use_noise_stream
        self._t_ns = 0  # the sample clock when a caller gives none: 100 Hz

    def use_noise_stream(self, rng: np.random.Generator) -> None:
        """Draw the per-sample noise and drift steps from ``rng`` from now on. The static parts stay (one unit);
        the simulated rig keys a stream per session, so two sessions never read the same noise (docs/simulator.md)."""
        self.noise_rng = rng

    def signal_counts(self, forces_n: np.ndarray) -> np.ndarray:
        """Noise-free counts above the baseline for taxel forces (..., n, 3) N: per-taxel gain, then cross-talk
        (and, with that imperfection, the neighbours' share)."""
        own = np.einsum("nij,...nj->...ni", self.crosstalk, self.gain_counts_per_n * np.asarray(forces_n))
        if self.neighbours is None:
            return own
        return own + np.einsum("nm,...mi->...ni", self.neighbours, own)

    def expected_counts(self, loads: TaxelLoads) -> np.ndarray:
        """Noise-free counts (n, 3) for these loads, before clipping (and before the elastomer's memory)."""
        return self.baseline_counts + self.signal_counts(loads.forces_n)

    def sample(
        self, loads: TaxelLoads, t_ns: int | None = None, noise_rng: np.random.Generator | None = None
    ) -> SensorSample:
        """The reading for ``loads`` at device time ``t_ns`` (creep and drift need it; None: 10 ms after the
        previous sample). Samples must come in time order: the elastomer and the drift carry state. The noise is
        drawn from ``noise_rng`` when given (a synthetic source's per-instant generator), else from the model's
        noise stream (:meth:`use_noise_stream`)."""
        normals = (noise_rng or self.noise_rng).standard_normal
        t_ns = self._clock(t_ns)
        if self.elastomer is not None:
            forces = np.asarray(loads.forces_n)
            (read,) = self.elastomer.read(t_ns, forces[:, 2], forces)
            loads = TaxelLoads(read, loads.displacement_mm)
        # nothing pressing (the approach, the transits): the signal is zero and the expected counts the baseline
        expected = self.expected_counts(loads) if np.count_nonzero(loads.forces_n) else self.baseline_counts
        counts = expected + self.params.noise_counts * normals(self.layout.frame_shape)
        if self.drift is not None:
            counts = counts + self.drift.step(t_ns, normals(3 * self.layout.n_taxels))
        return SensorSample(values=np.clip(counts, 0.0, COUNTS_MAX))

    def _clock(self, t_ns: int | None) -> int:
        self._t_ns = self._t_ns + 10_000_000 if t_ns is None else int(t_ns)
        return self._t_ns


class PapillArrayModel:
    """Pillar loads (N) and tip displacements (mm) -> PapillArray readings in N and mm.

    ``imperfections`` (default none): the pillars' hysteresis and creep on each pillar's load and displacement,
    each pillar-axis's calibration gain error and axis mixing (on the force, which the hub computes from the
    displacement), and a random walk of each tip's zero, with the figures of :class:`PapillArrayParams`."""

    def __init__(
        self,
        params: PapillArrayParams | None = None,
        rng: np.random.Generator | None = None,
        *,
        layout: SensorLayout = PAPILLARRAY,
        imperfections: Imperfections = CLEAN,
    ) -> None:
        self.params = p = params or PapillArrayParams()
        self.layout = layout
        self.rng = rng if rng is not None else np.random.default_rng(0)
        self.imperfections = imperfections
        n = layout.n_taxels
        self.calibration = np.asarray(p.calibration_n_per_mm, dtype=np.float64)  # (3,) N per mm, x y z
        self.offset_mm = self.rng.normal(0.0, p.offset_sd_mm, layout.frame_shape)
        self.offset_n = self.offset_mm * self.calibration  # the same offset, as the force it reads as
        # the force the hub computes per N of true load (n, out axis, in axis): identity unless gain or mixing errs
        self.force_map: np.ndarray | None = None
        if imperfections.gain_spread or imperfections.crosstalk:
            force_map = np.zeros((n, 3, 3))
            force_map[:, np.arange(3), np.arange(3)] = 1.0
            if imperfections.gain_spread:
                force_map[:, np.arange(3), np.arange(3)] += p.gain_sd * self.rng.standard_normal((n, 3))
            if imperfections.crosstalk:
                mix = p.axis_crosstalk_sd * self.rng.standard_normal((n, 3, 3))
                mix[:, np.arange(3), np.arange(3)] = 0.0
                force_map += mix
            self.force_map = force_map
        self.elastomer = elastomer_for(n, p, imperfections)
        self.drift = RandomWalk((n, 3), p.drift_mm_per_sqrt_s) if imperfections.drift else None
        self.noise_rng = self.rng
        self._t_ns = 0

    def use_noise_stream(self, rng: np.random.Generator) -> None:
        """As :meth:`UskinModel.use_noise_stream`."""
        self.noise_rng = rng

    def sample(
        self, loads: TaxelLoads, t_ns: int | None = None, noise_rng: np.random.Generator | None = None
    ) -> SensorSample:
        """The reading at device time ``t_ns`` (None: 10 ms after the previous sample), in time order; the noise
        from ``noise_rng`` when given, else from the model's noise stream (see :meth:`UskinModel.sample`)."""
        p = self.params
        shape = self.layout.frame_shape
        normals = (noise_rng or self.noise_rng).standard_normal
        self._t_ns = self._t_ns + 10_000_000 if t_ns is None else int(t_ns)
        forces_true = np.asarray(loads.forces_n)
        disp_true = None if loads.displacement_mm is None else np.asarray(loads.displacement_mm)
        if self.elastomer is not None:
            if disp_true is None:
                (forces_true,) = self.elastomer.read(self._t_ns, forces_true[:, 2], forces_true)
            else:
                forces_true, disp_true = self.elastomer.read(self._t_ns, forces_true[:, 2], forces_true, disp_true)
        error_mm = self.offset_mm + p.noise_mm * normals(shape)
        if self.drift is not None:
            error_mm = error_mm + self.drift.step(self._t_ns, normals(3 * self.layout.n_taxels))
        disp = np.zeros(shape) if disp_true is None else disp_true
        disp = disp + error_mm
        if self.force_map is not None:
            forces_true = np.einsum("nij,nj->ni", self.force_map, forces_true)
        forces = forces_true + error_mm * self.calibration
        return SensorSample(
            values=_quantise(forces, p.force_quantum_n), displacement_mm=_quantise(disp, p.displacement_quantum_mm)
        )


def _quantise(values: np.ndarray, step: float) -> np.ndarray:
    return np.rint(values / step) * step if step > 0 else values  # np.round to 0 decimals is rint


def model_for(
    layout: SensorLayout, rng: np.random.Generator | None = None, imperfections: Imperfections = CLEAN
) -> UskinModel | PapillArrayModel:
    """The default output model for a sensor layout (uSkin counts or PapillArray N/mm)."""
    if layout.units == "counts":
        return UskinModel(rng=rng, layout=layout, imperfections=imperfections)
    return PapillArrayModel(rng=rng, layout=layout, imperfections=imperfections)
