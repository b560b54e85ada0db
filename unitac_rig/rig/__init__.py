"""The rig: the Rig seam, its backends (hardware, simulated), the rig file, the object catalogue and poses."""
