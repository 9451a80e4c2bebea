"""Kernels of :class:`pscc.collision.front.NormalConeFront` (its only user): the node test, the refit,
shrinking, sprouting and the node ids. The buffers and the algorithm are in that module's docstring.
"""

from __future__ import annotations

import warp as wp

from pscc.collision.bvh import MaterialBvhArrays
from pscc.geometry import normal_cone as nc
from pscc.geometry import simple_contour as sc

wp.set_module_options({"enable_backward": False})


@wp.struct
class NodeTestArgs:
    """Everything the node test reads, bundled for the kernels."""

    bvh: MaterialBvhArrays
    faces: wp.array(dtype=wp.vec3i)
    positions_t0: wp.array(dtype=wp.vec3)
    positions_t1: wp.array(dtype=wp.vec3)
    directions: wp.array(dtype=wp.vec3)
    direction_table: wp.array(dtype=nc.mask_type)
    table_resolution: wp.int32
    node_mask: wp.array(dtype=nc.mask_type)
    node_normal: wp.array(dtype=wp.vec3)
    swept: wp.int32
    margin: wp.float32
    degenerate_ratio: wp.float32
    seam_gap_ratio: wp.float32
    simple_contour_max_edges: wp.int32


@wp.func
def _seam_pair_closed(x: wp.array(dtype=wp.vec3), a1: int, a2: int, b1: int, b2: int, ratio: float) -> bool:
    """Whether a sewn seam edge pair (a1 a2 on one side, b1 b2 welded to them) is closed: both stitch
    gaps are at most ``ratio`` times the shorter of the two seam edges."""
    gap = wp.max(wp.length(x[a1] - x[b1]), wp.length(x[a2] - x[b2]))
    return gap <= ratio * wp.min(wp.length(x[a2] - x[a1]), wp.length(x[b2] - x[b1]))


@wp.func
def _seams_closed(args: NodeTestArgs, node: int) -> bool:
    """Whether every sewn seam edge pair that is interior to ``node`` is closed, at t0 (and t1 when
    swept; a gap is convex in t, so it stays below the larger end value in between)."""
    bvh = args.bvh
    for s in range(bvh.seam_offsets[node], bvh.seam_offsets[node + 1]):
        a1 = bvh.seam_vertices[4 * s]
        a2 = bvh.seam_vertices[4 * s + 1]
        b1 = bvh.seam_vertices[4 * s + 2]
        b2 = bvh.seam_vertices[4 * s + 3]
        if not _seam_pair_closed(args.positions_t0, a1, a2, b1, b2, args.seam_gap_ratio):
            return False
        if args.swept == 1:
            if not _seam_pair_closed(args.positions_t1, a1, a2, b1, b2, args.seam_gap_ratio):
                return False
    return True


@wp.func
def _node_passes(args: NodeTestArgs, node: int) -> bool:
    """PSCC's node test: a leaf, a rigid node, or a patch certified by the normal-cone test."""
    bvh = args.bvh
    if bvh.is_leaf[node] == 1 or bvh.is_rigid[node] == 1:
        return True
    if bvh.testable[node] == 0:
        return False
    if not _seams_closed(args, node):
        return False
    m = args.node_mask[node]
    if nc.mask_is_empty(m):
        return False
    axis = nc.pick_axis(m, args.node_normal[node], args.directions)
    l = args.directions[axis]
    begin = bvh.contour_offsets[node]
    end = bvh.contour_offsets[node + 1]
    reference = bvh.reference_vertex[node]
    o0 = wp.vec3(0.0, 0.0, 0.0)
    o1 = wp.vec3(0.0, 0.0, 0.0)
    reference_face = bvh.reference_face[node]
    if reference >= 0:
        o0 = args.positions_t0[reference]
        o1 = args.positions_t1[reference]
    elif reference_face >= 0:
        # The centroid of a face chosen at build time (pscc.collision.reference_points).
        f = args.faces[reference_face]
        o0 = (args.positions_t0[f[0]] + args.positions_t0[f[1]] + args.positions_t0[f[2]]) / 3.0
        o1 = (args.positions_t1[f[0]] + args.positions_t1[f[1]] + args.positions_t1[f[2]]) / 3.0
    else:
        for i in range(begin, end):
            o0 += args.positions_t0[bvh.contour_vertices[i]]
            o1 += args.positions_t1[bvh.contour_vertices[i]]
        scale = 1.0 / float(wp.max(end - begin, 1))
        o0 = o0 * scale
        o1 = o1 * scale
    star = bool(False)
    if args.swept == 1:
        star = nc.contour_test_swept(bvh.contour_vertices, begin, end, args.positions_t0, args.positions_t1,
                                     o0, o1, l, args.margin)
    else:
        star = nc.contour_test(bvh.contour_vertices, begin, end, args.positions_t0, o0, l, args.margin)
    if star or end - begin > args.simple_contour_max_edges:
        return star
    # No point sees the loop turn one way: check that it is simple, edge pair by edge pair.
    return sc.contour_is_simple(bvh.contour_vertices, begin, end, args.positions_t0, args.positions_t1, l,
                                args.margin, args.swept)


@wp.func
def _refit_node(
    args: NodeTestArgs,
    node: int,
    node_mask: wp.array(dtype=nc.mask_type),
    node_normal: wp.array(dtype=wp.vec3),
):
    """A leaf's direction mask and normal from its face; an inner node's from its children (refitted)."""
    bvh = args.bvh
    empty = nc.mask_type(wp.uint32(0), wp.uint32(0), wp.uint32(0), wp.uint32(0))
    if bvh.is_rigid[node] == 1:
        node_mask[node] = empty
        node_normal[node] = wp.vec3(0.0, 0.0, 0.0)
        return
    if bvh.is_leaf[node] == 1:
        f = args.faces[bvh.face_order[bvh.face_begin[node]]]
        a0 = args.positions_t0[f[0]]
        b0 = args.positions_t0[f[1]]
        c0 = args.positions_t0[f[2]]
        n = wp.cross(b0 - a0, c0 - a0)
        if args.swept == 1:
            a1 = args.positions_t1[f[0]]
            b1 = args.positions_t1[f[1]]
            c1 = args.positions_t1[f[2]]
            n = n + wp.cross(b1 - a1, c1 - a1)
            node_mask[node] = nc.face_mask_swept_fast(a0, b0, c0, a1, b1, c1, args.direction_table,
                                                      args.table_resolution, args.directions, args.margin,
                                                      args.degenerate_ratio)
        else:
            node_mask[node] = nc.face_mask_fast(a0, b0, c0, args.direction_table, args.table_resolution,
                                                args.degenerate_ratio)
        node_normal[node] = n
        return
    left = bvh.left[node]
    right = bvh.right[node]
    node_mask[node] = nc.mask_and(node_mask[left], node_mask[right])
    node_normal[node] = node_normal[left] + node_normal[right]


@wp.kernel
def _refit_level(
    # in:
    args: NodeTestArgs,
    first_node: int,
    # out:
    node_mask: wp.array(dtype=nc.mask_type),
    node_normal: wp.array(dtype=wp.vec3),
):
    """One thread per node of one BVH level (node ids of a level are contiguous). GPU launch shape."""
    _refit_node(args, first_node + wp.tid(), node_mask, node_normal)


@wp.kernel
def _refit_all_in_order(
    # in:
    args: NodeTestArgs,
    node_count: int,
    # out:
    node_mask: wp.array(dtype=nc.mask_type),
    node_normal: wp.array(dtype=wp.vec3),
):
    """One thread refits every node, deepest level first (node ids grow with depth, so descending ids
    reach both children before their parent). CPU launch shape: the CPU runs a launch's threads one after
    another anyway, and one launch instead of one per level saves their fixed cost (:mod:`pscc._lanes`)."""
    for k in range(node_count):
        _refit_node(args, node_count - 1 - k, node_mask, node_normal)


@wp.kernel
def _begin_update(
    # in:
    shrink_interval: wp.int64,
    # out:
    calls: wp.array(dtype=wp.int64),
    counters: wp.array(dtype=wp.int32),
    shrink_go: wp.array(dtype=wp.int32),
):
    """One thread: count the call, clear the per-call counters, and decide whether to shrink."""
    c = calls[0] + wp.int64(1)
    calls[0] = c
    for k in range(4):
        counters[k] = 0
    shrink_go[0] = 0
    if c % shrink_interval == wp.int64(0):
        shrink_go[0] = 1


@wp.kernel
def _clear_flags(
    # out:
    in_front: wp.array(dtype=wp.int32),
    marked: wp.array(dtype=wp.int32),
):
    """One thread per BVH node (N + 1 flags)."""
    i = wp.tid()
    in_front[i] = 0
    marked[i] = 0


@wp.kernel
def _mark_front(
    # in:
    front: wp.array(dtype=wp.int32),
    front_count: wp.array(dtype=wp.int32),
    # out:
    in_front: wp.array(dtype=wp.int32),
    marked: wp.array(dtype=wp.int32),
    lifted: wp.array(dtype=wp.int32),
):
    """One thread per front slot (capacity N): flag the front's nodes (``marked`` keeps the flags
    of the round's start, ``in_front`` is updated by the lifts); thread 0 clears ``lifted``."""
    i = wp.tid()
    if i == 0:
        lifted[0] = 0
    if i < front_count[0]:
        in_front[front[i]] = 1
        marked[front[i]] = 1


@wp.kernel
def _shrink_pairs(
    # in:
    args: NodeTestArgs,
    front: wp.array(dtype=wp.int32),
    front_count: wp.array(dtype=wp.int32),
    marked: wp.array(dtype=wp.int32),
    # out:
    in_front: wp.array(dtype=wp.int32),
    lifted: wp.array(dtype=wp.int32),
):
    """One thread per front slot (capacity N): a left child whose sibling is also in the front
    lifts both to their parent when the parent passes the test.

    The sibling is looked up in ``marked`` (the front at the round's start), not in ``in_front``:
    a parent lifted to in this round is not yet a front node for its own sibling, so threads never
    depend on each other (they write disjoint flags) and every device gives the same front. This
    is also what a sequential pass in front order gives, as the front always lists a node before
    the children of its sibling (roots, node order after a shrink, and sprouting keep that).
    """
    i = wp.tid()
    if i >= front_count[0]:
        return
    node = front[i]
    bvh = args.bvh
    parent = bvh.parent[node]
    if parent < 0:
        return
    if bvh.left[parent] != node:
        return
    sibling = bvh.right[parent]
    if marked[sibling] == 0:
        return
    if _node_passes(args, parent):
        in_front[node] = 0
        in_front[sibling] = 0
        in_front[parent] = 1
        lifted[0] = 1


@wp.kernel
def _finish_shrink_round(
    # in:
    lifted: wp.array(dtype=wp.int32),
    offsets: wp.array(dtype=wp.int32),
    node_count: int,
    # out:
    front_count: wp.array(dtype=wp.int32),
    counters: wp.array(dtype=wp.int32),
):
    """One thread: after a round that lifted a pair, the front's new size and one more round."""
    if lifted[0] != 0:
        front_count[0] = offsets[node_count]
        counters[2] = counters[2] + 1


@wp.kernel
def _compact_flags(
    # in:
    in_front: wp.array(dtype=wp.int32),
    offsets: wp.array(dtype=wp.int32),
    lifted: wp.array(dtype=wp.int32),
    # out:
    front_out: wp.array(dtype=wp.int32),
):
    """One thread per BVH node: write front nodes in node order (only after a round that lifted)."""
    node = wp.tid()
    if lifted[0] == 0:
        return
    if in_front[node] == 1:
        front_out[offsets[node]] = node


@wp.kernel
def _start_sprout(
    # in:
    front: wp.array(dtype=wp.int32),
    front_count: wp.array(dtype=wp.int32),
    # out:
    frontier: wp.array(dtype=wp.int32),
    frontier_count: wp.array(dtype=wp.int32),
    counters: wp.array(dtype=wp.int32),
):
    """One thread per front slot (capacity N): the first frontier is the whole front."""
    i = wp.tid()
    count = front_count[0]
    if i == 0:
        frontier_count[0] = count
        counters[3] = 0
    if i < count:
        frontier[i] = front[i]


@wp.kernel
def _test_frontier(
    # in:
    args: NodeTestArgs,
    frontier: wp.array(dtype=wp.int32),
    frontier_count: wp.array(dtype=wp.int32),
    lanes: int,
    # out:
    keep: wp.array(dtype=wp.int32),
    split: wp.array(dtype=wp.int32),
):
    """Row kernel (:mod:`pscc._lanes`) over the frontier slots (capacity N + 1): keep the node (passes) or
    split it into its two children; slots past the frontier get 0, so the scans' last entries are the
    totals. (On the CPU one thread walks the slots: a thread per slot copied the node-test arguments, a
    struct of 27 arrays, for each of the N + 1 slots.)"""
    count = frontier_count[0]
    for i in range(wp.tid(), keep.shape[0], lanes):
        keep[i] = 0
        split[i] = 0
        if i < count:
            if _node_passes(args, frontier[i]):
                keep[i] = 1
            else:
                split[i] = 2


@wp.kernel
def _scatter_frontier(
    # in:
    bvh: MaterialBvhArrays,
    frontier: wp.array(dtype=wp.int32),
    frontier_count: wp.array(dtype=wp.int32),
    keep: wp.array(dtype=wp.int32),
    keep_offsets: wp.array(dtype=wp.int32),
    split_offsets: wp.array(dtype=wp.int32),
    counters: wp.array(dtype=wp.int32),
    # out:
    front_out: wp.array(dtype=wp.int32),
    frontier_out: wp.array(dtype=wp.int32),
):
    """One thread per frontier slot (capacity N): append the node to the new front (after the
    ``counters[3]`` nodes already there), or its children to the next frontier."""
    i = wp.tid()
    if i >= frontier_count[0]:
        return
    node = frontier[i]
    if keep[i] == 1:
        front_out[counters[3] + keep_offsets[i]] = node
    else:
        slot = split_offsets[i]
        frontier_out[slot] = bvh.left[node]
        frontier_out[slot + 1] = bvh.right[node]


@wp.kernel
def _advance_sprout(
    # in:
    keep_offsets: wp.array(dtype=wp.int32),
    split_offsets: wp.array(dtype=wp.int32),
    node_count: int,
    # out:
    frontier_count: wp.array(dtype=wp.int32),
    counters: wp.array(dtype=wp.int32),
):
    """One thread: account for the level just tested; the next frontier's size ends the loop at 0."""
    counters[0] = counters[0] + frontier_count[0]
    counters[1] = counters[1] + 1
    counters[3] = counters[3] + keep_offsets[node_count]
    frontier_count[0] = split_offsets[node_count]


@wp.kernel
def _copy_nodes(
    # in:
    source: wp.array(dtype=wp.int32),
    count: wp.array(dtype=wp.int32),
    # out:
    target: wp.array(dtype=wp.int32),
):
    """One thread per slot (capacity N): copy the first ``count[0]`` node ids."""
    i = wp.tid()
    if i < count[0]:
        target[i] = source[i]


@wp.kernel
def _finish_sprout(
    # in:
    front_next: wp.array(dtype=wp.int32),
    counters: wp.array(dtype=wp.int32),
    # out:
    front: wp.array(dtype=wp.int32),
    front_count: wp.array(dtype=wp.int32),
):
    """One thread per front slot (capacity N): the new front replaces the old one."""
    i = wp.tid()
    count = counters[3]
    if i == 0:
        front_count[0] = count
    if i < count:
        front[i] = front_next[i]


@wp.kernel
def _clear_range_marks(
    # out:
    marks: wp.array(dtype=wp.int32),
):
    """One thread per face position (and the one past the end): zero."""
    marks[wp.tid()] = 0


@wp.kernel
def _mark_front_ranges(
    # in:
    bvh: MaterialBvhArrays,
    front: wp.array(dtype=wp.int32),
    front_count: wp.array(dtype=wp.int32),
    # out:
    marks: wp.array(dtype=wp.int32),
):
    """One thread per front slot (capacity N): a front node adds node + 1 at its first face position and
    subtracts it at the position past its last. The front's face ranges partition the leaf order, so
    the inclusive prefix sum at a face position is exactly (its node) + 1."""
    i = wp.tid()
    if i < front_count[0]:
        node = front[i]
        wp.atomic_add(marks, bvh.face_begin[node], node + 1)
        wp.atomic_add(marks, bvh.face_end[node], -(node + 1))


@wp.kernel
def _assign_node_ids(
    # in:
    bvh: MaterialBvhArrays,
    range_owner: wp.array(dtype=wp.int32),
    # out:
    node_id_out: wp.array(dtype=wp.int32),
):
    """One thread per face position k: the front node owning it (the prefix sum of the range marks, less 1)."""
    k = wp.tid()
    node_id_out[bvh.face_order[k]] = range_owner[k] - 1
