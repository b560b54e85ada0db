"""pyserial URL ``simpapill://NAME``: the port of a simulated PapillArray hub (unitac_rig.sim.devices)."""

from unitac_rig.sim.devices.serial_port import SimSerialPort


class Serial(SimSerialPort):
    SCHEME = "simpapill"
