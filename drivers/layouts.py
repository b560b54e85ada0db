"""The tactile sensor layouts this package has drivers for: taxel grids, pitches, units and axis conventions.

Conventions used everywhere in the project (drivers, simulator, recorder, learning):

* A frame is an array of shape ``(n_taxels, 3)``; taxel ``i`` sits at grid ``(row, col) = divmod(i, cols)``.
* Looking at the sensing surface from the object: column index grows along +x (horizontal, across the press),
  row index grows along -y (row 0 is the top row; +y runs up the prism axis). z points out of the pad toward the
  object, and a compressive (pushing) normal load is positive z.
* ``units`` is what the wire carries: raw 16-bit counts for the uSkin, newtons (and millimetres for the pillar
  displacements) for the PapillArray.

Drivers declare their layout before connecting (``driver.layout``), so a recorder can size its datasets up front.
The application looks a layout up by sensor name in its sensor registry (``unitac_rig.rig.sensors``), which names
these constants; this module keeps no list of its own.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class SensorLayout:
    """Geometry and units of one tactile sensor model."""

    name: str
    model: str
    rows: int
    cols: int
    pitch_mm: float
    units: str  # "counts" or "N"
    has_displacement: bool
    description: str

    @property
    def n_taxels(self) -> int:
        return self.rows * self.cols

    @property
    def frame_shape(self) -> tuple[int, int]:
        return (self.n_taxels, 3)

    def taxel_xy_mm(self) -> np.ndarray:
        """Taxel centres, shape (n_taxels, 2), in mm, origin at the pad centre (x right, y up)."""
        rows, cols = np.divmod(np.arange(self.n_taxels), self.cols)
        x = (cols - (self.cols - 1) / 2.0) * self.pitch_mm
        y = ((self.rows - 1) / 2.0 - rows) * self.pitch_mm
        return np.stack([x, y], axis=1).astype(np.float64)

    def to_grid(self, frame: np.ndarray) -> np.ndarray:
        """Reshape ``(..., n_taxels, 3)`` to ``(..., rows, cols, 3)``."""
        return np.asarray(frame).reshape(*np.shape(frame)[:-2], self.rows, self.cols, 3)


USKIN = SensorLayout(
    name="uskin",
    model="XELA uSkin uSPa46",
    rows=4,
    cols=6,
    pitch_mm=7.25,
    units="counts",
    has_displacement=False,
    description="4x6 three-axis Hall-effect taxels under a continuous elastic skin, raw 16-bit counts",
)

PAPILLARRAY = SensorLayout(
    name="papillarray",
    model="Contactile PapillArray v2 (3x3)",
    rows=3,
    cols=3,
    pitch_mm=7.0,
    units="N",
    has_displacement=True,
    description="3x3 optical pillars, centre pillar proud; forces in N and tip displacements in mm",
)
