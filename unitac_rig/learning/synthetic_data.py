"""Synthetic force-matched sets for smoke tests and training benchmarks when no campaign data is at hand.

This is *not* the simulated rig (``unitac_rig.sim`` renders real wire bytes through real drivers); it is a small
closed-form contact picture that gives every sensor a frame for the same (object, rotation, angle, force), so the
learning code has realistic sizes and a real cross-sensor signal to learn:

* the surface under the pad is the object's outline profile across the pad (catalogue outline, see
  :mod:`unitac_rig.learning.contact_geometry`); each taxel column at lateral offset x sits ``depth(x)`` mm below
  contact;
* the pad sinks ``delta = delta10 * (F / 10 N)^(2/3)`` mm (Hertz-like; soft TPU conforms more), each taxel carries a
  share of the normal force ``F`` proportional to ``max(0, delta - depth)^1.5``;
* shear along x follows the surface slope under the pad (capped at 0.4 F), spread like the normal load;
* each sensor's reading of those loads is its registered :class:`~unitac_rig.rig.sensors.SyntheticResponse`
  (uSkin: ~110 counts/N normal, 60 counts/N shear, skin spreading to neighbours, 3-count noise; PapillArray:
  newtons, 0.01 N noise, the centre pillar 0.3 mm proud); a layout no sensor registers reads newtons.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from drivers.layouts import SensorLayout
from unitac_rig.learning.contact_geometry import OutlineGeometry, local_depth_profile
from unitac_rig.rig.sensors import SENSORS, SyntheticResponse

PAPER_TARGETS_N = tuple(float(x) for x in np.round(np.arange(4.0, 10.0 + 1e-9, 0.25), 2))
PAPER_ANGLES_DEG = tuple(float(a) for a in range(-45, 46))


def _sink_mm(material: str) -> float:
    return 2.0 if material.upper() == "TPU" else 1.2


def synthetic_frame(
    layout: SensorLayout, depths_mm: np.ndarray, force_n: float, material: str, rng: np.random.Generator
) -> np.ndarray:
    """One tare-subtracted frame (n_taxels, 3) in the layout's units for a contact with per-column ``depths_mm``."""
    spec = SENSORS.get(layout.name)
    response = spec.synthetic if spec is not None else SyntheticResponse()
    cols = layout.cols
    depth = np.where(np.isnan(depths_mm), 50.0, depths_mm).astype(np.float64)
    if material.upper() == "TPU":
        depth = depth * 0.6  # a soft wall flattens against the pad
    delta = _sink_mm(material) * (force_n / 10.0) ** (2.0 / 3.0)
    grid_depth = np.tile(depth, (layout.rows, 1))  # (rows, cols): a prism is the same along y
    grid_depth[layout.rows // 2, cols // 2] -= response.proud_centre_mm  # a centre taxel that stands out
    weight = np.clip(delta - grid_depth, 0.0, None) ** 1.5
    if layout.rows > 2:
        weight[[0, -1], :] *= 0.8  # edge rows carry a little less
    if weight.sum() <= 0:
        weight[:, int(np.nanargmin(depth))] = 1.0
    share = weight / weight.sum()
    slope = float(np.nan_to_num(np.gradient(depth).mean() / max(layout.pitch_mm, 1e-6)))
    shear_total = float(np.clip(0.8 * force_n * slope, -0.4 * force_n, 0.4 * force_n))
    normal = force_n * share
    shear_x = shear_total * share
    shear_y = 0.02 * force_n * share * rng.standard_normal()
    if response.spread:
        spread = np.asarray(response.spread)
        for axis in (0, 1):
            normal = np.apply_along_axis(lambda v: np.convolve(v, spread, mode="same"), axis, normal)
    gain_n, gain_s = response.gain_normal, response.gain_shear
    frame = np.stack([gain_s * shear_x, gain_s * shear_y, gain_n * normal], axis=-1)
    frame = frame + rng.normal(0.0, response.noise, frame.shape)
    return frame.reshape(layout.n_taxels, 3).astype(np.float32)


def synthetic_matched_sets(
    object_ids: Sequence[str],
    layouts: Sequence[SensorLayout],
    *,
    angles_deg: Sequence[float] = PAPER_ANGLES_DEG,
    targets_n: Sequence[float] = PAPER_TARGETS_N,
    rotations_deg: dict[str, Sequence[float]] | None = None,
    seed: int = 0,
) -> list:
    """One :class:`unitac_rig.storage.reader.MatchedSet` per (object, layout), marked ``simulated``.

    Rotations default to the catalogue's (four for the irregular prism).
    """
    from unitac_rig.rig.objects import get_object
    from unitac_rig.storage.reader import MatchedSet

    out = []
    for object_index, object_id in enumerate(object_ids):
        spec = get_object(object_id)
        outline = OutlineGeometry.from_catalogue(object_id)
        rotations = tuple((rotations_deg or {}).get(object_id, spec.rotations_deg))
        for layout_index, layout in enumerate(layouts):
            rng = np.random.default_rng([seed, object_index, layout_index])
            columns_mm = layout.taxel_xy_mm()[: layout.cols, 0]
            rot, ang, tgt, frames, force, err = [], [], [], [], [], []
            for rotation in rotations:
                for angle in angles_deg:
                    u, origin = outline.contact(float(angle), float(rotation))
                    depths = local_depth_profile(outline.outline_mm, u, origin, columns_mm)
                    for target in targets_n:
                        measured = float(target + rng.normal(0.0, 0.05))
                        frames.append(synthetic_frame(layout, depths, measured, spec.material, rng))
                        rot.append(float(rotation))
                        ang.append(float(angle))
                        tgt.append(float(target))
                        force.append(measured)
                        err.append(measured - float(target))
            out.append(
                MatchedSet(
                    object_id=object_id,
                    sensor=layout.name,
                    simulated=True,
                    rotation_deg=np.asarray(rot),
                    angle_deg=np.asarray(ang),
                    target_n=np.asarray(tgt),
                    values=np.stack(frames),
                    force_n=np.asarray(force),
                    error_n=np.asarray(err),
                )
            )
    return out
