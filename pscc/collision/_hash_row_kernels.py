"""Kernels of the work-row stage of :class:`pscc.collision.spatial_hash.SpatialHash` (private: only that
host imports them): the group slab test, the row plan and the test pass. Layouts, counters and structs are
those of :mod:`pscc.collision._spatial_hash_kernels`. Thread mappings, in launch order:

=======================================  =============================================================
kernel                                   one thread per
=======================================  =============================================================
``_compute_group_slabs``                 group slot (group slab test only): its axis and slab, and
                                         (first group of a cell) the cell's ``group_skip``
``_plan_rows``                           group slot: slab tests against later groups of its cell, its
                                         rows (runs of later groups that pass) and their BV tests
``_gather_row_info``                     (single thread) row count, the tests each test thread runs,
                                         whether the test pass reads cell codes
``_write_rows``                          group slot: its rows and the BV tests of each
``_write_code_masks``                    block of 64 entry slots: its code masks (`_code_mask_kernels`)
``_test_bounding_volumes``               test thread: a contiguous chunk of the BV tests
=======================================  =============================================================
"""

from __future__ import annotations

import warp as wp

from pscc.collision._code_mask_kernels import ALL_BITS, code_mask_query, lowest_bit
from pscc.collision._spatial_hash_kernels import (
    _CELL_CODES,
    _FACE_TESTS,
    _LIVE_ENTRIES,
    _LIVE_GROUPS,
    _LIVE_ROWS,
    _LIVE_TESTS,
    _MASK_BITS,
    _ROWS,
    _SAME_NODE,
    _SLAB_SAVED,
    _SLAB_TESTS,
    _TEST_CHUNK,
    DiagonalArgs,
    GridState,
    SlabArgs,
    TableArgs,
    cell_code,
    cell_of_point,
    key_cell,
    linear_cell_id,
    slab_test_on,
)
from pscc.collision.shared_vertex import (
    SHARED_CERTIFY,
    SHARED_SKIP,
    SharedVertexArgs,
    certified_in,
    shares_vertex,
)
from pscc.geometry.aabb import boxes_overlap
from pscc.geometry.dop import diagonal_slabs_overlap, vec10

wp.set_module_options({"enable_backward": False})


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


@wp.struct
class GroupTables:
    """The sorted entries and the group and cell ranges that the group passes read, bundled for the kernels
    (layout in :mod:`pscc.collision.spatial_hash`)."""

    entry_key: wp.array(dtype=wp.int64)
    entry_face: wp.array(dtype=wp.int32)
    group_start: wp.array(dtype=wp.int32)
    group_end: wp.array(dtype=wp.int32)
    group_cell: wp.array(dtype=wp.int32)
    cell_end: wp.array(dtype=wp.int32)


@wp.func
def _group_slab(
    g: int,
    live: int,
    entry_face: wp.array(dtype=wp.int32),
    group_start: wp.array(dtype=wp.int32),
    group_end: wp.array(dtype=wp.int32),
    group_cell: wp.array(dtype=wp.int32),
    cell_end: wp.array(dtype=wp.int32),
    slab: SlabArgs,
    group_axis: wp.array(dtype=wp.vec3),
    group_slab: wp.array(dtype=wp.vec2),
):
    """The body of ``_compute_group_slabs`` for live group g of ``live``."""
    start = group_start[g]
    end = group_end[g]
    cell = group_cell[g]
    if g == 0 or group_cell[g - 1] != cell:
        # The cell's first group writes every group's ``slab.group_skip`` (one backward walk per cell,
        # O(groups) in all).
        last = g
        while last + 1 < live and group_cell[last + 1] == cell:
            last += 1
        largest = int(0)
        next_for_one = last + 1
        next_for_two = last + 1
        h = last
        while h >= g:
            slab.group_skip[h] = wp.vec3i(largest, next_for_one, next_for_two)
            size = wp.int64(group_end[h] - group_start[h])
            largest = wp.max(largest, int(size))
            if size >= slab.min_work:
                next_for_one = h
            if wp.int64(2) * size >= slab.min_work:
                next_for_two = h
            h -= 1
    cell_start = int(0)
    if cell > 0:
        cell_start = cell_end[cell - 1]
    others = (cell_end[cell] - cell_start) - (end - start)
    size = wp.int64(end - start)
    # A slab test of groups g and h reads the axis, slab and sphere of both, and runs only when
    # n_g n_h >= min_work: a group with n_g x (the rest of its cell) < min_work is in none.
    if size * wp.int64(others) < slab.min_work:
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
    # One pass over the group's vertices (both ends of the step): the slab on the axis, and their box,
    # whose centre and half diagonal are the group's bounding sphere.
    lo = float(wp.inf)
    hi = float(-wp.inf)
    lower = wp.vec3(wp.inf, wp.inf, wp.inf)
    upper = wp.vec3(-wp.inf, -wp.inf, -wp.inf)
    faces = slab.faces
    for e in range(start, end):
        tri = faces[entry_face[e]]
        for v in range(3):
            for step_end in range(1 + int(slab.swept != 0)):
                p = slab.positions_t0[tri[v]]
                if step_end == 1:
                    p = slab.positions_t1[tri[v]]
                s = wp.dot(axis, p)
                lo = wp.min(lo, s)
                hi = wp.max(hi, s)
                lower = wp.min(lower, p)
                upper = wp.max(upper, p)
    group_slab[g] = wp.vec2(lo, hi)
    centre = 0.5 * (lower + upper)
    radius = 0.5 * wp.length(upper - lower)
    slab.group_sphere[g] = wp.vec4(centre[0], centre[1], centre[2], radius)



@wp.kernel
def _compute_group_slabs(
    # in:
    tables: GroupTables,
    slab: SlabArgs,
    info: wp.array(dtype=wp.int64),
    lanes: int,
    # out:
    group_axis: wp.array(dtype=wp.vec3),
    group_slab: wp.array(dtype=wp.vec2),
):
    """Row kernel (:mod:`pscc._lanes`) over the live groups: axis = unit normal of its middle face at
    mid-step (any axis is valid; this one makes the slab of a flat patch thin), slab = its faces'
    interval on the axis, and the bounding sphere of its vertices (``slab.group_sphere``). A zero axis (a
    degenerate middle face) marks a group that is never culled. Groups whose cell holds too few other
    entries for any slab test (``slab.min_work``) are skipped. The first group of each cell also writes
    the cell's ``slab.group_skip``."""
    live = int(info[_LIVE_GROUPS])
    if not slab_test_on(slab):
        return
    # Arrays out of the struct once: on the CPU every struct member access copies the array header.
    entry_face = tables.entry_face
    group_start = tables.group_start
    group_end = tables.group_end
    group_cell = tables.group_cell
    cell_end = tables.cell_end
    for g in range(wp.tid(), wp.min(live, group_slab.shape[0]), lanes):
        _group_slab(g, live, entry_face, group_start, group_end, group_cell, cell_end, slab, group_axis, group_slab)


@wp.func
def _slab_pair_passes(
    entry_face: wp.array(dtype=wp.int32),
    group_axis: wp.array(dtype=wp.vec3),
    group_slab: wp.array(dtype=wp.vec2),
    g: int,
    g_start: int,
    g_size: int,
    h: int,
    h_start: int,
    h_size: int,
    slab: SlabArgs,
    margin: float,
    bound_pad: float,
) -> bool:
    """False when the faces of groups g and h are provably farther apart than twice the half distance:
    a bound of the smaller group's vertices on the larger group's axis a misses that group's slab.

    The bound, in O(1): for a vertex p of the smaller group (sphere c, R; own axis a_h, slab [lo, hi]),
    p . a = p . a_h + c . delta + (p - c) . delta with delta = a - a_h, so p . a lies in
    [lo, hi] + c . delta +- R |delta| (with -a_h and -[hi, lo] when a + a_h is the shorter delta: facing
    layers), and in c . a +- R; both hold, so the bound is their intersection, grown by ``bound_pad``
    for its rounding. Parallel layers (delta near 0) get their own slabs' tightness. When that bound
    meets the slab and the groups would need at least ``slab.exact_min_work`` face tests, the smaller
    group's vertices are projected on the axis one by one (the exact interval) and tested again."""
    owner = g
    other = h
    if h_size > g_size:
        owner = h
        other = g
    axis = group_axis[owner]
    if axis[0] == 0.0 and axis[1] == 0.0 and axis[2] == 0.0:
        return True
    own = group_slab[owner]
    sphere = slab.group_sphere[other]
    centre = wp.vec3(sphere[0], sphere[1], sphere[2])
    radius = sphere[3]
    middle = wp.dot(axis, centre)
    lo = middle - radius
    hi = middle + radius
    other_axis = group_axis[other]
    if not (other_axis[0] == 0.0 and other_axis[1] == 0.0 and other_axis[2] == 0.0):
        other_slab = group_slab[other]
        delta = axis - other_axis
        base_lo = other_slab[0]
        base_hi = other_slab[1]
        facing = axis + other_axis
        if wp.dot(facing, facing) < wp.dot(delta, delta):
            delta = facing
            base_lo = -other_slab[1]
            base_hi = -other_slab[0]
        shift = wp.dot(centre, delta)
        spread = radius * wp.length(delta)
        lo = wp.max(lo, base_lo + shift - spread)
        hi = wp.min(hi, base_hi + shift + spread)
    lo = lo - bound_pad
    hi = hi + bound_pad
    if lo - margin > own[1] + margin:
        return False
    if own[0] - margin > hi + margin:
        return False
    if wp.int64(g_size) * wp.int64(h_size) < slab.exact_min_work:
        return True
    # Large enough to pay for it: the smaller group's vertices projected on the axis one by one.
    other_start = h_start
    other_end = h_start + h_size
    if other == g:
        other_start = g_start
        other_end = g_start + g_size
    exact = _project_group(entry_face, other_start, other_end, axis, slab)
    if exact[0] - margin > own[1] + margin:
        return False
    if own[0] - margin > exact[1] + margin:
        return False
    return True


@wp.func
def _bit_range(lo: int, hi: int) -> wp.uint64:
    """The uint64 with bits lo .. hi - 1 set (0 <= lo < hi <= 64)."""
    upper = ~wp.uint64(0)
    if hi < 64:
        upper = (wp.uint64(1) << wp.uint64(hi)) - wp.uint64(1)
    return upper & ~((wp.uint64(1) << wp.uint64(lo)) - wp.uint64(1))


@wp.func
def _plan_group_rows(
    g: int,
    live: int,
    entry_key: wp.array(dtype=wp.int64),
    entry_face: wp.array(dtype=wp.int32),
    group_start: wp.array(dtype=wp.int32),
    group_end: wp.array(dtype=wp.int32),
    group_cell: wp.array(dtype=wp.int32),
    cell_end: wp.array(dtype=wp.int32),
    group_axis: wp.array(dtype=wp.vec3),
    group_slab: wp.array(dtype=wp.vec2),
    slab: SlabArgs,
    grid: wp.array(dtype=GridState),
    check_keys: int,
    group_mask: wp.array(dtype=wp.uint64),
    row_count: wp.array(dtype=wp.int32),
    info: wp.array(dtype=wp.int64),
):
    """The body of ``_plan_rows`` for live group g of ``live``."""
    margin = grid[0].margin
    bound_pad = grid[0].bound_pad
    slab_on = slab_test_on(slab)
    start = group_start[g]
    end = group_end[g]
    n_g = wp.int64(end - start)
    stop = cell_end[group_cell[g]]
    mask = wp.uint64(0)
    runs = int(0)
    in_run = bool(False)
    work = wp.int64(0)
    slab_tests = wp.int64(0)
    saved = wp.int64(0)
    key = entry_key[start]
    same_node = wp.int64(0)
    h = g + 1
    t = int(0)
    b = end
    while b < stop:
        rest_passes = check_keys == 0 and (not slab_on or t >= _MASK_BITS)
        if not rest_passes and check_keys == 0:
            skip = slab.group_skip[h - 1]
            if n_g * wp.int64(skip[0]) < slab.min_work:
                # No later group of the cell is large enough to be slab-tested: all of them pass.
                mask = mask | _bit_range(t, _MASK_BITS)
                rest_passes = True
            elif n_g <= wp.int64(2):
                # Groups h .. jump - 1 are too small for a slab test with a group of one or two entries:
                # they pass, in O(1).
                jump = skip[1]
                if n_g == wp.int64(2):
                    jump = skip[2]
                if jump > h:
                    b_next = stop
                    if jump < live and group_cell[jump] == group_cell[g]:
                        b_next = group_start[jump]
                    k = jump - h
                    mask = mask | _bit_range(t, wp.min(t + k, _MASK_BITS))
                    work += n_g * wp.int64(b_next - b)
                    if not in_run:
                        runs += 1
                    in_run = True
                    b = b_next
                    h = jump
                    t += k
                    continue
        if rest_passes:
            if not in_run:
                runs += 1
            work += n_g * wp.int64(stop - b)
            break
        h_end = group_end[h]
        passed = bool(True)
        if check_keys != 0 and entry_key[b] == key:
            passed = False
            same_node += n_g * wp.int64(h_end - b)
        elif slab_on and t < _MASK_BITS:
            if n_g * wp.int64(h_end - b) >= slab.min_work:
                slab_tests += wp.int64(1)
                passed = _slab_pair_passes(entry_face, group_axis, group_slab, g, start, end - start, h, b,
                                           h_end - b, slab, margin, bound_pad)
                if not passed:
                    saved += n_g * wp.int64(h_end - b)
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
    if slab_on:
        group_mask[g] = mask
    row_count[g] = runs
    if work > wp.int64(0):
        wp.atomic_add(info, _FACE_TESTS, work)
    if slab_tests > wp.int64(0):
        wp.atomic_add(info, _SLAB_TESTS, slab_tests)
    if saved > wp.int64(0):
        wp.atomic_add(info, _SLAB_SAVED, saved)
    if same_node > wp.int64(0):
        wp.atomic_add(info, _SAME_NODE, same_node)



@wp.kernel
def _plan_rows(
    # in:
    tables: GroupTables,
    group_axis: wp.array(dtype=wp.vec3),
    group_slab: wp.array(dtype=wp.vec2),
    slab: SlabArgs,
    grid: wp.array(dtype=GridState),
    check_keys: int,
    lanes: int,
    # out:
    group_mask: wp.array(dtype=wp.uint64),
    row_count: wp.array(dtype=wp.int32),
    info: wp.array(dtype=wp.int64),
):
    """Row kernel (:mod:`pscc._lanes`) over the group slots g (``row_count``'s length; 0 rows past the live
    groups): walks the later groups of its cell
    (the rest of the workLoadHashTable row), slab-tests the first MASK_BITS of them whose face tests
    would number at least ``slab.min_work`` (the result goes to bit t of ``group_mask``), and counts
    its rows (maximal runs of later groups that pass), its face tests and its slab tests (``info``).
    With ``check_keys`` (a caller-given fill order, which could split a node), a later group with the
    same key never passes and its face pairs are counted as same-node pairs (they must be 0: faces of
    one node are never paired). Once no check is left for the rest of the cell (no key check, and no
    slab test, past MASK_BITS or no later group large enough for one: ``slab.group_skip``), the rest
    is one run, added in O(1), its mask bits set; for a group of one or two entries, a stretch of later
    groups too small for a slab test with it is passed in O(1) too."""
    live = int(info[_LIVE_GROUPS])
    entry_key = tables.entry_key
    entry_face = tables.entry_face
    group_start = tables.group_start
    group_end = tables.group_end
    group_cell = tables.group_cell
    cell_end = tables.cell_end
    for g in range(wp.tid(), row_count.shape[0], lanes):
        if g >= live:
            row_count[g] = 0
        else:
            _plan_group_rows(g, live, entry_key, entry_face, group_start, group_end, group_cell, cell_end, group_axis,
                             group_slab, slab, grid, check_keys, group_mask, row_count, info)


@wp.kernel
def _gather_row_info(
    # in:
    row_end: wp.array(dtype=wp.int32),
    row_capacity: wp.int64,
    test_threads: wp.int64,
    min_chunk: wp.int64,
    code_min_tests: wp.int64,
    # out:
    info: wp.array(dtype=wp.int64),
):
    """A single thread: the row count; when the rows fit, the BV tests of the test pass, the
    chunk of them each of the ``test_threads`` threads runs (at least ``min_chunk``), and whether the
    test pass reads cell codes: when it runs at least ``code_min_tests`` BV tests per live entry (writing
    a code costs about as much as that many box loads save)."""
    groups = int(info[_LIVE_GROUPS])
    if groups == 0:
        return
    rows = wp.int64(row_end[groups - 1])
    info[_ROWS] = rows
    if rows > row_capacity:
        return
    info[_LIVE_ROWS] = rows
    tests = info[_FACE_TESTS]
    info[_LIVE_TESTS] = tests
    info[_TEST_CHUNK] = wp.max(min_chunk, (tests + test_threads - wp.int64(1)) / test_threads)
    if tests >= code_min_tests * info[_LIVE_ENTRIES]:
        info[_CELL_CODES] = wp.int64(1)


@wp.func
def _write_group_rows(
    g: int,
    entry_key: wp.array(dtype=wp.int64),
    group_start: wp.array(dtype=wp.int32),
    group_end: wp.array(dtype=wp.int32),
    group_cell: wp.array(dtype=wp.int32),
    cell_end: wp.array(dtype=wp.int32),
    group_mask: wp.array(dtype=wp.uint64),
    slab: SlabArgs,
    check_keys: int,
    row_count: wp.array(dtype=wp.int32),
    row_end: wp.array(dtype=wp.int32),
    row_span: wp.array(dtype=wp.vec3i),
    row_work: wp.array(dtype=wp.int64),
):
    """The body of ``_write_rows`` for live group g."""
    slot = row_end[g] - row_count[g]
    n_g = wp.int64(group_end[g] - group_start[g])
    stop = cell_end[group_cell[g]]
    slab_enabled = slab_test_on(slab)
    mask = wp.uint64(0)
    if slab_enabled:
        mask = group_mask[g]
    key = entry_key[group_start[g]]
    h = g + 1
    t = int(0)
    b = group_end[g]
    run_start = int(-1)
    while b < stop:
        # The rest is one run when nothing is checked past here: no key check, and no slab test, past
        # MASK_BITS, or every mask bit from t on set (``_plan_rows`` sets them all when it stops early).
        if check_keys == 0 and (not slab_enabled or t >= _MASK_BITS
                                or (mask | ((wp.uint64(1) << wp.uint64(wp.min(t, _MASK_BITS - 1))) - wp.uint64(1)))
                                == ~wp.uint64(0)):
            if run_start < 0:
                run_start = b
            break
        h_end = group_end[h]
        passed = bool(True)
        if check_keys != 0 and entry_key[b] == key:
            passed = False
        elif slab_enabled and t < _MASK_BITS:
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



@wp.kernel
def _write_rows(
    # in:
    tables: GroupTables,
    group_mask: wp.array(dtype=wp.uint64),
    slab: SlabArgs,
    check_keys: int,
    row_count: wp.array(dtype=wp.int32),
    row_end: wp.array(dtype=wp.int32),
    info: wp.array(dtype=wp.int64),
    lanes: int,
    # out:
    row_span: wp.array(dtype=wp.vec3i),
    row_work: wp.array(dtype=wp.int64),
):
    """Row kernel (:mod:`pscc._lanes`) over the live groups g (none when the rows do not fit): the same
    walk as ``_plan_rows``, writing each run of passing later groups as the row (g, b_start, b_end) with
    its BV tests n_g x (b_end - b_start)."""
    if info[_LIVE_ROWS] == wp.int64(0):
        return
    live = wp.min(int(info[_LIVE_GROUPS]), row_count.shape[0])
    entry_key = tables.entry_key
    group_start = tables.group_start
    group_end = tables.group_end
    group_cell = tables.group_cell
    cell_end = tables.cell_end
    for g in range(wp.tid(), live, lanes):
        _write_group_rows(g, entry_key, group_start, group_end, group_cell, cell_end, group_mask, slab, check_keys,
                          row_count, row_end, row_span, row_work)


@wp.kernel
def _update_slab_policy(
    # in:
    info: wp.array(dtype=wp.int64),
    counts: wp.array(dtype=wp.int64),
    pair_capacity: wp.int64,
    test_cost: wp.int64,
    group_cost: wp.int64,
    probe_interval: int,
    max_backoff: int,
    # out:
    policy: wp.array(dtype=wp.int32),
):
    """A single thread, after the test pass: whether the next call slab-tests. ``policy`` = [state, calls]:
    state 1 runs the test (``calls`` then holds the backoff level a probe started from), state -L <= 0
    skips it at backoff level L (``calls``: calls since the last test). A call that slab-tested keeps the
    test on when the face tests its separated group pairs saved outweigh what the test cost (``test_cost``
    face tests per slab test and ``group_cost`` per group of the call), else turns it off: at level 0
    after calls on which it paid, one level higher (at most ``max_backoff``) after a probe that found it
    still does not pay. The (``probe_interval`` x 2^L)-th call without the test probes it again. A call
    whose rows or pairs did not fit its buffers changes nothing: it is run again, and the run again
    decides."""
    if info[_LIVE_ROWS] == wp.int64(0) or counts[0] > pair_capacity:
        return
    if policy[0] > 0:
        cost = info[_SLAB_TESTS] * test_cost + info[_LIVE_GROUPS] * group_cost
        if info[_SLAB_SAVED] > cost:
            policy[0] = 1
            policy[1] = 0
        else:
            policy[0] = -wp.min(policy[1], max_backoff)
            policy[1] = 0
    else:
        level = -policy[0]
        policy[1] = policy[1] + 1
        if policy[1] >= probe_interval << level:
            policy[0] = 1
            policy[1] = level + 1


@wp.func
def entry_cell_code(
    key: wp.int64, node_bits: int, lower: wp.vec3, upper: wp.vec3, state: GridState
) -> wp.uint32:
    """The cell code (:func:`pscc.collision._spatial_hash_kernels.cell_code`) of the box [lower, upper] in
    the cell of entry key ``key``: what ``_fill_entries`` stores with the entry, from the key alone (for
    checks; the fill knows the cell's coordinates)."""
    cell = int(key_cell(key, node_bits))  # < 2^31 (MAX_GRID_CELLS)
    nz = state.dims[2]
    ny = state.dims[1]
    column = cell / nz
    cz = cell - column * nz
    cx = column / ny
    cy = column - cx * ny
    scale = 1.0 / state.cell_size
    lo = (lower - state.origin) * scale
    hi = (upper - state.origin) * scale
    first = cell_of_point(lower, state.origin, state.cell_size)
    return cell_code(wp.vec3i(cx, cy, cz), first, lo, hi)


CODE_UPPER_BITS = wp.constant(wp.uint32(0x7FFF))
CODE_LOWER_BITS = wp.constant(wp.uint32(0x3FFF8000))
CODE_GUARDS = wp.constant(wp.uint32(0x21084210))  # bit 4 of each of the six 5-bit fields


@wp.func
def code_minuend(code_a: wp.uint32) -> wp.uint32:
    """Entry a's part of the packed comparison: its upper ends moved to bits 15-29, the guards set."""
    return ((code_a & CODE_UPPER_BITS) << wp.uint32(15)) | CODE_GUARDS


@wp.func
def code_subtrahend(code_a: wp.uint32) -> wp.uint32:
    """Entry a's lower ends, moved to bits 0-14."""
    return code_a >> wp.uint32(15)


@wp.func
def cell_codes_overlap(minuend_a: wp.uint32, subtrahend_a: wp.uint32, code_b: wp.uint32) -> bool:
    """Whether the cell codes of entries a and b overlap on every axis: upper_b >= lower_a in fields
    0-2 and upper_a >= lower_b in fields 3-5, in one subtraction (each field is at most 15 and its guard
    bit 16, so no field borrows from the next; the guard stays set exactly where the minuend field is
    the larger). False only when the boxes' float32 test fails as well (the fraction codes are
    monotone)."""
    difference = ((code_b & CODE_UPPER_BITS) | minuend_a) - (subtrahend_a | (code_b & CODE_LOWER_BITS))
    return (difference & CODE_GUARDS) == CODE_GUARDS


CODE_LOWER_X = wp.constant(wp.uint32(0xF << 15))
CODE_LOWER_Y = wp.constant(wp.uint32(0xF << 20))
CODE_LOWER_Z = wp.constant(wp.uint32(0xF << 25))


@wp.func
def codes_hold_token(code_a: wp.uint32, code_b: wp.uint32) -> bool:
    """The token rule on the codes of two entries of one cell: the cell holds the lower corner of the
    boxes' intersection, max(lower_a, lower_b), exactly when on every axis one of the boxes starts in
    it (a non-zero lower field). Equal to the test on the boxes: :func:`cell_of_point` is monotone per
    axis, so the corner's cell is the larger of the two lower ends' cells, and neither is past the
    cell (both boxes were inserted into it)."""
    either = code_a | code_b
    return (either & CODE_LOWER_X) != wp.uint32(0) and (either & CODE_LOWER_Y) != wp.uint32(0) and (
        either & CODE_LOWER_Z) != wp.uint32(0)


@wp.func
def face_pair_test(
    fa: int,
    fb: int,
    diagonals_on: int,
    diagonal_lower: wp.array(dtype=vec10),
    diagonal_upper: wp.array(dtype=vec10),
    mode: int,
    faces: wp.array(dtype=wp.vec3i),
    x0: wp.array(dtype=wp.vec3),
    x1: wp.array(dtype=wp.vec3),
    swept: int,
    margin: float,
) -> bool:
    """:func:`face_pair_kept` with the structs' members passed one by one (a kernel that tests many pairs
    reads them out of the structs once: on the CPU a struct passed on copies every array header it holds)."""
    if mode == SHARED_SKIP:
        if shares_vertex(faces[fa], faces[fb]):
            return False
    if mode == SHARED_CERTIFY:
        ta = faces[fa]
        tb = faces[fb]
        if shares_vertex(ta, tb):
            # Faces that share a vertex always pass the diagonal slabs (both hold its projections, computed
            # alike): only the certificate can drop them.
            return not certified_in(x0, x1, swept, margin, ta, tb)
    if diagonals_on != 0:
        if not diagonal_slabs_overlap(diagonal_lower[fa], diagonal_upper[fa], diagonal_lower[fb], diagonal_upper[fb]):
            return False
    return True


@wp.func
def face_pair_kept(fa: int, fb: int, diagonals: DiagonalArgs, shared: SharedVertexArgs) -> bool:
    """The tests of a face pair after its boxes overlap: a shared vertex (``shared.mode`` skip), the
    shared-vertex certificate (``shared.mode`` certify), else the diagonal slabs (``diagonals.enabled``),
    which faces that share a vertex always pass."""
    return face_pair_test(fa, fb, diagonals.enabled, diagonals.lower, diagonals.upper, shared.mode, shared.faces,
                          shared.positions_t0, shared.positions_t1, shared.swept, shared.margin)


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
    diagonals: DiagonalArgs,
    shared: SharedVertexArgs,
    grid: wp.array(dtype=GridState),
    node_bits: int,
    tables: TableArgs,
    info: wp.array(dtype=wp.int64),
    capacity: wp.int64,
    # out:
    counts: wp.array(dtype=wp.int64),
    pairs: wp.array(dtype=wp.vec2i),
):
    """The paper's DecodePairsAndTest: test thread tid runs the BV tests [tid c, (tid + 1) c) of the
    live total (c = ``info`` test chunk), one binary search for the chunk, then a walk along the
    work rows. Emitted pairs are appended below ``capacity``; the counter keeps counting past it.

    Row r = (g, b_start, b_end) holds the tests of every entry of group g against the entries
    [b_start, b_end) (later groups of the same cell); every row has at least one test. With
    ``diagonals.enabled`` a test is of the faces' 26-DOPs: the boxes, then (only for boxes that overlap
    in the token cell) the ten diagonal slabs. When ``_gather_row_info`` chose cell codes for the call,
    the boxes are loaded only for entries whose codes overlap (``cell_codes_overlap``, read in entry
    order, in a tight scan) and hold the token (``codes_hold_token``, which then replaces the token test
    on the boxes); the codes never reject a pair whose boxes overlap and whose cell emits it. On a run of at
least ``tables.mask_min_run`` entries of a row, the entries whose codes pass are found through the code
masks, 64 at a time (:mod:`pscc.collision._code_mask_kernels`; the same entries in the same order). A pair of
    faces that share a vertex is dropped with ``shared.mode`` skip (before the diagonals), or with
    certify, after every other test, when its two faces are certified
    (:func:`~pscc.collision.shared_vertex.shared_pair_certified`)."""
    total = info[_LIVE_TESTS]
    chunk = info[_TEST_CHUNK]
    k = wp.int64(wp.tid()) * chunk
    if k >= total:
        return
    end_test = wp.min(total, k + chunk)
    state = grid[0]
    # Arrays out of the struct once: on the CPU every struct member access copies the array header.
    entry_face = tables.entry_face
    entry_key = tables.entry_key
    group_starts = tables.group_start
    group_ends = tables.group_end
    row_span = tables.row_span
    row_work = tables.row_work
    row_scan = tables.row_scan
    entry_code = tables.entry_code
    code_masks = tables.code_masks
    diagonals_on = diagonals.enabled
    diagonal_lower = diagonals.lower
    diagonal_upper = diagonals.upper
    shared_mode = shared.mode
    shared_faces = shared.faces
    shared_x0 = shared.positions_t0
    shared_x1 = shared.positions_t1
    shared_swept = shared.swept
    shared_margin = shared.margin
    mask_min_run = tables.mask_min_run
    use_codes = info[_CELL_CODES] != wp.int64(0)
    r = _find_row(row_scan, int(info[_LIVE_ROWS]), k)
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
    row_cell = key_cell(entry_key[group_starts[g]], node_bits)
    last_a = group_ends[g]
    code_a = wp.uint32(0)
    if use_codes:
        code_a = entry_code[entry_a]
    minuend_a = code_minuend(code_a)
    subtrahend_a = code_subtrahend(code_a)
    # Entry a's code test against one 64-entry block of the code masks, kept while a stays the same.
    block = int(-1)
    block_bits = wp.uint64(0)
    while k < end_test:
        # The tests of entry a against entries [entry_b, segment_end) of its row (the chunk may end first).
        segment_end = b_end
        if wp.int64(b_end - entry_b) > end_test - k:
            segment_end = entry_b + int(end_test - k)
        k += wp.int64(segment_end - entry_b)
        while entry_b < segment_end:
            # Rows never pair two groups of one node (``_plan_rows`` leaves such groups out).
            if use_codes:
                # The codes decide the token rule exactly and reject most pairs: skip those, 64 entries a
                # word through the code masks on long runs, else in a tight scan.
                if segment_end - entry_b >= mask_min_run:
                    while entry_b < segment_end:
                        word = entry_b >> 6
                        if word != block:
                            block = word
                            block_bits = code_mask_query(code_masks, word, code_a)
                        bits = block_bits & (ALL_BITS << wp.uint64(entry_b & 63))
                        if bits != wp.uint64(0):
                            entry_b = wp.min(word * 64 + lowest_bit(bits), segment_end)
                            break
                        entry_b = wp.min((word + 1) * 64, segment_end)
                else:
                    while entry_b < segment_end:
                        code_b = entry_code[entry_b]
                        if cell_codes_overlap(minuend_a, subtrahend_a, code_b):
                            if codes_hold_token(code_a, code_b):
                                break
                        entry_b += 1
                if entry_b == segment_end:
                    break
            fa = entry_face[entry_a]
            fb = entry_face[entry_b]
            lower_a = face_lower[fa]
            lower_b = face_lower[fb]
            emit = boxes_overlap(lower_a, face_upper[fa], lower_b, face_upper[fb])
            if emit and not use_codes:
                # Token position: only the cell holding the lower corner of the boxes' intersection emits.
                token = cell_of_point(wp.max(lower_a, lower_b), state.origin, state.cell_size)
                emit = linear_cell_id(token, state.dims) == row_cell
            if emit:
                emit = face_pair_test(fa, fb, diagonals_on, diagonal_lower, diagonal_upper, shared_mode, shared_faces,
                                      shared_x0, shared_x1, shared_swept, shared_margin)
            if emit:
                slot = wp.atomic_add(counts, 0, wp.int64(1))
                if slot < capacity:
                    pairs[int(slot)] = wp.vec2i(wp.min(fa, fb), wp.max(fa, fb))
            entry_b += 1
        if k >= end_test:
            break
        entry_b = b_start
        entry_a += 1
        if entry_a == last_a:
            r += 1
            span = row_span[r]
            g = span[0]
            b_start = span[1]
            b_end = span[2]
            entry_a = group_starts[g]
            entry_b = b_start
            last_a = group_ends[g]
            row_cell = key_cell(entry_key[entry_a], node_bits)
        if use_codes:
            code_a = entry_code[entry_a]
            minuend_a = code_minuend(code_a)
            subtrahend_a = code_subtrahend(code_a)
            block = -1
