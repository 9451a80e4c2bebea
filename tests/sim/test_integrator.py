"""ImplicitEuler: hanging and falling sheets, contact springs and friction, handles, the linear system."""

from __future__ import annotations

import numpy as np
import pytest
import warp as wp

from pscc.mesh.generate import grid_sheet
from pscc.sim import ClothMaterial, ClothModel, ClothState, ContactSprings, ImplicitEuler, SolverConfig

DT = 1.0 / 200.0
G = 9.81


def unique_edges(faces: np.ndarray) -> np.ndarray:
    edges = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    return np.unique(np.sort(edges, axis=1), axis=0)


def edge_ratios(x: np.ndarray, x_rest: np.ndarray, edges: np.ndarray) -> np.ndarray:
    length = np.linalg.norm(x[edges[:, 0]] - x[edges[:, 1]], axis=1)
    rest = np.linalg.norm(x_rest[edges[:, 0]] - x_rest[edges[:, 1]], axis=1)
    return length / rest


def dense_matrix(integrator: ImplicitEuler) -> np.ndarray:
    return integrator.system.dense()


def contact_blocks_float64(model: ClothModel, integrator: ImplicitEuler, state: ClothState, springs: ContactSprings,
                           dt: float) -> np.ndarray:
    """K = dt^2 k_c n n^T + dt c (I - n n^T) of every stored contact, in float64 from the spring and state
    (free vertices only: v_ref = v_t; automatic stiffness)."""
    config = integrator.config
    x = state.positions.numpy().astype(np.float64)
    v = state.velocities.numpy().astype(np.float64)
    mass = model.mass_host.astype(np.float64)
    friction = model.vertices.friction.numpy().astype(np.float64)
    count = int(springs.count.numpy()[0])
    blocks = []
    for ids, w, n in zip(springs.vertices.numpy()[:count], springs.weights.numpy()[:count].astype(np.float64),
                         springs.normals.numpy()[:count].astype(np.float64), strict=True):
        gap = n @ (w @ x[ids]) - springs.rest_gap
        stiffness = config.contact_stiffness_scale / (np.sum(w**2 / mass[ids]) * dt**2)
        relative = w @ v[ids]
        tangential = relative - (relative @ n) * n
        damping = np.sum(0.5 * np.abs(w) * friction[ids]) * (-stiffness * gap) / max(
            np.linalg.norm(tangential), config.friction_velocity_epsilon)
        nn = np.outer(n, n)
        blocks.append(dt**2 * stiffness * nn + dt * damping * (np.eye(3) - nn))
    return np.array(blocks)


def simulate(integrator: ImplicitEuler, state: ClothState, steps: int, dt: float = DT, **kwargs):
    """Step ``steps`` times with double buffering; yield (step index, current state, stats)."""
    spare = state.clone()
    for k in range(steps):
        stats = integrator.step(state, spare, dt, **kwargs)
        state, spare = spare, state
        yield k, state, stats


def run_steps(integrator: ImplicitEuler, state: ClothState, steps: int, **kwargs):
    """Step ``steps`` times; return the final state and the list of step statistics."""
    stats, final = [], state
    for _, current, step_stats in simulate(integrator, state, steps, **kwargs):
        stats.append(step_stats)
        final = current
    return final, stats


# ------------------------------------------------------------------------------------------------
# Sheets under gravity
# ------------------------------------------------------------------------------------------------


def test_hanging_sheet_pinned_at_two_corners(device: str) -> None:
    vertices, faces, rest = grid_sheet(10, 10)
    pinned = [110, 120]  # corners (0, 1) and (1, 1)
    model = ClothModel(vertices, faces, rest=rest, pinned=pinned, device=device)
    integrator = ImplicitEuler(model)
    state = ClothState.from_model(model)
    edges = unique_edges(faces)
    initial_energy = integrator.energies(state)["total"]
    max_ratio, lowest, iterations = 1.0, 0.0, []
    for k, current, stats in simulate(integrator, state, 200):
        assert stats.cg_converged and stats.cg_residual <= integrator.config.cg_tolerance
        iterations.append(stats.cg_iterations)
        if k % 10 == 9:
            x = current.positions.numpy()
            assert np.all(np.isfinite(x)) and np.all(np.isfinite(current.velocities.numpy()))
            max_ratio = max(max_ratio, float(edge_ratios(x, vertices, edges).max()))
            lowest = min(lowest, float(x[:, 2].min()))
            # No energy is injected: kinetic + gravity + elastic never exceeds the start.
            assert integrator.energies(current)["total"] <= initial_energy + 1e-5
    x = current.positions.numpy()
    assert max_ratio < 1.10, f"an edge stretched by {100 * (max_ratio - 1):.1f} %"
    assert lowest < -0.6, "the free corners should swing well below the pins"
    assert np.array_equal(x[pinned], vertices[pinned])  # bitwise
    assert np.array_equal(current.velocities.numpy()[pinned], np.zeros((2, 3), np.float32))
    assert max(iterations) < integrator.config.cg_max_iterations


def test_free_fall_is_ballistic_without_stretch(device: str) -> None:
    vertices, faces, rest = grid_sheet(6, 6)
    # Tilt the sheet so the motion is not axis-aligned with its plane.
    angle = 0.4
    rotation = np.array([[1, 0, 0], [0, np.cos(angle), -np.sin(angle)], [0, np.sin(angle), np.cos(angle)]])
    start = (vertices @ rotation.T).astype(np.float32)
    v0 = np.array([0.3, -0.2, 1.0], np.float32)
    model = ClothModel(start, faces, rest=rest, device=device)
    integrator = ImplicitEuler(model)
    state = ClothState.from_model(model, velocities=np.tile(v0, (model.vertex_count, 1)))
    edges = unique_edges(faces)
    initial = integrator.energies(state)
    steps = 100
    previous_total = initial["total"]
    for _, current, stats in simulate(integrator, state, steps):
        assert stats.cg_converged
        energies = integrator.energies(current)
        assert energies["total"] <= previous_total + 1e-7  # monotone: backward Euler only dissipates
        previous_total = energies["total"]
    t = steps * DT
    x = current.positions.numpy()
    # Backward Euler: v_N = v0 + N dt g and x_N = x0 + t v0 + g dt^2 N (N + 1) / 2 (exactly ballistic
    # up to the O(dt) integrator error), which is within 1/N of the continuous g t^2 / 2.
    gravity = np.array([0.0, 0.0, -G])
    discrete = start + t * v0 + gravity * DT**2 * steps * (steps + 1) / 2
    continuous = start + t * v0 + gravity * t**2 / 2
    assert np.abs(x - discrete).max() < 1e-4
    assert np.abs(x - continuous).max() < 1.5 / steps * G * t**2 / 2
    # Velocities agree to ~1e-4 relative (CG stops at a relative residual of 1e-3 each step).
    np.testing.assert_allclose(current.velocities.numpy(), np.tile(v0 + gravity * t, (model.vertex_count, 1)),
                               atol=5e-4)
    assert np.abs(edge_ratios(x, start, edges) - 1.0).max() < 1e-4
    # The energy lost is the integrator's numerical damping, M g^2 dt^2 N / 2.
    lost = initial["total"] - previous_total
    assert lost == pytest.approx(model.total_mass * G**2 * DT**2 * steps / 2, rel=0.05)


def test_handles_follow_their_targets_and_drag_the_sheet(device: str) -> None:
    vertices, faces, rest = grid_sheet(4, 4)
    model = ClothModel(vertices, faces, rest=rest, handles=[0], pinned=[24], device=device)
    integrator = ImplicitEuler(model, SolverConfig(gravity=(0.0, 0.0, 0.0)))
    state = ClothState.from_model(model)
    for k, current, _ in simulate(integrator, state, 20):
        # Step k used the target set after step k - 1 (the initial position for k = 0).
        target = np.array([[0.0, 0.0, 0.005 * (k + 2)]], np.float32)
        integrator.set_handle_targets(target)  # reached at the end of the next step
        if k > 0:
            assert np.array_equal(current.positions.numpy()[0], np.array([0.0, 0.0, 0.005 * (k + 1)], np.float32))
    x = current.positions.numpy()
    assert x[1, 2] > 0.02 and x[5, 2] > 0.01  # neighbours follow the lifted corner
    assert np.array_equal(x[24], vertices[24])


# ------------------------------------------------------------------------------------------------
# Contact springs and friction
# ------------------------------------------------------------------------------------------------

THICKNESS = 0.002


def contact_scene(device: str, friction: float, height: float):
    """A large pinned ground triangle (z = 0, normal +z) and a small free triangle above it."""
    ground = [[-2.0, -2.0, 0.0], [4.0, -2.0, 0.0], [-2.0, 4.0, 0.0]]
    small = [[0.0, 0.0, height], [0.1, 0.0, height], [0.0, 0.1, height]]
    vertices = np.array(ground + small, np.float32)
    faces = np.array([[0, 1, 2], [3, 4, 5]], np.int32)
    material = ClothMaterial(friction=friction)
    return ClothModel(vertices, faces, materials=material, pinned=[0, 1, 2], device=device)


def vertex_face_contacts(x: np.ndarray, springs: ContactSprings) -> None:
    """VF contacts of vertices 3, 4, 5 against the ground triangle (0, 1, 2)."""
    a, b, c = x[0, :2], x[1, :2], x[2, :2]
    basis = np.stack([b - a, c - a], axis=1)
    ids, weights = [], []
    for p in (3, 4, 5):
        wb, wc = np.linalg.solve(basis, x[p, :2] - a)
        ids.append([p, 0, 1, 2])
        weights.append([1.0, -(1.0 - wb - wc), -wb, -wc])
    springs.set(np.array(ids, np.int32), np.array(weights, np.float32), np.tile([[0.0, 0.0, 1.0]], (3, 1)))


@pytest.mark.parametrize("use_contacts", [True, False])
def test_contact_springs_push_a_penetrating_vertex_face_pair_apart(device: str, use_contacts: bool) -> None:
    start = 0.0005  # 1.5 mm inside the 2 mm thickness
    model = contact_scene(device, 0.3, start)
    integrator = ImplicitEuler(model, SolverConfig(gravity=(0.0, 0.0, 0.0)))
    springs = ContactSprings(1, rest_gap=THICKNESS, device=device)  # grows to 3
    state = ClothState.from_model(model)
    heights = [start]
    for _ in range(20):
        vertex_face_contacts(state.positions.numpy(), springs)
        out = state.clone()
        integrator.step(state, out, DT, contacts=springs if use_contacts else None)
        state = out
        heights.append(float(state.positions.numpy()[3:, 2].mean()))
    heights = np.array(heights)
    if use_contacts:
        assert heights[1] > heights[0] + 1e-4  # the first step already separates
        assert np.all(np.diff(heights) > -1e-7)  # the gap never shrinks
        assert heights[-1] > THICKNESS - 1e-4  # pushed out to the thickness
        # The spring releases its energy as a separating velocity no larger than the one that closes
        # the penetration in a single step (k_c = m_eff / dt^2 closes half of it per step).
        exit_speed = state.velocities.numpy()[3:, 2]
        assert np.all(exit_speed > 0.0) and np.all(exit_speed <= (THICKNESS - start) / DT)
        assert springs.capacity >= 3
    else:
        np.testing.assert_allclose(heights, start, atol=1e-7)


@pytest.mark.parametrize("friction", [0.3, 0.0])
def test_friction_slows_tangential_sliding(device: str, friction: float) -> None:
    # Resting on the ground under gravity (spring compression m g / k_c = g dt^2), sliding along +x.
    model = contact_scene(device, friction, THICKNESS - G * DT**2)
    integrator = ImplicitEuler(model)
    springs = ContactSprings(3, rest_gap=THICKNESS, device=device)
    velocities = np.zeros((6, 3), np.float32)
    velocities[3:, 0] = 0.5
    state = ClothState.from_model(model, velocities=velocities)
    speeds = [0.5]
    steps = 20
    for _ in range(steps):
        vertex_face_contacts(state.positions.numpy(), springs)
        out = state.clone()
        integrator.step(state, out, DT, contacts=springs)
        state = out
        speeds.append(float(state.velocities.numpy()[3:, 0].mean()))
    speeds = np.array(speeds)
    z = state.positions.numpy()[3:, 2]
    assert np.all(np.abs(z - THICKNESS) < 1e-3)  # still resting on the ground
    if friction > 0.0:
        expected = 0.5 - friction * G * steps * DT  # Coulomb: deceleration mu g
        assert np.all(np.diff(speeds) < 0.0) and speeds[-1] > 0.0  # slows down, never reverses
        assert speeds[-1] == pytest.approx(expected, abs=0.1 * (0.5 - expected))
    else:
        assert np.abs(speeds - 0.5).max() < 1e-3


# ------------------------------------------------------------------------------------------------
# The linear system, CG and determinism
# ------------------------------------------------------------------------------------------------


def test_assembled_matrix_is_symmetric_positive_definite_and_cg_converges(device: str) -> None:
    vertices, faces, rest = grid_sheet(3, 3)
    rng = np.random.default_rng(4)
    model = ClothModel(vertices, faces, rest=rest, pinned=[0], handles=[15], device=device)
    config = SolverConfig(air_drag=0.5, wind=(1.0, 0.0, 2.0), cg_tolerance=1e-4, cg_check_every=1)
    integrator = ImplicitEuler(model, config)
    positions = vertices + rng.normal(scale=0.03, size=vertices.shape).astype(np.float32)
    state = ClothState.from_model(model, positions=positions,
                                  velocities=rng.normal(scale=0.2, size=vertices.shape))
    springs = ContactSprings(2, rest_gap=1.0, device=device)  # a large gap: both contacts active
    springs.set(np.array([[5, 10, 11, 14], [1, 2, 6, 9]], np.int32),
                np.array([[1.0, -0.2, -0.3, -0.5], [0.6, 0.4, -0.3, -0.7]], np.float32),
                np.array([[0.0, 0.3, 1.0], [1.0, 0.0, 0.2]]))
    out = state.clone()
    stats = integrator.step(state, out, DT, contacts=springs)

    a = dense_matrix(integrator)
    b = integrator.system.rhs.numpy().astype(np.float64).reshape(-1)
    dv = integrator.dv.numpy().astype(np.float64).reshape(-1)
    scale = np.abs(a).max()
    assert np.abs(a - a.T).max() <= 1e-6 * scale
    assert np.linalg.eigvalsh(a).min() > 0.0
    # Element part (A - M) is PSD: the Hessian approximations and dampers are.
    mass = np.repeat(model.mass_host.astype(np.float64), 3)
    assert np.linalg.eigvalsh(a - np.diag(mass)).min() >= -1e-6 * scale
    # Dirichlet rows/columns of the pinned and handle vertices hold only their mass block.
    for vertex in (0, 15):
        rows = slice(3 * vertex, 3 * vertex + 3)
        block = a[rows, rows]
        np.testing.assert_allclose(block, model.mass_host[vertex] * np.eye(3), rtol=1e-6)
        assert np.count_nonzero(a[rows]) == 3 and np.count_nonzero(a[:, rows]) == 3
    # Contacts couple vertices that share no face (5 and 14 do not; 1 and 9 do not).
    assert np.abs(a[15:18, 42:45]).max() > 0.0 and np.abs(a[3:6, 27:30]).max() > 0.0
    # A is the fixed-pattern element matrix plus w_a w_b K per contact, with K recomputed here in float64.
    system = integrator.system
    matrix = system.matrix
    rows = np.repeat(np.arange(16), np.diff(matrix.offsets.numpy()))
    reference = np.zeros((16, 3, 16, 3))
    np.add.at(reference, (rows, slice(None), matrix.columns.numpy()),
              matrix.values.numpy().astype(np.float64))
    blocks = system.contact_blocks().astype(np.float64)
    expected_blocks = contact_blocks_float64(model, integrator, state, springs, DT)
    np.testing.assert_allclose(blocks[:2], expected_blocks, rtol=1e-4, atol=1e-6 * np.abs(expected_blocks).max())
    weights = springs.weights.numpy().astype(np.float64)
    for c, ids in enumerate(springs.vertices.numpy()[:2]):
        assert np.abs(blocks[c]).max() > 0.0
        for i in range(4):
            for j in range(4):
                if ids[i] not in (0, 15) and ids[j] not in (0, 15):
                    reference[ids[i], :, ids[j], :] += weights[c, i] * weights[c, j] * blocks[c]
    np.testing.assert_allclose(a, reference.reshape(48, 48), rtol=1e-6, atol=1e-6 * scale)
    assert system.missing_blocks() == 0
    # apply() and diagonal() agree with the dense matrix.
    x = rng.normal(size=(16, 3)).astype(np.float32)
    y = wp.zeros(16, dtype=wp.vec3, device=device)
    system.apply(wp.array(x, dtype=wp.vec3, device=device), y)
    np.testing.assert_allclose(y.numpy().reshape(-1), a @ x.reshape(-1).astype(np.float64), rtol=1e-5,
                               atol=1e-5 * scale)
    diagonal = wp.zeros(16, dtype=wp.mat33, device=device)
    system.diagonal(diagonal)
    for vertex in range(16):
        rows = slice(3 * vertex, 3 * vertex + 3)
        np.testing.assert_allclose(diagonal.numpy()[vertex], a[rows, rows], rtol=1e-6, atol=1e-6 * scale)
    # CG converged: the true residual is below the tolerance.
    assert stats.cg_converged and stats.cg_iterations > 1
    relative = np.linalg.norm(b - a @ dv) / np.linalg.norm(b)
    assert relative <= 2 * config.cg_tolerance
    assert stats.cg_residual <= config.cg_tolerance
    assert stats.rhs_norm == pytest.approx(np.linalg.norm(b), rel=1e-3)
    # The step used dv: v_out = v + dv for free vertices.
    free = np.setdiff1d(np.arange(16), [0, 15])
    np.testing.assert_allclose(out.velocities.numpy()[free],
                               (state.velocities.numpy() + dv.reshape(-1, 3))[free], atol=1e-6)


@pytest.mark.parametrize("preconditioner", ["block_jacobi", "diag", "none"])
def test_preconditioners_give_the_same_step(device: str, preconditioner: str) -> None:
    vertices, faces, rest = grid_sheet(4, 4)
    model = ClothModel(vertices, faces, rest=rest, pinned=[20, 24], device=device)
    config = SolverConfig(preconditioner=preconditioner, cg_tolerance=1e-6, cg_check_every=1)
    integrator = ImplicitEuler(model, config)
    current, stats = run_steps(integrator, ClothState.from_model(model), 5)
    assert all(step.cg_converged for step in stats)
    reference = ImplicitEuler(model, SolverConfig(cg_tolerance=1e-6))
    expected, _ = run_steps(reference, ClothState.from_model(model), 5)
    np.testing.assert_allclose(current.positions.numpy(), expected.positions.numpy(), atol=1e-6)


def test_two_runs_are_bitwise_identical(device: str) -> None:
    def run() -> tuple[np.ndarray, np.ndarray]:
        vertices, faces, rest = grid_sheet(8, 8)
        model = ClothModel(vertices, faces, rest=rest, pinned=[72, 80], device=device)
        integrator = ImplicitEuler(model, SolverConfig(air_drag=0.3, wind=(0.5, 0.0, 1.0)))
        springs = ContactSprings(1, rest_gap=0.05, device=device)
        springs.set(np.array([[40, 0, 1, 9]], np.int32), np.array([[1.0, -0.3, -0.3, -0.4]], np.float32),
                    np.array([[0.0, 0.0, 1.0]]))
        current, _ = run_steps(integrator, ClothState.from_model(model), 30, contacts=springs)
        return current.positions.numpy(), current.velocities.numpy()

    first, second = run(), run()
    if wp.get_device(device).is_cpu:
        assert np.array_equal(first[0], second[0]) and np.array_equal(first[1], second[1])
    else:  # float atomics accumulate in no fixed order on a GPU (determinism is promised on the CPU)
        np.testing.assert_allclose(first[0], second[0], rtol=0, atol=1e-4)
        np.testing.assert_allclose(first[1], second[1], rtol=0, atol=1e-3 * np.abs(first[1]).max())
    assert np.abs(first[1]).max() > 0.1  # it moved
