"""The press scene's pads: from the section of the outline along one press ray (:class:`Section`) to a table of
taxel loads and tool wrench against the pad-side contact depth. The uSkin is a Winkler skin read through Gaussian
spreading (:class:`SkinPad`), the PapillArray nine pillar springs (:class:`PillarPad`); the module docstring of
:mod:`unitac_rig.sim.scene` says what is modelled and why, docs/simulator.md the numbers."""

from __future__ import annotations

import logging
import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from drivers.layouts import SensorLayout
from unitac_rig.rig.objects import MaterialSpec
from unitac_rig.sim.scene_geometry import Section

if TYPE_CHECKING:
    from unitac_rig.sim.scene_params import SceneParams

log = logging.getLogger(__name__)

TILT_ITERATIONS = 200  # fixed-point steps allowed for the object's bending tilt (38 at a 110 mm lever on TPU)

# =================================================================================================================
# Pads: from the section to a table of loads against contact depth
# =================================================================================================================


@dataclass
class PadTable:
    """Loads against the pad-side contact depth ``e`` (mm past first touch, before the object's global spring)."""

    depth: np.ndarray  # (m,) mm, increasing from 0
    loads: np.ndarray  # (m, n_taxels, 3) N, sensor frame
    displacement: np.ndarray | None  # (m, n_taxels, 3) mm
    wrench_tool: np.ndarray  # (m, 6) N and N*m, tool axes, about the TCP
    touch_cn: float  # object centre distance along the press at first touch (mm); -inf: never touches
    corner_proximity: float  # 0..1, how close to a corner the contact is (stiffens the global spring)


def _near_corner(material: MaterialSpec, xi: np.ndarray, params: SceneParams) -> np.ndarray:
    """Local wall stiffening factor along the contact: the material's corner factor at a corner, 1 mid-wall."""
    bump = np.exp(-np.asarray(xi) / params.corner_decay_mm)
    return 1.0 + (material.corner_stiffness_factor - 1.0) * bump


def _erf(x: np.ndarray) -> np.ndarray:
    return np.frompyfunc(math.erf, 1, 1)(x).astype(np.float64)


class SkinPad:
    """uSkin: Winkler skin over the whole pad, read by taxels through Gaussian spreading + cell integration.

    The pad section is cut into segments at a uniform step *and* at every outline vertex, so within a segment the
    outline is straight: the overlap is integrated exactly (a corner is found exactly where it is, whatever the
    step). The step only sets how finely load is placed on the taxels and how a circle is approximated by chords.
    """

    WEIGHT_LOOKUP_STEP_MM = 0.01
    HEIGHT_BINS = 200  # bins up the pad for the bending tilt's load profile (0.15 mm)

    def __init__(
        self, layout: SensorLayout, params: SceneParams, pitch_tan: float = 0.0, tilt_rad_per_n: float = 0.0
    ) -> None:
        self.layout = layout
        self.params = params
        self.pitch_tan = pitch_tan
        self.tilt_rad_per_n = tilt_rad_per_n
        pitch = layout.pitch_mm
        self.half_w = half_w = (layout.cols - 1) / 2 * pitch + params.skin_margin_x_mm
        self.half_h = half_h = (layout.rows - 1) / 2 * pitch + params.skin_margin_y_mm
        n_steps = max(2, 2 * math.ceil(half_w / params.section_step_mm))
        self.grid = np.linspace(-half_w, half_w, n_steps + 1)  # symmetric about the pad centre
        self.height = 2 * half_h
        sigma = params.skin_spread_sigma_mm
        self.lookup_s = np.linspace(-half_w, half_w, round(2 * half_w / self.WEIGHT_LOOKUP_STEP_MM) + 1)
        self.lookup_w = _cell_weights(self.lookup_s, layout.cols, pitch, sigma)  # (cols, n)
        # the pad's height in bins (y up, mm): what share of a line load at each height each row reads, and how the
        # skin spreads it onto the inner row edges (both exact for a load constant within a bin)
        y_edges = np.linspace(-half_h, half_h, self.HEIGHT_BINS + 1)
        self.y_mid = 0.5 * (y_edges[:-1] + y_edges[1:])
        self.y_width = np.diff(y_edges)
        # (rows, bins), row 0 on top; ``row_load_share`` the same for a load the same at every height (rows sum to 1)
        self.row_bin_w = _cell_weights(-self.y_mid, layout.rows, pitch, sigma) * self.y_width
        self.row_load_share = self.row_bin_w.sum(axis=1, keepdims=True)
        self.row_load_share /= float(self.row_load_share.sum())
        # skin bulge: the inner cell edges (mm) across the pad (columns) and up it (rows, row 0 on top)
        self.col_edges = (np.arange(1, layout.cols) - layout.cols / 2) * pitch
        # skin bulge up the pad: row r (top first) reads -kappa * (spread line load at its upper inner edge - at its
        # lower one); the outer rows reach to infinity, where the spread load is 0. ``edge_spread`` (rows + 1, bins)
        # takes the line load in each bin (N per mm of height) to the spread load at those edges (N/mm), top first
        self.edge_spread = np.zeros((layout.rows + 1, self.HEIGHT_BINS))
        if params.skin_bulge_mm > 0:
            edges = (np.arange(1, layout.rows) - layout.rows / 2) * pitch  # inner edges, bottom first

            def cdf(z: np.ndarray) -> np.ndarray:
                return 0.5 * (1.0 + _erf(z / math.sqrt(2)))

            inner = cdf((edges[:, None] - y_edges[None, :-1]) / sigma) - cdf(
                (edges[:, None] - y_edges[None, 1:]) / sigma
            )
            self.edge_spread[1:-1] = inner[::-1]

    def _nodes(self, section: Section) -> np.ndarray:
        extra = (
            [section.c_s]
            if section.radius is None
            else [section.c_s - section.radius, section.c_s, section.c_s + section.radius]
        )
        cuts = np.concatenate([section.s, np.asarray(extra)]) if section.radius is None else np.asarray(extra)
        cuts = cuts[(cuts > -self.half_w) & (cuts < self.half_w)]
        return np.unique(np.concatenate([self.grid, cuts]))

    def table(self, section: Section, material: MaterialSpec) -> PadTable:
        p = self.params
        layout = self.layout
        nodes = self._nodes(section)
        front_nodes, _, _ = section.front(nodes)
        a, b = front_nodes[:-1], front_nodes[1:]
        segment = np.isfinite(a) & np.isfinite(b) & (np.diff(nodes) > 1e-9)  # outline in front all along
        if not np.any(segment):
            return _no_contact(layout)
        left, right = nodes[:-1][segment], nodes[1:][segment]
        fa, fb = a[segment], b[segment]
        length = right - left
        mid = 0.5 * (left + right)
        slope = (fb - fa) / length
        _, _, xi = section.front(mid)
        fmin = float(min(fa.min(), fb.min()))
        gap_a, gap_b = fa - fmin, fb - fmin
        k_skin = p.skin_foundation_n_per_mm3
        if material.wall_foundation_n_per_mm3 is None:
            k_eff = np.full(mid.shape, k_skin)
        else:
            k_wall = material.wall_foundation_n_per_mm3 * _near_corner(material, xi, p)
            k_eff = 1.0 / (1.0 / k_skin + 1.0 / k_wall)
        # shear follows the outline's own slope, on soft walls too: the recorded TPU sessions show uSkin lateral
        # readings as large as PLA's (minima -1.9k..-3.1k counts against -1.2k..-3.0k), which a wall flattening the
        # interface (tilt x k_eff / k_skin, ~0.02 on TPU) would not give
        ratio, ratio_y = _friction_capped(
            p.shear_projection * slope, p.shear_projection * self.pitch_tan, p.skin_friction
        )
        if p.skin_flank_friction > 0:
            ratio = flank_shear_ratio(slope, p.skin_flank_friction)
            ratio_y = _friction_capped(np.zeros_like(ratio), p.shear_projection * self.pitch_tan, p.skin_friction)[1]
        scale = k_eff * self.height * length  # N per mm of mean overlap over the segment

        def force(e: float) -> float:
            return float(np.dot(scale, _mean_positive(e - gap_a, e - gap_b)))

        e_max = _depth_for_force(force, p.table_max_force_n)
        u = np.linspace(0.0, 1.0, p.table_points)
        depth = e_max * u**2
        near = np.minimum(gap_a, gap_b) <= e_max  # only segments the table's deepest press reaches
        d = depth[:, None]
        normal_seg = scale[near] * _mean_positive(d - gap_a[near], d - gap_b[near])  # (m, n_near) N
        shear_seg = normal_seg * ratio[near]
        shear_y_seg = normal_seg * ratio_y[near]
        weights = np.stack([np.interp(mid[near], self.lookup_s, w) for w in self.lookup_w])  # (cols, n_near)
        col_n = normal_seg @ weights.T  # (m, cols)
        col_x = shear_seg @ weights.T
        col_y = shear_y_seg @ weights.T
        kappa_x = p.skin_bulge_mm + material.skin_drag_mm  # the skin's bulge plus a soft wall's surface drag
        if kappa_x > 0:
            # the spread line load (N/mm) at each inner column edge; a column's lateral reading is -kappa times the
            # rate its normal load would change if the column moved toward +x (outer columns reach to infinity)
            sigma = p.skin_spread_sigma_mm
            dist = (self.col_edges[:, None] - mid[near][None, :]) / sigma
            line = normal_seg @ (np.exp(-0.5 * dist**2) / (sigma * math.sqrt(2 * math.pi))).T  # (m, cols - 1)
            padded = np.pad(line, ((0, 0), (1, 1)))
            col_x = col_x - kappa_x * (padded[:, 1:] - padded[:, :-1])
        m = depth.size
        # everything per mm of pad height at a uniform depth; the bending tilt then makes the depth vary up the pad
        sums = np.stack(
            [
                shear_seg.sum(axis=1),  # the bulge is internal to the skin: it sums to zero over the pad
                shear_y_seg.sum(axis=1),
                normal_seg.sum(axis=1),
                normal_seg @ mid[near] * 1e-3,  # tau_y = sum s * p (N*m)
                shear_y_seg @ mid[near] * 1e-3,  # tau_z = sum s * q_y
            ],
            axis=1,
        )
        line = np.concatenate([col_n, col_x, col_y, sums], axis=1) / self.height  # (m, 3 * cols + 5)
        loads, wrench = self._loads_up_the_pad(depth, line)
        contact = np.minimum(gap_a, gap_b) < p.corner_contact_depth_mm
        proximity = float(np.max(np.exp(-xi[contact] / p.corner_decay_mm))) if np.any(contact) else 0.0
        return PadTable(
            depth=depth,
            loads=loads.reshape(m, layout.n_taxels, 3),
            displacement=None,
            wrench_tool=wrench,
            touch_cn=-fmin,
            corner_proximity=proximity,
        )

    def _loads_up_the_pad(self, depth: np.ndarray, line: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Per-mm-of-height column loads and sums ``line`` (m, 3 * cols + 5) at each table depth -> taxel loads
        (m, rows, cols, 3) and the tool wrench (m, 6): spread over the rows (through the bending tilt's profile up
        the pad when it is on), plus the skin's bulge up the pad."""
        p = self.params
        layout = self.layout
        m = depth.size
        cols = layout.cols
        if self.tilt_rad_per_n > 0.0:
            profile = tilted_profile(depth, line, self.y_mid, self.y_width, self.tilt_rad_per_n, 3 * cols + 2)
            row_w, edge_w, width, y = self.row_bin_w, self.edge_spread, self.y_width, self.y_mid
        else:  # the same load at every height: the pad as one bin (a third faster, and the default)
            profile = line[:, None, :]
            row_w, edge_w = self.row_load_share * self.height, self.edge_spread.sum(axis=1, keepdims=True)
            width, y = np.array([self.height]), np.zeros(1)
        rows = np.einsum("rb,mbc->mrc", row_w, profile)  # (m, rows, channels)
        total = np.einsum("b,mbc->mc", width, profile)
        # the skin's bulge up the pad, from the normal load's profile up each column
        spread = np.einsum("eb,mbc->mec", edge_w, profile[:, :, :cols])  # (m, rows + 1, cols)
        bulge_y = -p.skin_bulge_mm * (spread[:, :-1] - spread[:, 1:])
        loads = np.zeros((m, layout.rows, cols, 3))
        loads[..., 2] = rows[:, :, :cols]
        loads[..., 0] = rows[:, :, cols : 2 * cols]
        loads[..., 1] = rows[:, :, 2 * cols : 3 * cols] + bulge_y
        wrench = np.zeros((m, 6))
        wrench[:, 0] = total[:, 3 * cols]
        wrench[:, 1] = total[:, 3 * cols + 1]
        wrench[:, 2] = -total[:, 3 * cols + 2]
        wrench[:, 3] = -(profile[:, :, 3 * cols + 2] @ (y * width)) * 1e-3  # tau_x = sum y * fz (N*m)
        wrench[:, 4] = total[:, 3 * cols + 3]
        wrench[:, 5] = total[:, 3 * cols + 4]
        return loads, wrench


class PillarPad:
    """PapillArray: nine pillar springs with hemispherical tips, the centre one proud; each pillar its own spring."""

    def __init__(
        self, layout: SensorLayout, params: SceneParams, pitch_tan: float = 0.0, tilt_rad_per_n: float = 0.0
    ) -> None:
        self.layout = layout
        self.params = params
        self.pitch_tan = pitch_tan
        self.tilt_rad_per_n = tilt_rad_per_n
        xy = layout.taxel_xy_mm()
        self.col_s = xy[: layout.cols, 0]
        rows, cols = np.divmod(np.arange(layout.n_taxels), layout.cols)
        mid_r, mid_c = (layout.rows - 1) / 2, (layout.cols - 1) / 2
        ring = np.maximum(np.abs(rows - mid_r), np.abs(cols - mid_c))
        off_axis = (rows != mid_r).astype(int) + (cols != mid_c).astype(int)
        recess = np.where(
            off_axis == 0, 0.0, np.where(off_axis == 1, params.pillar_edge_recess_mm, params.pillar_corner_recess_mm)
        )
        self.recess = recess * np.maximum(ring, 1)  # larger arrays: recess grows ring by ring
        self.rows, self.cols = rows, cols
        self.xy = xy

    def _normal_loads(self, depth: np.ndarray, gap: np.ndarray, k: np.ndarray) -> np.ndarray:
        """Pillar normal loads (m, n) N at each pad-side depth: k * (depth - gap), where the object's bending tilt
        theta = tilt * P (P the pillars' total) adds -theta * y to a pillar's depth (y up, mm). Fixed point as in
        :func:`tilted_profile`; inf gaps (pillars that never touch) carry nothing."""
        y = self.xy[:, 1]
        theta = np.zeros(depth.size)
        normal = np.zeros((depth.size, gap.size))
        for _ in range(TILT_ITERATIONS):
            normal = k[None, :] * np.maximum(0.0, depth[:, None] - gap[None, :] - theta[:, None] * y[None, :])
            if self.tilt_rad_per_n <= 0.0:
                break
            new_theta = self.tilt_rad_per_n * normal.sum(axis=1)
            if np.max(np.abs(new_theta - theta)) < 1e-9:
                break
            theta = new_theta
        else:
            log.warning("the object's bending tilt did not settle in %d steps; the lever is too long", TILT_ITERATIONS)
        return normal

    def table(self, section: Section, material: MaterialSpec) -> PadTable:
        p = self.params
        layout = self.layout
        contacts = [section.pillar_contact(float(s), p.pillar_tip_radius_mm) for s in self.col_s]
        col_cn = np.array([c[0] for c in contacts])
        if not np.any(np.isfinite(col_cn)):
            return _no_contact(layout)
        col_slope = np.array([c[1] for c in contacts])
        col_xi = np.array([c[2] for c in contacts])
        pillar_cn = col_cn[self.cols] - self.recess  # c_n at which each pillar touches
        touch = float(np.max(pillar_cn))
        gap = touch - pillar_cn  # pad-side depth at which each pillar starts to load (inf: never)
        # contact force direction: tangential/normal = the tip's slope at the contact, capped by friction
        mu = p.pillar_friction
        ratio, ratio_y = _friction_capped(
            p.shear_projection * col_slope[self.cols], np.full(layout.n_taxels, p.shear_projection * self.pitch_tan), mu
        )
        # an off-axis contact also bends the pillar sideways: with the tip's lateral spring in the load path the
        # pillar is softer along the press, 1/k = 1/k_axial + |ratio|^2/k_lateral (compatibility along the normal)
        k = 1.0 / (1.0 / p.pillar_axial_n_per_mm + (ratio**2 + ratio_y**2) / p.pillar_lateral_n_per_mm)
        if material.wall_point_stiffness_n_per_mm is not None:
            k_wall = material.wall_point_stiffness_n_per_mm * _near_corner(material, col_xi[self.cols], p)
            k = 1.0 / (1.0 / k + 1.0 / k_wall)
        k_sum = float(np.sum(k[np.isfinite(gap)]))
        finite_gap = gap[np.isfinite(gap)]
        e_max = float(np.max(finite_gap)) + p.table_max_force_n / k_sum
        depth = np.unique(np.concatenate([np.linspace(0.0, e_max, p.table_points), finite_gap]))
        normal = self._normal_loads(depth, gap, k)
        shear = normal * ratio[None, :]
        shear_y = normal * ratio_y[None, :]
        m = depth.size
        loads = np.zeros((m, layout.n_taxels, 3))
        loads[..., 0] = shear
        loads[..., 1] = shear_y
        loads[..., 2] = normal
        disp = np.zeros_like(loads)
        disp[..., 0] = shear / p.pillar_lateral_n_per_mm
        disp[..., 1] = shear_y / p.pillar_lateral_n_per_mm
        disp[..., 2] = normal / p.pillar_axial_n_per_mm
        s_pos, y_pos = self.xy[:, 0], self.xy[:, 1]
        fz = -normal  # force on the pad along tool z
        wrench = np.zeros((m, 6))
        wrench[:, 0] = shear.sum(axis=1)
        wrench[:, 1] = shear_y.sum(axis=1)
        wrench[:, 2] = fz.sum(axis=1)
        wrench[:, 3] = fz @ y_pos * 1e-3  # tau = r x f, r = (s, y, 0) mm -> m
        wrench[:, 4] = -(fz @ s_pos) * 1e-3
        wrench[:, 5] = (shear_y @ s_pos - shear @ y_pos) * 1e-3
        contact = gap < p.corner_contact_depth_mm
        proximity = float(np.max(np.exp(-col_xi[self.cols][contact] / p.corner_decay_mm))) if np.any(contact) else 0.0
        return PadTable(depth, loads, disp, wrench, touch, proximity)


def flank_shear_ratio(slope: np.ndarray, mu: float) -> np.ndarray:
    """Shear/normal ratio (across the pad) of a skin pressed by a rigid flank of slope ``slope`` (tan of its tilt
    phi from the pad), with Coulomb friction ``mu`` between them: tan(phi - atan mu), with the slope's sign, where
    phi > atan mu, else 0.

    A frictionless flank pushes the skin along the flank's own normal, phi off the pad's (shear/normal tan phi,
    outward from the apex); the incompressible skin is squeezed outward under it and slides along the flank, so
    friction turns the traction back toward the apex by atan mu, the edge of Coulomb's cone about the flank normal
    (Popov, Contact Mechanics and Friction, 2010, ch. 10). Where phi <= atan mu the cone holds the skin: it sticks
    and the flank pushes it straight in. The corner's angle thus reaches the readings: a 90 deg corner (phi 45 deg)
    gives tan(45 - atan mu), an 80 deg one tan(50 - atan mu), a 120 deg one (phi 30 deg) none for mu >= 0.58.
    """
    phi = np.arctan(np.abs(slope))
    return np.sign(slope) * np.tan(np.maximum(0.0, phi - math.atan(mu)))


def _friction_capped(ratio_x: np.ndarray, ratio_y: np.ndarray | float, mu: float) -> tuple[np.ndarray, np.ndarray]:
    """Shear/normal ratios (x, y) with their vector length capped at the friction coefficient ``mu``."""
    ratio_x, ratio_y = np.broadcast_arrays(np.asarray(ratio_x, dtype=np.float64), np.asarray(ratio_y, dtype=np.float64))
    length = np.hypot(ratio_x, ratio_y)
    shrink = np.where(length > mu, mu / np.where(length > 0, length, 1.0), 1.0)
    return ratio_x * shrink, ratio_y * shrink


def _mean_positive(at_a: np.ndarray, at_b: np.ndarray) -> np.ndarray:
    """Mean over a segment of max(0, v) for v linear from ``at_a`` to ``at_b`` (exact)."""
    hi = np.maximum(at_a, at_b)
    lo = np.minimum(at_a, at_b)
    crossing = hi * hi / (2.0 * np.where(hi > lo, hi - lo, 1.0))
    return np.where(lo >= 0.0, 0.5 * (hi + lo), np.where(hi <= 0.0, 0.0, crossing))


def _cell_weights(pos: np.ndarray, n_cells: int, pitch: float, sigma: float) -> np.ndarray:
    """Share of a load at ``pos`` each cell reads: Gaussian spreading then cell integration (sums to 1).

    Cell ``c`` is centred at ``(c - (n-1)/2) * pitch``; the outer cells reach to infinity so no load is lost.
    """
    centres = (np.arange(n_cells) - (n_cells - 1) / 2) * pitch
    lo = centres - pitch / 2
    hi = centres + pitch / 2
    lo[0], hi[-1] = -np.inf, np.inf
    if sigma <= 0:
        return ((pos[None, :] >= lo[:, None]) & (pos[None, :] < hi[:, None])).astype(np.float64)
    scale = sigma * math.sqrt(2.0)

    def cdf(edge: np.ndarray) -> np.ndarray:
        z = (edge[:, None] - pos[None, :]) / scale
        return 0.5 * (1.0 + _erf(np.clip(z, -40.0, 40.0)))

    return cdf(hi) - cdf(lo)


def tilted_profile(
    depth: np.ndarray, line: np.ndarray, y: np.ndarray, width: np.ndarray, tilt_rad_per_n: float, normal: int
) -> np.ndarray:
    """Line quantities up the pad (m, bins, channels) when the object tilts under the press.

    ``line`` (m, channels) holds what one mm of pad height carries at each uniform contact ``depth`` (mm, increasing
    from 0); channel ``normal`` is the normal line load (N/mm). Pressing with P newtons tilts the prism by
    ``theta = tilt_rad_per_n * P`` about the pad's x axis, so at height ``y`` (mm, up) the contact is
    ``depth - theta * y`` deep (deeper toward the base, below). P depends on theta and theta on P: a fixed-point
    iteration, which contracts while the tilt across the pad stays below the contact's depth: within 1e-9 rad in
    9 / 16 / 38 steps at a 70 / 90 / 110 mm lever on the TPU square (a warning if it has not settled in
    :data:`TILT_ITERATIONS`). Depths past the table extrapolate its last segment; a depth <= 0 carries nothing.
    """
    m = depth.size

    def at(theta: np.ndarray, values: np.ndarray) -> np.ndarray:
        """``values`` (m, ...) interpolated at each height's local depth: (m, bins, ...)."""
        local = depth[:, None] - theta[:, None] * y[None, :]
        i = np.clip(np.searchsorted(depth, local, side="right"), 1, m - 1)
        lo, hi = depth[i - 1], depth[i]
        frac = (local - lo) / np.where(hi > lo, hi - lo, 1.0)
        frac = frac.reshape(frac.shape + (1,) * (values.ndim - 1))
        inside = (local > 0.0).reshape(frac.shape)
        return np.where(inside, values[i - 1] + frac * (values[i] - values[i - 1]), 0.0)

    # the tilt from the normal channel alone, then every channel once at the settled tilt
    theta = tilt_rad_per_n * (line[:, normal] * float(width.sum()))
    for _ in range(TILT_ITERATIONS):
        new_theta = tilt_rad_per_n * (at(theta, line[:, normal]) @ width)
        if np.max(np.abs(new_theta - theta)) < 1e-9:
            theta = new_theta
            break
        theta = new_theta
    else:
        log.warning("the object's bending tilt did not settle in %d steps; the lever is too long", TILT_ITERATIONS)
    profile = at(theta, line)
    return profile


def _depth_for_force(force: Callable[[float], float], target_n: float) -> float:
    """Smallest depth (mm) at which the monotone ``force(depth)`` reaches ``target_n``, by doubling + bisection."""
    hi = 0.05
    while force(hi) < target_n and hi < 200.0:
        hi *= 2.0
    lo = 0.0
    for _ in range(40):
        mid = 0.5 * (lo + hi)
        if force(mid) < target_n:
            lo = mid
        else:
            hi = mid
    return hi


def _no_contact(layout: SensorLayout) -> PadTable:
    zeros = np.zeros((2, layout.n_taxels, 3))
    return PadTable(
        depth=np.array([0.0, 1.0]),
        loads=zeros,
        displacement=zeros.copy() if layout.has_displacement else None,
        wrench_tool=np.zeros((2, 6)),
        touch_cn=-math.inf,
        corner_proximity=0.0,
    )
