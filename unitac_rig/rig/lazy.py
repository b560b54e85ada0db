"""Objects named by import path (``"package.module:attribute"``) and imported only when first used.

The backend table and the sensor registry name simulator code this way, as python-can's interface table names its
backends, so ``unitac_rig.rig`` never imports ``unitac_rig.sim`` (the import contract in ``pyproject.toml``).
"""

from __future__ import annotations

import importlib


def load(path: str) -> object:
    """The attribute ``path`` names, importing its module on first use."""
    module_name, _, attribute = path.partition(":")
    return getattr(importlib.import_module(module_name), attribute)
