"""Kernels of :class:`pscc.collision.spatial_hash.SpatialHash` (private: only that host imports them).

Everything the host once decided from read-back counts is decided on the device: single-thread
kernels read the counts and write the small ``grid`` state and the ``info`` counters that the
later kernels read; every other kernel runs at a fixed capacity and returns early past the
device count. Thread mappings, in launch order:

=======================================  =============================================================
kernel                                   one thread per
=======================================  =============================================================
``_reset_counters``                      (single thread) zeroes ``info``, the pair counter, grid maxima
``_reduce_scene_chunks``                 chunk of faces (min corner, max corner, axis-length sum)
``_reduce_scene_total``                  (single thread) the whole scene, in a fixed order
``_clear_marks`` ... ``_check_marks``    face (``face_order`` only): each face must be listed once
(:mod:`pscc.collision._wide_face_kernels`)  the wide faces and the scene without them
``_plan_grid``                           (single thread) origin, slab margin, first cell size; starts
                                         the grid loop unless the input is bad
``_count_face_cells``                    face (grid loop body): cells its box overlaps, grid extent
``_check_grid``                          (single thread, loop body) doubles the cell size while the
                                         entries or the grid are too big, else ends the loop
``_fill_entries``                        face: its (key, face and cell code) entries, one per overlapped
                                         cell
``_pad_entries``                         entry slot: unused slots get the largest key (sorted last)
``_mark_runs`` / ``_write_tables``       entry slot: head flags / group ranges, group cell, cell ends
``_gather_table_info``                   (single thread) group and cell counts
(:mod:`pscc.collision._hash_row_kernels`)  group slab test, work rows and the test pass
(:mod:`pscc.collision._wide_face_kernels`)  every face against the wide faces
``_compute_pair_keys``                   pair slot: sort key a * face_count + b (unused: largest)
``_gather_summary``                      (single thread) every counter in one float64 array
=======================================  =============================================================
"""

from __future__ import annotations

import warp as wp

from pscc import tolerances
from pscc.geometry.dop import vec10

wp.set_module_options({"enable_backward": False})

NODE_BITS: int = 32
"""Most low bits of an entry key that hold the node id (its uint32 bit pattern); the cell id sits
above. A call that bounds its node ids uses fewer (``node_bits``), so the sort has less to do."""

MASK_BITS: int = 64
"""Later groups of a cell whose slab test result a group keeps (bits of ``group_mask``); later
groups past these are always tested face by face (conservative)."""

MAX_GRID_CELLS: int = 2**31 - 1  # a CellId must fit in the high 31 bits of a non-negative int64 key

LONG_FACE_RATIO: float = 3.0
"""A grid face whose mean box axis length exceeds this many times the mean over the grid faces is *long*:
left out of the mean that sets the cell size (still in the grid), so that a few colliders' long faces
do not coarsen the cells of the cloth (:mod:`pscc.collision._wide_face_kernels`)."""
_LONG_RATIO = wp.constant(wp.float64(LONG_FACE_RATIO))

# Slots of the int64 ``info`` counters (device). "Live" counts are what the later stages use: the
# count when its buffer holds it, else 0 (the stages after an overflow do nothing).
INFO_ENTRIES: int = 0  # entries of the final grid (may exceed the entry capacity)
INFO_GROUPS: int = 1  # {cell, node} groups (when the entries fit)
INFO_CELLS: int = 2  # non-empty cells (when the entries fit)
INFO_ROWS: int = 3  # work rows (when the groups fit)
INFO_FACE_TESTS: int = 4  # face box tests of the rows
INFO_SLAB_TESTS: int = 5  # group slab tests run
INFO_SAME_NODE: int = 6  # face pairs of one node met in two groups (a face_order that splits a node)
INFO_BAD_BOXES: int = 7  # boxes with NaN/Inf or lower > upper
INFO_BAD_NODES: int = 8  # node ids outside [0, node_id_bound)
INFO_BAD_ORDER: int = 9  # face_order ids out of range, faces listed twice or never
INFO_COARSENINGS: int = 10  # times the cell size was doubled
INFO_WANTED_CELLS: int = 11  # > 0: cells of a grid refused only for the sort's cell bits
INFO_LIVE_ENTRIES: int = 12
INFO_LIVE_GROUPS: int = 13
INFO_LIVE_ROWS: int = 14
INFO_LIVE_TESTS: int = 15  # BV tests the test pass runs
INFO_TEST_CHUNK: int = 16  # BV tests per test thread (a contiguous chunk each)
INFO_CELL_CODES: int = 17  # 1: the test pass reads the entries' cell codes (enough BV tests per entry)
INFO_SLAB_SAVED: int = 18  # face tests of the group pairs the slab test separated
INFO_WIDE_FOUND: int = 19  # faces wide at the round's cell (:mod:`pscc.collision._wide_face_kernels`)
INFO_WIDE_FACES: int = 20  # wide faces left out of the grid (0: none this call)
INFO_WIDE_LISTED: int = 21  # wide faces listed (counter of ``_list_wide_faces``)
INFO_WIDE_TESTS: int = 22  # face box tests against the wide faces
INFO_LONG_FACES: int = 23  # grid faces left out of the mean box length (:mod:`pscc.collision._wide_face_kernels`)
INFO_SIZE: int = 24
"""Slots of ``info``; ``summary`` holds them, then N_x, N_y, N_z, the cell size, the pairs emitted and
the wide cell."""
SUMMARY_DIMS: int = INFO_SIZE
SUMMARY_CELL_SIZE: int = INFO_SIZE + 3
SUMMARY_PAIRS: int = INFO_SIZE + 4
SUMMARY_WIDE_CELL: int = INFO_SIZE + 5
SUMMARY_SIZE: int = INFO_SIZE + 6

_MASK_BITS = wp.constant(MASK_BITS)
_MAX_GRID_CELLS = wp.constant(wp.int64(MAX_GRID_CELLS))
_MAX_GRID_CELLS_F = wp.constant(wp.float64(MAX_GRID_CELLS))
_SLAB_PAD = wp.constant(wp.float64(tolerances.GROUP_SLAB_RELATIVE_PAD))
_BOUND_PAD = wp.constant(wp.float64(tolerances.GROUP_BOUND_RELATIVE_PAD))
_ENTRIES = wp.constant(INFO_ENTRIES)
_GROUPS = wp.constant(INFO_GROUPS)
_CELLS = wp.constant(INFO_CELLS)
_ROWS = wp.constant(INFO_ROWS)
_FACE_TESTS = wp.constant(INFO_FACE_TESTS)
_SLAB_TESTS = wp.constant(INFO_SLAB_TESTS)
_SAME_NODE = wp.constant(INFO_SAME_NODE)
_BAD_BOXES = wp.constant(INFO_BAD_BOXES)
_BAD_NODES = wp.constant(INFO_BAD_NODES)
_BAD_ORDER = wp.constant(INFO_BAD_ORDER)
_COARSENINGS = wp.constant(INFO_COARSENINGS)
_WANTED_CELLS = wp.constant(INFO_WANTED_CELLS)
_LIVE_ENTRIES = wp.constant(INFO_LIVE_ENTRIES)
_LIVE_GROUPS = wp.constant(INFO_LIVE_GROUPS)
_LIVE_ROWS = wp.constant(INFO_LIVE_ROWS)
_LIVE_TESTS = wp.constant(INFO_LIVE_TESTS)
_TEST_CHUNK = wp.constant(INFO_TEST_CHUNK)
_CELL_CODES = wp.constant(INFO_CELL_CODES)
_SLAB_SAVED = wp.constant(INFO_SLAB_SAVED)
_WIDE_FOUND = wp.constant(INFO_WIDE_FOUND)
_WIDE_FACES = wp.constant(INFO_WIDE_FACES)
_WIDE_LISTED = wp.constant(INFO_WIDE_LISTED)
_LONG_FACES = wp.constant(INFO_LONG_FACES)
_WIDE_TESTS = wp.constant(INFO_WIDE_TESTS)
_INFO_SIZE = wp.constant(INFO_SIZE)


@wp.struct
class GridState:
    """The grid of the current call, written on the device: cell of p = floor((p - origin) /
    cell_size) per axis, ``dims`` cells per axis; ``margin`` grows each end of a group slab, and
    ``bound_pad`` the bound of the smaller group in a group slab test (the rounding of that bound);
    a face is wide (left out of the grid) when its box covers more than ``wide_limit`` cells of edge
    ``wide_cell`` (0: no wide faces this call; :mod:`pscc.collision._wide_face_kernels`)."""

    origin: wp.vec3
    cell_size: float
    dims: wp.vec3i
    margin: float
    bound_pad: float
    wide_cell: wp.float64
    wide_limit: wp.float64


@wp.struct
class DiagonalArgs:
    """The faces' diagonal slabs (:mod:`pscc.geometry.dop`) for the face test (``enabled`` = 0: boxes
    only, the arrays are not read)."""

    lower: wp.array(dtype=vec10)
    upper: wp.array(dtype=vec10)
    enabled: int


@wp.struct
class TableArgs:
    """The sorted entries, the two tables built from them and the work rows (layout in ``SpatialHash``)."""

    entry_key: wp.array(dtype=wp.int64)
    entry_face: wp.array(dtype=wp.int32)
    group_start: wp.array(dtype=wp.int32)
    group_end: wp.array(dtype=wp.int32)
    row_span: wp.array(dtype=wp.vec3i)
    row_work: wp.array(dtype=wp.int64)
    row_scan: wp.array(dtype=wp.int64)
    entry_code: wp.array(dtype=wp.uint32)
    code_masks: wp.array(dtype=wp.uint64)
    mask_min_run: int


@wp.struct
class SlabArgs:
    """Face geometry of the group slab test (``enabled`` = 0: every group pair is tested face by face).

    ``positions_t1`` is read only when ``swept`` != 0 (CCD: the slab holds both ends of the step).
    The margin that grows each end of a slab depends on the scene box, so it is in ``GridState``.
    ``group_skip[g]`` (written by ``_compute_group_slabs``, read by ``_plan_rows``) lets the row plan
    pass groups too small to be slab-tested: [0] the size of the largest group after g in its cell (0
    for the last); [1] and [2] the first group after g in its cell with at least ``min_work`` and
    ``ceil(min_work / 2)`` entries (the smallest that a group of one or two entries slab-tests), or
    one past the cell's last group. ``group_sphere[g]`` (centre, radius) bounds the vertices of group g.
    ``policy`` (persistent, :func:`slab_test_on`): [0] = 1 when this call slab-tests, [1] = calls since
    the last call that did.
    """

    enabled: int
    faces: wp.array(dtype=wp.vec3i)
    positions_t0: wp.array(dtype=wp.vec3)
    positions_t1: wp.array(dtype=wp.vec3)
    swept: int
    min_work: wp.int64
    exact_min_work: wp.int64
    group_skip: wp.array(dtype=wp.vec3i)
    group_sphere: wp.array(dtype=wp.vec4)
    policy: wp.array(dtype=wp.int32)


@wp.func
def slab_test_on(slab: SlabArgs) -> bool:
    """Whether this call runs the group slab test: configured (``enabled``) and chosen by the policy
    the last slab-testing call left (``_update_slab_policy``)."""
    return slab.enabled != 0 and slab.policy[0] > 0


@wp.func
def cell_of_point(p: wp.vec3, origin: wp.vec3, cell_size: float) -> wp.vec3i:
    """Integer cell coordinates of ``p``; the one floor used by insertion and by the token rule."""
    d = p - origin
    return wp.vec3i(
        int(wp.floor(d[0] / cell_size)), int(wp.floor(d[1] / cell_size)), int(wp.floor(d[2] / cell_size))
    )


@wp.func
def linear_cell_id(c: wp.vec3i, dims: wp.vec3i) -> wp.int64:
    """CellId = Id_x N_y N_z + Id_y N_z + Id_z (paper section 4.2)."""
    return (wp.int64(c[0]) * wp.int64(dims[1]) + wp.int64(c[1])) * wp.int64(dims[2]) + wp.int64(c[2])


@wp.func
def entry_key(cell: wp.int64, node: int, node_bits: int) -> wp.int64:
    """The exact paired key {CellId, NodeId}: cell in the high bits, the low ``node_bits`` bits of the
    node's uint32 pattern below (all of them when node_bits = 32; else ids lie in [0, 2^node_bits))."""
    mask = (wp.int64(1) << wp.int64(node_bits)) - wp.int64(1)
    return (cell << wp.int64(node_bits)) | (wp.int64(node) & mask)


@wp.func
def key_cell(key: wp.int64, node_bits: int) -> wp.int64:
    """The cell part of an entry key."""
    return key >> wp.int64(node_bits)


@wp.func
def box_cell_volume(lower: wp.vec3, upper: wp.vec3, cell: wp.float64) -> wp.float64:
    """prod_k (e_k / cell + 1), e = upper - lower in float64: a bound, independent of the grid's origin, of
    the cells of edge ``cell`` that the box overlaps (it overlaps at most floor(e_k / cell) + 2 per axis)."""
    volume = wp.float64(1.0)
    for k in range(3):
        volume = volume * ((wp.float64(upper[k]) - wp.float64(lower[k])) / cell + wp.float64(1.0))
    return volume


@wp.func
def is_wide(lower: wp.vec3, upper: wp.vec3, cell: wp.float64, limit: wp.float64) -> bool:
    """Whether a box is wide: ``cell`` > 0 (a wide set is in use) and its cell volume exceeds ``limit``."""
    if cell <= wp.float64(0.0):
        return False
    return box_cell_volume(lower, upper, cell) > limit


@wp.kernel
def _reset_counters(
    # out:
    info: wp.array(dtype=wp.int64),
    counts: wp.array(dtype=wp.int64),
    grid_max: wp.array(dtype=wp.int32),
):
    """A single thread: zeroes the counters of a call (a kernel, not a memset, so it is captured alike)."""
    for k in range(_INFO_SIZE):
        info[k] = wp.int64(0)
    for k in range(4):
        grid_max[k] = 0
        if k < 2:
            counts[k] = wp.int64(0)


@wp.kernel
def _reduce_scene_chunks(
    # in:
    face_lower: wp.array(dtype=wp.vec3),
    face_upper: wp.array(dtype=wp.vec3),
    chunk_size: int,
    # out:
    chunk_lower: wp.array(dtype=wp.vec3),
    chunk_upper: wp.array(dtype=wp.vec3),
    chunk_length_sum: wp.array(dtype=wp.float64),
    chunk_bad: wp.array(dtype=wp.int32),
    chunk_extent: wp.array(dtype=wp.vec3),
):
    """One thread per chunk of ``chunk_size`` faces: its valid boxes' corners, axis-length sum and
    largest extent per axis; its bad boxes."""
    c = wp.tid()
    begin = c * chunk_size
    end = wp.min(begin + chunk_size, face_lower.shape[0])
    lo = wp.vec3(wp.inf, wp.inf, wp.inf)
    hi = wp.vec3(-wp.inf, -wp.inf, -wp.inf)
    length_sum = wp.float64(0.0)
    extent = wp.vec3(0.0)
    bad = int(0)
    for f in range(begin, end):
        a = face_lower[f]
        b = face_upper[f]
        if not (wp.isfinite(a) and wp.isfinite(b)) or a[0] > b[0] or a[1] > b[1] or a[2] > b[2]:
            bad += 1
            continue
        lo = wp.min(lo, a)
        hi = wp.max(hi, b)
        e = b - a
        extent = wp.max(extent, e)
        length_sum += (wp.float64(e[0]) + wp.float64(e[1]) + wp.float64(e[2])) / wp.float64(3.0)
    chunk_lower[c] = lo
    chunk_upper[c] = hi
    chunk_length_sum[c] = length_sum
    chunk_bad[c] = bad
    chunk_extent[c] = extent


@wp.func
def fold_chunks(
    chunk_lower: wp.array(dtype=wp.vec3),
    chunk_upper: wp.array(dtype=wp.vec3),
    chunk_length_sum: wp.array(dtype=wp.float64),
    chunk_count: int,
    scene: wp.array(dtype=wp.float64),
):
    """scene[0:7] = the chunks' min corner, max corner and axis-length sum, folded in index order (the
    result is deterministic)."""
    lo = wp.vec3(wp.inf, wp.inf, wp.inf)
    hi = wp.vec3(-wp.inf, -wp.inf, -wp.inf)
    length_sum = wp.float64(0.0)
    for c in range(chunk_count):
        lo = wp.min(lo, chunk_lower[c])
        hi = wp.max(hi, chunk_upper[c])
        length_sum += chunk_length_sum[c]
    for k in range(3):
        scene[k] = wp.float64(lo[k])
        scene[3 + k] = wp.float64(hi[k])
    scene[6] = length_sum


@wp.kernel
def _reduce_scene_total(
    # in:
    chunk_lower: wp.array(dtype=wp.vec3),
    chunk_upper: wp.array(dtype=wp.vec3),
    chunk_length_sum: wp.array(dtype=wp.float64),
    chunk_bad: wp.array(dtype=wp.int32),
    chunk_count: int,
    # out:
    scene: wp.array(dtype=wp.float64),
    info: wp.array(dtype=wp.int64),
):
    """A single thread: the scene of every valid box (:func:`fold_chunks`) and the bad boxes."""
    fold_chunks(chunk_lower, chunk_upper, chunk_length_sum, chunk_count, scene)
    bad = int(0)
    for c in range(chunk_count):
        bad += chunk_bad[c]
    scene[7] = wp.float64(bad)
    info[_BAD_BOXES] = wp.int64(bad)


@wp.kernel
def _clear_marks(
    # out:
    marks: wp.array(dtype=wp.int64),
):
    """One thread per face: its permutation mark to 0."""
    marks[wp.tid()] = wp.int64(0)


@wp.kernel
def _mark_face_order(
    # in:
    face_order: wp.array(dtype=wp.int32),
    # out:
    marks: wp.array(dtype=wp.int64),
    info: wp.array(dtype=wp.int64),
):
    """One thread per face position k: marks face ``face_order[k]`` (an id outside the faces is an
    order error)."""
    f = face_order[wp.tid()]
    if f < 0 or f >= marks.shape[0]:
        wp.atomic_add(info, _BAD_ORDER, wp.int64(1))
    else:
        wp.atomic_add(marks, f, wp.int64(1))


@wp.kernel
def _check_marks(
    # in:
    marks: wp.array(dtype=wp.int64),
    # out:
    info: wp.array(dtype=wp.int64),
):
    """One thread per face: an order error unless the order lists it exactly once."""
    if marks[wp.tid()] != wp.int64(1):
        wp.atomic_add(info, _BAD_ORDER, wp.int64(1))


@wp.func
def _fit_estimate(cell_size: wp.float64, scene: wp.array(dtype=wp.float64), info: wp.array(dtype=wp.int64)) -> float:
    """The cell size rounded to float32, doubled while the grid estimate prod(extent / size + 2) is
    not finite or exceeds MAX_GRID_CELLS (each doubling counted in ``info``)."""
    size = cell_size
    searching = bool(True)
    while searching:
        size = wp.float64(wp.float32(size))
        e0 = (scene[3] - scene[0]) / size + wp.float64(2.0)
        e1 = (scene[4] - scene[1]) / size + wp.float64(2.0)
        e2 = (scene[5] - scene[2]) / size + wp.float64(2.0)
        estimate = e0 * e1 * e2
        if wp.isfinite(e0) and wp.isfinite(e1) and wp.isfinite(e2) and estimate <= _MAX_GRID_CELLS_F:
            searching = False
        else:
            size = size * wp.float64(2.0)
            info[_COARSENINGS] = info[_COARSENINGS] + wp.int64(1)
    return wp.float32(size)


@wp.func
def first_cell_size(scene: wp.array(dtype=wp.float64), face_count: int, cell_size_factor: wp.float64,
                    fixed_cell_size: wp.float64) -> wp.float64:
    """``fixed_cell_size`` when > 0, else the factor x the mean box axis length of the ``face_count``
    faces in the scene's sum (the scene's largest extent, at least 1, when every box is a point)."""
    cell = fixed_cell_size
    if cell <= wp.float64(0.0):
        cell = cell_size_factor * (scene[6] / wp.float64(face_count))
        if not (cell > wp.float64(0.0)):
            cell = wp.max(wp.max(scene[3] - scene[0], scene[4] - scene[1]), scene[5] - scene[2])
            cell = wp.max(cell, wp.float64(1.0))
    return cell


@wp.kernel
def _plan_grid(
    # in:
    scene: wp.array(dtype=wp.float64),
    face_count: int,
    cell_size_factor: wp.float64,
    fixed_cell_size: wp.float64,
    half_distance: wp.float64,
    wide_limit: wp.float64,
    # out:
    grid: wp.array(dtype=GridState),
    info: wp.array(dtype=wp.int64),
    loop_flag: wp.array(dtype=wp.int32),
):
    """A single thread: origin = the scene's min corner, the slab margin (from the scene box), the
    first cell size (``fixed_cell_size`` when > 0, else the factor x the mean box axis length of the
    grid faces that are not long; the scene extent when every box is a point), all over the faces that
    are not wide (the wide cell ``scene[9]`` when there are any). Starts the grid loop unless a box or
    the order is bad."""
    state = GridState()
    state.origin = wp.vec3(wp.float32(scene[0]), wp.float32(scene[1]), wp.float32(scene[2]))
    state.dims = wp.vec3i(0, 0, 0)
    # M = sum_k max(|lower_k|, |upper_k|) bounds |p|_1 for every vertex of the scene.
    size = wp.float64(0.0)
    for k in range(3):
        lower = scene[k]
        upper = lower + (scene[3 + k] - scene[k])
        size = size + wp.max(wp.abs(lower), wp.abs(upper))
    state.margin = wp.float32(half_distance * (wp.float64(1.0) + _SLAB_PAD) + _SLAB_PAD * (size + half_distance))
    state.bound_pad = wp.float32(_BOUND_PAD * size)
    wide = int(info[_WIDE_FACES])
    state.wide_cell = wp.float64(0.0)
    if wide > 0:
        state.wide_cell = scene[9]
    state.wide_limit = wide_limit
    cell = first_cell_size(scene, face_count - wide - int(info[_LONG_FACES]), cell_size_factor, fixed_cell_size)
    state.cell_size = float(1.0)
    flag = int(0)
    if info[_BAD_BOXES] == wp.int64(0) and info[_BAD_ORDER] == wp.int64(0):
        state.cell_size = _fit_estimate(cell, scene, info)
        flag = 1
    grid[0] = state
    loop_flag[0] = flag


@wp.kernel
def _count_face_cells(
    # in:
    face_lower: wp.array(dtype=wp.vec3),
    face_upper: wp.array(dtype=wp.vec3),
    grid: wp.array(dtype=GridState),
    node_id: wp.array(dtype=wp.int32),
    node_limit: int,
    face_order: wp.array(dtype=wp.int32),
    ordered: int,
    # out:
    face_cells: wp.array(dtype=wp.int64),
    grid_max: wp.array(dtype=wp.int32),
):
    """One thread per face position k (face ``face_order[k]`` when ``ordered``, else face k): its cell
    count goes to slot k (0 for a wide face); grid_max[3] counts node ids outside [0, node_limit) (when
    node_limit > 0)."""
    k = wp.tid()
    f = k
    if ordered != 0:
        f = face_order[k]
    if node_limit > 0:
        node = node_id[f]
        if node < 0 or node >= node_limit:
            wp.atomic_add(grid_max, 3, 1)
    state = grid[0]
    lower = face_lower[f]
    upper = face_upper[f]
    if is_wide(lower, upper, state.wide_cell, state.wide_limit):
        face_cells[k] = wp.int64(0)  # not in the grid (the test of the wide faces pairs it)
        return
    lo = cell_of_point(lower, state.origin, state.cell_size)
    hi = cell_of_point(upper, state.origin, state.cell_size)
    face_cells[k] = wp.int64(hi[0] - lo[0] + 1) * wp.int64(hi[1] - lo[1] + 1) * wp.int64(hi[2] - lo[2] + 1)
    wp.atomic_max(grid_max, 0, hi[0])
    wp.atomic_max(grid_max, 1, hi[1])
    wp.atomic_max(grid_max, 2, hi[2])


@wp.kernel
def _check_grid(
    # in:
    face_end: wp.array(dtype=wp.int64),
    scene: wp.array(dtype=wp.float64),
    max_entries: wp.int64,
    cell_limit: wp.int64,
    entry_capacity: wp.int64,
    # out:
    grid: wp.array(dtype=GridState),
    grid_max: wp.array(dtype=wp.int32),
    info: wp.array(dtype=wp.int64),
    loop_flag: wp.array(dtype=wp.int32),
):
    """A single thread, after a count: too many entries or cells (more than MAX_GRID_CELLS, or more
    than ``cell_limit`` = 2^cell_bits, the sort's range) double the cell size and keep the loop
    going; else the grid is final (``loop_flag`` = 0). Resets the grid maxima for the next count."""
    state = grid[0]
    entries = face_end[face_end.shape[0] - 1]
    dims = wp.vec3i(grid_max[0] + 1, grid_max[1] + 1, grid_max[2] + 1)
    cells = wp.int64(dims[0]) * wp.int64(dims[1]) * wp.int64(dims[2])
    info[_BAD_NODES] = wp.int64(grid_max[3])
    for k in range(4):
        grid_max[k] = 0
    flag = int(1)
    if entries > max_entries or cells > _MAX_GRID_CELLS:
        info[_COARSENINGS] = info[_COARSENINGS] + wp.int64(1)
    elif cells > cell_limit:
        # A grid the guard accepts but the sort's cell bits cannot hold: coarsen it (the pairs do
        # not change) and report the cells it wanted, so the sync point can widen the bits.
        if info[_WANTED_CELLS] == wp.int64(0):
            info[_WANTED_CELLS] = cells
        info[_COARSENINGS] = info[_COARSENINGS] + wp.int64(1)
    else:
        flag = 0
    if flag != 0:
        state.cell_size = _fit_estimate(wp.float64(state.cell_size) * wp.float64(2.0), scene, info)
    else:
        state.dims = dims
        info[_ENTRIES] = entries
        if entries <= entry_capacity:
            info[_LIVE_ENTRIES] = entries
    grid[0] = state
    loop_flag[0] = flag


@wp.func
def cell_fraction_code(t: float, cell: int) -> wp.uint32:
    """1 + the fifteenth of cell ``cell`` (one axis) that holds the grid coordinate ``t`` ((p - origin)
    times 1 / cell_size), clamped to [1, 15]. Non-decreasing in t for a fixed cell: a float32
    subtraction of a constant, a float32 product with the positive constant 15, floor and clamp are all
    monotone, so two entries of one cell whose float32 intervals overlap get codes that overlap."""
    q = wp.floor((t - float(cell)) * 15.0)
    return wp.uint32(int(wp.clamp(q + 1.0, 1.0, 15.0)))


@wp.func
def lower_end_code(lower_cell: int, t: float, cell: int) -> wp.uint32:
    """The code of a box's lower end on one axis in cell ``cell``: 0 when the box starts in an earlier
    cell (``lower_cell``, from :func:`cell_of_point`, below ``cell``), else ``cell_fraction_code``.
    0 is below every code of an end inside the cell, so the order of ends is kept."""
    if lower_cell < cell:
        return wp.uint32(0)
    return cell_fraction_code(t, cell)


@wp.func
def cell_code(cell: wp.vec3i, first: wp.vec3i, lo: wp.vec3, hi: wp.vec3) -> wp.uint32:
    """The cell code of a box in cell ``cell`` (coordinates), given the cell of its lower corner
    (``first``) and its ends in grid coordinates (``lo``, ``hi`` = (end - origin) x (1 / cell_size)):
    each end of each axis as a fifteenth of the cell (``cell_fraction_code``, 1-15), a lower end in an
    earlier cell as 0 (``lower_end_code``), packed as 5-bit fields: upper x, y, z in bits 0-14, lower
    x, y, z in bits 15-29 (bit 4 of every field clear: the guard of the test pass's packed comparison). A
    lower field is non-zero exactly when the box starts in this cell on that axis, which decides the
    token rule (:func:`pscc.collision._hash_row_kernels.codes_hold_token`)."""
    code = cell_fraction_code(hi[0], cell[0])
    code = code | (cell_fraction_code(hi[1], cell[1]) << wp.uint32(5))
    code = code | (cell_fraction_code(hi[2], cell[2]) << wp.uint32(10))
    code = code | (lower_end_code(first[0], lo[0], cell[0]) << wp.uint32(15))
    code = code | (lower_end_code(first[1], lo[1], cell[1]) << wp.uint32(20))
    return code | (lower_end_code(first[2], lo[2], cell[2]) << wp.uint32(25))


@wp.kernel
def _fill_entries(
    # in:
    face_lower: wp.array(dtype=wp.vec3),
    face_upper: wp.array(dtype=wp.vec3),
    node_id: wp.array(dtype=wp.int32),
    face_cells: wp.array(dtype=wp.int64),
    face_end: wp.array(dtype=wp.int64),
    grid: wp.array(dtype=GridState),
    node_bits: int,
    face_order: wp.array(dtype=wp.int32),
    ordered: int,
    info: wp.array(dtype=wp.int64),
    # out:
    keys: wp.array(dtype=wp.int64),
    values: wp.array(dtype=wp.int64),
):
    """One thread per face position k (as in ``_count_face_cells``): its entries at slot k of the exclusive
    scan of cell counts (entries in face-position order), each value the face and, in the high 32 bits,
    its box's cell code in that cell (:func:`cell_code`; the sort carries it along); nothing when the
    entries do not fit or the face is wide."""
    k = wp.tid()
    if info[_LIVE_ENTRIES] == wp.int64(0) or face_cells[k] == wp.int64(0):
        return  # the entries do not fit, or a wide face
    f = k
    if ordered != 0:
        f = face_order[k]
    state = grid[0]
    lower = face_lower[f]
    upper = face_upper[f]
    lo = cell_of_point(lower, state.origin, state.cell_size)
    hi = cell_of_point(upper, state.origin, state.cell_size)
    scale = 1.0 / state.cell_size
    lo_t = (lower - state.origin) * scale
    hi_t = (upper - state.origin) * scale
    node = node_id[f]
    slot = int(face_end[k] - face_cells[k])
    for x in range(lo[0], hi[0] + 1):
        for y in range(lo[1], hi[1] + 1):
            for z in range(lo[2], hi[2] + 1):
                cell = wp.vec3i(x, y, z)
                keys[slot] = entry_key(linear_cell_id(cell, state.dims), node, node_bits)
                code = cell_code(cell, lo, lo_t, hi_t)
                values[slot] = (wp.int64(code) << wp.int64(32)) | wp.int64(f)
                slot += 1


@wp.kernel
def _pad_entries(
    # in:
    info: wp.array(dtype=wp.int64),
    pad_key: wp.int64,
    # out:
    keys: wp.array(dtype=wp.int64),
    values: wp.array(dtype=wp.int64),
):
    """One thread per entry slot: slots past the live entries get the largest key (sorted last)."""
    i = wp.tid()
    if wp.int64(i) < info[_LIVE_ENTRIES]:
        return
    keys[i] = pad_key
    values[i] = wp.int64(0)


@wp.kernel
def _mark_runs(
    # in:
    keys: wp.array(dtype=wp.int64),
    node_bits: int,
    info: wp.array(dtype=wp.int64),
    # out:
    group_head: wp.array(dtype=wp.int32),
    cell_head: wp.array(dtype=wp.int32),
):
    """One thread per entry slot: 1 where a new {cell, node} group (or a new cell) begins, 0 past the
    live entries."""
    i = wp.tid()
    g = int(1)
    c = int(1)
    if wp.int64(i) >= info[_LIVE_ENTRIES]:
        g = 0
        c = 0
    elif i > 0:
        if keys[i] == keys[i - 1]:
            g = 0
        if key_cell(keys[i], node_bits) == key_cell(keys[i - 1], node_bits):
            c = 0
    group_head[i] = g
    cell_head[i] = c


@wp.kernel
def _write_tables(
    # in:
    keys: wp.array(dtype=wp.int64),
    group_rank: wp.array(dtype=wp.int32),
    cell_rank: wp.array(dtype=wp.int32),
    node_bits: int,
    info: wp.array(dtype=wp.int64),
    # out:
    group_start: wp.array(dtype=wp.int32),
    group_end: wp.array(dtype=wp.int32),
    group_cell: wp.array(dtype=wp.int32),
    cell_end: wp.array(dtype=wp.int32),
):
    """One thread per live entry: run heads and tails write the ranges of their group and cell
    (groups past the group capacity are not written; the sync point grows it).

    Heads and tails are recomputed from the keys (not read from the head flags), because
    ``group_start`` and ``cell_end`` share storage with the flags of ``_mark_runs``.
    """
    i = wp.tid()
    n = int(info[_LIVE_ENTRIES])
    if i >= n:
        return
    key = keys[i]
    g = group_rank[i] - 1
    c = cell_rank[i] - 1
    if g < group_end.shape[0]:
        if i == 0 or keys[i - 1] != key:
            group_start[g] = i
            group_cell[g] = c
        if i == n - 1 or keys[i + 1] != key:
            group_end[g] = i + 1
    if i == n - 1 or key_cell(keys[i + 1], node_bits) != key_cell(key, node_bits):
        cell_end[c] = i + 1


@wp.kernel
def _gather_table_info(
    # in:
    group_rank: wp.array(dtype=wp.int32),
    cell_rank: wp.array(dtype=wp.int32),
    group_capacity: wp.int64,
    # out:
    info: wp.array(dtype=wp.int64),
):
    """A single thread: group and cell counts (ranks of the last live entry, before the rank arrays
    are reused); the later stages see the groups only when they fit the capacity."""
    n = int(info[_LIVE_ENTRIES])
    if n == 0:
        return
    groups = wp.int64(group_rank[n - 1])
    info[_GROUPS] = groups
    info[_CELLS] = wp.int64(cell_rank[n - 1])
    if groups <= group_capacity:
        info[_LIVE_GROUPS] = groups


@wp.kernel
def _compute_pair_keys(
    # in:
    counts: wp.array(dtype=wp.int64),
    face_count: wp.int64,
    pad_key: wp.int64,
    # out:
    pairs: wp.array(dtype=wp.vec2i),
    keys: wp.array(dtype=wp.int64),
):
    """One thread per pair slot of the capacity: the sort key a * face_count + b of an emitted pair;
    slots past the emitted pairs get ``pad_key`` (above every pair key) and the pair (-1, -1)."""
    i = wp.tid()
    if wp.int64(i) < counts[0]:
        p = pairs[i]
        keys[i] = wp.int64(p[0]) * face_count + wp.int64(p[1])
    else:
        keys[i] = pad_key
        pairs[i] = wp.vec2i(-1, -1)


@wp.kernel
def _gather_summary(
    # in:
    info: wp.array(dtype=wp.int64),
    grid: wp.array(dtype=GridState),
    counts: wp.array(dtype=wp.int64),
    # out:
    summary: wp.array(dtype=wp.float64),
):
    """A single thread: the counters, the grid dims and cell size and the pairs emitted, as float64
    (exact below 2^53), so the sync point reads them in one copy."""
    for k in range(_INFO_SIZE):
        summary[k] = wp.float64(info[k])
    state = grid[0]
    for k in range(3):
        summary[_INFO_SIZE + k] = wp.float64(state.dims[k])
    summary[_INFO_SIZE + 3] = wp.float64(state.cell_size)
    summary[_INFO_SIZE + 4] = wp.float64(counts[0])
    summary[_INFO_SIZE + 5] = state.wide_cell
