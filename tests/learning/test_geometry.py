"""Contact-geometry ground truth cut from outlines, on shapes whose profiles can be worked by hand."""

from __future__ import annotations

import math

import numpy as np
import pytest

from unitac_rig.learning.contact_geometry import OutlineGeometry, local_depth_profile, profile_offsets_mm, surface_frame


def test_profile_is_11_points_over_14_mm() -> None:
    offsets = profile_offsets_mm()
    assert offsets.tolist() == pytest.approx([-7.0 + 1.4 * i for i in range(11)])


def test_circle_profile_is_the_sagitta() -> None:
    # r = 25 mm: at 7 mm across, depth = 25 - sqrt(625 - 49) = 25 - 24 = 1 mm
    angles = np.linspace(0, 2 * np.pi, 3600, endpoint=False)
    circle = 25.0 * np.stack([np.cos(angles), np.sin(angles)], axis=1)
    u = np.array([0.0, -1.0])
    depths = local_depth_profile(circle, u, 25.0 * u, np.array([-7.0, 0.0, 3.0, 7.0]))
    expected = [1.0, 0.0, 25 - math.sqrt(625 - 9), 1.0]
    assert depths.tolist() == pytest.approx(expected, abs=2e-3)


def test_flat_face_is_zero_and_a_hexagon_vertex_falls_away_at_tan_30() -> None:
    square = np.array([[20.0, -20.0], [20.0, 20.0], [-20.0, 20.0], [-20.0, -20.0]])
    u = np.array([0.0, 1.0])
    assert local_depth_profile(square, u, np.array([0.0, 20.0]), profile_offsets_mm()) == pytest.approx(np.zeros(11))
    # regular hexagon, circumradius 25, a vertex on +x; pressing onto that vertex from +x:
    # the two walls leave the vertex 30 degrees off the pad, so depth = |x| * tan(30 deg)
    hexagon = 25.0 * np.array([[math.cos(math.radians(a)), math.sin(math.radians(a))] for a in range(0, 360, 60)])
    depths = local_depth_profile(hexagon, np.array([1.0, 0.0]), np.array([25.0, 0.0]), np.array([-7.0, 0.0, 3.5]))
    assert depths.tolist() == pytest.approx([7 * math.tan(math.pi / 6), 0.0, 3.5 * math.tan(math.pi / 6)])


def test_profile_axis_is_the_pads_column_direction() -> None:
    # the rig presses along d = -u and the tool x axis is (-d_y, d_x) = (u_y, -u_x)
    x_hat, u = surface_frame(np.array([0.6, -0.8]))
    assert x_hat.tolist() == pytest.approx([-0.8, -0.6])
    assert float(x_hat @ u) == pytest.approx(0.0)


def test_catalogue_irregular_prism_has_its_80_degree_corner_at_minus_x() -> None:
    outline = OutlineGeometry.from_catalogue("irregular_pla")
    # rotation 90 turns the 80-degree corner V3 (-25, 0) toward the pad at angle 0 (pad side -y in the base frame)
    u, origin = outline.contact(0.0, 90.0)
    assert u.tolist() == pytest.approx([-1.0, 0.0])
    assert origin.tolist() == pytest.approx([-25.0, 0.0], abs=1e-6)
    depths = outline.profiles(np.array([0.0]), np.array([90.0]), np.array([-7.0, 7.0]))[0]
    # both walls leave the tip at 90 - 40 = 50 degrees off the pad: depth = 7 * tan(50 deg)
    assert depths.tolist() == pytest.approx([7 * math.tan(math.radians(50))] * 2, rel=1e-6)
