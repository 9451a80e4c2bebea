"""A scene: the cloth, its material, handles, obstacles and time stepping (what a solver runs)."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from pscc.sim.config import ClothMaterial, SolverConfig
from pscc.sim.obstacles import Handle, Obstacle


@dataclass
class Scene:
    """Everything the simulator needs to run a scene.

    Attributes:
        name: scene name.
        description: one line for ``pscc scenes`` and the stats.
        vertices: (n, 3) float32 initial cloth positions [m].
        faces: (m, 3) int32 cloth triangles.
        rest: (n, 2) float32 material (flat pattern) coordinates [m], or an (n, 3) rest shape [m] (each
            triangle's rest shape is its own; bending rest angles from the dihedral angles of that shape).
        object_ids: (m,) int32 cloth piece of each face.
        material: the cloth material of every piece, or a list indexed by ``object_ids`` (one
            material per piece). The contact distance is the largest thickness.
        solver: integration settings.
        handles: prescribed cloth vertices (pins and scripted ends).
        obstacles: animated rigid obstacles.
        frame_time: time between written frames [s].
        steps_per_frame: time steps per frame (dt = frame_time / steps_per_frame).
        flat_bending: optional (m,) bool: faces whose bending rest angles are 0 although the rest
            shape is 3-D (hinges with such a face bend towards flat).
        stitches: optional (s, 4) float64 rows ``(i, j, k, r)`` of cloth vertex ids: vertex i is sewn to
            the point (1 - r) x_j + r x_k (a seam). Stiff zero-length springs in the implicit solve; the
            stitched features never count as a contact or an intersection (``docs/simulator.md``).
    """

    name: str
    description: str
    vertices: np.ndarray
    faces: np.ndarray
    rest: np.ndarray
    object_ids: np.ndarray
    material: ClothMaterial | list[ClothMaterial] = field(default_factory=ClothMaterial)
    solver: SolverConfig = field(default_factory=SolverConfig)
    handles: list[Handle] = field(default_factory=list)
    obstacles: list[Obstacle] = field(default_factory=list)
    frame_time: float = 1.0 / 30.0
    steps_per_frame: int = 8
    flat_bending: np.ndarray | None = None
    stitches: np.ndarray | None = None

    @property
    def time_step(self) -> float:
        """dt [s]."""
        return self.frame_time / self.steps_per_frame
