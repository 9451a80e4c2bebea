"""Discrete vertex-face proximity on nearly flat triangles (flatness below ``WELL_SHAPED_MIN_FLATNESS``).

:func:`pscc.collision.narrow_phase.vertex_face_proximity_toi` decides such a pair by the closed-form
distance except in a band of ``thin_overestimate x L`` past the thickness; there a pair whose projection is
certified outside the face is decided by its edges, and the rest by the exact-safe search. Checked against a
float64 reference: no pair within the thickness is missed, every pair reported is within the rounding band
or reported by the search as well, and every pair rejected is beyond the thickness by half the rounding
band, as on a well-shaped face.
"""

from __future__ import annotations

import numpy as np
import pytest
import warp as wp

from pscc.collision.narrow_phase import ProximityParameters, proximity_parameters, vertex_face_proximity_toi
from pscc.geometry import distance as dist
from pscc.geometry import distance_tolerances as tol
from pscc.geometry.ccd import CcdParameters, ccd_parameters, vertex_face_ccd_toi
from tests.geometry.test_distance import local_scale, ref_vertex_face, triangle_flatness
from tests.geometry.test_projection_side import side_weights as ref_side_weights


@wp.kernel
def _proximity_batch(
    queries: wp.array(dtype=wp.vec3, ndim=2),
    thickness: wp.array(dtype=wp.float32),
    params: CcdParameters,
    proximity: ProximityParameters,
    fast: wp.array(dtype=wp.float32),
    search: wp.array(dtype=wp.float32),
):
    i = wp.tid()
    p = queries[i, 0]
    a = queries[i, 1]
    b = queries[i, 2]
    c = queries[i, 3]
    h = thickness[i]
    fast[i] = vertex_face_proximity_toi(p, a, b, c, dist.vertex_face_closest_point(p, a, b, c), h, params, proximity)
    search[i] = vertex_face_ccd_toi(p, a, b, c, p, a, b, c, h, 0.0, params)


def _thin_queries(seed: int, n: int) -> np.ndarray:
    """(n, 4, 3) vertex-face queries of unit size whose triangles have flatness 1e-7 .. 1e-2."""
    rng = np.random.default_rng(seed)
    q = rng.uniform(-1, 1, (n, 4, 3))
    # Vertex c near the line through a and b: the triangle's height is `spread` of its length.
    spread = 10.0 ** -rng.uniform(1.2, 3.4, (n, 1))
    u = rng.uniform(-0.3, 1.3, (n, 1))
    q[:, 3] = q[:, 1] + u * (q[:, 2] - q[:, 1]) + rng.normal(0, 1, (n, 3)) * spread
    # The vertex near the triangle: a point of its plane's neighbourhood plus an offset of 1e-4 .. 0.3.
    w = rng.dirichlet([1.0, 1.0, 1.0], n) * 1.4 - 0.2
    w /= w.sum(axis=1, keepdims=True)
    q[:, 0] = np.einsum("ni,nij->nj", w, q[:, 1:]) + rng.normal(0, 1, (n, 3)) * 10.0 ** -rng.uniform(0.5, 4, (n, 1))
    return q


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_thin_faces_miss_no_contact_and_add_only_the_rounding_band(device: str, seed: int) -> None:
    queries = _thin_queries(seed, 4096).astype(np.float32)
    flat = triangle_flatness(queries)
    keep = (flat < tol.WELL_SHAPED_MIN_FLATNESS) & (flat > tol.TRIANGLE_DEGENERATE_REL_SQ)
    queries = queries[keep]
    n = queries.shape[0]
    assert n > 2000
    exact = ref_vertex_face(queries)
    scale = local_scale(queries.astype(np.float64))
    closed_form = dist.vertex_face_distance(queries, device="cpu").astype(np.float64)
    proximity = proximity_parameters()
    error = float(proximity.distance_error) * scale
    band = float(proximity.thin_overestimate) * scale
    # Thicknesses around each pair's distance: well inside and outside, at the thickness within the
    # rounding, across the thin-face band past it, and the distance itself.
    rng = np.random.default_rng(seed + 100)
    choice = rng.integers(0, 5, n)
    thickness = np.select(
        [choice == 0, choice == 1, choice == 2, choice == 3],
        [exact * rng.uniform(0.5, 1.5, n), exact + rng.uniform(-2, 2, n) * error,
         closed_form - error - rng.uniform(0, 1.2, n) * band, exact],
        exact * rng.uniform(0.98, 1.02, n),
    )
    thickness = np.maximum(thickness, 0.0).astype(np.float32)
    h = thickness.astype(np.float64)
    fast = wp.zeros(n, dtype=wp.float32, device=device)
    search = wp.zeros(n, dtype=wp.float32, device=device)
    wp.launch(_proximity_batch, dim=n, device=device,
              inputs=[wp.array(queries, dtype=wp.vec3, device=device), wp.array(thickness, device=device),
                      ccd_parameters(), proximity], outputs=[fast, search])
    reported = fast.numpy() <= 1.0
    searched = search.numpy() <= 1.0
    # All three ways the thin-face test decides are exercised (the band's edges with a margin for the
    # float32 comparisons in the kernel).
    margin = 1e-6 * scale
    in_band = (closed_form > h + error + margin) & (closed_form <= h + error + band - margin)
    assert np.count_nonzero(closed_form <= h + error) > 100
    assert np.count_nonzero(closed_form > h + error + band) > 100
    assert np.count_nonzero(in_band) > 50
    # Zero false negatives against the float64 distance (with float64's own rounding).
    must = exact <= h - 1e-12 * scale
    assert np.all(reported[must]), np.flatnonzero(must & ~reported)[:10]
    # Every report is within the closed form's band (|d_float32 - d_exact| <= error / 2) or the search's.
    assert np.all(~reported | (exact <= h + 1.5 * error) | searched)
    # Every rejected pair is beyond the thickness by half the rounding band (float64's own rounding aside).
    assert np.all(reported | (exact > h + 0.5 * error - 1e-12 * scale)), np.flatnonzero(
        ~reported & (exact <= h + 0.5 * error - 1e-12 * scale))[:10]
    # In the band, where the decision by the edges and the search differ, the pair is truly beyond the
    # thickness: the search's own tolerance is wider than the edges' (it reports pairs up to several
    # rounding bands out), never narrower.
    differ = in_band & (reported != searched)
    assert np.all(exact[differ] > h[differ])
    beside = in_band & (ref_side_weights(queries).min(axis=1) < 0)
    assert np.count_nonzero(beside) > 20
