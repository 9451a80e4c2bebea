"""Material-space bounding-volume hierarchy with per-node contours, for normal-cone culling (PSCC §3.2).

:class:`MaterialBvh` is built once, on the host with vectorised NumPy, from the mesh topology and
the material (rest / UV) coordinates, and uploaded to Warp arrays. The normal-cone test front
(NCTF) runs on it every step; see ``docs/bvh.md`` for the design.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from typing import Any

import numpy as np
import warp as wp

from pscc._checks import INT32_MAX, as_numpy, check_object_ids
from pscc.collision.connected_splits import connected_cuts, face_adjacency, face_links, split_pieces, union_roots
from pscc.collision.panel_alignment import aligned_face_corners
from pscc.collision.reference_points import reference_faces
from pscc.errors import InputError
from pscc.mesh.mesh_data import MeshData, check_stitches
from pscc.mesh.topology import MeshTopology

wp.set_module_options({"enable_backward": False})


@wp.struct
class MaterialBvhArrays:
    """Device copies of the :class:`MaterialBvh` arrays, passed to kernels as one argument.

    Flags (``is_leaf``, ``is_rigid``, ``testable``) are int32 0/1. See :class:`MaterialBvh` for
    the meaning of every field.
    """

    left: wp.array(dtype=wp.int32)
    right: wp.array(dtype=wp.int32)
    parent: wp.array(dtype=wp.int32)
    depth: wp.array(dtype=wp.int32)
    face_begin: wp.array(dtype=wp.int32)
    face_end: wp.array(dtype=wp.int32)
    is_leaf: wp.array(dtype=wp.int32)
    is_rigid: wp.array(dtype=wp.int32)
    object_id: wp.array(dtype=wp.int32)
    testable: wp.array(dtype=wp.int32)
    reference_vertex: wp.array(dtype=wp.int32)
    reference_face: wp.array(dtype=wp.int32)
    contour_offsets: wp.array(dtype=wp.int32)
    contour_vertices: wp.array(dtype=wp.int32)
    seam_offsets: wp.array(dtype=wp.int32)
    seam_vertices: wp.array(dtype=wp.int32)
    face_order: wp.array(dtype=wp.int32)
    face_leaf: wp.array(dtype=wp.int32)
    level_offsets: wp.array(dtype=wp.int32)
    level_nodes: wp.array(dtype=wp.int32)


_DEVICE_FIELDS = tuple(MaterialBvhArrays.vars.keys())


# --- host helpers ------------------------------------------------------------------------------


def _range_positions(begin: np.ndarray, end: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Concatenate ``arange(begin[i], end[i])`` for all i; return the positions and the i of each."""
    lengths = (end - begin).astype(np.int64)
    segment = np.repeat(np.arange(lengths.shape[0], dtype=np.int64), lengths)
    starts = np.cumsum(lengths) - lengths
    positions = np.arange(int(lengths.sum()), dtype=np.int64) - np.repeat(starts - begin, lengths)
    return positions, segment


def _segment_starts(lengths: np.ndarray) -> np.ndarray:
    """Start of each segment in the concatenation of segments of the given (positive) lengths."""
    return (np.cumsum(lengths) - lengths).astype(np.int64)


FEATURE_EDGE_COSINE: float = 0.5
"""An edge between two faces whose unit normals have a dot product below this (normals more than 60 degrees
apart) is a feature edge of a shape the BVH embeds (:meth:`MaterialBvh.build`, ``feature_shape``): panels are
cut there, so the flat cap of a cylinder or a smooth face of a CAD part gets a subtree of its own.

A node across such an edge rarely passes the normal-cone test, and the median splits of a whole closed
surface mix the faces on both sides. Measured without rest coordinates:
- a cylinder whose caps are fans of slivers: 482 front nodes for its 1,024 faces before, 9 after, and a
  graph replay 3.1 times faster;
- Newton's CAD assemblies: 3-4 % fewer triangle pairs and a 5-9 % faster replay;
- cloth folds as sharp as this also cut a panel: the corpus's cloth frames changed by at most 0.13 % in
  pairs;
- the low-poly `bear`, a fifth of whose edges are this sharp, fell into 208 panels: 406 pairs instead of 292,
  with a 4 % faster replay."""


def _feature_edges(faces: np.ndarray, shape: np.ndarray, topology: MeshTopology) -> np.ndarray:
    """(edge_count,) bool: the edges of exactly two faces whose normals in ``shape`` are more than
    :data:`FEATURE_EDGE_COSINE` apart (faces of zero area have no normal and cut nothing)."""
    corners = shape[faces]
    normal = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    length = np.linalg.norm(normal, axis=1)
    valid = length > 0.0
    normal[valid] /= length[valid, None]
    offsets = topology.edge_face_offsets.astype(np.int64)
    two = np.flatnonzero(np.diff(offsets) == 2)
    first = topology.edge_face_indices[offsets[two]]
    second = topology.edge_face_indices[offsets[two] + 1]
    cut = valid[first] & valid[second] & (np.einsum("ij,ij->i", normal[first], normal[second]) < FEATURE_EDGE_COSINE)
    feature = np.zeros(offsets.shape[0] - 1, dtype=bool)
    feature[two[cut]] = True
    return feature


def _face_panels(topology: MeshTopology, object_ids: np.ndarray, cut: np.ndarray | None = None) -> np.ndarray:
    """Smallest face id of each face's panel (faces of one object connected through shared edges, not
    through the edges marked in ``cut``), by the vectorised union-find
    :func:`~pscc.collision.connected_splits.union_roots`."""
    m = object_ids.shape[0]
    offsets = topology.edge_face_offsets.astype(np.int64)
    slot_face = topology.edge_face_indices.astype(np.int64)
    slot_edge = np.repeat(np.arange(offsets.shape[0] - 1, dtype=np.int64), np.diff(offsets))
    if cut is not None:
        linkable = ~cut[slot_edge]
        slot_face, slot_edge = slot_face[linkable], slot_edge[linkable]
    slot_object = object_ids[slot_face]
    order = np.lexsort((slot_object, slot_edge))  # edge-major, then object: same-object faces adjacent
    edge_s, object_s, face_s = slot_edge[order], slot_object[order], slot_face[order]
    linked = (edge_s[1:] == edge_s[:-1]) & (object_s[1:] == object_s[:-1])
    return union_roots(m, face_s[:-1][linked], face_s[1:][linked])


def _seam_matches(faces: np.ndarray, topology: MeshTopology, object_ids: np.ndarray,
                  stitches: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
    """Sewn seam edges: pairs of boundary half-edges whose ends are welded by vertex stitches.

    A stitch ``(i, j, k, r)`` with r = 0 welds i to j (r = 1: to k); stitches with 0 < r < 1 put i
    inside an edge and weld nothing. A boundary half-edge a -> b (its edge has one face) is matched
    with the boundary half-edge c -> d of another face of the same object when a is welded to d and
    b to c (opposite directions: the two faces are consistently oriented across the seam), and the
    match is unique both ways. Anything else (a T-junction, three panels on one seam, flipped
    panels) stays unmatched, so its edges stay on the contours.

    Returns:
        ``(partner_face, partner_corner)``, both (m, 3) int64: for the half-edge of face f that
        starts at corner c, the face and corner of its matched half-edge, or -1.
    """
    m = faces.shape[0]
    partner_face = np.full((m, 3), -1, dtype=np.int64)
    partner_corner = np.full((m, 3), -1, dtype=np.int64)
    if stitches is None or stitches.shape[0] == 0:
        return partner_face, partner_corner
    rows = np.asarray(stitches, dtype=np.float64)
    ids = rows[:, :3].astype(np.int64)
    at_j, at_k = rows[:, 3] == 0.0, rows[:, 3] == 1.0
    pairs = np.concatenate([ids[at_j][:, [0, 1]], ids[at_k][:, [0, 2]]])
    if pairs.shape[0] == 0:
        return partner_face, partner_corner
    welded: dict[int, set[int]] = {}
    for i, j in pairs.tolist():
        welded.setdefault(i, set()).add(j)
        welded.setdefault(j, set()).add(i)
    offsets = topology.edge_face_offsets.astype(np.int64)
    boundary = (np.diff(offsets) == 1)[topology.face_edges.astype(np.int64)]  # (m, 3) per half-edge
    tails = faces
    heads = faces[:, [1, 2, 0]]
    candidates = np.flatnonzero((boundary & np.isin(tails, pairs) & np.isin(heads, pairs)).reshape(-1))
    slot = {(int(tails.flat[h]), int(heads.flat[h])): int(h) for h in candidates}
    match: dict[int, int] = {}
    for h in candidates.tolist():
        a, b = int(tails.flat[h]), int(heads.flat[h])
        found = [slot[(c, d)] for c in welded.get(b, ()) for d in welded.get(a, ()) if (c, d) in slot]
        found = [g for g in found if g // 3 != h // 3 and object_ids[g // 3] == object_ids[h // 3]]
        if len(found) == 1:
            match[h] = found[0]
    for h, g in match.items():
        if match.get(g) == h:
            partner_face.flat[h] = g // 3
            partner_corner.flat[h] = g % 3
    return partner_face, partner_corner


def _sewn_components(panel_of_face: np.ndarray, partner_face: np.ndarray) -> np.ndarray:
    """Component of each panel when panels joined by matched seam edges count as one (smallest panel)."""
    count = int(panel_of_face.max()) + 1
    parent = np.arange(count, dtype=np.int64)
    sewn = partner_face.reshape(-1) >= 0
    u = panel_of_face[np.repeat(np.arange(partner_face.shape[0]), 3)[sewn]]
    v = panel_of_face[partner_face.reshape(-1)[sewn]]

    def find(x: int) -> int:
        while parent[x] != x:
            parent[x] = parent[parent[x]]
            x = int(parent[x])
        return x

    for a, b in zip(u.tolist(), v.tolist(), strict=True):
        ra, rb = find(a), find(b)
        if ra != rb:
            parent[max(ra, rb)] = min(ra, rb)
    return np.array([find(p) for p in range(count)], dtype=np.int64)


def _face_geometry(faces: np.ndarray, material: np.ndarray) -> tuple[np.ndarray, ...]:
    """Per-face material-space centroid, box corners and area (float64)."""
    return _corner_geometry(material[faces])


def _corner_geometry(corners: np.ndarray) -> tuple[np.ndarray, ...]:
    """Centroid, box corners and area (float64) of faces given by their (m, 3, dim) corners."""
    centroid = corners.mean(axis=1)
    lower = corners.min(axis=1)
    upper = corners.max(axis=1)
    e1 = corners[:, 1] - corners[:, 0]
    e2 = corners[:, 2] - corners[:, 0]
    if corners.shape[2] == 2:
        area = 0.5 * np.abs(e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0])
    else:
        area = 0.5 * np.linalg.norm(np.cross(e1, e2), axis=1)
    return centroid, lower, upper, area


_SPLIT_WINDOW = 0.25
"""A median split may move to the widest centroid gap within ``(0.5 +- _SPLIT_WINDOW) * k`` of k faces."""


def _split_ranges(face_order: np.ndarray, begin: np.ndarray, end: np.ndarray, centroid: np.ndarray,
                  lower: np.ndarray, upper: np.ndarray) -> np.ndarray:
    """Sort each range ``face_order[begin:end]`` along its split axis and return its left child's face count.

    Split axis: the longest extent of the box of the range's face centroids, measured in mean face
    sizes along that axis (so a single row of thin faces is cut across the row, never into a
    zig-zag of lower and upper triangles). Faces are sorted by centroid along that axis, ties by
    the next axis. The cut goes at the median, moved to the widest gap between consecutive sorted
    centroids within the middle half (gap weighted by 1 - distance from the median / k): on
    structured meshes it then falls between rows of cells instead of through one, which keeps
    both children edge-connected single-loop patches.
    """
    positions, segment = _range_positions(begin, end)
    faces = face_order[positions]
    size = (end - begin).astype(np.int64)
    starts = _segment_starts(size)
    centers = centroid[faces]
    spread = np.maximum.reduceat(centers, starts, axis=0) - np.minimum.reduceat(centers, starts, axis=0)
    face_size = np.add.reduceat(upper[faces] - lower[faces], starts, axis=0) / size[:, None]
    axes = np.argsort(-(spread / np.maximum(face_size, np.finfo(np.float64).tiny)), axis=1, kind="stable")
    rows = np.arange(faces.shape[0])
    primary = centers[rows, axes[segment, 0]]
    order = np.lexsort((centers[rows, axes[segment, 1]], primary, segment))
    face_order[positions] = faces[order]

    primary = primary[order]
    local = positions - begin[segment]
    count = size[segment]
    gap = np.zeros(primary.shape[0])
    gap[1:] = primary[1:] - primary[:-1]
    deviation = np.abs(local - 0.5 * count) / count
    valid = (local >= 1) & ((deviation <= _SPLIT_WINDOW) | (local == (count + 1) // 2))
    score = np.where(valid, gap * (1.0 - deviation), -1.0)
    best = np.maximum.reduceat(score, starts)
    return np.minimum.reduceat(np.where(score == best[segment], local, np.iinfo(np.int64).max), starts)


def _chain_loops(node: np.ndarray, tail: np.ndarray, head: np.ndarray, vertex_count: int,
                 node_count: int, label: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Chain directed contour edges into loops, per node; keep the nodes made of exactly one loop.

    A node is kept iff every contour vertex has exactly one outgoing and one incoming contour edge
    (so the edges form disjoint cycles) and there is one cycle. The loop of a kept node starts at
    its smallest vertex id.

    ``label`` (default: ``tail``) is what the loop stores for each edge: with welded seams the edges
    are chained on welded vertex ids but each loop entry keeps its edge's own tail vertex.

    Returns:
        ``(node, rank, vertex)`` of every contour vertex of the kept nodes: the vertex (label) at
        loop position ``rank`` of ``node``.
    """
    label = tail if label is None else label
    if node.shape[0] == 0:
        empty = np.zeros(0, dtype=np.int64)
        return empty, empty, empty
    n = np.int64(max(vertex_count, 1))
    key_tail = node * n + tail
    order = np.argsort(key_tail, kind="stable")
    node, tail, head, key_tail, label = node[order], tail[order], head[order], key_tail[order], label[order]
    count = node.shape[0]
    # successor: the edge leaving the head vertex. It is a permutation of the node's edges iff every
    # head starts an edge and no head repeats (two edges leaving one vertex force, by counting, a
    # head that starts no edge or a repeated head, so they need no separate check).
    bad = np.zeros(node_count, dtype=bool)
    key_head = node * n + head
    successor = np.minimum(np.searchsorted(key_tail, key_head), count - 1)
    bad[node[key_tail[successor] != key_head]] = True  # a head that starts no edge: open chain
    sorted_head = np.sort(key_head)
    bad[sorted_head[1:][sorted_head[1:] == sorted_head[:-1]] // n] = True  # two edges entering one vertex

    keep = ~bad[node]
    new_index = np.cumsum(keep) - 1
    node, label, successor = node[keep], label[keep], new_index[successor[keep]]
    count = node.shape[0]
    if count == 0:
        empty = np.zeros(0, dtype=np.int64)
        return empty, empty, empty
    index = np.arange(count, dtype=np.int64)
    is_start = np.ones(count, dtype=bool)
    is_start[1:] = node[1:] != node[:-1]
    start = np.maximum.accumulate(np.where(is_start, index, 0))
    predecessor = np.empty(count, dtype=np.int64)
    predecessor[successor] = index
    # List ranking by pointer jumping towards the start: afterwards `rank` is the number of steps
    # from the start to each edge along the loop, for the edges on the start's cycle.
    jump = np.where(is_start, index, predecessor)
    rank = (~is_start).astype(np.int64)
    longest = int(np.diff(np.flatnonzero(np.append(is_start, True))).max())
    for _ in range(max(1, math.ceil(math.log2(longest))) + 1):
        rank = rank + rank[jump]
        jump = jump[jump]
    bad[node[jump != start]] = True  # an edge not on the start's cycle: several loops
    keep = ~bad[node]
    return node[keep], rank[keep], label[keep]


def _weld_in_nodes(faces: np.ndarray, level_faces: np.ndarray, face_node: np.ndarray, interior_seam: np.ndarray,
                   seams: tuple[np.ndarray, np.ndarray], n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """Welded vertices of one depth: the ends of the interior seam pairs of each node, joined per node.

    Returns None without interior seams, else ``(keys, targets, rows)``: sorted keys ``node * n + v``
    of the welded vertices, the smallest vertex each one is welded to within that node (through the
    node's own seam pairs only), and one row ``(node, a1, a2, b1, b2)`` per interior seam edge pair
    (a1 welded to b1, a2 to b2), each pair listed once.
    """
    rows, corners = np.nonzero(interior_seam)
    if rows.shape[0] == 0:
        return None
    partner_face, partner_corner = seams
    node = face_node[rows]
    face = level_faces[rows]
    other, other_corner = partner_face[face, corners], partner_corner[face, corners]
    a1, a2 = faces[face, corners], faces[face, (corners + 1) % 3]
    b2, b1 = faces[other, other_corner], faces[other, (other_corner + 1) % 3]  # partner runs b2 -> b1
    parent: dict[int, int] = {}

    def find(x: int) -> int:
        root = x
        while parent.get(root, root) != root:
            root = parent[root]
        while parent.get(x, x) != root:
            parent[x], x = root, parent[x]
        return root

    node2 = np.concatenate([node, node])
    for k, p, q in zip(node2.tolist(), np.concatenate([a1, a2]).tolist(), np.concatenate([b1, b2]).tolist(),
                       strict=True):
        rp, rq = find(k * n + p), find(k * n + q)
        if rp != rq:  # the root is the smallest key of the class, i.e. the smallest vertex of that node
            parent[max(rp, rq)] = min(rp, rq)
    keys = np.array(sorted(parent.keys() | set(parent.values())), dtype=np.int64)
    targets = np.array([find(int(key)) % n for key in keys], dtype=np.int64)
    once = face * 3 + corners < other * 3 + other_corner
    seam_rows = np.stack([node, a1, a2, b1, b2], axis=1)[once]
    return keys, targets, seam_rows


def _welded(weld: tuple[np.ndarray, np.ndarray, np.ndarray] | None, node: np.ndarray, vertex: np.ndarray,
            n: int) -> np.ndarray:
    """``vertex`` with every welded vertex of its ``node`` replaced by the smallest one it is welded to."""
    if weld is None:
        return vertex
    keys, targets, _ = weld
    key = node * n + vertex
    slot = np.minimum(np.searchsorted(keys, key), keys.shape[0] - 1)
    return np.where(keys[slot] == key, targets[slot], vertex)


# --- the hierarchy -----------------------------------------------------------------------------


class MaterialBvh:
    """Binary BVH of a mesh's faces built in material space, with the contour of every node.

    Build it with :meth:`build` (or :meth:`from_mesh`). Material coordinates are the mesh's
    ``rest`` coordinates when it has them; otherwise the caller passes the first positions
    (:meth:`from_mesh` does exactly that). Node ids are numbered level by level (breadth first),
    so the nodes of one depth are a contiguous id range and, within it, ordered by ``face_begin``.

    Structure: one subtree per panel (edge-connected component of the faces of one object), split
    top-down at the median face centroid along the node's longest extent down to one face per
    leaf (the cut may move to the widest centroid gap within the middle half of the faces, so it
    falls between rows of cells; see :func:`_split_ranges`). The panel roots of each object, ordered
    by their centroid along the object's widest spread, are joined by a balanced top tree, giving
    one root per object (a forest when there are several objects). A rigid object is a single
    leaf-like node holding all its faces. ``N`` = node count, ``m`` = face count, ``D`` = number of
    depths, ``C`` = total contour length; ``N = 2m - 1`` when no object is rigid.

    ====================  ==========  ===============================================================
    array                 shape       meaning (int32 unless noted; -1 = none)
    ====================  ==========  ===============================================================
    left, right           (N,)        children; -1 for leaves and rigid nodes
    parent                (N,)        parent; -1 for roots
    depth                 (N,)        0 at the roots
    face_begin, face_end  (N,)        the node covers ``face_order[face_begin:face_end]``
    is_leaf               (N,) bool   no children (one face, or a rigid object's faces)
    is_rigid              (N,) bool   node of a rigid object (never split, never tested)
    object_id             (N,)        object of the node's faces
    panel                 (N,)        panel of the node's faces; -1 above the panel roots
    testable              (N,) bool   the contour is one closed loop of a connected patch (below)
    reference_vertex      (N,)        interior vertex nearest the patch centroid, or -1
    reference_face        (N,)        without reference vertex: the face whose centroid is the contour
                                      test's point (:mod:`pscc.collision.reference_points`), or -1
    contour_offsets       (N + 1,)    CSR offsets into ``contour_vertices``
    contour_vertices      (C,)        loop v_0 .. v_{k-1} of each testable node (edge v_{k-1} v_0 implied)
    component             (N,)        sewn component of the node's panels (one only), else -1
    seam_offsets          (N + 1,)    CSR offsets of each node's interior sewn seam edge pairs
    seam_vertices         (4 S,)      a1 a2 b1 b2 per pair: a1 welded to b1, a2 to b2 (docs/bvh.md)
    face_order            (m,)        permutation of the faces; every node is a range of it
    face_leaf             (m,)        leaf (or rigid node) of each face
    face_panel            (m,)        panel of each face (panels numbered in top-tree order)
    level_offsets         (D + 1,)    nodes of depth d: ``level_nodes[level_offsets[d]:level_offsets[d+1]]``
    level_nodes           (N,)        node ids by depth, deepest last (the identity, ids are BFS)
    roots                 (R,)        root node of each object present, by ascending object id
    object_values         (R,)        the distinct object ids, ascending; ``roots[k]`` is the root of id
                                      ``object_values[k]``
    ====================  ==========  ===============================================================

    Contour: every mesh edge with exactly one incident face inside the node (edges shared with a
    face outside the node count), oriented as in that face (face (a, b, c) has a->b, b->c, c->a).
    A node is *testable* iff its faces are edge-connected, no edge of its faces has 3+ faces in the
    whole mesh, and its contour edges form exactly one closed loop in which every contour vertex
    has one outgoing and one incoming edge. Rigid nodes and nodes above the panel roots are never
    testable; leaves always are (their loop is their face (v0, v1, v2), no reference vertex). The
    loop of an internal node starts at its smallest vertex id. Non-testable nodes have an empty
    contour range.

    Object ids need not be contiguous (any id in [0, 2**31 - 1]): every per-object table has R rows,
    one per distinct id, never ``max id + 1``; :meth:`root_of` looks an id up.

    Device copies of these arrays (flags as int32 0/1; not ``panel``, ``face_panel``, ``roots``,
    ``object_values``) are the fields of :attr:`arrays`, a :class:`MaterialBvhArrays` on
    :attr:`device`. The host arrays are owned by the instance; do not modify them.
    """

    def __init__(self, host: dict[str, np.ndarray], device: Any = None) -> None:
        """Wrap host arrays made by :meth:`build` and upload them. Use :meth:`build` instead."""
        self.device = wp.get_device(device)
        self.left: np.ndarray = host["left"]
        self.right: np.ndarray = host["right"]
        self.parent: np.ndarray = host["parent"]
        self.depth: np.ndarray = host["depth"]
        self.face_begin: np.ndarray = host["face_begin"]
        self.face_end: np.ndarray = host["face_end"]
        self.is_leaf: np.ndarray = host["is_leaf"]
        self.is_rigid: np.ndarray = host["is_rigid"]
        self.object_id: np.ndarray = host["object_id"]
        self.panel: np.ndarray = host["panel"]
        self.testable: np.ndarray = host["testable"]
        self.reference_vertex: np.ndarray = host["reference_vertex"]
        self.reference_face: np.ndarray = host["reference_face"]
        self.contour_offsets: np.ndarray = host["contour_offsets"]
        self.contour_vertices: np.ndarray = host["contour_vertices"]
        self.seam_offsets: np.ndarray = host["seam_offsets"]
        self.seam_vertices: np.ndarray = host["seam_vertices"]
        self.component: np.ndarray = host["component"]
        self.face_order: np.ndarray = host["face_order"]
        self.face_leaf: np.ndarray = host["face_leaf"]
        self.face_panel: np.ndarray = host["face_panel"]
        self.level_offsets: np.ndarray = host["level_offsets"]
        self.level_nodes: np.ndarray = host["level_nodes"]
        self.roots: np.ndarray = host["roots"]
        self.object_values: np.ndarray = host["object_values"]
        self.arrays = MaterialBvhArrays()
        for name in _DEVICE_FIELDS:
            values = np.ascontiguousarray(host[name], dtype=np.int32)
            if values.size == 0:  # an empty seam list: one unused entry, as Warp arrays need a buffer
                values = np.zeros(1, dtype=np.int32)
            setattr(self.arrays, name, wp.array(values, dtype=wp.int32, device=self.device))

    # --- sizes ---------------------------------------------------------------------------------

    @property
    def node_count(self) -> int:
        """Number of nodes N."""
        return int(self.left.shape[0])

    @property
    def face_count(self) -> int:
        """Number of faces m."""
        return int(self.face_order.shape[0])

    @property
    def level_count(self) -> int:
        """Number of depths D (the deepest depth is D - 1)."""
        return int(self.level_offsets.shape[0]) - 1

    @property
    def levels(self) -> list[np.ndarray]:
        """Node ids of each depth, roots first and deepest last (views into ``level_nodes``)."""
        return [self.level_nodes[self.level_offsets[d]:self.level_offsets[d + 1]] for d in range(self.level_count)]

    @property
    def device_bytes(self) -> int:
        """Bytes held on the device by :attr:`arrays`."""
        return sum(getattr(self.arrays, name).capacity for name in _DEVICE_FIELDS)

    def contour(self, node: int) -> np.ndarray:
        """Loop vertices of ``node`` (empty when it is not testable); a view into ``contour_vertices``."""
        return self.contour_vertices[self.contour_offsets[node]:self.contour_offsets[node + 1]]

    def root_of(self, object_id: int) -> int:
        """Root node of object ``object_id``, or -1 when no face has that id.

        Allocates: no. Capture-safe: no (host lookup).
        """
        k = int(np.searchsorted(self.object_values, object_id))
        if k < self.object_values.shape[0] and int(self.object_values[k]) == int(object_id):
            return int(self.roots[k])
        return -1

    def faces_of(self, node: int) -> np.ndarray:
        """Faces covered by ``node``; a view into ``face_order``."""
        return self.face_order[self.face_begin[node]:self.face_end[node]]

    # --- construction --------------------------------------------------------------------------

    @classmethod
    def from_mesh(cls, mesh: MeshData, topology: MeshTopology, device: Any = None,
                  rigid_objects: Iterable[int] = frozenset()) -> MaterialBvh:
        """Build from a validated mesh: material coordinates are ``mesh.rest``, else ``mesh.vertices``.

        Args:
            mesh: The validated mesh.
            topology: ``MeshTopology.from_faces(mesh.faces, mesh.vertex_count)``.
            device: Warp device of the uploaded arrays.
            rigid_objects: Object ids whose faces form one unsplit node each.

        Returns:
            The hierarchy.

        Allocates: yes. Capture-safe: no.
        """
        material = mesh.rest if mesh.rest is not None else mesh.vertices
        return cls.build(mesh.faces, material, mesh.object_ids, topology, device, rigid_objects, mesh.stitches)

    @classmethod
    def build(cls, faces: Any, material: Any, object_ids: Any, topology: MeshTopology, device: Any = None,
              rigid_objects: Iterable[int] = frozenset(), stitches: Any = None,
              feature_shape: Any = None) -> MaterialBvh:
        """Build the hierarchy and its contours on the host, then upload it to ``device``.

        Args:
            faces: (face_count, 3) integer vertex ids (int32), at least one face.
            material: (vertex_count, 2) or (vertex_count, 3) float material coordinates: the rest
                / UV coordinates, or the first positions when the mesh has none.
            object_ids: (face_count,) integer object id of each face, in [0, 2**31 - 1]; ids need
                not be contiguous (memory grows with the number of distinct ids, not the largest).
            topology: ``MeshTopology.from_faces(faces, vertex_count)``.
            device: Warp device of the uploaded arrays.
            rigid_objects: Object ids whose faces form one unsplit node each.
            stitches: optional (s, 4) rows ``(i, j, k, r)`` (vertex i sewn to (1 - r) x_j + r x_k). Seam
                edges whose ends are welded by stitches with r = 0 or 1 join their panels into one sewn
                component, and count as interior edges of the nodes holding both sides (docs/bvh.md,
                "Sewn panels").
            feature_shape: optional (vertex_count, 3) positions of the mesh's 3-D shape (the detector
                passes the first positions of a mesh without rest coordinates, or a 3-D rest shape):
                panels are also cut at its feature edges (:data:`FEATURE_EDGE_COSINE`). Leave it out for
                2-D rest or UV coordinates, whose panels are the pattern's. A flat shape has no feature
                edges unless its faces' orientations disagree.

        Returns:
            The hierarchy. Host cost: O(m log m) per depth, O(m log^2 m) in all.

        Raises:
            InputError: wrong shapes or dtypes, ids out of range, non-finite coordinates, or a
                topology built for other faces.

        Allocates: yes. Capture-safe: no.
        """
        tris, coords, objects, rigid = _validate(faces, material, object_ids, topology, rigid_objects)
        rows = None if stitches is None else check_stitches(stitches, coords.shape[0], "argument")
        seams = _seam_matches(tris, topology, objects, rows)
        geometry = _face_geometry(tris, coords)
        cut = None
        if feature_shape is not None:
            shape = np.asarray(feature_shape, dtype=np.float64)
            if shape.shape != (coords.shape[0], 3) or not np.all(np.isfinite(shape)):
                raise InputError("argument", "feature_shape", f"has shape {shape.shape} or non-finite values",
                                 f"pass ({coords.shape[0]}, 3) finite positions, or None")
            cut = _feature_edges(tris.astype(np.int64), shape, topology)
        panel_root = _face_panels(topology, objects, cut)
        _, panel_of_face = np.unique(panel_root, return_inverse=True)
        # The cuts see each panel turned so that its mesh lines run along the axes (panel_alignment).
        split_geometry = _corner_geometry(aligned_face_corners(tris, coords, panel_of_face))
        # A 3-D shape (no rest coordinates, or a 3-D rest): its tessellation is not a pattern's, so the
        # halves of a median cut may fall in pieces, and small patches may have no interior vertex.
        shaped = feature_shape is not None
        host = _build_tree(split_geometry, objects, topology, rigid, seams[0], panel_root, connect_halves=shaped)
        host.update(_build_contours(tris, coords, geometry, topology, host, seams))
        host["reference_face"] = (reference_faces(tris, shape, host) if shaped
                                  else np.full(host["left"].shape[0], -1, dtype=np.int64))
        host = {name: values.astype(np.int32) if values.dtype.kind in "iu" else values
                for name, values in host.items()}
        return cls(host, device)


def _validate(faces: Any, material: Any, object_ids: Any, topology: MeshTopology,
              rigid_objects: Iterable[int]) -> tuple[np.ndarray, np.ndarray, np.ndarray, frozenset[int]]:
    """Check the public inputs of :meth:`MaterialBvh.build`; return int64 faces, float64 coordinates."""
    tris = as_numpy(faces)
    if tris.ndim != 2 or tris.shape[1] != 3 or tris.shape[0] == 0 or tris.dtype.kind not in "iu":
        raise InputError("argument", "faces", f"shape {tris.shape} dtype {tris.dtype} is not a non-empty (m, 3) "
                         "integer array", "pass the mesh's validated int32 faces")
    coords = as_numpy(material)
    if coords.ndim != 2 or coords.shape[1] not in (2, 3) or coords.dtype.kind not in "fiu":
        raise InputError("argument", "material", f"shape {coords.shape} dtype {coords.dtype} is not (n, 2) or "
                         "(n, 3) real", "pass the rest coordinates, or the first positions")
    coords = coords.astype(np.float64)
    if not np.all(np.isfinite(coords)):
        raise InputError("argument", "material", "holds NaN or Inf", "pass finite material coordinates")
    tris = tris.astype(np.int64)
    n = coords.shape[0]
    if tris.min() < 0 or tris.max() >= n:
        raise InputError("argument", "faces", f"a vertex id is outside [0, {n})",
                         "pass faces indexing the rows of material")
    objects = check_object_ids(object_ids, tris.shape[0])
    if topology.face_edges.shape != tris.shape or topology.vertex_count != n:
        raise InputError("argument", "topology", f"built for {topology.face_edges.shape[0]} faces and "
                         f"{topology.vertex_count} vertices, not {tris.shape[0]} and {n}",
                         "pass MeshTopology.from_faces(faces, vertex_count)")
    try:
        rigid = frozenset(int(o) for o in rigid_objects)
    except (TypeError, ValueError) as exc:
        raise InputError("argument", "rigid_objects", "is not a set of integer object ids",
                         "pass e.g. {1, 3}") from exc
    # Ids no face can have select nothing; dropping them keeps the set within int64 for np.isin.
    rigid = frozenset(o for o in rigid if 0 <= o <= INT32_MAX)
    return tris, coords, objects.astype(np.int64), rigid


class _HalfConnector:
    """The face links and adjacency :mod:`pscc.collision.connected_splits` needs, made on first use."""

    def __init__(self, topology: MeshTopology, face_count: int) -> None:
        self.topology = topology
        self.face_count = face_count
        self._links: tuple[np.ndarray, np.ndarray] | None = None
        self._adjacency: Any = None

    @property
    def links(self) -> tuple[np.ndarray, np.ndarray]:
        if self._links is None:
            self._links = face_links(self.topology)
        return self._links

    @property
    def adjacency(self) -> Any:
        if self._adjacency is None:
            self._adjacency = face_adjacency(self.topology, self.face_count)
        return self._adjacency


def _connect_halves(face_order: np.ndarray, begin: np.ndarray, end: np.ndarray, median: np.ndarray,
                    left_count: np.ndarray, splitter: _HalfConnector) -> None:
    """Cut again along the surface (:func:`~pscc.collision.connected_splits.connected_cuts`) the ``median``
    nodes of one level whose cut leaves a half that is not edge-connected; ``face_order`` and ``left_count``
    are updated in place for those a connected cut was found for."""
    nodes = np.flatnonzero(median)
    broken = nodes[split_pieces(face_order, begin[nodes], end[nodes], left_count[nodes], splitter.links,
                                splitter.face_count)]
    if broken.size:
        reordered = broken[connected_cuts(face_order, begin[broken], end[broken], splitter.adjacency,
                                          splitter.links)]
        left_count[reordered] = (end[reordered] - begin[reordered] + 1) // 2


def _build_tree(geometry: tuple[np.ndarray, ...], object_ids: np.ndarray, topology: MeshTopology,
                rigid: frozenset[int], partner_face: np.ndarray, panel_root: np.ndarray,
                connect_halves: bool = False) -> dict[str, np.ndarray]:
    """Top-down, level-by-level construction of the node arrays (see :class:`MaterialBvh`); with
    ``connect_halves``, a median cut that leaves a half in pieces is cut again along the surface
    (:mod:`pscc.collision.connected_splits`)."""
    centroid, lower, upper, _ = geometry
    m, dim = centroid.shape

    # Panels, ordered by object, then by centroid along the object's widest spread of panel centroids.
    # Panels sewn together (matched seam edges, :func:`_seam_matches`) form a sewn component; the
    # panels of one component are kept consecutive (ordered by the component's mean panel centroid),
    # so the top tree joins sewn panels before anything else.
    panel_min_face, panel_of_face = np.unique(panel_root, return_inverse=True)
    panel_count = panel_min_face.shape[0]
    panel_size = np.bincount(panel_of_face, minlength=panel_count)
    panel_center = np.stack([np.bincount(panel_of_face, weights=centroid[:, k], minlength=panel_count)
                             for k in range(dim)], axis=1) / panel_size[:, None]
    object_values, panel_object = np.unique(object_ids[panel_min_face], return_inverse=True)
    spread_lo = np.full((object_values.shape[0], dim), np.inf)
    spread_hi = np.full_like(spread_lo, -np.inf)
    np.minimum.at(spread_lo, panel_object, panel_center)
    np.maximum.at(spread_hi, panel_object, panel_center)
    axis = np.argmax(spread_hi - spread_lo, axis=1)[panel_object]
    keys = [panel_min_face] + [panel_center[:, k] for k in range(dim - 1, -1, -1)]
    along = panel_center[np.arange(panel_count), axis]
    panel_component = np.arange(panel_count, dtype=np.int64)
    if (partner_face >= 0).any():
        panel_component = _sewn_components(panel_of_face, partner_face)
        component_along = (np.bincount(panel_component, weights=along, minlength=panel_count)
                           / np.maximum(np.bincount(panel_component, minlength=panel_count), 1))
        keys += [along, panel_component]
        along = component_along[panel_component]
    panel_sequence = np.lexsort((*keys, along, panel_object))
    panel_rank = np.empty(panel_count, dtype=np.int64)
    panel_rank[panel_sequence] = np.arange(panel_count)
    face_panel = panel_rank[panel_of_face]
    face_order = np.argsort(face_panel, kind="stable")
    panel_begin = np.zeros(panel_count + 1, dtype=np.int64)
    np.cumsum(panel_size[panel_sequence], out=panel_begin[1:])

    # Object roots: one range of panels per object.
    sequence_object = panel_object[panel_sequence]
    first_panel = np.flatnonzero(np.append(True, sequence_object[1:] != sequence_object[:-1]))
    plo = first_panel.astype(np.int64)
    phi = np.append(first_panel[1:], panel_count).astype(np.int64)
    root_objects = object_values[sequence_object[first_panel]]
    is_rigid_object = np.isin(root_objects, np.fromiter(rigid, dtype=np.int64, count=len(rigid)))

    splitter = _HalfConnector(topology, m) if connect_halves else None
    seg = {"begin": panel_begin[plo], "end": panel_begin[phi], "plo": plo, "phi": phi,
           "rigid": is_rigid_object, "object": root_objects,
           "parent": np.full(plo.shape[0], -1, dtype=np.int64), "is_left": np.zeros(plo.shape[0], dtype=bool)}
    levels: list[dict[str, np.ndarray]] = []
    next_id = 0
    while seg["begin"].shape[0]:
        count = seg["begin"].shape[0]
        seg["id"] = np.arange(next_id, next_id + count, dtype=np.int64)
        next_id += count
        levels.append(seg)
        size = seg["end"] - seg["begin"]
        panels = seg["phi"] - seg["plo"]
        multi = (panels >= 2) & ~seg["rigid"]
        median = (panels == 1) & (size >= 2) & ~seg["rigid"]
        median_count = (size + 1) // 2
        if median.any():
            median_count[median] = _split_ranges(face_order, seg["begin"][median], seg["end"][median],
                                                          centroid, lower, upper)
            if splitter is not None:
                _connect_halves(face_order, seg["begin"], seg["end"], median, median_count, splitter)
        split = multi | median
        panel_mid = (seg["plo"] + seg["phi"]) // 2
        face_mid = np.where(multi, panel_begin[panel_mid], seg["begin"] + median_count)

        def pair(left: np.ndarray, right: np.ndarray, split: np.ndarray = split) -> np.ndarray:
            return np.stack([left[split], right[split]], axis=1).reshape(-1)

        seg = {"begin": pair(seg["begin"], face_mid), "end": pair(face_mid, seg["end"]),
               "plo": pair(seg["plo"], np.where(multi, panel_mid, seg["plo"])),
               "phi": pair(np.where(multi, panel_mid, seg["phi"]), seg["phi"]),
               "rigid": pair(seg["rigid"], seg["rigid"]), "object": pair(seg["object"], seg["object"]),
               "parent": pair(seg["id"], seg["id"]),
               "is_left": np.tile([True, False], int(split.sum()))}

    def gather(name: str) -> np.ndarray:
        return np.concatenate([level[name] for level in levels])

    node_count = next_id
    parent = gather("parent")
    is_left = gather("is_left")
    ids = np.arange(node_count, dtype=np.int64)
    left = np.full(node_count, -1, dtype=np.int64)
    right = np.full(node_count, -1, dtype=np.int64)
    child = parent >= 0
    left[parent[child & is_left]] = ids[child & is_left]
    right[parent[child & ~is_left]] = ids[child & ~is_left]
    begin, end = gather("begin"), gather("end")
    is_leaf = left < 0
    face_leaf = np.empty(m, dtype=np.int64)
    positions, which = _range_positions(begin[is_leaf], end[is_leaf])
    face_leaf[face_order[positions]] = ids[is_leaf][which]
    plo_all, phi_all = gather("plo"), gather("phi")
    # Sewn component of each node: its panels' one component (consecutive panels), else -1.
    sequence_component = panel_component[panel_sequence]
    first_component = sequence_component[plo_all]
    component = np.where(first_component == sequence_component[np.maximum(phi_all - 1, plo_all)],
                         first_component, -1)
    # One root per distinct object id, by ascending id (a table of max id + 1 rows would take 16 GiB
    # for an id of 2**31 - 1; ids need not be contiguous).
    root_order = np.argsort(levels[0]["object"], kind="stable")
    level_offsets = np.cumsum([0] + [level["id"].shape[0] for level in levels])
    return {
        "left": left, "right": right, "parent": parent,
        "depth": np.repeat(np.arange(len(levels)), np.diff(level_offsets)),
        "face_begin": begin, "face_end": end, "is_leaf": is_leaf, "is_rigid": gather("rigid"),
        "object_id": gather("object"), "panel": np.where(phi_all - plo_all == 1, plo_all, -1),
        "component": np.where(gather("rigid"), -1, component),
        "face_order": face_order, "face_leaf": face_leaf, "face_panel": face_panel,
        "level_offsets": level_offsets, "level_nodes": ids,
        "roots": levels[0]["id"][root_order], "object_values": levels[0]["object"][root_order],
    }


def _build_contours(faces: np.ndarray, material: np.ndarray, geometry: tuple[np.ndarray, ...],
                    topology: MeshTopology, host: dict[str, np.ndarray],
                    seams: tuple[np.ndarray, np.ndarray]) -> dict[str, np.ndarray]:
    """Contour loops, ``testable`` and ``reference_vertex`` of every node, one depth at a time.

    At one depth the nodes cover disjoint face ranges. A half-edge of face f is on the contour of
    f's node iff its edge has no other face, or its one other face lies in another node; edges with
    3+ faces make a node non-testable, so they need no counting. Loops are chained per depth by
    :func:`_chain_loops`; total work O(m log m) per depth.

    Sewn seams (``seams`` = :func:`_seam_matches`): a matched seam half-edge whose partner face is in
    the same node is interior, like a shared edge, and the two stitched ends of such a pair count as
    one vertex when the loop is chained (welded within that node only; the loop keeps each edge's
    own tail vertex). Those pairs are listed per node in ``seam_offsets`` / ``seam_vertices``
    (a1, a2, b1, b2: a1 welded to b1, a2 to b2) for the gap check of the node test.
    """
    partner_face, partner_corner = seams
    m = faces.shape[0]
    n = material.shape[0]
    node_count = host["left"].shape[0]
    face_order, begin, end = host["face_order"], host["face_begin"], host["face_end"]
    offsets = topology.edge_face_offsets.astype(np.int64)
    incident = topology.edge_face_indices.astype(np.int64)
    face_edges = topology.face_edges.astype(np.int64)
    degree = np.diff(offsets)[face_edges]
    first = incident[offsets[face_edges]]
    second = incident[np.minimum(offsets[face_edges] + 1, incident.shape[0] - 1)]
    other_face = np.where(degree == 2, first + second - np.arange(m)[:, None], -1)
    non_manifold = np.concatenate([[0], np.cumsum((degree >= 3).any(axis=1)[face_order])])
    centroid, _, _, area = geometry

    candidate = (~host["is_leaf"] & ~host["is_rigid"] & ((host["panel"] >= 0) | (host["component"] >= 0))
                 & (non_manifold[end] == non_manifold[begin]))
    seam_pieces: list[np.ndarray] = []
    contour_length = np.where(host["is_leaf"] & ~host["is_rigid"], 3, 0).astype(np.int64)
    reference_vertex = np.full(node_count, -1, dtype=np.int64)
    pieces: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []
    leaves = np.flatnonzero(host["is_leaf"] & ~host["is_rigid"])
    leaf_faces = faces[face_order[begin[leaves]]]
    pieces.append((np.repeat(leaves, 3), np.tile(np.arange(3), leaves.shape[0]), leaf_faces.reshape(-1)))

    node_of_face = np.full(m, -1, dtype=np.int64)
    level_offsets = host["level_offsets"]
    for d in range(level_offsets.shape[0] - 1):
        nodes = np.arange(level_offsets[d], level_offsets[d + 1])
        nodes = nodes[candidate[nodes]]
        if nodes.shape[0] == 0:
            continue
        positions, which = _range_positions(begin[nodes], end[nodes])
        level_faces = face_order[positions]
        face_node = nodes[which]
        node_of_face[level_faces] = face_node
        others = other_face[level_faces]
        on_contour = (others < 0) | (node_of_face[np.maximum(others, 0)] != face_node[:, None])
        sewn = partner_face[level_faces]
        interior_seam = (sewn >= 0) & (node_of_face[np.maximum(sewn, 0)] == face_node[:, None])
        node_of_face[level_faces] = -1
        on_contour &= ~interior_seam
        tails = faces[level_faces]
        heads = tails[:, [1, 2, 0]]
        half_node = np.broadcast_to(face_node[:, None], tails.shape)
        weld = _weld_in_nodes(faces, level_faces, face_node, interior_seam, seams, n)
        if weld is not None:
            seam_pieces.append(weld[2])
        chain_tail = _welded(weld, half_node[on_contour], tails[on_contour], n)
        chain_head = _welded(weld, half_node[on_contour], heads[on_contour], n)
        loop_node, rank, vertex = _chain_loops(half_node[on_contour], chain_tail, chain_head, n, node_count,
                                               tails[on_contour])
        if loop_node.shape[0] == 0:
            continue
        pieces.append((loop_node, rank, vertex))
        good = np.zeros(node_count, dtype=bool)
        good[loop_node] = True
        contour_length += np.bincount(loop_node, minlength=node_count)

        # Reference vertex: the interior vertex nearest the area-weighted centroid of the patch.
        keep = good[face_node]
        level_faces, face_node = level_faces[keep], face_node[keep]
        good_nodes = np.flatnonzero(good)
        starts = _segment_starts(end[good_nodes] - begin[good_nodes])
        weight = np.add.reduceat(area[level_faces], starts)
        weighted = np.add.reduceat(area[level_faces][:, None] * centroid[level_faces], starts, axis=0)
        plain = np.add.reduceat(centroid[level_faces], starts, axis=0) / (end - begin)[good_nodes][:, None]
        safe = np.where(weight > 0.0, weight, 1.0)[:, None]
        center = np.where(weight[:, None] > 0.0, weighted / safe, plain)
        slot = np.zeros(node_count, dtype=np.int64)
        slot[good_nodes] = np.arange(good_nodes.shape[0])
        corner_vertex = faces[level_faces].reshape(-1)
        corner_node = np.repeat(face_node, 3)
        contour_keys = np.sort(loop_node * n + _welded(weld, loop_node, vertex, n))
        corner_keys = corner_node * n + _welded(weld, corner_node, corner_vertex, n)
        found = contour_keys[np.minimum(np.searchsorted(contour_keys, corner_keys), contour_keys.shape[0] - 1)]
        interior = found != corner_keys
        corner_vertex, corner_node = corner_vertex[interior], corner_node[interior]
        distance = np.sum((material[corner_vertex] - center[slot[corner_node]]) ** 2, axis=1)
        if corner_node.shape[0]:
            # corner_node is non-decreasing: per node, the smallest distance, then the smallest vertex id.
            group = np.flatnonzero(np.append(True, corner_node[1:] != corner_node[:-1]))
            nearest = np.minimum.reduceat(distance, group)
            size = np.diff(np.append(group, corner_node.shape[0]))
            tied = distance == np.repeat(nearest, size)
            big = np.iinfo(np.int64).max
            reference_vertex[corner_node[group]] = np.minimum.reduceat(np.where(tied, corner_vertex, big), group)

    contour_offsets = np.zeros(node_count + 1, dtype=np.int64)
    np.cumsum(contour_length, out=contour_offsets[1:])
    contour_vertices = np.empty(int(contour_offsets[-1]), dtype=np.int64)
    for loop_node, rank, vertex in pieces:
        contour_vertices[contour_offsets[loop_node] + rank] = vertex
    seam_rows = np.concatenate(seam_pieces) if seam_pieces else np.zeros((0, 5), dtype=np.int64)
    seam_rows = seam_rows[np.argsort(seam_rows[:, 0], kind="stable")]
    seam_offsets = np.zeros(node_count + 1, dtype=np.int64)
    np.cumsum(np.bincount(seam_rows[:, 0], minlength=node_count), out=seam_offsets[1:])
    return {"testable": contour_length > 0, "reference_vertex": reference_vertex,
            "contour_offsets": contour_offsets, "contour_vertices": contour_vertices,
            "seam_offsets": seam_offsets, "seam_vertices": seam_rows[:, 1:].reshape(-1)}

