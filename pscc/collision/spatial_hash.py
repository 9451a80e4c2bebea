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
a token-position rule emits each overlapping face pair from exactly one cell. Calls with many BV
tests per entry first compare 4-byte *cell codes* (each box end as a fifteenth of the cell, a lower end
in an earlier cell as 0, packed so that one subtraction compares all six ends; the lower fields also
decide the token rule) and load the boxes only where they overlap and the cell holds the token; on runs
of consecutive entries the *code masks* (bit masks of the codes per 64 entries) find those 64 at a time. A face
whose box is too large for the grid (a *wide* face: a ground quad, a flung vertex's swept box) is left
out of it and of the cell size, and box-tested against every face instead
(:mod:`pscc.collision._wide_face_kernels`). See ``docs/spatial-hash.md`` for the derivations.

Device buffers of :class:`SpatialHash` (E = entries, G = groups, C = cells, R = work rows, P = pairs;
every buffer has a fixed capacity, and kernels run at it and stop at the device counts):

=========================  ====================  ===========================================================
buffer                     shape, dtype          meaning
=========================  ====================  ===========================================================
scene                      (11,) float64         min corner, max corner, axis-length sum of the faces in the
                                                 grid; bad boxes; the wide-cell search (round's cell,
                                                 accepted cell, ended)
chunk_extent               (chunks,) vec3        largest box extent per axis of each scene chunk
wide_faces                 (W,) int32            the call's wide faces, sorted (W = min(max_wide_faces,
                                                 face_count / 8); docs/spatial-hash.md §6a)
grid                       (1,) GridState        origin, cell size, dims and slab margin of this call
loop_flag                  (1,) int32            condition of the grid loop (``wp.capture_while``)
face_cells / face_end      (face_count,) int64   cells a face's box overlaps / inclusive scan (entry ends);
                                                 face_cells first holds the ``face_order`` marks
entry_key / entry_value    (2 E,) int64 / int64  {cell, node} key of each entry, and its face (low 32 bits) and
                                                 cell code (high 32 bits: its box ends as fifteenths of its
                                                 cell, written by the fill), sorted by key (the whole capacity
                                                 is sorted: unused slots hold the largest key; the second half
                                                 is radix-sort scratch); ``entry_face`` / ``entry_code`` are
                                                 strided views of the two halves
group_rank / cell_rank     (E,) int32            1-based group / cell of each sorted entry (scans of heads)
group_start / group_end    (E,) / (G,) int32     entry range of group g (triangleHashTable row g);
                                                 group_start first holds the run-head flags
group_cell                 (G,) int32            cell rank of group g (workLoadHashTable row of g)
cell_end                   (E,) int32            one past the last entry of cell c (first the cell-head flags)
code_masks                 (96 ceil(E / 64),)    per block of 64 sorted entries, per axis and quantised end,
                           uint64                the entries whose lower end is at most / upper end at least
                                                 it (:mod:`pscc.collision._code_mask_kernels`; with the codes)
group_axis / group_slab    (S,) vec3 / vec2      slab test only: axis of group g / (min, max) of its
                                                 faces' vertices on the axis (1 slot when off); S, the
                                                 slab capacity, grows with the groups of slab-testing
                                                 calls only
group_mask                 (S,) uint64           slab test only: bit t = the t-th later group of the cell
                                                 passed (or was not tested)
group_skip                 (S,) vec3i            slab test only: largest later group of g's cell, and the
                                                 next later groups large enough to be slab-tested with a
                                                 group of one / two entries (lets the row plan pass
                                                 groups too small to slab-test in O(1))
group_sphere               (S,) vec4             slab test only: centre and radius bounding group g's
                                                 vertices (the O(1) bound of the slab test)
slab_policy                (2,) int32            kept across calls: [1 this call slab-tests, or -level of
                                                 the probe backoff; a counter] (docs/spatial-hash.md §3a)
row_count / row_end        (G,) int32            rows of group g / inclusive scan (in the rank buffers)
row_span                   (R,) vec3i            work row r = (g, b_start, b_end): entries of group g
                                                 against entries [b_start, b_end) of its cell
row_work / row_scan        (R,) int64            BV tests of row r = n_g x (b_end - b_start) / inclusive
                                                 scan (searched by the test threads)
pairs / pair_keys          (2 P,) vec2i / int64  emitted face pairs (a < b) and their sort keys a m + b
                                                 (P slots and no keys when ``sort_pairs`` is off)
counts                     (2,) int64            [pairs emitted (keeps counting past P), unused]
info                       (23,) int64           device counters (``_spatial_hash_kernels.INFO_*``)
summary                    (29,) float64         the counters, dims, cell size, pair count and wide cell,
                                                 read at once
=========================  ====================  ===========================================================

Two paths. :meth:`SpatialHash.find_pairs_device` reads nothing back, synchronizes nothing and allocates
nothing, so it can be recorded into a graph: the scene bounds, the cell size and the grid guard (a
``wp.capture_while`` loop that doubles the cell size) are decided by single-thread kernels, and the
later kernels read the device counts. A buffer that is too small is not written past its end: the
stage stops, the true count is kept, and :meth:`SpatialHash.check_capacity` (the sync point: one
read of ``summary``) raises deferred input errors, grows what overflowed and says whether to run
again. :meth:`SpatialHash.find_pairs` is both, repeated until the buffers fit.

The input checks and the kernels' argument structs are in :mod:`pscc.collision.hash_arguments`; the
defaults, buffer limits and :class:`SpatialHashStats` live in
:mod:`pscc.collision.spatial_hash_settings` (re-exported here); the kernels in
:mod:`pscc.collision._spatial_hash_kernels` and :mod:`pscc.collision._hash_row_kernels`.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence

import numpy as np
import warp as wp

from pscc._lanes import row_lanes
from pscc._reductions import PrefixSum
from pscc.collision import _code_mask_kernels as mask_kernels
from pscc.collision import _hash_row_kernels as row_kernels
from pscc.collision import _spatial_hash_kernels as kernels
from pscc.collision import _wide_face_kernels as wide_kernels
from pscc.collision import shared_vertex
from pscc.collision.hash_arguments import check_face_array, diagonal_args, shared_args, slab_args
from pscc.collision.scratch import (
    Lender,
    TableSpec,
    check_lender,
    place_tables,
    scratch_lenders,
    strided_view,
    view,
)
from pscc.collision.spatial_hash_settings import (
    CELL_CODE_MIN_TESTS,
    CODE_MASK_MIN_RUN,
    DEFAULT_CELL_SIZE_FACTOR,
    DEFAULT_MAX_MEAN_CELLS_PER_FACE,
    DEFAULT_MAX_WIDE_FACES,
    DEFAULT_SLAB_EXACT_MIN_WORK,
    DEFAULT_SLAB_MIN_WORK,
    DEFAULT_TEST_THREADS,
    GROWTH,
    MAX_ENTRIES,
    MAX_GRID_CELLS,
    MAX_PAIRS,
    MIN_CELL_BITS,
    SCENE_CHUNKS,
    SLAB_GROUP_COST,
    SLAB_PROBE_BACKOFF,
    SLAB_PROBE_INTERVAL,
    SLAB_TEST_COST,
    TESTS_PER_LAUNCH,
    WIDE_FACE_MIN_CELLS,
    WIDE_FACE_SHARE,
    SpatialHashStats,
    check_integer,
    check_positive,
    raise_counted_input_errors,
)
from pscc.errors import CapacityError, InputError
from pscc.geometry.dop import vec10

__all__ = [
    "CELL_CODE_MIN_TESTS",
    "CODE_MASK_MIN_RUN",
    "DEFAULT_CELL_SIZE_FACTOR",
    "DEFAULT_MAX_MEAN_CELLS_PER_FACE",
    "DEFAULT_MAX_WIDE_FACES",
    "DEFAULT_SLAB_EXACT_MIN_WORK",
    "DEFAULT_SLAB_MIN_WORK",
    "DEFAULT_TEST_THREADS",
    "MAX_ENTRIES",
    "MAX_GRID_CELLS",
    "MAX_PAIRS",
    "MIN_CELL_BITS",
    "TESTS_PER_LAUNCH",
    "SpatialHash",
    "SpatialHashStats",
]

wp.set_module_options({"enable_backward": False})

class SpatialHash:
    """Spatial-hashing broad phase over face pairs with the paired {CellId, NodeId} key.

    Faces with the same node id are never paired. Give every face its own id (``node_id=None``)
    for plain spatial hashing, the normal-cone-test-front node of each face for PSCC, or one id
    per rigid body to skip the pairs inside each body. The pair set is exact: all face pairs
    whose closed boxes overlap and whose node ids differ, each once, sorted by (a, b). The grid
    changes only the cost, never the result. Buffer layout in the module docstring.

    Sync point: :meth:`check_capacity` (one read of the device counters). :meth:`find_pairs_device`
    reads nothing back and can be recorded into a graph; :meth:`find_pairs` runs both until the
    buffers fit.

    Args:
        face_count: faces m (the length of every per-face array).
        device: Warp device (``None``: the default device).
        cell_size_factor: k in cell size = k x mean over faces of the mean box axis length.
        faces: (face_count,) ``wp.vec3i`` vertex ids, needed only for ``skip_adjacent``,
            ``group_slab_test`` and calls with ``certify_shared``.
        skip_adjacent: drop pairs that share a vertex (default False: such pairs can still
            collide through their other features, so the narrow phase usually wants them).
        max_mean_cells_per_face: grid guard; more entries than this times face_count double
            the cell size (>= 1).
        pair_capacity: initial pair slots (default 4 x face_count); grown to the exact need.
        tests_per_launch: bounds the test launch to ceil(tests_per_launch / tests_per_thread)
            threads (and to ``test_threads``); the launch size is fixed at construction.
        tests_per_thread: the fewest BV tests each thread of the test kernel runs back to back (a
            thread runs a contiguous chunk of max(this, ceil(tests / threads)) tests, found with one
            binary search). ``None``: 1 on a GPU (one thread per BV test while the tests fit the
            launch, as in the paper) and 64 on the CPU, whose kernel threads run one after the other.
            Either way every thread gets the same amount of work.
        sort_pairs: sort the emitted pairs by (a, b) (deterministic order on every device). Without
            sorting, the order follows the atomic appends (deterministic on the CPU only) and the
            pair buffer needs half the memory; the detector sorts its final results anyway.
        group_slab_test: test two groups of a cell as wholes before their face pairs (needs
            ``faces``, and positions on every :meth:`find_pairs` call that passes node ids). The
            pairs are then those whose boxes overlap, whose node ids differ and whose groups are not
            separated along a group axis: a superset of the pairs closer than twice the half
            distance, a subset of the box pairs.
        slab_min_work: slab-test two groups only when they would need this many face tests.
        slab_exact_min_work: when the slab test's O(1) bound of the smaller group does not separate two
            groups, project the smaller group's vertices one by one only when the groups would need this
            many face tests (at least ``slab_min_work`` to matter).
        cell_code_min_tests: a call whose test pass runs at least this many BV tests per entry first
            compares the entries' 4-byte cell codes (each box end as a fifteenth of the cell, read in
            entry order) and loads the boxes only where the codes overlap; the pairs are the same
            either way (the codes never reject overlapping boxes). 0: always; 2^31: never. The
            choice is made on the device, so a recorded graph makes it anew on every replay.
        code_mask_min_run: with the codes, entry a's tests against a run of at least this many
            consecutive entries of its row read the *code masks* instead of one code per entry: per
            block of 64 sorted entries, one word per axis and quantised end holds the entries whose
            lower end is at most / upper end at least that value, so nine words give the entries of
            the block that pass a's code test (:mod:`pscc.collision._code_mask_kernels`). The pairs are
            the same. 1: always; 2^31 - 1: never.
        max_wide_faces: most *wide* faces a call leaves out of the grid: faces whose box covers more
            than max(64, face_count / 8) cells of the call's first cell size (a ground quad, a
            collider's large triangle, a vertex flung far). Each is box-tested against every face
            instead, and neither its cells nor its length reach the grid, so it does not coarsen the
            cell size for everything else (:mod:`pscc.collision._wide_face_kernels`). A call that finds
            more (or more than face_count / 8) inserts every face. 0: never. The pairs are the same.
        test_threads: threads of the test launch (``None``: ``DEFAULT_TEST_THREADS``, 1 on the CPU); the
            pairs and their order are the same for any count.

    Raises:
        InputError: invalid arguments.

    Allocates: yes (every buffer at its initial capacity). Capture-safe: no.
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
        slab_exact_min_work: int = DEFAULT_SLAB_EXACT_MIN_WORK,
        cell_code_min_tests: int = CELL_CODE_MIN_TESTS,
        code_mask_min_run: int = CODE_MASK_MIN_RUN,
        max_wide_faces: int = DEFAULT_MAX_WIDE_FACES,
        test_threads: int | None = None,
    ) -> None:
        self.sort_pairs = bool(sort_pairs)
        self.group_slab_test = bool(group_slab_test)
        self.slab_min_work = check_integer(slab_min_work, "slab_min_work", 1, None, "pass a positive integer such as 8")
        self.slab_exact_min_work = check_integer(slab_exact_min_work, "slab_exact_min_work", 1, None,
                                                 "pass a positive integer such as 64")
        check_integer(face_count, "face_count", 0, None, "pass the number of faces")
        if face_count > MAX_ENTRIES:
            raise InputError("argument", "face_count", f"{face_count} faces exceed {MAX_ENTRIES}",
                             "split the scene into several hashes")
        if pair_capacity is not None:
            check_integer(pair_capacity, "pair_capacity", 0, None, "pass a non-negative integer or None")
        self.device = wp.get_device(device)
        self._scan = PrefixSum(self.device)  # allocation-free inside the grid loop (and a step's loop) on CUDA
        if tests_per_thread is None:
            tests_per_thread = 1 if self.device.is_cuda else 64
        self.tests_per_thread = check_integer(tests_per_thread, "tests_per_thread", 1, None,
                                              "pass a positive integer or None")
        self.cell_code_min_tests = check_integer(
            cell_code_min_tests, "cell_code_min_tests", 0, 2**31,
            f"pass {CELL_CODE_MIN_TESTS} (the default), 0 to always use the codes or 2^31 to never")
        """BV tests per live entry from which a call compares cell codes first (:data:`CELL_CODE_MIN_TESTS`)."""
        self.code_mask_min_run = check_integer(
            code_mask_min_run, "code_mask_min_run", 1, 2**31 - 1,
            f"pass {CODE_MASK_MIN_RUN} (the default), 1 to always use the code masks or 2^31 - 1 to never")
        """Row segments of at least this many entries find code-test passes through the code masks
        (:data:`CODE_MASK_MIN_RUN`)."""
        check_integer(max_wide_faces, "max_wide_faces", 0, MAX_ENTRIES,
                      f"pass {DEFAULT_MAX_WIDE_FACES} (the default) or 0 to insert every face in the grid")
        self.wide_capacity = min(int(max_wide_faces), int(face_count) // WIDE_FACE_SHARE)
        """Most wide faces a call uses (0: none): ``max_wide_faces``, at most face_count / 8."""
        self.wide_limit = float(max(WIDE_FACE_MIN_CELLS, face_count / WIDE_FACE_SHARE))
        """Cells of the first cell size above which a face is wide."""
        self.face_count = int(face_count)
        self.cell_size_factor = check_positive(cell_size_factor, "cell_size_factor")
        self.max_mean_cells_per_face = check_positive(max_mean_cells_per_face, "max_mean_cells_per_face")
        if self.max_mean_cells_per_face < 1.0:
            raise InputError("argument", "max_mean_cells_per_face", f"{max_mean_cells_per_face!r} < 1",
                             "pass a value >= 1 (every face overlaps at least one cell)")
        self.tests_per_launch = check_integer(tests_per_launch, "tests_per_launch", 1, None,
                                              "pass a positive integer such as 2**24")
        self.skip_adjacent = bool(skip_adjacent)
        m = self.face_count
        self.vertex_bound = 0
        """One past the largest vertex id of ``faces`` (0 without faces): positions must cover it."""
        self.faces_given = faces is not None
        """Whether the caller gave ``faces`` (the slab test and ``certify_shared`` need them)."""
        if faces is not None:
            check_face_array(faces, "faces", wp.vec3i, self.face_count, self.device)
            self.faces = faces  # the caller's (not counted in device_bytes)
            if m > 0:
                # The slab test and the certificate read positions[faces]: one host read here lets
                # every call check them.
                self.vertex_bound = int(faces.numpy().max()) + 1
        elif self.skip_adjacent or self.group_slab_test:
            option = "skip_adjacent" if self.skip_adjacent else "group_slab_test"
            raise InputError("argument", "faces", f"{option}=True needs the faces' vertex ids",
                             f"pass faces=(face_count,) wp.vec3i or leave {option} False")
        else:
            self.faces = wp.zeros(1, dtype=wp.vec3i, device=self.device)
        dev = self.device
        chunks = max(1, min(SCENE_CHUNKS, math.isqrt(max(m, 1) - 1) + 1))  # about sqrt(m): SCENE_CHUNKS
        self._chunk_size = max(1, -(-m // chunks))
        self._chunk_count = max(1, -(-m // self._chunk_size))
        self.chunk_lower = wp.empty(self._chunk_count, dtype=wp.vec3, device=dev)
        self.chunk_upper = wp.empty(self._chunk_count, dtype=wp.vec3, device=dev)
        self.chunk_length_sum = wp.empty(self._chunk_count, dtype=wp.float64, device=dev)
        self.chunk_bad = wp.empty(self._chunk_count, dtype=wp.int32, device=dev)
        self.chunk_extent = wp.empty(self._chunk_count, dtype=wp.vec3, device=dev)
        self.chunk_long_sum = wp.empty(self._chunk_count, dtype=wp.float64, device=dev)
        self.chunk_long_count = wp.empty(self._chunk_count, dtype=wp.int32, device=dev)
        self.wide_faces = wp.zeros(max(1, self.wide_capacity), dtype=wp.int32, device=dev)
        self.scene = wp.zeros(11, dtype=wp.float64, device=dev)
        self.grid = wp.zeros(1, dtype=kernels.GridState, device=dev)
        self.loop_flag = wp.zeros(1, dtype=wp.int32, device=dev)
        self.face_cells = wp.empty(max(1, m), dtype=wp.int64, device=dev)
        self.face_end = wp.empty(max(1, m), dtype=wp.int64, device=dev)
        self.grid_max = wp.zeros(4, dtype=wp.int32, device=dev)
        self.info = wp.zeros(kernels.INFO_SIZE, dtype=wp.int64, device=dev)
        self.slab_policy = wp.array([1, 0], dtype=wp.int32, device=dev)  # SlabArgs.policy: the first call tests
        self.counts = wp.zeros(2, dtype=wp.int64, device=dev)
        self.summary = wp.zeros(kernels.SUMMARY_SIZE, dtype=wp.float64, device=dev)
        self.own_node_id = wp.array(np.arange(m, dtype=np.int32), dtype=wp.int32, device=dev)
        self._no_diagonals = wp.empty(0, dtype=vec10, device=dev)
        kind = "cuda" if self.device.is_cuda else "cpu"
        threads = DEFAULT_TEST_THREADS[kind] if test_threads is None else check_integer(
            test_threads, "test_threads", 1, 2**30, "pass a positive integer or None")
        self.test_threads = max(1, min(threads, -(-tests_per_launch // self.tests_per_thread)))
        self.cell_bits = min(31, max(MIN_CELL_BITS, m.bit_length()))
        self._lent: wp.array | None = None
        self._scratch_source: Callable[[], Sequence[wp.array]] | None = None
        self._scratch_key: tuple[tuple[int, int], ...] = ()
        self._lent_names: set[str] = set()
        self._allocate_entries(max(1, 4 * m))
        capacity = 4 * m if pair_capacity is None else pair_capacity
        self._allocate_pairs(max(1, min(MAX_PAIRS, capacity)))
        self._allocate_rows(max(1, m // 4))
        self._pair_count = 0
        self._pair_reruns = 0
        self._last_call: tuple[bool, int] | None = None
        self._last_slab = False
        self._stats = SpatialHashStats()
        self._stats_source: tuple[np.ndarray | None, int] | None = None  # (summary or None: unread, reruns)

    # ------------------------------------------------------------------ buffers

    def lend_scratch(self, buffer: wp.array | None,
                     scratch: Callable[[], Sequence[wp.array]] | None = None) -> None:
        """Let the per-call tables (entries, groups, slab tables, rows and the pairs; see
        :meth:`_place_tables`) live in lent memory, as many as fit (:func:`pscc.collision.scratch.place_tables`:
        the pairs first, then the largest tables); the others keep buffers of their own.

        Args:
            buffer: a buffer that holds nothing its lender needs from the start of a
                :meth:`find_pairs_device` call until the caller has read that call's :attr:`pairs`, and
                whose lender never reads what the hash leaves there. Any table may go there, the pairs
                included. The solver lends its BSR values: they are rewritten at the start of every
                integration and dead from its end to the next one, the stretch in which the broad phase,
                the CCD rounds and the intersection check hash and turn the pairs into feature pairs.
            scratch: a function giving more buffers (read at every call, as their owner may replace
                them), dead from the start of a call until its end: every table but the pairs may go
                there. The solver's detector lends its candidate pairs and times of impact, which the
                broad phase rewrites from the hash's pairs and which the step reads no more once its
                springs are built.

        Counters and stats keep buffers of their own. ``None`` takes a loan back. Allocates: the tables
        again. Capture-safe: no.
        """
        if buffer is not None:
            check_lender(buffer, self.device, "buffer")
        self._lent = buffer
        self._scratch_source = scratch
        self._place_tables()

    def _lenders(self) -> list[Lender]:
        """The lent buffers now: ``buffer`` first (it may hold the pairs), then the scratch buffers."""
        lenders = [] if self._lent is None else [Lender(self._lent, holds_outputs=True)]
        return lenders + scratch_lenders(self._scratch_source, self.device)

    def refresh_loans(self) -> bool:
        """Place the tables again if a scratch lender replaced its buffers since they were placed (each
        :meth:`find_pairs_device` call checks; a caller that resizes a lender may call it at once, so
        that a graph recorded next allocates nothing). Returns whether they moved. Allocates: only then.
        Capture-safe: yes while no lender changed."""
        if self._scratch_source is None:
            return False
        if tuple((a.ptr, a.capacity) for a in self._scratch_source()) == self._scratch_key:
            return False
        self._place_tables()
        return True

    def _allocate_entries(self, capacity: int) -> None:
        self.entry_capacity = capacity
        if not hasattr(self, "group_capacity"):
            self._allocate_groups(max(1, capacity // 4))  # places the tables
        else:
            self.group_capacity = max(1, min(self.group_capacity, capacity))
            self._place_tables()

    def _allocate_groups(self, capacity: int) -> None:
        """Per-group tables, sized by the group count (far below the entry count on cloth); never
        more slots than entries (the rank buffers of the entries hold the per-group row counts)."""
        self.group_capacity = max(1, min(capacity, self.entry_capacity))
        if not hasattr(self, "group_axis"):
            self._allocate_slabs(self.group_capacity if self.group_slab_test else 1)
        self._place_tables()

    def _allocate_slabs(self, capacity: int) -> None:
        """Per-group slab-test tables, sized by the groups of the calls that slab-test (calls without
        node ids, e.g. an intersection check sharing this hash, have one group per face and never
        touch them)."""
        self.slab_capacity = max(1, int(capacity))
        self._place_tables()

    def _allocate_rows(self, capacity: int) -> None:
        """Work rows, sized by the row count (at most the group count without the slab test)."""
        self.row_capacity = capacity
        self._place_tables()

    def _place_tables(self) -> None:
        """(Re)make the per-call tables of entries, groups and rows at their capacities: in lent memory
        (:meth:`lend_scratch`) where they fit, else in buffers of their own. Their contents live within
        one call, so none is kept; only the pairs outlive it."""
        if not hasattr(self, "slab_capacity"):
            return  # still in the constructor: placed once the group tables have a size
        n, g, slabs = self.entry_capacity, self.group_capacity, self.slab_capacity
        rows = getattr(self, "row_capacity", 1)
        # Sorting the pairs needs twice the slots (radix-sort scratch) and a key per pair.
        pair_slots = 2 * getattr(self, "pair_capacity", 1) if self.sort_pairs else getattr(self, "pair_capacity", 1)
        tables = [TableSpec("entry_key", 2 * n, wp.int64), TableSpec("entry_value", 2 * n, wp.int64),
                  TableSpec("code_masks", mask_kernels.block_count(n) * mask_kernels.WORDS_PER_BLOCK, wp.uint64),
                  TableSpec("cell_end", n, wp.int32), TableSpec("group_end", g, wp.int32),
                  TableSpec("group_cell", g, wp.int32), TableSpec("row_span", rows, wp.vec3i),
                  TableSpec("row_work", rows, wp.int64), TableSpec("row_scan", rows, wp.int64),
                  TableSpec("group_axis", slabs, wp.vec3), TableSpec("group_slab", slabs, wp.vec2),
                  TableSpec("group_mask", slabs, wp.uint64), TableSpec("group_skip", slabs, wp.vec3i),
                  TableSpec("group_sphere", slabs, wp.vec4),
                  TableSpec("pairs", pair_slots, wp.vec2i, output=True),
                  TableSpec("pair_keys", pair_slots if self.sort_pairs else 1, wp.int64)]
        lenders = self._lenders()
        placed, self._lent_names = place_tables(tables, lenders, self.device)
        self._scratch_key = tuple((lender.buffer.ptr, lender.buffer.capacity)
                                  for lender in lenders if not lender.holds_outputs)
        for name, table in placed.items():
            setattr(self, name, table)
        # The second halves of the entry buffers are the radix sort's scratch. Everything that reads the
        # ranks and the group starts runs after the sort and within the same call, so they live there
        # (views, not allocations: 12 bytes per entry slot less).
        self.group_rank = view(self.entry_key, 8 * n, n, wp.int32)
        self.cell_rank = view(self.entry_key, 12 * n, n, wp.int32)
        # Each sorted value is the entry's face (low half) and its cell code (high half, little-endian).
        self.entry_face = strided_view(self.entry_value, 0, n, wp.int32, 8)
        self.entry_code = strided_view(self.entry_value, 4, n, wp.uint32, 8)
        # group_start / cell_end first hold the head flags that are scanned into the ranks.
        self.group_start = view(self.entry_value, 8 * n, n, wp.int32)
        # The rank buffers are free once the tables are written: they hold the rows per group (views made
        # here, when the tables are placed, so the device path makes none).
        self.row_count = self.group_rank[:g]
        self.row_end = self.cell_rank[:g]

    def _allocate_pairs(self, capacity: int) -> None:
        self.pair_capacity = capacity
        self._place_tables()

    @property
    def device_bytes(self) -> dict[str, int]:
        """Bytes held on the device, per buffer name."""
        # group_rank, cell_rank and group_start are views into the entry buffers' sort scratch.
        names = ("chunk_lower", "chunk_upper", "chunk_length_sum", "chunk_bad", "chunk_extent", "chunk_long_sum",
                 "chunk_long_count", "wide_faces", "scene", "grid", "loop_flag", "face_cells", "face_end", "grid_max",
                 "info", "counts", "summary", "own_node_id", "slab_policy", "faces", "entry_key", "entry_value",
                 "code_masks", "cell_end", "group_end", "group_cell", "group_axis", "group_slab", "group_mask",
                 "group_skip", "group_sphere", "row_span", "row_work", "row_scan", "pairs", "pair_keys")
        # Tables in a lent buffer (lend_scratch) and faces passed in are the caller's memory: counted as 0.
        borrowed = self._lent_names | ({"faces"} if self.faces_given else set())
        return {name: 0 if name in borrowed else int(getattr(self, name).capacity) for name in names}

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
        face_diagonal_lower: wp.array | None = None,
        face_diagonal_upper: wp.array | None = None,
        certify_shared: bool = False,
    ) -> tuple[wp.array, int]:
        """All face pairs (a < b) whose closed boxes overlap and whose node ids differ (with the
        group slab test: less the pairs of groups separated along a group axis, none of which is
        closer than twice ``half_distance``).

        The device path (:meth:`find_pairs_device`), then the sync point :meth:`check_capacity`;
        again while a buffer had to grow.

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
                the node bits. Checked on the device to be a permutation; a grouping it breaks is
                caught by the same-node counter.
            face_diagonal_lower: (face_count,) ``vec10`` lower ends of the faces' diagonal slabs
                (:mod:`pscc.geometry.dop`, grown by the same half distance as the boxes), or ``None``.
                With them (both or neither) a face pair is emitted only when its slabs overlap on the
                ten diagonals as well: the faces' 26-DOPs overlap.
            face_diagonal_upper: (face_count,) ``vec10`` upper ends, or ``None``.
            certify_shared: also drop pairs of faces that share a vertex or an edge and are certified
                to meet only there (:meth:`find_pairs_device`); needs ``faces`` and ``positions_t0``.

        Returns:
            ``(pairs, count)``: a (count,) ``wp.vec2i`` view of the internal buffer, sorted by
            (a, b) when ``sort_pairs``, valid until the next call, and the number of pairs.

        Raises:
            InputError: wrong array, non-finite or inverted box, bad cell size, a node id outside
                [0, node_id_bound), a ``face_order`` that is no permutation or splits a node.
            CapacityError: more pairs than int32 indexing allows.

        Allocates: when a buffer grows. Capture-safe: no.
        """
        self._pair_reruns = 0
        while True:
            self.find_pairs_device(face_lower, face_upper, node_id, positions_t0=positions_t0,
                                   positions_t1=positions_t1, half_distance=half_distance,
                                   node_id_bound=node_id_bound, face_order=face_order, cell_size=cell_size,
                                   face_diagonal_lower=face_diagonal_lower,
                                   face_diagonal_upper=face_diagonal_upper, certify_shared=certify_shared)
            if self.check_capacity():
                return self.pairs[: self._pair_count], self._pair_count

    def find_pairs_device(
        self,
        face_lower: wp.array,
        face_upper: wp.array,
        node_id: wp.array | None = None,
        *,
        positions_t0: wp.array | None = None,
        positions_t1: wp.array | None = None,
        half_distance: float = 0.0,
        node_id_bound: int | None = None,
        face_order: wp.array | None = None,
        cell_size: float | None = None,
        order_is_node_contiguous: bool = False,
        face_diagonal_lower: wp.array | None = None,
        face_diagonal_upper: wp.array | None = None,
        certify_shared: bool = False,
    ) -> None:
        """The pairs of :meth:`find_pairs`, left on the device: no host read, synchronization,
        allocation or upload, so the call can be recorded into a graph.

        Results: ``self.pairs`` (the buffer) and ``self.counts[0]`` (int64, pairs emitted; the
        valid rows are the first min(counts[0], pair_capacity), sorted by (a, b) when
        ``sort_pairs``). Buffers that are too small are never written past their end: the stage
        stops and keeps its true count, and :meth:`check_capacity` (the sync point the caller
        chooses) grows them and says whether to run again. Input problems found on the device
        (non-finite or inverted boxes, node ids out of range, a ``face_order`` that is no
        permutation or splits a node) are raised by :meth:`check_capacity` as well.

        The grid loop (cell size doubling) is a ``wp.capture_while``: in a graph it stays on the
        device; called eagerly on a GPU, Warp reads its condition once per iteration.

        Args:
            face_lower: (face_count,) ``wp.vec3`` lower box corners, as for :meth:`find_pairs`.
            face_upper: (face_count,) ``wp.vec3`` upper box corners.
            node_id: (face_count,) ``wp.int32`` node ids, or ``None`` (every face its own node).
            positions_t0: vertex positions for the group slab test (with node ids).
            positions_t1: positions at the end of the step (CCD), or ``None``.
            half_distance: the half distance the boxes were grown by (length units, >= 0).
            node_id_bound: node ids lie in [0, node_id_bound) (checked on the device), or ``None``.
            face_order: node-contiguous permutation of the faces (checked on the device), or ``None``.
            cell_size: grid cell edge, or ``None`` (``cell_size_factor`` x the mean box axis length).
            order_is_node_contiguous: the caller guarantees that ``face_order`` keeps the faces of every
                node together (as a BVH's leaf order does for node ids that are BVH nodes, the
                detector's case). The device check that finds a split node is then left out: it
                compares every group with every later group of its cell, O(groups^2) per cell. A wrong
                promise costs pairs, not misses: two groups of one node in a cell are then tested like
                groups of two nodes (extra face pairs of one node), never dropped.
            face_diagonal_lower: the faces' diagonal slabs, as for :meth:`find_pairs`, or ``None``.
            face_diagonal_upper: their upper ends, or ``None``.
            certify_shared: drop a pair that shares a vertex or an edge when the normal-cone
                certificate of just those two faces holds (:mod:`pscc.collision.shared_vertex`: they
                meet only in what they share, at ``positions_t0`` or over the step to
                ``positions_t1``). Needs ``faces`` at construction (without ``skip_adjacent``) and
                the positions.
            Only types, shapes, devices and host scalars are validated here.

        Raises:
            InputError: wrong arrays or scalar arguments.

        Allocates: no (the tables again only when a scratch lender replaced its buffers since the last
        call: :meth:`refresh_loans`). Capture-safe: yes (with the arrays of the recorded call; after
        :meth:`check_capacity` grows a buffer or a lender's buffers change, record again).
        """
        check_face_array(face_lower, "face_lower", wp.vec3, self.face_count, self.device)
        check_face_array(face_upper, "face_upper", wp.vec3, self.face_count, self.device)
        own_nodes = node_id is None
        if own_nodes:
            node_id = self.own_node_id
            node_id_bound = max(1, self.face_count)
        else:
            check_face_array(node_id, "node_id", wp.int32, self.face_count, self.device)
        if node_id_bound is not None and (isinstance(node_id_bound, bool)
                                          or not isinstance(node_id_bound, int | np.integer)
                                          or not 1 <= node_id_bound <= 2**31):
            raise InputError("argument", "node_id_bound", f"{node_id_bound!r} is not an integer in [1, 2^31]",
                             "pass one more than the largest node id, or None")
        fixed_cell_size = 0.0 if cell_size is None else check_positive(cell_size, "cell_size")
        if face_order is not None:
            check_face_array(face_order, "face_order", wp.int32, self.face_count, self.device)
        diagonals = diagonal_args(face_diagonal_lower, face_diagonal_upper, self._no_diagonals, self.face_count,
                                  self.device)
        slab, half = slab_args(self, not own_nodes, positions_t0, positions_t1, half_distance)
        shared = shared_args(self, bool(certify_shared), positions_t0, positions_t1)
        node_bits = kernels.NODE_BITS if node_id_bound is None else max(1, (int(node_id_bound) - 1).bit_length())
        node_limit = 0 if node_id_bound is None else int(node_id_bound)
        self._last_call = (face_order is not None, node_limit)
        self._last_slab = bool(slab.enabled)
        self._pair_count = 0
        self.refresh_loans()
        dev = self.device
        wp.launch(kernels._reset_counters, dim=1, outputs=[self.info, self.counts, self.grid_max], device=dev)
        if self.face_count >= 2:
            self._plan(face_lower, face_upper, face_order, fixed_cell_size, half)
            ordered = face_order is not None
            order = self.own_node_id if face_order is None else face_order
            wp.capture_while(self.loop_flag, self._count_cells, face_lower=face_lower, face_upper=face_upper,
                             node_id=node_id, node_limit=node_limit, order=order, ordered=int(ordered))
            # Faces in node-contiguous order (own ids: face order; else the given order) need only the
            # cell bits sorted.
            self._insert_faces(face_lower, face_upper, node_id, node_bits, order, ordered, own_nodes or ordered)
            self._build_tables(face_lower, face_upper, node_bits, slab, int(ordered and not order_is_node_contiguous))
            self._test_pairs(face_lower, face_upper, diagonals, shared, node_bits)
            if self.wide_capacity > 0:
                self._test_wide_faces(face_lower, face_upper, node_id, diagonals, shared)
            if self.sort_pairs:
                self._sort_pairs()
            if slab.enabled:
                wp.launch(row_kernels._update_slab_policy, dim=1,
                          inputs=[self.info, self.counts, self.pair_capacity, SLAB_TEST_COST, SLAB_GROUP_COST,
                                  SLAB_PROBE_INTERVAL, SLAB_PROBE_BACKOFF],
                          outputs=[self.slab_policy], device=dev)
        wp.launch(kernels._gather_summary, dim=1, inputs=[self.info, self.grid, self.counts],
                  outputs=[self.summary], device=dev)

    def overflow_counters(self) -> list[tuple[wp.array, int, int]]:
        """``(device counter, index, capacity)`` triples: after a device call, a counter above its
        capacity means :meth:`check_capacity` has work to do (a buffer to grow, wider cell bits or a
        deferred input error). For callers that gather overflow flags on the device; the capacities
        change only in :meth:`check_capacity`. Index 4 is the slab tables' capacity against the groups of
        the last call when it slab-tested (never full otherwise)."""
        info = self.info
        slab_groups = self.slab_capacity if self._last_slab else MAX_ENTRIES
        return [(info, kernels.INFO_ENTRIES, self.entry_capacity), (info, kernels.INFO_GROUPS, self.group_capacity),
                (info, kernels.INFO_ROWS, self.row_capacity), (self.counts, 0, self.pair_capacity),
                (info, kernels.INFO_GROUPS, slab_groups),
                (info, kernels.INFO_WANTED_CELLS, 0), (info, kernels.INFO_BAD_BOXES, 0),
                (info, kernels.INFO_BAD_NODES, 0), (info, kernels.INFO_BAD_ORDER, 0)]

    def grow(self, counters: set[int], factor: float = 1.5) -> None:
        """Grow the buffers behind the given :meth:`overflow_counters` indices (0 entries, 1 groups,
        2 rows, 3 pairs, 4 slab tables) by ``factor`` ahead of an overflow (a caller that saw them
        nearly full). A recorded call then holds stale buffers and must be recorded again.

        Allocates: yes. Capture-safe: no.
        """
        if 0 in counters:
            self._allocate_entries(min(MAX_ENTRIES, int(factor * self.entry_capacity) + 1))
        if 1 in counters:
            self._allocate_groups(min(MAX_ENTRIES, int(factor * self.group_capacity) + 1))
        if 4 in counters:
            self._allocate_slabs(min(MAX_ENTRIES, int(factor * self.slab_capacity) + 1))
        if 2 in counters:
            self._allocate_rows(min(MAX_ENTRIES, int(factor * self.row_capacity) + 1))
        if 3 in counters:
            self._allocate_pairs(min(MAX_PAIRS, int(factor * self.pair_capacity) + 1))

    def trim(self, capacities: dict[int, int]) -> None:
        """Shrink the buffers behind the given :meth:`overflow_counters` indices (0 entries, 1 groups,
        2 rows, 3 pairs, 4 slab tables) to the given capacities where those are smaller (a caller that
        saw them far from full for a while). Contents are not kept, so call it between calls only, and
        record graphs again.

        Allocates: when shrinking. Capture-safe: no.
        """
        wanted = {k: max(1, int(v)) for k, v in capacities.items()}
        if 0 in wanted and wanted[0] < self.entry_capacity:
            # Never more group slots than entries (the entry rank buffers hold the per-group rows): the
            # groups shrink first, while the old rank buffers still cover them.
            groups = min(wanted.pop(1, self.group_capacity), wanted[0])
            if groups < self.group_capacity:
                self._allocate_groups(groups)
            self._allocate_entries(wanted[0])
        if 1 in wanted and wanted[1] < self.group_capacity:
            self._allocate_groups(wanted[1])
        if 2 in wanted and wanted[2] < self.row_capacity:
            self._allocate_rows(wanted[2])
        if 3 in wanted and wanted[3] < self.pair_capacity:
            self._allocate_pairs(wanted[3])
        if 4 in wanted and wanted[4] < self.slab_capacity:
            self._allocate_slabs(wanted[4])

    def capacities(self) -> dict[int, int]:
        """The capacities behind :meth:`overflow_counters` indices 0 to 4 (entries, groups, rows, pairs,
        slab tables)."""
        return {0: self.entry_capacity, 1: self.group_capacity, 2: self.row_capacity, 3: self.pair_capacity,
                4: self.slab_capacity}

    @property
    def stats(self) -> SpatialHashStats:
        """The stats of the last :meth:`check_capacity` (made from its counters on first access)."""
        if self._stats_source is not None:
            summary, reruns = self._stats_source
            summary = self.summary.numpy() if summary is None else summary
            self._stats = SpatialHashStats.from_summary(summary, self.face_count, reruns, self.device_bytes)
            self._stats_source = None
        return self._stats

    def check_capacity(self) -> bool:
        """Sync point: read the counters of the last device call (one copy), raise its deferred input
        errors, grow every buffer that overflowed (1.25 x the exact need) and keep them for :attr:`stats`.

        Returns:
            True when everything fit (the results are valid); False when a buffer grew or the sort's
            cell bits were widened: run the device call again (and record it again: grown buffers
            are new arrays).

        Raises:
            InputError: non-finite or inverted boxes, node ids outside [0, node_id_bound), a
                ``face_order`` that is no permutation or splits a node.
            CapacityError: more pairs than int32 indexing allows.

        Allocates: when a buffer grows. Capture-safe: no.
        """
        if self._last_call is None:
            raise InputError("argument", "check_capacity", "no device call has run", "call find_pairs_device first")
        summary = self.summary.numpy()
        info = summary.astype(np.int64).tolist()  # Python ints: cheaper to compare than numpy scalars
        ordered, node_limit = self._last_call
        raise_counted_input_errors(info, ordered, node_limit)
        fits = True
        needs = ((kernels.INFO_ENTRIES, "entry_capacity", MAX_ENTRIES, self._allocate_entries),
                 (kernels.INFO_GROUPS, "group_capacity", MAX_ENTRIES, self._allocate_groups),
                 (kernels.INFO_ROWS, "row_capacity", MAX_ENTRIES, self._allocate_rows))
        for slot, name, limit, allocate in needs:
            need = int(info[slot])
            if need > getattr(self, name):
                allocate(min(limit, int(need * GROWTH) + 1))
                fits = False
        if self._last_slab and int(info[kernels.INFO_GROUPS]) > self.slab_capacity:
            self._allocate_slabs(min(MAX_ENTRIES, int(int(info[kernels.INFO_GROUPS]) * GROWTH) + 1))
            fits = False
        found = int(info[kernels.SUMMARY_PAIRS])
        if found > MAX_PAIRS:
            raise CapacityError(f"spatial hash pair buffer: {found} pairs exceed {MAX_PAIRS}; "
                                "use smaller boxes or split the scene")
        if found > self.pair_capacity:
            self._allocate_pairs(min(MAX_PAIRS, int(found * GROWTH)))
            self._pair_reruns += 1
            fits = False
        wanted = int(info[kernels.INFO_WANTED_CELLS])
        if wanted > 0:
            self.cell_bits = min(31, max(self.cell_bits + 1, (wanted - 1).bit_length()))
            fits = False
        # The stats are made when asked for (:attr:`stats`): a caller that checks every replay pays only
        # for the counters.
        self._stats_source = (summary, self._pair_reruns)
        self._pair_count = min(found, self.pair_capacity) if fits else 0
        if fits:
            self._pair_reruns = 0
        return fits

    def accept_unread(self) -> None:
        """Accept the last call unread (a caller's device verdict, :mod:`pscc.collision.capacity_verdict`, found
        nothing to grow or raise): :attr:`stats` and :meth:`pairs_numpy` read the counters, of the last call then."""
        self._stats_source = (None, self._pair_reruns)
        self._pair_count = -1
        self._pair_reruns = 0

    def pairs_numpy(self) -> np.ndarray:
        """The pairs of the last :meth:`find_pairs` as a (count, 2) int32 array, sorted by (a, b) when
        ``sort_pairs``.

        Allocates: yes (host copy). Capture-safe: no.
        """
        if self._pair_count < 0:
            self._pair_count = min(int(self.summary.numpy()[kernels.SUMMARY_PAIRS]), self.pair_capacity)
        if self._pair_count == 0:
            return np.zeros((0, 2), dtype=np.int32)
        return self.pairs[: self._pair_count].numpy().reshape(-1, 2).astype(np.int32)

    # ------------------------------------------------------------------ stages (device path)

    def _plan(self, face_lower: wp.array, face_upper: wp.array, face_order: wp.array | None,
              fixed_cell_size: float, half_distance: float) -> None:
        """Scene bounds (a deterministic two-level reduction), the face order check, the wide faces and
        the scene without them, then the grid plan: origin, slab margin, first cell size, and the grid
        loop's start flag."""
        dev = self.device
        chunks = self._chunk_count
        wp.launch(kernels._reduce_scene_chunks, dim=chunks,
                  inputs=[face_lower, face_upper, self._chunk_size],
                  outputs=[self.chunk_lower, self.chunk_upper, self.chunk_length_sum, self.chunk_bad,
                           self.chunk_extent], device=dev)
        wp.launch(kernels._reduce_scene_total, dim=1,
                  inputs=[self.chunk_lower, self.chunk_upper, self.chunk_length_sum, self.chunk_bad, chunks],
                  outputs=[self.scene, self.info], device=dev)
        if face_order is not None:
            m = self.face_count
            wp.launch(kernels._clear_marks, dim=m, outputs=[self.face_cells], device=dev)
            wp.launch(kernels._mark_face_order, dim=m, inputs=[face_order], outputs=[self.face_cells, self.info],
                      device=dev)
            wp.launch(kernels._check_marks, dim=m, inputs=[self.face_cells], outputs=[self.info], device=dev)
        if self.wide_capacity > 0:
            self._find_wide_faces(face_lower, face_upper, fixed_cell_size)
        if fixed_cell_size == 0.0:
            wp.launch(wide_kernels._find_long_faces, dim=chunks,
                      inputs=[face_lower, face_upper, self._chunk_size, self.scene, self.info, self.wide_limit,
                              self.chunk_extent],
                      outputs=[self.chunk_long_sum, self.chunk_long_count], device=dev)
            wp.launch(wide_kernels._drop_long_faces, dim=1,
                      inputs=[self.chunk_long_sum, self.chunk_long_count, chunks],
                      outputs=[self.scene, self.info], device=dev)
        wp.launch(kernels._plan_grid, dim=1,
                  inputs=[self.scene, self.face_count, self.cell_size_factor, fixed_cell_size, half_distance,
                          self.wide_limit],
                  outputs=[self.grid, self.info, self.loop_flag], device=dev)

    def _find_wide_faces(self, face_lower: wp.array, face_upper: wp.array, fixed_cell_size: float) -> None:
        """The wide faces (:mod:`pscc.collision._wide_face_kernels`): ``WIDE_ROUNDS`` rounds of the cell
        search, each folding the scene without the faces wide at its cell, then the sorted list."""
        dev = self.device
        chunks = self._chunk_count
        folded = [self.chunk_lower, self.chunk_upper, self.chunk_length_sum]
        wp.launch(wide_kernels._plan_wide_faces, dim=1,
                  inputs=[self.face_count, self.cell_size_factor, fixed_cell_size],
                  outputs=[self.scene, self.info], device=dev)
        for _ in range(wide_kernels.WIDE_ROUNDS):
            wp.launch(wide_kernels._drop_wide_faces, dim=chunks,
                      inputs=[face_lower, face_upper, self._chunk_size, self.scene, self.wide_limit, self.chunk_extent],
                      outputs=[*folded, self.info], device=dev)
            wp.launch(wide_kernels._accept_wide_faces, dim=1,
                      inputs=[*folded, chunks, self.face_count, self.cell_size_factor, fixed_cell_size,
                              self.wide_capacity],
                      outputs=[self.scene, self.info], device=dev)
        wp.launch(wide_kernels._list_wide_faces, dim=chunks,
                  inputs=[face_lower, face_upper, self._chunk_size, self.scene, self.wide_limit, self.chunk_extent],
                  outputs=[self.info, self.wide_faces], device=dev)
        wp.launch(wide_kernels._sort_wide_faces, dim=1, inputs=[self.info], outputs=[self.wide_faces], device=dev)

    def _count_cells(self, face_lower: wp.array, face_upper: wp.array, node_id: wp.array, node_limit: int,
                     order: wp.array, ordered: int) -> None:
        """Body of the grid loop: count the cells of every face, scan, and let the device decide
        whether the grid is final or the cell size doubles (``_check_grid``)."""
        dev = self.device
        m = self.face_count
        max_entries = min(MAX_ENTRIES, max(m, int(self.max_mean_cells_per_face * m)))
        wp.launch(kernels._count_face_cells, dim=m,
                  inputs=[face_lower, face_upper, self.grid, node_id, node_limit, order, ordered],
                  outputs=[self.face_cells, self.grid_max], device=dev)
        self._scan(self.face_cells, self.face_end, inclusive=True)
        wp.launch(kernels._check_grid, dim=1,
                  inputs=[self.face_end, self.scene, max_entries, min(MAX_GRID_CELLS, 1 << self.cell_bits),
                          self.entry_capacity],
                  outputs=[self.grid, self.grid_max, self.info, self.loop_flag], device=dev)

    def _insert_faces(self, face_lower: wp.array, face_upper: wp.array, node_id: wp.array, node_bits: int,
                      order: wp.array, ordered: bool, grouped_fill: bool) -> None:
        """Fill the (key, face) entries, pad the rest of the capacity, sort the whole capacity."""
        dev = self.device
        wp.launch(kernels._fill_entries, dim=self.face_count,
                  inputs=[face_lower, face_upper, node_id, self.face_cells, self.face_end, self.grid, node_bits,
                          order, int(ordered), self.info],
                  outputs=[self.entry_key, self.entry_value], device=dev)
        end_bit = node_bits + self.cell_bits
        wp.launch(kernels._pad_entries, dim=self.entry_capacity, inputs=[self.info, (1 << end_bit) - 1],
                  outputs=[self.entry_key, self.entry_value], device=dev)
        # A stable sort on the cell bits keeps the fill order inside each cell; when that order keeps
        # each node's faces together, the node bits need no sorting.
        first_bit = node_bits if grouped_fill else 0
        wp.utils.radix_sort_pairs(self.entry_key, self.entry_value, self.entry_capacity, first_bit, end_bit)

    def _build_tables(self, face_lower: wp.array, face_upper: wp.array, node_bits: int, slab: kernels.SlabArgs,
                      check_keys: int) -> None:
        """Run heads -> ranks -> group and cell ranges -> slab tests and work rows -> row scan."""
        dev = self.device
        n = self.entry_capacity
        g = self.group_capacity
        wp.launch(kernels._mark_runs, dim=n, inputs=[self.entry_key, node_bits, self.info],
                  outputs=[self.group_start, self.cell_end], device=dev)
        self._scan(self.group_start, self.group_rank, inclusive=True)
        self._scan(self.cell_end, self.cell_rank, inclusive=True)
        wp.launch(kernels._write_tables, dim=n,
                  inputs=[self.entry_key, self.group_rank, self.cell_rank, node_bits, self.info],
                  outputs=[self.group_start, self.group_end, self.group_cell, self.cell_end], device=dev)
        # A slab-testing call uses the groups only when the slab tables hold them too.
        live_limit = min(g, self.slab_capacity) if slab.enabled else g
        wp.launch(kernels._gather_table_info, dim=1, inputs=[self.group_rank, self.cell_rank, live_limit],
                  outputs=[self.info], device=dev)
        lanes = row_lanes(dev, g)  # the group passes are row kernels over the group slots
        tables = row_kernels.GroupTables()
        tables.entry_key, tables.entry_face = self.entry_key, self.entry_face
        tables.group_start, tables.group_end = self.group_start, self.group_end
        tables.group_cell, tables.cell_end = self.group_cell, self.cell_end
        if slab.enabled:
            wp.launch(row_kernels._compute_group_slabs, dim=lanes, inputs=[tables, slab, self.info, lanes],
                      outputs=[self.group_axis, self.group_slab], device=dev)
        wp.launch(row_kernels._plan_rows, dim=lanes, inputs=[
            tables, self.group_axis, self.group_slab, slab, self.grid, check_keys, lanes],
            outputs=[self.group_mask, self.row_count, self.info], device=dev)
        self._scan(self.row_count, self.row_end, inclusive=True)
        wp.launch(row_kernels._gather_row_info, dim=1,
                  inputs=[self.row_end, self.row_capacity, self.test_threads, self.tests_per_thread,
                          self.cell_code_min_tests],
                  outputs=[self.info], device=dev)
        wp.launch(row_kernels._write_rows, dim=lanes, inputs=[
            tables, self.group_mask, slab, check_keys, self.row_count, self.row_end, self.info, lanes],
            outputs=[self.row_span, self.row_work], device=dev)
        self._scan(self.row_work, self.row_scan, inclusive=True)
        mask_kernels.write_code_masks(self.entry_code, self.info, self.code_masks, n, self.code_mask_min_run, dev)

    def _test_pairs(self, face_lower: wp.array, face_upper: wp.array, diagonals: kernels.DiagonalArgs,
                    shared: shared_vertex.SharedVertexArgs, node_bits: int) -> None:
        """The test pass: ``test_threads`` threads, each a contiguous chunk of the live BV tests."""
        tables = kernels.TableArgs()
        tables.entry_key = self.entry_key
        tables.entry_face = self.entry_face
        tables.group_start = self.group_start
        tables.group_end = self.group_end
        tables.row_span = self.row_span
        tables.row_work = self.row_work
        tables.row_scan = self.row_scan
        tables.entry_code = self.entry_code
        tables.code_masks = self.code_masks
        tables.mask_min_run = self.code_mask_min_run
        wp.launch(row_kernels._test_bounding_volumes, dim=self.test_threads,
                  inputs=[face_lower, face_upper, diagonals, shared, self.grid, node_bits,
                          tables, self.info, self.pair_capacity],
                  outputs=[self.counts, self.pairs], device=self.device)

    def _test_wide_faces(self, face_lower: wp.array, face_upper: wp.array, node_id: wp.array,
                         diagonals: kernels.DiagonalArgs, shared: shared_vertex.SharedVertexArgs) -> None:
        """Every face against the wide faces of the call (nothing when there are none): one thread per
        face on a GPU, per scene chunk on the CPU."""
        per_thread = 1 if self.device.is_cuda else self._chunk_size
        wp.launch(wide_kernels._test_wide_faces, dim=-(-self.face_count // per_thread),
                  inputs=[face_lower, face_upper, node_id, self.grid, self.wide_faces, per_thread, diagonals, shared,
                          self.info, self.pair_capacity],
                  outputs=[self.counts, self.pairs], device=self.device)

    def _sort_pairs(self) -> None:
        """Radix-sort the whole pair capacity on a * face_count + b (unused slots last), so the
        output is deterministic."""
        m = self.face_count
        key_bits = max(1, (m * m - 1).bit_length())
        wp.launch(kernels._compute_pair_keys, dim=self.pair_capacity, inputs=[self.counts, m, (1 << key_bits) - 1],
                  outputs=[self.pairs, self.pair_keys], device=self.device)
        wp.utils.radix_sort_pairs(self.pair_keys, self.pairs, self.pair_capacity, 0, key_bits)
