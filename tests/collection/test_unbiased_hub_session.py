"""A PapillArray whose zero has drifted past the SDK's contact threshold since its last bias (hours of a campaign,
a hub powered up cold) still starts its session: the first bias after the port opens is taken in free air at the
stand-off, and every later tare checks for contact against it."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from unitac_rig.collection.session import collect_session
from unitac_rig.rig.config import parse_rig_config
from unitac_rig.rig.objects import get_object
from unitac_rig.sim.fast_rig import SimRig
from unitac_rig.storage.reader import read_presses
from unitac_rig.storage.recorder import session_path


def test_a_session_starts_on_a_hub_whose_zero_drifted_past_the_contact_threshold(tmp_path: Path) -> None:
    config = parse_rig_config({"press": {"angle_count": 3, "angle_min_deg": -2.0, "angle_max_deg": 2.0}})
    with SimRig(config, seed=0) as rig:
        model = rig._models["papillarray"]  # the simulated sensor itself: its zero 0.7 N off on the centre pillar
        model.offset_mm[4, 2] += 0.7 / model.calibration[2]
        outcome = collect_session(rig, get_object("hex_pla"), "papillarray", tmp_path)
    assert outcome.stopped is None and outcome.complete == 3
    presses = read_presses(session_path(tmp_path, "hex_pla", "papillarray"))
    for press in presses:  # every press zeroed: free air reads ~0 on the drifted pillar, not 0.7 N
        assert abs(float(np.asarray(press.tactile_values)[0, 4, 2])) < 0.2
