"""The simulated press scene: a sensor pad pushed horizontally into a vertical hollow prism (2-D cross-section).

What it models (no more than the scene needs; parameters and sources in :class:`SceneParams` and docs/simulator.md):

* the exact outline of the object (``unitac_rig.rig.objects``), as mounted and rotated, cut by the pad's horizontal
  section: ``f(s)`` = how far the outline reaches toward the pad at each point ``s`` across the pad;
* the pad: **uSkin** = a bed of springs (Winkler skin, N/mm^3) over the whole pad, its pressure read by 4x6 magnets
  through the skin's spreading (a Gaussian of width ``skin_spread_sigma_mm`` followed by cell integration, which
  conserves load); **PapillArray** = nine separate pillar springs with hemispherical tips, the centre pillar proud;
* the object in series: a global spring (mount + prism translating away; non-linear and corner-dependent for hollow
  TPU) and, for soft walls, a local wall foundation that lets the wall flatten under the pad;
* shear from the local surface tilt (the contact normal), scaled by ``shear_projection`` and capped by one fitted
  friction coefficient per pad; a pad pitched on its mount (seeded per scene) adds vertical shear tan(beta) * p;
* on the uSkin, the skin's bulge: magnets move away from a contact as the incompressible skin is squeezed out from
  under the pressure gradient, a lateral reading -kappa * dF/ds (x across the pad, y at its free top and bottom);
* optionally (off by default, ``bending_lever_mm``), the object bending as a cantilever on its base: the contact
  is deeper toward the base by the prism's tilt P * L^2 / (2 E I), so on soft TPU the rows nearer the base carry
  more; and a seeded rotation of the object on its adapter (``rotation_error_deg``);
* a seeded centring error of the object (the press still aims at the nominal centre), drawn per placement of the
  object so that both sensors' sessions of one object see the same one (the adapter that places it stays), and a
  fixed offset of each sensor's pad from the tool axis (its adapter), the same for every object it presses;
* otherwise uniform along the prism axis: rows differ only by their share of the pad (uSkin) or their recess
  (PapillArray), and by the bending tilt when it is on.

Speed: the arm asks for the wrench 500 times per simulated second and the sensors for taxel loads 100-1000 times.
Along one press ray (fixed pad orientation and lateral offset) everything depends only on the travel past first
touch, so the scene builds one vectorised table per ray (loads and wrench against travel) and interpolates; it
rebuilds only when the pose leaves the ray.

Frames: see ``unitac_rig.rig.objects`` (rig geometry). ``wrench_on_tool`` is in base axes about the TCP and is the force
the object exerts on the tool; taxel loads are in the sensor frame (x, y shear; z normal, pushing = +), newtons.

Modules: :mod:`unitac_rig.sim.scene_params` holds the parameters; this one the scene (rays located from poses,
cached) and the per-ray tables;
:mod:`unitac_rig.sim.scene_geometry` the outline's section along a ray and the prism's bending;
:mod:`unitac_rig.sim.scene_pads` the two pad models (section -> loads against contact depth).
"""

from __future__ import annotations

import bisect
import logging
import math
import threading
from dataclasses import dataclass

import numpy as np

from drivers.layouts import SensorLayout
from unitac_rig.errors import ConfigError
from unitac_rig.rig.objects import DEFAULT_OBJECT_CENTER_M, MaterialSpec, ObjectSpec
from unitac_rig.rig.poses import approach_direction, pose_from, press_rotation, rotvec_to_matrix
from unitac_rig.rig.sensors import SENSORS
from unitac_rig.sim.scene_geometry import Outline, bending_tilt_rad_per_n
from unitac_rig.sim.scene_pads import PadTable, PillarPad, SkinPad
from unitac_rig.sim.scene_params import SceneParams
from unitac_rig.sim.world import NO_WRENCH, read_only

log = logging.getLogger(__name__)

RAYS_KEPT = 8  # press rays whose tables stay cached (a press, its retract, and a few neighbours)
NO_CONTACT_MARGIN_MM = 1.0  # beyond this past the outline's reach toward the pad no ray can touch: no table is built


@dataclass(frozen=True, slots=True)
class TaxelLoads:
    """What each taxel feels, in the sensor frame: ``forces_n`` (n, 3) x/y shear and z normal (pushing = +), N.

    ``displacement_mm`` (n, 3): pillar tip displacements (PapillArray, along the force), else None.
    """

    forces_n: np.ndarray
    displacement_mm: np.ndarray | None = None


def pad_kind(layout: SensorLayout) -> str:
    """``"skin"`` for a continuous-skin pad, ``"pillars"`` for separate pillars: the registered sensor's ``pad``; a
    layout no sensor registers has pillars where it reports their displacement."""
    spec = SENSORS.get(layout.name)
    if spec is not None:
        return spec.pad
    return "pillars" if layout.has_displacement else "skin"


def press_pose(
    angle_deg: float,
    distance_mm: float,
    *,
    object_center_m: tuple[float, float] = DEFAULT_OBJECT_CENTER_M,
    height_m: float = 0.30,
) -> np.ndarray:
    """TCP pose (6,) for approach angle ``angle_deg`` with the pad centre ``distance_mm`` from the object's axis."""
    u = approach_direction(angle_deg)
    return pose_from(np.array([*object_center_m, height_m]) + u * distance_mm * 1e-3, press_rotation(-u))


class PressScene:
    """One object (at one rotation) in front of one sensor pad; a ``ContactWorld`` for the simulated arm."""

    def __init__(
        self,
        obj: ObjectSpec,
        rotation_deg: float,
        layout: SensorLayout,
        *,
        object_center_m: tuple[float, float] = DEFAULT_OBJECT_CENTER_M,
        params: SceneParams | None = None,
        rng: np.random.Generator | None = None,
        placement_rng: np.random.Generator | None = None,
        pad: str | None = None,
    ) -> None:
        """``rng`` draws the sensor mount's errors (the pad pitch); ``placement_rng`` the object's centring error,
        so that two scenes of one object placement with different sensors can share it. Without ``placement_rng``
        both come from ``rng`` (centring first), for a scene on its own. ``pad``: the layout's :func:`pad_kind`
        unless given."""
        self.obj = obj
        self.rotation_deg = float(rotation_deg)
        self.layout = layout
        self.params = params or SceneParams()
        self.kind = pad or pad_kind(layout)
        drag = obj.material_params.skin_drag_mm
        if drag < 0 or (drag > 0 and self.params.skin_spread_sigma_mm <= 0):
            raise ConfigError(
                f"{obj.material_params.name}: skin drag {drag} mm cannot be used",
                hint="skin_drag_mm >= 0; a drag needs skin_spread_sigma_mm > 0 (it reads the spread load's gradient)",
            )
        rng = rng if rng is not None else np.random.default_rng(0)
        p = self.params
        # the seeded errors of this placement and mount, always drawn in this order so a seed means the same scene
        # whichever of them are switched on
        placement = placement_rng if placement_rng is not None else rng
        offset_mm = placement.standard_normal(2) * p.centring_error_mm
        self.pad_pitch_deg = float(p.pad_pitch_deg + rng.standard_normal() * p.pad_pitch_sd_deg)
        # drawn only when asked for, so that a scene without it keeps the draws it always had
        self.rotation_error_deg = (
            float(placement.standard_normal() * p.rotation_error_deg) if p.rotation_error_deg > 0 else 0.0
        )
        self.nominal_center_m = (float(object_center_m[0]), float(object_center_m[1]))  # where presses aim
        self._wrench_key: bytes | None = None  # the pose (float64 bytes) of the last wrench_on_tool, and its answer
        self._located_key: bytes | None = None  # the pose of the last ray lookup, and its (table, travel)
        self.center_mm = np.asarray(object_center_m, dtype=np.float64) * 1e3 + offset_mm  # where the object is
        # farthest any outline point reaches from the axis, plus room for pillar tips proud of the pad (mm)
        self._reach_mm = float(np.max(np.linalg.norm(np.asarray(obj.outer_mm), axis=1))) + 10.0
        self._outline = Outline(obj, self.rotation_deg + self.rotation_error_deg)
        self.pad_offset_mm = p.skin_pad_offset_mm if self.kind == "skin" else p.pillar_pad_offset_mm
        pitch_tan = math.tan(math.radians(self.pad_pitch_deg))
        self.tilt_rad_per_n = bending_tilt_rad_per_n(obj, p.bending_lever_mm)
        self._pad: SkinPad | PillarPad = (
            SkinPad(layout, p, pitch_tan, self.tilt_rad_per_n)
            if self.kind == "skin"
            else PillarPad(layout, p, pitch_tan, self.tilt_rad_per_n)
        )
        self._rays: list[_RayTable] = []  # most recent first, a few kept so alternating rays stay cheap
        self._last_rotvec: tuple[float, float, float] | None = None
        self._frame: tuple[np.ndarray, float, float, float, float, float, float] | None = None
        # how far any pad feature stands proud of the plane whose touch the outline's reach bounds (mm): pillars
        # sit at or below the centre one (recess >= 0), the skin is that plane
        proud_mm = float(max(0.0, -np.min(self._pad.recess))) if isinstance(self._pad, PillarPad) else 0.0
        self._no_contact_margin_mm = NO_CONTACT_MARGIN_MM + proud_mm
        self.rays_built = 0
        self._warned_tilt = False
        self._lock = threading.Lock()  # the arm and a device thread may ask at the same time
        self._wrench = NO_WRENCH
        self._located: tuple[_RayTable, float] | None = None

    @property
    def center_mm(self) -> np.ndarray:
        """Where the object's axis is (x, y) in mm, base frame (read only: set the whole, e.g. to move the object)."""
        return self._center_mm

    @center_mm.setter
    def center_mm(self, value: np.ndarray) -> None:
        center = np.array(value, dtype=np.float64)
        center.flags.writeable = False  # changed only through here, which forgets the answers kept for a pose
        self._center_mm = center
        self._center_xy = (float(center[0]), float(center[1]))
        self._wrench_key = self._located_key = None

    # ---- ContactWorld ------------------------------------------------------------------------------------
    def wrench_on_tool(self, tcp_pose: np.ndarray) -> np.ndarray:
        """Force (N) and torque (N*m) the object exerts on the tool, base axes, about the TCP; (6,).

        The last answer is kept for its pose (an arm at rest asks about the same pose every control period) and
        returned read only, the same array until the wrench changes; no contact is :data:`NO_WRENCH`.
        """
        pose = np.asarray(tcp_pose, dtype=np.float64)
        key = pose.tobytes()
        with self._lock:
            if key != self._wrench_key:
                ray, travel = self._locate_kept(pose, key)
                wrench = NO_WRENCH if travel <= 0.0 else ray.interp(ray.wrench_base, travel, ray.wrench_steps)
                self._wrench = read_only(wrench)
                self._wrench_key = key
            return self._wrench

    def taxel_loads(self, tcp_pose: np.ndarray) -> TaxelLoads:
        """Per-taxel loads at ``tcp_pose`` in the sensor frame (N, and pillar displacements in mm)."""
        ray, travel = self._locate(tcp_pose)
        return ray.loads_at(travel)

    # ---- helpers for presses, figures and tests ------------------------------------------------------------
    def press_force_n(self, tcp_pose: np.ndarray) -> float:
        """Force along the press direction (N, positive while pressing)."""
        ray, travel = self._locate(tcp_pose)
        return float(ray.interp(ray.force, travel)) if travel > 0 else 0.0

    def touch_distance_mm(self, angle_deg: float) -> float:
        """Distance (mm) from the nominal object centre to the TCP at first touch, pressing at ``angle_deg``."""
        ray = self._ray_for_angle(angle_deg)
        a = math.radians(angle_deg)
        offset_mm = self.center_mm - np.asarray(self.nominal_center_m) * 1e3  # placement error
        return ray.touch_cn - float(offset_mm @ np.array([-math.sin(a), math.cos(a)]))

    def pose_at_travel(self, angle_deg: float, travel_mm: float) -> np.ndarray:
        """TCP pose after travelling ``travel_mm`` past first touch at ``angle_deg`` (negative: before touch)."""
        return press_pose(
            angle_deg, self.touch_distance_mm(angle_deg) - travel_mm, object_center_m=self.nominal_center_m
        )

    def travel_at_force_mm(self, angle_deg: float, force_n: float) -> float:
        """Travel past first touch (mm) at which the press force reaches ``force_n``."""
        ray = self._ray_for_angle(angle_deg)
        return float(np.interp(force_n, ray.force, ray.travel))

    def force_curve(self, angle_deg: float, travel_mm: np.ndarray) -> np.ndarray:
        """Press force (N) against travel past first touch (mm) at ``angle_deg``."""
        ray = self._ray_for_angle(angle_deg)
        return np.array([ray.interp(ray.force, float(t)) if t > 0 else 0.0 for t in np.atleast_1d(travel_mm)])

    def loads_at_force(self, angle_deg: float, force_n: float) -> TaxelLoads:
        """Taxel loads when the press force along ``angle_deg`` reaches ``force_n`` (N)."""
        ray = self._ray_for_angle(angle_deg)
        return ray.loads_at(float(np.interp(force_n, ray.force, ray.travel)))

    def _ray_for_angle(self, angle_deg: float) -> _RayTable:
        ray, _ = self._locate(press_pose(angle_deg, 200.0, object_center_m=self.nominal_center_m), need_table=True)
        return ray

    # ---- internals ---------------------------------------------------------------------------------------
    def _locate(self, tcp_pose: np.ndarray, need_table: bool = False) -> tuple[_RayTable, float]:
        """The table of the press ray through ``tcp_pose`` (cached) and the travel past first touch (mm).

        Out of the object's reach, any cached table is returned with a negative travel (no contact), unless
        ``need_table`` asks for the table of that very ray.
        """
        pose = np.asarray(tcp_pose, dtype=np.float64)
        with self._lock:
            if need_table:
                self._located_key = None  # it may build a table and reorder the cache
                return self._locate_unlocked(pose, True)
            return self._locate_kept(pose, pose.tobytes())

    def _locate_kept(self, pose: np.ndarray, key: bytes) -> tuple[_RayTable, float]:
        """:meth:`_locate_unlocked` without a table demand, the last answer kept for its pose (``key``, its float64
        bytes): the arm and the sensors ask about the same pose in one control period."""
        if key != self._located_key or self._located is None:
            self._located = self._locate_unlocked(pose, False)
            self._located_key = key
        return self._located

    def _locate_unlocked(self, pose: np.ndarray, need_table: bool) -> tuple[_RayTable, float]:
        x_m, y_m, _, *turn = pose.tolist()  # Python floats: the same arithmetic as numpy's scalars, for less
        rotvec = (turn[0], turn[1], turn[2])
        if rotvec != self._last_rotvec or self._frame is None:
            rot = rotvec_to_matrix(np.array(rotvec))
            if abs(rot[2, 1]) < 0.99 and not self._warned_tilt:
                log.warning(
                    "tool y is %.1f deg off vertical; the 2-D scene ignores the tilt",
                    math.degrees(math.acos(min(1.0, abs(rot[2, 1])))),
                )
                self._warned_tilt = True
            xh = np.array([rot[0, 0], rot[1, 0]])
            zh = np.array([rot[0, 2], rot[1, 2]])
            xh /= np.linalg.norm(xh)
            zh /= np.linalg.norm(zh)
            reach = self._outline.reach_toward(zh)
            (xx, xy), (zx, zy) = xh.tolist(), zh.tolist()
            self._frame = (rot, xx, xy, zx, zy, math.atan2(zy, zx), reach)
            self._last_rotvec = rotvec
        rot, xx, xy, zx, zy, psi, reach = self._frame
        center_x, center_y = self._center_xy
        rel_x = center_x - x_m * 1e3
        rel_y = center_y - y_m * 1e3
        c_s = rel_x * xx + rel_y * xy - self.pad_offset_mm  # across the pad, from the pad's centre
        c_n = rel_x * zx + rel_y * zy
        p = self.params
        if self._rays and c_n > self._reach_mm and not need_table:
            # Nothing of the object is within reach of the pad (transit moves between presses): no contact, and no
            # point building a table for a ray that will never touch.
            return self._rays[0], -1.0
        for i, ray in enumerate(self._rays):
            if (
                abs(ray.c_s - c_s) <= p.ray_tolerance_mm
                and abs(math.remainder(ray.psi - psi, 2 * math.pi)) <= p.ray_tolerance_rad
            ):
                if i:
                    self._rays.insert(0, self._rays.pop(i))
                return ray, ray.touch_cn - c_n
        if self._rays and not need_table and c_n > reach + self._no_contact_margin_mm:
            # The outline reaches at most ``reach`` toward the pad along this ray, so its table would say "no
            # contact" here: the arm turning at its stand-off between presses built a table every control period
            # (a twentieth of a simulated session) that no press ever used.
            return self._rays[0], -1.0
        ray = self._build_ray(rot, (xx, xy), (zx, zy), psi, c_s)
        return ray, ray.touch_cn - c_n

    def _build_ray(
        self, rot: np.ndarray, x_axis: tuple[float, float], z_axis: tuple[float, float], psi: float, c_s: float
    ) -> _RayTable:
        section = self._outline.section(np.array(x_axis), np.array(z_axis), c_s)
        table = self._pad.table(section, self.obj.material_params)
        if self.pad_offset_mm:
            # the pad computes its torques about its own centre; the tool's are about the TCP, and the pad's centre is
            # at r = (m, 0, 0) mm from it: tau += r x F
            table.wrench_tool[:, 4] -= self.pad_offset_mm * 1e-3 * table.wrench_tool[:, 2]
            table.wrench_tool[:, 5] += self.pad_offset_mm * 1e-3 * table.wrench_tool[:, 1]
        ray = _RayTable(table, self.obj.material_params, self.params, rot, psi, c_s)
        self._rays.insert(0, ray)
        del self._rays[RAYS_KEPT:]
        self.rays_built += 1
        return ray


# =================================================================================================================
# One press ray: the pad table plus the object's global spring, indexed by travel
# =================================================================================================================


class _RayTable:
    """Loads and wrench against travel past first touch along one press ray (pad orientation + lateral offset)."""

    def __init__(
        self, table: PadTable, material: MaterialSpec, params: SceneParams, rot: np.ndarray, psi: float, c_s: float
    ) -> None:
        self.psi = psi
        self.c_s = c_s
        self.touch_cn = table.touch_cn
        self.has_displacement = table.displacement is not None
        force = -table.wrench_tool[:, 2]
        corner_factor = 1.0 + (material.corner_stiffness_factor - 1.0) * table.corner_proximity
        k0 = material.global_stiffness_n_per_mm * corner_factor
        w_object = _cubic_spring_deflection(force, k0, material.global_cubic_n_per_mm3)
        travel = table.depth + force / params.mount_stiffness_n_per_mm + w_object
        self.travel = travel
        self.force = force
        self.loads = table.loads
        self.displacement = table.displacement
        wrench = table.wrench_tool
        self.wrench_base = np.concatenate([wrench[:, :3] @ rot.T, wrench[:, 3:] @ rot.T], axis=1)
        self._travel_list = travel.tolist()
        self.n_taxels = table.loads.shape[1]
        # the differences of neighbouring rows, formed once for the tables asked about every control period or sample
        self.wrench_steps = _row_steps(self.wrench_base)
        self._load_steps = _row_steps(self.loads)
        self._displacement_steps = None if self.displacement is None else _row_steps(self.displacement)

    def _segment(self, travel: float) -> tuple[int, float]:
        t = self._travel_list
        i = bisect.bisect_right(t, travel)
        i = min(max(i, 1), len(t) - 1)  # beyond the ends: extrapolate the first/last segment
        span = t[i] - t[i - 1]
        frac = (travel - t[i - 1]) / span if span > 0 else 0.0
        return i, frac

    def interp(self, values: np.ndarray, travel: float, steps: np.ndarray | None = None) -> np.ndarray:
        """``values`` (one row per travel) at ``travel``, linearly; ``steps``: its :func:`_row_steps` if kept."""
        i, frac = self._segment(travel)
        step = values[i] - values[i - 1] if steps is None else steps[i - 1]
        return values[i - 1] + frac * step

    def loads_at(self, travel: float) -> TaxelLoads:
        if travel <= 0.0 or not math.isfinite(self.touch_cn):
            zeros = np.zeros((self.n_taxels, 3))
            return TaxelLoads(zeros, zeros.copy() if self.has_displacement else None)
        forces = self.interp(self.loads, travel, self._load_steps)
        disp = (
            self.interp(self.displacement, travel, self._displacement_steps) if self.displacement is not None else None
        )
        return TaxelLoads(forces, disp)


def _row_steps(values: np.ndarray) -> np.ndarray:
    """``values[i + 1] - values[i]`` for every row i: what an interpolation between the two rows subtracts."""
    return values[1:] - values[:-1]


def _cubic_spring_deflection(force: np.ndarray, k0: float, k3: float) -> np.ndarray:
    """Deflection w (mm) of the spring ``F = k0 w + k3 w^3`` under ``force`` (N); Cardano's real root."""
    f = np.maximum(np.asarray(force, dtype=np.float64), 0.0)
    if k3 <= 0.0:
        return f / k0
    q = f / (2.0 * k3)
    p3 = (k0 / (3.0 * k3)) ** 3
    root = np.sqrt(q * q + p3)
    return np.cbrt(q + root) + np.cbrt(q - root)
