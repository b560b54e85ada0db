"""The real-time twin: a simulated UR controller the real ur_rtde clients drive, and the whole rig around it.

* :class:`ControllerTwin` (:mod:`~unitac_rig.sim.twin.handle`): a UR e-Series controller in its own process on one
  loopback address (dashboard 29999, script port 30003, RTDE 30004), emulating ur_rtde's control script, with the
  fast twin's arm physics and contact scene inside, in real time at 500 Hz; ground truth and test hooks.
* :mod:`~unitac_rig.sim.twin.rig` (``unitac-rig twin``): the controller twin plus the sensors, served on loopback
  network transports from the same scene, and the rig file that points the hardware code path at them.

See docs/simulator.md, "Real-time twin".
"""

from unitac_rig.sim.twin.handle import (
    AddressTaken,
    ControllerTwin,
    address_free,
    first_free_loopback,
    start_twin_on_free_loopback,
)
from unitac_rig.sim.twin.params import ControllerParams, SceneSpec
from unitac_rig.sim.twin.truth import TwinTruth

__all__ = [
    "AddressTaken",
    "ControllerParams",
    "ControllerTwin",
    "SceneSpec",
    "TwinTruth",
    "address_free",
    "first_free_loopback",
    "start_twin_on_free_loopback",
]
