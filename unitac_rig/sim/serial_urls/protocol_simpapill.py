"""pyserial URL ``simpapill://NAME``: the port of a simulated PapillArray hub (unitac_rig.sim.devices)."""

from unitac_rig.sim.serial_urls import SimSerialPort


class Serial(SimSerialPort):
    SCHEME = "simpapill"
