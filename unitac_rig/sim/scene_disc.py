"""A disc pad against a vertical cylinder: the contact whose force leaves the press axis.

The press scene (:mod:`unitac_rig.sim.scene`) puts the load on the pad's face and caps its shear by friction, fitted
to presses of objects that stand where the rig file says. An object that stands to the side meets the pad's *rim*
instead: the contact normal is then the cylinder's surface normal at the rim, tilted from the press axis, and force
mode (compliant along the press axis only; the arm holds position across it) lets the lateral part grow with the
stiffness. This world gives that contact (frictionless: the worst case for the lateral force, which friction only
lowers), for the misplacement faults of the fault matrix and the tests of the off-axis bound
(collection/safety_check.py):

* the pad is a disc of radius ``pad_radius_mm`` centred on the TCP, its face normal to tool +z (the press
  direction); the cylinder is vertical, radius ``radius_mm``, axis at ``center_m`` (base x, y);
* in the horizontal section through the TCP the pad point nearest the cylinder's axis is the axis' offset across the
  pad clipped to the disc: the face while the axis passes within the disc, the rim beyond;
* the force is ``stiffness`` x penetration along the cylinder's outward normal at that point, its torque about the
  TCP the lever from the TCP to it. Base axes, N and N*m, as :class:`~unitac_rig.sim.world.ContactWorld` says.
"""

from __future__ import annotations

import math

import numpy as np

from unitac_rig.rig.poses import rotvec_to_matrix
from unitac_rig.sim.world import NO_WRENCH, read_only


class DiscPadOnCylinder:
    """A :class:`~unitac_rig.sim.world.ContactWorld`: a disc pad (``pad_radius_mm``) against a vertical cylinder
    (``radius_mm``, axis at ``center_m``, ``stiffness_n_per_mm`` of penetration)."""

    def __init__(
        self,
        center_m: tuple[float, float],
        *,
        radius_mm: float = 25.0,
        stiffness_n_per_mm: float = 10.0,
        pad_radius_mm: float = 10.0,
    ) -> None:
        if not (radius_mm > 0 and stiffness_n_per_mm > 0 and pad_radius_mm >= 0):
            raise ValueError("cylinder radius and stiffness must be > 0, the pad radius >= 0")
        self.center_m = np.array([float(center_m[0]), float(center_m[1])])
        self.radius_m = radius_mm / 1000.0
        self.stiffness_n_per_m = stiffness_n_per_mm * 1000.0
        self.pad_radius_m = pad_radius_mm / 1000.0

    def contact_point(self, tcp_pose: np.ndarray) -> np.ndarray:
        """The pad point (3,) nearest the cylinder's axis, base frame, m."""
        pose = np.asarray(tcp_pose, dtype=np.float64)
        across = rotvec_to_matrix(pose[3:6])[:, 0]
        across_h = np.array([across[0], across[1], 0.0])
        norm = float(np.linalg.norm(across_h))
        across_h = across_h / norm if norm > 1e-9 else across_h
        rel = np.array([self.center_m[0] - pose[0], self.center_m[1] - pose[1], 0.0])
        offset = float(np.clip(rel @ across_h, -self.pad_radius_m, self.pad_radius_m))
        return pose[:3] + across_h * offset

    def wrench_on_tool(self, tcp_pose: np.ndarray) -> np.ndarray:
        pose = np.asarray(tcp_pose, dtype=np.float64)
        point = self.contact_point(pose)
        outward = np.array([point[0] - self.center_m[0], point[1] - self.center_m[1], 0.0])
        distance = float(np.linalg.norm(outward))
        penetration = self.radius_m - distance
        if penetration <= 0.0 or distance < 1e-9:
            return NO_WRENCH
        force = outward / distance * self.stiffness_n_per_m * penetration  # pushes the pad out of the cylinder
        torque = np.cross(point - pose[:3], force)
        return read_only(np.concatenate([force, torque]))

    def tilt_deg(self, tcp_pose: np.ndarray) -> float:
        """Angle (deg) between the contact normal and the press axis at ``tcp_pose`` (0: a face contact)."""
        point = self.contact_point(tcp_pose)
        outward = np.array([point[0] - self.center_m[0], point[1] - self.center_m[1], 0.0])
        press = rotvec_to_matrix(np.asarray(tcp_pose, dtype=np.float64)[3:6])[:, 2]
        cos = -float(outward @ press) / max(float(np.linalg.norm(outward)), 1e-12)
        return math.degrees(math.acos(max(-1.0, min(1.0, cos))))
