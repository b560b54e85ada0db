"""Stateful device objects that own a transport (CAN bus, serial port, WebSocket, RTDE) and a codec.

Nothing here hard-codes a port: serial drivers take a pyserial URL, CAN drivers take a ``can.BusABC``.
Frames carry a measured host timestamp from an injectable clock (monotonic on hardware, virtual on the simulated rig).
"""
