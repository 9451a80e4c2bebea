"""Feature-pair extraction: all triangle pairs give every feature pair exactly once."""

from __future__ import annotations

import numpy as np
import warp as wp
from hypothesis import given, settings
from hypothesis import strategies as st

from pscc.collision.boxes import PrimitiveBoxes
from pscc.collision.candidates import CandidatePairs
from pscc.collision.device_topology import DeviceTopology
from pscc.collision.feature_pairs import FeaturePairs, ownership_bits
from pscc.mesh import MeshTopology, grid_sheet


def _extract(faces: np.ndarray, vertex_count: int, pairs: np.ndarray, device: str = "cpu", positions=None,
             thickness: float = 0.0):
    """Extract with the supporting-plane test; all-zero positions make every plane degenerate (no pair
    is separated), so every triangle pair is kept."""
    topology = MeshTopology.from_faces(faces, vertex_count)
    extractor = FeaturePairs(faces, DeviceTopology.upload(faces, topology, device), wp.get_device(device))
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
