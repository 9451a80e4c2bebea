"""The normal cone test front (NCTF) of PSCC: which BVH nodes certify a self-collision-free patch.

The front is a cut of the material-space BVH (:class:`pscc.collision.bvh.MaterialBvh`): every face
has exactly one ancestor-or-self in it, and that node's id is the face's *node id*. A front node is
a leaf, a rigid object, or a node whose patch passed the normal-cone test (normal directions and
unprojected contour, :mod:`pscc.geometry.normal_cone`), so no two of its faces can collide: the
spatial hash never pairs faces with the same node id.

Every :meth:`NormalConeFront.update` call (temporal coherence: the front persists across calls):

1. **Refit** the direction masks and summed normals of every node, one launch per BVH level,
   deepest first (a swept mask over [t0, t1] for CCD, an instantaneous one for DCD).
2. **Shrink** every ``shrink_interval`` calls (the call counter lives on the device): a pair of
   sibling front nodes is replaced by their parent when the parent passes the test; repeated
   until nothing changes.
3. **Sprout** (PSCC Algorithms 1 and 2, level-synchronous): front nodes are tested in parallel;
   failing nodes are replaced by their children, which are tested in turn, until every node of the
   new front passes or is a leaf. Compaction uses exclusive scans, so the front's order is
   deterministic.
4. **Node ids**: the front sorted by ``face_begin``; one thread per face position binary-searches it.

The call stays on the device: sizes live in (1,) device arrays, every kernel is launched at
capacity (N threads, each returning early past the device count), and the shrink and sprout loops
are ``wp.capture_while`` loops on device flags, so :meth:`NormalConeFront.update` can be recorded
into a graph (on the CPU too) and replayed; a replay advances the call counter like a call.

========================  ====================  ===========================================
buffer                    shape, dtype          meaning
========================  ====================  ===========================================
node_mask                 (N,) mask (4 x u32)   directions that see every normal of the node
node_normal               (N,) vec3             summed (area-weighted) normals of the node
front                     (N,) int32            the front's node ids, ``front_count[0]`` valid
front_count               (1,) int32            number of front nodes
calls                     (1,) int64            ``update`` calls so far (drives the shrink)
node_id                   (m,) int32            front node of each face
in_front, marked          (N + 1,) int32 x 2    1 for front nodes during / at the start of a
                                                shrink round
counters                  (4,) int32            last call: nodes tested, sprout levels, shrink
                                                rounds, new front size while sprouting
scratch                   (N,) / (N + 1,) int32 frontiers, flags, scan offsets; (2N,) sort
                                                keys and values
========================  ====================  ===========================================

The front never holds more than N nodes (the paper's bound is 2m + 1), nor does a frontier (its
nodes are distinct), so no buffer of the front can overflow.
"""

from __future__ import annotations

from typing import Any

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
    # out:
    keep: wp.array(dtype=wp.int32),
    split: wp.array(dtype=wp.int32),
):
    """One thread per frontier slot (capacity N + 1): keep the node (passes) or split it into its
    two children; slots past the frontier get 0, so the scans' last entries are the totals."""
    i = wp.tid()
    keep[i] = 0
    split[i] = 0
    if i >= frontier_count[0]:
        return
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
def _write_sort_keys(
    # in:
    bvh: MaterialBvhArrays,
    front: wp.array(dtype=wp.int32),
    front_count: wp.array(dtype=wp.int32),
    pad_key: int,
    # out:
    keys_out: wp.array(dtype=wp.int32),
    values_out: wp.array(dtype=wp.int32),
):
    """One thread per front slot (capacity N): sort key = the node's first face position; slots past
    the front get ``pad_key`` (larger than every face position), so they sort last."""
    i = wp.tid()
    if i < front_count[0]:
        node = front[i]
        keys_out[i] = bvh.face_begin[node]
        values_out[i] = node
    else:
        keys_out[i] = pad_key
        values_out[i] = -1


@wp.kernel
def _assign_node_ids(
    # in:
    bvh: MaterialBvhArrays,
    sorted_begins: wp.array(dtype=wp.int32),
    sorted_nodes: wp.array(dtype=wp.int32),
    front_count: wp.array(dtype=wp.int32),
    # out:
    node_id_out: wp.array(dtype=wp.int32),
):
    """One thread per face position: the last front node starting at or before it owns it."""
    k = wp.tid()
    lo = int(0)
    hi = front_count[0] - 1
    while lo < hi:
        mid = (lo + hi + 1) // 2
        if sorted_begins[mid] <= k:
            lo = mid
        else:
            hi = mid - 1
    node_id_out[bvh.face_order[k]] = sorted_nodes[lo]


class NormalConeFront:
    """PSCC's normal cone test front, persistent across calls (layout in the module docstring).

    :meth:`update` is the device path: no host read, no synchronisation, no allocation and no
    upload, so it can be recorded with ``wp.ScopedCapture`` and replayed (each replay is one call,
    shrinking included). The front cannot overflow, so there is no capacity check to run.

    Sync points (they read device data to the host): :attr:`front_size`, :attr:`stats`,
    :attr:`call_count` and :meth:`state_dict`. Callers that stay on the device read
    :attr:`front_count` ((1,) int32), :attr:`front` and :attr:`node_id` directly.

    Args:
        bvh: the material-space BVH of the mesh.
        faces: (face_count,) ``wp.vec3i`` device faces.
        device: Warp device.
        shrink_interval: run the shrinking operator every this many :meth:`update` calls (>= 1).
    """

    def __init__(self, bvh: MaterialBvh, faces: wp.array, device: wp.Device, shrink_interval: int = 5) -> None:
        """Allocate every buffer at capacity (N = ``bvh.node_count``); the front starts at the roots.

        Allocates: yes. Capture-safe: no.
        """
        self.bvh = bvh
        self.device = wp.get_device(device)
        device = self.device
        self.shrink_interval = max(1, int(shrink_interval))
        n = bvh.node_count
        self.node_mask = wp.zeros(n, dtype=nc.mask_type, device=device)
        self.node_normal = wp.zeros(n, dtype=wp.vec3, device=device)
        self.front = wp.zeros(n, dtype=wp.int32, device=device)
        self.front_count = wp.zeros(1, dtype=wp.int32, device=device)
        self.calls = wp.zeros(1, dtype=wp.int64, device=device)
        self._front_next = wp.zeros(n, dtype=wp.int32, device=device)
        # A frontier holds distinct nodes, so never more than the tree has.
        self._frontier = wp.zeros(n, dtype=wp.int32, device=device)
        self._frontier_next = wp.zeros(n, dtype=wp.int32, device=device)
        self._frontier_count = wp.zeros(1, dtype=wp.int32, device=device)
        self._keep = wp.zeros(n + 1, dtype=wp.int32, device=device)
        self._split = wp.zeros(n + 1, dtype=wp.int32, device=device)
        self._keep_offsets = wp.zeros(n + 1, dtype=wp.int32, device=device)
        self._split_offsets = wp.zeros(n + 1, dtype=wp.int32, device=device)
        # Sorted at capacity (N slots, the unused ones padded to sort last); radix sort needs twice that.
        self._sort_keys = wp.zeros(2 * n, dtype=wp.int32, device=device)
        self._sort_values = wp.zeros(2 * n, dtype=wp.int32, device=device)
        self._sort_bits = max(1, int(bvh.face_count).bit_length())
        self.in_front = wp.zeros(n + 1, dtype=wp.int32, device=device)
        self._marked = wp.zeros(n + 1, dtype=wp.int32, device=device)
        self._lifted = wp.zeros(1, dtype=wp.int32, device=device)
        self._counters = wp.zeros(4, dtype=wp.int32, device=device)
        self.node_id = wp.zeros(bvh.face_count, dtype=wp.int32, device=device)
        self.directions = wp.array(nc.sample_directions(), dtype=wp.vec3, device=device)
        table = nc.direction_mask_table(nc.TABLE_RESOLUTION, tolerances.NORMAL_CONE_MARGIN)
        self.direction_table = wp.array(table, dtype=nc.mask_type, device=device)
        self._set_front(np.asarray(bvh.roots, dtype=np.int32), 0)
        self._launch_key: tuple | None = None
        self._refit_launches: list = []
        self._launches: dict[str, Any] = {}
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

    # --- sync points ---------------------------------------------------------------------------

    @property
    def front_size(self) -> int:
        """Number of front nodes after the last call. Sync point: reads :attr:`front_count`.

        Allocates: yes (a host copy). Capture-safe: no.
        """
        return int(self.front_count.numpy()[0])

    @property
    def call_count(self) -> int:
        """:meth:`update` calls (and replays) so far. Sync point: reads :attr:`calls`.

        Allocates: yes (a host copy). Capture-safe: no.
        """
        return int(self.calls.numpy()[0])

    @property
    def stats(self) -> dict[str, int]:
        """Work of the last :meth:`update`: ``front_size``, ``front_nodes_tested`` (summed over the
        sprouting levels), ``sprout_levels`` and ``shrink_rounds`` (rounds that lifted a pair).
        All zero before the first call. Sync point: reads the device counters.

        Allocates: yes (host copies). Capture-safe: no.
        """
        tested, levels, rounds, _ = (int(v) for v in self._counters.numpy())
        return {"front_size": self.front_size, "front_nodes_tested": tested, "sprout_levels": levels,
                "shrink_rounds": rounds}

    @property
    def device_bytes(self) -> int:
        """Bytes held on the device by the front's buffers (the BVH is counted separately).

        Allocates: no. Capture-safe: yes (reads no device data).
        """
        arrays = (self.node_mask, self.node_normal, self.front, self.front_count, self.calls, self._front_next,
                  self._frontier, self._frontier_next, self._frontier_count, self._keep, self._split,
                  self._keep_offsets, self._split_offsets, self._sort_keys, self._sort_values, self.in_front,
                  self._marked, self._lifted, self._counters, self.node_id, self.directions, self.direction_table)
        return sum(a.capacity for a in arrays)

    def state_dict(self) -> dict[str, np.ndarray]:
        """What the front carries from call to call (its nodes and the call counter), as host arrays.

        Everything else is recomputed by :meth:`update`, so restoring this into a front over the
        same BVH makes later calls return exactly what the original front would (checkpoints).
        Sync point: reads the device front, its size and the call counter.

        Allocates: yes (host copies). Capture-safe: no.
        """
        size = self.front_size
        return {"front": self.front.numpy()[:size].copy(), "calls": self.calls.numpy().astype(np.int64)}

    def load_state_dict(self, state: dict[str, np.ndarray]) -> None:
        """Restore :meth:`state_dict` output (from a front over the same BVH) into the device state.

        Raises:
            InputError: node ids outside this BVH, more nodes than it can hold, or a negative
                call counter.

        Allocates: no (uploads into the existing buffers). Capture-safe: no.
        """
        nodes = np.asarray(state["front"], dtype=np.int32).reshape(-1)
        n = self.bvh.node_count
        if nodes.size == 0 or nodes.size > n or nodes.min() < 0 or nodes.max() >= n:
            raise InputError("checkpoint", "front", f"{nodes.size} node ids do not fit a BVH of {n} nodes",
                             "restore a checkpoint of the same scene")
        calls = int(np.asarray(state["calls"]).reshape(-1)[0])
        if calls < 0:
            raise InputError("checkpoint", "calls", f"{calls} is negative", "restore a checkpoint of the same scene")
        self._set_front(nodes, calls)

    def _set_front(self, nodes: np.ndarray, calls: int) -> None:
        """Upload a front and the call counter (host side: construction and checkpoints)."""
        n = self.bvh.node_count
        self.front.assign(np.concatenate([nodes, np.zeros(n - nodes.size, np.int32)]))
        self.front_count.assign(np.array([nodes.size], dtype=np.int32))
        self.calls.assign(np.array([calls], dtype=np.int64))

    # --- the device path -----------------------------------------------------------------------

    def update(self, positions_t0: wp.array, positions_t1: wp.array | None = None) -> wp.array:
        """Refit, shrink (every ``shrink_interval`` calls, counted on the device), sprout, and
        assign node ids.

        The device path: the front size, the call counter and the per-call counters stay on the
        device, every launch has a fixed size (N), and the shrink and sprout loops are
        ``wp.capture_while`` loops on device flags. Recorded into a graph, a replay is one call.
        Run eagerly on a CUDA device, Warp's ``capture_while`` itself reads its flag once per
        iteration; captured (or on the CPU, where the flag is read from memory directly) nothing is
        read back. The first call with new position arrays (or a new ``shrink_interval``) records
        its launches on the host; later calls with the same arrays replay them.

        Args:
            positions_t0: (vertex_count,) vec3 positions (DCD), or the start of the step (CCD).
            positions_t1: end of the step for CCD (the certificate then holds over the whole step).

        Returns:
            ``node_id``: (face_count,) int32 front node of each face (also :attr:`node_id`); the
            front is :attr:`front`, :attr:`front_count` nodes long.

        Allocates: no. Capture-safe: yes (capture after a first call with the same arrays).
        """
        self._record_launches(positions_t0, positions_t1)
        launches = self._launches
        for launch in self._refit_launches:
            launch.launch()
        launches["begin"].launch()
        wp.capture_while(self._lifted, self._shrink_round)
        launches["start_sprout"].launch()
        wp.capture_while(self._frontier_count, self._sprout_level)
        launches["finish_sprout"].launch()
        launches["write_sort_keys"].launch()
        wp.utils.radix_sort_pairs(self._sort_keys, self._sort_values, self.bvh.node_count, 0, self._sort_bits)
        launches["assign_node_ids"].launch()
        return self.node_id

    def _shrink_round(self) -> None:
        """Body of the shrink loop (runs while ``_lifted`` is set; ``_begin_update`` sets it on
        shrinking calls): one round of lifting sibling pairs, then compaction in node order."""
        launches = self._launches
        launches["clear_in_front"].launch()
        launches["mark_front"].launch()
        launches["shrink_pairs"].launch()
        wp.utils.array_scan(self.in_front, self._keep_offsets, inclusive=False)
        launches["finish_shrink_round"].launch()
        launches["compact_flags"].launch()

    def _sprout_level(self) -> None:
        """Body of the sprout loop (runs while the frontier is not empty): test one level."""
        launches = self._launches
        launches["test_frontier"].launch()
        wp.utils.array_scan(self._keep, self._keep_offsets, inclusive=False)
        wp.utils.array_scan(self._split, self._split_offsets, inclusive=False)
        launches["scatter_frontier"].launch()
        launches["advance_sprout"].launch()
        launches["copy_frontier"].launch()

    def _record_launches(self, positions_t0: wp.array, positions_t1: wp.array | None) -> None:
        """Record every launch of :meth:`update` once per set of position arrays (the arguments are
        the same every call while those arrays are), which saves their argument packing per call."""
        swept = 1 if positions_t1 is not None else 0
        positions_t1 = positions_t1 if positions_t1 is not None else positions_t0
        key = (positions_t0.ptr, positions_t1.ptr, swept, self.shrink_interval)
        if key == self._launch_key:
            return
        args = self.args
        args.positions_t0 = positions_t0
        args.positions_t1 = positions_t1
        args.swept = swept
        n = self.bvh.node_count
        bvh = self.bvh.arrays
        device = self.device

        def record(kernel: Any, dim: int, inputs: list, outputs: list) -> Any:
            return wp.launch(kernel, dim=dim, inputs=inputs, outputs=outputs, device=device, record_cmd=True)

        offsets = self.bvh.level_offsets
        self._refit_launches = []
        for depth in range(len(offsets) - 2, -1, -1):
            first, last = int(offsets[depth]), int(offsets[depth + 1])
            if last > first:
                self._refit_launches.append(
                    record(_refit_level, last - first, [args, first], [self.node_mask, self.node_normal]))
        self._launches = {
            "begin": record(_begin_update, 1, [self.shrink_interval], [self.calls, self._counters, self._lifted]),
            "clear_in_front": record(_clear_flags, n + 1, [], [self.in_front, self._marked]),
            "mark_front": record(_mark_front, n, [self.front, self.front_count],
                                 [self.in_front, self._marked, self._lifted]),
            "shrink_pairs": record(_shrink_pairs, n, [args, self.front, self.front_count, self._marked],
                                   [self.in_front, self._lifted]),
            "finish_shrink_round": record(_finish_shrink_round, 1, [self._lifted, self._keep_offsets, n],
                                          [self.front_count, self._counters]),
            "compact_flags": record(_compact_flags, n, [self.in_front, self._keep_offsets, self._lifted],
                                    [self.front]),
            "start_sprout": record(_start_sprout, n, [self.front, self.front_count],
                                   [self._frontier, self._frontier_count, self._counters]),
            "test_frontier": record(_test_frontier, n + 1, [args, self._frontier, self._frontier_count],
                                    [self._keep, self._split]),
            "scatter_frontier": record(_scatter_frontier, n,
                                       [bvh, self._frontier, self._frontier_count, self._keep,
                                        self._keep_offsets, self._split_offsets, self._counters],
                                       [self._front_next, self._frontier_next]),
            "advance_sprout": record(_advance_sprout, 1, [self._keep_offsets, self._split_offsets, n],
                                     [self._frontier_count, self._counters]),
            "copy_frontier": record(_copy_nodes, n, [self._frontier_next, self._frontier_count], [self._frontier]),
            "finish_sprout": record(_finish_sprout, n, [self._front_next, self._counters],
                                    [self.front, self.front_count]),
            "write_sort_keys": record(_write_sort_keys, n, [bvh, self.front, self.front_count, self.bvh.face_count],
                                   [self._sort_keys, self._sort_values]),
            "assign_node_ids": record(_assign_node_ids, self.bvh.face_count,
                                      [bvh, self._sort_keys, self._sort_values, self.front_count],
                                      [self.node_id]),
        }
        self._launch_key = key
