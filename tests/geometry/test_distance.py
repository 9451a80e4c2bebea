"""Tests of the float32 DCD distance primitives against a float64 reference and ipctk.

The reference below is exact up to float64 rounding: the closest point of a triangle is the
best of the interior projection (when it falls inside) and the three edges; the closest pair of
two segments is the best of the interior line-line pair (when both parameters fall inside) and
the four endpoint-to-segment pairs. Cross products of float32 coordinates are exact in float64
up to one rounding per component, so no tolerance is needed to detect degeneracy: exactly
degenerate input gives an exactly zero normal.
"""

from __future__ import annotations

import ipctk
import numpy as np
import pytest
import warp as wp
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from pscc.errors import InputError
from pscc.geometry import distance as dist
from pscc.geometry import distance_tolerances as tol

BOUND = tol.DISTANCE_ERROR_CONST * tol.EPS32
"""Tight relative bound ``C * EPS32`` on ``|d32 - d_exact| / L``."""

HYPOTHESIS = settings(
    max_examples=25,
    deadline=None,
    suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow],
)

# ------------------------------------------------------------------------------------------------
# Float64 reference
# ------------------------------------------------------------------------------------------------


def _dot(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    return np.einsum("...i,...i->...", u, v)


def ref_point_segment_sq(p: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Squared distance from points p to segments [a, b] (zero-length segments allowed)."""
    ab = b - a
    den = _dot(ab, ab)
    t = np.where(den > 0, np.clip(_dot(p - a, ab) / np.where(den > 0, den, 1.0), 0.0, 1.0), 0.0)
    r = p - a - t[..., None] * ab
    return _dot(r, r)


def ref_vertex_face(points: np.ndarray) -> np.ndarray:
    """Exact (float64) point-triangle distances for an (n, 4, 3) batch."""
    P = np.asarray(points, dtype=np.float64)
    p, a, b, c = P[:, 0], P[:, 1], P[:, 2], P[:, 3]
    best = np.minimum.reduce(
        [ref_point_segment_sq(p, a, b), ref_point_segment_sq(p, b, c), ref_point_segment_sq(p, c, a)]
    )
    n = np.cross(b - a, c - a)
    nn = _dot(n, n)
    inside = (
        (nn > 0)
        & (_dot(n, np.cross(c - b, p - b)) >= 0)
        & (_dot(n, np.cross(a - c, p - c)) >= 0)
        & (_dot(n, np.cross(b - a, p - a)) >= 0)
    )
    plane_sq = _dot(n, p - a) ** 2 / np.where(nn > 0, nn, 1.0)
    return np.sqrt(np.where(inside, np.minimum(best, plane_sq), best))


def ref_edge_edge(points: np.ndarray) -> np.ndarray:
    """Exact (float64) segment-segment distances for an (n, 4, 3) batch."""
    P = np.asarray(points, dtype=np.float64)
    a0, a1, b0, b1 = P[:, 0], P[:, 1], P[:, 2], P[:, 3]
    best = np.minimum.reduce(
        [
            ref_point_segment_sq(a0, b0, b1),
            ref_point_segment_sq(a1, b0, b1),
            ref_point_segment_sq(b0, a0, a1),
            ref_point_segment_sq(b1, a0, a1),
        ]
    )
    ea, eb, r = a1 - a0, b1 - b0, a0 - b0
    n = np.cross(ea, eb)
    nn = _dot(n, n)
    safe = np.where(nn > 0, nn, 1.0)
    s = _dot(n, np.cross(eb, r)) / safe
    t = _dot(n, np.cross(ea, r)) / safe
    inside = (nn > 0) & (s >= 0) & (s <= 1) & (t >= 0) & (t <= 1)
    return np.sqrt(np.where(inside, np.minimum(best, _dot(r, n) ** 2 / safe), best))


def local_scale(points: np.ndarray) -> np.ndarray:
    """L: the largest absolute coordinate difference among the four points of each query."""
    P = np.asarray(points, dtype=np.float64)
    return (P.max(axis=1) - P.min(axis=1)).max(axis=1)


def triangle_flatness(points: np.ndarray) -> np.ndarray:
    """``|ab x ac|^2 / max_edge^4`` of the triangles ``points[:, 1:4]`` (0 for degenerate ones)."""
    P = np.asarray(points, dtype=np.float64)
    a, b, c = P[:, 1], P[:, 2], P[:, 3]
    n = np.cross(b - a, c - a)
    longest = np.maximum.reduce([_dot(b - a, b - a), _dot(c - a, c - a), _dot(c - b, c - b)])
    return _dot(n, n) / np.where(longest > 0, longest, 1.0) ** 2


# ------------------------------------------------------------------------------------------------
# Checks shared by the tests
# ------------------------------------------------------------------------------------------------


def allowance(points: np.ndarray, rel: float) -> np.ndarray:
    """Allowed |error|: ``rel * L``, or ``L`` itself where L is below the resolved scale.

    Queries whose points all lie within ``MIN_LOCAL_SCALE`` of the anchor (so ``L <= 2 *
    MIN_LOCAL_SCALE``) are documented to collapse to one point.
    """
    L = local_scale(points)
    return np.where(L > 2 * tol.MIN_LOCAL_SCALE, rel * L, L)


def check_vertex_face(points: np.ndarray, device: str) -> tuple[np.ndarray, np.ndarray]:
    """Run both vertex-face wrappers and check every invariant; return (relative errors, flatness)."""
    P = np.asarray(points, dtype=np.float32)
    d_only = dist.vertex_face_distance(P, device=device)
    d, w = dist.vertex_face_closest_points(P, device=device)
    assert d.dtype == np.float32 and d.shape == (len(P),) and w.shape == (len(P), 3)
    assert np.all(np.isfinite(d)) and np.all(np.isfinite(w))
    tight = allowance(P, BOUND)
    assert np.all(np.abs(d_only - d) <= tight)
    assert np.all(w >= 0) and np.all(w <= 1)
    np.testing.assert_allclose(w.sum(axis=1), 1.0, atol=4 * tol.EPS32)

    err = d - ref_vertex_face(P)
    flat = triangle_flatness(P)
    # Never much below the truth, whatever the conditioning.
    assert np.all(err >= -tight), f"under-estimate {(-err / tight).max():.3g} x bound"
    well = (flat >= tol.WELL_SHAPED_MIN_FLATNESS) | (flat == 0)
    assert np.all(np.abs(err[well]) <= tight[well]), f"error {(np.abs(err) / tight)[well].max():.3g} x bound"
    ill = allowance(P, tol.ILL_CONDITIONED_REL_ERROR)
    assert np.all(err <= ill), f"ill-conditioned error {(err / ill).max():.3g} x bound"

    # The weights name a point at the reported distance (relative to f0: float32 weights times
    # absolute coordinates would add an error of EPS32 * |coordinate|, not EPS32 * L).
    Q = P.astype(np.float64)
    w64 = w.astype(np.float64)
    offset = Q[:, 0] - Q[:, 1] - w64[:, 1:2] * (Q[:, 2] - Q[:, 1]) - w64[:, 2:3] * (Q[:, 3] - Q[:, 1])
    assert np.all(np.abs(np.linalg.norm(offset, axis=1) - d) <= tight)
    L = local_scale(P)
    return err / np.where(L > 0, L, 1.0), flat


def check_edge_edge(points: np.ndarray, device: str) -> np.ndarray:
    """Run both edge-edge wrappers and check every invariant; return the relative errors."""
    P = np.asarray(points, dtype=np.float32)
    d_only = dist.edge_edge_distance(P, device=device)
    d, st_ = dist.edge_edge_closest_points(P, device=device)
    assert d.dtype == np.float32 and d.shape == (len(P),) and st_.shape == (len(P), 2)
    assert np.all(np.isfinite(d)) and np.all(np.isfinite(st_))
    tight = allowance(P, BOUND)
    assert np.all(np.abs(d_only - d) <= tight)
    assert np.all(st_ >= 0) and np.all(st_ <= 1)

    err = d - ref_edge_edge(P)
    assert np.all(np.abs(err) <= tight), f"error {(np.abs(err) / tight).max():.3g} x bound"

    Q = P.astype(np.float64)
    s, t = st_[:, :1].astype(np.float64), st_[:, 1:].astype(np.float64)
    pa = Q[:, 0] + s * (Q[:, 1] - Q[:, 0])
    pb = Q[:, 2] + t * (Q[:, 3] - Q[:, 2])
    assert np.all(np.abs(np.linalg.norm(pa - pb, axis=1) - d) <= tight)
    L = local_scale(P)
    return err / np.where(L > 0, L, 1.0)


# ------------------------------------------------------------------------------------------------
# Named cases
# ------------------------------------------------------------------------------------------------

TRI = [[0, 0, 0], [1, 0, 0], [0, 1, 0]]

VERTEX_FACE_CASES = {
    # name: ([p, f0, f1, f2], distance, weights or None when any minimiser will do)
    "above_interior": ([[0.25, 0.25, 2], *TRI], 2.0, [0.5, 0.25, 0.25]),
    "below_interior": ([[0.25, 0.5, -0.75], *TRI], 0.75, [0.25, 0.25, 0.5]),
    "in_plane_inside": ([[0.25, 0.375, 0], *TRI], 0.0, [0.375, 0.25, 0.375]),
    "on_face_edge": ([[0.5, 0, 0], *TRI], 0.0, [0.5, 0.5, 0]),
    "above_face_edge": ([[0.5, -1, 1], *TRI], np.sqrt(2.0), [0.5, 0.5, 0]),
    "on_face_vertex": ([[1, 0, 0], *TRI], 0.0, [0, 1, 0]),
    "in_plane_outside_edge": ([[2, 2, 0], *TRI], 3 / np.sqrt(2.0), [0, 0.5, 0.5]),
    "in_plane_outside_vertex": ([[-1, -1, 0], *TRI], np.sqrt(2.0), [1, 0, 0]),
    "collinear_face": ([[2, 1, 0], [0, 0, 0], [1, 0, 0], [3, 0, 0]], 1.0, None),
    "collinear_face_beyond_end": ([[5, 0, 0], [0, 0, 0], [3, 0, 0], [1, 0, 0]], 2.0, [0, 1, 0]),
    "collinear_face_on_it": ([[0.5, 0, 0], [0, 0, 0], [1, 0, 0], [3, 0, 0]], 0.0, None),
    "two_coincident_vertices": ([[0.5, 1, 0], [0, 0, 0], [0, 0, 0], [1, 0, 0]], 1.0, None),
    "coincident_face": ([[1, 2, 5], [1, 2, 3], [1, 2, 3], [1, 2, 3]], 2.0, None),
    "everything_coincident": ([[1, 2, 3]] * 4, 0.0, None),
}
NONDEGENERATE_FACES = [k for k in VERTEX_FACE_CASES if not k.startswith(("collinear", "two_", "coinc", "every"))]

EDGE_EDGE_CASES = {
    # name: ([a0, a1, b0, b1], distance, (s, t) or None when any minimiser will do)
    "crossing": ([[0, 0, 0], [1, 0, 0], [0.5, -1, 0], [0.5, 1, 0]], 0.0, [0.5, 0.5]),
    "skew": ([[0, 0, 0], [1, 0, 0], [0.25, -1, 1], [0.25, 1, 1]], 1.0, [0.25, 0.5]),
    "skew_clamped": ([[0, 0, 0], [1, 0, 0], [2, -1, 1], [2, 1, 1]], np.sqrt(2.0), [1, 0.5]),
    "parallel_overlapping": ([[0, 0, 0], [2, 0, 0], [1, 1, 0], [3, 1, 0]], 1.0, None),
    "parallel_disjoint": ([[0, 0, 0], [1, 0, 0], [2, 1, 0], [3, 1, 0]], np.sqrt(2.0), [1, 0]),
    "antiparallel_overlapping": ([[0, 0, 0], [2, 0, 0], [3, 1, 0], [1, 1, 0]], 1.0, None),
    "antiparallel_disjoint": ([[0, 0, 0], [1, 0, 0], [3, 1, 0], [2, 1, 0]], np.sqrt(2.0), [1, 1]),
    "collinear_overlapping": ([[0, 0, 0], [2, 0, 0], [1, 0, 0], [3, 0, 0]], 0.0, None),
    "collinear_disjoint": ([[0, 0, 0], [1, 0, 0], [3, 0, 0], [4, 0, 0]], 2.0, [1, 0]),
    "touching_endpoints": ([[0, 0, 0], [1, 0, 0], [1, 0, 0], [1, 1, 0]], 0.0, [1, 0]),
    "t_junction": ([[0, 0, 0], [2, 0, 0], [1, 0, 0], [1, 1, 1]], 0.0, [0.5, 0]),
    "zero_length_a": ([[0, 0, 0], [0, 0, 0], [2, 1, 0], [3, 1, 0]], np.sqrt(5.0), [0, 0]),
    "zero_length_b": ([[0, 0, 0], [1, 0, 0], [0.5, 1, 0], [0.5, 1, 0]], 1.0, [0.5, 0]),
    "zero_length_both": ([[0, 0, 0], [0, 0, 0], [3, 4, 0], [3, 4, 0]], 5.0, [0, 0]),
    "everything_coincident": ([[1, 2, 3]] * 4, 0.0, None),
}
NONDEGENERATE_EDGES = ["crossing", "skew", "skew_clamped", "touching_endpoints", "t_junction"]

# Exact float32 similarity transforms (power-of-two scale, shifts that keep every bit).
TRANSFORMS = {
    "identity": (1.0, np.zeros(3)),
    "small_and_far": (2.0**-10, np.array([1024.0, -512.0, 256.0])),
    "large": (2.0**10, np.array([-3.0, 5.0, 7.0])),
}


def _batch(cases: dict, transform: str) -> tuple[np.ndarray, np.ndarray, list]:
    scale, shift = TRANSFORMS[transform]
    points = np.array([c[0] for c in cases.values()], dtype=np.float64) * scale + shift
    assert np.array_equal(points.astype(np.float32), points), "transform must be exact in float32"
    return points.astype(np.float32), np.array([c[1] for c in cases.values()]) * scale, [
        c[2] for c in cases.values()
    ]


@pytest.mark.parametrize("transform", list(TRANSFORMS))
def test_vertex_face_named_cases(device: str, transform: str) -> None:
    points, expected, weights = _batch(VERTEX_FACE_CASES, transform)
    rel, _ = check_vertex_face(points, device)
    assert np.all(np.abs(rel) <= BOUND)
    d, w = dist.vertex_face_closest_points(points, device=device)
    L = local_scale(points)
    for name, di, ei, wi, want, Li in zip(VERTEX_FACE_CASES, d, expected, w, weights, L, strict=True):
        assert abs(di - ei) <= BOUND * Li, name
        if want is not None:
            np.testing.assert_allclose(wi, want, atol=4 * tol.EPS32, err_msg=name)


@pytest.mark.parametrize("transform", list(TRANSFORMS))
def test_edge_edge_named_cases(device: str, transform: str) -> None:
    points, expected, params = _batch(EDGE_EDGE_CASES, transform)
    check_edge_edge(points, device)
    d, st_ = dist.edge_edge_closest_points(points, device=device)
    L = local_scale(points)
    for name, di, ei, si, want, Li in zip(EDGE_EDGE_CASES, d, expected, st_, params, L, strict=True):
        assert abs(di - ei) <= BOUND * Li, name
        if want is not None:
            np.testing.assert_allclose(si, want, atol=4 * tol.EPS32, err_msg=name)


def test_named_cases_match_ipctk() -> None:
    vf = np.array([VERTEX_FACE_CASES[k][0] for k in NONDEGENERATE_FACES], dtype=np.float64)
    ipc = [ipctk.point_triangle_distance(*q) for q in vf]
    np.testing.assert_allclose(np.sqrt(ipc), [VERTEX_FACE_CASES[k][1] for k in NONDEGENERATE_FACES],
                               atol=1e-12)
    np.testing.assert_allclose(ref_vertex_face(vf) ** 2, ipc, atol=1e-12)
    ee = np.array([EDGE_EDGE_CASES[k][0] for k in NONDEGENERATE_EDGES], dtype=np.float64)
    ipc = [ipctk.edge_edge_distance(*q) for q in ee]
    np.testing.assert_allclose(np.sqrt(ipc), [EDGE_EDGE_CASES[k][1] for k in NONDEGENERATE_EDGES],
                               atol=1e-12)
    np.testing.assert_allclose(ref_edge_edge(ee) ** 2, ipc, atol=1e-12)


# ------------------------------------------------------------------------------------------------
# Random batches (hypothesis draws the batch parameters; one kernel launch per example)
# ------------------------------------------------------------------------------------------------

MODES = ["uniform", "touching", "flat"]


def random_batch(seed: int, mode: str, n: int = 512) -> tuple[np.ndarray, np.ndarray]:
    """Unit-size (vertex-face, edge-edge) query batches of the given kind."""
    rng = np.random.default_rng(seed)
    vf = rng.uniform(-1, 1, (n, 4, 3))
    ee = rng.uniform(-1, 1, (n, 4, 3))
    if mode == "flat":
        # Triangles and edge pairs of flatness / sin^2(angle) spread over 1 .. 1e-14.
        spread = 10.0 ** -rng.uniform(0, 7, (n, 1))
        u = rng.uniform(-0.5, 1.5, (n, 1))
        vf[:, 3] = vf[:, 1] + u * (vf[:, 2] - vf[:, 1]) + rng.normal(0, 1, (n, 3)) * spread
        ee[:, 3] = ee[:, 2] + u * (ee[:, 1] - ee[:, 0]) + rng.normal(0, 1, (n, 3)) * spread
    if mode in ("touching", "flat"):
        # Vertices near the face plane, edges near to crossing, at heights 1 .. 1e-8.
        height = 10.0 ** -rng.uniform(0, 8, (n, 1))
        w = rng.dirichlet([1.0, 1.0, 1.0], n) * 1.4 - 0.2
        w /= w.sum(axis=1, keepdims=True)
        vf[:, 0] = np.einsum("ni,nij->nj", w, vf[:, 1:]) + rng.normal(0, 1, (n, 3)) * height
        s, t = rng.uniform(-0.2, 1.2, (2, n, 1))
        gap = ee[:, 0] + s * (ee[:, 1] - ee[:, 0]) - ee[:, 2] - t * (ee[:, 3] - ee[:, 2])
        ee[:, 2:] += (gap + rng.normal(0, 1, (n, 3)) * height)[:, None, :]
    return vf, ee


@HYPOTHESIS
@given(
    seed=st.integers(0, 2**32 - 1),
    mode=st.sampled_from(MODES),
    log_scale=st.floats(-3, 3),
    offset=hnp.arrays(np.float64, 3, elements=st.floats(-1e3, 1e3)),
)
def test_random_batches_match_reference(
    device: str, seed: int, mode: str, log_scale: float, offset: np.ndarray
) -> None:
    vf, ee = random_batch(seed, mode)
    scale = 10.0**log_scale
    check_vertex_face((vf * scale + offset).astype(np.float32), device)
    check_edge_edge((ee * scale + offset).astype(np.float32), device)


@settings(HYPOTHESIS, max_examples=10)
@given(seed=st.integers(0, 2**32 - 1), log_scale=st.floats(-3, 3))
def test_random_batches_match_ipctk(device: str, seed: int, log_scale: float) -> None:
    vf, ee = random_batch(seed, "uniform", n=64)
    vf = (vf * 10.0**log_scale).astype(np.float32)
    ee = (ee * 10.0**log_scale).astype(np.float32)
    vf = vf[triangle_flatness(vf) >= tol.WELL_SHAPED_MIN_FLATNESS]
    for points, ipc_fn, ref_fn, our_fn in [
        (vf, ipctk.point_triangle_distance, ref_vertex_face, dist.vertex_face_distance),
        (ee, ipctk.edge_edge_distance, ref_edge_edge, dist.edge_edge_distance),
    ]:
        Q = points.astype(np.float64)
        ipc_sq = np.array([ipc_fn(*q) for q in Q])
        L = local_scale(Q)
        assert np.all(np.abs(ref_fn(Q) ** 2 - ipc_sq) <= 1e-10 * L**2)
        d = our_fn(points, device=device).astype(np.float64)
        ipc = np.sqrt(np.maximum(ipc_sq, 0.0))
        # |d^2 - e^2| = |d - e| (d + e) with |d - e| <= BOUND * L, plus ipctk's own rounding.
        assert np.all(np.abs(d**2 - ipc_sq) <= BOUND * L * (2 * ipc + BOUND * L) + 1e-10 * L**2)


unit_points = hnp.arrays(
    np.float64, (32, 4, 3), elements=st.floats(-1, 1, allow_subnormal=False, width=32)
)
grid_points = hnp.arrays(np.int64, (32, 4, 3), elements=st.integers(-3, 3))


@HYPOTHESIS
@given(points=unit_points, log_scale=st.floats(-3, 3), offset=st.floats(-1e3, 1e3))
def test_hypothesis_points_within_bound(
    device: str, points: np.ndarray, log_scale: float, offset: float
) -> None:
    queries = (points * 10.0**log_scale + offset).astype(np.float32)
    check_vertex_face(queries, device)
    check_edge_edge(queries, device)


@HYPOTHESIS
@given(points=grid_points, scale=st.sampled_from([2.0**-12, 1.0, 2.0**12]))
def test_integer_grid_degeneracies_within_bound(device: str, points: np.ndarray, scale: float) -> None:
    """Small integer grids are rich in exact degeneracies: coincident, collinear, parallel."""
    queries = (points * scale).astype(np.float32)
    check_vertex_face(queries, device)
    check_edge_edge(queries, device)


# ------------------------------------------------------------------------------------------------
# Extremes, device functions, input validation
# ------------------------------------------------------------------------------------------------


def test_extreme_scales_stay_finite(device: str) -> None:
    rng = np.random.default_rng(7)
    base = rng.uniform(-1, 1, (64, 4, 3))
    for scale in [1e-35, 1e-29, 1e-9, 1e9, 1e36]:
        queries = (base * scale).astype(np.float32)
        d_vf, w = dist.vertex_face_closest_points(queries, device=device)
        d_ee, st_ = dist.edge_edge_closest_points(queries, device=device)
        for array in (d_vf, w, d_ee, st_):
            assert np.all(np.isfinite(array)), scale
        if scale >= 1e-29:  # Above MIN_LOCAL_SCALE the bound holds at any magnitude.
            check_vertex_face(queries, device)
            check_edge_edge(queries, device)
    # Subnormal coordinates (1 / x overflows for them).
    subnormal = np.zeros((3, 4, 3), dtype=np.float32)
    subnormal[0, 0, 0] = 1.2e-39
    subnormal[1, 2, 1] = -1.4e-45
    subnormal[2, 3] = 1e-40
    check_vertex_face(subnormal, device)
    check_edge_edge(subnormal, device)
    # Mixed magnitudes: one point far away from a tiny primitive.
    mixed = (base * 1e-6).astype(np.float32)
    mixed[:, 0] = rng.uniform(-1e6, 1e6, (64, 3))
    check_vertex_face(mixed, device)
    check_edge_edge(mixed, device)


@wp.kernel
def _device_function_kernel(
    points: wp.array2d(dtype=wp.vec3),
    vf_sq: wp.array(dtype=float),
    ee_sq: wp.array(dtype=float),
):
    """One thread per query i: both squared distances of points[i] via the public wp.funcs."""
    i = wp.tid()
    vf_sq[i] = dist.vertex_face_distance_squared(points[i, 0], points[i, 1], points[i, 2], points[i, 3])
    ee_sq[i] = dist.edge_edge_distance_squared(points[i, 0], points[i, 1], points[i, 2], points[i, 3])


def test_device_functions_match_host_wrappers(device: str) -> None:
    vf, _ = random_batch(3, "touching", n=128)
    queries = vf.astype(np.float32)
    array = wp.array(queries, dtype=wp.vec3, device=device)
    vf_sq = wp.empty(len(queries), dtype=float, device=device)
    ee_sq = wp.empty(len(queries), dtype=float, device=device)
    wp.launch(_device_function_kernel, dim=len(queries), inputs=[array], outputs=[vf_sq, ee_sq],
              device=device)
    np.testing.assert_allclose(vf_sq.numpy(), dist.vertex_face_distance(queries, device=device) ** 2,
                               rtol=1e-6, atol=1e-12)
    np.testing.assert_allclose(ee_sq.numpy(), dist.edge_edge_distance(queries, device=device) ** 2,
                               rtol=1e-6, atol=1e-12)


def test_empty_batches(device: str) -> None:
    empty = np.zeros((0, 4, 3), dtype=np.float32)
    assert dist.vertex_face_distance(empty, device=device).shape == (0,)
    assert dist.edge_edge_distance(empty, device=device).shape == (0,)
    d, w = dist.vertex_face_closest_points(empty, device=device)
    assert d.shape == (0,) and w.shape == (0, 3) and w.dtype == np.float32
    d, st_ = dist.edge_edge_closest_points(empty, device=device)
    assert d.shape == (0,) and st_.shape == (0, 2) and st_.dtype == np.float32


def test_accepts_lists_float64_and_warp_arrays(device: str) -> None:
    query = [[[0.25, 0.25, 2.0], *TRI]]
    expected = np.array([2.0], dtype=np.float32)
    np.testing.assert_array_equal(dist.vertex_face_distance(query, device=device), expected)
    np.testing.assert_array_equal(dist.vertex_face_distance(np.array(query), device=device), expected)
    warp_query = wp.array(np.array(query, dtype=np.float32), dtype=wp.float32, device=device)
    np.testing.assert_array_equal(dist.vertex_face_distance(warp_query, device=device), expected)


BAD_INPUTS = {
    "missing_batch_axis": np.zeros((4, 3)),
    "three_points": np.zeros((5, 3, 3)),
    "two_dimensional_points": np.zeros((5, 4, 2)),
    "nan": np.where(np.arange(24).reshape(2, 4, 3) == 13, np.nan, 0.0),
    "inf": np.where(np.arange(24).reshape(2, 4, 3) == 5, -np.inf, 0.0),
    "overflows_float32": np.full((1, 4, 3), 1e39),
    "complex": np.zeros((2, 4, 3), dtype=np.complex64),
    "strings": np.full((1, 4, 3), "x"),
}


@pytest.mark.filterwarnings("ignore:overflow encountered in cast:RuntimeWarning")
@pytest.mark.parametrize("bad", list(BAD_INPUTS))
@pytest.mark.parametrize(
    "function",
    [dist.vertex_face_distance, dist.edge_edge_distance, dist.vertex_face_closest_points,
     dist.edge_edge_closest_points],
)
def test_bad_input_raises_input_error(function, bad: str) -> None:
    with pytest.raises(InputError, match="points"):
        function(BAD_INPUTS[bad], device="cpu")
