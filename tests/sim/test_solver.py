"""The solver of section 5 on small versions of the built-in scenes: every step intersection-free.

Each test steps a scene and checks after **every step** that the cloth-plus-obstacles mesh has no
intersection by ipctk's ``has_intersections`` (an independent oracle) and by our own check, that no
cloth edge is stretched by more than 10 %, that handles and pins are where their motion puts them,
and that nothing is NaN.
"""

from __future__ import annotations

import dataclasses

import ipctk
import numpy as np
import pytest
import warp as wp

from pscc.errors import InputError
from pscc.scenes import build_scene
from pscc.sim.contact_config import ContactConfig
from pscc.sim.scene import Scene
from pscc.sim.solver import ClothSolver


def _edges(faces: np.ndarray) -> np.ndarray:
    pairs = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    return np.unique(np.sort(pairs, axis=1), axis=0)


class _Checker:
    """Independent per-step checks of a solver's state."""

    def __init__(self, solver: ClothSolver) -> None:
        self.solver = solver
        faces = solver.collision_faces
        self.mesh = ipctk.CollisionMesh(np.zeros((solver.model.vertex_count, 3)), ipctk.edges(faces), faces)
        scene = solver.scene
        self.cloth_edges = _edges(scene.faces)
        rest = scene.rest[self.cloth_edges]
        self.rest_lengths = np.linalg.norm(rest[:, 0] - rest[:, 1], axis=1)
        self.max_stretch = 0.0

    def check(self, state, t: float) -> None:
        x = state.positions.numpy()
        assert np.all(np.isfinite(x)) and np.all(np.isfinite(state.velocities.numpy()))
        assert not ipctk.has_intersections(self.mesh, x.astype(np.float64)), f"ipctk: intersection at t={t:.4f}"
        assert self.solver.intersection_check.find(x).shape[0] == 0, f"own check: intersection at t={t:.4f}"
        cloth = x[: self.solver.cloth_vertex_count]
        lengths = np.linalg.norm(cloth[self.cloth_edges[:, 0]] - cloth[self.cloth_edges[:, 1]], axis=1)
        self.max_stretch = max(self.max_stretch, float((lengths / self.rest_lengths).max()))
        assert self.max_stretch <= 1.10, f"an edge stretched by {100 * (self.max_stretch - 1):.1f} % at t={t:.4f}"
        initial = self.solver.scene.vertices.astype(np.float64)
        for handle in self.solver.scene.handles:
            rotation, translation = handle.transform(t)
            expected = initial[handle.vertices] @ rotation.T + translation
            np.testing.assert_allclose(x[handle.vertices], expected, atol=1e-5)
        obstacle_vertices, _ = self.solver.obstacle_mesh(t)
        np.testing.assert_allclose(x[self.solver.cloth_vertex_count:], obstacle_vertices, atol=1e-5)


def _run(scene: Scene, steps: int, contact: ContactConfig | None = None) -> tuple[ClothSolver, _Checker, list]:
    solver = ClothSolver(scene, device="cpu", contact=contact)
    checker = _Checker(solver)
    state, other = solver.initial_state(), solver.initial_state()
    checker.check(state, 0.0)
    history = []
    for _ in range(steps):
        stats = solver.step(state, other, scene.time_step)
        state, other = other, state
        checker.check(state, solver.time)
        history.append(stats)
    return solver, checker, history


def _total(history: list, key: str) -> int:
    return sum(s["counts"][key] for s in history)


def test_drape_falls_on_sphere_and_folds() -> None:
    scene = build_scene("drape", 400)
    # Start just above the sphere, so contact begins within the first frames.
    scene.vertices = scene.vertices - np.array([0, 0, 0.09], np.float32)
    solver, checker, history = _run(scene, 48)
    assert _total(history, "dcd_vertex_face") + _total(history, "dcd_edge_edge") > 0
    assert _total(history, "ccd_hits") > 0  # penetration handling was exercised


def test_stack_layers_pressed_by_moving_sphere() -> None:
    scene = build_scene("stack", 450)
    # Start with the sphere almost touching the top layer so pressing happens within the test.
    motion = scene.obstacles[1].motion
    scene.obstacles[1] = dataclasses.replace(scene.obstacles[1], motion=lambda t: motion(t + 0.38))
    solver, checker, history = _run(scene, 40)
    assert _total(history, "ccd_hits") + _total(history, "dcd_vertex_face") > 0


def test_twist_ends_follow_handles_into_self_contact() -> None:
    scene = build_scene("twist", 300)
    ends = [h.motion for h in scene.handles]
    # Four times faster than the scene, so self-contact comes within the test.
    for handle, motion in zip(scene.handles, ends, strict=True):
        handle.motion = (lambda m: (lambda t: m(4.0 * t)))(motion)
    solver, checker, history = _run(scene, 60)
    assert _total(history, "dcd_vertex_face") + _total(history, "dcd_edge_edge") > 0


def test_runs_are_deterministic_on_the_cpu() -> None:
    results = []
    for _ in range(2):
        scene = build_scene("drape", 200)
        scene.vertices = scene.vertices - np.array([0, 0, 0.09], np.float32)
        solver = ClothSolver(scene, device="cpu")
        state, other = solver.initial_state(), solver.initial_state()
        for _ in range(24):
            solver.step(state, other, scene.time_step)
            state, other = other, state
        results.append(state.positions.numpy())
    np.testing.assert_array_equal(results[0], results[1])


def test_pinned_corners_stay_put() -> None:
    scene = build_scene("drape", 200)
    corners = np.array([0, int(np.argmax(scene.vertices[:, 0] - scene.vertices[:, 1]))])
    from pscc.sim.obstacles import Handle

    scene.handles = [Handle(corners, name="pins")]
    scene.obstacles = []
    solver = ClothSolver(scene, device="cpu")
    state, other = solver.initial_state(), solver.initial_state()
    for _ in range(16):
        solver.step(state, other, scene.time_step)
        state, other = other, state
    end = state.positions.numpy()[: scene.vertices.shape[0]]
    np.testing.assert_array_equal(end[corners], scene.vertices[corners])
    # The rest of the cloth has fallen meanwhile, so the pins are what held the corners.
    free = np.setdiff1d(np.arange(scene.vertices.shape[0]), corners)
    assert np.all(end[free, 2] < scene.vertices[free, 2])


def test_initial_intersection_is_refused_unless_allowed() -> None:
    scene = build_scene("drape", 200)
    scene.vertices = scene.vertices - np.array([0, 0, 0.3], np.float32)  # through the sphere
    with pytest.raises(InputError, match="intersects"):
        ClothSolver(scene, device="cpu")
    solver = ClothSolver(scene, device="cpu", contact=ContactConfig(allow_initial_intersections=True))
    assert solver.model.vertex_count > scene.vertices.shape[0]


def test_contact_buffers_grow_under_heavy_contact() -> None:
    scene = build_scene("stack", 450)
    motion = scene.obstacles[1].motion
    scene.obstacles[1] = dataclasses.replace(scene.obstacles[1], motion=lambda t: motion(t + 0.38))
    solver = ClothSolver(scene, device="cpu")
    first_capacity = solver.proximity.springs.capacity
    state, other = solver.initial_state(), solver.initial_state()
    most = 0
    for _ in range(24):
        stats = solver.step(state, other, scene.time_step)
        state, other = other, state
        most = max(most, stats["counts"]["contacts"])
    assert most > first_capacity
    assert solver.proximity.springs.capacity >= most
    memory = solver.device_bytes()
    assert memory["contact_springs"] >= most * 4 * 4  # at least the four vertex ids of each spring
    assert memory["total"] == sum(v for k, v in memory.items() if k != "total")


def test_device_bytes_counts_every_structure_and_grows_with_the_mesh() -> None:
    small, large = (ClothSolver(build_scene("drape", n), device="cpu").device_bytes() for n in (400, 1600))
    for memory in (small, large):
        assert set(memory) == {"collision", "contact_springs", "projection", "intersection_check", "integrator",
                               "device_step", "total"}
        assert memory["device_step"] == 0  # no device frame yet
        assert all(v > 0 for k, v in memory.items() if k != "device_step")
        assert memory["total"] == sum(v for k, v in memory.items() if k != "total")
    for key in ("collision", "intersection_check", "integrator"):
        assert large[key] > 2 * small[key], key


def test_device_bytes_count_the_device_steps_frame_copies() -> None:
    scene = build_scene("drape", 400)
    solver = ClothSolver(scene, device="cpu")
    state, scratch = solver.initial_state(), solver.initial_state()
    solver.advance_frame(state, scratch, scene.time_step, 2)
    memory = solver.device_bytes()
    # At least the saved positions, velocities and warm start (3 x vec3 per vertex).
    assert memory["device_step"] >= 3 * 12 * solver.model.vertex_count
    assert memory["total"] == sum(v for k, v in memory.items() if k != "total")


def test_per_object_materials_and_wind() -> None:
    from pscc.sim.config import ClothMaterial, SolverConfig

    scene = build_scene("stack", 150)
    soft = ClothMaterial(stretch_u=200.0, stretch_v=200.0, stretch_uv=20.0, shear=60.0, thickness=0.003)
    scene.material = [ClothMaterial(), soft, ClothMaterial()]
    scene.solver = SolverConfig(wind=(2.0, 0.0, 0.0), air_drag=0.5)
    solver, checker, history = _run(scene, 8)
    assert solver.thickness == 0.003  # the largest thickness is the contact distance
    stiffness = solver.model.faces.stiffness.numpy()
    object_ids = scene.object_ids
    assert np.allclose(stiffness[object_ids == 1, 0], 200.0) and np.allclose(stiffness[object_ids == 0, 0], 1000.0)
    scene.material = [ClothMaterial()]  # pieces 1 and 2 have no material
    with pytest.raises(InputError, match="material"):
        ClothSolver(scene, device="cpu")


@pytest.mark.parametrize("name", ["drape", "twist"])
def test_restored_solver_continues_bit_for_bit(name: str) -> None:
    def make() -> Scene:
        scene = build_scene(name, 200)
        if name == "drape":
            scene.vertices = scene.vertices - np.array([0, 0, 0.09], np.float32)
        else:
            for handle in scene.handles:
                handle.motion = (lambda m: (lambda t: m(4.0 * t)))(handle.motion)
        return scene

    scene = make()
    solver = ClothSolver(scene, device="cpu")
    state, other = solver.initial_state(), solver.initial_state()
    for _ in range(60):
        solver.step(state, other, scene.time_step)
        state, other = other, state
    checkpoint = solver.state_dict(state)
    assert checkpoint["spring_vertices"].shape[0] > 0  # contacts are part of what is restored
    for _ in range(12):
        solver.step(state, other, scene.time_step)
        state, other = other, state
    expected = state.positions.numpy()

    resumed = ClothSolver(make(), device="cpu")
    state, other = resumed.initial_state(), resumed.initial_state()
    resumed.load_state_dict(checkpoint, state)
    assert resumed.time == pytest.approx(60 * scene.time_step)
    for _ in range(12):
        resumed.step(state, other, scene.time_step)
        state, other = other, state
    np.testing.assert_array_equal(state.positions.numpy(), expected)


def test_checkpoint_of_another_scene_is_refused() -> None:
    solver = ClothSolver(build_scene("drape", 200), device="cpu")
    other = ClothSolver(build_scene("twist", 100), device="cpu")
    data = other.state_dict(other.initial_state())
    with pytest.raises(InputError, match="positions"):
        solver.load_state_dict(data, solver.initial_state())


def test_checkpoint_spring_multiplicity_is_checked_and_defaults_to_one() -> None:
    scene = build_scene("stack", 300)
    solver = ClothSolver(scene, device="cpu")
    state, other = solver.initial_state(), solver.initial_state()
    for _ in range(40):  # the layers settle onto each other
        solver.step(state, other, scene.time_step)
        state, other = other, state
    data = solver.state_dict(state)
    count = data["spring_vertices"].shape[0]
    assert count > 0 and data["spring_multiplicity"].max() > 1  # stacked layers: merged rows
    resumed = ClothSolver(scene, device="cpu")
    target = resumed.initial_state()
    bad = dict(data, spring_multiplicity=np.zeros(count, np.int32))
    before = target.positions.numpy().copy()
    with pytest.raises(InputError, match="spring_multiplicity"):
        resumed.load_state_dict(bad, target)
    np.testing.assert_array_equal(target.positions.numpy(), before)  # nothing written half-way
    # A checkpoint written before springs were merged: one spring per row.
    old = {k: v for k, v in data.items() if k != "spring_multiplicity"}
    resumed.load_state_dict(old, target)
    np.testing.assert_array_equal(resumed.proximity.springs.multiplicity.numpy()[:count], np.ones(count))


def test_rejected_steps_are_halved_and_stay_intersection_free(monkeypatch: pytest.MonkeyPatch) -> None:
    scene = build_scene("drape", 200)
    scene.vertices = scene.vertices - np.array([0, 0, 0.09], np.float32)
    solver = ClothSolver(scene, device="cpu")
    checker = _Checker(solver)
    real_find = solver.intersection_check.find
    calls = {"n": 0}

    def flaky_find(positions):
        calls["n"] += 1
        if calls["n"] == 3:  # pretend the third end state crosses: that attempt must be rejected
            return np.array([[0, 0]], dtype=np.int32)
        return real_find(positions)

    monkeypatch.setattr(solver.intersection_check, "find", flaky_find)
    state, other = solver.initial_state(), solver.initial_state()
    halvings = 0
    for _ in range(4):
        stats = solver.step(state, other, scene.time_step)
        state, other = other, state
        checker.check(state, solver.time)
        halvings += stats["counts"]["halvings"]
    assert halvings == 1
    assert solver.time == pytest.approx(4 * scene.time_step)


def test_a_step_that_cannot_be_fixed_stops_with_an_error() -> None:
    from pscc.sim.solver import SimulationError

    scene = build_scene("twist", 300)
    for handle in scene.handles:
        handle.motion = (lambda m: (lambda t: m(4.0 * t)))(handle.motion)
    contact = ContactConfig(max_response_rounds=1, projection_rounds=0, max_step_halvings=0)
    solver = ClothSolver(scene, device="cpu", contact=contact)
    state, other = solver.initial_state(), solver.initial_state()
    with pytest.raises(SimulationError, match="halvings"):
        for _ in range(120):
            solver.step(state, other, scene.time_step)
            state, other = other, state


def test_mesh_sequence_obstacle_with_impact_zones() -> None:
    from pscc.scenes.scene_file import SequenceObstacle

    scene = build_scene("drape", 200)
    scene.vertices = scene.vertices - np.array([0, 0, 0.09], np.float32)
    sphere = scene.obstacles[0]
    # The sphere breathes (non-rigid: radius 0.25 -> 0.27) and rises, played as a mesh sequence.
    frames = np.stack([sphere.vertices * (1.0 + 0.02 * k) + [0.0, 0.0, 0.004 * k] for k in range(20)])
    scene.obstacles = [SequenceObstacle(frames, sphere.faces, frame_time=scene.frame_time, name="breathing")]
    contact = ContactConfig(projection_rounds=0)  # every collision goes through the impact zones
    solver, checker, history = _run(scene, 40, contact)
    assert _total(history, "zone_rounds") > 0


def test_ccd_rechecks_in_the_response_loop_equal_full_ccd() -> None:
    # Every CCD round after a response tests only the pairs with a moved vertex; wrap the detector
    # so that each such round is compared with a full CCD of the same trajectory.
    scene = build_scene("stack", 450)
    solver = ClothSolver(scene, device="cpu")
    detector = solver.detector
    original = detector.narrow_phase
    compared = []

    def checked(x0, x1=None, thickness=0.0, recheck=False, inside_share=0.0):
        if x1 is None or not recheck:
            return original(x0, x1, thickness, recheck=recheck, inside_share=inside_share)
        reusable = detector._last_ccd_thickness == (thickness, inside_share)
        partial = original(x0, x1, thickness, recheck=True, inside_share=inside_share)
        if reusable:
            compared.append(int(detector.narrow.moved.numpy().sum()))
        full = original(x0, x1, thickness, inside_share=inside_share)
        assert _rows(partial) == _rows(full)
        return full

    detector.narrow_phase = checked
    state, other = solver.initial_state(), solver.initial_state()
    for _ in range(24):
        solver.step(state, other, scene.time_step)
        state, other = other, state
    assert len(compared) >= 3 and 0 < max(compared) < len(state.positions.numpy())


def _rows(result) -> tuple[list, list, list, list]:
    return (result.vertex_face.tolist(), result.edge_edge.tolist(), result.vertex_face_toi.tolist(),
            result.edge_edge_toi.tolist())


def test_the_largest_object_id_steps_like_a_small_one() -> None:
    """Cloth ids need not be small: obstacles get free ids (never max + 1 past int32) and the run is the same."""
    scene = build_scene("drape", 200)
    big = dataclasses.replace(scene, object_ids=np.full_like(scene.object_ids, 2**31 - 1))
    positions = []
    for candidate in (scene, big):
        solver = ClothSolver(candidate, device="cpu")
        assert len(set(solver.detector._object_ids_np.tolist())) == 1 + len(candidate.obstacles)
        state, following = solver.initial_state(), solver.initial_state()
        for _ in range(3):
            solver.step(state, following, candidate.time_step)
            state, following = following, state
        positions.append(state.positions.numpy().copy())
    np.testing.assert_array_equal(positions[0], positions[1])


def test_object_ids_that_do_not_fit_int32_are_refused_naming_the_scene() -> None:
    scene = build_scene("drape", 200)
    bad = dataclasses.replace(scene, object_ids=np.full(scene.faces.shape[0], 2**31, dtype=np.int64))
    with pytest.raises(InputError, match=f"{scene.name}: object_ids: .*outside"):
        ClothSolver(bad, device="cpu")


def test_the_detectors_hash_tables_live_in_the_bsr_values_and_the_pair_buffers_between_their_uses() -> None:
    scene = build_scene("drape", 400)
    solver = ClothSolver(scene, device="cpu")
    state, scratch = solver.initial_state(), solver.initial_state()
    without = ClothSolver(scene, device="cpu")
    without.detector.lend_scratch(None)
    other, other_scratch = without.initial_state(), without.initial_state()
    for _ in range(3):
        solver.advance_frame(state, scratch, scene.time_step, 4)
        without.advance_frame(other, other_scratch, scene.time_step, 4)
    # Every per-call table lives in the BSR values or in the candidate pairs and times of impact (the
    # pairs, which the broad phase turns into candidates, only in the values).
    spatial_hash, detector = solver.detector.spatial_hash, solver.detector
    values = solver.integrator.system.matrix.values
    pair_buffers = [detector.candidates.storage, detector.narrow.toi_storage]

    def lender(name: str) -> wp.array | None:
        table = getattr(spatial_hash, name)
        for buffer in [values, *pair_buffers]:
            if buffer.ptr <= table.ptr and table.ptr + table.capacity <= buffer.ptr + buffer.capacity:
                return buffer
        return None

    assert "pairs" in spatial_hash._lent_names and len(spatial_hash._lent_names) >= 5
    assert all(lender(name) is not None for name in spatial_hash._lent_names)
    assert lender("pairs") is values
    assert any(lender(name) is not values for name in spatial_hash._lent_names)
    # Sharing the memory changes nothing: the same frames, bit for bit, and less memory.
    np.testing.assert_array_equal(state.positions.numpy(), other.positions.numpy())
    assert solver.device_bytes()["collision"] < without.device_bytes()["collision"]


def test_the_springs_merge_table_lives_in_the_bsr_values_with_the_same_frames() -> None:
    # The springs are built after the integration, when the BSR values are dead.
    scene = build_scene("stack", 400)
    solver = ClothSolver(scene, device="cpu")
    without = ClothSolver(scene, device="cpu")
    without.proximity.springs.lend_merge_table(None)
    states = [(s.initial_state(), s.initial_state()) for s in (solver, without)]
    for _ in range(3):
        for s, (state, scratch) in zip((solver, without), states, strict=True):
            s.advance_frame(state, scratch, scene.time_step, 4)
    springs = solver.proximity.springs
    values = solver.integrator.system.matrix.values
    assert springs.merge_table_lent == {"merge_keys", "merge_counts"}
    assert values.ptr <= springs.merge_keys.ptr < values.ptr + values.capacity
    assert not without.proximity.springs.merge_table_lent
    assert springs.host_count > 0 and springs.host_count == without.proximity.springs.host_count
    np.testing.assert_array_equal(springs.multiplicity.numpy(), without.proximity.springs.multiplicity.numpy())
    np.testing.assert_array_equal(states[0][0].positions.numpy(), states[1][0].positions.numpy())
    # Counted once, as the integrator's.
    assert solver.device_bytes()["contact_springs"] < without.device_bytes()["contact_springs"]
    assert solver.device_bytes()["integrator"] == without.device_bytes()["integrator"]
