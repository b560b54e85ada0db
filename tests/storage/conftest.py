"""The storage tests reuse the robustness helpers (CLI runner, one-line errors, synthetic sessions)."""

from __future__ import annotations

import sys
from pathlib import Path

_ROBUSTNESS = str(Path(__file__).resolve().parents[1] / "robustness")
if _ROBUSTNESS not in sys.path:
    sys.path.insert(0, _ROBUSTNESS)
