"""The normal cone test front (NCTF) of PSCC: which BVH nodes certify a self-collision-free patch.

The front is a cut of the material-space BVH (:class:`pscc.collision.bvh.MaterialBvh`): every face
has exactly one ancestor-or-self in it, and that node's id is the face's *node id*. A front node is
a leaf, a rigid object, or a node whose patch passed the normal-cone test (normal directions and
unprojected contour, :mod:`pscc.geometry.normal_cone`), so no two of its faces can collide: the
spatial hash never pairs faces with the same node id.

Every :meth:`NormalConeFront.update` call (temporal coherence: the front persists across calls):

1. **Refit** the direction masks and summed normals of every node, one launch per BVH level,
   deepest first (a swept mask over [t0, t1] for CCD, an instantaneous one for DCD).
2. **Shrink** every ``shrink_interval`` calls: a pair of sibling front nodes is replaced by their
   parent when the parent passes the test; repeated until nothing changes.
3. **Sprout** (PSCC Algorithms 1 and 2, level-synchronous): front nodes are tested in parallel;
   failing nodes are replaced by their children, which are tested in turn, until every node of the
   new front passes or is a leaf. Compaction uses exclusive scans, so the front's order is
   deterministic.
4. **Node ids**: the front sorted by ``face_begin``; one thread per face position binary-searches it.

========================  ====================  ===========================================
buffer                    shape, dtype          meaning
========================  ====================  ===========================================
node_mask                 (N,) mask (4 x u32)   directions that see every normal of the node
node_normal               (N,) vec3             summed (area-weighted) normals of the node
front                     (N,) int32            the front's node ids, ``front_size`` valid
node_id                   (m,) int32            front node of each face
in_front                  (N,) int32            1 for front nodes
scratch                   (N,) int32 x 6        frontier, flags and scan offsets
========================  ====================  ===========================================

The front never holds more than N nodes (the paper's bound is 2m + 1).
"""

from __future__ import annotations

import numpy as np
import warp as wp

from pscc import tolerances
from pscc.collision.bvh import MaterialBvh, MaterialBvhArrays
from pscc.errors import InputError
from pscc.geometry import normal_cone as nc

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


@wp.func
def _node_passes(args: NodeTestArgs, node: int) -> bool:
    """PSCC's node test: a leaf, a rigid node, or a patch certified by the normal-cone test."""
    bvh = args.bvh
    if bvh.is_leaf[node] == 1 or bvh.is_rigid[node] == 1:
        return True
    if bvh.testable[node] == 0:
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
    if reference >= 0:
        o0 = args.positions_t0[reference]
        o1 = args.positions_t1[reference]
    else:
        for i in range(begin, end):
            o0 += args.positions_t0[bvh.contour_vertices[i]]
            o1 += args.positions_t1[bvh.contour_vertices[i]]
        scale = 1.0 / float(wp.max(end - begin, 1))
        o0 = o0 * scale
        o1 = o1 * scale
    if args.swept == 1:
        return nc.contour_test_swept(bvh.contour_vertices, begin, end, args.positions_t0, args.positions_t1,
                                     o0, o1, l, args.margin)
    return nc.contour_test(bvh.contour_vertices, begin, end, args.positions_t0, o0, l, args.margin)


@wp.kernel
def _refit_level(
    # in:
    args: NodeTestArgs,
    first_node: int,
    # out:
    node_mask: wp.array(dtype=nc.mask_type),
    node_normal: wp.array(dtype=wp.vec3),
):
    """One thread per node of one BVH level (node ids of a level are contiguous)."""
    node = first_node + wp.tid()
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
def _test_frontier(
    # in:
    args: NodeTestArgs,
    frontier: wp.array(dtype=wp.int32),
    # out:
    keep: wp.array(dtype=wp.int32),
    split: wp.array(dtype=wp.int32),
):
    """One thread per frontier node: keep it (passes) or split it into its two children."""
    i = wp.tid()
    node = frontier[i]
    if _node_passes(args, node):
        keep[i] = 1
        split[i] = 0
    else:
        keep[i] = 0
        split[i] = 2


@wp.kernel
def _scatter_frontier(
    # in:
    bvh: MaterialBvhArrays,
    frontier: wp.array(dtype=wp.int32),
    keep: wp.array(dtype=wp.int32),
    keep_offsets: wp.array(dtype=wp.int32),
    split_offsets: wp.array(dtype=wp.int32),
    front_base: int,
    # out:
    front_out: wp.array(dtype=wp.int32),
    frontier_out: wp.array(dtype=wp.int32),
):
    """One thread per frontier node: append it to the front, or its children to the next frontier."""
    i = wp.tid()
    node = frontier[i]
    if keep[i] == 1:
        front_out[front_base + keep_offsets[i]] = node
    else:
        slot = split_offsets[i]
        frontier_out[slot] = bvh.left[node]
        frontier_out[slot + 1] = bvh.right[node]


@wp.kernel
def _mark_front(front: wp.array(dtype=wp.int32), in_front: wp.array(dtype=wp.int32)):
    """One thread per front node."""
    in_front[front[wp.tid()]] = 1


@wp.kernel
def _shrink_pairs(
    # in:
    args: NodeTestArgs,
    front: wp.array(dtype=wp.int32),
    # out:
    in_front: wp.array(dtype=wp.int32),
    lifted: wp.array(dtype=wp.int32),
):
    """One thread per front node: a left child whose sibling is also in the front lifts both to
    their parent when the parent passes the test."""
    node = front[wp.tid()]
    bvh = args.bvh
    parent = bvh.parent[node]
    if parent < 0 or bvh.left[parent] != node:
        return
    sibling = bvh.right[parent]
    if in_front[sibling] == 0:
        return
    if _node_passes(args, parent):
        in_front[node] = 0
        in_front[sibling] = 0
        in_front[parent] = 1
        lifted[0] = 1


@wp.kernel
def _compact_flags(
    # in:
    in_front: wp.array(dtype=wp.int32),
    offsets: wp.array(dtype=wp.int32),
    # out:
    front_out: wp.array(dtype=wp.int32),
):
    """One thread per BVH node: write front nodes in node order."""
    node = wp.tid()
    if in_front[node] == 1:
        front_out[offsets[node]] = node


@wp.kernel
def _front_begins(bvh: MaterialBvhArrays, front: wp.array(dtype=wp.int32), keys_out: wp.array(dtype=wp.int32),
                  values_out: wp.array(dtype=wp.int32)):
    """One thread per front node: sort key = the node's first face position."""
    i = wp.tid()
    keys_out[i] = bvh.face_begin[front[i]]
    values_out[i] = front[i]


@wp.kernel
def _assign_node_ids(
    # in:
    bvh: MaterialBvhArrays,
    sorted_begins: wp.array(dtype=wp.int32),
    sorted_nodes: wp.array(dtype=wp.int32),
    front_size: int,
    # out:
    node_id_out: wp.array(dtype=wp.int32),
):
    """One thread per face position: the last front node starting at or before it owns it."""
    k = wp.tid()
    lo = int(0)
    hi = front_size - 1
    while lo < hi:
        mid = (lo + hi + 1) // 2
        if sorted_begins[mid] <= k:
            lo = mid
        else:
            hi = mid - 1
    node_id_out[bvh.face_order[k]] = sorted_nodes[lo]


class NormalConeFront:
    """PSCC's normal cone test front, persistent across calls (layout in the module docstring).

    Args:
        bvh: the material-space BVH of the mesh.
        faces: (face_count,) ``wp.vec3i`` device faces.
        device: Warp device.
        shrink_interval: run the shrinking operator every this many :meth:`update` calls (>= 1).
    """

    def __init__(self, bvh: MaterialBvh, faces: wp.array, device: wp.Device, shrink_interval: int = 5) -> None:
        self.bvh = bvh
        self.device = device
        self.shrink_interval = max(1, int(shrink_interval))
        self.calls = 0
        n = bvh.node_count
        self.node_mask = wp.zeros(n, dtype=nc.mask_type, device=device)
        self.node_normal = wp.zeros(n, dtype=wp.vec3, device=device)
        self.front = wp.zeros(n, dtype=wp.int32, device=device)
        self._front_next = wp.zeros(n, dtype=wp.int32, device=device)
        # A frontier never holds more nodes than the tree has.
        self._frontier = wp.zeros(n, dtype=wp.int32, device=device)
        self._frontier_next = wp.zeros(n, dtype=wp.int32, device=device)
        self._keep = wp.zeros(n + 1, dtype=wp.int32, device=device)
        self._split = wp.zeros(n + 1, dtype=wp.int32, device=device)
        self._keep_offsets = wp.zeros(n + 1, dtype=wp.int32, device=device)
        self._split_offsets = wp.zeros(n + 1, dtype=wp.int32, device=device)
        # The front is a cut, so it holds at most one node per leaf; radix sort needs twice that.
        leaves = int(np.count_nonzero(bvh.is_leaf))
        self._sort_keys = wp.zeros(2 * leaves, dtype=wp.int32, device=device)
        self._sort_values = wp.zeros(2 * leaves, dtype=wp.int32, device=device)
        self.in_front = wp.zeros(n + 1, dtype=wp.int32, device=device)
        self._lifted = wp.zeros(1, dtype=wp.int32, device=device)
        self.node_id = wp.zeros(bvh.face_count, dtype=wp.int32, device=device)
        self.directions = wp.array(nc.sample_directions(), dtype=wp.vec3, device=device)
        table = nc.direction_mask_table(nc.TABLE_RESOLUTION, tolerances.NORMAL_CONE_MARGIN)
        self.direction_table = wp.array(table, dtype=nc.mask_type, device=device)
        roots = np.asarray(bvh.roots, dtype=np.int32)
        self.front.assign(np.concatenate([roots, np.zeros(n - len(roots), np.int32)]))
        self.front_size = int(len(roots))
        self._refit_key: tuple | None = None
        self._refit_launches: list = []
        self.args = NodeTestArgs()
        self.args.bvh = bvh.arrays
        self.args.faces = faces
        self.args.directions = self.directions
        self.args.direction_table = self.direction_table
        self.args.table_resolution = nc.TABLE_RESOLUTION
        self.args.node_mask = self.node_mask
        self.args.node_normal = self.node_normal
        self.args.margin = tolerances.NORMAL_CONE_MARGIN
        self.args.degenerate_ratio = tolerances.DEGENERATE_FACE_RATIO
        self.stats: dict[str, int] = {}

    @property
    def device_bytes(self) -> int:
        """Bytes held on the device by the front's buffers (the BVH is counted separately)."""
        arrays = (self.node_mask, self.node_normal, self.front, self._front_next, self._frontier,
                  self._frontier_next, self._keep, self._split, self._keep_offsets, self._split_offsets,
                  self._sort_keys, self._sort_values, self.in_front, self._lifted, self.node_id, self.directions,
                  self.direction_table)
        return sum(a.capacity for a in arrays)

    def state_dict(self) -> dict[str, np.ndarray]:
        """What the front carries from call to call (its nodes and the call counter), as host arrays.

        Everything else is recomputed by :meth:`update`, so restoring this into a front over the
        same BVH makes later calls return exactly what the original front would (checkpoints).
        Allocates: yes (host copies). Capture-safe: no.
        """
        return {"front": self.front.numpy()[: self.front_size].copy(),
                "calls": np.array([self.calls], dtype=np.int64)}

    def load_state_dict(self, state: dict[str, np.ndarray]) -> None:
        """Restore :meth:`state_dict` output (from a front over the same BVH).

        Raises:
            InputError: node ids outside this BVH or more nodes than it can hold.
        Allocates: no. Capture-safe: no.
        """
        nodes = np.asarray(state["front"], dtype=np.int32).reshape(-1)
        n = self.bvh.node_count
        if nodes.size == 0 or nodes.size > n or nodes.min() < 0 or nodes.max() >= n:
            raise InputError("checkpoint", "front", f"{nodes.size} node ids do not fit a BVH of {n} nodes",
                             "restore a checkpoint of the same scene")
        self.front.assign(np.concatenate([nodes, np.zeros(n - nodes.size, np.int32)]))
        self.front_size = int(nodes.size)
        self.calls = int(np.asarray(state["calls"]).reshape(-1)[0])

    def update(self, positions_t0: wp.array, positions_t1: wp.array | None = None) -> wp.array:
        """Refit, shrink (every ``shrink_interval`` calls), sprout, and assign node ids.

        Args:
            positions_t0: (vertex_count,) vec3 positions (DCD), or the start of the step (CCD).
            positions_t1: end of the step for CCD (the certificate then holds over the whole step).

        Returns:
            ``node_id``: (face_count,) int32 front node of each face.

        Reads counts to the host once per sprouting level (sync points). Allocates: no.
        """
        args = self.args
        args.positions_t0 = positions_t0
        args.positions_t1 = positions_t1 if positions_t1 is not None else positions_t0
        args.swept = 1 if positions_t1 is not None else 0
        self._refit()
        self.calls += 1
        shrink_rounds = 0
        if self.calls % self.shrink_interval == 0:
            shrink_rounds = self._shrink()
        tested, levels = self._sprout()
        self._assign_node_ids()
        self.stats = {"front_size": self.front_size, "front_nodes_tested": tested, "sprout_levels": levels,
                      "shrink_rounds": shrink_rounds}
        return self.node_id

    def _refit(self) -> None:
        """One launch per BVH level, bottom-up. The launches are recorded once per set of position
        arrays (the arguments are the same every call while those arrays are), which saves their
        argument packing on every call."""
        args = self.args
        key = (args.positions_t0.ptr, args.positions_t1.ptr, args.swept)
        if key != self._refit_key:
            offsets = self.bvh.level_offsets
            self._refit_launches = []
            for depth in range(len(offsets) - 2, -1, -1):
                first, last = int(offsets[depth]), int(offsets[depth + 1])
                if last > first:
                    self._refit_launches.append(
                        wp.launch(_refit_level, dim=last - first, inputs=[args, first],
                                  outputs=[self.node_mask, self.node_normal], device=self.device, record_cmd=True))
            self._refit_key = key
        for launch in self._refit_launches:
            launch.launch()

    def _sprout(self) -> tuple[int, int]:
        frontier, frontier_next = self._frontier, self._frontier_next
        wp.copy(frontier, self.front, count=self.front_size)
        count = self.front_size
        front_size = 0
        tested = 0
        levels = 0
        while count > 0:
            tested += count
            levels += 1
            wp.launch(_test_frontier, dim=count, inputs=[self.args, frontier],
                      outputs=[self._keep, self._split], device=self.device)
            self._keep[count : count + 1].zero_()
            self._split[count : count + 1].zero_()
            wp.utils.array_scan(self._keep[: count + 1], self._keep_offsets[: count + 1], inclusive=False)
            wp.utils.array_scan(self._split[: count + 1], self._split_offsets[: count + 1], inclusive=False)
            kept = int(self._keep_offsets[count : count + 1].numpy()[0])
            children = int(self._split_offsets[count : count + 1].numpy()[0])
            wp.launch(_scatter_frontier, dim=count,
                      inputs=[self.bvh.arrays, frontier, self._keep, self._keep_offsets, self._split_offsets,
                              front_size],
                      outputs=[self._front_next, frontier_next], device=self.device)
            front_size += kept
            count = children
            frontier, frontier_next = frontier_next, frontier
        self.front, self._front_next = self._front_next, self.front
        self.front_size = front_size
        return tested, levels

    def _shrink(self) -> int:
        n = self.bvh.node_count
        rounds = 0
        while True:
            self.in_front.zero_()
            wp.launch(_mark_front, dim=self.front_size, inputs=[self.front, self.in_front], device=self.device)
            self._lifted.zero_()
            wp.launch(_shrink_pairs, dim=self.front_size, inputs=[self.args, self.front],
                      outputs=[self.in_front, self._lifted], device=self.device)
            if int(self._lifted.numpy()[0]) == 0:
                return rounds
            rounds += 1
            wp.utils.array_scan(self.in_front[: n + 1], self._keep_offsets[: n + 1], inclusive=False)
            self.front_size = int(self._keep_offsets[n : n + 1].numpy()[0])
            wp.launch(_compact_flags, dim=n, inputs=[self.in_front, self._keep_offsets], outputs=[self.front],
                      device=self.device)

    def _assign_node_ids(self) -> None:
        size = self.front_size
        wp.launch(_front_begins, dim=size, inputs=[self.bvh.arrays, self.front],
                  outputs=[self._sort_keys, self._sort_values], device=self.device)
        wp.utils.radix_sort_pairs(self._sort_keys, self._sort_values, size)
        wp.launch(_assign_node_ids, dim=self.bvh.face_count,
                  inputs=[self.bvh.arrays, self._sort_keys, self._sort_values, size],
                  outputs=[self.node_id], device=self.device)
