"""Kernels of :class:`pscc.collision.spatial_hash.SpatialHash` (private: only that host imports them).

Thread mappings, in launch order:

====================================  ==============================================================
kernel                                one thread per
====================================  ==============================================================
``_reduce_scene_chunks``              chunk of faces (min corner, max corner, axis-length sum)
``_reduce_scene_total``               (single thread) the whole scene, in a fixed order
``_count_face_cells``                 face: cells its box overlaps, grid extent (atomic max)
``_gather_entry_info``                (single thread) entry count and grid size for the host
``_fill_entries``                     face: its (key, face) entries, one per overlapped cell
``_mark_runs``                        sorted entry: head flags of groups and of cells
``_write_tables``                     sorted entry: group ranges, group cell, cell ends
``_compute_group_slabs``              group (group slab test only): its axis and slab
``_plan_rows``                        group: slab tests against later groups of its cell, its rows
                                      (runs of later groups that pass) and their BV tests
``_gather_table_info``                (single thread) group and cell counts, before the rank buffers
                                      are reused for the rows
``_gather_row_info``                  (single thread) rows, face tests, slab tests, same-node pairs
``_write_rows``                       group: its rows (a-range = the group, b-range = a run of
                                      later groups of its cell) and the BV tests of each
``_test_bounding_volumes``            BV test (a batch of the global test index range)
``_compute_pair_keys``                emitted pair: its sort key a * face_count + b
====================================  ==============================================================
"""

from __future__ import annotations

import warp as wp

from pscc import tolerances
from pscc.geometry.aabb import boxes_overlap

wp.set_module_options({"enable_backward": False})

NODE_BITS: int = 32
"""Most low bits of an entry key that hold the node id (its uint32 bit pattern); the cell id sits
above. A call that bounds its node ids uses fewer (``GridArgs.node_bits``), so the sort has less to do."""

MASK_BITS: int = 64
"""Later groups of a cell whose slab test result a group keeps (bits of ``group_mask``); later
groups past these are always tested face by face (conservative)."""

_MASK_BITS = wp.constant(MASK_BITS)
_SLAB_PAD = wp.constant(float(tolerances.GROUP_SLAB_RELATIVE_PAD))


@wp.struct
class GridArgs:
    """The uniform grid: cell of p = floor((p - origin) / cell_size) per axis; ``node_bits`` low bits
    of an entry key hold the node id."""

    origin: wp.vec3
    cell_size: float
    dims: wp.vec3i
    node_bits: int


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
    row_count: int


@wp.struct
class SlabArgs:
    """Face geometry of the group slab test (``enabled`` = 0: every group pair is tested face by face).

    ``positions_t1`` is read only when ``swept`` != 0 (CCD: the slab holds both ends of the step).
    ``margin`` grows each end of a slab: the half distance plus the rounding bound
    ``GROUP_SLAB_RELATIVE_PAD (M + half_distance)``, M a bound on |p|_1 over the scene's vertices.
    """

    enabled: int
    faces: wp.array(dtype=wp.vec3i)
    positions_t0: wp.array(dtype=wp.vec3)
    positions_t1: wp.array(dtype=wp.vec3)
    swept: int
    half_distance: float
    margin: float
    min_work: wp.int64


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
):
    """One thread per chunk of ``chunk_size`` faces."""
    c = wp.tid()
    begin = c * chunk_size
    end = wp.min(begin + chunk_size, face_lower.shape[0])
    lo = wp.vec3(wp.inf, wp.inf, wp.inf)
    hi = wp.vec3(-wp.inf, -wp.inf, -wp.inf)
    length_sum = wp.float64(0.0)
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
        length_sum += (wp.float64(e[0]) + wp.float64(e[1]) + wp.float64(e[2])) / wp.float64(3.0)
    chunk_lower[c] = lo
    chunk_upper[c] = hi
    chunk_length_sum[c] = length_sum
    chunk_bad[c] = bad


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
):
    """A single thread: folds the chunks in index order, so the result is deterministic."""
    lo = wp.vec3(wp.inf, wp.inf, wp.inf)
    hi = wp.vec3(-wp.inf, -wp.inf, -wp.inf)
    length_sum = wp.float64(0.0)
    bad = int(0)
    for c in range(chunk_count):
        lo = wp.min(lo, chunk_lower[c])
        hi = wp.max(hi, chunk_upper[c])
        length_sum += chunk_length_sum[c]
        bad += chunk_bad[c]
    for k in range(3):
        scene[k] = wp.float64(lo[k])
        scene[3 + k] = wp.float64(hi[k])
    scene[6] = length_sum
    scene[7] = wp.float64(bad)


@wp.kernel
def _count_face_cells(
    # in:
    face_lower: wp.array(dtype=wp.vec3),
    face_upper: wp.array(dtype=wp.vec3),
    origin: wp.vec3,
    cell_size: float,
    node_id: wp.array(dtype=wp.int32),
    node_limit: int,
    face_order: wp.array(dtype=wp.int32),
    ordered: int,
    # out:
    face_cells: wp.array(dtype=wp.int64),
    grid_max: wp.array(dtype=wp.int32),
):
    """One thread per face position k (face ``face_order[k]`` when ``ordered``, else face k): its cell
    count goes to slot k; grid_max[3] counts node ids outside [0, node_limit) (when node_limit > 0)."""
    k = wp.tid()
    f = k
    if ordered != 0:
        f = face_order[k]
    if node_limit > 0:
        node = node_id[f]
        if node < 0 or node >= node_limit:
            wp.atomic_add(grid_max, 3, 1)
    lo = cell_of_point(face_lower[f], origin, cell_size)
    hi = cell_of_point(face_upper[f], origin, cell_size)
    face_cells[k] = wp.int64(hi[0] - lo[0] + 1) * wp.int64(hi[1] - lo[1] + 1) * wp.int64(hi[2] - lo[2] + 1)
    wp.atomic_max(grid_max, 0, hi[0])
    wp.atomic_max(grid_max, 1, hi[1])
    wp.atomic_max(grid_max, 2, hi[2])


@wp.kernel
def _gather_entry_info(
    # in:
    face_end: wp.array(dtype=wp.int64),
    grid_max: wp.array(dtype=wp.int32),
    # out:
    info: wp.array(dtype=wp.int64),
):
    """A single thread: [entries, N_x, N_y, N_z, bad node ids] in one array, so the host reads it at once."""
    info[0] = face_end[face_end.shape[0] - 1]
    for k in range(3):
        info[1 + k] = wp.int64(grid_max[k] + 1)
    info[4] = wp.int64(grid_max[3])


@wp.kernel
def _fill_entries(
    # in:
    face_lower: wp.array(dtype=wp.vec3),
    face_upper: wp.array(dtype=wp.vec3),
    node_id: wp.array(dtype=wp.int32),
    face_cells: wp.array(dtype=wp.int64),
    face_end: wp.array(dtype=wp.int64),
    grid: GridArgs,
    face_order: wp.array(dtype=wp.int32),
    ordered: int,
    # out:
    keys: wp.array(dtype=wp.int64),
    faces: wp.array(dtype=wp.int32),
):
    """One thread per face position k (as in ``_count_face_cells``): writes the face's entries at slot
    k of the exclusive scan of cell counts, so entries lie in face-position order."""
    k = wp.tid()
    f = k
    if ordered != 0:
        f = face_order[k]
    lo = cell_of_point(face_lower[f], grid.origin, grid.cell_size)
    hi = cell_of_point(face_upper[f], grid.origin, grid.cell_size)
    node = node_id[f]
    slot = int(face_end[k] - face_cells[k])
    for x in range(lo[0], hi[0] + 1):
        for y in range(lo[1], hi[1] + 1):
            for z in range(lo[2], hi[2] + 1):
                keys[slot] = entry_key(linear_cell_id(wp.vec3i(x, y, z), grid.dims), node, grid.node_bits)
                faces[slot] = f
                slot += 1


@wp.kernel
def _mark_runs(
    # in:
    keys: wp.array(dtype=wp.int64),
    node_bits: int,
    # out:
    group_head: wp.array(dtype=wp.int32),
    cell_head: wp.array(dtype=wp.int32),
):
    """One thread per sorted entry: 1 where a new {cell, node} group (or a new cell) begins."""
    i = wp.tid()
    g = int(1)
    c = int(1)
    if i > 0:
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
    # out:
    group_start: wp.array(dtype=wp.int32),
    group_end: wp.array(dtype=wp.int32),
    group_cell: wp.array(dtype=wp.int32),
    cell_end: wp.array(dtype=wp.int32),
):
    """One thread per sorted entry: run heads and tails write the ranges of their group and cell.

    Heads and tails are recomputed from the keys (not read from the head flags), because
    ``group_start`` and ``cell_end`` may share storage with the flags of ``_mark_runs``.
    """
    i = wp.tid()
    n = keys.shape[0]
    key = keys[i]
    g = group_rank[i] - 1
    c = cell_rank[i] - 1
    if i == 0 or keys[i - 1] != key:
        group_start[g] = i
        group_cell[g] = c
    if i == n - 1 or keys[i + 1] != key:
        group_end[g] = i + 1
    if i == n - 1 or key_cell(keys[i + 1], node_bits) != key_cell(key, node_bits):
        cell_end[c] = i + 1


@wp.func
def _project_group(
    entry_face: wp.array(dtype=wp.int32), start: int, end: int, axis: wp.vec3, slab: SlabArgs
) -> wp.vec2:
    """(min, max) of axis . p over the vertices p of the faces of entries [start, end) at both ends of
    the step (t0 only when not swept)."""
    lo = float(wp.inf)
    hi = float(-wp.inf)
    for e in range(start, end):
        tri = slab.faces[entry_face[e]]
        for v in range(3):
            s = wp.dot(axis, slab.positions_t0[tri[v]])
            lo = wp.min(lo, s)
            hi = wp.max(hi, s)
            if slab.swept != 0:
                s = wp.dot(axis, slab.positions_t1[tri[v]])
                lo = wp.min(lo, s)
                hi = wp.max(hi, s)
    return wp.vec2(lo, hi)


@wp.kernel
def _compute_group_slabs(
    # in:
    entry_face: wp.array(dtype=wp.int32),
    group_start: wp.array(dtype=wp.int32),
    group_end: wp.array(dtype=wp.int32),
    group_cell: wp.array(dtype=wp.int32),
    cell_end: wp.array(dtype=wp.int32),
    slab: SlabArgs,
    # out:
    group_axis: wp.array(dtype=wp.vec3),
    group_slab: wp.array(dtype=wp.vec2),
):
    """One thread per group: axis = unit normal of its middle face at mid-step (any axis is valid;
    this one makes the slab of a flat patch thin), slab = its faces' interval on the axis.
    A zero axis (a degenerate middle face) marks a group that is never culled. Groups
    whose cell holds too few other entries for any slab test (``slab.min_work``) are skipped."""
    g = wp.tid()
    start = group_start[g]
    end = group_end[g]
    cell = group_cell[g]
    cell_start = int(0)
    if cell > 0:
        cell_start = cell_end[cell - 1]
    others = (cell_end[cell] - cell_start) - (end - start)
    if wp.int64(end - start) * wp.int64(others) < slab.min_work:
        group_axis[g] = wp.vec3(0.0, 0.0, 0.0)
        return
    # The normal of the group's middle face (in fill order): one cross product
    # instead of a pass over the group; on a flat patch every face gives nearly the same axis.
    tri = slab.faces[entry_face[(start + end) // 2]]
    a = slab.positions_t0[tri[0]]
    b = slab.positions_t0[tri[1]]
    c = slab.positions_t0[tri[2]]
    if slab.swept != 0:
        a = 0.5 * (a + slab.positions_t1[tri[0]])
        b = 0.5 * (b + slab.positions_t1[tri[1]])
        c = 0.5 * (c + slab.positions_t1[tri[2]])
    n = wp.cross(b - a, c - a)
    length = wp.length(n)
    axis = wp.vec3(0.0, 0.0, 0.0)
    if length > 0.0:
        axis = n / length
    group_axis[g] = axis
    group_slab[g] = _project_group(entry_face, start, end, axis, slab)


@wp.func
def _slab_pair_passes(
    entry_face: wp.array(dtype=wp.int32),
    group_axis: wp.array(dtype=wp.vec3),
    group_slab: wp.array(dtype=wp.vec2),
    g: int,
    g_start: int,
    g_end: int,
    h: int,
    h_start: int,
    h_end: int,
    slab: SlabArgs,
) -> bool:
    """False when the faces of groups g and h are provably farther apart than twice the half distance:
    the smaller group projected on the larger group's axis misses that group's slab."""
    owner = g
    other_start = h_start
    other_end = h_end
    if h_end - h_start > g_end - g_start:
        owner = h
        other_start = g_start
        other_end = g_end
    axis = group_axis[owner]
    if axis[0] == 0.0 and axis[1] == 0.0 and axis[2] == 0.0:
        return True
    own = group_slab[owner]
    other = _project_group(entry_face, other_start, other_end, axis, slab)
    if other[0] - slab.margin > own[1] + slab.margin:
        return False
    if own[0] - slab.margin > other[1] + slab.margin:
        return False
    return True


@wp.kernel
def _plan_rows(
    # in:
    group_count: int,
    entry_key: wp.array(dtype=wp.int64),
    entry_face: wp.array(dtype=wp.int32),
    group_start: wp.array(dtype=wp.int32),
    group_end: wp.array(dtype=wp.int32),
    group_cell: wp.array(dtype=wp.int32),
    cell_end: wp.array(dtype=wp.int32),
    group_axis: wp.array(dtype=wp.vec3),
    group_slab: wp.array(dtype=wp.vec2),
    slab: SlabArgs,
    check_keys: int,
    # out:
    group_mask: wp.array(dtype=wp.uint64),
    row_count: wp.array(dtype=wp.int32),
    work_counts: wp.array(dtype=wp.int64),
):
    """One thread per group g: walks the later groups of its cell (the rest of the workLoadHashTable
    row), slab-tests the first MASK_BITS of them whose face tests would number at least
    ``slab.min_work`` (the result goes to bit t of ``group_mask``), and counts its rows (maximal runs
    of later groups that pass), its face tests (work_counts[0]) and its slab tests (work_counts[1]).
    With ``check_keys`` (a caller-given fill order, which could split a node), a later group with the
    same key never passes and its face pairs are counted in work_counts[2] (they must be 0: faces of
    one node are never paired). Once no check is left for the rest of the cell (no key check, and no
    slab test or past MASK_BITS), the rest is one run, added in O(1)."""
    g = wp.tid()
    if g >= group_count:
        return
    start = group_start[g]
    end = group_end[g]
    n_g = wp.int64(end - start)
    stop = cell_end[group_cell[g]]
    mask = wp.uint64(0)
    runs = int(0)
    in_run = bool(False)
    work = wp.int64(0)
    slab_tests = wp.int64(0)
    key = entry_key[start]
    same_node = wp.int64(0)
    h = g + 1
    t = int(0)
    b = end
    while b < stop:
        if check_keys == 0 and (slab.enabled == 0 or t >= _MASK_BITS):
            if not in_run:
                runs += 1
            work += n_g * wp.int64(stop - b)
            break
        h_end = group_end[h]
        passed = bool(True)
        if check_keys != 0 and entry_key[b] == key:
            passed = False
            same_node += n_g * wp.int64(h_end - b)
        elif slab.enabled != 0 and t < _MASK_BITS:
            if n_g * wp.int64(h_end - b) >= slab.min_work:
                slab_tests += wp.int64(1)
                passed = _slab_pair_passes(entry_face, group_axis, group_slab, g, start, end, h, b, h_end, slab)
            if passed:
                mask = mask | (wp.uint64(1) << wp.uint64(t))
        if passed:
            work += n_g * wp.int64(h_end - b)
            if not in_run:
                runs += 1
        in_run = passed
        b = h_end
        h += 1
        t += 1
    if slab.enabled != 0:
        group_mask[g] = mask
    row_count[g] = runs
    if work > wp.int64(0):
        wp.atomic_add(work_counts, 0, work)
    if slab_tests > wp.int64(0):
        wp.atomic_add(work_counts, 1, slab_tests)
    if same_node > wp.int64(0):
        wp.atomic_add(work_counts, 2, same_node)


@wp.kernel
def _gather_table_info(
    # in:
    group_rank: wp.array(dtype=wp.int32),
    cell_rank: wp.array(dtype=wp.int32),
    # out:
    info: wp.array(dtype=wp.int64),
):
    """A single thread: [groups, cells] of the last sorted entry (before the rank arrays are reused)."""
    last = group_rank.shape[0] - 1
    info[0] = wp.int64(group_rank[last])
    info[1] = wp.int64(cell_rank[last])


@wp.kernel
def _gather_row_info(
    # in:
    row_end: wp.array(dtype=wp.int32),
    work_counts: wp.array(dtype=wp.int64),
    # out:
    info: wp.array(dtype=wp.int64),
):
    """A single thread: info[2:6] = [rows, face tests, slab tests, same-node face pairs], next to
    [groups, cells], so the host reads all six at once."""
    info[2] = wp.int64(row_end[row_end.shape[0] - 1])
    info[3] = work_counts[0]
    info[4] = work_counts[1]
    info[5] = work_counts[2]


@wp.kernel
def _write_rows(
    # in:
    group_count: int,
    entry_key: wp.array(dtype=wp.int64),
    group_start: wp.array(dtype=wp.int32),
    group_end: wp.array(dtype=wp.int32),
    group_cell: wp.array(dtype=wp.int32),
    cell_end: wp.array(dtype=wp.int32),
    group_mask: wp.array(dtype=wp.uint64),
    slab_enabled: int,
    check_keys: int,
    row_count: wp.array(dtype=wp.int32),
    row_end: wp.array(dtype=wp.int32),
    # out:
    row_span: wp.array(dtype=wp.vec3i),
    row_work: wp.array(dtype=wp.int64),
):
    """One thread per group g: the same walk as ``_plan_rows``, writing each run of passing later
    groups as the row (g, b_start, b_end) with its BV tests n_g x (b_end - b_start)."""
    g = wp.tid()
    if g >= group_count:
        return
    slot = row_end[g] - row_count[g]
    n_g = wp.int64(group_end[g] - group_start[g])
    stop = cell_end[group_cell[g]]
    mask = wp.uint64(0)
    if slab_enabled != 0:
        mask = group_mask[g]
    key = entry_key[group_start[g]]
    h = g + 1
    t = int(0)
    b = group_end[g]
    run_start = int(-1)
    while b < stop:
        if check_keys == 0 and (slab_enabled == 0 or t >= _MASK_BITS):
            if run_start < 0:
                run_start = b
            break
        h_end = group_end[h]
        passed = bool(True)
        if check_keys != 0 and entry_key[b] == key:
            passed = False
        elif slab_enabled != 0 and t < _MASK_BITS:
            passed = ((mask >> wp.uint64(t)) & wp.uint64(1)) != wp.uint64(0)
        if passed and run_start < 0:
            run_start = b
        if not passed and run_start >= 0:
            row_span[slot] = wp.vec3i(g, run_start, b)
            row_work[slot] = n_g * wp.int64(b - run_start)
            slot += 1
            run_start = -1
        b = h_end
        h += 1
        t += 1
    if run_start >= 0:
        row_span[slot] = wp.vec3i(g, run_start, stop)
        row_work[slot] = n_g * wp.int64(stop - run_start)


@wp.func
def _find_row(row_scan: wp.array(dtype=wp.int64), row_count: int, k: wp.int64) -> int:
    """First row r with row_scan[r] > k (row_scan is the inclusive scan of the row work)."""
    lo = int(0)
    hi = row_count - 1
    while lo < hi:
        mid = (lo + hi) // 2
        if row_scan[mid] > k:
            hi = mid
        else:
            lo = mid + 1
    return lo


@wp.kernel
def _test_bounding_volumes(
    # in:
    face_lower: wp.array(dtype=wp.vec3),
    face_upper: wp.array(dtype=wp.vec3),
    faces: wp.array(dtype=wp.vec3i),
    skip_adjacent: int,
    grid: GridArgs,
    tables: TableArgs,
    first_test: wp.int64,
    end_test: wp.int64,
    tests_per_thread: int,
    capacity: wp.int64,
    # out:
    counts: wp.array(dtype=wp.int64),
    pairs: wp.array(dtype=wp.vec2i),
):
    """The paper's DecodePairsAndTest: thread tid runs BV tests first_test + tid x tests_per_thread
    onwards, ``tests_per_thread`` of them (1 = one thread per BV test). Every thread gets the same
    amount of work; consecutive tests walk along the work rows, so a batch needs one binary search.

    Row r = (g, b_start, b_end) holds the tests of every entry of group g against the entries
    [b_start, b_end) (later groups of the same cell); every row has at least one test."""
    # Arrays out of the struct once: on the CPU every struct member access copies the array header.
    entry_face = tables.entry_face
    entry_key = tables.entry_key
    group_starts = tables.group_start
    group_ends = tables.group_end
    row_span = tables.row_span
    row_work = tables.row_work
    row_scan = tables.row_scan
    k = first_test + wp.int64(wp.tid()) * wp.int64(tests_per_thread)
    if k >= end_test:
        return
    r = _find_row(row_scan, tables.row_count, k)
    q = k - (row_scan[r] - row_work[r])
    # Per-row values, reloaded only when the walk enters the next row. The test (a, b) of row r at
    # offset q is entry a = group_start + q / rest against entry b = b_start + q % rest; the walk
    # keeps both indices and divides only once per thread.
    span = row_span[r]
    g = span[0]
    b_start = span[1]
    b_end = span[2]
    rest = wp.int64(b_end - b_start)
    entry_a = group_starts[g] + int(q // rest)
    entry_b = b_start + int(q % rest)
    row_cell = key_cell(entry_key[group_starts[g]], grid.node_bits)
    last_a = group_ends[g]
    fa = entry_face[entry_a]
    lower_a = face_lower[fa]
    upper_a = face_upper[fa]
    for _step in range(tests_per_thread):
        if k >= end_test:
            break
        fb = entry_face[entry_b]
        # Rows never pair two groups of one node (``_plan_rows`` leaves such groups out).
        lower_b = face_lower[fb]
        emit = boxes_overlap(lower_a, upper_a, lower_b, face_upper[fb])
        if emit:
            # Token position: only the cell holding the lower corner of the boxes' intersection emits.
            token = cell_of_point(wp.max(lower_a, lower_b), grid.origin, grid.cell_size)
            emit = linear_cell_id(token, grid.dims) == row_cell
        if emit and skip_adjacent != 0:
            ta = faces[fa]
            tb = faces[fb]
            for u in range(3):
                for v in range(3):
                    if ta[u] == tb[v]:
                        emit = False
        if emit:
            slot = wp.atomic_add(counts, 0, wp.int64(1))
            if slot < capacity:
                pairs[int(slot)] = wp.vec2i(wp.min(fa, fb), wp.max(fa, fb))
        k += wp.int64(1)
        entry_b += 1
        if entry_b == b_end:
            entry_b = b_start
            entry_a += 1
            if entry_a == last_a:
                if k >= end_test:
                    break
                r += 1
                span = row_span[r]
                g = span[0]
                b_start = span[1]
                b_end = span[2]
                entry_a = group_starts[g]
                entry_b = b_start
                last_a = group_ends[g]
                row_cell = key_cell(entry_key[entry_a], grid.node_bits)
            fa = entry_face[entry_a]
            lower_a = face_lower[fa]
            upper_a = face_upper[fa]


@wp.kernel
def _compute_pair_keys(
    # in:
    pairs: wp.array(dtype=wp.vec2i),
    face_count: wp.int64,
    # out:
    keys: wp.array(dtype=wp.int64),
):
    """One thread per emitted pair."""
    i = wp.tid()
    p = pairs[i]
    keys[i] = wp.int64(p[0]) * face_count + wp.int64(p[1])
