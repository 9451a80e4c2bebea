"""The normal cone test front (NCTF) of PSCC: which BVH nodes certify a self-collision-free patch.

The front is a cut of the material-space BVH (:class:`pscc.collision.bvh.MaterialBvh`): every face
has exactly one ancestor-or-self in it, and that node's id is the face's *node id*. A front node is
a leaf, a rigid object, or a node whose patch passed the normal-cone test (normal directions and
unprojected contour, :mod:`pscc.geometry.normal_cone`, or, when no point sees the contour turn one way,
the simple-polygon check of :mod:`pscc.geometry.simple_contour`), so no two of its faces can collide: the
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
4. **Node ids**: every front node adds node + 1 at its first face position (in the BVH's leaf order)
   and subtracts it past its last; the front's face ranges partition the leaf order, so the
   inclusive prefix sum at a face position is its node + 1. No sort: O(front + faces).

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
scratch                   (N,) / (N + 1,) int32 frontiers, flags, scan offsets; (m + 1,)
                                                int32 x 2 face-range marks and their sums
========================  ====================  ===========================================

The front never holds more than N nodes (the paper's bound is 2m + 1), nor does a frontier (its
nodes are distinct), so no buffer of the front can overflow.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import numpy as np
import warp as wp

from pscc import tolerances
from pscc._lanes import row_lanes
from pscc._reductions import PrefixSum
from pscc.collision._front_kernels import (
    NodeTestArgs,
    _advance_sprout,
    _assign_node_ids,
    _begin_update,
    _clear_flags,
    _clear_range_marks,
    _compact_flags,
    _copy_nodes,
    _finish_shrink_round,
    _finish_sprout,
    _mark_front,
    _mark_front_ranges,
    _refit_all_in_order,
    _refit_level,
    _scatter_frontier,
    _shrink_pairs,
    _start_sprout,
    _test_frontier,
)
from pscc.collision.bvh import MaterialBvh
from pscc.collision.scratch import TableSpec, place_tables, scratch_lenders
from pscc.errors import InputError
from pscc.geometry import normal_cone as nc
from pscc.geometry import simple_contour

wp.set_module_options({"enable_backward": False})


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
        self.front = wp.zeros(n, dtype=wp.int32, device=device)
        self.front_count = wp.zeros(1, dtype=wp.int32, device=device)
        # Allocation-free inside the shrink and sprout loops on CUDA; also scans the face-range marks.
        self._scan = PrefixSum(device, max(n + 1, bvh.face_count + 1))
        self.calls = wp.zeros(1, dtype=wp.int64, device=device)
        self._frontier_count = wp.zeros(1, dtype=wp.int32, device=device)
        # The per-call tables (node masks and normals, frontiers, flags, scans, range marks): in lent
        # memory when lend_scratch() gives some, else buffers of their own.
        self._scratch_source: Callable[[], Sequence[wp.array]] | None = None
        self._scratch_key: tuple[tuple[int, int], ...] = ()
        self._placements = 0
        self._last_positions: tuple[wp.array, wp.array | None] | None = None
        self._lent_names: set[str] = set()
        self._place_scratch()
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
        self.args.seam_gap_ratio = tolerances.SEAM_GAP_RATIO
        self.args.simple_contour_max_edges = simple_contour.SIMPLE_CONTOUR_MAX_EDGES

    # --- lent memory ---------------------------------------------------------------------------

    def lend_scratch(self, source: Callable[[], Sequence[wp.array]] | None) -> None:
        """Let the per-call tables (:meth:`_scratch_tables`: node masks and normals, frontiers, flags,
        scans and the face-range marks, which :meth:`update` fills before it reads them) live in the buffers
        ``source()`` gives, where they fit (:func:`pscc.collision.scratch.place_tables`); the front, its
        counters and :attr:`node_id` keep buffers of their own.

        For buffers that hold nothing their owner needs while :meth:`update` runs and whose owner never
        reads what it leaves there. ``source`` is called at every update (the owner may replace its
        buffers; the tables move with them). The detector lends what it lends its spatial hash: the
        front is updated at the start of the broad phase, before the hash. ``None`` takes the loan back.
        Allocates: the tables again. Capture-safe: no.
        """
        self._scratch_source = source
        self._place_scratch()

    def _scratch_tables(self) -> list[TableSpec]:
        n = self.bvh.node_count
        return [TableSpec("node_mask", n, nc.mask_type), TableSpec("node_normal", n, wp.vec3),
                TableSpec("_front_next", n, wp.int32), TableSpec("_frontier", n, wp.int32),
                TableSpec("_frontier_next", n, wp.int32), TableSpec("_keep", n + 1, wp.int32),
                TableSpec("_split", n + 1, wp.int32), TableSpec("_keep_offsets", n + 1, wp.int32),
                TableSpec("_split_offsets", n + 1, wp.int32), TableSpec("in_front", n + 1, wp.int32),
                TableSpec("_marked", n + 1, wp.int32),
                # The front nodes' face ranges as +-(node + 1) marks per face position, and their prefix sums.
                TableSpec("_range_marks", self.bvh.face_count + 1, wp.int32),
                TableSpec("_range_owner", self.bvh.face_count + 1, wp.int32)]

    def _place_scratch(self) -> None:
        """(Re)make the per-call tables; the launches are recorded again at the next update."""
        lenders = scratch_lenders(self._scratch_source, self.device)
        placed, self._lent_names = place_tables(self._scratch_tables(), lenders, self.device)
        for name, table in placed.items():
            setattr(self, name, table)
        self._scratch_key = tuple((lender.buffer.ptr, lender.buffer.capacity) for lender in lenders)
        self._placements += 1
        if hasattr(self, "args"):
            self.args.node_mask = self.node_mask
            self.args.node_normal = self.node_normal

    def refresh_loans(self) -> None:
        """Place the tables again when a lender replaced its buffers since they were placed (every
        :meth:`update` checks; a caller that resized a lender may call it at once, so that a graph recorded
        next records nothing again). Allocates: only then. Capture-safe: yes while no lender changed."""
        if self._scratch_source is None:
            return
        if tuple((a.ptr, a.capacity) for a in self._scratch_source()) != self._scratch_key:
            self._place_scratch()
            if self._last_positions is not None:  # record the launches on the new tables now
                self._record_launches(*self._last_positions)

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
        arrays = [self.front, self.front_count, self.calls, self._frontier_count, self._lifted, self._counters,
                  self.node_id, self.directions, self.direction_table]
        # Tables in lent memory (lend_scratch) are the lenders' to count.
        arrays += [getattr(self, t.name) for t in self._scratch_tables() if t.name not in self._lent_names]
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
            InputError: node ids outside this BVH, more nodes than it can hold, nodes that are not a cut
                of it (their face ranges do not cover every face once), or a negative call counter.

        Allocates: no (uploads into the existing buffers). Capture-safe: no.
        """
        nodes = np.asarray(state["front"], dtype=np.int32).reshape(-1)
        n = self.bvh.node_count
        if nodes.size == 0 or nodes.size > n or nodes.min() < 0 or nodes.max() >= n:
            raise InputError("checkpoint", "front", f"{nodes.size} node ids do not fit a BVH of {n} nodes",
                             "restore a checkpoint of the same scene")
        # A front must be a cut: its nodes' face ranges tile the faces. A checkpoint of another scene or of a
        # pscc whose tree was built otherwise (node ids in range, other nodes) would leave faces out of every
        # node or in two, and their pairs untested.
        begin = self.bvh.face_begin[nodes].astype(np.int64)
        end = self.bvh.face_end[nodes].astype(np.int64)
        order = np.argsort(begin, kind="stable")
        begin, end = begin[order], end[order]
        if begin[0] != 0 or end[-1] != self.bvh.face_count or np.any(begin[1:] != end[:-1]):
            raise InputError("checkpoint", "front", f"its {nodes.size} nodes do not cover each of the "
                             f"{self.bvh.face_count} faces once (a checkpoint of another scene, or of a pscc "
                             "that built this scene's tree otherwise)",
                             "restore a checkpoint written by this version of pscc for this scene, or start the run "
                             "again")
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
        self.refresh_loans()
        self._record_launches(positions_t0, positions_t1)
        launches = self._launches
        for launch in self._refit_launches:
            launch.launch()
        launches["begin"].launch()
        wp.capture_while(self._lifted, self._shrink_round)
        launches["start_sprout"].launch()
        wp.capture_while(self._frontier_count, self._sprout_level)
        launches["finish_sprout"].launch()
        launches["clear_range_marks"].launch()
        launches["mark_front_ranges"].launch()
        self._scan(self._range_marks, self._range_owner, inclusive=True)
        launches["assign_node_ids"].launch()
        return self.node_id

    def _shrink_round(self) -> None:
        """Body of the shrink loop (runs while ``_lifted`` is set; ``_begin_update`` sets it on
        shrinking calls): one round of lifting sibling pairs, then compaction in node order."""
        launches = self._launches
        launches["clear_in_front"].launch()
        launches["mark_front"].launch()
        launches["shrink_pairs"].launch()
        self._scan(self.in_front, self._keep_offsets, inclusive=False)
        launches["finish_shrink_round"].launch()
        launches["compact_flags"].launch()

    def _sprout_level(self) -> None:
        """Body of the sprout loop (runs while the frontier is not empty): test one level."""
        launches = self._launches
        launches["test_frontier"].launch()
        self._scan(self._keep, self._keep_offsets, inclusive=False)
        self._scan(self._split, self._split_offsets, inclusive=False)
        launches["scatter_frontier"].launch()
        launches["advance_sprout"].launch()
        launches["copy_frontier"].launch()

    def _record_launches(self, positions_t0: wp.array, positions_t1: wp.array | None) -> None:
        """Record every launch of :meth:`update` once per set of position arrays (the arguments are
        the same every call while those arrays are), which saves their argument packing per call."""
        self._last_positions = (positions_t0, positions_t1)
        swept = 1 if positions_t1 is not None else 0
        positions_t1 = positions_t1 if positions_t1 is not None else positions_t0
        key = (positions_t0.ptr, positions_t1.ptr, swept, self.shrink_interval, self._placements)
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
        if wp.get_device(device).is_cpu:
            # One thread walks every node bottom-up: the same results as the level launches below.
            self._refit_launches.append(record(_refit_all_in_order, 1, [args, n], [self.node_mask, self.node_normal]))
        else:
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
            "test_frontier": record(_test_frontier, row_lanes(device, n + 1),
                                    [args, self._frontier, self._frontier_count, row_lanes(device, n + 1)],
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
            "clear_range_marks": record(_clear_range_marks, self.bvh.face_count + 1, [], [self._range_marks]),
            "mark_front_ranges": record(_mark_front_ranges, n, [bvh, self.front, self.front_count],
                                        [self._range_marks]),
            "assign_node_ids": record(_assign_node_ids, self.bvh.face_count, [bvh, self._range_owner],
                                      [self.node_id]),
        }
        self._launch_key = key
