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
    return (springs.vertices.numpy()[:count], springs.weights.numpy()[:count], springs.normals.numpy()[:count],
            springs.multiplicity.numpy()[:count])


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
    vertices, weights, normals, multiplicity = _springs(springs)
    np.testing.assert_array_equal(vertices, [[0, 1, 2, 3], [4, 5, 6, 7]])
    np.testing.assert_array_equal(multiplicity, [1, 1])
    np.testing.assert_allclose(weights, [[1.0, -0.6, -0.2, -0.2], [0.5, 0.5, -0.5, -0.5]], atol=1e-6)
    np.testing.assert_allclose(normals, [[0, 0, 1], [0, 0, 1]], atol=1e-6)

    host = ProximityContacts(faces, kinematic, THICKNESS, device)
    host.update(np.array([[0, 0], [9, 1]]), np.array([[4, 5, 6, 7]]), positions)
    for a, b in zip(_springs(host.springs), (vertices, weights, normals, multiplicity), strict=True):
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
    else:  # appended in another order, and a merged contact's spring may come from another of its rows
        assert len(got[0]) == len(expected[0]) and got[3].sum() == expected[3].sum()


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
        springs.multiplicity.zero_()
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
    # At most the count of the overflowing run: its merge table (one slot per spring slot) was too small
    # to merge every edge or corner contact, so that count is an upper bound.
    assert 0 < springs.host_count <= needed
    host = ProximityContacts(faces, kinematic, THICKNESS, device)
    host.update(*_host_rows(edges, vertex_face, vf_toi, edge_edge, ee_toi), positions)
    got, expected = _springs(springs), _springs(host.springs)
    if wp.get_device(device).is_cpu:
        for a, b in zip(got, expected, strict=True):
            np.testing.assert_array_equal(_bits(a), _bits(b))
    else:  # appended in another order, and a merged contact's spring may come from another of its rows
        assert len(got[0]) == len(expected[0]) and got[3].sum() == expected[3].sum()


def _two_layers(shift: tuple[float, float], jitter: float, seed: int):
    """Two 6 x 6 grid sheets of 50 cm (cells of 8.3 cm) 1 cm apart, the top one shifted in the plane by
    ``shift`` cells and jittered by up to ``jitter`` [m] (thickness 1.5 cm: no contact within a sheet).
    Returns positions, faces and rest coordinates."""
    from pscc.mesh.generate import grid_sheet

    rng = np.random.default_rng(seed)
    vertices, faces, rest = grid_sheet(6, 6, 0.5, 0.5)
    vertices = np.asarray(vertices, np.float64)
    top = vertices + np.array([shift[0] * 0.5 / 6, shift[1] * 0.5 / 6, 0.01]) + rng.uniform(-jitter, jitter,
                                                                                           vertices.shape)
    return (np.concatenate([vertices, top]).astype(np.float32),
            np.concatenate([faces, faces + len(vertices)]).astype(np.int32), np.concatenate([rest, rest]))


def _contact_key(row: np.ndarray, weights: np.ndarray) -> tuple:
    """The contact a spring stands for: its closest features (vertex, edge or face) on each side."""
    split = 1 if weights[1] <= 0.0 else 2  # edge-edge springs have s > 0 in weights[1]
    first = tuple(sorted(int(v) for v, w in zip(row[:split], weights[:split], strict=True) if abs(w) > 1e-5))
    second = tuple(sorted(int(v) for v, w in zip(row[split:], weights[split:], strict=True) if abs(w) > 1e-5))
    return tuple(sorted([first, second]))


LAYERS = [((0.0, 0.0), 0.0, 0), ((0.5, 0.0), 0.0, 0), ((0.5, 0.5), 0.0, 0), ((0.3, 0.7), 0.002, 1),
          ((0.0, 0.0), 0.003, 2)]
"""Aligned layers (every vertex over a vertex), layers shifted onto edges and onto face centres, and
jittered layers."""


@pytest.mark.parametrize(("shift", "jitter", "seed"), LAYERS)
def test_the_rows_of_one_contact_become_one_spring_with_their_count(device: str, shift, jitter, seed) -> None:
    from pscc.collision.detector import CollisionDetector

    thickness = 0.015
    x, faces, _ = _two_layers(shift, jitter, seed)
    rows = CollisionDetector(faces, method="brute-force", device=device).detect(x, None, thickness)
    positions = wp.array(x, dtype=wp.vec3, device=device)
    merged = ProximityContacts(faces, np.zeros(len(x), bool), thickness, device)
    merged.update(rows.vertex_face, rows.edge_edge, positions)
    per_row = ProximityContacts(faces, np.zeros(len(x), bool), thickness, device, merge=False)
    per_row.update(rows.vertex_face, rows.edge_edge, positions)
    vertices, weights, _, multiplicity = _springs(merged.springs)
    assert per_row.springs.host_count == len(rows.vertex_face) + len(rows.edge_edge)
    assert int(multiplicity.sum()) == per_row.springs.host_count  # every row counted once
    assert multiplicity.min() >= 1
    keys = [_contact_key(v, w) for v, w in zip(vertices, weights, strict=True)]
    assert len(set(keys)) == len(keys), "a contact became two springs"
    if jitter == 0.0:  # vertices over vertices or over edges: most rows are duplicates
        assert len(vertices) < 0.5 * per_row.springs.host_count
    if shift == (0.0, 0.0) and jitter == 0.0:  # one vertex-vertex spring per pair of vertices
        assert len(vertices) == len(x) // 2


@pytest.mark.parametrize(("shift", "jitter", "seed"), LAYERS)
def test_merged_springs_give_the_system_of_one_spring_per_row(device: str, shift, jitter, seed) -> None:
    from pscc.collision.detector import CollisionDetector
    from pscc.sim import ClothModel, ClothState, ImplicitEuler

    thickness = 0.015
    x, faces, rest = _two_layers(shift, jitter, seed)
    rows = CollisionDetector(faces, method="brute-force", device=device).detect(x, None, thickness)
    model = ClothModel(x, faces, rest=rest, device=device)
    state = ClothState.from_model(model, positions=x,
                                  velocities=np.random.default_rng(seed).normal(scale=0.2, size=x.shape))
    systems = []
    for merge in (True, False):
        proximity = ProximityContacts(faces, np.zeros(len(x), bool), thickness, device, merge=merge)
        springs = proximity.update(rows.vertex_face, rows.edge_edge, state.positions)
        integrator = ImplicitEuler(model)
        integrator.step(state, state.clone(), 1.0 / 200.0, contacts=springs)
        systems.append((integrator.system.dense(), integrator.system.rhs.numpy().copy()))
    (matrix, rhs), (matrix_rows, rhs_rows) = systems
    np.testing.assert_allclose(matrix, matrix_rows, rtol=1e-4, atol=1e-4 * np.abs(matrix_rows).max())
    np.testing.assert_allclose(rhs, rhs_rows, rtol=1e-4, atol=1e-4 * np.abs(rhs_rows).max())


def test_the_fused_dcd_and_springs_equal_the_dcd_then_the_springs() -> None:
    """ProximityContacts.test_and_update_device (the device step's one pass) gives, bit for bit, the times
    of impact, hit counts and springs of the narrow phase's DCD followed by update_device."""
    from pscc.collision.detector import CollisionDetector
    from pscc.mesh.generate import folded_sheet

    mesh = folded_sheet(800, layers=3, seed=4)
    thickness = 0.6 * float(np.ptp(mesh.vertices[:, 2])) / 2
    results = []
    for fused in (False, True):
        detector = CollisionDetector(mesh.faces, device="cpu")
        positions = wp.array(mesh.vertices, dtype=wp.vec3)
        detector.broad_phase(positions, thickness=thickness)
        proximity = ProximityContacts(mesh.faces, np.zeros(len(mesh.vertices), bool), thickness, "cpu",
                                      device_topology=detector.device_topology)
        proximity.springs.ensure(4000)
        if fused:
            contacts = detector.narrow_phase_device(positions, None, thickness, defer_dcd=True)
            springs = proximity.test_and_update_device(contacts, positions, detector.narrow.proximity_test(thickness))
        else:
            contacts = detector.narrow_phase_device(positions, None, thickness)
            springs = proximity.update_device(contacts.args, positions)
        assert proximity.check_capacity()
        counts = detector.candidates.counts.numpy()
        results.append((contacts.args.vertex_face_toi.numpy()[:counts[0]].copy(),
                        contacts.args.edge_edge_toi.numpy()[:counts[1]].copy(), contacts.hit_counts.numpy().copy(),
                        *(np.ascontiguousarray(a).copy() for a in _springs(springs))))
    plain, fused = results
    assert plain[2].sum() > 100 and len(plain[3]) > 50  # hits and springs to compare
    for a, b in zip(plain, fused, strict=True):
        np.testing.assert_array_equal(_bits(a) if a.dtype.kind == "f" else a, _bits(b) if b.dtype.kind == "f" else b)
