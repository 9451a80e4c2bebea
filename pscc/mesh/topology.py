"""Edge and adjacency tables of a triangle mesh, built with vectorised NumPy.

Layout, for a mesh of m faces, n vertices and E unique edges::

    faces            (m, 3)   f = [v0, v1, v2]
    face_edges       (m, 3)   [edge(v0, v1), edge(v1, v2), edge(v2, v0)]   -> ids into edges
    edges            (E, 2)   [a, b] with a < b, unique, sorted lexicographically

    edge -> faces (CSR):
    edge_face_offsets  (E + 1,)   0 ......... k0 ......... k1 ...... 3m
    edge_face_indices  (3m,)      [faces of edge 0 | faces of edge 1 | ...]   ascending per edge
        faces of edge e = edge_face_indices[edge_face_offsets[e]:edge_face_offsets[e + 1]]

    vertex -> faces (CSR):
    vertex_face_offsets  (n + 1,)
    vertex_face_indices  (3m,)    [faces of vertex 0 | faces of vertex 1 | ...] ascending
        (an isolated vertex has an empty range)

    boundary_edges   (B,)     ids of edges with exactly one face

An edge with one face is a boundary edge, with two an interior manifold edge and with three or
more a non-manifold edge; all three kinds are represented.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from pscc._checks import as_numpy
from pscc.errors import InputError


def _csr_offsets(counts: np.ndarray) -> np.ndarray:
    offsets = np.zeros(counts.shape[0] + 1, dtype=np.int64)
    np.cumsum(counts, out=offsets[1:])
    return offsets.astype(np.int32)


@dataclass(frozen=True, eq=False)
class MeshTopology:
    """Edges of a triangle mesh and the face adjacency of its edges and vertices.

    Build it with :meth:`from_faces`; see the module docstring for the array layout.

    Attributes:
        edges: (E, 2) int32 vertex ids ``[a, b]``, ``a < b``, unique and sorted lexicographically.
        face_edges: (m, 3) int32 edge ids of the face edges (f0, f1), (f1, f2), (f2, f0).
        edge_face_offsets: (E + 1,) int32 CSR offsets into ``edge_face_indices``.
        edge_face_indices: (3m,) int32 faces of each edge, ascending within an edge.
        boundary_edges: (B,) int32 ids of the edges that belong to exactly one face, ascending.
        vertex_face_offsets: (n + 1,) int32 CSR offsets into ``vertex_face_indices``.
        vertex_face_indices: (3m,) int32 faces of each vertex, ascending within a vertex.
    """

    edges: np.ndarray
    face_edges: np.ndarray
    edge_face_offsets: np.ndarray
    edge_face_indices: np.ndarray
    boundary_edges: np.ndarray
    vertex_face_offsets: np.ndarray
    vertex_face_indices: np.ndarray

    @property
    def edge_count(self) -> int:
        """Number of unique edges E."""
        return int(self.edges.shape[0])

    @property
    def vertex_count(self) -> int:
        """Number of vertices n the tables were built for."""
        return int(self.vertex_face_offsets.shape[0]) - 1

    @property
    def is_manifold(self) -> bool:
        """True when no edge belongs to more than two faces (boundaries are allowed)."""
        if self.edge_count == 0:
            return True
        return bool(np.diff(self.edge_face_offsets).max() <= 2)

    def faces_of_edge(self, edge: int) -> np.ndarray:
        """Face ids of edge ``edge``, ascending (a view into ``edge_face_indices``)."""
        return self.edge_face_indices[self.edge_face_offsets[edge]:self.edge_face_offsets[edge + 1]]

    def faces_of_vertex(self, vertex: int) -> np.ndarray:
        """Face ids of vertex ``vertex``, ascending (a view into ``vertex_face_indices``)."""
        return self.vertex_face_indices[
            self.vertex_face_offsets[vertex]:self.vertex_face_offsets[vertex + 1]]

    @classmethod
    def from_faces(cls, faces: Any, vertex_count: int) -> MeshTopology:
        """Build the tables from triangle faces (one sort of the 3m half-edges, one of the corners).

        Args:
            faces: (m, 3) integer vertex ids; each face must list three distinct ids in
                ``[0, vertex_count)`` (as :func:`pscc.mesh.mesh_data.validate_mesh` guarantees).
                m may be 0.
            vertex_count: Number of vertices n (vertices not used by any face are isolated).

        Returns:
            The topology tables.

        Raises:
            InputError: ``faces`` is not an (m, 3) integer array, an id is out of range, or a
                face lists a vertex id twice.
        """
        n = int(vertex_count)
        tris = as_numpy(faces)
        if n < 0:
            raise InputError("argument", "vertex_count", f"{vertex_count!r} is negative",
                             "pass the number of vertices (>= 0)")
        if tris.size == 0:
            tris = tris.reshape(0, 3)
        if tris.ndim != 2 or tris.shape[1] != 3 or tris.dtype.kind not in "iu":
            raise InputError("argument", "faces", f"shape {tris.shape} dtype {tris.dtype} is not an "
                             "(m, 3) integer array", "pass validated triangle faces")
        tris = tris.astype(np.int64, copy=False)
        m = tris.shape[0]
        if m and (tris.min() < 0 or tris.max() >= n):
            raise InputError("argument", "faces", f"a vertex id is outside [0, {n})",
                             "validate the mesh with pscc.mesh.validate_mesh first")
        if m and np.any((tris[:, 0] == tris[:, 1]) | (tris[:, 1] == tris[:, 2])
                        | (tris[:, 0] == tris[:, 2])):
            raise InputError("argument", "faces", "a face lists the same vertex id twice",
                             "validate the mesh with pscc.mesh.validate_mesh first")

        # Half-edges in face-major order: half-edge h belongs to face h // 3.
        start = tris.reshape(-1)
        end = tris[:, [1, 2, 0]].reshape(-1)
        low = np.minimum(start, end)
        high = np.maximum(start, end)
        keys = low * max(n, 1) + high  # lexicographic (low, high) order; fits int64 for n < 2**31
        order = np.argsort(keys, kind="stable")  # stable: faces ascending within an edge
        sorted_keys = keys[order]
        is_first = np.empty(sorted_keys.shape[0], dtype=bool)
        if sorted_keys.shape[0]:
            is_first[0] = True
            np.not_equal(sorted_keys[1:], sorted_keys[:-1], out=is_first[1:])
        edge_of_sorted = np.cumsum(is_first) - 1
        edge_count = int(edge_of_sorted[-1]) + 1 if edge_of_sorted.size else 0

        face_edges = np.empty(3 * m, dtype=np.int32)
        face_edges[order] = edge_of_sorted
        first_half_edges = order[is_first]
        edges = np.stack([low[first_half_edges], high[first_half_edges]], axis=1).astype(np.int32)
        edge_counts = np.bincount(edge_of_sorted, minlength=edge_count)
        edge_face_offsets = _csr_offsets(edge_counts)
        edge_face_indices = (order // 3).astype(np.int32)
        boundary_edges = np.flatnonzero(edge_counts == 1).astype(np.int32)

        vertex_order = np.argsort(start, kind="stable")
        vertex_face_indices = (vertex_order // 3).astype(np.int32)
        vertex_face_offsets = _csr_offsets(np.bincount(start, minlength=n))

        return cls(
            edges=edges.reshape(edge_count, 2),
            face_edges=face_edges.reshape(m, 3),
            edge_face_offsets=edge_face_offsets,
            edge_face_indices=edge_face_indices,
            boundary_edges=boundary_edges,
            vertex_face_offsets=vertex_face_offsets,
            vertex_face_indices=vertex_face_indices,
        )
