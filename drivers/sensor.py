"""The tactile-sensor seam shared by every sensor driver (uSkin over CAN or xela_server, PapillArray over serial).

A driver owns one transport and one codec. Two ways to get frames, one decode path:

* ``poll()`` drains whatever the transport holds right now and decodes it on the caller's thread (lockstep use on the
  simulated rig, where the caller advances a virtual clock and then polls, so runs are deterministic);
* ``start_reader()`` runs that same pump on a background thread (hardware), and ``poll()`` then returns the frames the
  thread has queued since the last call.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Protocol, runtime_checkable

import numpy as np

from drivers.frames import TactileFrame
from drivers.layouts import SensorLayout


@dataclass
class SensorHealth:
    """Counters a driver keeps while it runs; all monotonic except ``last_frame_ns``."""

    frames: int = 0
    invalid_frames: int = 0  # frames flagged because a taxel was missing or stale
    sequence_gaps: int = 0  # frames lost according to the device counter
    checksum_errors: int = 0
    bytes_dropped: int = 0  # garbage skipped while resynchronising
    stalls: int = 0  # times no frame arrived within the stall timeout
    reconnects: int = 0
    implausible_frames: int = 0  # passed the link's own check, but hold values the sensor cannot produce
    link_check: str = ""  # what the link's own integrity check cannot catch, where the driver knows
    last_frame_ns: int | None = None
    saturated_taxels: list[int] = field(default_factory=list)
    dead_taxels: list[int] = field(default_factory=list)

    def as_dict(self) -> dict[str, Any]:
        return {k: (list(v) if isinstance(v, list) else v) for k, v in self.__dict__.items()}


@dataclass(frozen=True)
class TareRecord:
    """A tare (bias) taken while unloaded: the per-taxel baseline in the layout's units and how it was taken."""

    baseline: np.ndarray  # (n_taxels, 3)
    n_frames: int
    host_t_ns: int
    method: str  # e.g. "host-median" or "device-bias+host-median"
    spread: float  # max per-channel std over the tare window, layout units


@runtime_checkable
class TactileSensor(Protocol):
    layout: SensorLayout

    def connect(self) -> None:
        """Open the transport, start the device streaming. Raises DeviceNotFound / DeviceTimeout."""
        ...

    def disconnect(self) -> None:
        """Stop streaming, stop the reader thread, close the transport. Safe to call more than once."""
        ...

    def poll(self) -> list[TactileFrame]:
        """Return every frame completed since the last call (never blocks)."""
        ...

    def start_reader(self) -> None: ...

    def stop_reader(self) -> None: ...

    def tare(self, frames: list[TactileFrame]) -> TareRecord:
        """Take a baseline from frames recorded while unloaded (PapillArray also sends the device bias)."""
        ...

    def health(self) -> SensorHealth: ...

    def identity(self) -> dict[str, Any]:
        """What is known about the connected device (model, transport, firmware map, controller id)."""
        ...
