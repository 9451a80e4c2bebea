"""Feature-pair extraction: all triangle pairs give every feature pair exactly once."""

from __future__ import annotations

import numpy as np
import warp as wp
from hypothesis import given, settings
from hypothesis import strategies as st

from pscc import tolerances
from pscc.collision.boxes import PrimitiveBoxes
from pscc.collision.candidates import CandidatePairs
from pscc.collision.device_topology import DeviceTopology
from pscc.collision.feature_pairs import FeaturePairs, ownership_bits
from pscc.collision.pair_filter import _static_sides, sides_agree
from pscc.mesh import MeshTopology, grid_sheet


def _extract(faces: np.ndarray, vertex_count: int, pairs: np.ndarray, device: str = "cpu", positions=None,
             thickness: float = 0.0, face_planes: bool = True):
    """Extract with the supporting-plane test; all-zero positions make every plane degenerate (no pair
    is separated), so every triangle pair is kept."""
    topology = MeshTopology.from_faces(faces, vertex_count)
    extractor = FeaturePairs(faces, DeviceTopology.upload(faces, topology, device), wp.get_device(device))
    extractor.use_face_planes = face_planes
    if face_planes:  # every call takes the plane slabs, however few its pairs
        extractor.face_planes.min_pairs = 0
    candidates = CandidatePairs(1, 1, wp.get_device(device))
    triangle_pairs = wp.array(pairs.reshape(-1, 2).astype(np.int32), dtype=wp.vec2i, device=device)
    x = np.zeros((vertex_count, 3), np.float32) if positions is None else positions
    x_device = wp.array(x, dtype=wp.vec3, device=device)
    boxes = PrimitiveBoxes(wp.array(faces, dtype=wp.vec3i, device=device),
                           wp.array(topology.edges, dtype=wp.vec2i, device=device), vertex_count, wp.get_device(device))
    boxes.compute(x_device, x_device, thickness)
    extractor.extract(triangle_pairs, len(pairs), candidates, x_device, None, thickness,
                      wp.zeros(len(faces), dtype=wp.int32, device=device), boxes.as_struct())
    if positions is None:
        assert extractor.kept_pairs == _pairs_with_features(faces, topology, pairs)
    assert extractor.kept_pairs <= len(pairs)
    vf = candidates.vertex_face.numpy()[: candidates.vertex_face_count].reshape(-1, 2)
    ee = candidates.edge_edge.numpy()[: candidates.edge_edge_count].reshape(-1, 2)
    return topology, vf, ee


def _pairs_with_features(faces: np.ndarray, topology: MeshTopology, pairs: np.ndarray) -> int:
    """Triangle pairs that own at least one vertex-face or edge-edge pair sharing no vertex (every
    such pair is kept when all boxes overlap and no plane separates)."""
    vertex_bits, edge_bits = ownership_bits(faces, topology)
    kept = 0
    for a, b in pairs.reshape(-1, 2):
        found = any((vertex_bits[p] >> k) & 1 and faces[p][k] not in faces[q]
                    for p, q in ((a, b), (b, a)) for k in range(3))
        for j in range(3):
            for k in range(3):
                if (edge_bits[a] >> j) & 1 and (edge_bits[b] >> k) & 1:
                    ea, eb = topology.edges[topology.face_edges[a][j]], topology.edges[topology.face_edges[b][k]]
                    found = found or not set(ea.tolist()) & set(eb.tolist())
        kept += int(found)
    return kept


def _all_pairs(face_count: int) -> np.ndarray:
    a, b = np.triu_indices(face_count, k=1)
    return np.stack([a, b], axis=1)


def _check_complete_and_unique(faces, vertex_count, vf, ee, topology) -> None:
    expected_vf = {(v, f) for f, tri in enumerate(faces) for v in range(vertex_count)
                   if v not in tri and len(topology.faces_of_vertex(v)) > 0}
    got_vf = [tuple(int(x) for x in r) for r in vf]
    assert len(got_vf) == len(set(got_vf)), "a vertex-face pair was emitted twice"
    assert set(got_vf) == expected_vf
    edges = topology.edges
    expected_ee = {(i, j) for i in range(len(edges)) for j in range(i + 1, len(edges))
                   if not set(edges[i]) & set(edges[j])}
    got_ee = [tuple(int(x) for x in r) for r in ee]
    assert len(got_ee) == len(set(got_ee)), "an edge-edge pair was emitted twice"
    assert set(got_ee) == expected_ee


def test_grid_all_pairs(device: str) -> None:
    vertices, faces, _ = grid_sheet(3, 2)
    topology, vf, ee = _extract(faces, len(vertices), _all_pairs(len(faces)), device)
    _check_complete_and_unique(faces, len(vertices), vf, ee, topology)


@settings(max_examples=25, deadline=None)
@given(st.lists(st.lists(st.integers(0, 9), min_size=3, max_size=3, unique=True), min_size=1, max_size=14,
                unique_by=lambda f: tuple(sorted(f))))
def test_random_meshes_all_pairs(face_list) -> None:
    faces = np.array(face_list, dtype=np.int32)
    topology, vf, ee = _extract(faces, 10, _all_pairs(len(faces)))
    _check_complete_and_unique(faces, 10, vf, ee, topology)


def test_empty_input() -> None:
    vertices, faces, _ = grid_sheet(1, 1)
    _, vf, ee = _extract(faces, len(vertices), np.zeros((0, 2), np.int32))
    assert vf.shape == (0, 2) and ee.shape == (0, 2)


def test_supporting_plane_drops_separated_pairs() -> None:
    # Two parallel triangles 1.0 apart: separated for thickness 0.5, kept for thickness 2.
    x = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 0, 1], [0, 1, 1]], np.float32)
    faces = np.array([[0, 1, 2], [3, 4, 5]], np.int32)
    _, vf, ee = _extract(faces, 6, np.array([[0, 1]]), positions=x, thickness=0.5)
    assert len(vf) == 0 and len(ee) == 0
    _, vf, ee = _extract(faces, 6, np.array([[0, 1]]), positions=x, thickness=2.0)
    assert len(vf) == 6 and len(ee) == 9


@wp.kernel
def _separated(tris: wp.array(dtype=wp.vec3, ndim=2), thickness: wp.array(dtype=wp.float32), factor: float,
               out: wp.array(dtype=wp.int32)):
    i = wp.tid()
    h = thickness[i]
    a0 = tris[i, 0]
    a1 = tris[i, 1]
    a2 = tris[i, 2]
    b0 = tris[i, 3]
    b1 = tris[i, 4]
    b2 = tris[i, 5]
    out[i] = int(sides_agree(_static_sides(a0, a1, a2, b0, b1, b2, h, factor))
                 or sides_agree(_static_sides(b0, b1, b2, a0, a1, a2, h, factor)))


def test_supporting_plane_test_against_float64() -> None:
    """Random triangle pairs (tilted, near-parallel, touching, at distances around the thickness): a pair
    the supporting-plane test separates is farther apart than the thickness (float64 ipctk distance),
    and a pair that a float64 supporting plane separates by more than 1e-5 of its size is separated."""
    from tests.collision.test_group_slab import _triangle_distance

    rng = np.random.default_rng(12)
    n = 3000
    a = rng.uniform(-1, 1, (n, 3, 3))
    normal = rng.normal(size=(n, 3))
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    offset = normal * rng.uniform(-0.5, 0.5, (n, 1))
    b = a[:, rng.permutation(3)] * rng.uniform(0.5, 1.5, (n, 1, 1)) + offset[:, None, :]
    b += rng.normal(size=(n, 3, 3)) * 10.0 ** rng.uniform(-6, -1, (n, 1, 1))
    tris = np.concatenate([a, b], axis=1).astype(np.float32)
    thickness = (rng.uniform(0.0, 0.3, n) * (rng.random(n) < 0.8)).astype(np.float32)
    out = wp.zeros(n, dtype=wp.int32, device="cpu")
    factor = tolerances.COPLANARITY_ROUNDING_FACTOR * tolerances.FLOAT32_UNIT_ROUNDOFF
    wp.launch(_separated, dim=n, inputs=[wp.array(tris, dtype=wp.vec3, device="cpu"),
                                         wp.array(thickness, device="cpu"), factor], outputs=[out], device="cpu")
    separated = out.numpy().astype(bool)
    t64 = tris.astype(np.float64)

    def plane_margin(p: np.ndarray, q: np.ndarray) -> np.ndarray:
        nrm = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
        nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
        s = np.einsum("nj,nkj->nk", nrm, q - p[:, :1])
        return np.maximum(s.min(axis=1), -s.max(axis=1))  # > h: q beyond h on one side

    margin = np.maximum(plane_margin(t64[:, :3], t64[:, 3:]), plane_margin(t64[:, 3:], t64[:, :3]))
    clear = margin > thickness + 1e-5 * np.abs(t64).max(axis=(1, 2))
    assert 300 < separated.sum() < n - 300
    assert np.all(separated[clear])
    for i in np.flatnonzero(separated):
        assert _triangle_distance(t64[i, :3], t64[i, 3:]) > thickness[i], i


def _close_feature_pairs(faces: np.ndarray, topology: MeshTopology, x: np.ndarray, h: float):
    """Every vertex-face pair (vertex not on the face) and edge-edge pair (no shared vertex) whose
    float64 ipctk distance is at most h."""
    import ipctk

    x = x.astype(np.float64)
    vf = {(v, f) for f, tri in enumerate(faces) for v in range(x.shape[0])
          if v not in tri and ipctk.point_triangle_distance(x[v], *x[tri]) <= h * h}
    edges = topology.edges
    ee = {(i, j) for i in range(len(edges)) for j in range(i + 1, len(edges))
          if not set(edges[i]) & set(edges[j])
          and ipctk.edge_edge_distance(*x[edges[i]], *x[edges[j]]) <= h * h}
    return vf, ee


@settings(max_examples=15, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), face_planes=st.booleans())
def test_plane_sides_drop_no_close_feature_pair(seed: int, face_planes: bool) -> None:
    """Two crumpled 4 x 4 sheets close to each other, all triangle pairs: the per-vertex supporting-plane
    sides, from the per-face plane slabs or from the six vertices, leave out only feature pairs farther
    than the thickness (float64 ipctk distances)."""
    rng = np.random.default_rng(seed)
    vertices, sheet, _ = grid_sheet(4, 4)
    n = vertices.shape[0]
    top = vertices + np.array([0.05, 0.03, 0.08]) + rng.normal(0, 0.04, vertices.shape)
    bottom = vertices + rng.normal(0, 0.04, vertices.shape)
    x = np.concatenate([bottom, top]).astype(np.float32)
    faces = np.concatenate([sheet, sheet + n]).astype(np.int32)
    h = 0.06
    topology, vf, ee = _extract(faces, 2 * n, _all_pairs(len(faces)), positions=x, thickness=h,
                                face_planes=face_planes)
    got_vf = {tuple(int(v) for v in r) for r in vf}
    got_ee = {tuple(sorted(int(v) for v in r)) for r in ee}
    close_vf, close_ee = _close_feature_pairs(faces, topology, x, h)
    assert close_vf <= got_vf and close_ee <= got_ee
    assert len(close_vf) + len(close_ee) > 0


def test_plane_sides_leave_out_the_features_beyond_the_plane() -> None:
    """Triangle A tilted 45 degrees (plane x = z, so its box is a unit cube); triangle B touches A's plane
    at one vertex and has the other two inside A's box but 0.42 below its plane (thickness 0.1): the
    pair is kept, the near vertex against A is a candidate, and the two far vertices against A and
    the far edge against A's edges, whose boxes all overlap, are not."""
    x = np.array([[0, 0, 0], [1, 0, 1], [0, 1, 0], [0.3, 0.3, 0.35], [0.2, 0.3, 0.8], [0.3, 0.2, 0.9]],
                 np.float32)
    faces = np.array([[0, 1, 2], [3, 4, 5]], np.int32)
    topology, vf, ee = _extract(faces, 6, np.array([[0, 1]]), positions=x, thickness=0.1)
    got_vf = {tuple(int(v) for v in r) for r in vf}
    assert (3, 0) in got_vf
    assert (4, 0) not in got_vf and (5, 0) not in got_vf
    far_edge = int(np.flatnonzero([set(e.tolist()) == {4, 5} for e in topology.edges])[0])
    assert all(far_edge not in (int(a), int(b)) for a, b in ee)
    # With a thickness past the far vertices' distance, the same pair keeps them (their boxes overlap).
    _, vf_thick, ee_thick = _extract(faces, 6, np.array([[0, 1]]), positions=x, thickness=2.5)
    assert {(4, 0), (5, 0)} <= {tuple(int(v) for v in r) for r in vf_thick}
    assert any(far_edge in (int(a), int(b)) for a, b in ee_thick)
