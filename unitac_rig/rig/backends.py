"""The backend table: which :class:`~unitac_rig.rig.base.Rig` a rig file opens.

Backends are named by import path and imported only when chosen (python-can's interface registry does the same),
so the seam never imports a backend and nothing but this table (and the CLI's ``--simulated`` paths) reaches
``unitac_rig.sim``. The import-layer contract in ``pyproject.toml`` checks that.
"""

from __future__ import annotations

import importlib

from unitac_rig.rig.base import Rig
from unitac_rig.rig.config import RigConfig

#: backend name -> "module:Class". ``sim`` is the fast lockstep twin; ``hardware`` the real devices (or the
#: real-time twin, which is served on loopback addresses and looks like hardware to this code).
RIG_BACKENDS: dict[str, str] = {
    "sim": "unitac_rig.sim.fast_rig:SimRig",
    "hardware": "unitac_rig.rig.hardware:HardwareRig",
}


def backend_class(name: str) -> type[Rig]:
    """The Rig class registered under ``name`` (imported on first use)."""
    module_name, _, class_name = RIG_BACKENDS[name].partition(":")
    cls = getattr(importlib.import_module(module_name), class_name)
    assert isinstance(cls, type) and issubclass(cls, Rig)
    return cls


def open_rig(config: RigConfig, *, seed: int = 0) -> Rig:
    """The hardware rig the config describes, or the simulated rig when it names no arm."""
    if config.simulated:
        return backend_class("sim")(config, seed=seed)  # type: ignore[call-arg]
    return backend_class("hardware")(config)  # type: ignore[call-arg]
