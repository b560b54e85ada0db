"""The press strategies, one module each, behind the interface of ``unitac_rig/collection/strategy.py`` and named in
the table of ``unitac_rig/rig/strategies.py``."""
