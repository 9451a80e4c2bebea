"""Splits of a BVH node that keep both children edge-connected.

The material-space BVH (:mod:`pscc.collision.bvh`) cuts a node's faces at the median of their centroids
along one axis. On structured cloth both halves are edge-connected patches. On the tessellations of CAD
parts and shipped assets (fans and strips of long slivers whose centroids interleave) a half is often
several pieces. A node whose faces are not edge-connected has several contour loops, so it is never
*testable* (docs/bvh.md) and never passes the normal-cone test: the test front sinks to the leaves, and
every pair of nearby faces of the part is tested. On Newton's `crazyflie` and `rj45_plug` assemblies 9 of
10 such failing nodes just above the front were disconnected.

This module finds the cuts whose halves are not edge-connected (:func:`split_pieces`, vectorised over a
tree level) and cuts those nodes again along the surface (:func:`connected_cuts`, all of a level's nodes in
the same breadth-first passes; :func:`connected_cut` for one node): faces ordered by their
graph distance to one far face minus that to another (two ends found by breadth-first search over shared
edges), cut at the median; failing that, by the distance to the first end alone. A cut is kept only when
both halves are edge-connected, else the first cut stays. The node keeps its faces either way; a node cut
again is cut at the median, (k + 1) // 2 faces to the left (the first cut may have moved to a gap between
centroids), so the tree stays balanced.
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
    """The faces' edge-adjacency graph (symmetric CSR, unit weights), for :func:`connected_cuts`."""
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


def _level_faces(face_order: np.ndarray, begin: np.ndarray, end: np.ndarray) -> tuple[np.ndarray, ...]:
    """The positions of the nodes' faces in ``face_order``, each one's node and its rank within the node."""
    lengths = (end - begin).astype(np.int64)
    node = np.repeat(np.arange(lengths.shape[0], dtype=np.int64), lengths)
    rank = np.arange(int(lengths.sum()), dtype=np.int64) - np.repeat(np.cumsum(lengths) - lengths, lengths)
    return rank + begin[node], node, rank


def _distances(sources: np.ndarray, label: np.ndarray, adjacency: sparse.csr_matrix) -> np.ndarray:
    """Breadth-first graph distances (in shared edges) from ``sources`` (one face per node), each search
    kept to the faces of its source's node (``label``: node of each face, -1 outside); -1 where not reached.
    All nodes' searches advance together, one frontier per step."""
    distance = np.full(label.shape[0], -1, dtype=np.int64)
    distance[sources] = 0
    frontier = sources
    step = 0
    indptr, indices = adjacency.indptr, adjacency.indices
    while frontier.size:
        step += 1
        counts = indptr[frontier + 1] - indptr[frontier]
        origin = np.repeat(frontier, counts)
        offsets = np.arange(int(counts.sum())) - np.repeat(np.cumsum(counts) - counts, counts)
        neighbour = indices[np.repeat(indptr[frontier], counts) + offsets]
        fresh = (distance[neighbour] < 0) & (label[neighbour] == label[origin])
        frontier = np.unique(neighbour[fresh])
        distance[frontier] = step
    return distance


def connected_cuts(face_order: np.ndarray, begin: np.ndarray, end: np.ndarray, adjacency: sparse.csr_matrix,
                   links: tuple[np.ndarray, np.ndarray]) -> np.ndarray:
    """Cut the nodes ``face_order[begin[i]:end[i]]`` (disjoint, edge-connected or not) again along the
    surface: each node's faces ordered by graph distance to its first face minus that to the face farthest
    from it (ties by their given order), else by the distance to the first face alone, and cut at the median
    ``(k + 1) // 2``. A node whose new cut leaves both halves edge-connected gets its faces reordered in
    ``face_order``; the others (and nodes not edge-connected themselves) are left as they are.

    Returns:
        (nodes,) bool: the nodes reordered. Work: a few breadth-first passes over the nodes' faces, all nodes
        at once.
    """
    face_count = adjacency.shape[0]
    positions, node, rank = _level_faces(face_order, begin, end)
    faces = face_order[positions]
    sizes = (end - begin).astype(np.int64)
    label = np.full(face_count, -1, dtype=np.int64)
    label[faces] = node
    first = face_order[begin]
    from_first = _distances(first, label, adjacency)[faces]
    # Nodes in pieces: a face the first one's search never reached.
    whole = np.bincount(node, weights=(from_first < 0), minlength=sizes.shape[0]) == 0
    # The far end: the largest distance, the first such face in the given order.
    best = np.full(sizes.shape[0], -1, dtype=np.int64)
    np.maximum.at(best, node, from_first)
    far_rank = np.full(sizes.shape[0], np.iinfo(np.int64).max)
    np.minimum.at(far_rank, node, np.where(from_first == best[node], rank, np.iinfo(np.int64).max))
    far = face_order[begin + np.minimum(far_rank, sizes - 1)]
    from_far = _distances(far, label, adjacency)[faces]
    done = ~whole | (sizes < 2)
    for key in (from_first - from_far, from_first):
        pending = np.flatnonzero(~done)
        if pending.size == 0:
            break
        order = np.lexsort((rank, key, node))
        ordered = faces[order]
        trial = face_order.copy()
        trial[positions] = ordered
        cut = (sizes + 1) // 2
        pieces = split_pieces(trial, begin[pending], end[pending], cut[pending], links, face_count)
        accept = pending[~pieces]
        take = np.isin(node[order], accept)
        face_order[positions[take]] = ordered[take]
        done[accept] = True
    return done & whole & (sizes >= 2)


def connected_cut(faces: np.ndarray, adjacency: sparse.csr_matrix) -> np.ndarray | None:
    """:func:`connected_cuts` of one node: the reordered ``faces`` (in the order of its median cut), or None
    when the search finds no cut with both halves edge-connected (or the faces are not edge-connected)."""
    order = np.array(faces, dtype=np.int64)
    u, v = sparse.triu(adjacency).nonzero()
    reordered = connected_cuts(order, np.array([0]), np.array([order.shape[0]]), adjacency, (u, v))
    return order if reordered[0] else None
