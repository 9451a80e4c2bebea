"""Splits of a BVH node that keep both children edge-connected.

The material-space BVH (:mod:`pscc.collision.bvh`) cuts a node's faces at the median of their centroids
along one axis. On structured cloth both halves are edge-connected patches. On the tessellations of CAD
parts and shipped assets (fans and strips of long slivers whose centroids interleave) a half is often
several pieces. A node whose faces are not edge-connected has several contour loops, so it is never
*testable* (docs/bvh.md) and never passes the normal-cone test: the test front sinks to the leaves, and
every pair of nearby faces of the part is tested. On Newton's `crazyflie` and `rj45_plug` assemblies 9 of
10 such failing nodes just above the front were disconnected.

This module finds the cuts whose halves are not edge-connected (:func:`split_pieces`, vectorised over a
tree level) and cuts those nodes again along the surface (:func:`connected_cut`): faces ordered by their
graph distance to one far face minus that to another (two ends found by breadth-first search over shared
edges), cut at the median; failing that, by the distance to the first end alone. A cut is kept only when
both halves are edge-connected, else the median cut stays. Either way the node's faces and the tree's
shape (a median cut, left half the larger by at most one) are unchanged: only which faces go left.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sparse
from scipy.sparse import csgraph

from pscc.mesh.topology import MeshTopology


def union_roots(count: int, u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Smallest member of each element's class when elements ``u[i]`` and ``v[i]`` are joined.

    Vectorised union-find: every round hooks each tree root onto the smallest root it is linked to (roots
    only ever point to smaller ids, so no cycles form), then compresses paths by pointer jumping until
    every element points at its root.
    """
    parent = np.arange(count, dtype=np.int64)
    u = np.asarray(u, dtype=np.int64)
    v = np.asarray(v, dtype=np.int64)
    while u.size:
        root_u, root_v = parent[u], parent[v]
        low, high = np.minimum(root_u, root_v), np.maximum(root_u, root_v)
        active = low != high
        if not active.any():
            break
        u, v, low, high = u[active], v[active], low[active], high[active]  # settled links never matter again
        np.minimum.at(parent, high, low)
        while True:
            grand = parent[parent]
            if np.array_equal(grand, parent):
                break
            parent = grand
    return parent


def face_links(topology: MeshTopology) -> tuple[np.ndarray, np.ndarray]:
    """Pairs of faces that share an edge: consecutive incident faces of every edge (a chain per edge, so an
    edge of three faces links all three)."""
    offsets = topology.edge_face_offsets.astype(np.int64)
    incident = topology.edge_face_indices.astype(np.int64)
    same_edge = np.repeat(np.arange(offsets.shape[0] - 1), np.diff(offsets))
    chained = same_edge[1:] == same_edge[:-1]
    return incident[:-1][chained], incident[1:][chained]


def face_adjacency(topology: MeshTopology, face_count: int) -> sparse.csr_matrix:
    """The faces' edge-adjacency graph (symmetric CSR, unit weights), for :func:`connected_cut`."""
    u, v = face_links(topology)
    rows = np.concatenate([u, v])
    cols = np.concatenate([v, u])
    graph = sparse.csr_matrix((np.ones(rows.shape[0], dtype=np.int8), (rows, cols)), shape=(face_count, face_count))
    graph.sum_duplicates()
    return graph


def split_pieces(face_order: np.ndarray, begin: np.ndarray, end: np.ndarray, left_count: np.ndarray,
                 links: tuple[np.ndarray, np.ndarray], face_count: int) -> np.ndarray:
    """(nodes,) bool: node i's cut (its first ``left_count[i]`` faces of ``face_order[begin[i]:end[i]]`` go
    left) leaves a half that is not edge-connected. The ranges must be disjoint (one tree level)."""
    lengths = (end - begin).astype(np.int64)
    node = np.repeat(np.arange(lengths.shape[0], dtype=np.int64), lengths)
    local = np.arange(int(lengths.sum()), dtype=np.int64) - np.repeat(np.cumsum(lengths) - lengths, lengths)
    faces = face_order[local + begin[node]]
    label = np.full(face_count, -1, dtype=np.int64)
    label[faces] = 2 * node + (local >= left_count[node])
    u, v = links
    keep = (label[u] >= 0) & (label[u] == label[v])
    graph = sparse.coo_matrix((np.ones(int(keep.sum()), dtype=np.int8), (u[keep], v[keep])),
                              shape=(face_count, face_count))
    count, component = csgraph.connected_components(graph, directed=False)
    # Links join faces of one half only, so each component lies in one half: count them per half.
    half_of_component = np.full(count, -1, dtype=np.int64)
    half_of_component[component[faces]] = label[faces]
    pieces = np.bincount(half_of_component[half_of_component >= 0], minlength=2 * lengths.shape[0])
    return (pieces[0::2] > 1) | (pieces[1::2] > 1)


def _connected(graph: sparse.csr_matrix) -> bool:
    return graph.shape[0] <= 1 or csgraph.connected_components(graph, directed=False)[0] == 1


def _halves_connected(graph: sparse.csr_matrix, order: np.ndarray, cut: int) -> bool:
    left, right = order[:cut], order[cut:]
    return _connected(graph[left][:, left]) and _connected(graph[right][:, right])


def connected_cut(faces: np.ndarray, adjacency: sparse.csr_matrix) -> np.ndarray | None:
    """A reordering of ``faces`` (one node's faces, in the order of its median cut) whose first
    ``(k + 1) // 2`` faces and the rest are both edge-connected, or None when the search finds none (or the
    node itself is not edge-connected). Ties keep the given order, so the result is deterministic."""
    k = faces.shape[0]
    cut = (k + 1) // 2
    graph = adjacency[faces][:, faces]
    if k < 2 or not _connected(graph):
        return None
    rank = np.arange(k)
    # One end: the graph distances from the first face of the median cut (an extreme along its axis).
    from_first = csgraph.shortest_path(graph, directed=False, unweighted=True, indices=0)
    far = int(np.argmax(from_first))
    from_far = csgraph.shortest_path(graph, directed=False, unweighted=True, indices=far)
    for key in (from_first - from_far, from_first):
        order = np.lexsort((rank, key))
        if _halves_connected(graph, order, cut):
            return faces[order]
    return None
