"""The backend table: which :class:`~unitac_rig.rig.base.Rig` a rig file opens.

Backends are named by import path and imported only when chosen (python-can's interface registry does the same),
so the seam never imports a backend and nothing but this table, the sensor registry's ``simulated`` entries (also by
path) and the CLI's ``--simulated`` paths reach ``unitac_rig.sim``. The import contract in ``pyproject.toml`` checks
that.
"""

from __future__ import annotations

from unitac_rig.rig.base import Rig
from unitac_rig.rig.config import RigConfig
from unitac_rig.rig.lazy import load

#: backend name -> "module:Class". ``sim`` is the fast lockstep twin; ``hardware`` the real devices (or the
#: real-time twin, which is served on loopback addresses and looks like hardware to this code).
RIG_BACKENDS: dict[str, str] = {
    "sim": "unitac_rig.sim.fast_rig:SimRig",
    "hardware": "unitac_rig.rig.hardware:HardwareRig",
}


def open_rig(config: RigConfig, *, seed: int = 0, imperfections: str | None = None) -> Rig:
    """The hardware rig the config describes, or the simulated rig when it names no arm (each imported on first use).
    ``imperfections``: which of the real sensors' imperfections the simulated rig has (sim/imperfections.py; None:
    all, "none": the clean twin); hardware has its own."""
    backend = load(RIG_BACKENDS["sim" if config.simulated else "hardware"])
    assert isinstance(backend, type) and issubclass(backend, Rig)
    if config.simulated:
        return backend(config, seed=seed, imperfections=imperfections)  # type: ignore[call-arg]
    return backend(config)  # type: ignore[call-arg]
