"""The imperfections real tactile sensors and a printed rig have, as switches of the fast twin (issue 38).

A twin without them is far easier than the hardware: its readings are one smooth function of the contact, so a
model that interpolates between seen contacts scores as well as one that generalises. Each imperfection here is a
field of :class:`Imperfections` (True = on; the default, :data:`REALISTIC`, has all of them); :data:`CLEAN` turns
every one off and gives, bit for bit, the twin as it was before them (``unitac-rig campaign --imperfections none``).

* ``hysteresis`` and ``creep`` of the elastomer (the uSkin's skin, the PapillArray's silicone pillars):
  :class:`ElastomerMemory` changes each taxel's load before its transducer reads it;
* ``drift``: a random walk of each channel's zero (temperature, the Hall chips' and LEDs' offsets), in wire units;
* ``gain_spread``: each taxel-axis its own gain error, fixed per sensor seed;
* ``crosstalk``: the uSkin's Hall chips also read their neighbours' magnets, the PapillArray's axes mix;
* ``print_tolerance``: each printed object a little larger or smaller than its CAD, and not quite round/square
  (:func:`printed_object`, seeded per object, the same for every sensor and rotation);
* ``mount_offset``: each time a sensor is mounted its pad sits a little off the tool axis (:func:`mounted_params`,
  seeded per session);
* ``flank_friction``: the uSkin's skin sheared by each flank it meets along that flank's own normal, turned back by
  friction (:data:`SKIN_FLANK_FRICTION`, ``unitac_rig.sim.scene_pads.flank_shear_ratio``), instead of the clean
  twin's shear in proportion to the tilt with one cap: a corner's angle reaches the readings.

The figures and their sources are with each parameter (sensor ones in ``sim/sensor_models.py``) and in
docs/simulator.md ("Imperfections").
"""

from __future__ import annotations

import dataclasses
import math
import zlib
from dataclasses import dataclass

import numpy as np

from unitac_rig.errors import UsageError
from unitac_rig.rig.objects import ObjectSpec

# ---- scene-level figures ------------------------------------------------------------------------------------------
PRINT_TOLERANCE_MM = 0.2  # [S] "typical accuracy: +-0.2 mm on calibrated FDM machines" (get3dprints.com, "3D
# printing tolerances and accuracy"); taken as 2 sigma: a size error (the outline offset outward or inward) of
# sd 0.1 mm and a scale error per axis (steps/mm, shrinkage) of sd 0.1 mm over the object's radius
MOUNT_OFFSET_SD_MM = 0.2  # [S/D] an M3 bolt in its ISO 273 "medium" clearance hole (3.4 mm) has 0.2 mm of radial
# play, and the printed adapter itself +-0.2 mm (the FDM figure above): each remount puts the pad's centre off the
# tool axis along the pad by sd 0.2 mm, on top of the fitted offsets of SceneParams
SKIN_FLANK_FRICTION = 0.25  # [I] fitted on the seen objects' recorded uSkin extremes: Coulomb mu of the uSkin's
# skin on a printed flank, the shear's direction set by the flank (SceneParams.skin_flank_friction). Over 5 placement
# draws (benchmarks/fidelity.py draws --set skin_flank_friction=MU) it meets 28.6 of the 32 seen targets per draw at
# 0.25, 27.8 at 0.36, 28.4 at 0.47, 26.8 / 26.4 at the handbook's rubber on PLA 0.62 / 0.76, 28.2 with it off: the
# same below-handbook value the fitted cap skin_friction (0.18) says of printed layer lines


@dataclass(frozen=True)
class Imperfections:
    """Which imperfections the fast twin has (each True = on). Off, each gives back the twin without it."""

    hysteresis: bool = True
    creep: bool = True
    drift: bool = True
    gain_spread: bool = True
    crosstalk: bool = True
    print_tolerance: bool = True
    mount_offset: bool = True
    flank_friction: bool = True

    @property
    def any(self) -> bool:
        return any(dataclasses.astuple(self))

    @property
    def text(self) -> str:
        """The switches as :meth:`parse` reads them: ``"all"``, ``"none"`` or the names that are on."""
        on = [f.name for f in dataclasses.fields(self) if getattr(self, f.name)]
        if len(on) == len(dataclasses.fields(self)):
            return "all"
        return ",".join(on) if on else "none"

    @classmethod
    def parse(cls, text: str) -> Imperfections:
        """``"all"`` (every one), ``"none"`` (the clean twin), ``"all,-creep"`` (all but creep), or the names to
        switch on (``"hysteresis,creep"``). A name it does not know is a usage error."""
        names = [f.name for f in dataclasses.fields(cls)]
        items = [t.strip() for t in text.split(",") if t.strip()]
        if not items:
            raise UsageError("no imperfections named", hint=f"'all', 'none', or some of: {', '.join(names)}")
        base = items[0] in ("all", "none")
        state = dict.fromkeys(names, items[0] == "all") if base else dict.fromkeys(names, False)
        for item in items[1:] if base else items:
            name, on = (item[1:], False) if item.startswith("-") else (item.lstrip("+"), True)
            if name not in state:
                raise UsageError(f"unknown imperfection {name!r}", hint=f"use 'all', 'none', or: {', '.join(names)}")
            state[name] = on
        return cls(**state)


REALISTIC = Imperfections()
CLEAN = Imperfections(**{f.name: False for f in dataclasses.fields(Imperfections)})


def as_imperfections(value: Imperfections | str | None) -> Imperfections:
    """``value`` as :class:`Imperfections` (None: :data:`REALISTIC`; a string: :meth:`Imperfections.parse`)."""
    if value is None:
        return REALISTIC
    if isinstance(value, str):
        return Imperfections.parse(value)
    return value


# ---- the elastomer ------------------------------------------------------------------------------------------------


class ElastomerMemory:
    """Hysteresis and creep of an elastomer, per taxel: what its transducer reads from the load applied.

    * hysteresis: the reading lags the load, low while loading, high while unloading, by
      ``d * H(f)``, ``H(f) = (h * FS / 2) * 4u(1 - u)``, ``u = min(f / FS, 1)``, ``f`` the taxel's normal load (N);
      ``d`` moves from -1 (loading) to +1 (unloading) as the load falls by ``2 * switch * FS`` (and back as it
      rises). So the loading and unloading curves differ by ``h * FS`` at half scale and meet at zero and full scale
      (the datasheet definition). It scales the taxel's whole reading by ``1 + d * H(f) / f = 1 + 2 d h (1 - u)``;
    * creep: a retarded copy ``z`` of each quantity follows it with time constant ``tau`` (s),
      ``dz/dt = (q - z) / tau``, and adds ``c * z``: under a constant load the reading rises by ``c`` of it (63 % of
      that after ``tau``), and once unloaded the remainder fades as fast (the skin recovering).
    """

    def __init__(
        self,
        n_taxels: int,
        *,
        full_scale_n: float,
        hysteresis_fraction: float = 0.0,
        switch_fraction: float = 0.05,
        creep_fraction: float = 0.0,
        creep_tau_s: float = 1.0,
    ) -> None:
        if full_scale_n <= 0 or switch_fraction <= 0 or creep_tau_s <= 0:
            raise ValueError("full scale, switch fraction and creep time constant must be positive")
        self.full_scale_n = full_scale_n
        self.hysteresis_fraction = hysteresis_fraction
        self.switch_fraction = switch_fraction
        self.creep_fraction = creep_fraction
        self.creep_tau_s = creep_tau_s
        self.direction = np.full(n_taxels, -1.0)  # -1: on the loading branch, +1: on the unloading branch
        self.previous_n = np.zeros(n_taxels)
        self.retarded: list[np.ndarray] = []  # z of each quantity read, in its units
        self.t_ns: int | None = None

    def read(self, t_ns: int, normal_n: np.ndarray, *quantities: np.ndarray) -> list[np.ndarray]:
        """Each of ``quantities`` ((n, 3) per taxel: forces in N, tip displacements in mm) as read at ``t_ns``, the
        hysteresis set by each taxel's normal load ``normal_n`` (n,) N; advances the state (once per sample, in time
        order, always the same quantities)."""
        f = np.maximum(np.asarray(normal_n, dtype=np.float64), 0.0)
        out = [np.asarray(q, dtype=np.float64) for q in quantities]
        if self.hysteresis_fraction > 0:
            fs = self.full_scale_n
            self.direction = np.clip(self.direction - (f - self.previous_n) / (self.switch_fraction * fs), -1.0, 1.0)
            u = np.minimum(f / fs, 1.0)
            factor = 1.0 + self.direction * 2.0 * self.hysteresis_fraction * (1.0 - u)
            out = [q * factor[:, None] for q in out]
        self.previous_n = f
        if self.creep_fraction > 0:
            dt = 0.0 if self.t_ns is None else max(0.0, (t_ns - self.t_ns) * 1e-9)
            decay = math.exp(-dt / self.creep_tau_s)
            if not self.retarded:
                self.retarded = [np.zeros_like(q, dtype=np.float64) for q in quantities]
            for i, q in enumerate(quantities):
                self.retarded[i] = q + (self.retarded[i] - q) * decay
                out[i] = out[i] + self.creep_fraction * self.retarded[i]
        self.t_ns = t_ns
        return out


class RandomWalk:
    """A zero that wanders: each channel a Wiener process of ``sigma`` (units per sqrt(s)), stepped at each sample
    from the time since the last one; its normals come from ``normals`` (the model's own stream)."""

    def __init__(self, shape: tuple[int, ...], sigma_per_sqrt_s: np.ndarray | float) -> None:
        self.value = np.zeros(shape)
        self.sigma = sigma_per_sqrt_s
        self.t_ns: int | None = None

    def step(self, t_ns: int, normals: np.ndarray) -> np.ndarray:
        if self.t_ns is not None and t_ns > self.t_ns:
            dt = (t_ns - self.t_ns) * 1e-9
            self.value = self.value + self.sigma * math.sqrt(dt) * normals.reshape(self.value.shape)
        self.t_ns = t_ns if self.t_ns is None else max(self.t_ns, t_ns)
        return self.value


# ---- the printed object and the mount ----------------------------------------------------------------------------


def print_seed(seed: int, object_id: str) -> list[int]:
    """Seed of one printed object's dimensional error: one per object (one print), whatever presses it."""
    return [seed, 6, zlib.crc32(object_id.encode())]


def mount_seed(seed: int, object_id: str, sensor: str, rotation_deg: float) -> list[int]:
    """Seed of the sensor's mounting error in one session (the sensor is swapped between sessions)."""
    return [seed, 7, zlib.crc32(object_id.encode()), zlib.crc32(sensor.encode()), round(rotation_deg * 1000) % 2**32]


def printed_object(obj: ObjectSpec, rng: np.random.Generator, tolerance_mm: float = PRINT_TOLERANCE_MM) -> ObjectSpec:
    """``obj`` as one FDM print of it: the outline offset along its radius by ``d`` (sd ``tolerance_mm / 2``) and,
    for a polygon, scaled per axis by ``1 + e`` (sd ``tolerance_mm / 2`` over its mean radius); a circle keeps its
    exact form (the scene computes it as a circle) and takes the size error alone."""
    sd = tolerance_mm / 2.0
    offset_mm = float(rng.standard_normal() * sd)
    outer = np.asarray(obj.outer_mm, dtype=np.float64)
    inner = np.asarray(obj.inner_mm, dtype=np.float64)
    mean_radius = float(np.mean(np.linalg.norm(outer, axis=1)))
    scale = 1.0 + rng.standard_normal(2) * sd / mean_radius
    if obj.radius_mm is not None:
        scale = np.ones(2)

    def apply(points: np.ndarray) -> np.ndarray:
        if len(points) == 0:
            return points
        radius = np.linalg.norm(points, axis=1, keepdims=True)
        unit = points / np.where(radius > 0, radius, 1.0)
        return points * scale + offset_mm * unit

    radius_mm = None if obj.radius_mm is None else obj.radius_mm + offset_mm
    return dataclasses.replace(obj, outer_mm=apply(outer), inner_mm=apply(inner), radius_mm=radius_mm)


def mount_offset_mm(rng: np.random.Generator, sd_mm: float = MOUNT_OFFSET_SD_MM) -> float:
    """This mounting's extra offset of the pad's centre from the tool axis, along the pad (mm)."""
    return float(rng.standard_normal() * sd_mm)
