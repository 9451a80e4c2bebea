"""Built-in simulation scenes (``pscc simulate SCENE``); see :mod:`pscc.scenes.builtin`."""

from pscc.scenes.builtin import SCENES, build_scene
from pscc.sim.scene import Scene

__all__ = ["SCENES", "Scene", "build_scene"]
