"""The one figure helper: every figure the library draws (learning reports, stability, benchmarks, simulator docs).

Figures are :class:`matplotlib.figure.Figure` objects on their own Agg canvas (:func:`new_figure`), never pyplot, and
:func:`save_figure` writes them: nothing touches matplotlib's global backend or pyplot's figure registry, so library
code works without a display and leaves an interactive session (a notebook, a user's own pyplot) as it was.
"""

from __future__ import annotations

from pathlib import Path
from typing import Literal

import numpy as np
from matplotlib.axes import Axes
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.cm import ScalarMappable
from matplotlib.figure import Figure

from drivers.layouts import SensorLayout
from unitac_rig.errors import DataError


def draw_taxel_map(
    ax: Axes,
    layout: SensorLayout,
    frame: np.ndarray,
    *,
    vmin: float | None = None,
    vmax: float | None = None,
    title: str = "",
    arrow_scale: float | None = None,
    cmap: str = "viridis",
) -> ScalarMappable:
    """Draw one tactile frame as the paper's reconstruction figure: a cell per taxel, colour = normal force (z),
    an arrow from each cell's centre for the shear (x, y).

    ``frame``: (n_taxels, 3) in any units (N, baseline-removed counts...), layout order; cells sit at the taxel
    positions in mm (x right, y up, as seen from the object). ``arrow_scale``: frame units per mm of arrow; by
    default the largest shear draws 0.45 pitch long. Returns the cell mappable, for a colour bar.
    """
    values = np.asarray(frame, dtype=np.float64)
    if values.shape != layout.frame_shape:
        raise DataError(
            f"frame shape {values.shape} does not match {layout.name} {layout.frame_shape}",
            hint="pass one frame in layout order, shape (n_taxels, 3)",
        )
    grid = layout.to_grid(values)
    pitch = layout.pitch_mm
    half_w = layout.cols * pitch / 2
    half_h = layout.rows * pitch / 2
    x_edges = np.linspace(-half_w, half_w, layout.cols + 1)
    y_edges = np.linspace(half_h, -half_h, layout.rows + 1)  # row 0 on top
    mesh = ax.pcolormesh(
        x_edges, y_edges, grid[..., 2], cmap=cmap, vmin=vmin, vmax=vmax, edgecolors="white", linewidth=0.8
    )
    xy = layout.taxel_xy_mm()
    shear = values[:, :2]
    longest = float(np.max(np.hypot(shear[:, 0], shear[:, 1]))) if len(shear) else 0.0
    if arrow_scale is None:
        arrow_scale = longest / (0.45 * pitch) if longest > 0 else 1.0
    if longest > 0:
        ax.quiver(
            xy[:, 0],
            xy[:, 1],
            shear[:, 0],
            shear[:, 1],
            angles="xy",
            scale_units="xy",
            scale=arrow_scale,
            color="red",
            width=0.012,
            headwidth=3.5,
            zorder=3,
        )
    ax.scatter(xy[:, 0], xy[:, 1], s=4, color="white", zorder=2)
    ax.set_xlim(-half_w, half_w)
    ax.set_ylim(-half_h, half_h)
    ax.set_aspect("equal")
    ax.set_xticks([])
    ax.set_yticks([])
    if title:
        ax.set_title(title, fontsize=8)
    return mesh


def new_figure(
    width_in: float, height_in: float, dpi: int = 110, *, layout: Literal["constrained", "tight"] = "constrained"
) -> Figure:
    """A pyplot-free figure (Agg canvas attached), laid out when saved; add axes with ``fig.subplots``."""
    fig = Figure(figsize=(width_in, height_in), dpi=dpi)
    FigureCanvasAgg(fig)
    fig.set_layout_engine(layout)
    return fig


def save_figure(fig: Figure, path: Path, dpi: float | None = None) -> Path:
    """Write ``fig`` as PNG (at the figure's dpi unless ``dpi`` is given), creating the folder; returns the path."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi="figure" if dpi is None else dpi)
    return path
