"""The contour test without a reference point (pscc.geometry.simple_contour): a projected loop passes only
when it is a simple polygon, at one instant and over a linear step; checked against float64 references."""

from __future__ import annotations

import math

import numpy as np
import pytest
import warp as wp

from pscc.geometry import normal_cone as nc
from pscc.geometry import simple_contour as sc

MARGIN = 1.0e-5


@wp.kernel
def _simple_kernel(
    loop: wp.array(dtype=wp.int32),
    positions_t0: wp.array(dtype=wp.vec3),
    positions_t1: wp.array(dtype=wp.vec3),
    l: wp.vec3,
    swept: int,
    out: wp.array(dtype=wp.int32),
):
    ok = sc.contour_is_simple(loop, 0, loop.shape[0], positions_t0, positions_t1, l, MARGIN, swept)
    out[0] = wp.where(ok, 1, 0)


@wp.kernel
def _star_kernel(loop: wp.array(dtype=wp.int32), positions: wp.array(dtype=wp.vec3), o: wp.vec3, l: wp.vec3,
                 out: wp.array(dtype=wp.int32)):
    out[0] = wp.where(nc.contour_test(loop, 0, loop.shape[0], positions, o, l, MARGIN), 1, 0)


def _simple(points, l=(0.0, 0.0, 1.0), points_t1=None, device="cpu") -> bool:
    points = np.asarray(points, np.float32)
    if points.shape[1] == 2:
        points = np.concatenate([points, np.zeros((len(points), 1), np.float32)], axis=1)
    swept = points_t1 is not None
    p1 = np.asarray(points_t1 if swept else points, np.float32)
    if p1.shape[1] == 2:
        p1 = np.concatenate([p1, np.zeros((len(p1), 1), np.float32)], axis=1)
    out = wp.zeros(1, dtype=wp.int32, device=device)
    unit = np.asarray(l, np.float64) / np.linalg.norm(l)
    wp.launch(_simple_kernel, dim=1, device=device, inputs=[
        wp.array(np.arange(len(points), dtype=np.int32), device=device),
        wp.array(points, dtype=wp.vec3, device=device), wp.array(p1, dtype=wp.vec3, device=device),
        wp.vec3(*unit.astype(np.float32)), 1 if swept else 0, out])
    return bool(out.numpy()[0])


def _star(points, o, device="cpu") -> bool:
    points = np.concatenate([np.asarray(points, np.float32), np.zeros((len(points), 1), np.float32)], axis=1)
    out = wp.zeros(1, dtype=wp.int32, device=device)
    wp.launch(_star_kernel, dim=1, device=device, inputs=[
        wp.array(np.arange(len(points), dtype=np.int32), device=device), wp.array(points, dtype=wp.vec3, device=device),
        wp.vec3(o[0], o[1], 0.0), wp.vec3(0.0, 0.0, 1.0), out])
    return bool(out.numpy()[0])


def _segment_distance(p: np.ndarray, q: np.ndarray, r: np.ndarray, s: np.ndarray) -> float:
    """Distance of 2-D segments pq and rs in float64 (0 when they cross)."""
    def orient(a, b, c):
        return (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0])
    if orient(p, q, r) * orient(p, q, s) < 0 and orient(r, s, p) * orient(r, s, q) < 0:
        return 0.0

    def point_segment(x, a, b):
        d = b - a
        t = np.clip(np.dot(x - a, d) / max(np.dot(d, d), 1e-300), 0.0, 1.0)
        return float(np.linalg.norm(x - (a + t * d)))
    return min(point_segment(p, r, s), point_segment(q, r, s), point_segment(r, p, q), point_segment(s, p, q))


def _gap(polygon: np.ndarray) -> float:
    """Smallest float64 distance between non-adjacent edges of a 2-D loop, and -1 when two adjacent edges
    fold onto each other (0 when the loop touches or crosses itself)."""
    n = len(polygon)
    gap = math.inf
    for i in range(n):
        a, v, c = polygon[i], polygon[(i + 1) % n], polygon[(i + 2) % n]
        cross = (v[0] - a[0]) * (c[1] - v[1]) - (v[1] - a[1]) * (c[0] - v[0])
        if cross == 0.0 and np.dot(v - a, c - v) <= 0.0:
            return -1.0
        for j in range(i + 2, n - 1 if i == 0 else n):
            gap = min(gap, _segment_distance(polygon[i], polygon[(i + 1) % n], polygon[j], polygon[(j + 1) % n]))
    return gap


def _untangled(points: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """A simple polygon through ``points`` (2-opt: reverse the chain between two crossing edges until none
    cross), usually not star-shaped."""
    order = list(rng.permutation(len(points)))
    for _ in range(10_000):
        n = len(order)
        crossing = None
        for i in range(n):
            for j in range(i + 2, n - 1 if i == 0 else n):
                p, q = points[order[i]], points[order[(i + 1) % n]]
                r, s = points[order[j]], points[order[(j + 1) % n]]
                if _segment_distance(p, q, r, s) == 0.0:
                    crossing = (i, j)
                    break
            if crossing:
                break
        if crossing is None:
            return points[order]
        i, j = crossing
        order[i + 1:j + 1] = order[i + 1:j + 1][::-1]
    raise AssertionError("2-opt did not converge")


L_SHAPE = [[0, 0], [3, 0], [3, 1], [1, 1], [1, 3], [0, 3]]
U_SHAPE = [[0, 0], [3, 0], [3, 3], [2, 3], [2, 1], [1, 1], [1, 3], [0, 3]]
COMB = [[0, 0], [7, 0], [7, 3], [6, 3], [6, 1], [5, 1], [5, 3], [4, 3], [4, 1], [3, 1], [3, 3], [2, 3], [2, 1],
        [1, 1], [1, 3], [0, 3]]


@pytest.mark.parametrize("shape", [U_SHAPE, COMB], ids=["U", "comb"])
def test_non_star_simple_loops_pass(shape, device) -> None:
    """A U and a comb are simple but no point sees every edge turn one way: the star test fails with their
    centroid, the simple test passes them in both orientations and tilted out of the plane."""
    points = np.asarray(shape, np.float64)
    assert not _star(points, points.mean(axis=0), device=device)
    assert _simple(points, device=device)
    assert _simple(points[::-1], device=device)
    tilted = np.concatenate([points, 0.3 * points[:, :1] - 0.2 * points[:, 1:]], axis=1)
    assert _simple(tilted, l=(0.3, -0.2, 1.0), device=device)  # an affine image of the plane: still simple
    lift = np.concatenate([points, np.sin(points[:, :1])], axis=1)   # heights along l = z change nothing
    assert _simple(lift, device=device)


def test_an_l_passes_in_both_orientations(device) -> None:
    assert _simple(L_SHAPE, device=device)
    assert _simple(L_SHAPE[::-1], device=device)


def test_straight_borders_of_many_collinear_edges_pass(device) -> None:
    """A rectangle whose sides are split into collinear edges (a CAD panel's straight borders): collinear
    non-adjacent edges are told apart along their own direction."""
    ring = [[i, 0] for i in range(8)] + [[8, j] for j in range(3)] + [[8 - i, 3] for i in range(8)]
    ring += [[0, 3 - j] for j in range(3)]
    assert _simple(ring, device=device)


@pytest.mark.parametrize("name", ["pentagram", "double loop", "figure eight", "pinched", "fold back", "touching"])
def test_loops_that_are_not_simple_fail(name, device) -> None:
    loops = {
        "pentagram": [[math.cos(4 * math.pi * k / 5), math.sin(4 * math.pi * k / 5)] for k in range(5)],
        "double loop": [[math.cos(4 * math.pi * k / 12), math.sin(4 * math.pi * k / 12)] for k in range(12)],
        "figure eight": [[0, 0], [1, 1], [2, 0], [2, 1], [1, 0], [0, 1]],
        # One vertex visited twice: the loop touches itself there.
        "pinched": [[0, 0], [2, 0], [1, 1], [2, 2], [0, 2], [1, 1]],
        # An edge folds back onto the previous one.
        "fold back": [[0, 0], [2, 0], [1, 0], [1, 1]],
        # A vertex of the U's right arm lies on its left arm.
        "touching": [[0, 0], [3, 0], [3, 3], [2, 3], [1, 1.5], [1, 1], [1, 3], [0, 3]],
    }
    assert not _simple(loops[name], device=device)


def test_a_folded_strip_fails(device) -> None:
    """The strip of tests/geometry/test_normal_cone.py folded over itself: its projection crosses itself."""
    folded = [[0, 0, 0], [2, 0, 0], [2, 1, 0], [0.5, 1, 0.2], [0.5, -0.5, 0.2], [1.5, -0.5, 0.2], [1.5, 2, 0]]
    assert not _simple(folded, device=device)


@pytest.mark.parametrize("seed", range(4))
def test_random_loops_against_a_float64_reference(seed: int, device) -> None:
    """Untangled random polygons (simple, mostly not star-shaped) and random-order ones (mostly crossing),
    lifted to 3-D and seen along a random direction: a loop passes only when float64 finds it simple with
    a gap, and every loop whose gap is above 1e-3 of its size passes."""
    rng = np.random.default_rng(seed)
    passed_simple = 0
    for case in range(40):
        count = int(rng.integers(4, 24))
        flat = rng.random((count, 2))
        flat = _untangled(flat, rng) if case % 2 == 0 else flat
        gap = _gap(flat)
        l = rng.normal(size=3)
        l /= np.linalg.norm(l)
        u = np.cross(l, [1.0, 0.0, 0.0] if abs(l[0]) < 0.9 else [0.0, 1.0, 0.0])
        u /= np.linalg.norm(u)
        v = np.cross(l, u)
        points = flat[:, :1] * u + flat[:, 1:] * v + rng.normal(0.0, 0.3, (count, 1)) * l + rng.normal(size=3)
        got = _simple(points, l=l, device=device)
        if got:
            assert gap > 0.0, f"case {case}: a loop that is not simple passed"
        if gap > 1e-3:
            assert got, f"case {case}: a simple loop with gap {gap:.2e} failed"
            passed_simple += 1
    assert passed_simple >= 10


def test_swept_loops(device) -> None:
    """Over a step: a U that translates and tilts stays simple and passes; a square turned half a turn is
    a square at both ends but collapses to its centre half-way and fails, and so does a U that becomes its
    mirror image (simple at both ends, a segment half-way)."""
    u = np.concatenate([np.asarray(U_SHAPE, np.float64), np.zeros((8, 1))], axis=1)
    moved = u + [0.4, -0.2, 0.0] + 0.1 * u[:, :1] * [0.0, 0.0, 1.0]
    assert _simple(u, points_t1=moved, device=device)
    square = np.asarray([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]], np.float64)
    assert _simple(square, device=device) and _simple(-square, device=device)
    assert not _simple(square, points_t1=-square, device=device)
    mirrored = u * [-1.0, 1.0, 1.0] + [3.0, 0.0, 0.0]   # the U mirrored: half-way it is a segment
    assert _simple(mirrored, device=device)
    assert not _simple(u, points_t1=mirrored, device=device)


def test_edges_apart_over_a_step(device) -> None:
    """Two segments that are apart at both ends of a step but pass through each other half-way are not."""
    @wp.kernel
    def apart(p: wp.array(dtype=wp.vec3), out: wp.array(dtype=wp.int32)):
        out[0] = wp.where(sc.edges_apart(p[0], p[1], p[2], p[3], p[4], p[5], p[6], p[7], wp.vec3(0.0, 0.0, 1.0),
                                         MARGIN), 1, 0)

    def run(points):
        out = wp.zeros(1, dtype=wp.int32, device=device)
        wp.launch(apart, dim=1, device=device,
                  inputs=[wp.array(np.asarray(points, np.float32), dtype=wp.vec3, device=device), out])
        return bool(out.numpy()[0])

    a = [[0, 0, 0], [1, 0, 0]]
    above = [[0.4, 1, 0], [0.6, 1, 0]]
    below = [[0.4, -1, 0], [0.6, -1, 0]]
    assert run(a + a + above + above)
    assert run(a + a + below + below)
    assert not run(a + a + above + below)
    assert run(a + a + above + [[0.4, 0.5, 0], [0.6, 0.5, 0]])


@pytest.mark.parametrize("seed", range(3))
def test_random_swept_loops_are_simple_at_every_sampled_time(seed: int, device) -> None:
    """Untangled random polygons moved by random linear motions, some small (they stay simple) and some
    large (they cross themselves on the way): a loop that passes is simple, with a gap, at each of 101
    times of the step in float64."""
    rng = np.random.default_rng(100 + seed)
    passed = 0
    for case in range(30):
        count = int(rng.integers(4, 16))
        start = _untangled(rng.random((count, 2)), rng)
        motion = rng.normal(0.0, [0.01, 0.05, 0.3][case % 3], (count, 2))
        end = start + motion
        got = _simple(start, points_t1=end, device=device)
        if got:
            passed += 1
            for t in np.linspace(0.0, 1.0, 101):
                assert _gap(start + t * motion) > 0.0, f"case {case}: passed but not simple at t = {t:.2f}"
    assert passed >= 5
