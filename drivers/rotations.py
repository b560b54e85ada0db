"""Rotation-vector helpers for the arm drivers (UR poses are [x, y, z (m), rx, ry, rz (rad, rotation vector)]).

The one implementation: the application (``unitac_rig.rig.poses``, the simulator) uses these too.
"""

from __future__ import annotations

import math

import numpy as np


def rotvec_to_matrix(rotvec: np.ndarray) -> np.ndarray:
    """Rodrigues' formula: rotation vector (rad) to a 3x3 rotation matrix."""
    r = np.asarray(rotvec, dtype=np.float64)
    theta = float(np.linalg.norm(r))
    if theta < 1e-12:
        return np.eye(3)
    k = r / theta
    kx = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + math.sin(theta) * kx + (1 - math.cos(theta)) * (kx @ kx)


def matrix_to_rotvec(m: np.ndarray) -> np.ndarray:
    """Inverse of :func:`rotvec_to_matrix` (robust near 0 and pi)."""
    m = np.asarray(m, dtype=np.float64)
    theta = math.acos(max(-1.0, min(1.0, (float(np.trace(m)) - 1.0) / 2.0)))
    if theta < 1e-9:
        return np.zeros(3)
    if math.pi - theta < 1e-6:
        b = (m + np.eye(3)) / 2.0
        i = int(np.argmax(np.diag(b)))
        return b[:, i] / math.sqrt(b[i, i]) * theta
    axis = np.array([m[2, 1] - m[1, 2], m[0, 2] - m[2, 0], m[1, 0] - m[0, 1]]) / (2 * math.sin(theta))
    return axis * theta


def angle_between(rotvec_a: np.ndarray, rotvec_b: np.ndarray) -> float:
    """Angle (rad) of the rotation taking orientation ``a`` to orientation ``b``."""
    relative = rotvec_to_matrix(rotvec_a).T @ rotvec_to_matrix(rotvec_b)
    return math.acos(max(-1.0, min(1.0, (float(np.trace(relative)) - 1.0) / 2.0)))
