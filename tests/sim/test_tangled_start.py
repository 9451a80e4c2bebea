"""A tangled start (issue 13): with allow_initial_intersections, the crossing pairs of the initial state are
exempt from collision handling until they come apart, the count of those left is in every frame's stats,
and no new crossing appears."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from pscc.bench.oracle import crossings
from pscc.mesh.generate import grid_sheet
from pscc.scenes.scene_file import load_scene_file
from pscc.sim.simulation import Simulation
from pscc.sim.solver import SimulationError

SCENE = """
[solver]
gravity = [0.0, 0.0, 0.0]
[contact]
allow_initial_intersections = true
[[cloth]]
name = "below"
translate = [0.12, 0.12, 0.0]
pins = { corner = ["bottom-left", "bottom-right", "top-left", "top-right"] }
[cloth.sheet]
size = [0.24, 0.24]
cells = [12, 12]
[[cloth]]
name = "bumped"
mesh = "bumped.npz"
pins = { corner = ["bottom-left", "bottom-right", "top-left", "top-right"] }
"""


def _scene(folder: Path) -> Path:
    """A sheet 1 cm above another whose middle bulges 8 mm through it (its rest shape is flat)."""
    vertices, faces, rest = grid_sheet(12, 12, 0.24, 0.24)
    bumped = vertices.astype(np.float64)
    bumped[:, 2] = 0.01 - 0.018 * np.exp(-(np.linalg.norm(bumped[:, :2] - 0.12, axis=1) / 0.03) ** 2)
    np.savez(folder / "bumped.npz", vertices=bumped, faces=faces, rest=rest)
    path = folder / "scene.toml"
    path.write_text(SCENE)
    return path


def test_a_sheet_bulging_through_another_comes_apart(tmp_path: Path) -> None:
    scene, contact, _ = load_scene_file(_scene(tmp_path))
    sim = Simulation(scene, device="cpu", contact=contact)
    assert sim.solver.initial_crossings > 0
    faces = sim.solver.collision_faces
    counts = []
    for _ in range(6):
        record = sim.step_frame()
        assert record["counts"]["halvings"] == 0
        counts.append(record["counts"].get("intersecting_pairs", 0))
    # The bulge springs back through the lower sheet (its rest shape is flat): every crossing is gone after
    # the first frame, and none appears afterwards (ipctk, nothing exempt).
    assert counts == [0] * 6
    assert sim.solver.intersecting_pairs == 0
    assert crossings(sim.state.positions.numpy(), faces).shape == (0, 3)
    bulge = len(scene.vertices) - 169 + 84  # the bumped sheet's middle vertex
    assert sim.state.positions.numpy()[bulge, 2] > 0.005  # back above the lower sheet


def test_without_the_exemption_the_same_start_fails(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """The collision response alone cannot take crossing features apart (what the exemption is for)."""
    from pscc.sim.solver import ClothSolver

    monkeypatch.setattr(ClothSolver, "_join_crossings", lambda self, crossings: None)
    scene, contact, _ = load_scene_file(_scene(tmp_path))
    sim = Simulation(scene, device="cpu", contact=contact)
    with pytest.raises(SimulationError, match="could not be made intersection-free"):
        sim.step_frame()
