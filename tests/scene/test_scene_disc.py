"""The disc pad against a cylinder (sim/scene_disc.py): a face contact pushes straight back along the press axis; an
object to the side meets the rim, whose contact normal is the cylinder's, tilted from the press axis by
asin((offset - pad radius) / cylinder radius): the lateral force force mode cannot regulate."""

from __future__ import annotations

import math

import numpy as np
import pytest

from unitac_rig.rig.poses import approach_direction
from unitac_rig.sim.scene import press_pose
from unitac_rig.sim.scene_disc import DiscPadOnCylinder

CENTER = (-0.15, 0.625)


def _pose_at(distance_mm: float) -> np.ndarray:
    """The pad on the 0 deg ray (pressing along base +y), its centre ``distance_mm`` from the nominal axis."""
    return press_pose(0.0, distance_mm, object_center_m=CENTER, height_m=0.2)


def test_a_face_contact_pushes_back_along_the_press_axis_with_the_stiffness() -> None:
    world = DiscPadOnCylinder(CENTER, radius_mm=25.0, stiffness_n_per_mm=10.0, pad_radius_mm=10.0)
    assert not np.any(world.wrench_on_tool(_pose_at(25.5)))  # 0.5 mm short of the surface
    wrench = world.wrench_on_tool(_pose_at(24.0))  # 1 mm in
    press = -approach_direction(0.0)
    assert -float(wrench[:3] @ press) == pytest.approx(10.0, rel=1e-6)
    assert float(np.linalg.norm(wrench[:3] + (wrench[:3] @ press) * -press)) == pytest.approx(0.0, abs=1e-9)
    assert world.tilt_deg(_pose_at(24.0)) == pytest.approx(0.0, abs=1e-6)


@pytest.mark.parametrize(("pad_mm", "offset_mm"), [(2.0, 20.0), (10.0, 20.0), (5.0, 21.0)])
def test_an_object_to_the_side_meets_the_rim_and_the_force_leaves_the_press_axis(
    pad_mm: float, offset_mm: float
) -> None:
    world = DiscPadOnCylinder((CENTER[0] + offset_mm / 1000.0, CENTER[1]), pad_radius_mm=pad_mm)
    tilt = math.asin((offset_mm - pad_mm) / 25.0)
    # the rim point touches once the pad centre is 25 cos(tilt) from the axis along the press; 1 mm deeper along it
    pose = _pose_at(25.0 * math.cos(tilt) - 1.0)
    wrench = world.wrench_on_tool(pose)
    press = -approach_direction(0.0)
    along = -float(wrench[:3] @ press)
    lateral = float(np.linalg.norm(wrench[:3] + along * press))
    # the normal runs from the axis to the rim point: (offset - pad) across, the pad's distance from the axis along
    expected = (offset_mm - pad_mm) / (25.0 * math.cos(tilt) - 1.0)
    assert along > 0 and lateral / along == pytest.approx(expected, rel=1e-6)
    assert world.tilt_deg(pose) == pytest.approx(math.degrees(math.atan(expected)), abs=1e-6)
    assert np.linalg.norm(wrench[3:]) > 0  # the rim is off the TCP: a torque too
