"""The spatial hash's cell codes (pscc.collision._hash_row_kernels): each entry's box ends as fifteenths
of its cell (a lower end in an earlier cell as 0), compared with one packed subtraction before the boxes
are loaded. The codes never reject a pair whose float32 boxes overlap (random, touching, point and far-off
boxes, any cell), they decide the token rule exactly as the boxes do, they do reject boxes apart by
more than a fifteenth inside the cell, and the hash and the detector give the same pairs
with the codes always on, on the default choice and never on."""

from __future__ import annotations

import numpy as np
import pytest
import warp as wp
from hypothesis import given, settings
from hypothesis import strategies as st

from pscc.collision._hash_row_kernels import (
    cell_codes_overlap,
    code_minuend,
    code_subtrahend,
    codes_hold_token,
    entry_cell_code,
)
from pscc.collision._spatial_hash_kernels import INFO_CELL_CODES, INFO_LIVE_ENTRIES, GridState, cell_of_point
from pscc.collision.detector import CollisionDetector
from pscc.collision.spatial_hash import CELL_CODE_MIN_TESTS, SpatialHash
from pscc.errors import InputError
from pscc.mesh import folded_sheet
from tests.collision.test_group_slab import _twist
from tests.collision.test_spatial_hash import _reference

DEVICE = "cpu"
NODE_BITS = wp.constant(5)


@wp.kernel
def _codes_overlap(
    cells: wp.array(dtype=wp.vec3i),
    lower_a: wp.array(dtype=wp.vec3),
    upper_a: wp.array(dtype=wp.vec3),
    lower_b: wp.array(dtype=wp.vec3),
    upper_b: wp.array(dtype=wp.vec3),
    grid: wp.array(dtype=GridState),
    out: wp.array(dtype=wp.int32),
):
    i = wp.tid()
    state = grid[0]
    c = cells[i]
    cell = (wp.int64(c[0]) * wp.int64(state.dims[1]) + wp.int64(c[1])) * wp.int64(state.dims[2]) + wp.int64(c[2])
    key = (cell << wp.int64(NODE_BITS)) | wp.int64(i % 32)
    code_a = entry_cell_code(key, int(NODE_BITS), lower_a[i], upper_a[i], state)
    code_b = entry_cell_code(key, int(NODE_BITS), lower_b[i], upper_b[i], state)
    ab = cell_codes_overlap(code_minuend(code_a), code_subtrahend(code_a), code_b)
    ba = cell_codes_overlap(code_minuend(code_b), code_subtrahend(code_b), code_a)
    out[i] = int(ab) + 2 * int(ba)


@wp.kernel
def _token_rules(
    cells: wp.array(dtype=wp.vec3i),
    lower_a: wp.array(dtype=wp.vec3),
    upper_a: wp.array(dtype=wp.vec3),
    lower_b: wp.array(dtype=wp.vec3),
    upper_b: wp.array(dtype=wp.vec3),
    grid: wp.array(dtype=GridState),
    out: wp.array(dtype=wp.int32),
):
    """Bit 0: both boxes span the sample's cell (they would be entries of it); bit 1: the cell holds
    the token by the boxes (the cell of max(lower_a, lower_b)); bit 2: by the codes."""
    i = wp.tid()
    state = grid[0]
    c = cells[i]
    cell = (wp.int64(c[0]) * wp.int64(state.dims[1]) + wp.int64(c[1])) * wp.int64(state.dims[2]) + wp.int64(c[2])
    key = (cell << wp.int64(NODE_BITS)) | wp.int64(i % 32)
    first_a = cell_of_point(lower_a[i], state.origin, state.cell_size)
    last_a = cell_of_point(upper_a[i], state.origin, state.cell_size)
    first_b = cell_of_point(lower_b[i], state.origin, state.cell_size)
    last_b = cell_of_point(upper_b[i], state.origin, state.cell_size)
    spans = int(1)
    for k in range(3):
        if first_a[k] > c[k] or last_a[k] < c[k] or first_b[k] > c[k] or last_b[k] < c[k]:
            spans = 0
    token = cell_of_point(wp.max(lower_a[i], lower_b[i]), state.origin, state.cell_size)
    by_boxes = int(token[0] == c[0] and token[1] == c[1] and token[2] == c[2])
    code_a = entry_cell_code(key, int(NODE_BITS), lower_a[i], upper_a[i], state)
    code_b = entry_cell_code(key, int(NODE_BITS), lower_b[i], upper_b[i], state)
    out[i] = spans + 2 * by_boxes + 4 * int(codes_hold_token(code_a, code_b))


def _grid(origin: np.ndarray, cell_size: float, dims: tuple[int, int, int]) -> wp.array:
    state = GridState()
    state.origin = wp.vec3(*origin.astype(np.float32).tolist())
    state.cell_size = float(cell_size)
    state.dims = wp.vec3i(*dims)
    state.margin = 0.0
    return wp.array([state], dtype=GridState, device=DEVICE)


def _codes(cells, la, ua, lb, ub, grid) -> np.ndarray:
    """Per sample: bit 0 = codes of a then b overlap, bit 1 = codes of b then a overlap."""
    out = wp.zeros(cells.shape[0], dtype=wp.int32, device=DEVICE)
    arrays = [wp.array(v.astype(np.float32), dtype=wp.vec3, device=DEVICE) for v in (la, ua, lb, ub)]
    wp.launch(_codes_overlap, dim=cells.shape[0], device=DEVICE,
              inputs=[wp.array(cells.astype(np.int32), dtype=wp.vec3i, device=DEVICE), *arrays, grid], outputs=[out])
    return out.numpy()


def _box_pairs(rng, n: int, offset: float, cell_size: float, first_cell: int, ends):
    """n samples of two boxes around a cell (coordinates in [first_cell, 6) per axis) of a grid at
    ``offset``: each box end is ``ends()`` cells from the cell's corner. Returns (origin, cells, lower
    and upper of box a, lower and upper of box b), float32."""
    origin = np.float32(offset) + rng.normal(size=3).astype(np.float32)
    cells = rng.integers(first_cell, 6, size=(n, 3))
    base = origin + cells * np.float32(cell_size)
    p, q, r, s = ((base + ends() * cell_size).astype(np.float32) for _ in range(4))
    return origin, cells, np.minimum(p, q), np.maximum(p, q), np.minimum(r, s), np.maximum(r, s)


def _overlap(la, ua, lb, ub) -> np.ndarray:
    """The hash's float32 closed-box test."""
    return np.all((la <= ub) & (lb <= ua), axis=1)


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), offset=st.sampled_from([0.0, 3.0, -250.0, 1e5]),
       cell_size=st.sampled_from([1.0, 0.37, 1e-3, 40.0]))
def test_codes_never_reject_overlapping_boxes(seed: int, offset: float, cell_size: float) -> None:
    """Random boxes around one cell, with ends on the cell's fifteenths (the codes' steps), on its faces, shared by both
    boxes (touching) and zero-size boxes: whenever the float32 boxes overlap, so do their codes, in
    the cell of the sample (any cell: the argument is monotonicity, not which cell emits)."""
    rng = np.random.default_rng(seed)
    n = 4000

    def ends() -> np.ndarray:
        kind = rng.integers(0, 4, size=(n, 3))
        free = rng.uniform(-0.5, 1.5, size=(n, 3))
        fifteenth = rng.integers(-2, 18, size=(n, 3)) / 15.0
        face = rng.integers(0, 2, size=(n, 3)).astype(np.float64)
        return np.where(kind == 0, free, np.where(kind == 1, fifteenth, np.where(kind == 2, face, free * 1e-3)))

    origin, cells, la, ua, lb, ub = _box_pairs(rng, n, offset, cell_size, 0, ends)
    # Touching boxes: b starts exactly where a ends on one axis; point boxes.
    touch = rng.random(n) < 0.25
    axis = rng.integers(0, 3, size=n)
    lb[touch, axis[touch]] = ua[touch, axis[touch]]
    ub[touch, axis[touch]] = np.maximum(ub[touch, axis[touch]], lb[touch, axis[touch]])
    point = rng.random(n) < 0.1
    ua[point] = la[point]
    overlap = _overlap(la, ua, lb, ub)
    got = _codes(cells, la, ua, lb, ub, _grid(origin, cell_size, (7, 7, 7)))
    assert np.all(got[overlap] == 3), "the codes rejected a pair of overlapping boxes"
    # Both orders give the same answer.
    assert np.all((got == 0) | (got == 3))
    assert overlap.sum() > 200


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), offset=st.sampled_from([0.0, 3.0, -250.0, 1e5]),
       cell_size=st.sampled_from([1.0, 0.37, 1e-3, 40.0]))
def test_codes_hold_the_token_exactly_where_the_boxes_do(seed: int, offset: float, cell_size: float) -> None:
    """For two boxes that are both entries of a cell, the token rule on their codes (a non-zero lower
    field on every axis in code_a | code_b) is the token rule on the boxes, also for ends on cell
    faces and far from the origin."""
    rng = np.random.default_rng(seed)
    n = 4000

    def ends() -> np.ndarray:
        kind = rng.integers(0, 3, size=(n, 3))
        free = rng.uniform(-1.5, 2.5, size=(n, 3))
        face = rng.integers(-1, 3, size=(n, 3)).astype(np.float64)
        near_face = face + rng.choice([-1.0, 1.0], size=(n, 3)) * 1e-7
        return np.where(kind == 0, free, np.where(kind == 1, face, near_face))

    origin, cells, la, ua, lb, ub = _box_pairs(rng, n, offset, cell_size, 1, ends)
    out = wp.zeros(n, dtype=wp.int32, device=DEVICE)
    arrays = [wp.array(v, dtype=wp.vec3, device=DEVICE) for v in (la, ua, lb, ub)]
    wp.launch(_token_rules, dim=n, device=DEVICE,
              inputs=[wp.array(cells.astype(np.int32), dtype=wp.vec3i, device=DEVICE), *arrays,
                      _grid(origin, cell_size, (8, 8, 8))], outputs=[out])
    got = out.numpy()
    entries = (got & 1) == 1
    by_boxes = (got >> 1) & 1
    by_codes = (got >> 2) & 1
    if abs(offset) * 2.0**-23 < cell_size / 64:  # float32 resolves the cell (not 1e-3 cells at 1e5)
        assert entries.sum() > 100 and by_boxes[entries].sum() > 20 and (1 - by_boxes[entries]).sum() > 20
    np.testing.assert_array_equal(by_codes[entries], by_boxes[entries])


def test_codes_reject_boxes_apart_within_the_cell() -> None:
    """Two boxes inside one cell, apart by more than a fifteenth on one axis, are rejected; the same
    boxes shifted to touch are kept."""
    n = 300
    rng = np.random.default_rng(2)
    origin = np.zeros(3, dtype=np.float32)
    cells = np.tile(np.array([[2, 1, 3]]), (n, 1))
    base = cells.astype(np.float32)
    axis = rng.integers(0, 3, size=n)
    la = base + np.float32(0.05)
    ua = base + np.float32(0.30)
    lb = base + np.float32(0.05)
    ub = base + np.float32(0.30)
    rows = np.arange(n)
    lb[rows, axis] = base[rows, axis] + np.float32(0.45)
    ub[rows, axis] = base[rows, axis] + np.float32(0.90)
    apart = _codes(cells, la, ua, lb, ub, _grid(origin, 1.0, (5, 5, 5)))
    assert np.all(apart == 0)
    lb[rows, axis] = ua[rows, axis]
    touching = _codes(cells, la, ua, lb, ub, _grid(origin, 1.0, (5, 5, 5)))
    assert np.all(touching == 3)


def _hash_pairs(lower, upper, node, cell_size, min_tests: int) -> tuple[np.ndarray, int, int]:
    hash_ = SpatialHash(lower.shape[0], DEVICE, cell_code_min_tests=min_tests)
    hash_.find_pairs(wp.array(lower, dtype=wp.vec3, device=DEVICE), wp.array(upper, dtype=wp.vec3, device=DEVICE),
                     wp.array(node, dtype=wp.int32, device=DEVICE), cell_size)
    info = hash_.info.numpy()
    return hash_.pairs_numpy(), int(info[INFO_CELL_CODES]), hash_.stats.bv_tests


@pytest.mark.parametrize("layout", ["random", "lattice", "points", "far"])
def test_hash_pairs_are_the_same_with_and_without_codes(layout: str) -> None:
    """Exact box pairs (brute force) with the codes always on and never on; lattice boxes touch exactly
    on cell faces, points sit on cell corners."""
    rng = np.random.default_rng(7)
    m = 700
    if layout == "random":
        lower = rng.uniform(0.0, 6.0, size=(m, 3)).astype(np.float32)
        upper = lower + rng.uniform(0.0, 0.8, size=(m, 3)).astype(np.float32)
        cell_size = None
    elif layout == "lattice":
        lower = rng.integers(0, 6, size=(m, 3)).astype(np.float32) * np.float32(0.5)
        upper = lower + rng.integers(0, 3, size=(m, 3)).astype(np.float32) * np.float32(0.5)
        cell_size = 1.0
    elif layout == "points":
        lower = rng.integers(0, 5, size=(m, 3)).astype(np.float32)
        upper = lower.copy()
        cell_size = 1.0
    else:
        lower = (np.float32(1e5) + rng.uniform(0.0, 3.0, size=(m, 3))).astype(np.float32)
        upper = (lower + rng.uniform(0.0, 0.3, size=(m, 3))).astype(np.float32)
        cell_size = None
    node = rng.integers(0, m // 3, size=m).astype(np.int32)
    expected = _reference(lower, upper, node)
    always, used_always, tests_always = _hash_pairs(lower, upper, node, cell_size, 0)
    never, used_never, tests_never = _hash_pairs(lower, upper, node, cell_size, 2**31)
    assert used_always == 1 and used_never == 0
    assert tests_always == tests_never
    np.testing.assert_array_equal(always, expected)
    np.testing.assert_array_equal(never, expected)


def test_default_choice_follows_the_tests_per_entry() -> None:
    """Sparse boxes (few BV tests per entry) leave the codes off; a crowded cell turns them on."""
    rng = np.random.default_rng(4)
    sparse = rng.uniform(0.0, 50.0, size=(400, 3)).astype(np.float32)
    _, used, _ = _hash_pairs(sparse, sparse + np.float32(0.2), np.arange(400, dtype=np.int32), None,
                             CELL_CODE_MIN_TESTS)
    assert used == 0
    crowded = rng.uniform(0.0, 1.0, size=(400, 3)).astype(np.float32)
    pairs, used, tests = _hash_pairs(crowded, crowded + np.float32(0.9), np.arange(400, dtype=np.int32), 2.0,
                                     CELL_CODE_MIN_TESTS)
    assert used == 1 and tests >= CELL_CODE_MIN_TESTS * 400
    np.testing.assert_array_equal(pairs, _reference(crowded, crowded + np.float32(0.9),
                                                    np.arange(400, dtype=np.int32)))


@pytest.mark.parametrize("method", ["pscc", "spatial-hash"])
@pytest.mark.parametrize("continuous", [False, True])
def test_detector_pairs_do_not_change(method: str, continuous: bool) -> None:
    """Twisted layers (many tests per entry): the same VF / EE rows with the codes always and never."""
    mesh = folded_sheet(1500, layers=3, seed=11)
    x0 = _twist(mesh.vertices, 0.5)
    x1 = _twist(mesh.vertices_end, 0.52)
    h = 0.3 * float(np.linalg.norm(x0[mesh.faces[:, 0]] - x0[mesh.faces[:, 1]], axis=1).mean())
    results = []
    for min_tests in (0, 2**31):
        det = CollisionDetector(mesh.faces, method=method, rest=mesh.rest if method == "pscc" else None,
                                device=DEVICE)
        det.detect(x0, x1 if continuous else None, thickness=h)
        det.spatial_hash.cell_code_min_tests = min_tests
        result = det.detect(x0, x1 if continuous else None, thickness=h)
        results.append((result.vertex_face.copy(), result.edge_edge.copy(), result.stats["triangle_pairs"],
                        int(det.spatial_hash.info.numpy()[INFO_CELL_CODES])))
    (vf_on, ee_on, pairs_on, used_on), (vf_off, ee_off, pairs_off, used_off) = results
    assert used_on == 1 and used_off == 0
    assert vf_on.shape[0] + ee_on.shape[0] > 0
    np.testing.assert_array_equal(vf_on, vf_off)
    np.testing.assert_array_equal(ee_on, ee_off)
    assert pairs_on == pairs_off


@pytest.mark.parametrize("bad", [-1, 2**31 + 1, 1.5, True, "4"])
def test_bad_min_tests(bad: object) -> None:
    with pytest.raises(InputError, match="cell_code_min_tests"):
        SpatialHash(10, DEVICE, cell_code_min_tests=bad)


@wp.kernel
def _codes_from_keys(
    keys: wp.array(dtype=wp.int64),
    entry_face: wp.array(dtype=wp.int32),
    lower: wp.array(dtype=wp.vec3),
    upper: wp.array(dtype=wp.vec3),
    grid: wp.array(dtype=GridState),
    node_bits: int,
    out: wp.array(dtype=wp.uint32),
):
    i = wp.tid()
    f = entry_face[i]
    out[i] = entry_cell_code(keys[i], node_bits, lower[f], upper[f], grid[0])


@pytest.mark.parametrize("offset", [0.0, 1e5])
def test_codes_written_by_the_fill_match_the_keys(offset: float) -> None:
    """The fill stores each entry's code with its face (the sort carries both); decoded from the sorted key
    alone, every live entry's code is the same, for boxes across many cells and far from the origin."""
    rng = np.random.default_rng(5)
    m = 600
    lower = (np.float32(offset) + rng.uniform(0.0, 5.0, size=(m, 3))).astype(np.float32)
    upper = (lower + rng.uniform(0.0, 1.2, size=(m, 3))).astype(np.float32)
    hash_ = SpatialHash(m, DEVICE, cell_code_min_tests=0)
    lower_wp = wp.array(lower, dtype=wp.vec3, device=DEVICE)
    upper_wp = wp.array(upper, dtype=wp.vec3, device=DEVICE)
    hash_.find_pairs(lower_wp, upper_wp, None, 0.7)
    entries = int(hash_.info.numpy()[INFO_LIVE_ENTRIES])
    assert entries > 2 * m
    out = wp.zeros(entries, dtype=wp.uint32, device=DEVICE)
    wp.launch(_codes_from_keys, dim=entries, device=DEVICE,
              inputs=[hash_.entry_key, hash_.entry_face, lower_wp, upper_wp, hash_.grid, (m - 1).bit_length()],
              outputs=[out])
    stored = hash_.entry_code.numpy()[:entries]
    np.testing.assert_array_equal(stored, out.numpy())
    np.testing.assert_array_equal(np.sort(hash_.entry_face.numpy()[:entries]),
                                  np.sort(np.repeat(np.arange(m), hash_.face_cells.numpy()[:m])))
