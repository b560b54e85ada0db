"""The press scene as a :class:`~unitac_rig.sim.sensor_signals.SignalSource`: what the simulated sensor device sends.

Each sample asks ``pose_provider`` for the arm's current TCP pose (the simulated arm's state, base frame), asks the
scene what every taxel feels there, and turns that into wire units with the sensor's output model. The simulated
device (``unitac_rig.sim.devices``) calls :meth:`SceneSensorSource.sample` once per sample period and encodes it.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from unitac_rig.errors import ConfigError
from unitac_rig.sim.scene import PressScene
from unitac_rig.sim.sensor_models import PapillArrayModel, UskinModel, model_for
from unitac_rig.sim.sensor_signals import SensorSample


class SceneSensorSource:
    """Samples ``scene`` at the pose ``pose_provider()`` returns, through ``model`` (uSkin counts or PapillArray N)."""

    def __init__(
        self,
        scene: PressScene,
        model: UskinModel | PapillArrayModel | None,
        pose_provider: Callable[[], np.ndarray],
    ) -> None:
        self.scene = scene
        self.model = model if model is not None else model_for(scene.layout)
        if self.model.layout.name != scene.layout.name:
            raise ConfigError(
                f"sensor model is for {self.model.layout.name!r} but the scene's pad is {scene.layout.name!r}",
                hint="build the model for the scene's layout (sensor_models.model_for(scene.layout))",
            )
        self.pose_provider = pose_provider
        self.samples = 0

    def sample(self, t_ns: int) -> SensorSample:
        """The reading at device time ``t_ns`` (the scene is quasi-static: only the current pose matters)."""
        loads = self.scene.taxel_loads(np.asarray(self.pose_provider(), dtype=np.float64))
        self.samples += 1
        return self.model.sample(loads, t_ns)
