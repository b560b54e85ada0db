"""Simulated sensor devices that speak the real wire formats into real transports (see each module)."""

from unitac_rig.sim.devices.papillarray import SimPapillArrayHub
from unitac_rig.sim.devices.xela_can import SimSlcanAdapter, SimXelaController, counts_from_sample
from unitac_rig.sim.devices.xela_server import SimXelaServer

__all__ = ["SimPapillArrayHub", "SimSlcanAdapter", "SimXelaController", "SimXelaServer", "counts_from_sample"]
