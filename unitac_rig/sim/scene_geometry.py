"""Geometry of the press scene's 2-D cut: the object's outline seen from the pad along one press ray, and the
prism's bending stiffness. Used by :mod:`unitac_rig.sim.scene` (the rays) and :mod:`unitac_rig.sim.scene_pads`
(the pads' contact); the module docstring of :mod:`unitac_rig.sim.scene` says what is modelled and why."""

from __future__ import annotations

import math

import numpy as np

from unitac_rig.rig.objects import ObjectSpec

# =================================================================================================================
# Geometry of the cut: the outline seen from the pad
# =================================================================================================================


class Section:
    """The outline in pad coordinates for one ray: ``s`` across the pad (mm, TCP at 0), ``n`` toward the object.

    ``front(s)`` is how far the outline reaches toward the pad, relative to the object centre: the surface is at
    ``n = c_n + front(s)`` when the centre is at ``n = c_n``. ``slope`` = d front / ds, ``xi`` = distance along the
    outline to the nearest corner (inf without corners).
    """

    def __init__(self, outline: Outline, x_axis: np.ndarray, z_axis: np.ndarray, c_s: float) -> None:
        self.c_s = c_s
        self.radius = outline.radius
        rel = outline.points
        self.s = rel @ x_axis + c_s
        self.n = rel @ z_axis
        self.corner_to_start = outline.corner_to_start
        self.corner_from_end = outline.corner_from_end
        self.edge_len = outline.edge_len

    def front(self, s: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(front, slope, xi) at pad positions ``s`` (mm); front = +inf where the outline is not in front."""
        s = np.asarray(s, dtype=np.float64)
        if self.radius is not None:
            ds = s - self.c_s
            inside = np.abs(ds) <= self.radius
            root = np.sqrt(np.where(inside, self.radius**2 - ds**2, 1.0))
            front = np.where(inside, -root, np.inf)
            slope = np.where(inside & (root > 0), ds / np.where(root > 0, root, 1.0), 0.0)
            return front, slope, np.full(s.shape, np.inf)
        a_s, a_n = self.s, self.n
        b_s, b_n = np.roll(a_s, -1), np.roll(a_n, -1)
        ds_edge = b_s - a_s
        valid = np.abs(ds_edge) > 1e-12
        ds_edge = np.where(valid, ds_edge, 1.0)
        t = (s[None, :] - a_s[:, None]) / ds_edge[:, None]
        on = valid[:, None] & (t >= 0.0) & (t <= 1.0)
        n_at = a_n[:, None] + t * (b_n - a_n)[:, None]
        n_at = np.where(on, n_at, np.inf)
        k = np.argmin(n_at, axis=0)
        cols = np.arange(s.size)
        front = n_at[k, cols]
        slope = ((b_n - a_n) / ds_edge)[k]
        tk = np.clip(t[k, cols], 0.0, 1.0)
        length = self.edge_len[k]
        xi = np.minimum(self.corner_to_start[k] + tk * length, self.corner_from_end[k] + (1.0 - tk) * length)
        slope = np.where(np.isfinite(front), slope, 0.0)
        return front, slope, xi

    def pillar_contact(self, s_axis: float, tip_radius: float) -> tuple[float, float, float]:
        """First contact of a hemispherical tip on axis ``s_axis`` (tip apex at n = 0 when the centre is at c_n).

        Returns (c_n at touch, contact slope dn/ds of the tip at the contact point, xi at the contact);
        c_n = -inf when the tip never meets the outline.
        """
        rho = tip_radius
        if self.radius is not None:
            ds = self.c_s - s_axis
            reach = self.radius + rho
            if abs(ds) >= reach:
                return -math.inf, 0.0, math.inf
            c_n = math.sqrt(reach**2 - ds**2) - rho
            return c_n, -ds / (c_n + rho), math.inf
        # candidates: outline vertices over the tip, and tangency points on each edge
        best = (-math.inf, 0.0, math.inf)
        a_s, a_n = self.s, self.n
        b_s, b_n = np.roll(a_s, -1), np.roll(a_n, -1)
        cand_s = [float(v) for v in a_s if abs(v - s_axis) < rho]
        for i in range(a_s.size):
            d = b_s[i] - a_s[i]
            if abs(d) < 1e-12:
                continue
            m = (b_n[i] - a_n[i]) / d
            r = -m * rho / math.sqrt(1.0 + m * m)  # tip slope -r/sqrt(rho^2-r^2) equals the edge slope
            sc = s_axis + r
            if min(a_s[i], b_s[i]) <= sc <= max(a_s[i], b_s[i]):
                cand_s.append(sc)
        if not cand_s:
            return best
        cs = np.array(cand_s)
        front, _, xi = self.front(cs)
        r = cs - s_axis
        tip = -(rho - np.sqrt(np.maximum(rho**2 - r**2, 0.0)))
        value = tip - front  # c_n at which this point touches
        j = int(np.argmax(value))
        if not np.isfinite(value[j]):
            return best
        rj = float(r[j])
        slope = -rj / math.sqrt(max(rho**2 - rj**2, 1e-12))
        return float(value[j]), slope, float(xi[j])


class Outline:
    """The mounted outline (base axes, mm, relative to the object centre) and where its corners are."""

    def __init__(self, obj: ObjectSpec, rotation_deg: float) -> None:
        self.radius = obj.radius_mm
        pts = obj.outer_rotated_mm(rotation_deg)
        self.points = pts
        edge = np.roll(pts, -1, axis=0) - pts
        self.edge_len = np.linalg.norm(edge, axis=1)
        n = len(pts)
        corners = set(obj.corner_vertices().tolist())
        inf = math.inf
        to_start = np.full(n, inf)  # distance along the outline from edge i's start vertex back to a corner
        from_end = np.full(n, inf)  # from edge i's end vertex forward to a corner
        if corners:
            for i in range(n):
                dist, j = 0.0, i
                for _ in range(n):
                    if j in corners:
                        break
                    j = (j - 1) % n
                    dist += self.edge_len[j]
                to_start[i] = dist
                dist, j = 0.0, (i + 1) % n
                for _ in range(n):
                    if j in corners:
                        break
                    dist += self.edge_len[j]
                    j = (j + 1) % n
                from_end[i] = dist
        self.corner_to_start = to_start
        self.corner_from_end = from_end

    def section(self, x_axis: np.ndarray, z_axis: np.ndarray, c_s: float) -> Section:
        return Section(self, x_axis, z_axis, c_s)

    def reach_toward(self, z_axis: np.ndarray) -> float:
        """The farthest the outline reaches toward a pad looking along ``z_axis`` (unit, base xy), from the centre
        (mm): a bound on any section's touch distance along that direction, whatever its lateral offset."""
        if self.radius is not None:
            return float(self.radius)
        return float(np.max(-(self.points @ z_axis)))


def bending_tilt_rad_per_n(obj: ObjectSpec, lever_mm: float) -> float:
    """Tilt of the prism at the press (rad per N of press force): a cantilever of the hollow section clamped at its
    base, loaded ``lever_mm`` above it, turns by P * L^2 / (2 E I) there. I is the mean of the wall section's two
    principal second moments (exact for the circle, square and hexagon, whose I is the same about every axis)."""
    if lever_mm <= 0.0:
        return 0.0
    e_mpa = obj.material_params.youngs_modulus_mpa
    i_mm4 = _ring_second_moment_mm4(np.asarray(obj.outer_mm), np.asarray(obj.inner_mm))
    return lever_mm**2 / (2.0 * e_mpa * i_mm4)


def _ring_second_moment_mm4(outer: np.ndarray, inner: np.ndarray) -> float:
    """Mean principal second moment of area (mm^4) of the wall between two counter-clockwise polygons, about the
    wall's centroid (shoelace sums)."""

    def moments(poly: np.ndarray) -> np.ndarray:
        x, y = poly[:, 0], poly[:, 1]
        xn, yn = np.roll(x, -1), np.roll(y, -1)
        cross = x * yn - xn * y
        area = cross.sum() / 2.0
        sx = ((x + xn) * cross).sum() / 6.0  # first moments: area * centroid
        sy = ((y + yn) * cross).sum() / 6.0
        ixx = ((y * y + y * yn + yn * yn) * cross).sum() / 12.0  # about the origin: integral of y^2
        iyy = ((x * x + x * xn + xn * xn) * cross).sum() / 12.0
        return np.array([area, sx, sy, ixx, iyy])

    area, sx, sy, ixx, iyy = moments(outer) - moments(inner)
    cx, cy = sx / area, sy / area
    return float(0.5 * ((ixx - area * cy * cy) + (iyy - area * cx * cx)))
