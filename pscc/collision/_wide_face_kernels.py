"""Kernels of the *wide* and *long* faces of :class:`pscc.collision.spatial_hash.SpatialHash` (private: only that host
imports them).

A face whose box covers more than ``wide_limit`` cells of a *wide cell* is *wide*: a ground quad, a
collider's coarse triangle, a vertex flung far in one step. Inserting such a face in the grid costs an
entry per cell, and its length moves the mean box length that sets the cell size: one ground quad fifty
times the cloth's extent triples the cell and multiplies the entries by ten. A wide face is instead left
out of the grid, of the scene box and of the mean, and compared with every other face
(``_test_wide_faces``): face_count box tests per wide face, fewer than the ``wide_limit`` >= face_count / 8
entries it would have made.

The wide cell is found in ``WIDE_ROUNDS`` rounds, so that wide faces of several sizes (a ground and a
coarse collider) all leave: round r classifies at c_r, and folds the scene without the faces wide at c_r;
c_(r+1) = min(c_r, the first cell size of that fold). The cells only shrink, so a face wide in one round
is wide in every later one, and the final set is simply "wide at the accepted cell". A round that finds
no new wide face ends the search; one that finds more than the capacity (at most face_count / 8) ends
it as well and keeps the previous round's set (none after round 0: every face is inserted as before).

Thread mappings, in launch order:

=======================================  =============================================================
kernel                                   one thread per
=======================================  =============================================================
``_plan_wide_faces``                     (single thread) c_0, from the fold of every face
``_drop_wide_faces``                     (each round) chunk of faces: refolds a chunk that may hold
                                         wide faces without them, counting them
``_accept_wide_faces``                   (each round, single thread) accepts or ends the search; the
                                         next round's cell
``_list_wide_faces``                     chunk of faces: lists the wide faces of the accepted cell
``_sort_wide_faces``                     (single thread) sorts that list (face order on every device)
``_find_long_faces``                     chunk of faces (no explicit cell size): its long faces' length
                                         sum and count
``_drop_long_faces``                     (single thread) takes them out of the scene's length sum
``_test_wide_faces``                     run of ``faces_per_thread`` faces: each against every wide face
=======================================  =============================================================

*Long* faces are the milder case: grid faces whose mean box axis length exceeds ``LONG_FACE_RATIO`` (3)
times the mean of the grid faces (``cloth_rollers``' 120 cm roller walls beside 3 x 7 cm cloth cells). They
stay in the grid but leave the mean that sets the cell size (``_find_long_faces``, ``_drop_long_faces``),
so the cell suits the faces that make up the dense regions. At most a third of the faces can be long.

``scene[8]`` holds the cell of the current round, ``scene[9]`` the accepted cell (0: no wide faces),
``scene[10]`` 1 once the search has ended. The classification, prod_k (e_k / c + 1) > ``wide_limit`` in
float64 with e the box extent (:func:`~pscc.collision._spatial_hash_kernels.is_wide`), does not depend on
where the box lies in the grid, so every kernel (and a NumPy reference) decides it alike.
"""

from __future__ import annotations

import warp as wp

from pscc.collision._hash_row_kernels import face_pair_kept
from pscc.collision._spatial_hash_kernels import (
    _BAD_BOXES,
    _BAD_ORDER,
    _LONG_FACES,
    _LONG_RATIO,
    _WIDE_FACES,
    _WIDE_FOUND,
    _WIDE_LISTED,
    _WIDE_TESTS,
    DiagonalArgs,
    GridState,
    first_cell_size,
    fold_chunks,
    is_wide,
)
from pscc.collision.shared_vertex import SharedVertexArgs
from pscc.geometry.aabb import boxes_overlap

wp.set_module_options({"enable_backward": False})

WIDE_ROUNDS: int = 3
"""Rounds of the wide-cell search (each a chunk pass and a single-thread fold)."""


@wp.kernel
def _plan_wide_faces(
    # in:
    face_count: int,
    cell_size_factor: wp.float64,
    fixed_cell_size: wp.float64,
    # in / out:
    scene: wp.array(dtype=wp.float64),
    info: wp.array(dtype=wp.int64),
):
    """A single thread, after the fold of every face: c_0 = its first cell size (``scene[8]``), no
    accepted cell; the search ends at once when a box or the face order is bad."""
    scene[8] = first_cell_size(scene, face_count, cell_size_factor, fixed_cell_size)
    scene[9] = wp.float64(0.0)
    scene[10] = wp.float64(0.0)
    if info[_BAD_BOXES] != wp.int64(0) or info[_BAD_ORDER] != wp.int64(0):
        scene[10] = wp.float64(1.0)


@wp.func
def _chunk_may_be_wide(chunk_extent: wp.array(dtype=wp.vec3), c: int, cell: wp.float64, limit: wp.float64) -> bool:
    """Whether chunk c may hold a box wide at ``cell``: a box of its largest extents per axis is."""
    return is_wide(wp.vec3(0.0), chunk_extent[c], cell, limit)


@wp.kernel
def _drop_wide_faces(
    # in:
    face_lower: wp.array(dtype=wp.vec3),
    face_upper: wp.array(dtype=wp.vec3),
    chunk_size: int,
    scene: wp.array(dtype=wp.float64),
    wide_limit: wp.float64,
    chunk_extent: wp.array(dtype=wp.vec3),
    # in / out:
    chunk_lower: wp.array(dtype=wp.vec3),
    chunk_upper: wp.array(dtype=wp.vec3),
    chunk_length_sum: wp.array(dtype=wp.float64),
    info: wp.array(dtype=wp.int64),
):
    """One thread per chunk of faces, in a round that has not ended: a chunk that may hold a face wide at
    the round's cell is folded again without its wide faces, which are counted in
    ``info[INFO_WIDE_FOUND]``; any other chunk keeps its values (it held no wide face before either)."""
    c = wp.tid()
    cell = scene[8]
    if scene[10] != wp.float64(0.0) or not _chunk_may_be_wide(chunk_extent, c, cell, wide_limit):
        return
    begin = c * chunk_size
    end = wp.min(begin + chunk_size, face_lower.shape[0])
    lo = wp.vec3(wp.inf, wp.inf, wp.inf)
    hi = wp.vec3(-wp.inf, -wp.inf, -wp.inf)
    length_sum = wp.float64(0.0)
    wide = wp.int64(0)
    for f in range(begin, end):
        a = face_lower[f]
        b = face_upper[f]
        if not (wp.isfinite(a) and wp.isfinite(b)) or a[0] > b[0] or a[1] > b[1] or a[2] > b[2]:
            continue
        if is_wide(a, b, cell, wide_limit):
            wide += wp.int64(1)
            continue
        lo = wp.min(lo, a)
        hi = wp.max(hi, b)
        e = b - a
        length_sum += (wp.float64(e[0]) + wp.float64(e[1]) + wp.float64(e[2])) / wp.float64(3.0)
    chunk_lower[c] = lo
    chunk_upper[c] = hi
    chunk_length_sum[c] = length_sum
    wp.atomic_add(info, _WIDE_FOUND, wide)


@wp.kernel
def _accept_wide_faces(
    # in:
    chunk_lower: wp.array(dtype=wp.vec3),
    chunk_upper: wp.array(dtype=wp.vec3),
    chunk_length_sum: wp.array(dtype=wp.float64),
    chunk_count: int,
    face_count: int,
    cell_size_factor: wp.float64,
    fixed_cell_size: wp.float64,
    wide_capacity: int,
    # in / out:
    scene: wp.array(dtype=wp.float64),
    info: wp.array(dtype=wp.int64),
):
    """A single thread, after a round's ``_drop_wide_faces``: no more wide faces than accepted (none new),
    or more than ``wide_capacity``, end the search with the accepted set; else the round's set is
    accepted: the scene without it, its cell, and the next round's cell."""
    if scene[10] != wp.float64(0.0):
        return
    found = info[_WIDE_FOUND]
    info[_WIDE_FOUND] = wp.int64(0)
    if found <= info[_WIDE_FACES] or found > wp.int64(wide_capacity):
        scene[10] = wp.float64(1.0)
        return
    fold_chunks(chunk_lower, chunk_upper, chunk_length_sum, chunk_count, scene)
    info[_WIDE_FACES] = found
    scene[9] = scene[8]
    rest = face_count - int(found)
    scene[8] = wp.min(scene[8], first_cell_size(scene, rest, cell_size_factor, fixed_cell_size))
    info[_WIDE_TESTS] = found * wp.int64(rest) + found * (found - wp.int64(1)) / wp.int64(2)


@wp.kernel
def _list_wide_faces(
    # in:
    face_lower: wp.array(dtype=wp.vec3),
    face_upper: wp.array(dtype=wp.vec3),
    chunk_size: int,
    scene: wp.array(dtype=wp.float64),
    wide_limit: wp.float64,
    chunk_extent: wp.array(dtype=wp.vec3),
    # out:
    info: wp.array(dtype=wp.int64),
    wide_faces: wp.array(dtype=wp.int32),
):
    """One thread per chunk of faces: appends the faces wide at the accepted cell ``scene[9]`` (in any
    order; ``_sort_wide_faces`` sorts them). Their count is ``info[INFO_WIDE_FACES]``, at most the list's
    length."""
    c = wp.tid()
    cell = scene[9]
    if not _chunk_may_be_wide(chunk_extent, c, cell, wide_limit):
        return
    begin = c * chunk_size
    end = wp.min(begin + chunk_size, face_lower.shape[0])
    for f in range(begin, end):
        if is_wide(face_lower[f], face_upper[f], cell, wide_limit):
            slot = wp.atomic_add(info, _WIDE_LISTED, wp.int64(1))
            if slot < wp.int64(wide_faces.shape[0]):
                wide_faces[int(slot)] = f


@wp.kernel
def _sort_wide_faces(
    # in:
    info: wp.array(dtype=wp.int64),
    # in / out:
    wide_faces: wp.array(dtype=wp.int32),
):
    """A single thread: insertion sort of the (short) wide list."""
    count = int(info[_WIDE_FACES])
    for i in range(1, count):
        f = wide_faces[i]
        j = i
        while j > 0 and wide_faces[j - 1] > f:
            wide_faces[j] = wide_faces[j - 1]
            j -= 1
        wide_faces[j] = f


@wp.func
def _grid_faces(face_count: int, info: wp.array(dtype=wp.int64)) -> int:
    """The faces in the grid: every face but the wide ones."""
    return face_count - int(info[_WIDE_FACES])


@wp.kernel
def _find_long_faces(
    # in:
    face_lower: wp.array(dtype=wp.vec3),
    face_upper: wp.array(dtype=wp.vec3),
    chunk_size: int,
    scene: wp.array(dtype=wp.float64),
    info: wp.array(dtype=wp.int64),
    wide_limit: wp.float64,
    chunk_extent: wp.array(dtype=wp.vec3),
    # out:
    chunk_long_sum: wp.array(dtype=wp.float64),
    chunk_long_count: wp.array(dtype=wp.int32),
):
    """One thread per chunk of faces, after the wide faces: the axis-length sum and the count of the
    chunk's *long* faces, grid faces whose mean box axis length exceeds ``LONG_FACE_RATIO`` times the mean
    of all grid faces (0 for a chunk whose largest extents cannot make one)."""
    c = wp.tid()
    limit = _LONG_RATIO * scene[6] / wp.float64(_grid_faces(face_lower.shape[0], info))
    bound = chunk_extent[c]
    long_sum = wp.float64(0.0)
    count = int(0)
    if (wp.float64(bound[0]) + wp.float64(bound[1]) + wp.float64(bound[2])) / wp.float64(3.0) > limit:
        wide_cell = wp.float64(0.0)
        if info[_WIDE_FACES] > wp.int64(0):
            wide_cell = scene[9]
        begin = c * chunk_size
        end = wp.min(begin + chunk_size, face_lower.shape[0])
        for f in range(begin, end):
            a = face_lower[f]
            b = face_upper[f]
            if not (wp.isfinite(a) and wp.isfinite(b)) or is_wide(a, b, wide_cell, wide_limit):
                continue
            e = b - a
            length = (wp.float64(e[0]) + wp.float64(e[1]) + wp.float64(e[2])) / wp.float64(3.0)
            if length > limit:
                long_sum += length
                count += 1
    chunk_long_sum[c] = long_sum
    chunk_long_count[c] = count


@wp.kernel
def _drop_long_faces(
    # in:
    chunk_long_sum: wp.array(dtype=wp.float64),
    chunk_long_count: wp.array(dtype=wp.int32),
    chunk_count: int,
    # in / out:
    scene: wp.array(dtype=wp.float64),
    info: wp.array(dtype=wp.int64),
):
    """A single thread: the long faces' lengths leave the scene's length sum (``scene[6]``), folded in
    chunk order, and their count goes to ``info[INFO_LONG_FACES]``, so that the cell size is the factor
    times the mean of the other grid faces. They stay in the scene box and in the grid."""
    long_sum = wp.float64(0.0)
    count = wp.int64(0)
    for c in range(chunk_count):
        long_sum += chunk_long_sum[c]
        count += wp.int64(chunk_long_count[c])
    if count > wp.int64(0):
        scene[6] = scene[6] - long_sum
        info[_LONG_FACES] = count


@wp.kernel
def _test_wide_faces(
    # in:
    face_lower: wp.array(dtype=wp.vec3),
    face_upper: wp.array(dtype=wp.vec3),
    node_id: wp.array(dtype=wp.int32),
    grid: wp.array(dtype=GridState),
    wide_faces: wp.array(dtype=wp.int32),
    faces_per_thread: int,
    diagonals: DiagonalArgs,
    shared: SharedVertexArgs,
    info: wp.array(dtype=wp.int64),
    capacity: wp.int64,
    # out:
    counts: wp.array(dtype=wp.int64),
    pairs: wp.array(dtype=wp.vec2i),
):
    """One thread per run of ``faces_per_thread`` faces: each face f against every wide face w != f of
    another node whose box overlaps f's (a wide f only against wide faces w > f, so each pair is met
    once), then the tests of :func:`face_pair_kept`. Pairs are appended as by the test pass."""
    wide_count = int(info[_WIDE_FACES])
    if wide_count == 0:
        return
    state = grid[0]
    begin = wp.tid() * faces_per_thread
    end = wp.min(begin + faces_per_thread, face_lower.shape[0])
    for f in range(begin, end):
        lower_f = face_lower[f]
        upper_f = face_upper[f]
        f_wide = is_wide(lower_f, upper_f, state.wide_cell, state.wide_limit)
        node_f = node_id[f]
        for i in range(wide_count):
            w = wide_faces[i]
            if w == f or (f_wide and w < f) or node_id[w] == node_f:
                continue
            if not boxes_overlap(lower_f, upper_f, face_lower[w], face_upper[w]):
                continue
            if face_pair_kept(f, w, diagonals, shared):
                slot = wp.atomic_add(counts, 0, wp.int64(1))
                if slot < capacity:
                    pairs[int(slot)] = wp.vec2i(wp.min(f, w), wp.max(f, w))
