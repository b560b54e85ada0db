"""Synthetic sensor signals (:class:`~unitac_rig.sim.sensor_signals.SignalSource`): a repeating press with noise.

They stand in for the press scene when a simulated device needs *something* to send (tests, ``probe --simulated``).
The contact is a synthetic load profile (a sin^2 press of ``peak_load_n`` spread over the pad by a Gaussian
footprint, slightly off-axis), and the reading is the sensor's own output model (:mod:`unitac_rig.sim.sensor_models`:
uSkin counts with baselines, gains and cross-talk, PapillArray N and mm with offsets), so there is one definition of
what a sensor reports. The model's static parts are drawn from ``[seed, 0xBA5E]`` and each sample's noise from
``[seed, t_ns]``: every sample is a pure function of ``(seed, t_ns)``, so a device that samples the same instants
sends the same values whatever thread or timing mode it runs in.
"""

from __future__ import annotations

import math
import threading
from dataclasses import dataclass
from functools import cached_property

import numpy as np

from drivers.layouts import SensorLayout
from unitac_rig.sim.scene import TaxelLoads
from unitac_rig.sim.sensor_models import PapillArrayModel, PapillArrayParams, UskinModel, UskinParams, model_for
from unitac_rig.sim.sensor_signals import SensorSample, SignalSource


def press_load_n(t_ns: int, *, period_s: float, peak_load_n: float, rest_fraction: float) -> float:
    """Total normal load (N) of a repeating press: ``rest_fraction`` of each period unloaded, then a sin^2 bump."""
    if peak_load_n <= 0 or period_s <= 0:
        return 0.0
    phase = (t_ns / 1e9 / period_s) % 1.0
    if phase < rest_fraction:
        return 0.0
    bump_phase = (phase - rest_fraction) / (1.0 - rest_fraction)
    return peak_load_n * math.sin(math.pi * bump_phase) ** 2


@dataclass(frozen=True)
class PressSource:
    """A flat press on ``layout``'s pad, read through the sensor's output model.

    ``peak_load_n=0`` gives an unloaded, noisy sensor (tare tests, idle probes). ``params`` replaces the model's
    parameters (e.g. ``PapillArrayParams(noise_mm=0.0)``); its type must fit the layout's units.
    """

    layout: SensorLayout
    seed: int = 0
    period_s: float = 2.0
    peak_load_n: float = 10.0
    rest_fraction: float = 0.5
    shear_ratio: float = 0.15  # tangential load per N of normal load (a slightly off-axis press)
    footprint_sigma_mm: float = 7.0  # of the Gaussian share of the load around the pad centre
    params: UskinParams | PapillArrayParams | None = None

    @cached_property
    def model(self) -> UskinModel | PapillArrayModel:
        """The sensor's output model, its static parts drawn from the seed (the imperfections off: no state)."""
        rng = np.random.default_rng([self.seed, 0xBA5E])
        if self.params is None:
            return model_for(self.layout, rng)
        if isinstance(self.params, UskinParams):
            return UskinModel(self.params, rng, layout=self.layout)
        return PapillArrayModel(self.params, rng, layout=self.layout)

    @cached_property
    def _footprint(self) -> np.ndarray:
        xy = self.layout.taxel_xy_mm()
        weights = np.exp(-0.5 * np.sum(xy**2, axis=1) / self.footprint_sigma_mm**2)
        return weights / weights.sum()

    def loads(self, t_ns: int) -> TaxelLoads:
        """What each taxel feels at ``t_ns``: forces (N) and, for pillars, tips displaced by force / stiffness."""
        load = press_load_n(
            t_ns, period_s=self.period_s, peak_load_n=self.peak_load_n, rest_fraction=self.rest_fraction
        )
        fz = load * self._footprint
        forces = np.stack([self.shear_ratio * fz, -0.5 * self.shear_ratio * fz, fz], axis=1)
        if not self.layout.has_displacement:
            return TaxelLoads(forces, None)
        stiffness = np.asarray(getattr(self.model.params, "calibration_n_per_mm", (1.0, 1.0, 1.0)))
        return TaxelLoads(forces, forces / stiffness)

    def sample(self, t_ns: int) -> SensorSample:
        return self.model.sample(self.loads(t_ns), t_ns, noise_rng=np.random.default_rng([self.seed, t_ns]))


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
