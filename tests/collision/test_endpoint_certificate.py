"""The endpoint certificate of the discrete narrow phase (:func:`pscc.collision.narrow_phase.points_within`):
a vertex within the thickness of a face corner, or an edge end within it of the other edge's end, is a
contact without its closest points. Every certified pair of points is truly closer than the thickness (float64
distances), also at the thickness give or take a few rounding units and far from the origin; the certificate
is not vacuous; and on dense contact the narrow phase reports exactly the reference's pairs with it."""

from __future__ import annotations

import numpy as np
import pytest
import warp as wp

from pscc.collision.narrow_phase import certain_contact_sq, corner_within, ends_within, points_within
from tests.geometry.test_distance import ref_edge_edge, ref_vertex_face


@wp.kernel
def _within_kernel(p: wp.array(dtype=wp.vec3), q: wp.array(dtype=wp.vec3), thickness: float,
                   out: wp.array(dtype=wp.int32)):
    i = wp.tid()
    out[i] = wp.where(points_within(p[i], q[i], certain_contact_sq(thickness)), 1, 0)


@wp.kernel
def _rows_kernel(points: wp.array(dtype=wp.vec3, ndim=2), thickness: float, edge_edge: int,
                 out: wp.array(dtype=wp.int32)):
    i = wp.tid()
    certain_sq = certain_contact_sq(thickness)
    hit = bool(False)
    if edge_edge == 1:
        hit = ends_within(points[i, 0], points[i, 1], points[i, 2], points[i, 3], certain_sq)
    else:
        hit = corner_within(points[i, 0], points[i, 1], points[i, 2], points[i, 3], certain_sq)
    out[i] = wp.where(hit, 1, 0)


def _within(p: np.ndarray, q: np.ndarray, thickness: float) -> np.ndarray:
    out = wp.zeros(p.shape[0], dtype=wp.int32, device="cpu")
    wp.launch(_within_kernel, dim=p.shape[0], device="cpu",
              inputs=[wp.array(p, dtype=wp.vec3, device="cpu"), wp.array(q, dtype=wp.vec3, device="cpu"),
                      thickness], outputs=[out])
    return out.numpy().astype(bool)


@pytest.mark.parametrize("offset", [0.0, 1000.0])
@pytest.mark.parametrize("thickness", [1e-6, 0.01, 30.0])
def test_certified_points_are_closer_than_the_thickness(offset: float, thickness: float) -> None:
    rng = np.random.default_rng(int(thickness * 1e6) % 997)
    n = 20000
    p = rng.uniform(-1, 1, (n, 3)) * max(thickness, 1.0) + offset
    direction = rng.normal(size=(n, 3))
    direction /= np.linalg.norm(direction, axis=1, keepdims=True)
    # Gaps at the thickness within a few float32 rounding units of the coordinates or of the thickness,
    # and spread over [0, 2] thicknesses.
    ulp = max(float(np.spacing(np.float32(abs(offset) + max(thickness, 1.0)))), thickness * 2.0**-23)
    near = thickness + rng.uniform(-8, 8, (n // 2, 1)) * ulp
    spread = rng.uniform(0, 2, (n - n // 2, 1)) * thickness
    q = p + direction * np.concatenate([near, spread])
    p32, q32 = p.astype(np.float32), q.astype(np.float32)
    certified = _within(p32, q32, thickness)
    exact = np.linalg.norm(p32.astype(np.float64) - q32.astype(np.float64), axis=1)
    assert np.all(exact[certified] < thickness), np.flatnonzero(certified & (exact >= thickness))[:10]
    # Not vacuous: pairs clearly within (by 1e-4 of the thickness, above the coordinates' rounding) pass
    # (where the coordinates resolve the thickness at all: not 1e-6 at 1000).
    clearly = exact < thickness * (1.0 - 1e-4) - 4 * ulp
    if ulp < 1e-3 * thickness:
        assert np.count_nonzero(clearly) > n // 5
    assert np.all(certified[clearly])


def test_nan_and_coincident_points() -> None:
    p = np.array([[0, 0, 0], [np.nan, 0, 0], [1, 1, 1]], dtype=np.float32)
    q = np.array([[0, 0, 0], [0, 0, 0], [1, 1, 1]], dtype=np.float32)
    assert _within(p, q, 0.01).tolist() == [True, False, True]
    assert _within(p, q, 0.0).tolist() == [False, False, False]


@pytest.mark.parametrize("edge_edge", [0, 1])
def test_certified_rows_are_contacts(edge_edge: int) -> None:
    """Random vertex-face and edge-edge rows at about the thickness: every row certified by a pair of its
    points is within the thickness by the float64 reference, and many are certified."""
    rng = np.random.default_rng(7 + edge_edge)
    n = 20000
    h = 0.05
    rows = rng.uniform(-1, 1, (n, 1, 3)) * 0.1 + rng.normal(0, 0.04, (n, 4, 3))
    rows = rows.astype(np.float32)
    out = wp.zeros(n, dtype=wp.int32, device="cpu")
    wp.launch(_rows_kernel, dim=n, device="cpu",
              inputs=[wp.array(rows, dtype=wp.vec3, device="cpu"), h, edge_edge], outputs=[out])
    certified = out.numpy().astype(bool)
    exact = ref_edge_edge(rows) if edge_edge else ref_vertex_face(rows)
    assert np.count_nonzero(certified) > n // 20
    assert np.all(exact[certified] < h)


def test_dense_contact_detection_matches_the_reference() -> None:
    """Two crumpled sheets closer than their thickness almost everywhere (most candidate rows certified):
    the brute-force detector's discrete contacts (all feature pairs that share no vertex are its candidates)
    are the float64 reference's, give or take pairs within the rounding band."""
    from pscc.collision.detector import CollisionDetector
    from pscc.mesh import grid_sheet

    rng = np.random.default_rng(11)
    vertices, sheet, _ = grid_sheet(10, 10)
    n = vertices.shape[0]
    edge = float(np.linalg.norm(vertices[sheet[0, 0]] - vertices[sheet[0, 1]]))
    h = 1.5 * edge
    bottom = vertices + rng.normal(0, 0.2 * edge, vertices.shape)
    top = vertices + np.array([0.0, 0.0, 0.5 * edge]) + rng.normal(0, 0.2 * edge, vertices.shape)
    x = np.concatenate([bottom, top]).astype(np.float32)
    faces = np.concatenate([sheet, sheet + n]).astype(np.int32)
    brute = CollisionDetector(faces, method="brute-force", device="cpu")
    result = brute.detect(x, thickness=h)
    x64 = x.astype(np.float64)
    vf_rows = brute.candidates.vertex_face.numpy()[: brute.candidates.vertex_face_count]
    ee_rows = brute.candidates.edge_edge.numpy()[: brute.candidates.edge_edge_count]
    vf_points = np.stack([x64[vf_rows[:, 0]], *(x64[faces[vf_rows[:, 1]][:, k]] for k in range(3))], axis=1)
    edges = brute.topology.edges[ee_rows]  # (rows, 2 edges, 2 ends)
    ee_points = x64[edges.reshape(-1, 4)]
    vf_exact, ee_exact = ref_vertex_face(vf_points), ref_edge_edge(ee_points)
    band = 1e-5 * h
    must_vf = {tuple(r) for r in vf_rows[vf_exact <= h - band].tolist()}
    may_vf = {tuple(r) for r in vf_rows[vf_exact <= h + band].tolist()}
    ends = np.sort(edges.reshape(-1, 2, 2), axis=2)  # each edge's ends in order
    swap = (ends[:, 0, 0] > ends[:, 1, 0]) | ((ends[:, 0, 0] == ends[:, 1, 0]) & (ends[:, 0, 1] > ends[:, 1, 1]))
    ends[swap] = ends[swap][:, ::-1]  # the lower edge first: the detector's row layout
    keys = ends.reshape(-1, 4)
    must_ee = {tuple(r) for r in keys[ee_exact <= h - band].tolist()}
    may_ee = {tuple(r) for r in keys[ee_exact <= h + band].tolist()}
    got_vf = {tuple(r) for r in result.vertex_face.tolist()}
    got_ee = {tuple(r) for r in result.edge_edge.tolist()}
    assert len(must_vf) > 500 and len(must_ee) > 1000
    assert must_vf <= got_vf <= may_vf
    assert must_ee <= got_ee <= may_ee
