"""The group slab test of SpatialHash: it only drops face pairs that are farther apart than the
distance (checked with float64 ipctk distances), never a box pair that is closer, and it cuts the
face tests between stacked layers."""

from __future__ import annotations

import ipctk
import numpy as np
import pytest
import warp as wp
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from pscc.collision.detector import CollisionDetector
from pscc.collision.spatial_hash import SpatialHash
from pscc.errors import InputError
from pscc.mesh import folded_sheet, grid_sheet
from tests.collision.test_spatial_hash import _reference

_SETTINGS = settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])


def _boxes(faces: np.ndarray, x0: np.ndarray, x1: np.ndarray | None, half: float) -> tuple[np.ndarray, np.ndarray]:
    """Face boxes over the step grown by ``half`` (and a relative pad, like PrimitiveBoxes)."""
    corners = x0[faces] if x1 is None else np.concatenate([x0[faces], x1[faces]], axis=1)
    lower = corners.min(axis=1).astype(np.float64)
    upper = corners.max(axis=1).astype(np.float64)
    pad = half + 2.0**-21 * np.maximum(np.abs(lower), np.abs(upper)).max(axis=1, keepdims=True)
    return (lower - pad).astype(np.float32), (upper + pad).astype(np.float32)


def _find(faces, x0, x1, node, half, *, slab: bool, cell_size=None, **options):
    device = "cpu"
    hash_ = SpatialHash(faces.shape[0], device, faces=wp.array(faces, dtype=wp.vec3i, device=device),
                        group_slab_test=slab, **options)
    lower, upper = _boxes(faces, x0, x1, half)
    hash_.find_pairs(wp.array(lower, dtype=wp.vec3, device=device), wp.array(upper, dtype=wp.vec3, device=device),
                     wp.array(node, dtype=wp.int32, device=device), cell_size,
                     positions_t0=wp.array(x0, dtype=wp.vec3, device=device),
                     positions_t1=None if x1 is None else wp.array(x1, dtype=wp.vec3, device=device),
                     half_distance=half)
    return hash_.pairs_numpy(), hash_, lower, upper


def _triangle_distance(a: np.ndarray, b: np.ndarray) -> float:
    """Exact (float64) distance between triangles a and b, (3, 3) arrays each."""
    a = a.astype(np.float64)
    b = b.astype(np.float64)
    for p, q in ((a, b), (b, a)):
        for i in range(3):
            if ipctk.is_edge_intersecting_triangle(p[i], p[(i + 1) % 3], q[0], q[1], q[2]):
                return 0.0
    best = np.inf
    for p, q in ((a, b), (b, a)):
        for i in range(3):
            best = min(best, ipctk.point_triangle_distance(p[i], q[0], q[1], q[2]))
    for i in range(3):
        for j in range(3):
            best = min(best, ipctk.edge_edge_distance(a[i], a[(i + 1) % 3], b[j], b[(j + 1) % 3]))
    return float(np.sqrt(best))


def _check_conservative(faces, x0, x1, node, half, **options) -> tuple[SpatialHash, int]:
    """Slab-tested pairs = box pairs less some pairs, and each dropped pair is farther than 2 half
    (at t0 and t1 and at sampled times in between for a step)."""
    got, hash_, lower, upper = _find(faces, x0, x1, node, half, slab=True, **options)
    boxes = _reference(lower, upper, np.asarray(node, dtype=np.int32))
    got_set = {tuple(p) for p in got.tolist()}
    box_set = {tuple(p) for p in boxes.tolist()}
    assert got_set <= box_set
    assert len(got_set) == got.shape[0]
    times = [0.0] if x1 is None else np.linspace(0.0, 1.0, 9)
    for a, b in box_set - got_set:
        for t in times:
            x = x0 if x1 is None else (1.0 - t) * x0.astype(np.float64) + t * x1.astype(np.float64)
            distance = _triangle_distance(x[faces[a]], x[faces[b]])
            assert distance > 2.0 * half * (1.0 - 1e-9), f"pair ({a}, {b}) at distance {distance} was dropped"
    stats = hash_.stats
    assert stats.bv_tests == stats.face_tests + stats.slab_tests
    assert stats.same_node_tests == 0
    return hash_, len(box_set - got_set)


def _patch_nodes(rest: np.ndarray, faces: np.ndarray, patches: int, across: int | None = None) -> np.ndarray:
    """A node id per face: a tiling of the rest (material) coordinates into ``patches`` along x and
    ``across`` (default ``patches``) along y, like the front nodes of flat regions."""
    across = patches if across is None else across
    centre = rest[faces].mean(axis=1)
    lo = centre.min(axis=0)
    span = np.maximum(centre.max(axis=0) - lo, 1e-12)
    tiles = np.array([patches, across])
    cell = np.minimum((tiles * (centre[:, :2] - lo[:2]) / span[:2]).astype(np.int64), tiles - 1)
    return (cell[:, 0] * across + cell[:, 1]).astype(np.int32)


def _twist(points: np.ndarray, turns: float) -> np.ndarray:
    x = points.astype(np.float64)
    centre = x.mean(axis=0)
    angle = 2.0 * np.pi * turns * (x[:, 0] - x[:, 0].min())
    y, z = x[:, 1] - centre[1], x[:, 2] - centre[2]
    out = x.copy()
    out[:, 1] = centre[1] + np.cos(angle) * y - np.sin(angle) * z
    out[:, 2] = centre[2] + np.sin(angle) * y + np.cos(angle) * z
    return out.astype(np.float32)


def _edge(x: np.ndarray, faces: np.ndarray) -> float:
    return float(np.linalg.norm(x[faces[:, 0]] - x[faces[:, 1]], axis=1).mean())


def _twisted_front(triangles: int, seed: int, turns: float):
    """Three-layer folded cloth twisted by ``turns``, a quarter edge as the half distance, and the
    detector whose normal cone test front ran on it (its node ids are the groups' nodes)."""
    mesh = folded_sheet(triangles, layers=3, seed=seed)
    x = _twist(mesh.vertices_end, turns)
    half = 0.25 * _edge(x, mesh.faces)
    detector = CollisionDetector(mesh.faces, rest=mesh.rest, device="cpu")
    detector.detect(x, thickness=2.0 * half)
    return mesh, x, half, detector


@pytest.mark.parametrize("turns", [0.0, 0.5])
def test_twisted_layers_discrete(turns: float) -> None:
    mesh, x, half, detector = _twisted_front(1500, 3, turns)
    node = detector.front.node_id.numpy()  # the node ids of a real normal cone test front
    slab, dropped = _check_conservative(mesh.faces, x, None, node, half)
    assert dropped > 0 or not turns  # flat layers: the culled groups' boxes missed anyway
    _, plain, _, _ = _find(mesh.faces, x, None, node, half, slab=False)
    assert slab.stats.slab_tests > 0
    assert plain.stats.slab_tests == 0
    assert slab.stats.face_tests <= plain.stats.face_tests


def test_slab_test_cuts_face_tests_between_twisted_layers() -> None:
    # At this resolution and k = 1.5 a cell holds a nearly flat piece of each layer, two edges from the
    # next (the default k = 3 gives larger cells, in which the layers bend more: 0.66 of the tests).
    mesh, x, half, detector = _twisted_front(12000, 0, 0.5)
    node = detector.front.node_id.numpy()
    slab_pairs, slab, _, _ = _find(mesh.faces, x, None, node, half, slab=True, cell_size_factor=1.5)
    plain_pairs, plain, _, _ = _find(mesh.faces, x, None, node, half, slab=False, cell_size_factor=1.5)
    assert slab.stats.bv_tests < 0.5 * plain.stats.bv_tests
    assert slab_pairs.shape[0] < plain_pairs.shape[0]
    assert {tuple(p) for p in slab_pairs.tolist()} <= {tuple(p) for p in plain_pairs.tolist()}


def test_twisted_layers_over_a_step() -> None:
    mesh = folded_sheet(1200, layers=3, seed=5)
    x0 = _twist(mesh.vertices, 0.5)
    x1 = _twist(mesh.vertices_end, 0.51)
    node = _patch_nodes(mesh.rest, mesh.faces, 5)
    slab, dropped = _check_conservative(mesh.faces, x0, x1, node, 0.0)
    assert slab.stats.slab_tests > 0 and dropped > 0


@pytest.mark.parametrize("swept", [False, True])
def test_constant_time_bound_alone_is_conservative(swept: bool) -> None:
    """With the exact projection switched off (``slab_exact_min_work`` past every pair), the O(1) bound of
    the smaller group (its own slab moved by c . delta +- R |delta|, and its sphere) still drops only
    pairs farther than the distance, and still drops some between twisted and between tilted layers."""
    mesh = folded_sheet(1500, layers=3, seed=3)
    x0 = _twist(mesh.vertices_end if not swept else mesh.vertices, 0.5)
    x1 = _twist(mesh.vertices_end, 0.51) if swept else None
    detector = CollisionDetector(mesh.faces, rest=mesh.rest, device="cpu")
    detector.detect(x0, x1, thickness=0.5 * _edge(x0, mesh.faces))
    node = detector.front.node_id.numpy()
    half = 0.25 * _edge(x0, mesh.faces)
    _, dropped = _check_conservative(mesh.faces, x0, x1, node, half, slab_exact_min_work=2**40)
    assert dropped > 0
    x, faces, plate = _tilted_plates(0.04)
    _, dropped = _check_conservative(faces, x, None, plate, 0.005, slab_exact_min_work=2**40, slab_min_work=4)
    assert dropped > 0


def _two_sheets(gap: float, tilt: float, n: int = 8) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Two parallel n x n sheets ``gap`` apart, both rotated by ``tilt`` about the x axis."""
    vertices, sheet_faces, _ = grid_sheet(n, n)
    v = vertices.astype(np.float64)
    top = v.copy()
    top[:, 2] += gap
    x = np.concatenate([v, top])
    c, s = np.cos(tilt), np.sin(tilt)
    rotated = x.copy()
    rotated[:, 1] = c * x[:, 1] - s * x[:, 2]
    rotated[:, 2] = s * x[:, 1] + c * x[:, 2]
    faces = np.concatenate([sheet_faces, sheet_faces + v.shape[0]]).astype(np.int32)
    node = np.repeat(np.arange(2, dtype=np.int32), sheet_faces.shape[0])
    return faces, rotated.astype(np.float32), node


def test_separated_tilted_sheets_need_no_face_test() -> None:
    faces, x, node = _two_sheets(gap=0.15, tilt=0.785, n=4)
    # One big cell: the two sheets share it, their boxes overlap, but their slabs are 0.15 apart.
    got, hash_, lower, upper = _find(faces, x, None, node, 0.02, slab=True, cell_size=10.0)
    assert _reference(lower, upper, node).shape[0] > 0
    assert got.shape[0] == 0
    assert hash_.stats.face_tests == 0
    assert hash_.stats.slab_tests == 1


@pytest.mark.parametrize("tilt", [0.0, 0.7])
def test_sheets_exactly_at_the_distance_are_kept(tilt: float) -> None:
    # gap = 2 half: every face of one sheet has a face of the other at exactly the distance.
    half = 0.125
    faces, x, node = _two_sheets(gap=2.0 * half, tilt=tilt)
    got, _, lower, upper = _find(faces, x, None, node, half, slab=True, cell_size=10.0)
    np.testing.assert_array_equal(got, _reference(lower, upper, node))
    assert got.shape[0] > 0
    # One percent farther apart, the slabs miss each other and no pair is left.
    faces, x, node = _two_sheets(gap=2.0 * half * 1.01, tilt=tilt)
    far, _, _, _ = _find(faces, x, None, node, half, slab=True, cell_size=10.0)
    assert far.shape[0] == 0


def test_sheet_passing_through_over_the_step_is_kept() -> None:
    faces, x0, node = _two_sheets(gap=0.4, tilt=0.3)
    x1 = x0.copy()
    top = np.arange(x0.shape[0]) >= x0.shape[0] // 2
    x1[top] = x0[top] - np.float32(0.8) * np.array([0.0, -np.sin(0.3), np.cos(0.3)], dtype=np.float32)
    got, _, lower, upper = _find(faces, x0, x1, node, 0.0, slab=True, cell_size=10.0)
    np.testing.assert_array_equal(got, _reference(lower, upper, node))
    # Moving apart instead: culled.
    x1[top] = x0[top] + np.float32(0.4) * np.array([0.0, -np.sin(0.3), np.cos(0.3)], dtype=np.float32)
    apart, _, _, _ = _find(faces, x0, x1, node, 0.0, slab=True, cell_size=10.0)
    assert apart.shape[0] == 0


@_SETTINGS
@given(seed=st.integers(0, 10_000), amplitude=st.floats(0.0, 0.3), patches=st.integers(1, 6),
       factor=st.sampled_from([0.75, 1.5, 3.0]), swept=st.booleans(), min_work=st.sampled_from([1, 8]))
def test_crumpled_sheets_never_lose_a_close_pair(seed, amplitude, patches, factor, swept, min_work) -> None:
    rng = np.random.default_rng(seed)
    vertices, sheet_faces, _ = grid_sheet(9, 9)
    faces = sheet_faces.astype(np.int32)
    x0 = vertices.astype(np.float64)
    # Fold the sheet over itself and crumple it, so groups lie close in every direction.
    x0[:, 2] = amplitude * np.sin(3.0 * x0[:, 0] + rng.uniform(0, 6)) + 0.1 * rng.standard_normal(x0.shape[0])
    x0[:, 1] = np.where(x0[:, 1] > 0.5, 1.0 - x0[:, 1], x0[:, 1])
    x0 = x0.astype(np.float32)
    x1 = (x0 + 0.05 * rng.standard_normal(x0.shape)).astype(np.float32) if swept else None
    node = _patch_nodes(vertices, faces, patches)
    half = float(rng.choice([0.0, 0.01, 0.05]))
    _check_conservative(faces, x0, x1, node, half, cell_size_factor=factor, slab_min_work=min_work)


def test_deterministic_and_same_as_without_slabs_when_nothing_is_culled() -> None:
    mesh = folded_sheet(800, layers=2, seed=1)
    node = _patch_nodes(mesh.rest, mesh.faces, 4)
    first, _, _, _ = _find(mesh.faces, mesh.vertices_end, None, node, 0.01, slab=True)
    again, _, _, _ = _find(mesh.faces, mesh.vertices_end, None, node, 0.01, slab=True)
    np.testing.assert_array_equal(first, again)
    # A huge distance: every group pair passes, so the pairs are exactly the box pairs.
    got, hash_, lower, upper = _find(mesh.faces, mesh.vertices_end, None, node, 5.0, slab=True)
    np.testing.assert_array_equal(got, _reference(lower, upper, node))


def test_bad_slab_arguments() -> None:
    device = "cpu"
    faces = np.array([[0, 1, 2], [3, 4, 5]], dtype=np.int32)
    with pytest.raises(InputError, match="faces"):
        SpatialHash(2, device, group_slab_test=True)
    with pytest.raises(InputError, match="slab_min_work"):
        SpatialHash(2, device, faces=wp.array(faces, dtype=wp.vec3i, device=device), slab_min_work=0)
    hash_ = SpatialHash(2, device, faces=wp.array(faces, dtype=wp.vec3i, device=device), group_slab_test=True)
    box = wp.array(np.zeros((2, 3), dtype=np.float32), dtype=wp.vec3, device=device)
    node = wp.array(np.array([0, 1], dtype=np.int32), dtype=wp.int32, device=device)
    with pytest.raises(InputError, match="positions_t0"):
        hash_.find_pairs(box, box, node)
    x = wp.array(np.zeros((6, 3), dtype=np.float32), dtype=wp.vec3, device=device)
    with pytest.raises(InputError, match="half_distance"):
        hash_.find_pairs(box, box, node, positions_t0=x, half_distance=-1.0)
    with pytest.raises(InputError, match="positions_t1"):
        hash_.find_pairs(box, box, node, positions_t0=x, positions_t1=wp.zeros(5, dtype=wp.vec3, device=device))
    with pytest.raises(InputError, match="positions_t0"):
        hash_.find_pairs(box, box, node, positions_t0=wp.zeros(5, dtype=wp.vec3, device=device))
    with pytest.raises(InputError, match="node_id"):
        hash_.find_pairs(box, box, node, positions_t0=x, node_id_bound=1)
    with pytest.raises(InputError, match="node_id_bound"):
        hash_.find_pairs(box, box, node, positions_t0=x, node_id_bound=0)
    # Without node ids every face is its own group: no slab test, no positions needed.
    _, count = hash_.find_pairs(box, box)
    assert count == 1 and hash_.stats.slab_tests == 0


def test_face_order_gives_the_same_pairs_with_a_shorter_sort() -> None:
    mesh, x, half, detector = _twisted_front(1500, 4, 0.3)
    node = detector.front.node_id.numpy()
    order = wp.array(detector.bvh.face_order.astype(np.int32), dtype=wp.int32, device="cpu")
    device = "cpu"
    lower, upper = _boxes(mesh.faces, x, None, half)
    box_pairs = _reference(lower, upper, node)

    def run(slab: bool, face_order):
        hash_ = SpatialHash(mesh.face_count, device, faces=wp.array(mesh.faces, dtype=wp.vec3i, device=device),
                            group_slab_test=slab)
        hash_.find_pairs(wp.array(lower, dtype=wp.vec3, device=device), wp.array(upper, dtype=wp.vec3, device=device),
                         wp.array(node, dtype=wp.int32, device=device),
                         positions_t0=wp.array(x, dtype=wp.vec3, device=device), half_distance=half,
                         node_id_bound=detector.bvh.node_count, face_order=face_order)
        assert hash_.stats.same_node_tests == 0
        return hash_.pairs_numpy(), hash_.stats

    # Without the slab test the pairs are the box pairs whatever the entry order, with the same tests.
    plain, plain_stats = run(False, None)
    ordered, ordered_stats = run(False, order)
    np.testing.assert_array_equal(plain, box_pairs)
    np.testing.assert_array_equal(ordered, box_pairs)
    assert (ordered_stats.groups, ordered_stats.bv_tests) == (plain_stats.groups, plain_stats.bv_tests)
    # With it, the group axes (middle faces) follow the order; every dropped pair is still far apart.
    slabbed, _ = run(True, order)
    got = {tuple(p) for p in slabbed.tolist()}
    boxes = {tuple(p) for p in box_pairs.tolist()}
    assert got <= boxes
    for a, b in boxes - got:
        assert _triangle_distance(x[mesh.faces[a]], x[mesh.faces[b]]) > 2.0 * half * (1.0 - 1e-9)


@pytest.mark.parametrize("slab", [False, True])
def test_a_node_contiguous_order_skips_the_split_check_and_nothing_else(slab: bool) -> None:
    # The detector's case: node ids of a front in the BVH's leaf order. Telling the hash so leaves out
    # the per-cell split-node check (and lets the row plan pass small groups in O(1)); pairs, BV tests
    # and slab tests are those of the checked call.
    mesh, x, half, detector = _twisted_front(1500, 4, 0.3)
    node = detector.front.node_id.numpy()
    order_np = detector.bvh.face_order.astype(np.int32)
    ranks = node[order_np]
    assert all(np.all(np.diff(np.flatnonzero(ranks == n)) == 1) for n in np.unique(ranks))  # contiguous runs
    device = "cpu"
    lower, upper = _boxes(mesh.faces, x, None, half)
    arrays = [wp.array(lower, dtype=wp.vec3, device=device), wp.array(upper, dtype=wp.vec3, device=device),
              wp.array(node, dtype=wp.int32, device=device)]
    order = wp.array(order_np, dtype=wp.int32, device=device)

    def run(contiguous: bool):
        hash_ = SpatialHash(mesh.face_count, device, faces=wp.array(mesh.faces, dtype=wp.vec3i, device=device),
                            group_slab_test=slab)
        while True:
            hash_.find_pairs_device(*arrays, positions_t0=wp.array(x, dtype=wp.vec3, device=device),
                                    half_distance=half, node_id_bound=detector.bvh.node_count, face_order=order,
                                    order_is_node_contiguous=contiguous)
            if hash_.check_capacity():
                break
        stats = hash_.stats
        return hash_.pairs_numpy(), (stats.groups, stats.rows, stats.bv_tests, stats.slab_tests, stats.triangle_pairs)

    checked, checked_stats = run(False)
    trusted, trusted_stats = run(True)
    assert checked.shape[0] > 0
    np.testing.assert_array_equal(trusted, checked)
    assert trusted_stats == checked_stats
    if slab:
        assert checked_stats[3] > 0  # the slab test ran


def test_bad_face_order() -> None:
    device = "cpu"
    faces = np.array([[0, 1, 2], [3, 4, 5], [6, 7, 8]], dtype=np.int32)
    hash_ = SpatialHash(3, device)
    box = wp.array(np.zeros((3, 3), dtype=np.float32), dtype=wp.vec3, device=device)
    with pytest.raises(InputError, match="permutation"):
        hash_.find_pairs(box, box, wp.array(np.array([0, 1, 2], dtype=np.int32), device=device),
                         face_order=wp.array(np.array([0, 0, 2], dtype=np.int32), device=device))
    # Node 0 split by face 1 (node 1): the same-node counter catches it.
    with pytest.raises(InputError, match="contiguous"):
        hash_.find_pairs(box, box, wp.array(np.array([0, 1, 0], dtype=np.int32), device=device),
                         face_order=wp.array(np.array([0, 1, 2], dtype=np.int32), device=device))
    del faces


def _tilted_plates(gap: float, plates: int = 6, cells: int = 12) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``plates`` parallel square plates tilted 45 degrees about x, ``gap`` apart along their normal:
    their faces' boxes overlap across plates (tilted), their slabs do not when the gap exceeds the
    distance. One node per plate."""
    vertices, faces, _ = grid_sheet(cells, cells)
    normal = np.array([0.0, -np.sqrt(0.5), np.sqrt(0.5)])
    tilt = np.array([[1.0, 0.0, 0.0], [0.0, np.sqrt(0.5), -np.sqrt(0.5)], [0.0, np.sqrt(0.5), np.sqrt(0.5)]])
    xs, fs, nodes = [], [], []
    for k in range(plates):
        xs.append(vertices @ tilt.T + k * gap * normal)
        fs.append(faces + k * vertices.shape[0])
        nodes.append(np.full(faces.shape[0], k, dtype=np.int32))
    return np.concatenate(xs).astype(np.float32), np.concatenate(fs).astype(np.int32), np.concatenate(nodes)


def _policy_calls(x: np.ndarray, faces: np.ndarray, node: np.ndarray, half: float,
                  calls: int) -> list[tuple[int, bytes]]:
    """(slab tests, sorted pairs) of ``calls`` host calls of one hash on the same boxes."""
    device = "cpu"
    hash_ = SpatialHash(faces.shape[0], device, faces=wp.array(faces, dtype=wp.vec3i, device=device),
                        group_slab_test=True, slab_min_work=4)
    lower, upper = _boxes(faces, x, None, half)
    arrays = (wp.array(lower, dtype=wp.vec3, device=device), wp.array(upper, dtype=wp.vec3, device=device),
              wp.array(node, dtype=wp.int32, device=device))
    out = []
    for _ in range(calls):
        hash_.find_pairs(*arrays, 0.25, positions_t0=wp.array(x, dtype=wp.vec3, device=device), half_distance=half)
        out.append((hash_.stats.slab_tests, hash_.pairs_numpy().tobytes()))
    return out


def test_slab_policy_keeps_the_test_where_it_pays() -> None:
    """Tilted plates 0.04 apart at half distance 0.005: the slab test separates every plate pair (their
    boxes overlap), saves far more face tests than it costs, and runs on every call."""
    x, faces, node = _tilted_plates(0.04)
    calls = _policy_calls(x, faces, node, 0.005, 4)
    assert all(tests > 0 for tests, _ in calls)
    assert len({pairs for _, pairs in calls}) == 1


def test_slab_policy_drops_the_test_where_it_does_not_pay_and_probes_again() -> None:
    """Plates 0.0015 apart at half distance 0.005 (all six within the distance): no group pair separates, so
    after the first call the test is off; the SLAB_PROBE_INTERVAL-th call after runs it again, and each probe
    that finds it still does not pay doubles the interval, SLAB_PROBE_BACKOFF times at most. The pairs are
    the same on every call (nothing was separated)."""
    from pscc.collision.spatial_hash_settings import SLAB_PROBE_BACKOFF, SLAB_PROBE_INTERVAL

    intervals = [SLAB_PROBE_INTERVAL << min(k, SLAB_PROBE_BACKOFF) for k in range(SLAB_PROBE_BACKOFF + 2)]
    x, faces, node = _tilted_plates(0.0015)
    calls = _policy_calls(x, faces, node, 0.005, 1 + sum(n + 1 for n in intervals) + 1)
    tests = [t for t, _ in calls]
    probes = [k for k, t in enumerate(tests) if t > 0]
    expected = [0]
    for n in intervals:
        expected.append(expected[-1] + n + 1)
    assert probes == expected  # the first call, then probes 8, 16, 32, 64, 64 calls apart
    assert len({pairs for _, pairs in calls}) == 1
    assert len(calls[0][1]) > 0


def test_slab_policy_backoff_restarts_when_the_test_pays() -> None:
    """A probe that finds the test paying keeps it on; when it stops paying again the next probe comes
    after SLAB_PROBE_INTERVAL calls, not after the interval the earlier probes had reached."""
    from pscc.collision.spatial_hash_settings import SLAB_PROBE_INTERVAL

    near, faces, node = _tilted_plates(0.0015)
    # Pairs of plates 0.0015 apart, the pairs 0.04 apart: the slab test separates the pairs, rows stay.
    apart = near.reshape(6, -1, 3).copy()
    normal = np.array([0.0, -np.sqrt(0.5), np.sqrt(0.5)], dtype=np.float32)
    for k in range(6):
        apart[k] += (k // 2) * 0.04 * normal
    apart = apart.reshape(-1, 3)
    device = "cpu"
    hash_ = SpatialHash(faces.shape[0], device, faces=wp.array(faces, dtype=wp.vec3i, device=device),
                        group_slab_test=True, slab_min_work=4)

    def call(x: np.ndarray) -> int:
        lower, upper = _boxes(faces, x, None, 0.005)
        hash_.find_pairs(wp.array(lower, dtype=wp.vec3, device=device),
                         wp.array(upper, dtype=wp.vec3, device=device),
                         wp.array(node, dtype=wp.int32, device=device), 0.25,
                         positions_t0=wp.array(x, dtype=wp.vec3, device=device), half_distance=0.005)
        return int(hash_.stats.slab_tests)

    first = [call(near) for _ in range(1 + 2 * SLAB_PROBE_INTERVAL + 3)]  # on, off, probe, off at level 1
    assert [k for k, t in enumerate(first) if t > 0] == [0, SLAB_PROBE_INTERVAL + 1]
    assert hash_.slab_policy.numpy()[0] == -1
    hash_.slab_policy.assign(np.array([1, 1], dtype=np.int32))  # the level-1 probe comes now ...
    assert call(apart) > 0  # ... and finds the test paying: level 0, on
    assert hash_.slab_policy.numpy().tolist() == [1, 0]
    assert call(near) > 0 and hash_.slab_policy.numpy()[0] == 0  # not paying any more: off at level 0
    tests = [call(near) for _ in range(SLAB_PROBE_INTERVAL + 1)]
    assert tests[:-1] == [0] * SLAB_PROBE_INTERVAL and tests[-1] > 0  # the probe after 8 calls, not 16


def test_slab_policy_is_not_stepped_by_a_call_that_overflowed() -> None:
    """A first call whose pair buffer is too small is run again by the host API; the policy the run
    again reads is the first call's (on), so the slab test runs in it."""
    x, faces, node = _tilted_plates(0.0015)
    device = "cpu"
    hash_ = SpatialHash(faces.shape[0], device, faces=wp.array(faces, dtype=wp.vec3i, device=device),
                        group_slab_test=True, slab_min_work=4, pair_capacity=1)
    lower, upper = _boxes(faces, x, None, 0.005)
    hash_.find_pairs(wp.array(lower, dtype=wp.vec3, device=device), wp.array(upper, dtype=wp.vec3, device=device),
                     wp.array(node, dtype=wp.int32, device=device), 0.25,
                     positions_t0=wp.array(x, dtype=wp.vec3, device=device), half_distance=0.005)
    assert hash_.stats.reruns > 0
    assert hash_.stats.slab_tests > 0
    assert hash_.slab_policy.numpy()[0] == 0  # and the completed call turned it off


def test_detector_checkpoint_keeps_the_slab_policy() -> None:
    """The detector's state_dict carries the slab policy: a detector restored from it makes the same
    choices on its next calls (here: the probe after SLAB_PROBE_INTERVAL calls without the test comes on
    the same call), so it hands the narrow phase the same pairs; a bad policy is refused."""
    from pscc.collision.spatial_hash_settings import SLAB_PROBE_INTERVAL

    x, faces, _ = _tilted_plates(0.0015)
    first = CollisionDetector(faces, device="cpu")
    for _ in range(3):
        first.detect(x, thickness=0.01)
    state = first.state_dict()
    assert state["hash_slab_policy"][0] == 0  # the test did not pay
    second = CollisionDetector(faces, device="cpu")
    second.detect(x, thickness=0.01)  # sizes its buffers (a call the restore then overrides)
    second.load_state_dict(state)
    tests = []
    for _ in range(SLAB_PROBE_INTERVAL):
        a = first.detect(x, thickness=0.01)
        b = second.detect(x, thickness=0.01)
        tests.append((a.stats["grid"]["slab_tests"], b.stats["grid"]["slab_tests"]))
        assert a.stats["triangle_pairs"] == b.stats["triangle_pairs"]
        np.testing.assert_array_equal(a.vertex_face, b.vertex_face)
        np.testing.assert_array_equal(a.edge_edge, b.edge_edge)
    assert all(ta == tb for ta, tb in tests)
    assert sum(1 for ta, _ in tests if ta > 0) == 1  # one probe
    with pytest.raises(InputError, match="hash_slab_policy"):
        second.load_state_dict({**state, "hash_slab_policy": np.array([2, 0])})
