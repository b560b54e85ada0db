"""``press.rest_s``: each press rests that long in free air at the stand-off before its tare, the arm still, so the
elastomer recovers and the session keeps the paper's pace; the press itself is unchanged."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from unitac_rig.collection.session import collect_session
from unitac_rig.errors import ConfigError
from unitac_rig.rig.config import parse_rig_config
from unitac_rig.rig.objects import get_object
from unitac_rig.sim.fast_rig import SimRig
from unitac_rig.storage.reader import read_presses
from unitac_rig.storage.recorder import session_path


def _session(tmp_path: Path, rest_s: float) -> list:  # type: ignore[type-arg]
    config = parse_rig_config(
        {"press": {"angle_count": 3, "angle_min_deg": -2.0, "angle_max_deg": 2.0, "rest_s": rest_s}}
    )
    with SimRig(config, seed=0) as rig:
        outcome = collect_session(rig, get_object("hex_pla"), "uskin", tmp_path)
    assert outcome.stopped is None
    return sorted(read_presses(session_path(tmp_path, "hex_pla", "uskin")), key=lambda p: float(p.tactile_t_s[0]))


def test_a_rest_spaces_the_presses_by_it_and_leaves_each_press_as_it_was(tmp_path: Path) -> None:
    quick, rested = _session(tmp_path / "quick", 0.0), _session(tmp_path / "rested", 3.0)
    gaps_quick = np.diff([float(p.tactile_t_s[0]) for p in quick])
    gaps_rested = np.diff([float(p.tactile_t_s[0]) for p in rested])
    assert gaps_rested == pytest.approx(gaps_quick + 3.0, abs=0.3)
    for a, b in zip(quick, rested, strict=True):
        assert b.status == a.status == "complete"
        peak_a, peak_b = float(np.max(a.press_force_n)), float(np.max(b.press_force_n))
        assert peak_b == pytest.approx(peak_a, abs=0.5)  # the same press after the rest
        assert float(np.max(b.press_force_n)) < 12.0


def test_a_rest_is_bounded_in_the_rig_file() -> None:
    with pytest.raises(ConfigError, match="rest_s"):
        parse_rig_config({"press": {"rest_s": 120.0}})
    with pytest.raises(ConfigError, match="rest_s"):
        parse_rig_config({"press": {"rest_s": -1.0}})
