"""pscc's DCD contract on meshes as exporters write them, not as generators do: closed surfaces squashed
flat, vertices no face uses, two coincident copies of one mesh, a non-manifold fin, collapsed faces."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from pscc.mesh import folded_sheet
from tests.collision.test_pscc import _check_dcd_contract, _detectors


def _sphere() -> tuple[np.ndarray, np.ndarray]:
    sphere = trimesh.creation.icosphere(subdivisions=2)
    return np.asarray(sphere.faces, dtype=np.int32), np.asarray(sphere.vertices, dtype=np.float32)


def _contacts(detector, x: np.ndarray, thickness: float) -> int:
    result = detector.detect(x, thickness=thickness)
    return len(result.vertex_face) + len(result.edge_edge)


@pytest.mark.parametrize("with_rest", [False, True])
def test_a_sphere_squashed_flat_touches_itself(with_rest: bool) -> None:
    faces, x = _sphere()
    flat = x * np.array([1.0, 1.0, 0.01], np.float32)  # top and bottom halves 0.02 apart at most
    detectors = _detectors(faces, x if with_rest else None)
    _check_dcd_contract(faces, flat, 0.005, detectors)
    assert _contacts(detectors["pscc"], flat, 0.005) > 0


def test_vertices_no_face_uses_are_ignored() -> None:
    faces, x = _sphere()
    stray = np.random.default_rng(0).normal(size=(40, 3)).astype(np.float32) * 0.5  # some inside the sphere
    with_stray = np.concatenate([x * np.array([1.0, 1.0, 0.01], np.float32), stray])
    detectors = _detectors(faces)
    _check_dcd_contract(faces, with_stray, 0.005, detectors)
    rows = detectors["pscc"].detect(with_stray, thickness=0.005)
    assert rows.vertex_face.size == 0 or rows.vertex_face[:, 0].max() < len(x)


@pytest.mark.parametrize("two_objects", [False, True])
def test_two_coincident_copies_touch_everywhere(two_objects: bool) -> None:
    faces, x = _sphere()
    both = np.concatenate([faces, faces + len(x)])
    ids = np.repeat([0, 1], len(faces)).astype(np.int32) if two_objects else None
    positions = np.concatenate([x, x])
    detectors = {m: d for m, d in _detectors(both, None, ids).items()}
    _check_dcd_contract(both, positions, 0.0, detectors)
    # Every vertex of one copy lies on the faces of the other (distance 0).
    culled = detectors["pscc"].detect(positions, thickness=0.0)
    touched = {int(v) % len(x) for v, f in culled.vertex_face if (v < len(x)) != (f < len(faces))}
    assert touched == set(range(len(x)))


def test_a_non_manifold_fin() -> None:
    # Three sheets meet along the edge (0, 1), which three faces share; a fourth sheet passes 0.03 from it.
    x = np.array([[0, 0, 0], [0, 0, 1], [1, 0, 0], [1, 0, 1], [-1, 0, 0], [-1, 0, 1], [0, 1, 0], [0, 1, 1],
                  [0.03, -0.5, 0.5], [0.03, 0.5, 0.5], [0.03, 0.0, 1.5]], np.float32)
    faces = np.array([[0, 2, 3], [0, 3, 1], [0, 1, 5], [0, 5, 4], [0, 6, 7], [0, 7, 1], [8, 9, 10]], np.int32)
    detectors = _detectors(faces)
    _check_dcd_contract(faces, x, 0.05, detectors)
    result = detectors["pscc"].detect(x, thickness=0.05)
    edges = {tuple(sorted(r[:2])) for r in result.edge_edge} | {tuple(sorted(r[2:])) for r in result.edge_edge}
    assert (0, 1) in edges  # the fin's edge against the passing sheet's edge (8, 9)


def test_collapsed_faces_in_a_fold() -> None:
    mesh = folded_sheet(600, layers=3, seed=3)
    x = mesh.vertices_end.copy()
    x[mesh.faces[5, 1]] = x[mesh.faces[5, 0]]  # an edge of zero length
    a, b, c = mesh.faces[40]
    x[c] = 0.5 * (x[a] + x[b])  # three collinear vertices
    _check_dcd_contract(mesh.faces, x, 0.01, _detectors(mesh.faces, mesh.rest))
