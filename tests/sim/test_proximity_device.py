"""The proximity springs' device path: springs built from a DCD's ContactArgs with the count on the
device. It equals the host path, replays bit-identically from a graph, reads nothing back and
catches an overflow of the spring buffers."""

from __future__ import annotations

import numpy as np
import pytest
import warp as wp

from pscc.bench.host_traffic import count_host_traffic
from pscc.sim.proximity import ProximityContacts
from tests.sim.contact_rows import contact_args

THICKNESS = 0.01


def _scene(seed: int, rows: int = 60):
    """Random positions, faces, edges, kinematic flags and DCD rows of which about 70 % are hits
    (toi 0; misses have toi > 1): (x, kinematic, faces, edges, vertex_face, vf_toi, edge_edge, ee_toi)."""
    rng = np.random.default_rng(seed)
    n = 30
    x = rng.uniform(-0.1, 0.1, size=(n, 3)).astype(np.float32)
    kinematic = rng.random(n) < 0.5
    faces = np.array([rng.choice(n, 3, replace=False) for _ in range(20)], np.int32)
    edges = np.array([rng.choice(n, 2, replace=False) for _ in range(20)], np.int32)
    vertex_face = np.stack([rng.integers(0, n, rows), rng.integers(0, 20, rows)], axis=1)
    vertex_face = vertex_face[~(faces[vertex_face[:, 1]] == vertex_face[:, :1]).any(axis=1)]
    edge_edge = np.stack([rng.integers(0, 20, rows), rng.integers(0, 20, rows)], axis=1)
    shared = (edges[edge_edge[:, 0]][:, :, None] == edges[edge_edge[:, 1]][:, None, :]).any(axis=(1, 2))
    edge_edge = edge_edge[~shared]
    vf_toi = np.where(rng.random(len(vertex_face)) < 0.7, 0.0, 2.0)
    ee_toi = np.where(rng.random(len(edge_edge)) < 0.7, 0.0, np.inf)
    return x, kinematic, faces, edges, vertex_face, vf_toi, edge_edge, ee_toi


def _host_rows(edges, vertex_face, vf_toi, edge_edge, ee_toi):
    """The hit rows as the host API takes them: (k, 2) vertex-face and (l, 4) edge-edge vertex rows."""
    ee = edge_edge[ee_toi <= 1.0]
    return vertex_face[vf_toi <= 1.0], np.concatenate([edges[ee[:, 0]], edges[ee[:, 1]]], axis=1)


def _springs(springs) -> tuple[np.ndarray, ...]:
    count = springs.host_count
    return springs.vertices.numpy()[:count], springs.weights.numpy()[:count], springs.normals.numpy()[:count]


def _bits(a: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(a).view(np.uint32)




def test_vertex_over_a_face_and_crossing_edges_become_springs(device: str) -> None:
    # Vertex 0 hovers 5 mm over face (1, 2, 3); edge (4, 5) crosses 4 mm over edge (6, 7); the row of
    # vertex 8 misses; the pair (9, face 1) is kinematic only and is dropped.
    x = np.array([[0.2, 0.2, 0.005], [0, 0, 0], [1, 0, 0], [0, 1, 0],
                  [2, -1, 0.004], [2, 1, 0.004], [1, 0, 0], [3, 0, 0], [0.3, 0.3, 0.5],
                  [5, 5, 0.001], [4.5, 4.5, 0], [5.5, 4.5, 0], [5, 5.5, 0]], dtype=np.float32)
    kinematic = np.zeros(len(x), bool)
    kinematic[9:] = True
    faces = np.array([[1, 2, 3], [10, 11, 12]])
    edges = np.array([[4, 5], [6, 7]])
    contacts = contact_args(device, faces, edges, np.array([[0, 0], [8, 0], [9, 1]]), np.array([0.0, 2.0, 0.0]),
                             np.array([[0, 1]]), np.array([0.0]))
    proximity = ProximityContacts(faces, kinematic, THICKNESS, device)
    positions = wp.array(x, dtype=wp.vec3, device=device)
    springs = proximity.update_device(contacts, positions)
    assert not proximity.check_capacity()  # one slot at first: grown, run again
    assert proximity.update_device(contacts, positions) is springs
    assert proximity.check_capacity()
    assert springs is proximity.springs and springs.host_count == 2
    vertices, weights, normals = _springs(springs)
    np.testing.assert_array_equal(vertices, [[0, 1, 2, 3], [4, 5, 6, 7]])
    np.testing.assert_allclose(weights, [[1.0, -0.6, -0.2, -0.2], [0.5, 0.5, -0.5, -0.5]], atol=1e-6)
    np.testing.assert_allclose(normals, [[0, 0, 1], [0, 0, 1]], atol=1e-6)

    host = ProximityContacts(faces, kinematic, THICKNESS, device)
    host.update(np.array([[0, 0], [9, 1]]), np.array([[4, 5, 6, 7]]), positions)
    for a, b in zip(_springs(host.springs), (vertices, weights, normals), strict=True):
        np.testing.assert_array_equal(_bits(a), _bits(b))


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_device_springs_equal_host_springs(device: str, seed: int) -> None:
    x, kinematic, faces, edges, vertex_face, vf_toi, edge_edge, ee_toi = _scene(seed)
    positions = wp.array(x, dtype=wp.vec3, device=device)
    device_path = ProximityContacts(faces, kinematic, THICKNESS, device)
    device_path.springs.ensure(200)
    device_path.update_device(contact_args(device, faces, edges, vertex_face, vf_toi, edge_edge, ee_toi), positions)
    assert device_path.check_capacity()
    host = ProximityContacts(faces, kinematic, THICKNESS, device)
    host.update(*_host_rows(edges, vertex_face, vf_toi, edge_edge, ee_toi), positions)
    got, expected = _springs(device_path.springs), _springs(host.springs)
    assert 0 < len(got[0]) == len(expected[0]) < len(vertex_face) + len(edge_edge)
    if wp.get_device(device).is_cpu:
        for a, b in zip(got, expected, strict=True):
            np.testing.assert_array_equal(_bits(a), _bits(b))
    else:  # appended in another order
        order = np.lexsort(got[0].T), np.lexsort(expected[0].T)
        for a, b in zip(got, expected, strict=True):
            np.testing.assert_array_equal(a[order[0]], b[order[1]])


def test_replay_from_a_graph_is_bit_identical_to_the_eager_device_path(device: str) -> None:
    x, kinematic, faces, edges, vertex_face, vf_toi, edge_edge, ee_toi = _scene(4)
    contacts = contact_args(device, faces, edges, vertex_face, vf_toi, edge_edge, ee_toi)
    proximity = ProximityContacts(faces, kinematic, THICKNESS, device)
    positions = wp.array(x, dtype=wp.vec3, device=device)
    proximity.update_device(contacts, positions)
    assert not proximity.check_capacity()  # grown from one slot; the graph binds the grown buffers
    proximity.update_device(contacts, positions)
    assert proximity.check_capacity()
    eager = tuple(a.copy() for a in _springs(proximity.springs))
    assert len(eager[0]) > 10
    springs = proximity.springs
    with wp.ScopedCapture(device=device) as capture:
        proximity.update_device(contacts, positions)
    for _ in range(2):
        springs.vertices.zero_()
        springs.weights.zero_()
        springs.normals.zero_()
        springs.count.zero_()
        wp.capture_launch(capture.graph)
        wp.synchronize_device(device)
        for a, b in zip(_springs(springs), eager, strict=True):
            np.testing.assert_array_equal(_bits(a), _bits(b))


def test_the_device_path_makes_no_host_traffic(device: str, monkeypatch: pytest.MonkeyPatch) -> None:
    x, kinematic, faces, edges, vertex_face, vf_toi, edge_edge, ee_toi = _scene(5)
    contacts = contact_args(device, faces, edges, vertex_face, vf_toi, edge_edge, ee_toi)
    proximity = ProximityContacts(faces, kinematic, THICKNESS, device)
    proximity.springs.ensure(200)
    positions = wp.array(x, dtype=wp.vec3, device=device)
    proximity.update_device(contacts, positions)  # warm-up: modules loaded
    with count_host_traffic() as counts:
        proximity.update_device(contacts, positions)
    assert counts == {"reads": 0, "syncs": 0, "uploads": 0, "allocations": 0}
    with count_host_traffic() as counts:  # the counters really count
        assert proximity.check_capacity() and proximity.springs.host_count > 0
        proximity.update(*_host_rows(edges, vertex_face, vf_toi, edge_edge, ee_toi), positions)
    assert counts["reads"] > 0 and counts["uploads"] > 0


def test_an_overflow_is_caught_grown_and_rerun_exactly(device: str) -> None:
    x, kinematic, faces, edges, vertex_face, vf_toi, edge_edge, ee_toi = _scene(6, rows=120)
    contacts = contact_args(device, faces, edges, vertex_face, vf_toi, edge_edge, ee_toi)
    proximity = ProximityContacts(faces, kinematic, THICKNESS, device)
    springs = proximity.springs
    capacity = springs.capacity
    positions = wp.array(x, dtype=wp.vec3, device=device)
    proximity.update_device(contacts, positions)
    needed = int(springs.count.numpy()[0])  # the counter kept counting past the capacity
    assert needed > capacity
    assert springs.host_count == capacity  # the stored rows
    assert not proximity.check_capacity()
    assert springs.capacity >= 1.25 * needed
    proximity.update_device(contacts, positions)
    assert proximity.check_capacity()
    assert springs.host_count == needed
    host = ProximityContacts(faces, kinematic, THICKNESS, device)
    host.update(*_host_rows(edges, vertex_face, vf_toi, edge_edge, ee_toi), positions)
    got, expected = _springs(springs), _springs(host.springs)
    if wp.get_device(device).is_cpu:
        for a, b in zip(got, expected, strict=True):
            np.testing.assert_array_equal(_bits(a), _bits(b))
    else:
        order = np.lexsort(got[0].T), np.lexsort(expected[0].T)
        for a, b in zip(got, expected, strict=True):
            np.testing.assert_array_equal(a[order[0]], b[order[1]])
