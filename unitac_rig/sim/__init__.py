"""The simulated rig: a digital twin of the press rig that speaks the real wire formats into real transports.

Shipped in the package (not in tests) because users run it too: with no rig file, every command runs here.
"""
