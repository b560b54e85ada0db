"""The press-strategy table: every name a rig file's ``press.strategy`` may take -> the strategy, by import path.

The strategies live in ``unitac_rig/collection/strategies/`` (one module each, behind the interface of
``collection/strategy.py``); this table names them as ``"module:attribute"`` and they are imported when a press first
uses one (``rig/lazy.py``), as the backend table names the simulated rig, so the rig seam never imports the
collection room. The rig file's choice is validated against this table; adding a strategy is its module and one line
here (docs/architecture.md, "Adding a press strategy").
"""

from __future__ import annotations

PRESS_STRATEGIES: dict[str, str] = {
    "guarded": "unitac_rig.collection.strategies.guarded:GUARDED",
    "two-phase": "unitac_rig.collection.strategies.two_phase:TWO_PHASE",
    "force-ramp": "unitac_rig.collection.strategies.force_ramp:FORCE_RAMP",
}


def known_strategy(name: str) -> str:
    """``name`` if it is registered, else ValueError listing the registered ones (pydantic names the field)."""
    if name not in PRESS_STRATEGIES:
        raise ValueError(f"unknown press strategy {name!r} (use one of: {', '.join(PRESS_STRATEGIES)})")
    return name
