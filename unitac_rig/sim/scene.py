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

Why one module of ~800 lines: the 2-D section, both pad models and the per-ray tables share one parameter set and
the same geometry helpers, and the physics is easiest to check read top to bottom.
"""

from __future__ import annotations

import bisect
import logging
import math
import threading
from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np

from drivers.layouts import SensorLayout
from unitac_rig.errors import ConfigError
from unitac_rig.rig.objects import DEFAULT_OBJECT_CENTER_M, MaterialSpec, ObjectSpec
from unitac_rig.rig.poses import matrix_to_rotvec, rotvec_to_matrix

log = logging.getLogger(__name__)

RAYS_KEPT = 8  # press rays whose tables stay cached (a press, its retract, and a few neighbours)
NO_CONTACT_MARGIN_MM = 1.0  # beyond this past the outline's reach toward the pad no ray can touch: no table is built
TILT_ITERATIONS = 200  # fixed-point steps allowed for the object's bending tilt (38 at a 110 mm lever on TPU)


@dataclass(frozen=True)
class SceneParams:
    """Every number of the scene model, with its source: [S] stated, [D] derived, [I] inferred or fitted."""

    # ---- uSkin uSPa46 pad ----------------------------------------------------------------------------------
    skin_foundation_n_per_mm3: float = 0.53  # [I] Winkler K = E_eff/h: E 0.3-1 MPa x2-10 (bonded, incompressible),
    # h ~2.5 mm, so 0.24-4; refitted (benchmarks/fidelity_fit.py) toward the soft end: a softer skin widens a circle's
    # contact more than a corner's, lowering the circles' uSkin maxima against the prisms'; ~0.9 mm under a corner
    skin_spread_sigma_mm: float = 2.0  # [I] Gaussian load spreading of the continuous skin, 2-4 mm (0.3-0.55 pitch)
    skin_margin_x_mm: float = 4.55  # [S] first taxel 4.55 mm from the pad edge across the press (LeapXELA layout)
    skin_margin_y_mm: float = 4.43  # [S] same along the prism axis
    skin_friction: float = 0.18  # [I] fitted: Coulomb coefficient of the skin on either printed material (caps skin
    # shear at mu * p). Far below silicone on PLA/TPU (0.6-1.0): the recorded uSkin minima are the same on the
    # hexagon and the square (-2.7k..-3.1k counts) although the square's faces tilt further, so the skin slides
    # (capped) on both; one value serves both materials, the TPU sessions' larger lateral readings come from the
    # wall's drag (MaterialSpec.skin_drag_mm)
    # ---- PapillArray pad -----------------------------------------------------------------------------------
    pillar_axial_n_per_mm: float = 6.0  # [D] 15 N / 2.5 mm range ratio; data: 4.9 N at 0.86 mm
    pillar_lateral_n_per_mm: float = 1.2  # [I] fitted: data pillar shear ~1.9 N with displacement ~1.5 mm
    # (the spec's 4 N / 1 mm range ratio would give 4 N/mm; the recorded displacements say the tips are softer)
    pillar_tip_radius_mm: float = 3.0  # [S] pillars 6 mm diameter, hemispherical tips
    pillar_edge_recess_mm: float = 0.4  # [I] edge pillars below the centre one (spec: centre tallest), 0.3-0.5
    pillar_corner_recess_mm: float = 0.8  # [I] corner pillars, 0.6-1.0
    pillar_friction: float = 0.45  # [I] fitted: Coulomb coefficient of the silicone pillar tips on either printed
    # material, caps pillar shear at mu * normal (handbook silicone on PLA 0.6-1.0, on TPU 0.8-1.2; printed layer
    # lines and the tips' coating are not in those). With shear_projection 0.55 it binds on the square's corners
    # (recorded pillar minima -1.56/-1.86 N, PLA/TPU) but not on the hexagon's 30 deg tilts (-1.30/-1.09 N), which is
    # the recorded ~1.4x between them; a cap binding on both (0.32 with c = 1) gave them the same
    # ---- contact and object --------------------------------------------------------------------------------
    shear_projection: float = 0.55  # [I] fitted: c in q = c * p * tan(tilt), capped at mu * p. 1 = a frictionless
    # contact (force along the surface normal), 0 = a contact that sticks as the pad moves along its own normal; a
    # hemispherical tip rolls and slips part-way. 0.55 puts the pillars' shear at the recorded hexagon/square ratio
    mount_stiffness_n_per_mm: float = 20.0  # [I] printed object adapter + sensor adapter + arm, fitted so that
    # k * v * t_latency gives the recorded 0.6-1.8 N overshoot at 2-10 mm/s with 10-20 ms stop latency
    corner_decay_mm: float = 4.0  # [I] how far (along the outline) a corner stiffens a soft wall, ~1.5 walls
    corner_contact_depth_mm: float = 0.3  # [I] outline within this depth of first touch counts as the contact
    # when deciding whether the object's global spring is loaded at a corner
    centring_error_mm: float = 0.4  # [I] fitted: std of the object's placement error per axis (seeded, per
    # placement). The recorded uSkin circle maxima (1785 / 1608 counts) are what a contact on the pad's middle column
    # boundary gives (1753 / 1629 here); each mm off it adds ~25 %, so the placement error is small
    rotation_error_deg: float = 0.0  # [I] std of the object's rotation on its adapter about the prism axis (seeded
    # per placement, after the centring error); 0 by default: 2 deg moves no fidelity target (docs/simulator.md)
    # ---- sensor mount --------------------------------------------------------------------------------------
    pad_pitch_deg: float = 7.0  # [I] mean pitch beta of the pad about its x axis on its mount: the contact normal
    # leans off the pad normal by beta, giving vertical (layout y) shear q_y = c * tan(beta) * p, capped by friction;
    # beta > 0 pushes the taxels toward the pad's +y. The data fix c * tan(beta) (~6.7 % of normal: the 0.06 N face
    # y-std target), not beta alone: with c = 0.55 that is 7 deg (3.5 deg when c was 1)
    pad_pitch_sd_deg: float = 0.5  # [I] seeded spread of beta from one mounting to the next (drawn per scene)
    skin_pad_offset_mm: float = 0.0  # [I] where the uSkin pad's centre sits off the tool axis along the pad's x
    # (mm): an error of the sensor's adapter or of the TCP set for it, the same for every object that sensor presses
    # (the centring error is drawn per placement). 0: the recorded uSkin circle maxima say its contacts were centred
    pillar_pad_offset_mm: float = -1.3  # [I] fitted: the same for the PapillArray. Both recorded circle sessions
    # read pillar minima of -0.12 / -0.17 N and -0.11 / -0.12 mm (PLA / TPU), a lateral load a centred cylinder does
    # not give: a tip 1.3 mm off the cylinder's crest leans by c * 1.3 / 28 of its load. The sign is the one that
    # also makes the hexagon's displacement maxima exceed its minima, as recorded (1.13 / -1.03 mm on PLA)
    # ---- object bending ----------------------------------------------------------------------------------
    bending_lever_mm: float = 0.0  # [I] height of the press above the object's clamped collar, 55-95 mm (CAD:
    # flat walls 40-110 mm up; the pad, ~31 mm tall, presses on them); 0 = a prism that does not bend. A press of P
    # newtons tilts a cantilevered prism at the contact by P * L^2 / (2 E I), deeper toward the base: on TPU
    # (E 26 MPa) at 70 mm ~0.9 deg at 10 N on the square (I 5.9e4 mm^4), ~0.5 mm across the pad, so the rows nearer
    # the base carry more; on PLA 135x less. Off by default: measured over 10 placement draws it trades the TPU uSkin
    # misses rather than closing them (docs/simulator.md, "What is left out")
    # ---- uSkin skin bulge ----------------------------------------------------------------------------------
    skin_bulge_mm: float = 0.5  # [I] kappa: a taxel's lateral reading = -kappa * dF/ds, where F is the normal load
    # its cell would read when shifted by s (x and y): the incompressible skin is squeezed out from under a pressure
    # gradient, so magnets move away from the contact. In N of equivalent shear; sums to zero over the pad.
    # ---- fidelity (speed against accuracy: benchmarks/bench_simulator.py) -----------------------------------
    section_step_mm: float = 0.1  # sampling step of the pad section (uSkin)
    table_points: int = 200  # samples of the per-ray load table (quadratic spacing in depth)
    table_max_force_n: float = 80.0  # table range; deeper presses extrapolate the last segment linearly
    ray_tolerance_mm: float = 0.005  # a pose within this of the cached ray reuses its table
    ray_tolerance_rad: float = 1e-4

    def __post_init__(self) -> None:
        if self.section_step_mm <= 0 or self.table_points < 8 or self.table_max_force_n <= 0:
            raise ConfigError(
                "scene fidelity settings out of range",
                hint="section_step_mm > 0, table_points >= 8, table_max_force_n > 0",
            )
        if abs(self.pad_pitch_deg) >= 45.0:
            raise ConfigError("pad pitch out of range", hint="|pad_pitch_deg| < 45")
        if (
            min(
                self.centring_error_mm,
                self.rotation_error_deg,
                self.pad_pitch_sd_deg,
                self.skin_bulge_mm,
                self.skin_friction,
                self.pillar_friction,
            )
            < 0
        ):
            raise ConfigError(
                "scene error spreads, the skin bulge and friction cannot be negative",
                hint="centring_error_mm, rotation_error_deg, pad_pitch_sd_deg, skin_bulge_mm, skin_friction,"
                " pillar_friction >= 0",
            )
        if self.bending_lever_mm < 0:
            raise ConfigError("the bending lever cannot be negative", hint="bending_lever_mm >= 0 (0: no bending)")
        if self.skin_bulge_mm > 0 and self.skin_spread_sigma_mm <= 0:
            raise ConfigError(
                "the skin bulge reads the spread pressure's gradient",
                hint="skin_bulge_mm needs skin_spread_sigma_mm > 0",
            )

    def exact(self) -> SceneParams:
        """The same scene with the object placed and the pad mounted exactly (hand-worked cases and figures)."""
        return replace(
            self,
            centring_error_mm=0.0,
            rotation_error_deg=0.0,
            pad_pitch_deg=0.0,
            pad_pitch_sd_deg=0.0,
            skin_pad_offset_mm=0.0,
            pillar_pad_offset_mm=0.0,
        )


@dataclass(frozen=True, slots=True)
class TaxelLoads:
    """What each taxel feels, in the sensor frame: ``forces_n`` (n, 3) x/y shear and z normal (pushing = +), N.

    ``displacement_mm`` (n, 3): pillar tip displacements (PapillArray, along the force), else None.
    """

    forces_n: np.ndarray
    displacement_mm: np.ndarray | None = None


def pad_kind(layout: SensorLayout) -> str:
    """``"skin"`` for a continuous-skin pad (uSkin), ``"pillars"`` for separate pillars (PapillArray)."""
    if layout.name == "uskin":
        return "skin"
    if layout.name == "papillarray":
        return "pillars"
    return "pillars" if layout.has_displacement else "skin"


def press_pose(
    angle_deg: float,
    distance_mm: float,
    *,
    object_center_m: tuple[float, float] = DEFAULT_OBJECT_CENTER_M,
    height_m: float = 0.30,
) -> np.ndarray:
    """TCP pose (6,) for approach angle ``angle_deg`` with the pad centre ``distance_mm`` from the object's axis."""
    a = math.radians(angle_deg)
    u = (math.sin(a), -math.cos(a))
    x = object_center_m[0] + u[0] * distance_mm * 1e-3
    y = object_center_m[1] + u[1] * distance_mm * 1e-3
    d = (-u[0], -u[1], 0.0)
    rot = np.array([[-d[1], 0.0, d[0]], [d[0], 0.0, d[1]], [0.0, 1.0, 0.0]])
    return np.concatenate([[x, y, height_m], matrix_to_rotvec(rot)])


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
    ) -> None:
        """``rng`` draws the sensor mount's errors (the pad pitch); ``placement_rng`` the object's centring error,
        so that two scenes of one object placement with different sensors can share it. Without ``placement_rng``
        both come from ``rng`` (centring first), for a scene on its own."""
        self.obj = obj
        self.rotation_deg = float(rotation_deg)
        self.layout = layout
        self.params = params or SceneParams()
        self.kind = pad_kind(layout)
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
        self.center_mm = np.asarray(object_center_m, dtype=np.float64) * 1e3 + offset_mm  # where the object is
        # farthest any outline point reaches from the axis, plus room for pillar tips proud of the pad (mm)
        self._reach_mm = float(np.max(np.linalg.norm(np.asarray(obj.outer_mm), axis=1))) + 10.0
        self._outline = _Outline(obj, self.rotation_deg + self.rotation_error_deg)
        self.pad_offset_mm = p.skin_pad_offset_mm if self.kind == "skin" else p.pillar_pad_offset_mm
        pitch_tan = math.tan(math.radians(self.pad_pitch_deg))
        self.tilt_rad_per_n = bending_tilt_rad_per_n(obj, p.bending_lever_mm)
        self._pad: _SkinPad | _PillarPad = (
            _SkinPad(layout, p, pitch_tan, self.tilt_rad_per_n)
            if self.kind == "skin"
            else _PillarPad(layout, p, pitch_tan, self.tilt_rad_per_n)
        )
        self._rays: list[_RayTable] = []  # most recent first, a few kept so alternating rays stay cheap
        self._last_rotvec: tuple[float, float, float] | None = None
        self._frame: tuple[np.ndarray, float, float, float, float, float, float] | None = None
        # how far any pad feature stands proud of the plane whose touch the outline's reach bounds (mm): pillars
        # sit at or below the centre one (recess >= 0), the skin is that plane
        proud_mm = float(max(0.0, -np.min(self._pad.recess))) if isinstance(self._pad, _PillarPad) else 0.0
        self._no_contact_margin_mm = NO_CONTACT_MARGIN_MM + proud_mm
        self.rays_built = 0
        self._warned_tilt = False
        self._lock = threading.Lock()  # the arm and a device thread may ask at the same time
        self._wrench_key: bytes | None = None  # the pose (float64 bytes) of the last wrench_on_tool, and its answer
        self._wrench = np.zeros(6)

    # ---- ContactWorld ------------------------------------------------------------------------------------
    def wrench_on_tool(self, tcp_pose: np.ndarray) -> np.ndarray:
        """Force (N) and torque (N*m) the object exerts on the tool, base axes, about the TCP; (6,).

        The last answer is kept for its pose: an arm at rest asks about the same pose every control period.
        """
        pose = np.asarray(tcp_pose, dtype=np.float64)
        key = pose.tobytes()
        with self._lock:
            if key != self._wrench_key:
                ray, travel = self._locate_unlocked(pose, False)
                self._wrench = np.zeros(6) if travel <= 0.0 else ray.interp(ray.wrench_base, travel)
                self._wrench_key = key
            return self._wrench.copy()

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
        with self._lock:
            return self._locate_unlocked(np.asarray(tcp_pose, dtype=np.float64), need_table)

    def _locate_unlocked(self, pose: np.ndarray, need_table: bool) -> tuple[_RayTable, float]:
        rotvec = (float(pose[3]), float(pose[4]), float(pose[5]))
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
            self._frame = (
                rot, float(xh[0]), float(xh[1]), float(zh[0]), float(zh[1]), math.atan2(zh[1], zh[0]), reach
            )  # fmt: skip
            self._last_rotvec = rotvec
        rot, xx, xy, zx, zy, psi, reach = self._frame
        rel_x = self.center_mm[0] - pose[0] * 1e3
        rel_y = self.center_mm[1] - pose[1] * 1e3
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
# Geometry of the cut: the outline seen from the pad
# =================================================================================================================


class _Section:
    """The outline in pad coordinates for one ray: ``s`` across the pad (mm, TCP at 0), ``n`` toward the object.

    ``front(s)`` is how far the outline reaches toward the pad, relative to the object centre: the surface is at
    ``n = c_n + front(s)`` when the centre is at ``n = c_n``. ``slope`` = d front / ds, ``xi`` = distance along the
    outline to the nearest corner (inf without corners).
    """

    def __init__(self, outline: _Outline, x_axis: np.ndarray, z_axis: np.ndarray, c_s: float) -> None:
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


class _Outline:
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

    def section(self, x_axis: np.ndarray, z_axis: np.ndarray, c_s: float) -> _Section:
        return _Section(self, x_axis, z_axis, c_s)

    def reach_toward(self, z_axis: np.ndarray) -> float:
        """The farthest the outline reaches toward a pad looking along ``z_axis`` (unit, base xy), from the centre
        (mm): a bound on any section's touch distance along that direction, whatever its lateral offset."""
        if self.radius is not None:
            return float(self.radius)
        return float(np.max(-(self.points @ z_axis)))


# =================================================================================================================
# Pads: from the section to a table of loads against contact depth
# =================================================================================================================


@dataclass
class _PadTable:
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


class _SkinPad:
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

    def _nodes(self, section: _Section) -> np.ndarray:
        extra = (
            [section.c_s]
            if section.radius is None
            else [section.c_s - section.radius, section.c_s, section.c_s + section.radius]
        )
        cuts = np.concatenate([section.s, np.asarray(extra)]) if section.radius is None else np.asarray(extra)
        cuts = cuts[(cuts > -self.half_w) & (cuts < self.half_w)]
        return np.unique(np.concatenate([self.grid, cuts]))

    def table(self, section: _Section, material: MaterialSpec) -> _PadTable:
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
        cols = layout.cols
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
        if self.tilt_rad_per_n > 0.0:
            profile = _tilted_profile(depth, line, self.y_mid, self.y_width, self.tilt_rad_per_n, 3 * cols + 2)
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
        contact = np.minimum(gap_a, gap_b) < p.corner_contact_depth_mm
        proximity = float(np.max(np.exp(-xi[contact] / p.corner_decay_mm))) if np.any(contact) else 0.0
        return _PadTable(
            depth=depth,
            loads=loads.reshape(m, layout.n_taxels, 3),
            displacement=None,
            wrench_tool=wrench,
            touch_cn=-fmin,
            corner_proximity=proximity,
        )


class _PillarPad:
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
        :func:`_tilted_profile`; inf gaps (pillars that never touch) carry nothing."""
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

    def table(self, section: _Section, material: MaterialSpec) -> _PadTable:
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
        return _PadTable(depth, loads, disp, wrench, touch, proximity)


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


def _tilted_profile(
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


def _no_contact(layout: SensorLayout) -> _PadTable:
    zeros = np.zeros((2, layout.n_taxels, 3))
    return _PadTable(
        depth=np.array([0.0, 1.0]),
        loads=zeros,
        displacement=zeros.copy() if layout.has_displacement else None,
        wrench_tool=np.zeros((2, 6)),
        touch_cn=-math.inf,
        corner_proximity=0.0,
    )


# =================================================================================================================
# One press ray: the pad table plus the object's global spring, indexed by travel
# =================================================================================================================


class _RayTable:
    """Loads and wrench against travel past first touch along one press ray (pad orientation + lateral offset)."""

    def __init__(
        self, table: _PadTable, material: MaterialSpec, params: SceneParams, rot: np.ndarray, psi: float, c_s: float
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

    def _segment(self, travel: float) -> tuple[int, float]:
        t = self._travel_list
        i = bisect.bisect_right(t, travel)
        i = min(max(i, 1), len(t) - 1)  # beyond the ends: extrapolate the first/last segment
        span = t[i] - t[i - 1]
        frac = (travel - t[i - 1]) / span if span > 0 else 0.0
        return i, frac

    def interp(self, values: np.ndarray, travel: float) -> np.ndarray:
        i, frac = self._segment(travel)
        return values[i - 1] + frac * (values[i] - values[i - 1])

    def loads_at(self, travel: float) -> TaxelLoads:
        if travel <= 0.0 or not math.isfinite(self.touch_cn):
            zeros = np.zeros((self.n_taxels, 3))
            return TaxelLoads(zeros, zeros.copy() if self.has_displacement else None)
        forces = self.interp(self.loads, travel)
        disp = self.interp(self.displacement, travel) if self.displacement is not None else None
        return TaxelLoads(forces, disp)


def _cubic_spring_deflection(force: np.ndarray, k0: float, k3: float) -> np.ndarray:
    """Deflection w (mm) of the spring ``F = k0 w + k3 w^3`` under ``force`` (N); Cardano's real root."""
    f = np.maximum(np.asarray(force, dtype=np.float64), 0.0)
    if k3 <= 0.0:
        return f / k0
    q = f / (2.0 * k3)
    p3 = (k0 / (3.0 * k3)) ** 3
    root = np.sqrt(q * q + p3)
    return np.cbrt(q + root) + np.cbrt(q - root)
