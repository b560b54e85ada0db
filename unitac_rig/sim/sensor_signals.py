"""The seam between what a simulated sensor *feels* and the simulated device that *sends* it.

A :class:`SignalSource` answers "what would the sensor read at time t"; a simulated device (XELA controller,
xela_server, PapillArray hub) calls it once per sample period and encodes the answer into real wire bytes.
Sources: synthetic test signals, and the press scene (``unitac_rig.sim.scene``) driven by the simulated arm's pose.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import numpy as np


@dataclass(frozen=True, slots=True)
class SensorSample:
    """One sample in wire units, before encoding.

    ``values``: (n_taxels, 3); uSkin raw counts (float; the encoder rounds and clips to 0..65535), PapillArray N.
    ``displacement_mm``: (n_taxels, 3) pillar tip displacements for the PapillArray, else None.
    """

    values: np.ndarray
    displacement_mm: np.ndarray | None = None


class SignalSource(Protocol):
    def sample(self, t_ns: int) -> SensorSample:
        """The reading at time ``t_ns`` (the device's clock, ns)."""
        ...
