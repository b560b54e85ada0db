"""The controller twin's contact world: the press scene the simulated arm presses into, built in the background
where the pad nears the object so that a table build never stalls the 2 ms cycle (:class:`SceneWorld`), and
:func:`build_scene`, the one place a :class:`~unitac_rig.sim.twin.params.SceneSpec` becomes a scene (the controller
and the twin's sensors build the same one)."""

from __future__ import annotations

import logging
import threading
from typing import Any

import numpy as np

from unitac_rig.rig.poses import rotvec_to_matrix
from unitac_rig.sim.twin.params import SceneSpec

logger = logging.getLogger(__name__)


class SceneWorld:
    """The contact world the arm presses into; rebuilt when a hook moves the object.

    The scene builds a contact table the first time the pad nears the object on a new press ray (0.4-35 ms on a
    2-core box), which would stall the controller cycle. So when a move starts toward a pose near the object, a
    background thread builds that ray's table (:meth:`warm`) while the cycle goes on; until it is done, poses clear of
    the object (the pad's plane more than ``_CLEAR_MARGIN_MM`` in front of the outline's farthest point) get no force
    without asking the scene, and only a pose that could touch waits for the table.
    """

    _CLEAR_MARGIN_MM = 5.0

    def __init__(self, spec: SceneSpec | None) -> None:
        self.scene: Any = None
        self.spec = spec
        self.force_scale = 1.0  # a fault hook: x10 makes the contact ten times stiffer (same geometry)
        # a fault hook: the pad as a disc of this radius against the object's circumscribed cylinder (the rim
        # contact an object standing to the side gives, sim/scene_disc.py) instead of the press scene; None: off
        self.disc: Any = None
        self._radius_mm = 0.0
        self._warming = threading.Event()
        self.warm_builds = 0
        if spec is not None:
            self.rebuild(spec)

    def rebuild(self, spec: SceneSpec) -> None:
        self.spec = spec
        self.scene = build_scene(spec)
        self._radius_mm = float(np.max(np.linalg.norm(np.asarray(self.scene.obj.outer_mm), axis=1)))

    def warm(self, pad_pose: np.ndarray) -> None:
        """Build the contact table of the ray through ``pad_pose`` in the background (no-op while one is built)."""
        scene = self.scene
        if scene is None or self._warming.is_set():
            return
        self._warming.set()
        threading.Thread(target=self._build, args=(scene, np.array(pad_pose)), name="twin-scene", daemon=True).start()

    def _build(self, scene: Any, pad_pose: np.ndarray) -> None:
        try:
            scene.wrench_on_tool(pad_pose)
            self.warm_builds += 1
        except Exception:
            logger.exception("building a contact table in the background failed")
        finally:
            self._warming.clear()

    def _clear_of_object(self, pad_pose: np.ndarray) -> bool:
        assert self.spec is not None
        press = rotvec_to_matrix(pad_pose[3:6])[:2, 2]
        norm = float(np.linalg.norm(press))
        if norm < 1e-9:
            return False
        to_axis_mm = (np.asarray(self.spec.true_center_m) - pad_pose[:2]) * 1e3
        return float(to_axis_mm @ (press / norm)) > self._radius_mm + self._CLEAR_MARGIN_MM

    def set_disc_pad(self, pad_radius_mm: float | None, stiffness_n_per_mm: float = 10.0) -> None:
        """Switch the disc-pad contact on (the pad's radius, mm, and the contact's stiffness, N/mm) or off (None)."""
        if pad_radius_mm is None or self.spec is None:
            self.disc = None
            return
        from unitac_rig.sim.scene_disc import DiscPadOnCylinder

        self.disc = DiscPadOnCylinder(
            self.spec.true_center_m,
            radius_mm=self._radius_mm,
            stiffness_n_per_mm=stiffness_n_per_mm,
            pad_radius_mm=pad_radius_mm,
        )

    def wrench_on_tool(self, tcp_pose: np.ndarray) -> np.ndarray:
        if self.disc is not None:
            return np.asarray(self.disc.wrench_on_tool(tcp_pose)) * self.force_scale
        if self.scene is None:
            return np.zeros(6)
        if self._warming.is_set() and self._clear_of_object(tcp_pose):
            return np.zeros(6)  # out of reach of the object: the scene's answer, without waiting for its lock
        result: np.ndarray = self.scene.wrench_on_tool(tcp_pose) * self.force_scale
        return result


def build_scene(spec: SceneSpec) -> Any:
    """The PressScene a :class:`SceneSpec` describes (the controller and the twin's sensors build the same one)."""
    from pathlib import Path

    from unitac_rig.rig.objects import get_object
    from unitac_rig.sim.scene import PressScene

    obj = get_object(spec.object_id, tuple(Path(p) for p in spec.objects_files))
    assert spec.layout is not None  # filled in when the spec was made
    return PressScene(
        obj,
        spec.rotation_deg,
        spec.layout,
        object_center_m=spec.true_center_m,
        rng=np.random.default_rng([spec.seed, 4]),
        pad=spec.pad,
    )
