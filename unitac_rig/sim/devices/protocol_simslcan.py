"""pyserial URL ``simslcan://NAME``: the port of a simulated SLCAN (Lawicel ASCII) USB-CAN adapter."""

from unitac_rig.sim.devices.serial_port import SimSerialPort


class Serial(SimSerialPort):
    SCHEME = "simslcan"
