"""The CCD's plane filter (``pscc.geometry.ccd.plane_keeps_distance``): a pair whose features provably stay
farther than the minimum distance from each other's moving plane is excluded before the search, and no pair
that comes within the distance is ever excluded."""

from __future__ import annotations

import ipctk
import numpy as np
import pytest
import warp as wp

from pscc.geometry.ccd import ccd_parameters, edge_edge_ccd, plane_keeps_distance, vertex_face_ccd


@wp.kernel
def _probe(q: wp.array(dtype=wp.vec3), distance: float, factor: float, out: wp.array(dtype=wp.int32)):
    out[0] = wp.where(plane_keeps_distance(q[0], q[1], q[2], q[3], q[4], q[5], distance, factor), 1, 0)


def _keeps(q0, e10, e20, q1, e11, e21, distance: float) -> bool:
    q = wp.array(np.array([q0, e10, e20, q1, e11, e21], dtype=np.float32), dtype=wp.vec3, device="cpu")
    out = wp.zeros(1, dtype=wp.int32, device="cpu")
    wp.launch(_probe, dim=1, inputs=[q, float(distance), float(ccd_parameters().coplanarity_factor)], outputs=[out],
              device="cpu")
    return bool(out.numpy()[0])


def test_the_filter_proves_parallel_motion_apart_and_nothing_closer() -> None:
    # A vertex 2 cm above the plane of a triangle (q = p - a, e1 = a - b, e2 = a - c), sliding along it.
    e1, e2 = np.array([-0.1, 0.0, 0.0]), np.array([0.0, -0.1, 0.0])
    for height, expected in ((0.02, True), (0.0095, False), (-0.02, True)):
        q0 = np.array([0.03, 0.02, height])
        q1 = q0 + [0.05, 0.0, 0.0]
        assert _keeps(q0, e1, e2, q1, e1, e2, 0.01) is expected, height
    # Crossing the plane during the step: never proven apart.
    assert not _keeps([0.03, 0.02, 0.02], e1, e2, [0.03, 0.02, -0.02], e1, e2, 0.001)
    # A plane that tilts towards the vertex: apart at both ends is not enough if the middle comes close.
    tilted = np.array([0.0, -0.1, 0.25])
    assert not _keeps([0.03, 0.05, 0.02], e1, e2, [0.03, 0.05, 0.02], e1, tilted, 0.01)


def _sampled_min_distance(kind: str, x0: np.ndarray, x1: np.ndarray, samples: int = 101) -> np.ndarray:
    best = np.full(x0.shape[0], np.inf)
    for t in np.linspace(0.0, 1.0, samples):
        x = (1.0 - t) * x0 + t * x1
        for i in range(x.shape[0]):
            p = x[i]
            d2 = ipctk.point_triangle_distance(*p) if kind == "vf" else ipctk.edge_edge_distance(*p)
            best[i] = min(best[i], float(np.sqrt(d2)))
    return best


@pytest.mark.parametrize("kind", ["vf", "ee"])
def test_no_pair_that_comes_within_the_distance_is_excluded(kind: str) -> None:
    """Near-plane trajectories (the filter's hard case): every one whose sampled distance comes within the
    minimum distance is a hit with the filter, and the filter only removes hits the search did not find."""
    rng = np.random.default_rng(7 if kind == "vf" else 8)
    count, distance = 600, 0.004
    x0 = rng.uniform(-0.05, 0.05, (count, 4, 3))
    x0[:, 0, 2] = rng.uniform(-0.01, 0.01, count)  # the first feature starts near the others' plane z ~ 0
    x0[:, 1:, 2] *= 0.05
    x1 = x0 + rng.normal(0.0, 0.004, (count, 4, 3))
    x0, x1 = x0.astype(np.float32), x1.astype(np.float32)
    run = vertex_face_ccd if kind == "vf" else edge_edge_ccd
    filtered, _ = run(x0, x1, distance)
    searched, _ = run(x0, x1, distance, plane_filter=False)
    assert np.all(filtered <= searched)  # the filter only ever excludes
    close = _sampled_min_distance(kind, x0.astype(np.float64), x1.astype(np.float64)) <= distance * 0.999
    assert close.sum() > 30
    assert np.all(filtered[close]), np.flatnonzero(close & ~filtered)
