"""The brute-force detector against a plain NumPy all-pairs reference with float64 ipctk decisions."""

from __future__ import annotations

import ipctk
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pscc.collision.detector import CollisionDetector
from pscc.errors import InputError
from pscc.mesh import MeshTopology, folded_sheet, grid_sheet

BAND = 1e-3
"""Near-miss band (absolute; the test meshes have unit size) a reported pair must fall within:
the tolerance band of :mod:`pscc.tolerances`, widened for queries that spend their box budget."""


def _reference(faces, x0, x1, thickness, band):
    """All feature pairs (sharing no vertex), decided in float64 by ipctk.

    Returns (must, may): the pairs that truly come within ``thickness`` and the pairs that come
    within ``thickness + band`` (every reported pair must be in ``may``).
    """
    vertex_count = x0.shape[0]
    edges = MeshTopology.from_faces(faces, vertex_count).edges
    ccd = ipctk.TightInclusionCCD(tolerance=1e-7, max_iterations=100_000, conservative_rescaling=1.0)
    lo = np.minimum(x0, x1)
    hi = np.maximum(x0, x1)
    grow = thickness + band

    def near(idx_a, idx_b):
        return bool(np.all(lo[idx_a].min(0) <= hi[idx_b].max(0) + grow)
                    and np.all(lo[idx_b].min(0) <= hi[idx_a].max(0) + grow))

    def distance_squared(kind, points):
        if kind == "vf":
            return ipctk.point_triangle_distance(*points)
        return ipctk.edge_edge_distance(*points)

    def must_hit(kind, points0, points1):
        """True contact within ``thickness`` (Euclidean)."""
        if x1 is x0:
            return distance_squared(kind, points0) <= thickness * thickness
        fn = ccd.point_triangle_ccd if kind == "vf" else ccd.edge_edge_ccd
        if fn(*points0, *points1, min_distance=0.0)[0]:
            return True
        if thickness == 0.0:
            return False
        # ipctk's minimum distance is per axis (L-infinity): sample the Euclidean distance instead.
        for t in np.linspace(0.0, 1.0, 101):
            points = [(1 - t) * a + t * b for a, b in zip(points0, points1, strict=True)]
            if distance_squared(kind, points) <= thickness * thickness:
                return True
        return False

    def may_hit(kind, points0, points1):
        """Contact within ``thickness + band`` per axis: a superset of the Euclidean answer."""
        if x1 is x0:
            return distance_squared(kind, points0) <= grow * grow
        fn = ccd.point_triangle_ccd if kind == "vf" else ccd.edge_edge_ccd
        return fn(*points0, *points1, min_distance=grow)[0]

    def decide(kind, points0, points1, distance):
        if distance == thickness:
            return must_hit(kind, points0, points1)
        return may_hit(kind, points0, points1)

    must_vf, may_vf, must_ee, may_ee = set(), set(), set(), set()
    used = set(np.unique(faces).tolist())
    for v in range(vertex_count):
        if v not in used:
            continue  # isolated vertices take no part
        for f, tri in enumerate(faces):
            if v in tri:
                continue
            idx = [v, *tri]
            if not near([v], list(tri)):
                continue
            p0 = [x0[i].astype(np.float64) for i in idx]
            p1 = [x1[i].astype(np.float64) for i in idx]
            if decide("vf", p0, p1, thickness):
                must_vf.add((v, f))
            if decide("vf", p0, p1, thickness + band):
                may_vf.add((v, f))
    for i, ea in enumerate(edges):
        for eb in edges[i + 1:]:
            if len({*ea, *eb}) < 4 or not near(list(ea), list(eb)):
                continue
            idx = [*ea, *eb]
            p0 = [x0[k].astype(np.float64) for k in idx]
            p1 = [x1[k].astype(np.float64) for k in idx]
            row = (int(ea[0]), int(ea[1]), int(eb[0]), int(eb[1]))
            if decide("ee", p0, p1, thickness):
                must_ee.add(row)
            if decide("ee", p0, p1, thickness + band):
                may_ee.add(row)
    return must_vf, may_vf, must_ee, may_ee


def _check(result, reference):
    must_vf, may_vf, must_ee, may_ee = reference
    got_vf = {tuple(int(x) for x in r) for r in result.vertex_face}
    got_ee = {tuple(int(x) for x in r) for r in result.edge_edge}
    assert must_vf <= got_vf, f"missed vertex-face pairs {sorted(must_vf - got_vf)[:5]}"
    assert must_ee <= got_ee, f"missed edge-edge pairs {sorted(must_ee - got_ee)[:5]}"
    assert got_vf <= may_vf, f"reported pairs that are not near {sorted(got_vf - may_vf)[:5]}"
    assert got_ee <= may_ee, f"reported pairs that are not near {sorted(got_ee - may_ee)[:5]}"


def _crumpled(seed: int, n: int = 4, amplitude: float = 0.3):
    rng = np.random.default_rng(seed)
    vertices, faces, _ = grid_sheet(n, n)
    x0 = vertices.astype(np.float64)
    x0[:, 2] += rng.normal(0.0, amplitude * 0.2, len(x0))
    x1 = x0 + rng.normal(0.0, amplitude, x0.shape)
    return faces, x0.astype(np.float32), x1.astype(np.float32)


@settings(max_examples=4, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), thickness=st.sampled_from([0.0, 0.02]))
def test_ccd_matches_reference_on_crumpled_sheets(seed: int, thickness: float) -> None:
    faces, x0, x1 = _crumpled(seed)
    result = CollisionDetector(faces, method="brute-force").detect(x0, x1, thickness=thickness)
    _check(result, _reference(faces, x0, x1, thickness, band=BAND))
    assert result.vertex_face_toi.shape == (len(result.vertex_face),)
    assert np.all((result.vertex_face_toi >= 0) & (result.vertex_face_toi <= 1))


@settings(max_examples=4, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), thickness=st.sampled_from([0.0, 0.05, 0.2]))
def test_dcd_matches_reference_on_crumpled_sheets(seed: int, thickness: float) -> None:
    faces, x0, _ = _crumpled(seed, amplitude=1.0)
    result = CollisionDetector(faces, method="brute-force").detect(x0, thickness=thickness)
    assert result.vertex_face_toi is None and result.edge_edge_toi is None
    _check(result, _reference(faces, x0, x0, thickness, band=BAND))


def test_multi_object_ccd(device: str) -> None:
    a = folded_sheet(60, layers=2, seed=1)
    b = folded_sheet(60, layers=2, seed=2)
    offset = len(a.vertices)
    faces = np.concatenate([a.faces, b.faces + offset])
    object_ids = np.concatenate([np.zeros(len(a.faces)), np.ones(len(b.faces))]).astype(np.int32)
    x0 = np.concatenate([a.vertices, b.vertices + np.float32([0.05, 0.05, 0.3])])
    x1 = np.concatenate([a.vertices_end, b.vertices_end - np.float32([0.0, 0.0, 0.1])])
    det = CollisionDetector(faces, method="brute-force", object_ids=object_ids, device=device)
    result = det.detect(x0, x1)
    _check(result, _reference(faces, x0, x1, 0.0, band=BAND))
    inter = [r for r in result.vertex_face if (r[0] < offset) != (faces[r[1]][0] < offset)]
    assert len(inter) > 0, "the two objects should collide"


def test_degenerate_faces_and_non_manifold_edges(device: str) -> None:
    # Three faces share edge (0, 1); face 3 has zero area; a small falling triangle (6, 8, 9)
    # crosses all of them. Vertex 10 is isolated (used by no face) and takes no part.
    x0 = np.array([[0, 0, 0], [1, 0, 0], [0.5, 1, 0], [0.5, -1, 0], [0.5, 0, 1], [2, 0, 0],
                   [0.5, 0.2, 0.5], [3, 0, 0], [0.6, 0.25, 0.5], [0.55, 0.3, 0.5], [0.4, 0.4, 0.5]], np.float32)
    faces = np.array([[0, 1, 2], [0, 1, 3], [0, 1, 4], [1, 5, 7], [6, 8, 9]], np.int32)
    x1 = x0.copy()
    x1[[6, 8, 9, 10], 2] = -0.5
    result = CollisionDetector(faces, method="brute-force", device=device).detect(x0, x1)
    _check(result, _reference(faces, x0, x1, 0.0, band=BAND))
    pairs = {tuple(r) for r in result.vertex_face}
    assert (6, 0) in pairs
    assert not any(v == 10 for v, _ in pairs)


def test_repeated_calls_are_deterministic(device: str) -> None:
    sheet = folded_sheet(400, layers=3, seed=3)
    det = CollisionDetector(sheet.faces, method="brute-force", device=device)
    first = det.detect(sheet.vertices, sheet.vertices_end)
    second = det.detect(sheet.vertices, sheet.vertices_end)
    assert np.array_equal(first.vertex_face, second.vertex_face)
    assert np.array_equal(first.edge_edge, second.edge_edge)
    assert np.array_equal(first.vertex_face_toi, second.vertex_face_toi)
    assert first.stats["vertex_face_pairs"] + first.stats["edge_edge_pairs"] > 0
    assert set(first.stats["seconds"]) >= {"boxes", "broad_phase", "narrow_phase", "total"}
    assert first.stats["device_bytes"]["total"] > 0


def test_candidate_buffers_grow(device: str) -> None:
    # A thick DCD on a crumpled sheet overflows the initial candidate capacity (4 per face).
    faces, x0, _ = _crumpled(5, n=6, amplitude=1.0)
    det = CollisionDetector(faces, method="brute-force", device=device)
    result = det.detect(x0, thickness=0.5)
    assert det.candidates.vertex_face_count > 4 * len(faces)
    _check(result, _reference(faces, x0, x0, 0.5, band=BAND))


def test_rows_are_canonical(device: str) -> None:
    sheet = folded_sheet(300, layers=3, seed=4)
    detector = CollisionDetector(sheet.faces, method="brute-force", device=device)
    result = detector.detect(sheet.vertices, sheet.vertices_end)
    ee = result.edge_edge
    assert np.all(ee[:, 0] < ee[:, 1]) and np.all(ee[:, 2] < ee[:, 3])
    assert np.all((ee[:, 0] < ee[:, 2]) | ((ee[:, 0] == ee[:, 2]) & (ee[:, 1] < ee[:, 3])))
    for rows in (result.vertex_face, ee):
        assert np.array_equal(rows, rows[np.lexsort(rows.T[::-1])])


def test_bad_arguments() -> None:
    faces = np.array([[0, 1, 2]])
    with pytest.raises(InputError, match="method"):
        CollisionDetector(faces, method="octree")
    with pytest.raises(InputError, match="faces"):
        CollisionDetector(np.array([[0, 1, 2, 3]]))
    det = CollisionDetector(faces)
    with pytest.raises(InputError, match="thickness"):
        det.detect(np.zeros((3, 3)), thickness=-1)
    with pytest.raises(InputError, match="out of range|index"):
        CollisionDetector(np.array([[0, 1, 5]])).detect(np.zeros((3, 3)))
    det.detect(np.eye(3))
    with pytest.raises(InputError, match="positions"):
        det.detect(np.zeros((4, 3)))
