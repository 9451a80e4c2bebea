"""Triangle-pair broad phase of PSCC: spatial hashing with the paired {CellId, NodeId} key (paper §4).

Each face box is inserted in every grid cell it overlaps, keyed by the exact 64-bit
``(CellId << 32) | uint32(NodeId)``. Sorting the entries by key lays out both tables of the paper:

* ``triangleHashTable``: one row per distinct {cell, node} key (a *group*), its faces contiguous;
* ``workLoadHashTable``: one row per non-empty cell, its groups contiguous (the cell is the high half
  of the key, so the groups of a cell are adjacent after the sort).

Faces of one group are never paired (same normal-cone-test-front node: the self-collision culling).
With the *group slab test* on (PSCC), two groups of a cell are first tested as wholes: the faces of
the smaller group, projected on the larger group's axis (the mean normal of its faces, so a flat
front node gives a thin slab), must reach that group's slab, both grown by the half distance and a
rounding bound. Groups that miss each other hold no pair of faces closer than the distance, so their
face pairs are skipped. Every remaining pair of entries of a cell is one bounding-volume (BV) test,
run by one thread, found through *work rows* (a group against a run of later groups of its cell);
a token-position rule emits each overlapping face pair from exactly one cell. See
``docs/spatial-hash.md`` for the derivations.

Device buffers of :class:`SpatialHash` (E = entries, G = groups, C = cells, all <= entry capacity):

=========================  ====================  ===========================================================
buffer                     shape, dtype          meaning
=========================  ====================  ===========================================================
face_cells / face_end      (face_count,) int64   cells a face's box overlaps / inclusive scan (entry ends)
entry_key / entry_face     (2 E,) int64 / int32  {cell, node} key and face of each entry, sorted by key
                                                 (the second half is radix-sort scratch)
group_rank / cell_rank     (E,) int32            1-based group / cell of each sorted entry (scans of heads)
group_start / group_end    (E,) / (G,) int32     entry range of group g (triangleHashTable row g);
                                                 group_start first holds the run-head flags
group_cell                 (G,) int32            cell rank of group g (workLoadHashTable row of g)
cell_end                   (E,) int32            one past the last entry of cell c (first the cell-head flags)
group_axis / group_slab    (G,) vec3 / vec2      slab test only: axis of group g / (min, max) of its
                                                 faces' vertices on the axis (1 slot when off)
group_mask                 (G,) uint64           slab test only: bit t = the t-th later group of the cell
                                                 passed (or was not tested)
row_count / row_end        (G,) int32            rows of group g / inclusive scan (in the rank buffers)
row_span                   (R,) vec3i            work row r = (g, b_start, b_end): entries of group g
                                                 against entries [b_start, b_end) of its cell
row_work / row_scan        (R,) int64            BV tests of row r = n_g x (b_end - b_start) / inclusive
                                                 scan (searched by the test threads)
pairs / pair_keys          (2 P,) vec2i / int64  emitted face pairs (a < b) and their sort keys a m + b
                                                 (P slots and no keys when ``sort_pairs`` is off)
counts                     (2,) int64            [pairs emitted, unused]
work_counts                (3,) int64            [face tests, slab tests, same-node face pairs] of the rows
=========================  ====================  ===========================================================

Sync points of :meth:`SpatialHash.find_pairs` (host reads of device data, each a few scalars):
(1) scene bounds and mean box size, (2) entry count and grid size, (3) group count, (4) cell, row,
face-test and slab-test counts, (5) emitted pair count. Everything else stays on the device.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import warp as wp

from pscc import tolerances
from pscc.collision import _spatial_hash_kernels as kernels
from pscc.errors import CapacityError, InputError

wp.set_module_options({"enable_backward": False})

DEFAULT_CELL_SIZE_FACTOR: float = 1.5
"""k in Size_cell = k x BoxAxisLen_aver (the paper does not give its value)."""

TESTS_PER_LAUNCH: int = 2**24
"""BV tests (threads) per launch of the test kernel; bounds launch size, not memory (O(G))."""

MAX_GRID_CELLS: int = 2**31 - 1
"""Most cells of the grid: a CellId must fit in the high 31 bits of a non-negative int64 key."""

MAX_ENTRIES: int = 2**30 - 1
"""Most face-cell entries: entries are int32-indexed and the radix sort needs 2 E slots."""

MAX_PAIRS: int = 2**30 - 1
"""Most emitted face pairs: the pair buffer is int32-indexed and the radix sort needs 2 P slots."""

DEFAULT_SLAB_MIN_WORK: int = 8
"""Two groups are slab-tested only when they would need at least this many face tests (n_g n_h):
a slab test projects the smaller group's vertices, so tiny groups are cheaper to test face by face."""

DEFAULT_MAX_MEAN_CELLS_PER_FACE: float = 64.0
"""Grid guard: when the entries exceed this many per face, the cell size is doubled and the
faces are counted again (pairs are unchanged, only culling gets coarser)."""

_SCENE_CHUNKS: int = 1024
"""Threads of the scene-bounds reduction (each folds a chunk of faces)."""

_GROWTH: float = 1.25
"""Grown buffers get this factor over the exact count, so small increases do not re-grow."""


@dataclass
class SpatialHashStats:
    """Counters of the last :meth:`SpatialHash.find_pairs` call.

    Attributes:
        cell_size: cell edge used (float32 value; larger than requested after coarsening).
        grid_dims: (N_x, N_y, N_z) cells per axis.
        entries: face-cell insertions E.
        groups: distinct {cell, node} keys (triangleHashTable rows).
        cells: non-empty cells (workLoadHashTable rows).
        bv_tests: bounding-volume tests run: ``face_tests + slab_tests``.
        face_tests: face box tests run: sum over cells of sum_{i<j} n_i n_j over the group pairs
            that are not culled by a slab test (all of them when the slab test is off).
        slab_tests: group slab tests run (0 when the slab test is off).
        rows: work rows (a group against a run of later groups of its cell).
        triangle_pairs: face pairs emitted (unique, a < b).
        mean_cells_per_face: E / face_count.
        coarsenings: times the cell size was doubled by the grid guard.
        reruns: times the test pass ran again after the pair buffer grew.
        same_node_tests: face pairs of one node that met in a cell in two groups (never tested; 0
            unless a ``face_order`` splits a node; checked by the tests).
        device_bytes: bytes held on the device, per buffer.
    """

    cell_size: float = 0.0
    grid_dims: tuple[int, int, int] = (0, 0, 0)
    entries: int = 0
    groups: int = 0
    cells: int = 0
    bv_tests: int = 0
    face_tests: int = 0
    slab_tests: int = 0
    rows: int = 0
    triangle_pairs: int = 0
    mean_cells_per_face: float = 0.0
    coarsenings: int = 0
    reruns: int = 0
    same_node_tests: int = 0
    device_bytes: dict[str, int] = field(default_factory=dict)


def _check_positive(value: float, name: str) -> float:
    try:
        number = float(value)
    except (TypeError, ValueError) as exc:
        raise InputError("argument", name, f"{value!r} is not a number", "pass a finite float > 0") from exc
    if not math.isfinite(number) or number <= 0.0:
        raise InputError("argument", name, f"{value!r} is not a finite number > 0", "pass a finite float > 0")
    return number


class SpatialHash:
    """Spatial-hashing broad phase over face pairs with the paired {CellId, NodeId} key.

    Faces with the same node id are never paired. Give every face its own id (``node_id=None``)
    for plain spatial hashing, the normal-cone-test-front node of each face for PSCC, or one id
    per rigid body to skip the pairs inside each body. The pair set is exact: all face pairs
    whose closed boxes overlap and whose node ids differ, each once, sorted by (a, b). The grid
    changes only the cost, never the result. Buffer layout in the module docstring.

    Args:
        face_count: faces m (the length of every per-face array).
        device: Warp device (``None``: the default device).
        cell_size_factor: k in cell size = k x mean over faces of the mean box axis length.
        faces: (face_count,) ``wp.vec3i`` vertex ids, needed only for ``skip_adjacent``.
        skip_adjacent: drop pairs that share a vertex (default False: such pairs can still
            collide through their other features, so the narrow phase usually wants them).
        max_mean_cells_per_face: grid guard; more entries than this times face_count double
            the cell size (>= 1).
        pair_capacity: initial pair slots (default 4 x face_count); grown to the exact need.
        tests_per_launch: BV tests per launch of the test kernel.
        tests_per_thread: BV tests each thread of the test kernel runs back to back. ``None``: 1 on
            a GPU (the paper's one thread per BV test) and 64 on the CPU, whose kernel threads run
            one after the other (one binary search per 64 tests instead of per test). Either way
            every thread gets the same amount of work.
        sort_pairs: sort the emitted pairs by (a, b) (deterministic order on every device). Without
            sorting, the order follows the atomic appends (deterministic on the CPU only) and the
            pair buffer needs half the memory; the detector sorts its final results anyway.
        group_slab_test: test two groups of a cell as wholes before their face pairs (needs
            ``faces``, and positions on every :meth:`find_pairs` call that passes node ids). The
            pairs are then those whose boxes overlap, whose node ids differ and whose groups are not
            separated along a group axis: a superset of the pairs closer than twice the half
            distance, a subset of the box pairs.
        slab_min_work: slab-test two groups only when they would need this many face tests.

    Raises:
        InputError: invalid arguments.
    """

    def __init__(
        self,
        face_count: int,
        device: wp.Device | str | None = None,
        cell_size_factor: float = DEFAULT_CELL_SIZE_FACTOR,
        *,
        faces: wp.array | None = None,
        skip_adjacent: bool = False,
        max_mean_cells_per_face: float = DEFAULT_MAX_MEAN_CELLS_PER_FACE,
        pair_capacity: int | None = None,
        tests_per_launch: int = TESTS_PER_LAUNCH,
        sort_pairs: bool = True,
        tests_per_thread: int | None = None,
        group_slab_test: bool = False,
        slab_min_work: int = DEFAULT_SLAB_MIN_WORK,
    ) -> None:
        self.sort_pairs = bool(sort_pairs)
        self.group_slab_test = bool(group_slab_test)
        if isinstance(slab_min_work, bool) or not isinstance(slab_min_work, int | np.integer) or slab_min_work < 1:
            raise InputError("argument", "slab_min_work", f"{slab_min_work!r} is not an integer >= 1",
                             "pass a positive integer such as 8")
        self.slab_min_work = int(slab_min_work)
        if isinstance(face_count, bool) or not isinstance(face_count, int | np.integer) or face_count < 0:
            raise InputError("argument", "face_count", f"{face_count!r} is not an integer >= 0",
                             "pass the number of faces")
        if face_count > MAX_ENTRIES:
            raise InputError("argument", "face_count", f"{face_count} faces exceed {MAX_ENTRIES}",
                             "split the scene into several hashes")
        if pair_capacity is not None and (isinstance(pair_capacity, bool) or not isinstance(pair_capacity, int)
                                          or pair_capacity < 0):
            raise InputError("argument", "pair_capacity", f"{pair_capacity!r} is not an integer >= 0",
                             "pass a non-negative integer or None")
        self.device = wp.get_device(device)
        if tests_per_thread is None:
            tests_per_thread = 1 if self.device.is_cuda else 64
        if isinstance(tests_per_thread, bool) or not isinstance(tests_per_thread, int) or tests_per_thread < 1:
            raise InputError("argument", "tests_per_thread", f"{tests_per_thread!r} is not an integer >= 1",
                             "pass a positive integer or None")
        self.tests_per_thread = int(tests_per_thread)
        self.face_count = int(face_count)
        self.cell_size_factor = _check_positive(cell_size_factor, "cell_size_factor")
        self.max_mean_cells_per_face = _check_positive(max_mean_cells_per_face, "max_mean_cells_per_face")
        if self.max_mean_cells_per_face < 1.0:
            raise InputError("argument", "max_mean_cells_per_face", f"{max_mean_cells_per_face!r} < 1",
                             "pass a value >= 1 (every face overlaps at least one cell)")
        if isinstance(tests_per_launch, bool) or not isinstance(tests_per_launch, int) or tests_per_launch < 1:
            raise InputError("argument", "tests_per_launch", f"{tests_per_launch!r} is not an integer >= 1",
                             "pass a positive integer such as 2**24")
        self.tests_per_launch = tests_per_launch
        self.skip_adjacent = bool(skip_adjacent)
        m = self.face_count
        self._vertex_bound = 0
        if faces is not None:
            self._check_array(faces, "faces", wp.vec3i)
            self.faces = faces
            if self.group_slab_test and m > 0:
                # The slab test reads positions[faces]: one host read here lets every call check them.
                self._vertex_bound = int(faces.numpy().max()) + 1
        elif self.skip_adjacent or self.group_slab_test:
            option = "skip_adjacent" if self.skip_adjacent else "group_slab_test"
            raise InputError("argument", "faces", f"{option}=True needs the faces' vertex ids",
                             f"pass faces=(face_count,) wp.vec3i or leave {option} False")
        else:
            self.faces = wp.zeros(1, dtype=wp.vec3i, device=self.device)

        dev = self.device
        chunks = max(1, min(_SCENE_CHUNKS, m))
        self._chunk_size = max(1, -(-m // chunks))
        self._chunk_count = max(1, -(-m // self._chunk_size))
        self.chunk_lower = wp.empty(self._chunk_count, dtype=wp.vec3, device=dev)
        self.chunk_upper = wp.empty(self._chunk_count, dtype=wp.vec3, device=dev)
        self.chunk_length_sum = wp.empty(self._chunk_count, dtype=wp.float64, device=dev)
        self.chunk_bad = wp.empty(self._chunk_count, dtype=wp.int32, device=dev)
        self.scene = wp.zeros(8, dtype=wp.float64, device=dev)
        self.face_cells = wp.empty(max(1, m), dtype=wp.int64, device=dev)
        self.face_end = wp.empty(max(1, m), dtype=wp.int64, device=dev)
        self.grid_max = wp.zeros(4, dtype=wp.int32, device=dev)
        self.entry_info = wp.zeros(5, dtype=wp.int64, device=dev)
        self.table_info = wp.zeros(6, dtype=wp.int64, device=dev)
        self.counts = wp.zeros(2, dtype=wp.int64, device=dev)
        self.work_counts = wp.zeros(3, dtype=wp.int64, device=dev)
        self.own_node_id = wp.array(np.arange(m, dtype=np.int32), dtype=wp.int32, device=dev)
        self._allocate_entries(max(1, 4 * m))
        capacity = 4 * m if pair_capacity is None else pair_capacity
        self._allocate_pairs(max(1, min(MAX_PAIRS, capacity)))
        self._allocate_rows(max(1, m // 4))
        self._pair_count = 0
        self.stats = SpatialHashStats()

    # ------------------------------------------------------------------ buffers

    def _allocate_entries(self, capacity: int) -> None:
        dev = self.device
        self.entry_capacity = capacity
        self.entry_key = wp.empty(2 * capacity, dtype=wp.int64, device=dev)
        self.entry_face = wp.empty(2 * capacity, dtype=wp.int32, device=dev)
        self.group_rank = wp.empty(capacity, dtype=wp.int32, device=dev)
        self.cell_rank = wp.empty(capacity, dtype=wp.int32, device=dev)
        # group_start / cell_end first hold the head flags that are scanned into the ranks.
        self.group_start = wp.empty(capacity, dtype=wp.int32, device=dev)
        self.cell_end = wp.empty(capacity, dtype=wp.int32, device=dev)
        if not hasattr(self, "group_end"):
            self._allocate_groups(max(1, capacity // 4))

    def _allocate_groups(self, capacity: int) -> None:
        """Per-group tables, sized by the group count (far below the entry count on cloth)."""
        dev = self.device
        self.group_capacity = capacity
        self.group_end = wp.empty(capacity, dtype=wp.int32, device=dev)
        self.group_cell = wp.empty(capacity, dtype=wp.int32, device=dev)
        slab_capacity = capacity if self.group_slab_test else 1
        self.group_axis = wp.empty(slab_capacity, dtype=wp.vec3, device=dev)
        self.group_slab = wp.empty(slab_capacity, dtype=wp.vec2, device=dev)
        self.group_mask = wp.empty(slab_capacity, dtype=wp.uint64, device=dev)

    def _allocate_rows(self, capacity: int) -> None:
        """Work rows, sized by the row count (at most the group count without the slab test)."""
        dev = self.device
        self.row_capacity = capacity
        self.row_span = wp.empty(capacity, dtype=wp.vec3i, device=dev)
        self.row_work = wp.empty(capacity, dtype=wp.int64, device=dev)
        self.row_scan = wp.empty(capacity, dtype=wp.int64, device=dev)

    def _allocate_pairs(self, capacity: int) -> None:
        self.pair_capacity = capacity
        # Sorting needs twice the slots (radix-sort scratch) and a key per pair.
        slots = 2 * capacity if self.sort_pairs else capacity
        self.pairs = wp.empty(slots, dtype=wp.vec2i, device=self.device)
        self.pair_keys = wp.empty(slots if self.sort_pairs else 1, dtype=wp.int64, device=self.device)

    @property
    def device_bytes(self) -> dict[str, int]:
        """Bytes held on the device, per buffer name."""
        names = ("chunk_lower", "chunk_upper", "chunk_length_sum", "chunk_bad", "scene", "face_cells",
                 "face_end", "grid_max", "entry_info", "table_info", "counts", "work_counts", "own_node_id",
                 "faces", "entry_key", "entry_face", "group_rank", "cell_rank", "group_start", "cell_end",
                 "group_end", "group_cell", "group_axis", "group_slab", "group_mask", "row_span", "row_work",
                 "row_scan", "pairs", "pair_keys")
        return {name: int(getattr(self, name).capacity) for name in names}

    # ------------------------------------------------------------------ validation

    def _check_array(self, value: object, name: str, dtype: type) -> None:
        m = self.face_count
        if not isinstance(value, wp.array):
            raise InputError("argument", name, f"got {type(value).__name__}, not a wp.array",
                             f"pass a ({m},) wp.array of {dtype.__name__}")
        if value.dtype != dtype or value.ndim != 1 or value.shape[0] != m:
            raise InputError("argument", name, f"got a {value.shape} array of {wp.types.type_repr(value.dtype)}",
                             f"pass a ({m},) wp.array of {dtype.__name__}")
        if value.device != self.device:
            raise InputError("argument", name, f"array is on {value.device}, the hash on {self.device}",
                             f"copy it to {self.device} first")
        if not value.is_contiguous:
            raise InputError("argument", name, "array is not contiguous", "pass a contiguous array")

    # ------------------------------------------------------------------ public API

    def find_pairs(
        self,
        face_lower: wp.array,
        face_upper: wp.array,
        node_id: wp.array | None = None,
        cell_size: float | None = None,
        *,
        positions_t0: wp.array | None = None,
        positions_t1: wp.array | None = None,
        half_distance: float = 0.0,
        node_id_bound: int | None = None,
        face_order: wp.array | None = None,
    ) -> tuple[wp.array, int]:
        """All face pairs (a < b) whose closed boxes overlap and whose node ids differ (with the
        group slab test: less the pairs of groups separated along a group axis, none of which is
        closer than twice ``half_distance``).

        Sync points: five host reads of a few scalars each (module docstring); the buffers grow
        when an exact count exceeds their capacity, and the test pass then re-runs.

        Args:
            face_lower: (face_count,) ``wp.vec3`` lower box corners (length units).
            face_upper: (face_count,) ``wp.vec3`` upper box corners, >= ``face_lower``.
            node_id: (face_count,) ``wp.int32`` node of each face (faces of one node are never
                paired; any int32 value); ``None`` gives every face its own node.
            cell_size: grid cell edge (length units); ``None`` uses ``cell_size_factor`` x the
                mean box axis length.
            positions_t0: (vertex_count,) ``wp.vec3`` vertex positions at the start of the step, the
                ones the boxes were built from; needed by the group slab test when ``node_id`` is
                given (without node ids every group is one face and no group is slab-tested).
            positions_t1: positions at the end of the step (CCD; ``None``: discrete).
            half_distance: the half distance the boxes were grown by (length units, >= 0).
            node_id_bound: every node id lies in [0, node_id_bound): the keys then need only
                bit_length(node_id_bound - 1) node bits, and the sort fewer passes (``None``: any
                int32 ids, 32 bits). Checked on the device.
            face_order: (face_count,) ``wp.int32`` permutation of the faces in which faces with
                equal node ids are contiguous (for PSCC the BVH's face order: every front node is
                a range of it). Entries are then laid out in this order, so after a stable sort on
                the cell bits alone the faces of a node stay together in each cell: the sort skips
                the node bits. Checked to be a permutation once per array (its contents must not
                change between calls); a grouping it breaks is caught by the same-node counter.

        Returns:
            ``(pairs, count)``: a (count,) ``wp.vec2i`` view of the internal buffer, sorted by
            (a, b) and valid until the next call, and the number of pairs.

        Raises:
            InputError: wrong array, non-finite or inverted box, bad cell size, a node id outside
                [0, node_id_bound), a ``face_order`` that is no permutation or splits a node.
            CapacityError: more entries or pairs than int32 indexing allows.

        Allocates: when a buffer grows. Capture-safe: no.
        """
        self._check_array(face_lower, "face_lower", wp.vec3)
        self._check_array(face_upper, "face_upper", wp.vec3)
        if node_id is None:
            node_id = self.own_node_id
            node_id_bound = max(1, self.face_count)
        else:
            self._check_array(node_id, "node_id", wp.int32)
        if node_id_bound is not None and (isinstance(node_id_bound, bool)
                                          or not isinstance(node_id_bound, int | np.integer)
                                          or not 1 <= node_id_bound <= 2**31):
            raise InputError("argument", "node_id_bound", f"{node_id_bound!r} is not an integer in [1, 2^31]",
                             "pass one more than the largest node id, or None")
        if cell_size is not None:
            cell_size = _check_positive(cell_size, "cell_size")
        if face_order is not None:
            self._check_face_order(face_order)
        slab = self._slab_args(node_id is not self.own_node_id, positions_t0, positions_t1, half_distance)
        self.stats = SpatialHashStats()
        self._pair_count = 0
        if self.face_count < 2:
            self.stats.device_bytes = self.device_bytes
            if self.face_count == 1:
                self.stats.entries = self.stats.groups = self.stats.cells = 1
                self.stats.mean_cells_per_face = 1.0
            return self.pairs[:0], 0

        origin, extent, mean_length = self._scene_bounds(face_lower, face_upper)
        self._slab_margin(slab, origin, extent)
        if cell_size is None:
            cell_size = self.cell_size_factor * mean_length
            if not cell_size > 0.0:  # every box is degenerate: one cell per scene extent
                cell_size = max(float(np.max(extent)), 1.0)
        grid = kernels.GridArgs()
        grid.origin = wp.vec3(*origin)
        grid.node_bits = kernels.NODE_BITS if node_id_bound is None else max(1, (int(node_id_bound) - 1).bit_length())
        node_limit = 0 if node_id_bound is None else int(node_id_bound)
        # Faces in node-contiguous order (own ids: face order; else the given order) need only the cell bits sorted.
        grouped_fill = node_id is self.own_node_id or face_order is not None
        order = self.own_node_id if face_order is None else face_order
        entries = self._insert_faces(face_lower, face_upper, node_id, node_limit, grid, cell_size, extent, order,
                                     face_order is not None, grouped_fill)
        self._build_tables(entries, grid.node_bits, slab, int(face_order is not None))
        self._test_pairs(face_lower, face_upper, grid)
        if face_order is not None and self.stats.same_node_tests > 0:
            raise InputError("argument", "face_order", "faces of one node are not contiguous in it",
                             "pass an order in which equal node ids are adjacent, or None")
        if self.sort_pairs:
            self._sort_pairs()
        self.stats.mean_cells_per_face = entries / self.face_count
        self.stats.device_bytes = self.device_bytes
        return self.pairs[: self._pair_count], self._pair_count

    def _check_face_order(self, face_order: wp.array) -> None:
        """Shape and dtype on every call; that it is a permutation once per array (one host read)."""
        self._check_array(face_order, "face_order", wp.int32)
        key = (face_order.ptr, face_order.shape[0])
        if key == getattr(self, "_checked_order", None):
            return
        order = face_order.numpy()
        if order.shape[0] and (order.min() < 0 or order.max() >= self.face_count
                               or np.bincount(order, minlength=self.face_count).max() != 1):
            raise InputError("argument", "face_order", "is not a permutation of the faces",
                             "pass each face id exactly once")
        self._checked_order = key

    def _slab_args(self, grouped: bool, positions_t0: wp.array | None, positions_t1: wp.array | None,
                   half_distance: float) -> kernels.SlabArgs:
        """The slab test's launch arguments (disabled unless configured and given node ids)."""
        slab = kernels.SlabArgs()
        slab.enabled = 0
        slab.faces = self.faces
        slab.swept = 0
        slab.half_distance = 0.0
        slab.margin = 0.0
        slab.min_work = self.slab_min_work
        if not (self.group_slab_test and grouped):
            slab.positions_t0 = slab.positions_t1 = self.chunk_lower
            return slab
        for name, value in (("positions_t0", positions_t0), ("positions_t1", positions_t1)):
            if value is None:
                if name == "positions_t0":
                    raise InputError("argument", name, "the group slab test needs the vertex positions",
                                     "pass positions_t0 (and positions_t1 for CCD) with node_id")
                continue
            if not isinstance(value, wp.array) or value.dtype != wp.vec3 or value.ndim != 1:
                raise InputError("argument", name, f"got {type(value).__name__}, not a 1-D wp.array of vec3",
                                 "pass the (vertex_count,) wp.vec3 positions the boxes were built from")
            if value.device != self.device:
                raise InputError("argument", name, f"array is on {value.device}, the hash on {self.device}",
                                 f"copy it to {self.device} first")
        if positions_t0.shape[0] < self._vertex_bound:
            raise InputError("argument", "positions_t0", f"{positions_t0.shape[0]} positions, but the faces use "
                             f"{self._vertex_bound} vertices", "pass a position for every vertex the faces use")
        if positions_t1 is not None and positions_t1.shape != positions_t0.shape:
            raise InputError("argument", "positions_t1", f"shape {positions_t1.shape} != positions_t0's "
                             f"{positions_t0.shape}", "pass both ends of the step for the same vertices")
        half = float(half_distance)
        if not math.isfinite(half) or half < 0.0:
            raise InputError("argument", "half_distance", f"{half_distance!r} is not a finite number >= 0",
                             "pass the half distance the boxes were grown by")
        slab.enabled = 1
        slab.positions_t0 = positions_t0
        slab.positions_t1 = positions_t0 if positions_t1 is None else positions_t1
        slab.swept = 0 if positions_t1 is None else 1
        slab.half_distance = half
        return slab

    @staticmethod
    def _slab_margin(slab: kernels.SlabArgs, origin: np.ndarray, extent: np.ndarray) -> None:
        """Set the slab growth from the scene box (it contains every face box, so every vertex):
        M = sum_k max(|lower_k|, |upper_k|) bounds |p|_1 (``tolerances.GROUP_SLAB_RELATIVE_PAD``)."""
        lower = origin.astype(np.float64)
        upper = lower + extent
        size = float(np.maximum(np.abs(lower), np.abs(upper)).sum())
        pad = tolerances.GROUP_SLAB_RELATIVE_PAD
        slab.margin = float(slab.half_distance * (1.0 + pad) + pad * (size + slab.half_distance))

    def pairs_numpy(self) -> np.ndarray:
        """The pairs of the last :meth:`find_pairs` as a (count, 2) int32 array, sorted by (a, b).

        Allocates: yes (host copy). Capture-safe: no.
        """
        if self._pair_count == 0:
            return np.zeros((0, 2), dtype=np.int32)
        return self.pairs[: self._pair_count].numpy().reshape(-1, 2).astype(np.int32)

    # ------------------------------------------------------------------ stages

    def _scene_bounds(self, face_lower: wp.array, face_upper: wp.array) -> tuple[np.ndarray, np.ndarray, float]:
        """Sync point 1: min corner, extent and mean box axis length (a deterministic reduction)."""
        dev = self.device
        wp.launch(kernels._reduce_scene_chunks, dim=self._chunk_count,
                  inputs=[face_lower, face_upper, self._chunk_size],
                  outputs=[self.chunk_lower, self.chunk_upper, self.chunk_length_sum, self.chunk_bad], device=dev)
        wp.launch(kernels._reduce_scene_total, dim=1,
                  inputs=[self.chunk_lower, self.chunk_upper, self.chunk_length_sum, self.chunk_bad,
                          self._chunk_count],
                  outputs=[self.scene], device=dev)
        scene = self.scene.numpy()
        if scene[7] > 0:
            raise InputError("argument", "face_lower/face_upper",
                             f"{int(scene[7])} boxes hold NaN/Inf or have lower > upper on some axis",
                             "pass finite boxes with lower <= upper")
        origin = scene[0:3].astype(np.float32)
        extent = scene[3:6] - scene[0:3]
        return origin, extent, float(scene[6]) / self.face_count

    def _insert_faces(
        self, face_lower: wp.array, face_upper: wp.array, node_id: wp.array, node_limit: int,
        grid: kernels.GridArgs, cell_size: float, extent: np.ndarray, order: wp.array, ordered: bool,
        grouped_fill: bool,
    ) -> int:
        """Count, scan and fill the (key, face) entries, then sort them. Sync point 2.

        Chooses the final cell size: doubles it while the grid or the entries are too big.
        """
        dev = self.device
        m = self.face_count
        max_entries = min(MAX_ENTRIES, max(m, int(self.max_mean_cells_per_face * m)))
        while True:
            cell_size = float(np.float32(cell_size))
            estimate = [extent[k] / cell_size + 2.0 for k in range(3)]
            if not all(math.isfinite(e) for e in estimate) or math.prod(estimate) > MAX_GRID_CELLS:
                cell_size *= 2.0
                self.stats.coarsenings += 1
                continue
            self.grid_max.zero_()
            wp.launch(kernels._count_face_cells, dim=m,
                      inputs=[face_lower, face_upper, grid.origin, cell_size, node_id, node_limit, order,
                              int(ordered)],
                      outputs=[self.face_cells, self.grid_max], device=dev)
            wp.utils.array_scan(self.face_cells, self.face_end, inclusive=True)
            wp.launch(kernels._gather_entry_info, dim=1, inputs=[self.face_end, self.grid_max],
                      outputs=[self.entry_info], device=dev)
            info = self.entry_info.numpy()
            if info[4] > 0:
                raise InputError("argument", "node_id", f"{int(info[4])} node ids lie outside [0, {node_limit})",
                                 "pass node ids below node_id_bound, or node_id_bound=None")
            entries = int(info[0])
            dims = tuple(int(n) for n in info[1:4])
            if entries > max_entries or math.prod(dims) > MAX_GRID_CELLS:
                cell_size *= 2.0
                self.stats.coarsenings += 1
                continue
            break
        grid.cell_size = cell_size
        grid.dims = wp.vec3i(*dims)
        self.stats.cell_size = cell_size
        self.stats.grid_dims = dims
        self.stats.entries = entries
        if entries > self.entry_capacity:
            self._allocate_entries(min(MAX_ENTRIES, int(entries * _GROWTH)))
        wp.launch(kernels._fill_entries, dim=m,
                  inputs=[face_lower, face_upper, node_id, self.face_cells, self.face_end, grid, order, int(ordered)],
                  outputs=[self.entry_key, self.entry_face], device=dev)
        cell_bits = max(1, (math.prod(dims) - 1).bit_length())
        # A stable sort on the cell bits keeps the fill order inside each cell; when that order keeps
        # each node's faces together, the node bits need no sorting.
        first_bit = grid.node_bits if grouped_fill else 0
        wp.utils.radix_sort_pairs(self.entry_key, self.entry_face, entries, first_bit, grid.node_bits + cell_bits)
        return entries

    def _build_tables(self, entries: int, node_bits: int, slab: kernels.SlabArgs, check_keys: int) -> None:
        """Run heads -> ranks -> group and cell ranges -> slab tests and work rows -> row scan.
        Sync points 3 (group count) and 4 (cells, rows, face tests, slab tests)."""
        dev = self.device
        n = entries
        keys = self.entry_key[:n]
        wp.launch(kernels._mark_runs, dim=n, inputs=[keys, node_bits],
                  outputs=[self.group_start[:n], self.cell_end[:n]], device=dev)
        wp.utils.array_scan(self.group_start[:n], self.group_rank[:n], inclusive=True)
        wp.utils.array_scan(self.cell_end[:n], self.cell_rank[:n], inclusive=True)
        groups = int(self.group_rank[n - 1 : n].numpy()[0])
        if groups > self.group_capacity:
            self._allocate_groups(int(groups * _GROWTH) + 1)
        wp.launch(kernels._write_tables, dim=n, inputs=[keys, self.group_rank[:n], self.cell_rank[:n], node_bits],
                  outputs=[self.group_start, self.group_end, self.group_cell, self.cell_end], device=dev)
        wp.launch(kernels._gather_table_info, dim=1, inputs=[self.group_rank[:n], self.cell_rank[:n]],
                  outputs=[self.table_info], device=dev)
        if slab.enabled:
            wp.launch(kernels._compute_group_slabs, dim=groups,
                      inputs=[self.entry_face, self.group_start, self.group_end, self.group_cell, self.cell_end,
                              slab],
                      outputs=[self.group_axis, self.group_slab], device=dev)
        # The rank buffers are free once the tables are written: they hold the rows per group.
        row_count = self.group_rank[:groups]
        row_end = self.cell_rank[:groups]
        self.work_counts.zero_()
        wp.launch(kernels._plan_rows, dim=groups,
                  inputs=[groups, self.entry_key, self.entry_face, self.group_start, self.group_end, self.group_cell,
                          self.cell_end, self.group_axis, self.group_slab, slab, check_keys],
                  outputs=[self.group_mask, row_count, self.work_counts], device=dev)
        wp.utils.array_scan(row_count, row_end, inclusive=True)
        wp.launch(kernels._gather_row_info, dim=1, inputs=[row_end, self.work_counts], outputs=[self.table_info],
                  device=dev)
        info = self.table_info.numpy()
        rows = int(info[2])
        self.stats.groups = int(info[0])
        self.stats.cells = int(info[1])
        self.stats.rows = rows
        self.stats.face_tests = int(info[3])
        self.stats.slab_tests = int(info[4])
        self.stats.bv_tests = self.stats.face_tests + self.stats.slab_tests
        self.stats.same_node_tests = int(info[5])
        if rows == 0:
            return
        if rows > self.row_capacity:
            self._allocate_rows(int(rows * _GROWTH) + 1)
        wp.launch(kernels._write_rows, dim=groups,
                  inputs=[groups, self.entry_key, self.group_start, self.group_end, self.group_cell, self.cell_end,
                          self.group_mask, slab.enabled, check_keys, row_count, row_end],
                  outputs=[self.row_span, self.row_work], device=dev)
        wp.utils.array_scan(self.row_work[:rows], self.row_scan[:rows], inclusive=True)

    def _test_pairs(self, face_lower: wp.array, face_upper: wp.array, grid: kernels.GridArgs) -> None:
        """One thread per BV test, in batches; grows the pair buffer and re-runs on overflow. Sync point 5."""
        tables = kernels.TableArgs()
        tables.entry_key = self.entry_key
        tables.entry_face = self.entry_face
        tables.group_start = self.group_start
        tables.group_end = self.group_end
        tables.row_span = self.row_span
        tables.row_work = self.row_work
        tables.row_scan = self.row_scan
        tables.row_count = self.stats.rows
        total = self.stats.face_tests
        while True:
            self.counts.zero_()
            per_thread = self.tests_per_thread
            for first in range(0, total, self.tests_per_launch):
                end = min(total, first + self.tests_per_launch)
                threads = (end - first + per_thread - 1) // per_thread
                wp.launch(kernels._test_bounding_volumes, dim=threads,
                          inputs=[face_lower, face_upper, self.faces, int(self.skip_adjacent), grid,
                                  tables, first, end, per_thread, self.pair_capacity],
                          outputs=[self.counts, self.pairs], device=self.device)
            counts = self.counts.numpy()
            found = int(counts[0])
            if found <= self.pair_capacity:
                break
            if found > MAX_PAIRS:
                raise CapacityError(f"spatial hash pair buffer: {found} pairs exceed {MAX_PAIRS}; "
                                    "use smaller boxes or split the scene")
            self._allocate_pairs(min(MAX_PAIRS, int(found * _GROWTH)))
            self.stats.reruns += 1
        self._pair_count = found
        self.stats.triangle_pairs = found

    def _sort_pairs(self) -> None:
        """Radix-sort the emitted pairs on a * face_count + b, so the output is deterministic."""
        count = self._pair_count
        if count == 0:
            return
        m = self.face_count
        wp.launch(kernels._compute_pair_keys, dim=count, inputs=[self.pairs, m], outputs=[self.pair_keys],
                  device=self.device)
        key_bits = max(1, (m * m - 1).bit_length())
        wp.utils.radix_sort_pairs(self.pair_keys, self.pairs, count, 0, key_bits)
