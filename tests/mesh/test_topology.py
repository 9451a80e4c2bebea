"""MeshTopology against a plain Python reference, on hand-made and random (hypothesis) meshes."""

from __future__ import annotations

import time

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pscc.errors import InputError
from pscc.mesh import MeshTopology, grid_sheet


def reference(faces: list[list[int]], n: int) -> dict:
    """Edge and adjacency tables computed the slow, obvious way."""
    edge_faces: dict[tuple[int, int], list[int]] = {}
    for f, face in enumerate(faces):
        for k in range(3):
            a, b = face[k], face[(k + 1) % 3]
            edge_faces.setdefault((min(a, b), max(a, b)), []).append(f)
    edges = sorted(edge_faces)
    edge_id = {e: i for i, e in enumerate(edges)}
    face_edges = [
        [edge_id[(min(face[k], face[(k + 1) % 3]), max(face[k], face[(k + 1) % 3]))] for k in range(3)]
        for face in faces
    ]
    vertex_faces: list[list[int]] = [[] for _ in range(n)]
    for f, face in enumerate(faces):
        for v in face:
            vertex_faces[v].append(f)
    return {
        "edges": edges,
        "face_edges": face_edges,
        "edge_faces": [sorted(edge_faces[e]) for e in edges],
        "boundary": [i for i, e in enumerate(edges) if len(edge_faces[e]) == 1],
        "vertex_faces": [sorted(fs) for fs in vertex_faces],
        "manifold": all(len(fs) <= 2 for fs in edge_faces.values()),
    }


def check_against_reference(faces: list[list[int]], n: int) -> MeshTopology:
    array = np.array(faces, dtype=np.int32).reshape(-1, 3)
    topo = MeshTopology.from_faces(array, n)
    ref = reference(faces, n)
    e = len(ref["edges"])
    assert topo.edge_count == e
    assert topo.edges.dtype == np.int32 and topo.edges.shape == (e, 2)
    assert [tuple(x) for x in topo.edges.tolist()] == ref["edges"]
    assert topo.face_edges.dtype == np.int32 and topo.face_edges.shape == (len(faces), 3)
    assert topo.face_edges.tolist() == ref["face_edges"]
    assert topo.edge_face_offsets.dtype == np.int32 and topo.edge_face_offsets.shape == (e + 1,)
    assert topo.edge_face_indices.dtype == np.int32
    assert [topo.faces_of_edge(i).tolist() for i in range(e)] == ref["edge_faces"]
    assert topo.boundary_edges.dtype == np.int32 and topo.boundary_edges.tolist() == ref["boundary"]
    assert topo.vertex_face_offsets.dtype == np.int32 and topo.vertex_face_offsets.shape == (n + 1,)
    assert topo.vertex_face_indices.dtype == np.int32
    assert [topo.faces_of_vertex(v).tolist() for v in range(n)] == ref["vertex_faces"]
    assert topo.is_manifold == ref["manifold"]
    assert topo.vertex_count == n
    return topo


@st.composite
def random_faces(draw: st.DrawFn) -> tuple[list[list[int]], int]:
    """Distinct triangles (in random vertex order) over up to 30 vertices, some isolated."""
    n = draw(st.integers(min_value=3, max_value=30))
    triple = st.lists(st.integers(0, n - 1), min_size=3, max_size=3, unique=True)
    faces = draw(st.lists(triple, min_size=0, max_size=50,
                          unique_by=lambda f: tuple(sorted(f))))
    return faces, n


@settings(max_examples=150, deadline=None)
@given(random_faces())
def test_matches_reference(case: tuple[list[list[int]], int]) -> None:
    faces, n = case
    check_against_reference(faces, n)


@settings(max_examples=50, deadline=None)
@given(st.integers(min_value=3, max_value=8), st.integers(min_value=3, max_value=6), st.data())
def test_fans_with_non_manifold_edges(n_extra: int, fan: int, data: st.DataObject) -> None:
    # `fan` faces all share edge (0, 1): a non-manifold edge when fan >= 3.
    faces = [[0, 1, 2 + k] if data.draw(st.booleans()) else [1, 0, 2 + k] for k in range(fan)]
    check = check_against_reference(faces, 2 + fan + n_extra)  # n_extra isolated vertices
    assert not check.is_manifold
    assert check.faces_of_edge(0).tolist() == list(range(fan))


def test_two_triangles() -> None:
    topo = check_against_reference([[0, 1, 2], [0, 2, 3]], 5)
    assert topo.edges.tolist() == [[0, 1], [0, 2], [0, 3], [1, 2], [2, 3]]
    assert topo.face_edges.tolist() == [[0, 3, 1], [1, 4, 2]]
    assert topo.edge_face_offsets.tolist() == [0, 1, 3, 4, 5, 6]
    assert topo.boundary_edges.tolist() == [0, 2, 3, 4]
    assert topo.is_manifold
    assert topo.faces_of_vertex(4).size == 0  # isolated vertex


def test_empty_faces() -> None:
    topo = MeshTopology.from_faces(np.zeros((0, 3), np.int32), 4)
    assert topo.edge_count == 0 and topo.is_manifold
    assert topo.edge_face_offsets.tolist() == [0]
    assert topo.vertex_face_offsets.tolist() == [0] * 5


def test_grid_counts() -> None:
    _, faces, _ = grid_sheet(7, 5)
    topo = MeshTopology.from_faces(faces, 8 * 6)
    # A triangulated grid: E = V + F - 1 (Euler, one boundary loop); boundary = 2 (nx + ny).
    assert topo.edge_count == 48 + 70 - 1
    assert topo.boundary_edges.size == 2 * (7 + 5)
    assert topo.is_manifold


@pytest.mark.parametrize(
    ("faces", "n", "field"),
    [
        (np.array([[0, 1, 5]]), 4, "faces"),
        (np.array([[0, 1, 1]]), 4, "faces"),
        (np.array([[0.0, 1.0, 2.0]]), 4, "faces"),
        (np.array([[0, 1, 2, 3]]), 4, "faces"),
        (np.array([[0, 1, 2]]), -1, "vertex_count"),
    ],
)
def test_rejects_bad_faces(faces: np.ndarray, n: int, field: str) -> None:
    with pytest.raises(InputError) as info:
        MeshTopology.from_faces(faces, n)
    assert info.value.field == field


def test_large_mesh_is_fast() -> None:
    _, faces, _ = grid_sheet(400, 250)  # 200k faces
    start = time.perf_counter()
    topo = MeshTopology.from_faces(faces, 401 * 251)
    assert time.perf_counter() - start < 2.0
    assert topo.edge_count == 401 * 251 + 200_000 - 1
