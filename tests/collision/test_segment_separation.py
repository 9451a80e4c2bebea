"""The edge-edge separation test (pscc.collision.pair_filter.segments_separated) that lets the discrete
narrow phase skip the closed form: a pair it certifies is farther apart than the thickness (float64
distances), near the thickness within rounding, far from the origin, and for parallel edges."""

from __future__ import annotations

import numpy as np
import pytest
import warp as wp

from pscc.collision.pair_filter import segments_separated


@wp.kernel
def _separated(points: wp.array(dtype=wp.vec3, ndim=2), thickness: float, out: wp.array(dtype=wp.int32)):
    i = wp.tid()
    out[i] = int(segments_separated(points[i, 0], points[i, 1], points[i, 2], points[i, 3], thickness))


def _run(points: np.ndarray, thickness: float) -> np.ndarray:
    out = wp.zeros(points.shape[0], dtype=wp.int32, device="cpu")
    wp.launch(_separated, dim=points.shape[0], inputs=[wp.array(points.astype(np.float32), dtype=wp.vec3,
                                                                device="cpu"), thickness], outputs=[out],
              device="cpu")
    return out.numpy().astype(bool)


def _distance(p: np.ndarray) -> float:
    import ipctk

    return float(np.sqrt(ipctk.edge_edge_distance(p[0], p[1], p[2], p[3])))


@pytest.mark.parametrize("offset, spread", [(0.0, 40.0), (1000.0, 40.0), (0.0, 2.0), (0.0, 0.5)])
def test_certified_pairs_are_farther_than_the_thickness(offset: float, spread: float) -> None:
    """Random segment pairs whose lines pass at the thickness give or take a few rounding units (so the
    float32 rounding decides many), and random pairs at any distance: every certified pair is farther than
    the thickness (``spread``: the gap's spread around the thickness, in rounding units of the coordinates;
    at 0.5 and 2 the bound leaves nothing certified, and without it this test fails)."""
    rng = np.random.default_rng(3)
    n = 6000
    h = 0.01
    a0 = rng.uniform(-1, 1, (n, 3))
    da = rng.normal(size=(n, 3))
    db = rng.normal(size=(n, 3))
    normal = np.cross(da, db)
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    ulp = np.spacing(np.float32(max(offset, 1.0)))
    gap = h + rng.uniform(-spread, spread, (n, 1)) * ulp
    # Segments crossing near their middles, so the closest points are inside both.
    b_mid = a0 + 0.5 * da + normal * gap
    points = np.stack([a0, a0 + da, b_mid - 0.5 * db, b_mid + 0.5 * db], axis=1) + offset
    points = points.astype(np.float32)
    separated = _run(points, h)
    p64 = points.astype(np.float64)
    for i in np.flatnonzero(separated):
        assert _distance(p64[i]) > h, i
    if spread > 10:
        assert separated.sum() > 0.1 * n
    # Any distance: certified ones are farther; pairs whose common normal clearly separates are certified.
    far = (rng.uniform(-1, 1, (n, 4, 3)) * rng.uniform(0.01, 1, (n, 1, 1)) + offset).astype(np.float32)
    separated = _run(far, h)
    for i in np.flatnonzero(separated):
        assert _distance(far[i].astype(np.float64)) > h, i
    assert 0 < separated.sum() < n


def test_parallel_degenerate_and_nan_are_never_separated() -> None:
    """Parallel edges (no common normal), a zero-length edge and NaN coordinates certify nothing, however far
    apart."""
    points = np.array([
        [[0, 0, 0], [1, 0, 0], [0, 5, 0], [1, 5, 0]],        # parallel, 5 apart
        [[0, 0, 0], [0, 0, 0], [0, 5, 0], [1, 5, 3]],        # a point and an edge
        [[0, 0, 0], [1, 0, 0], [0, 5, np.nan], [0, 5, 1]],   # NaN
    ], np.float32)
    assert not _run(points, 0.1).any()


def test_crossing_edges_at_the_threshold() -> None:
    """Two perpendicular edges 1.0 apart: certified for thicknesses below 1.0 by more than rounding, not at
    1.0 or above."""
    points = np.array([[[-1, 0, 0], [1, 0, 0], [0, -1, 1], [0, 1, 1]]], np.float32)
    assert _run(points, 0.999)[0]
    for h in (1.0, 1.0001, 3.0):
        assert not _run(points, h)[0]


def test_the_narrow_phase_drops_only_pairs_farther_than_the_thickness() -> None:
    """Two crumpled sheets close to each other, discrete detection with the edge test on and off
    (``ProximityParameters.edge_separation``): the edge-edge contacts with it are those without it, less only
    pairs whose float64 distance exceeds the thickness; the test does certify some candidate rows."""
    from pscc.collision.detector import CollisionDetector
    from pscc.mesh import grid_sheet

    rng = np.random.default_rng(4)
    vertices, sheet, _ = grid_sheet(12, 12)
    n = vertices.shape[0]
    top = vertices + np.array([0.0, 0.0, 0.03]) + rng.normal(0, 0.01, vertices.shape)
    x = np.concatenate([vertices + rng.normal(0, 0.01, vertices.shape), top]).astype(np.float32)
    faces = np.concatenate([sheet, sheet + n]).astype(np.int32)
    h = 0.02
    results = []
    for flag in (0, 1):
        detector = CollisionDetector(faces, method="brute-force", device="cpu")
        detector.prepare(x)
        detector.narrow.proximity.edge_separation = flag
        results.append(detector.detect(x, thickness=h))
        rows = detector.candidates.edge_edge.numpy()[: detector.candidates.edge_edge_count]
        ends = detector.topology.edges[rows]  # (rows, 2 edges, 2 ends)
    without, with_test = ({tuple(r) for r in res.edge_edge.tolist()} for res in results)
    assert with_test <= without and len(with_test) > 0
    x64 = x.astype(np.float64)
    for a0, a1, b0, b1 in without - with_test:
        assert _distance(x64[[a0, a1, b0, b1]]) > h
    np.testing.assert_array_equal(results[0].vertex_face, results[1].vertex_face)
    certified = _run(x[ends.reshape(-1, 4)], h)
    assert certified.any()
