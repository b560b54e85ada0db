"""The object catalogue: exact cross-sections of the pressed prisms, their materials, and the rig geometry around them.

Built-in objects are the UniTac-NV prisms (``unitac_rig/data/objects.json``, outlines read from the authors' STEP
files): ``circle_pla circle_tpu square_pla square_tpu hex_pla hex_tpu irregular_pla``. Users add their own prisms
with TOML or JSON object files (:func:`load_object_file`).

Geometry conventions (shared with ``unitac_rig.rig.poses``, the press routine and the simulator):

* An outline lives in the object's CAD cross-section frame ``(x, z)`` in mm, origin on the prism axis (the collar
  axis, where every press is aimed), vertices counter-clockwise (``atan2(z, x)`` increasing).
* Mounting: the CAD ``(x, z)`` plane maps onto the robot base ``(x, y)`` plane after turning the object by
  ``rotation_deg`` about the vertical axis (positive = counter-clockwise seen from above, base +z), centred at the
  rig's object centre (default ``(-0.15, 0.625)`` m, as in the authors' setup). ``base_xy = centre + Rot(rotation) @
  cad_xz``.
* Approach angle ``theta`` in [-45, 45] deg: the pad comes from base-frame direction ``u = (sin theta, -cos theta)``
  and presses along ``d = -u`` toward the centre (the authors' angle is ``atan2(y - 0.625, x + 0.15) + 90 deg`` of the
  pad position, which gives back ``theta``).
* The TCP is the centre of the sensing surface; tool +z = d; tool x = ``(-dy, dx, 0)`` (horizontal, across the press
  = the layout's +x, column index growing); tool y = base +z (up = the layout's +y, row 0 on top).
"""

from __future__ import annotations

import functools
import json
import logging
import math
import tomllib
from collections.abc import Sequence
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, ValidationError, field_validator, model_validator

from unitac_rig.errors import ConfigError, UsageError
from unitac_rig.rig.config import describe_validation_error

log = logging.getLogger(__name__)

CIRCLE_POLYGON_VERTICES = 720  # 0.5 deg steps: a 25 mm circle deviates from its polygon by 0.24 um
DEFAULT_OBJECT_CENTER_M = (-0.15, 0.625)  # authors' prism centre in the UR5e base frame [S: 0_data_preprocessing.py]
CORNER_MAX_INTERIOR_DEG = 170.0  # vertices sharper than this count as corners (stiff, line loads)
SYMMETRY_TOLERANCE_MM = 0.05  # an outline maps onto itself when every vertex lands this close to its boundary
MAX_SYMMETRY_ORDER = 24  # rotational orders tried; beyond this an outline is treated as having none (order 1)


@dataclass(frozen=True)
class MaterialSpec:
    """How a printed prism of this material responds to a press (used by the simulated scene).

    The object sits in series with the sensor: a *global* spring (the prism translating away: ring ovalisation,
    cantilever bending), ``F = k0 * w + k3 * w**3`` with ``k0`` raised by ``corner_stiffness_factor`` when the
    contact is near a corner (load goes into two walls in-plane), and for soft materials a *local* wall compliance,
    softer mid-wall than near corners: a foundation (Winkler, N/mm^3) under a line contact along the whole pad (the
    hollow wall bends flat over a width), and a point spring (N/mm) under a single pillar tip (a local dimple).
    """

    name: str
    youngs_modulus_mpa: float  # the springs below are what the scene uses; E itself only for the optional bending
    friction: float  # Coulomb coefficient against the sensors' silicone skins, caps shear at mu * normal
    global_stiffness_n_per_mm: float  # k0, mid-wall
    global_cubic_n_per_mm3: float  # k3, geometric stiffening as the hollow wall flattens
    corner_stiffness_factor: float  # k0 (and local wall stiffness) multiplier when the contact is at a corner
    wall_foundation_n_per_mm3: float | None  # local flattening under a line contact, per area; None = rigid wall
    wall_point_stiffness_n_per_mm: float | None  # local dimpling under one pillar tip; None = rigid wall
    skin_drag_mm: float = 0.0  # a soft wall flattening under the uSkin stretches its surface outward from the
    # contact and, stuck to the skin, drags the magnets with it: an extra lateral (x) reading -drag * dF/ds on top of
    # the skin's own bulge (same form, see the scene); 0 for a wall too stiff to stretch
    source: str = ""


# Sources and the measurements behind each fit: docs/simulator.md, "Materials". [S] stated, [D] derived, [I] fitted.
MATERIALS: dict[str, MaterialSpec] = {
    "PLA": MaterialSpec(
        name="PLA",
        youngs_modulus_mpa=3500.0,  # [S] PLA filament TDS (printed walls 2-3.5 GPa [I])
        friction=0.8,  # [S/I] rubber on printed PLA 0.62-0.76, silicone on PLA 0.6-1.0
        global_stiffness_n_per_mm=150.0,  # [D] ring ovalisation 60-160 N/mm, face beam 510+ N/mm: take the soft end
        global_cubic_n_per_mm3=0.0,  # [I] linear: deflections stay ~0.1 mm
        corner_stiffness_factor=3.0,  # [I] corner loads go into two walls in-plane
        wall_foundation_n_per_mm3=None,  # [D] E is 135x TPU's: local flattening negligible next to the skin
        wall_point_stiffness_n_per_mm=None,  # [D] E t^2/R ~ 900 N/mm, 150x a pillar
        source="E 3.5 GPa (TDS); thin-ring/beam formulas in scene-facts section 4",
    ),
    "TPU": MaterialSpec(
        name="TPU",
        youngs_modulus_mpa=26.0,  # [I] TPU 95A typical TDS value (20-30 MPa)
        friction=1.0,  # [I] silicone on TPU 0.8-1.2
        global_stiffness_n_per_mm=2.0,  # [D/I] free-ring ovalisation 0.5-1.4 (lower bound), face beam 4.4-12.5
        global_cubic_n_per_mm3=0.15,  # [I] stiffening: tangent ~6 N/mm at 3 mm, 10 N reached after ~3 mm
        corner_stiffness_factor=3.0,  # [I] corner loading stiffer than face-centre loading
        wall_foundation_n_per_mm3=0.03,  # [I] fitted: at 10 N the TPU circle flattens to a ~15 mm wide contact
        wall_point_stiffness_n_per_mm=4.7,  # [D/I] shell dimple ~ E t^2 / R = 6.5 N/mm, refitted to 0.7x that
        skin_drag_mm=0.5,  # [I] fitted to the TPU sessions' uSkin lateral readings (larger than PLA's)
        source="Shore 95A TPU; thin-ring/beam formulas in scene-facts section 4",
    ),
}


@dataclass(frozen=True, eq=False)
class ObjectSpec:
    """One pressable prism: its cross-section (CAD frame, mm), material and how it is swept.

    ``outer_mm``/``inner_mm``: (N, 2) counter-clockwise polygons (circles as a fine polygon with ``radius_mm`` set).
    ``rotations_deg``: the object rotations of a campaign ((0,) or (0, 90, 180, 270) for the irregular prism).
    ``in_autoencoder_training``: False for objects kept out of autoencoder training (the unseen irregular prism).
    ``aliases``: other names for it (the authors' file names: cylinder/circular, oblong, hexagon/hexagonal, arbitrary).
    """

    id: str
    shape: str
    material: str
    outer_mm: np.ndarray
    inner_mm: np.ndarray
    wall_mm: float
    rotations_deg: tuple[float, ...] = (0.0,)
    in_autoencoder_training: bool = True
    aliases: tuple[str, ...] = ()
    radius_mm: float | None = None
    material_params: MaterialSpec = field(default_factory=lambda: MATERIALS["PLA"])
    description: str = ""

    def __post_init__(self) -> None:
        for name in ("outer_mm", "inner_mm"):
            arr = np.array(getattr(self, name), dtype=np.float64)
            arr.setflags(write=False)
            object.__setattr__(self, name, arr)

    def __repr__(self) -> str:
        return f"ObjectSpec(id={self.id!r}, shape={self.shape!r}, material={self.material!r})"

    def outline_hit(self, direction_xy: np.ndarray) -> np.ndarray:
        """Where the ray from the centre along ``direction_xy`` (CAD frame) meets the outer outline (mm, (2,))."""
        u = np.asarray(direction_xy, dtype=np.float64)
        u = u / np.linalg.norm(u)
        if self.radius_mm is not None:
            return u * self.radius_mm
        return u * _ray_polygon_distance(self.outer_mm, u)

    def corner_vertices(self) -> np.ndarray:
        """Indices of outer vertices sharper than 170 deg interior angle (none for a circle)."""
        if self.radius_mm is not None:
            return np.zeros(0, dtype=int)
        return np.flatnonzero(interior_angles_deg(self.outer_mm) < CORNER_MAX_INTERIOR_DEG)

    @functools.cached_property
    def symmetry(self) -> Symmetry:
        """The cross-section's symmetry about the prism axis, derived from its outlines (:func:`outline_symmetry`):
        two approach rays a symmetry maps onto each other press the same geometry."""
        if self.radius_mm is not None:
            return Symmetry(order=0, mirror_axis_deg=0.0)
        return outline_symmetry((self.outer_mm, self.inner_mm))

    def outer_rotated_mm(self, rotation_deg: float) -> np.ndarray:
        """The outer outline turned by ``rotation_deg`` as mounted (base-frame axes, mm, relative to the centre)."""
        return self.outer_mm @ _rotation_2d(rotation_deg).T


@dataclass(frozen=True)
class Symmetry:
    """A cross-section's symmetry group about the prism axis (the point every press aims at).

    ``order``: turning the outline by ``360 / order`` deg maps it onto itself (1: no rotational symmetry; 0: every
    angle, a circle). ``mirror_axis_deg``: the direction (CAD frame, deg) of one mirror line through the axis, or
    None without mirror symmetry (with ``order`` n there are then n mirror lines, ``180 / n`` deg apart)."""

    order: int
    mirror_axis_deg: float | None = None

    @property
    def continuous(self) -> bool:
        return self.order == 0


def outline_symmetry(outlines: Sequence[np.ndarray], tolerance_mm: float = SYMMETRY_TOLERANCE_MM) -> Symmetry:
    """The largest rotational order (up to 24) and a mirror line of closed polygons about the origin: a turn or a
    reflection is a symmetry when every vertex of every outline, mapped, lies within ``tolerance_mm`` of that
    outline's boundary and back. Mirror lines through the origin pass through a vertex or an edge's midpoint, so
    those directions are the candidates."""
    polygons = [np.asarray(p, dtype=np.float64) for p in outlines if len(p)]

    def maps_onto_itself(matrix: np.ndarray) -> bool:
        for polygon in polygons:
            mapped = polygon @ matrix.T
            if _boundary_distance(polygon, mapped).max() > tolerance_mm:
                return False
            if _boundary_distance(mapped, polygon).max() > tolerance_mm:
                return False
        return True

    order = max(n for n in range(1, MAX_SYMMETRY_ORDER + 1) if maps_onto_itself(_rotation_2d(360.0 / n)))
    outer = polygons[0]
    candidates = np.concatenate([outer, 0.5 * (outer + np.roll(outer, -1, axis=0))])
    for phi in sorted({round(math.degrees(math.atan2(z, x)) % (180.0 / order), 6) for x, z in candidates}):
        c, s = math.cos(math.radians(2 * phi)), math.sin(math.radians(2 * phi))
        if maps_onto_itself(np.array([[c, s], [s, -c]])):
            return Symmetry(order=order, mirror_axis_deg=float(phi))
    return Symmetry(order=order)


def _boundary_distance(polygon: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Each point's distance to the closed polygon's boundary (mm)."""
    a = polygon[None, :, :]
    e = np.roll(polygon, -1, axis=0)[None, :, :] - a
    d = points[:, None, :] - a
    t = np.clip(np.sum(d * e, axis=2) / np.maximum(np.sum(e * e, axis=2), 1e-18), 0.0, 1.0)
    return np.min(np.linalg.norm(d - t[..., None] * e, axis=2), axis=1)


def pad_side_direction(angle_deg: float, rotation_deg: float) -> np.ndarray:
    """Unit 2-vector in the object's CAD frame from the object centre toward where the pad comes from.

    Base frame: ``u = (sin theta, -cos theta)``; the object is turned by ``rotation_deg``, so in CAD axes it is
    ``Rot(-rotation_deg) @ u``.
    """
    a = math.radians(angle_deg)
    u = np.array([math.sin(a), -math.cos(a)])
    return _rotation_2d(-rotation_deg) @ u


def interior_angles_deg(polygon: np.ndarray) -> np.ndarray:
    """Interior angle at each vertex of a counter-clockwise polygon (deg)."""
    p = np.asarray(polygon, dtype=np.float64)
    to_prev = np.roll(p, 1, axis=0) - p
    to_next = np.roll(p, -1, axis=0) - p
    cross = to_next[:, 0] * to_prev[:, 1] - to_next[:, 1] * to_prev[:, 0]
    dot = np.sum(to_next * to_prev, axis=1)
    return np.degrees(np.mod(np.arctan2(cross, dot), 2 * np.pi))


def offset_polygon_inward(polygon: np.ndarray, distance_mm: float) -> np.ndarray:
    """Move every edge of a counter-clockwise polygon inward by ``distance_mm`` (mitred corners)."""
    p = np.asarray(polygon, dtype=np.float64)
    edge = np.roll(p, -1, axis=0) - p
    edge /= np.linalg.norm(edge, axis=1, keepdims=True)
    inward = np.stack([-edge[:, 1], edge[:, 0]], axis=1)  # left of a CCW edge is inside
    prev_edge, prev_in = np.roll(edge, 1, axis=0), np.roll(inward, 1, axis=0)
    # vertex i: intersection of the offset lines of edge i-1 and edge i
    a0 = p + distance_mm * prev_in
    a1 = p + distance_mm * inward
    denom = prev_edge[:, 0] * edge[:, 1] - prev_edge[:, 1] * edge[:, 0]
    diff = a1 - a0
    t = (diff[:, 0] * edge[:, 1] - diff[:, 1] * edge[:, 0]) / denom
    return a0 + t[:, None] * prev_edge


def _rotation_2d(angle_deg: float) -> np.ndarray:
    a = math.radians(angle_deg)
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s], [s, c]])


def _ray_polygon_distance(polygon: np.ndarray, u: np.ndarray) -> float:
    """Distance from the origin along unit ``u`` to the polygon boundary (nearest crossing, mm)."""
    a = polygon
    b = np.roll(polygon, -1, axis=0)
    e = b - a
    denom = u[0] * e[:, 1] - u[1] * e[:, 0]
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (a[:, 0] * e[:, 1] - a[:, 1] * e[:, 0]) / denom  # along the ray
        s = (a[:, 0] * u[1] - a[:, 1] * u[0]) / denom  # along the edge
    ok = (np.abs(denom) > 1e-12) & (s >= -1e-9) & (s <= 1 + 1e-9) & (t > 0)
    if not np.any(ok):
        raise ConfigError("the ray from the object centre misses its outline", hint="the centre must lie inside")
    return float(np.min(t[ok]))


def _circle_polygon(radius_mm: float) -> np.ndarray:
    angles = np.linspace(0.0, 2 * np.pi, CIRCLE_POLYGON_VERTICES, endpoint=False)
    return radius_mm * np.stack([np.cos(angles), np.sin(angles)], axis=1)


def _signed_area(polygon: np.ndarray) -> float:
    x, z = polygon[:, 0], polygon[:, 1]
    return 0.5 * float(np.sum(x * np.roll(z, -1) - np.roll(x, -1) * z))


def _star_shaped_about_origin(polygon: np.ndarray) -> bool:
    """True when every edge turns counter-clockwise about the origin (each ray from it crosses the outline once)."""
    b = np.roll(polygon, -1, axis=0)
    return bool(np.all(polygon[:, 0] * b[:, 1] - polygon[:, 1] * b[:, 0] > 1e-9))


def _edge_distances_from_origin(polygon: np.ndarray) -> np.ndarray:
    b = np.roll(polygon, -1, axis=0)
    e = b - polygon
    return np.abs(polygon[:, 0] * e[:, 1] - polygon[:, 1] * e[:, 0]) / np.linalg.norm(e, axis=1)


# ---------------------------------------------------------------------------------------------------------------
# Object files
# ---------------------------------------------------------------------------------------------------------------


class ObjectFile(BaseModel):
    """Schema of a user object file (TOML or JSON). Lengths in mm, angles in degrees, CAD cross-section frame."""

    model_config = ConfigDict(extra="forbid")

    id: str = Field(pattern=r"^[a-z0-9][a-z0-9_\-]*$", description="lower-case id used on the command line")
    shape: str = Field("user", description="circle, square, hexagon, irregular or any label")
    material: str = Field(description="a known material: " + ", ".join(MATERIALS))
    radius_mm: float | None = Field(None, gt=0, description="outer radius of a circular prism")
    outline_mm: list[tuple[float, float]] | None = Field(
        None, min_length=3, description="outer vertices (x, z) around the prism axis, either orientation"
    )
    wall_mm: float = Field(gt=0, description="wall thickness of the hollow prism")
    rotations_deg: list[float] = Field(default_factory=lambda: [0.0], min_length=1)
    in_autoencoder_training: bool = True
    aliases: list[str] = Field(default_factory=list)
    description: str = ""

    @field_validator("material")
    @classmethod
    def _known_material(cls, value: str) -> str:
        upper = value.upper()
        if upper not in MATERIALS:
            raise ValueError(f"unknown material {value!r}; known: {', '.join(MATERIALS)}")
        return upper

    @model_validator(mode="after")
    def _geometry(self) -> ObjectFile:
        if (self.radius_mm is None) == (self.outline_mm is None):
            raise ValueError("give exactly one of radius_mm (circle) or outline_mm (polygon)")
        if self.radius_mm is not None and self.wall_mm >= self.radius_mm:
            raise ValueError(f"wall_mm {self.wall_mm} must be smaller than radius_mm {self.radius_mm}")
        if self.outline_mm is not None:
            poly = np.asarray(self.outline_mm, dtype=np.float64)
            if not np.all(np.isfinite(poly)):
                raise ValueError("outline_mm has non-finite values")
            if _signed_area(poly) < 0:
                poly = poly[::-1]
                self.outline_mm = [(float(x), float(z)) for x, z in poly]  # counter-clockwise from here on
            if not _star_shaped_about_origin(poly):
                raise ValueError(
                    "outline_mm must surround the origin (the prism axis) and be seen whole from it: every ray "
                    "from the origin must cross the outline once"
                )
            inradius = float(np.min(_edge_distances_from_origin(poly)))
            if self.wall_mm >= inradius:
                raise ValueError(f"wall_mm {self.wall_mm} must be smaller than the outline's inradius {inradius:.3f}")
            if not _star_shaped_about_origin(offset_polygon_inward(poly, self.wall_mm)):
                raise ValueError(f"the {self.wall_mm} mm wall does not fit inside the outline: use a thinner wall_mm")
        return self


def load_object_file(path: Path) -> ObjectSpec:
    """Read and validate one user object file (``.toml`` or ``.json``); errors name the file and the field."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as exc:
        raise ConfigError(f"cannot read object file {path}: {exc.strerror}", hint="check the path") from exc
    try:
        if path.suffix.lower() == ".toml":
            raw: Any = tomllib.loads(text)
        elif path.suffix.lower() == ".json":
            raw = json.loads(text)
        else:
            raise ConfigError(f"object file {path} must end in .toml or .json", hint="rename it")
    except (tomllib.TOMLDecodeError, json.JSONDecodeError) as exc:
        raise ConfigError(f"object file {path} is not valid {path.suffix[1:].upper()}: {exc}") from exc
    try:
        spec = ObjectFile.model_validate(raw)
    except ValidationError as exc:
        raise ConfigError(
            describe_validation_error(exc, f"object file {path}", ObjectFile),
            hint="see docs/simulator.md (object files) for the fields",
        ) from exc
    if spec.radius_mm is not None:
        outer, inner = _circle_polygon(spec.radius_mm), _circle_polygon(spec.radius_mm - spec.wall_mm)
    else:
        outer = np.asarray(spec.outline_mm, dtype=np.float64)
        inner = offset_polygon_inward(outer, spec.wall_mm)
    return ObjectSpec(
        id=spec.id,
        shape=spec.shape,
        material=spec.material,
        outer_mm=outer,
        inner_mm=inner,
        wall_mm=spec.wall_mm,
        rotations_deg=tuple(float(r) for r in spec.rotations_deg),
        in_autoencoder_training=spec.in_autoencoder_training,
        aliases=tuple(a.lower() for a in spec.aliases),
        radius_mm=spec.radius_mm,
        material_params=MATERIALS[spec.material],
        description=spec.description,
    )


# ---------------------------------------------------------------------------------------------------------------
# Catalogue
# ---------------------------------------------------------------------------------------------------------------


@functools.cache
def _builtin_objects() -> tuple[ObjectSpec, ...]:
    raw = json.loads(resources.files("unitac_rig").joinpath("data/objects.json").read_text(encoding="utf-8"))
    shapes = raw["shapes"]
    specs = []
    for entry in raw["objects"]:
        shape = shapes[entry["shape"]]
        radius = shape.get("radius_mm")
        if radius is not None:
            outer, inner = _circle_polygon(radius), _circle_polygon(shape["inner_radius_mm"])
        else:
            outer, inner = np.asarray(shape["outer_mm"]), np.asarray(shape["inner_mm"])
        material = entry["material"]
        specs.append(
            ObjectSpec(
                id=entry["id"],
                shape=entry["shape"],
                material=material,
                outer_mm=outer,
                inner_mm=inner,
                wall_mm=float(shape["wall_mm"]),
                rotations_deg=tuple(float(r) for r in entry.get("rotations_deg", [0.0])),
                in_autoencoder_training=bool(entry.get("in_autoencoder_training", True)),
                aliases=tuple(entry.get("aliases", ())),
                radius_mm=radius,
                material_params=MATERIALS[material],
                description=f"UniTac-NV {entry['shape']} prism, {material} ({shape['step_file']})",
            )
        )
    return tuple(specs)


def list_objects(extra_files: Sequence[Path] = ()) -> list[ObjectSpec]:
    """Built-in objects followed by those in ``extra_files``; a clash of ids or aliases is a ConfigError."""
    specs = list(_builtin_objects())
    names = {name: spec.id for spec in specs for name in (spec.id, *spec.aliases)}
    for path in extra_files:
        spec = load_object_file(Path(path))
        for name in (spec.id, *spec.aliases):
            if name in names:
                raise ConfigError(
                    f"object file {path}: name {name!r} is already used by object {names[name]!r}",
                    hint="give the object another id or alias",
                )
            names[name] = spec.id
        specs.append(spec)
    return specs


def get_object(object_id: str, extra_files: Sequence[Path] = ()) -> ObjectSpec:
    """The object with this id or alias (case-insensitive); unknown names raise UsageError listing the ids."""
    wanted = object_id.strip().lower()
    specs = list_objects(extra_files)
    for spec in specs:
        if wanted == spec.id or wanted in spec.aliases:
            return spec
    known = " ".join(spec.id for spec in specs)
    raise UsageError(f"unknown object {object_id!r}", hint=f"known objects: {known}")
