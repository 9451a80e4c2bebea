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
``_compute_row_work``                 group: BV tests of its row (its members x later groups)
``_gather_table_info``                (single thread) groups, cells, BV tests for the host
``_test_bounding_volumes``            BV test (a batch of the global test index range)
``_compute_pair_keys``                emitted pair: its sort key a * face_count + b
====================================  ==============================================================
"""

from __future__ import annotations

import warp as wp

from pscc.geometry.aabb import boxes_overlap

wp.set_module_options({"enable_backward": False})

NODE_BITS: int = 32
"""Low bits of an entry key that hold the node id (its uint32 bit pattern); the cell id sits above."""

_NODE_SHIFT = wp.constant(wp.int64(NODE_BITS))
_NODE_MASK = wp.constant(wp.int64((1 << NODE_BITS) - 1))


@wp.struct
class GridArgs:
    """The uniform grid: cell of p = floor((p - origin) / cell_size) per axis."""

    origin: wp.vec3
    cell_size: float
    dims: wp.vec3i


@wp.struct
class TableArgs:
    """The sorted entries and the two tables built from them (layout in ``SpatialHash``)."""

    entry_key: wp.array(dtype=wp.int64)
    entry_face: wp.array(dtype=wp.int32)
    group_start: wp.array(dtype=wp.int32)
    group_end: wp.array(dtype=wp.int32)
    group_cell: wp.array(dtype=wp.int32)
    cell_end: wp.array(dtype=wp.int32)
    row_work: wp.array(dtype=wp.int64)
    row_scan: wp.array(dtype=wp.int64)
    group_count: int


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
def entry_key(cell: wp.int64, node: int) -> wp.int64:
    """The exact paired key {CellId, NodeId}: cell in the high bits, uint32(node) in the low 32."""
    return (cell << _NODE_SHIFT) | (wp.int64(node) & _NODE_MASK)


@wp.func
def key_cell(key: wp.int64) -> wp.int64:
    """The cell half of an entry key."""
    return key >> _NODE_SHIFT


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
    # out:
    face_cells: wp.array(dtype=wp.int64),
    grid_max: wp.array(dtype=wp.int32),
):
    """One thread per face."""
    f = wp.tid()
    lo = cell_of_point(face_lower[f], origin, cell_size)
    hi = cell_of_point(face_upper[f], origin, cell_size)
    face_cells[f] = wp.int64(hi[0] - lo[0] + 1) * wp.int64(hi[1] - lo[1] + 1) * wp.int64(hi[2] - lo[2] + 1)
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
    """A single thread: [entries, N_x, N_y, N_z] in one array, so the host reads it at once."""
    info[0] = face_end[face_end.shape[0] - 1]
    for k in range(3):
        info[1 + k] = wp.int64(grid_max[k] + 1)


@wp.kernel
def _fill_entries(
    # in:
    face_lower: wp.array(dtype=wp.vec3),
    face_upper: wp.array(dtype=wp.vec3),
    node_id: wp.array(dtype=wp.int32),
    face_cells: wp.array(dtype=wp.int64),
    face_end: wp.array(dtype=wp.int64),
    grid: GridArgs,
    # out:
    keys: wp.array(dtype=wp.int64),
    faces: wp.array(dtype=wp.int32),
):
    """One thread per face: writes its entries at its slot of the exclusive scan of cell counts."""
    f = wp.tid()
    lo = cell_of_point(face_lower[f], grid.origin, grid.cell_size)
    hi = cell_of_point(face_upper[f], grid.origin, grid.cell_size)
    node = node_id[f]
    slot = int(face_end[f] - face_cells[f])
    for x in range(lo[0], hi[0] + 1):
        for y in range(lo[1], hi[1] + 1):
            for z in range(lo[2], hi[2] + 1):
                keys[slot] = entry_key(linear_cell_id(wp.vec3i(x, y, z), grid.dims), node)
                faces[slot] = f
                slot += 1


@wp.kernel
def _mark_runs(
    # in:
    keys: wp.array(dtype=wp.int64),
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
        if key_cell(keys[i]) == key_cell(keys[i - 1]):
            c = 0
    group_head[i] = g
    cell_head[i] = c


@wp.kernel
def _write_tables(
    # in:
    keys: wp.array(dtype=wp.int64),
    group_rank: wp.array(dtype=wp.int32),
    cell_rank: wp.array(dtype=wp.int32),
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
    if i == n - 1 or key_cell(keys[i + 1]) != key_cell(key):
        cell_end[c] = i + 1


@wp.kernel
def _compute_row_work(
    # in:
    group_rank: wp.array(dtype=wp.int32),
    group_start: wp.array(dtype=wp.int32),
    group_end: wp.array(dtype=wp.int32),
    group_cell: wp.array(dtype=wp.int32),
    cell_end: wp.array(dtype=wp.int32),
    # out:
    row_work: wp.array(dtype=wp.int64),
):
    """One thread per group (slots past the group count, if launched, get 0).

    Row g holds the tests of every member of group g against every entry of the later groups of
    the same cell: n_g x (cell_end - group_end[g]). Summed over a cell: sum_{i<j} n_i n_j.
    """
    g = wp.tid()
    if g >= group_rank[group_rank.shape[0] - 1]:
        row_work[g] = wp.int64(0)
        return
    rest = cell_end[group_cell[g]] - group_end[g]
    row_work[g] = wp.int64(group_end[g] - group_start[g]) * wp.int64(rest)


@wp.kernel
def _gather_table_info(
    # in:
    group_rank: wp.array(dtype=wp.int32),
    cell_rank: wp.array(dtype=wp.int32),
    row_scan: wp.array(dtype=wp.int64),
    # out:
    info: wp.array(dtype=wp.int64),
):
    """A single thread: [groups, cells, BV tests] in one array, so the host reads it at once."""
    last = group_rank.shape[0] - 1
    info[0] = wp.int64(group_rank[last])
    info[1] = wp.int64(cell_rank[last])
    info[2] = row_scan[row_scan.shape[0] - 1]


@wp.func
def _find_row(row_scan: wp.array(dtype=wp.int64), group_count: int, k: wp.int64) -> int:
    """First group g with row_scan[g] > k (row_scan is the inclusive scan of the row work)."""
    lo = int(0)
    hi = group_count - 1
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
    amount of work; consecutive tests walk along the rows of the workload table, so a batch needs
    one binary search."""
    # Arrays out of the struct once: on the CPU every struct member access copies the array header.
    entry_face = tables.entry_face
    entry_key = tables.entry_key
    group_starts = tables.group_start
    group_ends = tables.group_end
    group_cell = tables.group_cell
    cell_ends = tables.cell_end
    row_work = tables.row_work
    row_scan = tables.row_scan
    k = first_test + wp.int64(wp.tid()) * wp.int64(tests_per_thread)
    if k >= end_test:
        return
    g = _find_row(row_scan, tables.group_count, k)
    q = k - (row_scan[g] - row_work[g])
    # Per-row values, reloaded only when the walk enters the next row. The test (a, b) of row g at
    # offset q is entry a = group_start + q / rest against entry b = group_end + q % rest; the walk
    # keeps both indices and divides only once per thread.
    rest = wp.int64(cell_ends[group_cell[g]] - group_ends[g])
    entry_a = group_starts[g] + int(q // rest)
    entry_b = group_ends[g] + int(q % rest)
    row_key = entry_key[group_starts[g]]
    row_cell = key_cell(row_key)
    group_end = group_ends[g]
    cell_end = cell_ends[group_cell[g]]
    last_a = group_ends[g]
    fa = entry_face[entry_a]
    lower_a = face_lower[fa]
    upper_a = face_upper[fa]
    for _step in range(tests_per_thread):
        if k >= end_test:
            break
        fb = entry_face[entry_b]
        emit = True
        if entry_key[entry_b] == row_key:
            # Cannot happen: later groups of a cell have other keys (other node ids). Counted so tests
            # can assert it.
            wp.atomic_add(counts, 1, wp.int64(1))
            emit = False
        if emit:
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
        if entry_b == cell_end:
            entry_b = group_end
            entry_a += 1
            if entry_a == last_a:
                # Next row with work (rows of groups that are last in their cell have none).
                if k >= end_test:
                    break
                g += 1
                while g < tables.group_count - 1 and row_work[g] == wp.int64(0):
                    g += 1
                entry_a = group_starts[g]
                group_end = group_ends[g]
                last_a = group_end
                entry_b = group_end
                cell_end = cell_ends[group_cell[g]]
                row_key = entry_key[entry_a]
                row_cell = key_cell(row_key)
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
