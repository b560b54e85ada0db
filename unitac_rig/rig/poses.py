"""Rig geometry: approach directions, press frames and pose conversions (base frame, metres, radians), in the
conventions that ``rig/objects.py``'s docstring states (the pad comes from u = (sin theta, -cos theta, 0) and presses
along d = -u; tool +z = d, tool y = base +z)."""

from __future__ import annotations

import math

import numpy as np

from drivers.rotations import matrix_to_rotvec, rotvec_to_matrix

__all__ = [
    "approach_direction",
    "matrix_to_rotvec",
    "pose_from",
    "press_force_n",
    "press_rotation",
    "rotvec_to_matrix",
    "tool_z",
]


def approach_direction(angle_deg: float) -> np.ndarray:
    """Unit vector (3,) in the base frame from the object centre toward where the pad comes from."""
    a = math.radians(angle_deg)
    return np.array([math.sin(a), -math.cos(a), 0.0])


def press_rotation(press_dir: np.ndarray) -> np.ndarray:
    """Rotation matrix (3x3, columns = tool x, y, z in base axes) for a horizontal press along ``press_dir``."""
    d = np.asarray(press_dir, dtype=np.float64).copy()
    d[2] = 0.0
    d /= np.linalg.norm(d)
    x = np.array([-d[1], d[0], 0.0])
    y = np.array([0.0, 0.0, 1.0])
    return np.column_stack([x, y, d])


def pose_from(position_m: np.ndarray, rot: np.ndarray) -> np.ndarray:
    """[x, y, z, rx, ry, rz] from a position and a rotation matrix."""
    return np.concatenate([np.asarray(position_m, dtype=np.float64), matrix_to_rotvec(rot)])


def tool_z(pose: np.ndarray) -> np.ndarray:
    """The tool's +z axis (the press direction) in base coordinates."""
    return rotvec_to_matrix(np.asarray(pose)[3:6])[:, 2]


def press_force_n(tcp_force: np.ndarray, press_dir: np.ndarray) -> float:
    """Force along the press (N, positive while pressing): minus the environment's force on the tool along d."""
    return -float(np.dot(np.asarray(tcp_force)[:3], press_dir))
