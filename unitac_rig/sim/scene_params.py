"""Every number of the press scene (:mod:`unitac_rig.sim.scene`) with its source, in one frozen dataclass that the
scene, its pad models (:mod:`unitac_rig.sim.scene_pads`) and the sensor models read; docs/simulator.md says how each
was fitted."""

from __future__ import annotations

from dataclasses import dataclass, replace

from unitac_rig.errors import ConfigError


@dataclass(frozen=True)
class SceneParams:
    """Every number of the scene model, with its source: [S] stated, [D] derived, [I] inferred or fitted."""

    # ---- uSkin uSPa46 pad ----------------------------------------------------------------------------------
    skin_foundation_n_per_mm3: float = 0.53  # [I] Winkler K = E_eff/h: E 0.3-1 MPa x2-10 (bonded, incompressible),
    # h ~2.5 mm, so 0.24-4; refitted (fidelity.py fit @dfa451f) toward the soft end: a softer skin widens a circle's
    # contact more than a corner's, lowering the circles' uSkin maxima against the prisms'; ~0.9 mm under a corner
    skin_spread_sigma_mm: float = 2.0  # [I] Gaussian load spreading of the continuous skin, 2-4 mm (0.3-0.55 pitch)
    skin_margin_x_mm: float = 4.55  # [S] first taxel 4.55 mm from the pad edge across the press (LeapXELA layout)
    skin_margin_y_mm: float = 4.43  # [S] same along the prism axis
    skin_friction: float = 0.18  # [I] fitted: Coulomb coefficient of the skin on either printed material (caps skin
    # shear at mu * p). Far below silicone on PLA/TPU (0.6-1.0): the recorded uSkin minima are the same on the
    # hexagon and the square (-2.7k..-3.1k counts) although the square's faces tilt further, so the skin slides
    # (capped) on both; one value serves both materials, the TPU sessions' larger lateral readings come from the
    # wall's drag (MaterialSpec.skin_drag_mm)
    skin_flank_friction: float = 0.0  # [S/I] mu of the skin on a printed flank when the flank sets the shear's
    # direction (scene_pads.flank_shear_ratio): shear/normal tan(phi - atan mu) past Coulomb's cone, 0 inside it;
    # 0 = off (the fitted c * tan(tilt) capped at skin_friction). Rubber on printed PLA 0.62-0.76 [S], silicone on
    # PLA 0.6-1.0 [I] (scene facts section 4)
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
                self.skin_flank_friction,
            )
            < 0
        ):
            raise ConfigError(
                "scene error spreads, the skin bulge and friction cannot be negative",
                hint="centring_error_mm, rotation_error_deg, pad_pitch_sd_deg, skin_bulge_mm, skin_friction,"
                " pillar_friction, skin_flank_friction >= 0",
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
