"""Proximity constraints in the projection (issue 14 item 4): the contact springs of a step's start join its
first projection round, so a response does not push a vertex out of one collision into the surface it already
touches, which the next CCD round would find. Fewer rounds, the same guarantees (no crossing)."""

from __future__ import annotations

from pathlib import Path

import ipctk
import numpy as np
import pytest
import warp as wp

from pscc.scenes.scene_file import load_scene_file
from pscc.sim.contact_config import ContactConfig
from pscc.sim.contact_springs import ContactSprings
from pscc.sim.inelastic_projection import InelasticProjection
from pscc.sim.solver import ClothSolver

EMPTY = np.zeros((0, 4), np.int32)


def _squeezed(device: str, near: bool) -> np.ndarray:
    """A free triangle (1, 2, 3) falls through the free vertex 0, which rests 0.3 mm above the kinematic
    triangle (4, 5, 6) in z = 0 (a contact spring). Returns the projected end positions."""
    x0 = np.array([[0.2, 0.2, 0.0003], [0, 0, 0.01], [1, 0, 0.01], [0, 1, 0.01], [-1, -1, 0], [2, -1, 0], [-1, 2, 0]],
                  dtype=np.float32)
    x1 = x0.copy()
    x1[1:4, 2] = -0.002  # the upper triangle passes the vertex (which stays where it is)
    inverse_mass = np.array([1, 1, 1, 1, 0, 0, 0], dtype=np.float64)
    projection = InelasticProjection(inverse_mass, wp.get_device(device), max_iterations=20000, check_every=8)
    p0 = wp.array(x0, dtype=wp.vec3, device=device)
    p1 = wp.array(x1, dtype=wp.vec3, device=device)
    projection.reset()
    # Vertex 0 against the upper triangle, linearised when the triangle is 0.7 mm above it: normal down.
    projection.add(np.array([[0, 1, 2, 3]]), np.array([0.75]), EMPTY, np.zeros(0), p0, p1)
    if near:
        springs = ContactSprings(4, rest_gap=0.002, device=device)
        under = np.array([0.4, 0.4, 0.2])  # vertex 0's barycentric coordinates on (4, 5, 6)
        springs.set(np.array([[0, 4, 5, 6]]), np.array([[1.0, *-under]]), np.array([[0.0, 0.0, 1.0]]))
        projection.add_near(springs, p1, 0.001)
        assert projection.count == 2
    projection.solve(p1, 0.001, 1e-7)
    return p1.numpy()


def test_a_near_constraint_keeps_the_response_from_pushing_a_vertex_into_what_it_touches(device: str) -> None:
    without = _squeezed(device, near=False)
    result = _squeezed(device, near=True)
    # Without it, the response pushes vertex 0 down, through the kinematic triangle under it (the next
    # round's collision); with it the vertex keeps its gap (0.3 mm, below the 1 mm separation) and the
    # falling triangle is pushed up instead, to the separation above the vertex.
    assert without[0, 2] < 0.0
    assert result[0, 2] == pytest.approx(0.0003, abs=2e-6)
    above = 0.6 * result[1, 2] + 0.2 * result[2, 2] + 0.2 * result[3, 2]  # the face point over vertex 0
    assert above - result[0, 2] == pytest.approx(0.001, abs=2e-6)


SCENE = """
[scene]
frames = 1
[[cloth]]
name = "lower"
translate = [0.0, 0.0, 0.0505]
[cloth.sheet]
size = [0.2, 0.2]
cells = [6, 6]
[[cloth]]
name = "upper"
translate = [0.0, 0.0, 0.0555]
[cloth.sheet]
size = [0.14, 0.14]
cells = [5, 5]
[[obstacle]]
box = { size = [1.0, 1.0, 0.1] }
"""


def _drop_onto_resting_layer(tmp_path: Path, near: bool) -> tuple[dict, np.ndarray, ClothSolver]:
    """One step of an upper sheet thrown (3 m/s) onto a lower one that rests 0.5 mm above a box: the upper
    sheet passes through the lower one within the step."""
    (tmp_path / "scene.toml").write_text(SCENE)
    scene, _, _ = load_scene_file(tmp_path / "scene.toml")
    solver = ClothSolver(scene, device="cpu", contact=ContactConfig(proximity_constraints=near))
    state, after = solver.initial_state(), solver.initial_state()
    solver.step(state, after, scene.time_step)  # at rest: the step's DCD finds the lower layer's springs
    velocities = after.velocities.numpy().copy()
    velocities[49:85, 2] = -3.0  # the upper sheet's 36 vertices (the lower one has 49)
    after.velocities.assign(velocities)
    stats = solver.step(after, state, scene.time_step)
    return stats["counts"], state.positions.numpy().astype(np.float64), solver


def test_the_lower_layer_is_not_pushed_into_the_box_so_one_round_resolves_the_drop(tmp_path: Path) -> None:
    old, _, _ = _drop_onto_resting_layer(tmp_path, near=False)
    counts, x, solver = _drop_onto_resting_layer(tmp_path, near=True)
    assert old["ccd_hits"] > 0 and old["halvings"] == 0 == counts["halvings"]
    # Without the proximity constraints the first response pushes the lower layer into the box (the second
    # round's collisions); with them one response round is enough.
    assert old["projection_rounds"] >= 2
    assert counts["projection_rounds"] == 1
    assert counts["ccd_rounds"] < old["ccd_rounds"]
    assert counts["zone_rounds"] == 0
    faces = solver.collision_faces
    mesh = ipctk.CollisionMesh(np.zeros_like(x), ipctk.edges(faces), faces)
    assert not ipctk.has_intersections(mesh, x)
    assert x[49:85, 2].min() > x[:49, 2].max() - 1e-9  # the upper sheet stayed above the lower one


def test_the_device_path_adds_them_in_the_first_round_like_the_host_path(tmp_path: Path) -> None:
    """The device step appends the springs in its first projection round only (the round counter gates
    the kernel), like the host path: the same rounds and, on the CPU, the same end positions."""
    counts, x_host, _ = _drop_onto_resting_layer(tmp_path, near=True)
    scene, _, _ = load_scene_file(tmp_path / "scene.toml")
    solver = ClothSolver(scene, device="cpu", contact=ContactConfig(proximity_constraints=True))
    # Room for the drop's constraints and springs (else the frame falls back to the host path to grow them).
    solver.projection.reserve(1000)
    solver.proximity.springs.ensure(1000)
    solver.integrator.system.reserve_contacts(solver.proximity.springs.capacity)
    state, scratch = solver.initial_state(), solver.initial_state()
    solver.advance_frame(state, scratch, scene.time_step, 1, graph=False)
    velocities = state.velocities.numpy().copy()
    velocities[49:85, 2] = -3.0
    state.velocities.assign(velocities)
    record = solver.advance_frame(state, scratch, scene.time_step, 1, graph=False)
    assert record["counts"]["device_fallbacks"] == 0
    assert record["counts"]["projection_rounds"] == counts["projection_rounds"] == 1
    assert record["counts"]["ccd_rounds"] == counts["ccd_rounds"]
    np.testing.assert_allclose(state.positions.numpy(), x_host, atol=1e-6)


def test_a_step_rejected_with_them_is_redone_without_them_before_halving(tmp_path: Path, monkeypatch) -> None:
    """If the constraints leave the response no room (here forced: every attempt that uses them is rejected),
    the same step runs again without them, with no halving, and ends where a run without them ends."""
    import pscc.sim.solver as solver_module

    _, x_without, _ = _drop_onto_resting_layer(tmp_path, near=False)
    attempts: list[bool] = []
    original = solver_module.ClothSolver._attempt

    def attempt(self, state_in, state_out, t, dt, stats):
        uses_them = self.contact.proximity_constraints and not self._near_off
        attempts.append(uses_them)
        if uses_them:
            raise solver_module._StepRejected("forced: no room for the response")
        return original(self, state_in, state_out, t, dt, stats)

    monkeypatch.setattr(solver_module.ClothSolver, "_attempt", attempt)
    counts, x, solver = _drop_onto_resting_layer(tmp_path, near=True)
    assert attempts.count(True) == 2 and attempts.count(False) == 2  # each of the two steps: once with, once without
    assert counts["halvings"] == 0 and not solver._near_off
    np.testing.assert_array_equal(x, x_without)
