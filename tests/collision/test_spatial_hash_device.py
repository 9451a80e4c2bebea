"""The device paths of SpatialHash and IntersectionCheck: graph capture and replay bit-identical to the
eager call, no host traffic, device overflow flags that the sync points turn into growth and exact
re-runs, and input errors deferred to the sync point."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest
import warp as wp

from pscc.bench.host_traffic import count_host_traffic, device_path_traffic
from pscc.collision import _spatial_hash_kernels as kernels
from pscc.collision.intersection import IntersectionCheck
from pscc.collision.spatial_hash import MIN_CELL_BITS, SpatialHash
from pscc.errors import InputError
from pscc.mesh import folded_sheet, grid_sheet
from tests.collision.test_spatial_hash import _reference

_PATCH = 50


def _scene(triangle_count: int = 1500, seed: int = 4) -> dict[str, Any]:
    """A folded cloth over a step: boxes of both ends grown by 1e-3, patch nodes, positions."""
    mesh = folded_sheet(triangle_count, layers=3, seed=seed)
    tri0 = mesh.vertices[mesh.faces]
    tri1 = mesh.vertices_end[mesh.faces]
    lower = (np.minimum(tri0.min(axis=1), tri1.min(axis=1)) - 1e-3).astype(np.float32)
    upper = (np.maximum(tri0.max(axis=1), tri1.max(axis=1)) + 1e-3).astype(np.float32)
    m = lower.shape[0]
    node = (np.arange(m) // _PATCH).astype(np.int32)
    # A permutation that keeps every patch contiguous: patches in reverse order, each reversed.
    order = np.arange(m, dtype=np.int32)[::-1].copy()
    return {"mesh": mesh, "lower": lower, "upper": upper, "node": node, "order": order, "m": m}


def _configs(scene: dict[str, Any], device: str) -> dict[str, tuple[dict, dict]]:
    """Hash options and call arguments of plain hashing, node culling and the PSCC-like call."""
    mesh, m = scene["mesh"], scene["m"]
    arr = {
        "face_lower": wp.array(scene["lower"], dtype=wp.vec3, device=device),
        "face_upper": wp.array(scene["upper"], dtype=wp.vec3, device=device),
    }
    node = wp.array(scene["node"], dtype=wp.int32, device=device)
    faces = wp.array(mesh.faces, dtype=wp.vec3i, device=device)
    pscc_call = dict(arr, node_id=node, positions_t0=wp.array(mesh.vertices, dtype=wp.vec3, device=device),
                     positions_t1=wp.array(mesh.vertices_end, dtype=wp.vec3, device=device), half_distance=1e-3,
                     node_id_bound=m // _PATCH + 1,
                     face_order=wp.array(scene["order"], dtype=wp.int32, device=device))
    return {
        "plain": ({}, dict(arr)),
        "nodes-unsorted": ({"sort_pairs": False}, dict(arr, node_id=node)),
        "coarsened": ({"max_mean_cells_per_face": 1.0}, dict(arr)),
        "pscc": ({"faces": faces, "group_slab_test": True, "skip_adjacent": True}, pscc_call),
    }


def _valid_pairs(hash_: SpatialHash) -> np.ndarray:
    count = min(int(hash_.counts.numpy()[0]), hash_.pair_capacity)
    return hash_.pairs.numpy()[:count].copy()


def _snapshot(hash_: SpatialHash) -> dict[str, np.ndarray]:
    entries = int(hash_.summary.numpy()[kernels.INFO_LIVE_ENTRIES])
    return {"counts": hash_.counts.numpy().copy(), "summary": hash_.summary.numpy().copy(),
            "pairs": _valid_pairs(hash_), "entry_key": hash_.entry_key.numpy()[:entries].copy(),
            "entry_face": hash_.entry_face.numpy()[:entries].copy()}


def _poison(hash_: SpatialHash) -> None:
    hash_.pairs.fill_(wp.vec2i(-7, -7))
    hash_.entry_key.fill_(-7)
    hash_.counts.fill_(-7)
    hash_.summary.fill_(-7.0)


@pytest.mark.parametrize("config", ["plain", "nodes-unsorted", "coarsened", "pscc"])
def test_capture_replay_is_bit_identical_to_eager(device: str, config: str) -> None:
    scene = _scene()
    options, call = _configs(scene, device)[config]
    hash_ = SpatialHash(scene["m"], device, **options)
    hash_.find_pairs(**call)  # sizes the buffers
    expected = hash_.pairs_numpy()
    hash_.find_pairs_device(**call)
    assert hash_.check_capacity()
    eager = _snapshot(hash_)
    if config == "coarsened":
        assert hash_.stats.coarsenings > 0  # the grid loop ran more than once
    np.testing.assert_array_equal(np.sort(eager["pairs"].view(np.int64).ravel()),
                                  np.sort(expected.view(np.int64).ravel()))
    _poison(hash_)
    with wp.ScopedCapture(device=device) as capture:
        hash_.find_pairs_device(**call)
    assert np.all(hash_.counts.numpy() == -7)  # recorded, not run
    for _ in range(2):
        _poison(hash_)
        wp.capture_launch(capture.graph)
        replay = _snapshot(hash_)
        for name in ("counts", "summary", "entry_key", "entry_face"):
            assert replay[name].tobytes() == eager[name].tobytes(), name
        if options.get("sort_pairs", True) or wp.get_device(device).is_cpu:
            assert replay["pairs"].tobytes() == eager["pairs"].tobytes()
        else:  # unsorted atomic appends on a GPU: same set
            np.testing.assert_array_equal(np.sort(replay["pairs"].view(np.int64).ravel()),
                                          np.sort(eager["pairs"].view(np.int64).ravel()))
    assert hash_.check_capacity()


def test_replay_follows_new_array_contents(device: str) -> None:
    """A recorded graph reads the arrays by pointer: new boxes in the same arrays give their pairs."""
    first, second = _scene(seed=4), _scene(seed=9)
    m = first["m"]
    assert second["m"] == m
    lower = wp.array(first["lower"], dtype=wp.vec3, device=device)
    upper = wp.array(first["upper"], dtype=wp.vec3, device=device)
    hash_ = SpatialHash(m, device)
    for scene in (second, first):  # size the buffers for both inputs
        lower.assign(scene["lower"])
        upper.assign(scene["upper"])
        hash_.find_pairs(lower, upper)
    with wp.ScopedCapture(device=device) as capture:
        hash_.find_pairs_device(lower, upper)
    lower.assign(second["lower"])
    upper.assign(second["upper"])
    wp.capture_launch(capture.graph)
    assert hash_.check_capacity()
    expected = _reference(second["lower"], second["upper"], np.arange(m))
    np.testing.assert_array_equal(_valid_pairs(hash_), expected)
    assert hash_.stats.triangle_pairs == expected.shape[0]


def test_device_path_makes_no_host_traffic(device: str, monkeypatch: pytest.MonkeyPatch) -> None:
    scene = _scene()
    hashes = []
    for options, call in _configs(scene, device).values():
        hash_ = SpatialHash(scene["m"], device, **options)
        hash_.find_pairs(**call)
        hashes.append((hash_, call))
    mesh = scene["mesh"]
    check = IntersectionCheck(mesh.faces, mesh.vertex_count, device)
    positions = wp.array(mesh.vertices_end, dtype=wp.vec3, device=device)
    check.find(positions)
    with count_host_traffic() as traffic:
        wp.array(np.zeros(2, np.float32), device=device).numpy()  # the counters themselves work
    assert traffic["reads"] == 1 and traffic["uploads"] == 1

    def device_path() -> None:
        for hash_, call in hashes:
            hash_.find_pairs_device(**call)
        check.count_device(positions, cloth_face_count=scene["m"] // 2)

    device_path()
    traffic = device_path_traffic(device, device_path)
    assert traffic == {"reads": 0, "syncs": 0, "uploads": 0, "allocations": 0}
    assert all(hash_.check_capacity() for hash_, _ in hashes) and check.check_capacity()


def test_overflow_flags_growth_and_exact_rerun(device: str) -> None:
    scene = _scene(1000, seed=7)
    lower, upper, m = scene["lower"], scene["upper"], scene["m"]
    expected = _reference(lower, upper, np.arange(m))
    # A fine grid (more than the initial 4 entries per face), one pair slot: every stage overflows in turn.
    hash_ = SpatialHash(m, device, cell_size_factor=0.25, pair_capacity=1)
    args = (wp.array(lower, dtype=wp.vec3, device=device), wp.array(upper, dtype=wp.vec3, device=device))
    hash_.find_pairs_device(*args)
    summary = hash_.summary.numpy()
    assert summary[kernels.INFO_ENTRIES] > hash_.entry_capacity  # the true count is kept ...
    assert summary[kernels.INFO_LIVE_ENTRIES] == 0 and hash_.counts.numpy()[0] == 0  # ... and nothing ran on
    grown = []
    for _ in range(8):
        counted = int(hash_.counts.numpy()[0])
        capacity = hash_.pair_capacity
        if hash_.check_capacity():
            break
        grown.append((counted, capacity))
        hash_.find_pairs_device(*args)
    else:
        pytest.fail("the buffers never fit")
    assert hash_.entry_capacity >= summary[kernels.INFO_ENTRIES]
    # The pair counter kept counting past its one slot: the exact count, which sized the buffer.
    assert (expected.shape[0], 1) in grown
    assert hash_.pair_capacity == int(expected.shape[0] * 1.25)
    np.testing.assert_array_equal(_valid_pairs(hash_), expected)
    assert hash_.stats.triangle_pairs == expected.shape[0] and hash_.stats.mean_cells_per_face > 4.0


def test_cell_bits_grow_for_large_grids(device: str) -> None:
    """A grid beyond the sort's cell bits is coarsened on the device (same pairs); the sync point
    widens the bits and asks for a re-run, which uses the requested grid."""
    rng = np.random.default_rng(11)
    lower = rng.uniform(0.0, 100.0, (300, 3)).astype(np.float32)
    upper = (lower + rng.uniform(0.0, 3.0, (300, 3))).astype(np.float32)
    expected = _reference(lower, upper, np.arange(300))
    hash_ = SpatialHash(300, device)
    assert hash_.cell_bits == MIN_CELL_BITS
    args = (wp.array(lower, dtype=wp.vec3, device=device), wp.array(upper, dtype=wp.vec3, device=device))
    hash_.find_pairs_device(*args, cell_size=1.0)
    wanted = int(hash_.summary.numpy()[kernels.INFO_WANTED_CELLS])
    assert wanted > 2**MIN_CELL_BITS
    np.testing.assert_array_equal(_valid_pairs(hash_), expected)  # already exact on the coarse grid
    assert not hash_.check_capacity()
    assert hash_.cell_bits == (wanted - 1).bit_length() and hash_.stats.coarsenings > 0
    for _ in range(4):  # the finer grid may need more entries, groups, rows and pairs
        hash_.find_pairs_device(*args, cell_size=1.0)
        if hash_.check_capacity():
            break
    else:
        pytest.fail("the buffers never fit")
    assert hash_.stats.coarsenings == 0 and np.prod(hash_.stats.grid_dims) == wanted
    assert hash_.stats.cell_size == 1.0
    np.testing.assert_array_equal(_valid_pairs(hash_), expected)


def test_input_errors_are_deferred_to_the_sync_point(device: str) -> None:
    m = 6
    rng = np.random.default_rng(3)
    lower = rng.uniform(0.0, 0.1, (m, 3)).astype(np.float32)  # every box holds the cell of the origin
    good = (wp.array(lower, dtype=wp.vec3, device=device), wp.array(lower + 0.5, dtype=wp.vec3, device=device))
    hash_ = SpatialHash(m, device)
    with pytest.raises(InputError, match="no device call"):
        hash_.check_capacity()
    bad = lower.copy()
    bad[2, 1] = np.nan
    hash_.find_pairs_device(wp.array(bad, dtype=wp.vec3, device=device), good[1])
    with pytest.raises(InputError, match="NaN"):
        hash_.check_capacity()
    node = wp.array(np.array([0, 0, 1, 1, 2, 5], np.int32), dtype=wp.int32, device=device)
    hash_.find_pairs_device(*good, node, node_id_bound=3)
    with pytest.raises(InputError, match="node ids lie outside"):
        hash_.check_capacity()
    # Ids out of range in the order: caught before any kernel indexes with them.
    for order in ([0, 1, 2, 3, 4, 99], [0, 1, 2, 3, 4, 4], [-1, 1, 2, 3, 4, 5]):
        hash_.find_pairs_device(*good, node, face_order=wp.array(np.array(order, np.int32), device=device))
        with pytest.raises(InputError, match="permutation"):
            hash_.check_capacity()
    split = wp.array(np.array([0, 2, 1, 3, 4, 5], np.int32), device=device)  # node 0 = faces 0, 1 split by 2
    hash_.find_pairs_device(*good, node, face_order=split)
    with pytest.raises(InputError, match="contiguous"):
        hash_.check_capacity()
    hash_.find_pairs(*good, node)  # a good call is fine again
    hash_.find_pairs_device(*good, node)
    assert hash_.check_capacity()
    np.testing.assert_array_equal(_valid_pairs(hash_), _reference(lower, lower + 0.5, node.numpy()))


def _intersecting_scene(device: str) -> tuple[IntersectionCheck, np.ndarray, np.ndarray, int]:
    """A flat cloth pierced by an upright obstacle sheet, and far away two obstacle sheets crossing
    each other (obstacle-obstacle crossings, which the cloth count leaves out)."""
    flat, faces, _ = grid_sheet(8, 8)
    upright = np.stack([flat[:, 0] + 0.031, np.full(len(flat), 0.513, np.float32), flat[:, 1] - 0.47], axis=1)
    far = np.array([5.0, 0.0, 0.0], np.float32)
    parts = [flat, upright, flat + far, upright + far]
    positions = np.concatenate(parts).astype(np.float32)
    all_faces = np.concatenate([faces + k * len(flat) for k in range(len(parts))]).astype(np.int32)
    check = IntersectionCheck(all_faces, positions.shape[0], device, hit_capacity=1)
    return check, positions, all_faces, faces.shape[0]


def test_intersection_count_device(device: str, monkeypatch: pytest.MonkeyPatch) -> None:
    check, positions, faces, cloth_faces = _intersecting_scene(device)
    hits = check.find(positions)
    owners = check.edge_owner_faces[hits[:, 0]]
    cloth_hits = int(((owners < cloth_faces) | (hits[:, 1] < cloth_faces)).sum())
    assert 0 < cloth_hits < hits.shape[0]  # some crossings are among the second copy only
    points = wp.array(positions, dtype=wp.vec3, device=device)
    for cloth, expected in ((None, hits.shape[0]), (cloth_faces, cloth_hits), (0, 0)):
        check.count_device(points, cloth)
        assert check.check_capacity()
        assert int(check.crossing_count.numpy()[0]) == expected
    # Capture and replay: bit-identical counters and hits.
    check.count_device(points, cloth_faces)
    assert check.check_capacity()
    eager = (check.crossing_count.numpy().copy(), check.hit_count.numpy().copy())
    with wp.ScopedCapture(device=device) as capture:
        check.count_device(points, cloth_faces)
    check.crossing_count.fill_(-1)
    wp.capture_launch(capture.graph)
    assert (check.crossing_count.numpy().tobytes(), check.hit_count.numpy().tobytes()) == \
        (eager[0].tobytes(), eager[1].tobytes())
    # Overflow: a fresh check with one hit slot grows and re-runs to the exact count.
    small = IntersectionCheck(faces, positions.shape[0], device, hit_capacity=1)
    small.count_device(points, cloth_faces)
    runs = 1
    while not small.check_capacity():
        small.count_device(points, cloth_faces)
        runs += 1
    assert runs >= 2 and small.hit_capacity >= hits.shape[0]
    assert int(small.crossing_count.numpy()[0]) == cloth_hits
    assert small.has_intersections(positions) and small.stats.hits == hits.shape[0]
    with pytest.raises(InputError, match="cloth_face_count"):
        small.count_device(points, -1)
    with pytest.raises(InputError, match="positions"):
        small.count_device(positions)
