"""The inelastic projection's device path: rows read from a narrow phase's ContactArgs, the solve loop
on the device. It equals the host path, replays bit-identically from a graph, reads nothing back and
catches an overflow of its constraint buffers."""

from __future__ import annotations

import numpy as np
import pytest
import warp as wp

from pscc.bench.host_traffic import count_host_traffic, device_path_traffic
from pscc.collision.contacts import ContactArgs
from pscc.sim.inelastic_projection import InelasticProjection
from tests.sim.contact_rows import contact_args

SEPARATION = 0.01
TOLERANCE = 1e-6


def _scene(seed: int, rows: int = 20):
    """Random positions, faces and edges, and candidate rows of which about 70 % are hits (toi <= 1):
    (x0, x1, inverse_mass, faces, edges, vertex_face, vf_toi, edge_edge, ee_toi)."""
    rng = np.random.default_rng(seed)
    n = 24
    x0 = rng.uniform(-0.1, 0.1, size=(n, 3)).astype(np.float32)
    x1 = (x0 + rng.normal(scale=0.02, size=(n, 3))).astype(np.float32)
    inverse_mass = rng.uniform(0.5, 2.0, size=n)
    inverse_mass[:2] = 0.0  # two kinematic vertices
    faces = np.array([rng.choice(n, 3, replace=False) for _ in range(16)], np.int32)
    edges = np.array([rng.choice(n, 2, replace=False) for _ in range(16)], np.int32)
    vertex_face = np.stack([rng.integers(0, n, rows), rng.integers(0, 16, rows)], axis=1)
    vertex_face = vertex_face[~(faces[vertex_face[:, 1]] == vertex_face[:, :1]).any(axis=1)]
    edge_edge = np.stack([rng.integers(0, 16, rows), rng.integers(0, 16, rows)], axis=1)
    shared = (edges[edge_edge[:, 0]][:, :, None] == edges[edge_edge[:, 1]][:, None, :]).any(axis=(1, 2))
    edge_edge = edge_edge[~shared]
    vf_toi = np.where(rng.random(len(vertex_face)) < 0.7, rng.uniform(0, 1, len(vertex_face)), 2.0)
    ee_toi = np.where(rng.random(len(edge_edge)) < 0.7, rng.uniform(0, 1, len(edge_edge)), np.inf)
    return x0, x1, inverse_mass, faces, edges, vertex_face, vf_toi, edge_edge, ee_toi


def _host_rows(faces, edges, vertex_face, vf_toi, edge_edge, ee_toi):
    """The hit rows as the host API takes them: (k, 4) vertex rows and their times of impact."""
    vf_hit = vf_toi <= 1.0
    ee_hit = ee_toi <= 1.0
    vf = np.concatenate([vertex_face[vf_hit, :1], faces[vertex_face[vf_hit, 1]]], axis=1)
    ee = np.concatenate([edges[edge_edge[ee_hit, 0]], edges[edge_edge[ee_hit, 1]]], axis=1)
    return vf, vf_toi[vf_hit], ee, ee_toi[ee_hit]


def _bits(a: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(a).view(np.uint32)




def _device_round(projection: InelasticProjection, contacts: ContactArgs, p0: wp.array, p1: wp.array) -> None:
    projection.add_device(contacts, p0, p1)
    projection.solve_device(p1, SEPARATION, TOLERANCE)


def test_vertex_face_and_edge_edge_rows_are_projected_like_the_host_path(device: str) -> None:
    # Vertex 0 falls through face (1, 2, 3); edge (4, 5) falls through edge (6, 7); one row is a miss.
    x0 = np.array([[0.2, 0.2, 0.05], [0, 0, 0], [1, 0, 0], [0, 1, 0],
                   [2, -1, 0.05], [2, 1, 0.05], [1, 0, 0], [3, 0, 0]], dtype=np.float32)
    x1 = x0.copy()
    x1[0, 2] = -0.05
    x1[4:6, 2] = -0.05
    faces = np.array([[1, 2, 3]])
    edges = np.array([[4, 5], [6, 7], [1, 2]])
    contacts = contact_args(device, faces, edges, np.array([[0, 0], [4, 0]]), np.array([0.5, 3.0]),
                             np.array([[0, 1]]), np.array([0.5]))
    device_path = InelasticProjection(np.ones(8), device)
    p0 = wp.array(x0, dtype=wp.vec3, device=device)
    p1 = wp.array(x1, dtype=wp.vec3, device=device)
    device_path.reset()
    _device_round(device_path, contacts, p0, p1)
    result = device_path.result()
    assert result.constraints == 2 and result.converged and 0 < result.iterations < 512
    x = p1.numpy()
    under = 0.6 * x[1] + 0.2 * x[2] + 0.2 * x[3]
    assert x[0, 2] - under[2] == pytest.approx(SEPARATION, abs=1e-5)
    assert 0.5 * (x[4, 2] + x[5, 2]) - 0.5 * (x[6, 2] + x[7, 2]) == pytest.approx(SEPARATION, abs=1e-5)

    host_path = InelasticProjection(np.ones(8), device)
    q1 = wp.array(x1, dtype=wp.vec3, device=device)
    host_path.add(np.array([[0, 1, 2, 3]]), np.array([0.5]), np.array([[4, 5, 6, 7]]), np.array([0.5]), p0, q1)
    assert host_path.solve(q1, SEPARATION, TOLERANCE) == result
    np.testing.assert_array_equal(_bits(q1.numpy()), _bits(x))


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_device_rounds_equal_host_rounds(device: str, seed: int) -> None:
    """Two CCD rounds (the second warm-starts): the same constraints and end positions as the host API
    given the hit rows (bit for bit on the CPU, where appends follow the row order)."""
    x0, x1, inverse_mass, faces, edges, *_ = _scene(seed)
    rounds = [_scene(seed + 100 * r)[5:] for r in (1, 2)]
    device_path = InelasticProjection(inverse_mass, device, max_iterations=300, check_every=7)
    host_path = InelasticProjection(inverse_mass, device, max_iterations=300, check_every=7)
    p0 = wp.array(x0, dtype=wp.vec3, device=device)
    p1 = wp.array(x1, dtype=wp.vec3, device=device)
    q1 = wp.array(x1, dtype=wp.vec3, device=device)
    device_path.reset()
    host_path.reset()
    for vertex_face, vf_toi, edge_edge, ee_toi in rounds:
        contacts = contact_args(device, faces, edges, vertex_face, vf_toi, edge_edge, ee_toi)
        _device_round(device_path, contacts, p0, p1)
        assert device_path.check_capacity()
        host_path.add(*_host_rows(faces, edges, vertex_face, vf_toi, edge_edge, ee_toi), p0, q1)
        expected = host_path.solve(q1, SEPARATION, TOLERANCE)
        got = device_path.result()
        assert got.constraints == expected.constraints > 0
        if wp.get_device(device).is_cpu:
            assert got == expected
            np.testing.assert_array_equal(_bits(p1.numpy()), _bits(q1.numpy()))
        else:  # appends (and float atomics) in another order
            assert got.converged == expected.converged
            np.testing.assert_allclose(p1.numpy(), q1.numpy(), atol=1e-5)
    count = host_path.count
    for name in ("vertices", "weights", "normals"):
        a = getattr(device_path, name).numpy()[:count]
        b = getattr(host_path, name).numpy()[:count]
        if wp.get_device(device).is_cpu:
            np.testing.assert_array_equal(a, b)
        else:
            key = np.lexsort(device_path.vertices.numpy()[:count].T), np.lexsort(host_path.vertices.numpy()[:count].T)
            np.testing.assert_allclose(a[key[0]], b[key[1]], atol=1e-6)


def test_replay_from_a_graph_is_bit_identical_to_the_eager_device_path(device: str) -> None:
    x0, x1, inverse_mass, faces, edges, vertex_face, vf_toi, edge_edge, ee_toi = _scene(5)
    contacts = contact_args(device, faces, edges, vertex_face, vf_toi, edge_edge, ee_toi)
    second = contact_args(device, faces, edges, *_scene(105)[5:])
    projection = InelasticProjection(inverse_mass, device, max_iterations=200, check_every=5)
    p0 = wp.array(x0, dtype=wp.vec3, device=device)
    p1 = wp.array(x1, dtype=wp.vec3, device=device)
    start = wp.array(x1, dtype=wp.vec3, device=device)

    def step() -> None:
        projection.reset()
        _device_round(projection, contacts, p0, p1)
        _device_round(projection, second, p0, p1)  # a second CCD round (warm start)

    step()
    assert projection.check_capacity()
    eager = p1.numpy().copy()
    eager_result = projection.result()
    eager_multiplier = projection.multiplier.numpy().copy()
    assert eager_result.constraints > 10 and eager_result.iterations > 5

    wp.copy(p1, start)
    with wp.ScopedCapture(device=device) as capture:
        step()
    if wp.get_device(device).is_cpu:  # nothing ran during the capture
        np.testing.assert_array_equal(p1.numpy(), x1)
    for _ in range(2):
        wp.copy(p1, start)
        projection.multiplier.zero_()
        wp.capture_launch(capture.graph)
        wp.synchronize_device(device)
        np.testing.assert_array_equal(_bits(p1.numpy()), _bits(eager))
        np.testing.assert_array_equal(_bits(projection.multiplier.numpy()), _bits(eager_multiplier))
        assert projection.result() == eager_result


def test_the_device_path_makes_no_host_traffic(device: str, monkeypatch: pytest.MonkeyPatch) -> None:
    x0, x1, inverse_mass, faces, edges, vertex_face, vf_toi, edge_edge, ee_toi = _scene(6)
    contacts = contact_args(device, faces, edges, vertex_face, vf_toi, edge_edge, ee_toi)
    projection = InelasticProjection(inverse_mass, device, max_iterations=100, check_every=4)
    p0 = wp.array(x0, dtype=wp.vec3, device=device)
    p1 = wp.array(x1, dtype=wp.vec3, device=device)
    projection.reset()
    _device_round(projection, contacts, p0, p1)  # warm-up: modules loaded, launches packed
    assert projection.check_capacity()

    def device_path() -> None:
        projection.reset()
        _device_round(projection, contacts, p0, p1)
        _device_round(projection, contacts, p0, p1)

    counts = device_path_traffic(device, device_path)
    assert counts == {"reads": 0, "syncs": 0, "uploads": 0, "allocations": 0}
    # The counters really count: the host API reads and uploads.
    with count_host_traffic() as counts:
        projection.add(np.array([[2, 3, 4, 5]]), np.array([0.5]), np.zeros((0, 4)), np.zeros(0), p0, p1)
        projection.solve(p1, SEPARATION, TOLERANCE)
    assert counts["reads"] > 0 and counts["uploads"] > 0


def test_an_overflow_is_caught_grown_and_rerun_exactly(device: str) -> None:
    # 150 vertices fall through the faces of a grid under them: 150 hits > the initial 64 slots.
    side = 15
    xs, ys = np.meshgrid(np.arange(side + 1, dtype=np.float32), np.arange(side + 1, dtype=np.float32))
    grid = np.stack([xs.ravel(), ys.ravel(), np.zeros(xs.size, np.float32)], axis=1)
    ids = np.arange((side + 1) ** 2).reshape(side + 1, side + 1)
    faces = np.stack([ids[:-1, :-1].ravel(), ids[:-1, 1:].ravel(), ids[1:, :-1].ravel()], axis=1)
    hits = 150
    falling = (grid[ids[:-1, :-1].ravel()[:hits]] + [0.25, 0.25, 0.05]).astype(np.float32)
    x0 = np.concatenate([grid, falling])
    x1 = x0.copy()
    x1[len(grid):, 2] = -0.05
    inverse_mass = np.concatenate([np.zeros(len(grid)), np.ones(hits)])  # the grid is an obstacle
    vertex_face = np.stack([len(grid) + np.arange(hits), np.arange(hits)], axis=1)
    toi = np.full(hits, 0.5)
    contacts = contact_args(device, faces, np.array([[0, 1]]), vertex_face, toi, np.zeros((0, 2)), np.zeros(0))
    projection = InelasticProjection(inverse_mass, device)
    assert projection.capacity < hits
    p0 = wp.array(x0, dtype=wp.vec3, device=device)
    p1 = wp.array(x1, dtype=wp.vec3, device=device)
    projection.reset()
    projection.add_device(contacts, p0, p1)
    assert int(projection.constraint_count.numpy()[0]) == hits  # the counter kept counting
    capacity = projection.capacity
    assert not projection.check_capacity()
    assert projection.capacity >= 1.25 * hits > capacity
    # Re-run the step with the grown buffers: every constraint is stored and met.
    wp.copy(p1, wp.array(x1, dtype=wp.vec3, device=device))
    projection.reset()
    _device_round(projection, contacts, p0, p1)
    assert projection.check_capacity()
    result = projection.result()
    assert result.constraints == hits and result.converged
    np.testing.assert_allclose(p1.numpy()[len(grid):, 2], SEPARATION, atol=2e-6)
    host = InelasticProjection(inverse_mass, device)
    q1 = wp.array(x1, dtype=wp.vec3, device=device)
    host.add(np.concatenate([vertex_face[:, :1], faces[vertex_face[:, 1]]], axis=1), toi, np.zeros((0, 4)),
             np.zeros(0), p0, q1)
    assert host.solve(q1, SEPARATION, TOLERANCE) == result
    np.testing.assert_allclose(q1.numpy(), p1.numpy(), atol=0 if wp.get_device(device).is_cpu else 1e-6)


def test_nothing_to_project_is_converged_at_once(device: str) -> None:
    x0, x1, inverse_mass, faces, edges, vertex_face, _, edge_edge, _ = _scene(7)
    misses = contact_args(device, faces, edges, vertex_face, np.full(len(vertex_face), 2.0), edge_edge,
                           np.full(len(edge_edge), np.inf))
    projection = InelasticProjection(inverse_mass, device)
    p0 = wp.array(x0, dtype=wp.vec3, device=device)
    p1 = wp.array(x1, dtype=wp.vec3, device=device)
    _device_round(projection, misses, p0, p1)
    assert projection.result() == (result := projection.solve(p1, SEPARATION, TOLERANCE))
    assert (result.iterations, result.violation, result.constraints, result.converged) == (0, 0.0, 0, True)
    np.testing.assert_array_equal(p1.numpy(), x1)
