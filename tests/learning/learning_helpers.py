"""Test helpers for the learning tests: small synthetic paired data and session files written through the
recorder's real API (so ``unitac-rig train --data`` reads them back through ``unitac_rig.storage.reader``)."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np

from drivers.layouts import PAPILLARRAY, USKIN, SensorLayout
from unitac_rig.learning.synthetic_data import synthetic_matched_sets
from unitac_rig.storage.extraction import ExtractionSettings, extract_press
from unitac_rig.storage.press_record import PressRecord, press_id
from unitac_rig.storage.reader import MatchedSet
from unitac_rig.storage.recorder import SessionWriter

SMALL_OBJECTS = ("circle_pla", "hex_tpu", "irregular_pla")
SMALL_ANGLES = tuple(float(a) for a in range(-45, 46, 9))  # 11 approach angles
SMALL_TARGETS = (4.0, 5.5, 7.0, 8.5, 10.0)


def small_sets(
    layouts: Sequence[SensorLayout] = (USKIN, PAPILLARRAY), objects: Sequence[str] = SMALL_OBJECTS, seed: int = 0
) -> list[MatchedSet]:
    """11 angles x 5 targets per object (x 4 rotations for the irregular prism), synthetic contacts."""
    return synthetic_matched_sets(objects, layouts, angles_deg=SMALL_ANGLES, targets_n=SMALL_TARGETS, seed=seed)


def write_sessions(data_dir: Path, sets: Sequence[MatchedSet]) -> None:
    """One session file per set: each press is a 5 N/s force ramp at 500 Hz with one tactile frame at each
    target's crossing, and the recorder's own extraction picks those frames back."""
    for matched in sets:
        writer = SessionWriter(
            data_dir,
            matched.object_id,
            matched.sensor,
            {"object": matched.object_id, "sensor": matched.sensor, "simulated": True},
        )
        directions = sorted(set(zip(matched.rotation_deg.tolist(), matched.angle_deg.tolist(), strict=True)))
        for rotation, angle in directions:
            rows = np.flatnonzero((matched.rotation_deg == rotation) & (matched.angle_deg == angle))
            rows = rows[np.argsort(matched.target_n[rows])]
            targets = matched.target_n[rows]
            robot_t = np.arange(0.0, 2.2, 0.002)
            force = 5.0 * robot_t
            tactile_t = targets / 5.0
            extraction = extract_press(
                robot_t, force, tactile_t, settings=ExtractionSettings(targets_n=tuple(float(t) for t in targets))
            )
            n = len(rows)
            writer.write_press(
                PressRecord(
                    press_id=press_id(rotation, angle),
                    rotation_deg=rotation,
                    angle_deg=angle,
                    status="complete",
                    reason="force",
                    robot_t_s=robot_t,
                    robot_force=np.zeros((robot_t.size, 6)),
                    robot_pose=np.zeros((robot_t.size, 6)),
                    press_force_n=force,
                    tactile_t_s=tactile_t,
                    tactile_values=matched.values[rows],
                    tactile_seq=np.arange(n),
                    tactile_device_t_us=np.full(n, -1),
                    tactile_valid=np.ones(n, bool),
                    tare_baseline=np.zeros(matched.values.shape[1:]),
                    extraction=extraction,
                )
            )


#: Prepended to a script run in a fresh interpreter: an import of this project fails there, so an exported model
#: that still needs unitac_rig, drivers or protocols is caught.
REFUSE_PROJECT_IMPORTS = """
import sys

class Refuse:
    def find_spec(self, name, path=None, target=None):
        if name.split(".")[0] in ("unitac_rig", "drivers", "protocols"):
            raise ImportError("the exported model must not need " + name)
        return None

sys.meta_path.insert(0, Refuse())
"""
