"""The simulated rig: a digital twin of the press rig that speaks the real wire formats into real transports.

Shipped in the package (not in tests) because users run it too: with no rig file, every command runs here.
"""

import serial as _serial

# Make the simulated serial devices reachable through pyserial URLs (simpapill://NAME, simslcan://NAME).
if "unitac_rig.sim.devices" not in _serial.protocol_handler_packages:
    _serial.protocol_handler_packages.append("unitac_rig.sim.devices")
