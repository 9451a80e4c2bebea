"""Reference points for the contour test of BVH nodes that have no interior vertex.

The unprojected contour test (:func:`pscc.geometry.normal_cone.contour_test`) asks whether a node's
contour, seen along the cone axis l from a point o, turns one way around o (star test) and winds once.
Any point o works, as long as it moves linearly over a step (docs/design algorithms §1.5): the test
proves the patch is a height field over the region its contour bounds. The BVH takes for o the interior
vertex nearest the patch's centroid (``MaterialBvh.reference_vertex``); a patch without interior vertex
fell back to the mean of its contour vertices.

On CAD tessellations most small patches have no interior vertex (strips and partial fans of slivers, every
vertex on the boundary), and the mean of their contour lies outside the kernel of the projected contour:
on Newton's `crazyflie` and `rj45_plug` assemblies it made 9 of 10 contour-test failures just above the
test front. :func:`reference_faces` therefore picks, for such a node, the face whose centroid sees the
contour turn one way in a given shape (the mesh's first shape, or its rest coordinates), with the largest
margin; the node test then uses that face's centroid (an affine combination of three vertices, so it
moves linearly over a step). Nodes whose contour mean already passes in that shape keep it. The choice
affects only how often nodes pass, never what a passing node certifies.
"""

from __future__ import annotations

import numpy as np

MAX_CANDIDATES = 64
"""At most this many face centroids are tried per node (those nearest its area-weighted centroid)."""

BATCH_TURNS = 1 << 21
"""Candidate-edge pairs evaluated together (bounds the search's memory to a few hundred MB)."""

MIN_TURN = 1.0e-6
"""A contour edge must turn around o by at least this much (``|l . (a - o) x (b - o)| / (|a - o| |b - o|)``,
the sine of the angle it subtends) for a candidate to count: a tolerance for the float32 test at run time."""


def _ranges(begin: np.ndarray, end: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The concatenated ``arange(begin[i], end[i])`` and where each range starts in it."""
    lengths = (end - begin).astype(np.int64)
    starts = np.cumsum(lengths) - lengths
    return np.arange(int(lengths.sum())) - np.repeat(starts - begin, lengths), starts


def _turns(o: np.ndarray, tails: np.ndarray, heads: np.ndarray, axis: np.ndarray) -> np.ndarray:
    """Sine of the signed angle each contour edge (tail, head) subtends at o about ``axis`` (positive:
    counter-clockwise); the arguments broadcast against each other (points and axes along the last axis)."""
    a = tails - o
    b = heads - o
    norms = np.linalg.norm(a, axis=-1) * np.linalg.norm(b, axis=-1)
    return np.sum(np.cross(a, b) * axis, axis=-1) / np.where(norms > 0.0, norms, np.inf)


def reference_faces(faces: np.ndarray, shape: np.ndarray, host: dict[str, np.ndarray]) -> np.ndarray:
    """(N,) int64: for each testable inner node without a reference vertex whose contour mean fails the star
    test in ``shape`` (along its faces' area-weighted normal), the face of the node whose centroid passes it
    with the largest margin (among :data:`MAX_CANDIDATES` faces nearest the node's centroid); -1 elsewhere.

    Args:
        faces: (m, 3) vertex ids.
        shape: (n, 2) or (n, 3) coordinates to judge the candidates in (2-D ones are taken as z = 0).
        host: the BVH's host arrays (``testable``, ``is_leaf``, ``reference_vertex``, ``contour_offsets``,
            ``contour_vertices``, ``face_order``, ``face_begin``, ``face_end``).
    """
    points = np.asarray(shape, dtype=np.float64)
    if points.shape[1] == 2:
        points = np.concatenate([points, np.zeros((points.shape[0], 1))], axis=1)
    node_count = host["testable"].shape[0]
    chosen = np.full(node_count, -1, dtype=np.int64)
    offsets = host["contour_offsets"]
    loops = host["contour_vertices"]
    order, begin, end = host["face_order"], host["face_begin"], host["face_end"]
    corners = points[faces]
    normal = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    centroid = corners.mean(axis=1)
    weight = np.linalg.norm(normal, axis=1)
    nodes = np.flatnonzero(host["testable"] & ~host["is_leaf"] & (host["reference_vertex"] < 0))
    if nodes.shape[0] == 0:
        return chosen
    # Every candidate node's axis (its faces' area-weighted normal) and the star test of its contour mean at
    # once; only the nodes that fail it are searched.
    face_positions, face_starts = _ranges(begin[nodes], end[nodes])
    axes = np.add.reduceat(normal[order[face_positions]], face_starts, axis=0)
    lengths = np.linalg.norm(axes, axis=1)
    unit = axes / np.where(lengths > 0.0, lengths, 1.0)[:, None]
    slots, loop_starts = _ranges(offsets[nodes], offsets[nodes + 1])
    loop_lengths = (offsets[nodes + 1] - offsets[nodes]).astype(np.int64)
    node_of_slot = np.repeat(np.arange(nodes.shape[0]), loop_lengths)
    last = slots + 1 == offsets[nodes + 1][node_of_slot]
    tails = points[loops[slots]]
    heads = points[loops[np.where(last, offsets[nodes][node_of_slot], slots + 1)]]
    means = np.add.reduceat(tails, loop_starts, axis=0) / loop_lengths[:, None]
    turns = _turns(means[node_of_slot], tails, heads, unit[node_of_slot])
    mean_passes = (np.minimum.reduceat(turns, loop_starts) >= MIN_TURN) | (
        np.maximum.reduceat(turns, loop_starts) <= -MIN_TURN)
    search = np.flatnonzero(~mean_passes & (lengths > 0.0))
    # The search, a batch of nodes at a time (at most about BATCH_TURNS candidate-edge pairs): each node's
    # candidates are its MAX_CANDIDATES faces nearest its area-weighted centroid (ties by face id).
    face_counts = (end[nodes] - begin[nodes]).astype(np.int64)
    pairs = np.cumsum(np.minimum(face_counts[search], MAX_CANDIDATES) * loop_lengths[search])
    for batch in np.split(search, np.flatnonzero(np.diff(pairs // BATCH_TURNS)) + 1):
        if batch.size:
            chosen[nodes[batch]] = _search(batch, nodes, order, begin, end, offsets, loops, points, centroid, weight,
                                           unit)
    return chosen


def _search(batch: np.ndarray, nodes: np.ndarray, order: np.ndarray, begin: np.ndarray, end: np.ndarray,
            offsets: np.ndarray, loops: np.ndarray, points: np.ndarray, centroid: np.ndarray, weight: np.ndarray,
            unit: np.ndarray) -> np.ndarray:
    """The chosen face (or -1) of each node ``nodes[batch]`` (:func:`reference_faces`), all at once."""
    ids = nodes[batch]
    face_positions, face_starts = _ranges(begin[ids], end[ids])
    face_lengths = (end[ids] - begin[ids]).astype(np.int64)
    owner = np.repeat(np.arange(batch.size), face_lengths)
    node_faces = order[face_positions]
    area = weight[node_faces]
    total = np.add.reduceat(area, face_starts)
    weighted = np.add.reduceat(area[:, None] * centroid[node_faces], face_starts, axis=0)
    plain = np.add.reduceat(centroid[node_faces], face_starts, axis=0) / face_lengths[:, None]
    center = np.where(total[:, None] > 0.0, weighted / np.where(total > 0.0, total, 1.0)[:, None], plain)
    distance = np.sum((centroid[node_faces] - center[owner]) ** 2, axis=1)
    ranked = np.lexsort((node_faces, distance, owner))
    place = np.arange(ranked.size) - np.repeat(face_starts, face_lengths)
    keep = ranked[place < MAX_CANDIDATES]
    candidate, candidate_owner = node_faces[keep], owner[keep]
    # Every (candidate, contour edge) pair of its node, candidate-major.
    loop_lengths = (offsets[ids + 1] - offsets[ids]).astype(np.int64)
    edges = loop_lengths[candidate_owner]
    pair_owner = np.repeat(candidate_owner, edges)
    local = np.arange(int(edges.sum())) - np.repeat(np.cumsum(edges) - edges, edges)
    tail_slot = offsets[ids][pair_owner] + local
    head_slot = np.where(local + 1 == loop_lengths[pair_owner], offsets[ids][pair_owner], tail_slot + 1)
    o = np.repeat(centroid[candidate], edges, axis=0)
    turns = _turns(o, points[loops[tail_slot]], points[loops[head_slot]], unit[batch][pair_owner])
    starts = np.cumsum(edges) - edges
    low = np.minimum.reduceat(turns, starts)
    high = np.maximum.reduceat(turns, starts)
    margin = np.where(low >= MIN_TURN, low, np.where(high <= -MIN_TURN, -high, -1.0))
    # Per node, the candidate with the largest margin (the nearest such one on ties), if it is positive.
    best = np.full(batch.size, -np.inf)
    np.maximum.at(best, candidate_owner, margin)
    first = np.full(batch.size, np.iinfo(np.int64).max)
    np.minimum.at(first, candidate_owner, np.where(margin == best[candidate_owner], np.arange(margin.size),
                                                   np.iinfo(np.int64).max))
    found = best > 0.0
    result = np.full(batch.size, -1, dtype=np.int64)
    result[found] = candidate[first[found]]
    return result
