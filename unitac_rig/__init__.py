"""unitac-rig: collect cross-sensor tactile datasets on a UR5e press rig and learn the UniTac-NV representation."""

__version__ = "0.1.0"
