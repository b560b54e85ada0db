"""Typed, timestamped samples that drivers hand to the application."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass(frozen=True, slots=True)
class TactileFrame:
    """One complete reading of a tactile sensor.

    ``values`` has shape ``(n_taxels, 3)`` in the layout's units (uSkin counts, PapillArray N), in layout order.
    ``host_t_ns`` is the host clock when the frame was completed (never synthesised from an index).
    ``seq`` and ``device_t_us`` are the device's own counter and timestamp where the protocol has them.
    ``valid`` is False when any taxel was missing or stale; ``stale_mask`` then says which.
    ``calibrated_n`` is a device-side force estimate (n_taxels, 3) in N where the device sends one (xela_server
    with its calibration module on), else None.
    """

    sensor: str
    host_t_ns: int
    values: np.ndarray
    seq: int | None = None
    device_t_us: int | None = None
    displacement_mm: np.ndarray | None = None
    valid: bool = True
    stale_mask: np.ndarray | None = field(default=None, repr=False)
    calibrated_n: np.ndarray | None = field(default=None, repr=False)
