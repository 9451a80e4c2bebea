"""A garment that starts in contact (closer than the thickness to a body and to another layer) is normal
input: accepted, separated to about the thickness without halved steps or intersections, never refused
(issue 13). Not yet gentle: the outer layer first overshoots by about 2 thicknesses (see the test)."""

from __future__ import annotations

from pathlib import Path

import ipctk
import numpy as np

from pscc.scenes.scene_file import load_scene_file
from pscc.sim.simulation import Simulation

THICKNESS = 0.002
SCENE = """
[scene]
frames = 4
[[cloth]]
name = "inner"
translate = [0.0, 0.0, 0.0503]
[cloth.sheet]
size = [0.3, 0.3]
cells = [10, 10]
[[cloth]]
name = "outer"
translate = [0.0, 0.0, 0.0506]
[cloth.sheet]
size = [0.24, 0.24]
cells = [8, 8]
[[obstacle]]
box = { size = [1.0, 1.0, 0.1] }
"""


def test_layers_starting_inside_the_thickness_separate_gently(tmp_path: Path) -> None:
    # The inner layer starts 0.3 mm above the box's top (z = 0.05), the outer one 0.3 mm above it:
    # both well inside the 2 mm thickness.
    (tmp_path / "scene.toml").write_text(SCENE)
    scene, contact, _ = load_scene_file(tmp_path / "scene.toml")
    sim = Simulation(scene, device="cpu", contact=contact)
    inner = np.arange(121)
    outer = np.arange(121, 202)
    start = scene.vertices.astype(np.float64)
    faces = sim.solver.collision_faces
    for frame in range(4):
        record = sim.step_frame()
        assert record["counts"]["halvings"] == 0
        x = sim.state.positions.numpy().astype(np.float64)
        cloth = x[:len(scene.vertices)]
        if frame == 0:
            # The push-out is not gentle yet: the stiff contact springs restore the whole missing gap in a
            # few steps, and the outer layer overshoots to about 3 thicknesses before it settles. Bounded here
            # so that it cannot get worse unnoticed.
            assert np.abs(cloth - start).max() < 4 * THICKNESS
        mesh = ipctk.CollisionMesh(np.zeros_like(x), ipctk.edges(faces), faces)
        assert not ipctk.has_intersections(mesh, x)
    # Separated to about the thickness: from the box, and between the layers (at the outer layer's middle).
    assert 0.7 * THICKNESS < cloth[inner, 2].min() - 0.05 < 1.5 * THICKNESS
    middle = outer[np.argsort(np.linalg.norm(cloth[outer, :2], axis=1))[:9]]
    below = inner[np.argsort(np.linalg.norm(cloth[inner, :2], axis=1))[:9]]
    assert 0.7 * THICKNESS < cloth[middle, 2].mean() - cloth[below, 2].mean() < 1.5 * THICKNESS
