""":func:`pscc.geometry.distance.projection_outside_triangle` against a float64 reference.

The certificate may only say "outside" when the point's projection is truly outside the triangle (strictly,
beyond the float64 reference's own rounding); it must say so for points clearly beside thin and regular
triangles alike; it never certifies anything for zero-area triangles or coincident points.
"""

from __future__ import annotations

import numpy as np
import pytest
import warp as wp

from pscc.geometry import distance as dist
from pscc.geometry import distance_tolerances as tol
from tests.geometry.test_distance import triangle_flatness


@wp.kernel
def _outside_batch(queries: wp.array(dtype=wp.vec3, ndim=2), outside: wp.array(dtype=wp.int32)):
    i = wp.tid()
    outside[i] = wp.where(dist.projection_outside_triangle(queries[i, 0], queries[i, 1], queries[i, 2],
                                                           queries[i, 3]), 1, 0)


def _run(queries: np.ndarray, device: str) -> np.ndarray:
    out = wp.zeros(queries.shape[0], dtype=wp.int32, device=device)
    wp.launch(_outside_batch, dim=queries.shape[0], device=device,
              inputs=[wp.array(queries, dtype=wp.vec3, device=device)], outputs=[out])
    return out.numpy().astype(bool)


def side_weights(queries: np.ndarray) -> np.ndarray:
    """(n, 3) float64 signed face weights ``n . (e x (p - v))`` of the three edges, divided by ``|n|`` and
    the edge's length: the signed in-plane distance of the projection from each edge's line (positive
    inside)."""
    P = queries.astype(np.float64)
    p, a, b, c = P[:, 0], P[:, 1], P[:, 2], P[:, 3]
    n = np.cross(b - a, c - a)
    norm = np.linalg.norm(n, axis=1)
    rows = []
    for v, w in ((a, b), (b, c), (c, a)):
        e = w - v
        rows.append(np.einsum("ij,ij->i", n, np.cross(e, p - v))
                    / np.maximum(norm * np.linalg.norm(e, axis=1), 1e-300))
    return np.stack(rows, axis=1)


def _scaled_margins(queries: np.ndarray) -> np.ndarray:
    """(n, 3) float64 signed face weights as the kernel forms them (shifted to ``a``, scaled by the largest
    absolute coordinate of ``ab``, ``ac``, ``ap``), each divided by its rounding bound
    (``PROJECTION_SIDE_ERROR_PER_NORMAL``): below -1 the kernel must certify the point outside."""
    P = queries.astype(np.float64)
    ab, ac, ap = P[:, 2] - P[:, 1], P[:, 3] - P[:, 1], P[:, 0] - P[:, 1]
    scale = np.abs(np.stack([ab, ac, ap], axis=1)).max(axis=(1, 2))[:, None]
    ab, ac, ap = ab / scale, ac / scale, ap / scale
    n = np.cross(ab, ac)
    normal_max = np.abs(n).max(axis=1)
    rows = []
    for edge, offset in ((ab, ap), (-ac, ap), (ac - ab, ap - ab)):
        bound = (np.abs(edge).max(axis=1) * np.abs(offset).max(axis=1)
                 * (tol.PROJECTION_SIDE_ERROR_PER_NORMAL * normal_max + tol.PROJECTION_SIDE_ERROR_BASE))
        weight = np.einsum("ij,ij->i", n, np.cross(edge, offset))
        rows.append(weight / np.maximum(bound, 1e-300))
    return np.stack(rows, axis=1)


def _queries(seed: int, n: int, spread_exponent: tuple[float, float]) -> np.ndarray:
    """(n, 4, 3) float32 queries: triangles of height ``10**-spread`` of their length, points around them
    (weights from -0.3 to 1.3, so inside and outside) and off their plane."""
    rng = np.random.default_rng(seed)
    q = rng.uniform(-1, 1, (n, 4, 3))
    spread = 10.0 ** -rng.uniform(*spread_exponent, (n, 1))
    q[:, 3] = q[:, 1] + rng.uniform(-0.3, 1.3, (n, 1)) * (q[:, 2] - q[:, 1]) + rng.normal(0, 1, (n, 3)) * spread
    w = rng.dirichlet([1.0, 1.0, 1.0], n) * 1.6 - 0.2
    w /= w.sum(axis=1, keepdims=True)
    q[:, 0] = np.einsum("ni,nij->nj", w, q[:, 1:]) + rng.normal(0, 1, (n, 3)) * 10.0 ** -rng.uniform(0, 4, (n, 1))
    return q.astype(np.float32)


@pytest.mark.parametrize("spread", [(0.0, 1.0), (1.0, 2.5), (2.5, 4.0)])
def test_certified_outside_only_when_truly_outside(device: str, spread: tuple[float, float]) -> None:
    queries = _queries(int(spread[0] * 10), 8192, spread)
    outside = _run(queries, device)
    side = side_weights(queries)
    truly_outside = side.min(axis=1) < -1e-12
    assert not np.any(outside & ~truly_outside), np.flatnonzero(outside & ~truly_outside)[:10]
    # Every point beside an edge by twice that edge's rounding bound is certified (the weights' rounding
    # error is below the bound).
    clearly = _scaled_margins(queries).min(axis=1) < -2.0
    assert np.count_nonzero(clearly) > 1000
    assert np.all(outside[clearly]), np.flatnonzero(clearly & ~outside)[:10]
    assert np.count_nonzero(~outside & truly_outside) < np.count_nonzero(truly_outside)


def test_degenerate_triangles_and_points_are_never_certified(device: str) -> None:
    cases = np.array([
        [[2, 0, 0], [0, 0, 0], [1, 0, 0], [3, 0, 0]],  # collinear, the point on their line
        [[0, 5, 0], [0, 0, 0], [1, 0, 0], [2, 0, 0]],  # collinear, the point beside
        [[1, 1, 1], [0, 0, 0], [0, 0, 0], [0, 0, 0]],  # one point
        [[0, 0, 0], [0, 0, 0], [0, 0, 0], [0, 0, 0]],  # nothing at all
        [[-1e-31, -1e-31, 0], [1e-31, 0, 0], [0, 1e-31, 0], [0, 0, 0]],  # beside, below the resolved scale
    ], dtype=np.float32)
    assert not np.any(_run(cases, device))
    assert np.all(triangle_flatness(cases[:4]) == 0.0)


def test_points_on_an_edge_line_or_vertex_are_not_certified(device: str) -> None:
    # On the edge's line inside the triangle's span, at a vertex, and in the plane just inside.
    cases = np.array([
        [[0.5, 0, 0], [0, 0, 0], [1, 0, 0], [0, 1, 0]],
        [[0.5, 0, 3], [0, 0, 0], [1, 0, 0], [0, 1, 0]],
        [[1, 0, 0], [0, 0, 0], [1, 0, 0], [0, 1, 0]],
        [[0.25, 0.25, -2], [0, 0, 0], [1, 0, 0], [0, 1, 0]],
    ], dtype=np.float32)
    assert not np.any(_run(cases, device))
    # Beside the edge by more than the margin (in units of the local scale, here up to 3): certified.
    beside = cases[:2].copy()
    beside[:, 0, 1] = -0.05
    assert np.all(_run(beside, device))


def test_points_beyond_a_sliver_short_edge_are_certified(device: str) -> None:
    """A sliver 1 long and 1e-4 wide: points just beyond its short edge (its far end), in its plane and a
    little off it, are certified outside (the bound scales with the short edge), points just inside are not.
    (Far off the plane the normal's own rounding, 4 units absolute, outweighs a 1e-4-wide face's weight.)"""
    a, b, c = [0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1e-4, 0.0]
    beyond = [[1.0 + d, 5e-5, z, *a, *b, *c] for d in (1e-3, 1e-2) for z in (0.0, 0.01)]
    inside = [[1.0 - d, 5e-5, z, *a, *b, *c] for d in (1e-3, 1e-2) for z in (0.0, 0.01)]
    queries = np.array(beyond + inside, dtype=np.float32).reshape(-1, 4, 3)
    got = _run(queries, device)
    assert got[: len(beyond)].all()
    assert not got[len(beyond):].any()
