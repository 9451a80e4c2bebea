"""SpatialHash against a brute-force NumPy reference: exact pair sets, BV test counts, determinism."""

from __future__ import annotations

import dataclasses
import itertools

import numpy as np
import pytest
import warp as wp
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from pscc.collision.spatial_hash import DEFAULT_CELL_SIZE_FACTOR, SpatialHash
from pscc.errors import InputError
from pscc.mesh import folded_sheet, grid_sheet

_SETTINGS = settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])


def _reference(lower: np.ndarray, upper: np.ndarray, node: np.ndarray, faces: np.ndarray | None = None) -> np.ndarray:
    """All pairs (a < b) whose closed boxes overlap and whose node ids differ, sorted."""
    overlap = np.all((lower[:, None, :] <= upper[None, :, :]) & (lower[None, :, :] <= upper[:, None, :]), axis=2)
    overlap &= node[:, None] != node[None, :]
    if faces is not None:
        shared = (faces[:, None, :, None] == faces[None, :, None, :]).any(axis=(2, 3))
        overlap &= ~shared
    return np.argwhere(np.triu(overlap, 1)).astype(np.int32).reshape(-1, 2)


def _wide_mask(lower: np.ndarray, upper: np.ndarray, wide_cell: float) -> np.ndarray:
    """The faces the hash leaves out of the grid: prod_k (e_k / c0 + 1) > max(64, m / 8) in float64."""
    m = lower.shape[0]
    if wide_cell <= 0.0:
        return np.zeros(m, dtype=bool)
    extent = upper.astype(np.float64) - lower.astype(np.float64)
    volume = np.ones(m)
    for k in range(3):
        volume = volume * (extent[:, k] / wide_cell + 1.0)
    return volume > max(64.0, m / 8)


def _reference_bv_tests(lower: np.ndarray, upper: np.ndarray, node: np.ndarray, cell_size: float,
                        wide_cell: float = 0.0) -> int:
    """Sum over cells of sum_{i<j} n_i n_j over the faces in the grid, with the hash's float32 cell
    formula, plus the tests of the wide faces (each against every other face once)."""
    wide = _wide_mask(lower, upper, wide_cell)
    w = int(wide.sum())
    origin = lower[~wide].min(axis=0)
    cs = np.float32(cell_size)
    lo = np.floor((lower - origin) / cs).astype(np.int64)
    hi = np.floor((upper - origin) / cs).astype(np.int64)
    groups: dict[tuple[int, int, int], dict[int, int]] = {}
    for f in np.flatnonzero(~wide):
        for cell in itertools.product(*(range(lo[f, k], hi[f, k] + 1) for k in range(3))):
            per_node = groups.setdefault(cell, {})
            per_node[int(node[f])] = per_node.get(int(node[f]), 0) + 1
    total = 0
    for per_node in groups.values():
        n = np.array(list(per_node.values()), dtype=np.int64)
        total += int((n.sum() ** 2 - (n * n).sum()) // 2)
    return total + w * (lower.shape[0] - w) + w * (w - 1) // 2


def _run(device: str, lower: np.ndarray, upper: np.ndarray, node: np.ndarray | None, cell_size: float | None = None,
         **options) -> tuple[np.ndarray, SpatialHash]:
    hash_ = SpatialHash(lower.shape[0], device, **options)
    node_arr = None if node is None else wp.array(node, dtype=wp.int32, device=device)
    pairs, count = hash_.find_pairs(wp.array(lower, dtype=wp.vec3, device=device),
                                    wp.array(upper, dtype=wp.vec3, device=device), node_arr, cell_size)
    result = hash_.pairs_numpy()
    assert count == result.shape[0] == pairs.shape[0]
    return result, hash_


def _check_exact(device: str, lower, upper, node, cell_size=None, **options) -> SpatialHash:
    faces_np = options.pop("faces_np", None)
    lower = np.ascontiguousarray(lower, dtype=np.float32)
    upper = np.ascontiguousarray(upper, dtype=np.float32)
    node_ref = np.arange(lower.shape[0], dtype=np.int32) if node is None else np.asarray(node, dtype=np.int32)
    got, hash_ = _run(device, lower, upper, node, cell_size, **options)
    expected = _reference(lower, upper, node_ref, faces_np)
    np.testing.assert_array_equal(got, expected)  # sorted, so equality also rules out duplicates
    assert hash_.stats.same_node_tests == 0
    assert hash_.stats.triangle_pairs == expected.shape[0]
    assert hash_.stats.bv_tests == _reference_bv_tests(lower, upper, node_ref, hash_.stats.cell_size,
                                                       hash_.stats.wide_cell_size)
    assert hash_.stats.wide_faces == int(_wide_mask(lower, upper, hash_.stats.wide_cell_size).sum())
    return hash_


@st.composite
def _lattice_boxes(draw):
    """Boxes on a half-unit lattice: exact touching at faces, edges and corners, zero-size boxes,
    corners on cell boundaries (for cell sizes that are multiples of 0.5), clusters and huge boxes."""
    m = draw(st.integers(2, 40))
    corner = draw(st.lists(st.tuples(*[st.integers(0, 8)] * 3), min_size=m, max_size=m))
    size = draw(st.lists(st.tuples(*[st.sampled_from([0, 0, 1, 1, 2, 3])] * 3), min_size=m, max_size=m))
    lower = np.array(corner, dtype=np.float32) * 0.5
    upper = lower + np.array(size, dtype=np.float32) * 0.5
    if draw(st.booleans()):  # many boxes inside one cell
        k = draw(st.integers(2, m))
        lower[:k] = lower[0]
        upper[:k] = lower[0] + np.array(draw(st.lists(st.sampled_from([0.0, 0.1, 0.25]), min_size=3, max_size=3)))
    if draw(st.booleans()):  # one huge box spanning many cells
        i = draw(st.integers(0, m - 1))
        lower[i] = -1.0
        upper[i] = 6.0
    return lower, upper


@st.composite
def _float_boxes(draw):
    m = draw(st.integers(2, 60))
    seed = draw(st.integers(0, 2**31 - 1))
    rng = np.random.default_rng(seed)
    lower = rng.uniform(-1.0, 1.0, (m, 3)).astype(np.float32)
    scale = draw(st.sampled_from([0.0, 0.05, 0.3, 1.0]))
    sizes = (rng.exponential(1.0, (m, 3)) * scale).astype(np.float32)
    sizes[rng.random(m) < 0.1] = 0.0
    return lower, (lower + sizes).astype(np.float32)


def _nodes(draw, m: int, mode: str) -> np.ndarray | None:
    if mode == "none":
        return None
    if mode == "distinct":
        return np.array(draw(st.permutations(range(m))), dtype=np.int32)
    if mode == "grouped":
        groups = draw(st.integers(1, 4))
        return np.array(draw(st.lists(st.integers(0, groups - 1), min_size=m, max_size=m)), dtype=np.int32)
    return np.array(draw(st.lists(st.sampled_from([-(2**31), -1, 0, 7, 2**31 - 1]), min_size=m, max_size=m)),
                     dtype=np.int32)


@_SETTINGS
@given(data=st.data(), boxes=_lattice_boxes(), mode=st.sampled_from(["none", "distinct", "grouped", "extreme"]),
       cell_size=st.sampled_from([None, 0.5, 1.0, 0.3, 7.0]))
def test_lattice_boxes_match_reference(device: str, data, boxes, mode: str, cell_size) -> None:
    lower, upper = boxes
    _check_exact(device, lower, upper, _nodes(data.draw, lower.shape[0], mode), cell_size)


@_SETTINGS
@given(data=st.data(), boxes=_float_boxes(), mode=st.sampled_from(["none", "distinct", "grouped"]),
       factor=st.sampled_from([0.5, 1.0, 2.0, 4.0]))
def test_random_boxes_match_reference(device: str, data, boxes, mode: str, factor: float) -> None:
    lower, upper = boxes
    _check_exact(device, lower, upper, _nodes(data.draw, lower.shape[0], mode), cell_size_factor=factor)


def test_touching_unit_cubes(device: str) -> None:
    """A 4^3 lattice of unit cubes touching at faces, edges and corners, cells aligned on them."""
    corners = np.array(list(itertools.product(range(4), repeat=3)), dtype=np.float32)
    for cell_size in (1.0, 0.5, 2.0, None):
        hash_ = _check_exact(device, corners, corners + 1.0, None, cell_size)
    assert hash_.stats.triangle_pairs == 3 * (3 * 16) + 6 * (3 * 3 * 4) + 4 * 27  # faces + edges + corners


def test_points_on_cell_boundaries(device: str) -> None:
    """Zero-size boxes, several at the same point, on cell corners."""
    points = np.array([[0, 0, 0], [0, 0, 0], [1, 1, 1], [1, 1, 1], [1, 1, 1], [2, 0, 1], [2, 0, 1]], np.float32)
    hash_ = _check_exact(device, points, points.copy(), None, 1.0)
    assert hash_.stats.triangle_pairs == 1 + 3 + 1


def test_many_boxes_in_one_cell(device: str) -> None:
    rng = np.random.default_rng(1)
    lower = rng.uniform(0.0, 0.4, (300, 3)).astype(np.float32)
    upper = lower + rng.uniform(0.0, 0.1, (300, 3)).astype(np.float32)
    _check_exact(device, lower, upper, None, 1.0)
    _check_exact(device, lower, upper, rng.integers(0, 5, 300).astype(np.int32), 1.0)


def test_huge_box_spanning_many_cells(device: str) -> None:
    rng = np.random.default_rng(2)
    lower = rng.uniform(0.0, 10.0, (400, 3)).astype(np.float32)
    upper = lower + 0.05
    lower[7], upper[7] = -1.0, 11.0
    hash_ = _check_exact(device, lower, upper, None, cell_size=0.5, max_wide_faces=0)
    assert hash_.stats.coarsenings == 0 and hash_.stats.wide_faces == 0
    assert hash_.stats.entries > 24**3  # the huge box sits in every cell of the grid
    # By default it is a wide face: out of the grid, tested against the 399 others.
    hash_ = _check_exact(device, lower, upper, None, cell_size=0.5)
    assert hash_.stats.wide_faces == 1 and hash_.stats.wide_tests == 399
    assert hash_.stats.entries < 8 * 399


@st.composite
def _scenes_with_wide_faces(draw):
    """Small boxes in the unit cube and 1 to 3 boxes far larger than the scene (flat ones like a ground
    quad, or solid), some of them touching each other."""
    m = draw(st.integers(64, 240))
    rng = np.random.default_rng(draw(st.integers(0, 2**31 - 1)))
    lower = rng.uniform(0.0, 1.0, (m, 3)).astype(np.float32)
    upper = (lower + rng.exponential(0.03, (m, 3))).astype(np.float32)
    wide = draw(st.integers(1, 3))
    for i in rng.choice(m, wide, replace=False):
        half = draw(st.sampled_from([20.0, 60.0, 300.0]))
        height = np.float32(rng.uniform(0.0, 1.0))
        flat = draw(st.booleans())
        lower[i] = (0.5 - half, 0.5 - half, height if flat else 0.5 - half)
        upper[i] = (0.5 + half, 0.5 + half, height if flat else 0.5 + half)
    return lower, upper, wide


@_SETTINGS
@given(data=st.data(), scene=_scenes_with_wide_faces(), mode=st.sampled_from(["none", "distinct", "grouped"]),
       cell_size=st.sampled_from([None, None, 0.05]))
def test_wide_faces_match_reference(device: str, data, scene, mode: str, cell_size) -> None:
    lower, upper, wide = scene
    hash_ = _check_exact(device, lower, upper, _nodes(data.draw, lower.shape[0], mode), cell_size)
    assert hash_.stats.wide_faces == wide
    assert hash_.stats.entries <= 8 * lower.shape[0]  # the grid holds the small boxes only


def test_wide_faces_leave_the_grid_as_it_was(device: str) -> None:
    """Two ground quads around a cloth-like layer: the cell size and the entries of the others are
    those without the ground, and every pair with the ground is found."""
    lower, upper, _ = _cloth_boxes(1500, seed=7)
    plain = _check_exact(device, lower, upper, None)
    ground_lower = np.array([[-50.0, -50.0, 0.3], [-50.0, -50.0, 0.3]], dtype=np.float32)
    ground_upper = np.array([[50.0, 50.0, 0.3], [50.0, 50.0, 0.3]], dtype=np.float32)
    with_ground = _check_exact(device, np.concatenate([lower, ground_lower]), np.concatenate([upper, ground_upper]),
                               None)
    assert with_ground.stats.wide_faces == 2
    assert with_ground.stats.cell_size == plain.stats.cell_size
    assert with_ground.stats.entries == plain.stats.entries
    assert with_ground.stats.triangle_pairs > plain.stats.triangle_pairs + 2  # the layer crosses the ground
    inserted = _check_exact(device, np.concatenate([lower, ground_lower]), np.concatenate([upper, ground_upper]),
                            None, max_wide_faces=0)
    assert inserted.stats.wide_faces == 0 and inserted.stats.cell_size > 2 * plain.stats.cell_size


def test_too_many_wide_faces_are_inserted(device: str) -> None:
    """More wide faces than face_count / 8 (or than ``max_wide_faces``): every face goes in the grid."""
    rng = np.random.default_rng(8)
    lower = rng.uniform(0.0, 1.0, (64, 3)).astype(np.float32)
    upper = lower + 0.02
    lower[:9], upper[:9] = -20.0, 21.0  # 9 > 64 / 8
    assert _check_exact(device, lower, upper, None).stats.wide_faces == 0
    assert _check_exact(device, lower[5:], upper[5:], None).stats.wide_faces == 4
    assert _check_exact(device, lower[5:], upper[5:], None, max_wide_faces=3).stats.wide_faces == 0


def test_grid_guard_coarsens_without_losing_pairs(device: str) -> None:
    rng = np.random.default_rng(3)
    lower = rng.uniform(0.0, 10.0, (200, 3)).astype(np.float32)
    upper = lower + 0.05
    lower[0], upper[0] = -1.0, 11.0
    hash_ = _check_exact(device, lower, upper, None, max_mean_cells_per_face=2.0, max_wide_faces=0)
    assert hash_.stats.coarsenings > 0
    assert hash_.stats.entries <= 2 * 200
    hash_ = _check_exact(device, lower, upper, None, cell_size=1e-6)  # grid cap
    assert hash_.stats.coarsenings > 0


def _cloth_boxes(triangle_count: int, seed: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    mesh = folded_sheet(triangle_count, layers=3, seed=seed)
    tri0 = mesh.vertices[mesh.faces]
    tri1 = mesh.vertices_end[mesh.faces]
    lower = np.minimum(tri0.min(axis=1), tri1.min(axis=1)) - 1e-3
    upper = np.maximum(tri0.max(axis=1), tri1.max(axis=1)) + 1e-3
    return lower.astype(np.float32), upper.astype(np.float32), mesh.faces


def test_cloth_boxes_with_culling(device: str) -> None:
    lower, upper, faces = _cloth_boxes(1500, seed=4)
    m = lower.shape[0]
    baseline = _check_exact(device, lower, upper, None)
    patches = (np.arange(m) // 50).astype(np.int32)  # contiguous patches, like front nodes
    culled = _check_exact(device, lower, upper, patches)
    assert culled.stats.bv_tests < baseline.stats.bv_tests
    assert culled.stats.triangle_pairs < baseline.stats.triangle_pairs


def test_skip_adjacent_is_opt_in(device: str) -> None:
    vertices, faces, _ = grid_sheet(6, 6)
    tri = vertices[faces]
    lower = (tri.min(axis=1) - 0.01).astype(np.float32)
    upper = (tri.max(axis=1) + 0.01).astype(np.float32)
    kept = _check_exact(device, lower, upper, None)
    faces_wp = wp.array(faces, dtype=wp.vec3i, device=device)
    skipped = _check_exact(device, lower, upper, None, faces=faces_wp, skip_adjacent=True, faces_np=faces)
    assert 0 < skipped.stats.triangle_pairs < kept.stats.triangle_pairs


def test_same_node_never_paired(device: str) -> None:
    rng = np.random.default_rng(5)
    lower = rng.uniform(0.0, 1.0, (500, 3)).astype(np.float32)
    upper = lower + 0.2
    node = np.zeros(500, dtype=np.int32)
    got, hash_ = _run(device, lower, upper, node)
    assert got.shape[0] == 0 and hash_.stats.bv_tests == 0
    node[::2] = 1
    hash_ = _check_exact(device, lower, upper, node)
    assert hash_.stats.same_node_tests == 0


def test_deterministic(device: str) -> None:
    lower, upper, _ = _cloth_boxes(3000, seed=6)
    node = (np.arange(lower.shape[0]) // 40).astype(np.int32)
    hash_ = SpatialHash(lower.shape[0], device)
    args = (wp.array(lower, dtype=wp.vec3, device=device), wp.array(upper, dtype=wp.vec3, device=device),
            wp.array(node, dtype=wp.int32, device=device))
    hash_.find_pairs(*args)
    first, stats = hash_.pairs_numpy(), hash_.stats
    assert stats.reruns == 1  # the first call grew the pair buffer
    for _ in range(2):
        hash_.find_pairs(*args)
        np.testing.assert_array_equal(hash_.pairs_numpy(), first)
        assert hash_.stats == dataclasses.replace(stats, reruns=0, device_bytes=hash_.device_bytes)
    assert np.all(first[:, 0] < first[:, 1])


def test_buffers_grow(device: str) -> None:
    lower, upper, _ = _cloth_boxes(1000, seed=7)
    hash_ = _check_exact(device, lower, upper, None, pair_capacity=1)
    assert hash_.stats.reruns == 1 and hash_.pair_capacity >= hash_.stats.triangle_pairs
    # Entries grow too: a finer grid needs more than the initial 4 per face.
    hash_ = _check_exact(device, lower, upper, None, cell_size_factor=0.25, pair_capacity=1)
    assert hash_.stats.mean_cells_per_face > 4.0
    # Small batches of BV tests cover the same range (the CPU's default launch is one thread: ask for more).
    _check_exact(device, lower, upper, None, tests_per_launch=97, test_threads=2**10)


def test_cell_size_factor_does_not_change_pairs(device: str) -> None:
    lower, upper, _ = _cloth_boxes(1200, seed=8)
    node = (np.arange(lower.shape[0]) // 30).astype(np.int32)
    results = [_run(device, lower, upper, node, cell_size_factor=k)[0] for k in (0.5, 1.0, 2.0, 3.0, 8.0, 100.0)]
    for result in results[1:]:
        np.testing.assert_array_equal(result, results[0])


def test_tiny_inputs(device: str) -> None:
    for m in (0, 1):
        got, hash_ = _run(device, np.zeros((m, 3), np.float32), np.ones((m, 3), np.float32), None)
        assert got.shape == (0, 2) and hash_.stats.triangle_pairs == 0
    _check_exact(device, np.zeros((2, 3)), np.zeros((2, 3)), None)  # two equal points: zero extent


def test_bad_arguments(device: str) -> None:
    m = 4
    hash_ = SpatialHash(m, device)
    good = wp.zeros(m, dtype=wp.vec3, device=device)
    with pytest.raises(InputError, match="face_lower"):
        hash_.find_pairs(wp.zeros(m + 1, dtype=wp.vec3, device=device), good)
    with pytest.raises(InputError, match="face_upper"):
        hash_.find_pairs(good, np.zeros((m, 3), np.float32))
    with pytest.raises(InputError, match="node_id"):
        hash_.find_pairs(good, good, wp.zeros(m, dtype=wp.int64, device=device))
    with pytest.raises(InputError, match="cell_size"):
        hash_.find_pairs(good, good, None, 0.0)
    inverted = wp.array(np.full((m, 3), -1.0, np.float32), dtype=wp.vec3, device=device)
    with pytest.raises(InputError, match="lower > upper"):
        hash_.find_pairs(good, inverted)
    nan = wp.array(np.full((m, 3), np.nan, np.float32), dtype=wp.vec3, device=device)
    with pytest.raises(InputError, match="NaN"):
        hash_.find_pairs(nan, good)
    with pytest.raises(InputError, match="skip_adjacent"):
        SpatialHash(m, device, skip_adjacent=True)
    with pytest.raises(InputError, match="cell_size_factor"):
        SpatialHash(m, device, cell_size_factor=-1.0)


def test_unsorted_pairs_are_the_same_set(device: str) -> None:
    lower, upper, _ = _cloth_boxes(1500, seed=6)
    patches = (np.arange(lower.shape[0]) // 40).astype(np.int32)
    sorted_pairs, _ = _run(device, lower, upper, patches)
    unsorted, hash_ = _run(device, lower, upper, patches, sort_pairs=False, pair_capacity=8)
    assert hash_.stats.reruns > 0  # the unsorted buffer grew too
    assert len(unsorted) == len(sorted_pairs)
    np.testing.assert_array_equal(unsorted[np.lexsort(unsorted.T[::-1])], sorted_pairs)
    assert hash_.device_bytes["pair_keys"] < 64


def test_tests_per_thread_does_not_change_pairs(device: str) -> None:
    lower, upper, _ = _cloth_boxes(1200, seed=8)
    patches = (np.arange(lower.shape[0]) // 30).astype(np.int32)
    one, hash_one = _run(device, lower, upper, patches, tests_per_thread=1, test_threads=2**10)
    many, hash_many = _run(device, lower, upper, patches, tests_per_thread=7, test_threads=2**10)
    single, hash_single = _run(device, lower, upper, patches, test_threads=1)
    np.testing.assert_array_equal(one, many)
    np.testing.assert_array_equal(one, single)
    assert hash_one.test_threads > 1 and hash_many.test_threads > 1 and hash_single.test_threads == 1
    assert hash_one.stats.bv_tests == hash_many.stats.bv_tests == hash_single.stats.bv_tests


def test_device_bytes_counts_every_buffer_it_owns() -> None:
    """Every wp.array the hash holds is in ``device_bytes``, except views into another buffer (the
    ranks and group starts in the sort's scratch halves)."""
    hash_ = SpatialHash(64, "cpu", faces=wp.zeros(64, dtype=wp.vec3i, device="cpu"), group_slab_test=True)
    lower = np.random.default_rng(0).uniform(0.0, 2.0, size=(64, 3)).astype(np.float32)
    hash_.find_pairs(wp.array(lower, dtype=wp.vec3, device="cpu"),
                     wp.array(lower + np.float32(0.3), dtype=wp.vec3, device="cpu"))
    arrays = {name: value for name, value in vars(hash_).items() if isinstance(value, wp.array) and value.capacity}

    def inside_another(name: str) -> bool:
        a = arrays[name]
        return any(other != name and b.ptr <= a.ptr < b.ptr + b.capacity and (b.ptr, -b.capacity) < (a.ptr, -a.capacity)
                   for other, b in arrays.items())

    owned = {name for name in arrays if not inside_another(name)}
    counted = set(hash_.device_bytes)
    assert owned - counted == set()
    assert {"group_rank", "cell_rank", "group_start", "row_count", "row_end"}.isdisjoint(owned)


def test_wide_face_sharing_a_vertex(device: str) -> None:
    """A wide face that shares sheet vertices is dropped with ``skip_adjacent`` against exactly the faces it
    shares one with, like a face in the grid."""
    vertices, faces, _ = grid_sheet(8, 8)
    far = vertices.max(axis=0) + 200.0
    vertices = np.concatenate([vertices, [far, far + np.float32([0.0, 200.0, 0.0])]]).astype(np.float32)
    n = len(vertices)
    faces = np.concatenate([faces, [[0, n - 2, n - 1]]]).astype(np.int32)  # from sheet vertex 0 far away
    tri = vertices[faces]
    lower = (tri.min(axis=1) - 0.01).astype(np.float32)
    upper = (tri.max(axis=1) + 0.01).astype(np.float32)
    faces_wp = wp.array(faces, dtype=wp.vec3i, device=device)
    skipped = _check_exact(device, lower, upper, None, faces=faces_wp, skip_adjacent=True, faces_np=faces)
    kept = _check_exact(device, lower, upper, None)
    assert skipped.stats.wide_faces == kept.stats.wide_faces == 1
    assert skipped.stats.triangle_pairs < kept.stats.triangle_pairs


def test_long_faces_leave_the_mean_but_not_the_grid(device: str) -> None:
    """A few faces far longer than the rest (a collider's walls beside the cloth) do not set the cell size:
    it is the factor times the mean box axis length of the other faces; the pairs are exact."""
    rng = np.random.default_rng(9)
    lower = rng.uniform(0.0, 4.0, (400, 3)).astype(np.float32)
    upper = (lower + rng.uniform(0.05, 0.15, (400, 3))).astype(np.float32)
    upper[:20, 0] = lower[:20, 0] + 3.0  # 20 slivers 30 times as long on x
    hash_ = _check_exact(device, lower, upper, None)
    assert hash_.stats.long_faces == 20 and hash_.stats.wide_faces == 0
    mean_length = ((upper[20:].astype(np.float64) - lower[20:]).mean(axis=1)).mean()
    assert hash_.stats.cell_size == pytest.approx(DEFAULT_CELL_SIZE_FACTOR * mean_length, rel=1e-6)
    fixed = _check_exact(device, lower, upper, None, cell_size=0.5)
    assert fixed.stats.long_faces == 0 and fixed.stats.cell_size == 0.5
