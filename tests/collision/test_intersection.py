"""Tests of the conservative segment-triangle test and of :class:`IntersectionCheck`.

Oracles:

* an **exact** segment-triangle predicate in Python integers (every float32 times 2**149 is an
  integer, so orientation signs, coplanarity and collinearity are decided without rounding);
* a float64 distance between segment and triangle (0 where the exact predicate says they meet),
  used to check that every pair reported without intersecting lies within its certified bound;
* ``ipctk.has_intersections`` (float64, exact orientation gate) on whole meshes.

The contract checked everywhere: no false negatives (exact intersection => reported), no false
certain crossing, and every near pair within its bound ``Delta`` (float64 distance <= Delta) with
``Delta <= NEAR_BOUND_CAP * L``.
"""

from __future__ import annotations

import ipctk
import numpy as np
import pytest
import warp as wp

from pscc.collision.intersection import IntersectionCheck
from pscc.errors import InputError
from pscc.geometry import segment_triangle as st
from pscc.mesh.generate import folded_sheet, grid_sheet

CAP = st.NEAR_BOUND_CAP
MISS, CROSSING, NEAR = (int(k) for k in st.SegmentTriangleKind)

# ------------------------------------------------------------------------------------------------
# Exact reference (Python integers)
# ------------------------------------------------------------------------------------------------

_SCALE = 2.0**149  # float32 * 2**149 is an integer, exactly representable in float64


def _to_exact(points: np.ndarray) -> list:
    """(n, k, 3) float32 -> nested tuples of exact Python ints."""
    scaled = np.asarray(points, dtype=np.float32).astype(np.float64) * _SCALE
    return [[tuple(int(v) for v in row) for row in query] for query in scaled]


def _sub(u, v):
    return (u[0] - v[0], u[1] - v[1], u[2] - v[2])


def _cross(u, v):
    return (u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2], u[0] * v[1] - u[1] * v[0])


def _orient(x, y, z, w) -> int:
    """Sign of det(y - x, z - x, w - x)."""
    u, n = _sub(y, x), _cross(_sub(z, x), _sub(w, x))
    det = u[0] * n[0] + u[1] * n[1] + u[2] * n[2]
    return (det > 0) - (det < 0)


def _orient2(a, b, c) -> int:
    det = (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0])
    return (det > 0) - (det < 0)


def _drop(u, k):
    return tuple(u[i] for i in range(3) if i != k)


def _in_box(p, a, b) -> bool:
    return all(min(a[i], b[i]) <= p[i] <= max(a[i], b[i]) for i in range(len(p)))


def _segments_2d(p, q, a, b) -> bool:
    """Closed 2-D segments meet."""
    d1, d2, d3, d4 = _orient2(a, b, p), _orient2(a, b, q), _orient2(p, q, a), _orient2(p, q, b)
    if d1 * d2 < 0 and d3 * d4 < 0:
        return True
    return ((d1 == 0 and _in_box(p, a, b)) or (d2 == 0 and _in_box(q, a, b))
            or (d3 == 0 and _in_box(a, p, q)) or (d4 == 0 and _in_box(b, p, q)))


def _point_on_segment(p, a, b) -> bool:
    return _cross(_sub(b, a), _sub(p, a)) == (0, 0, 0) and _in_box(p, a, b)


def _segments_3d(p, q, a, b) -> bool:
    """Closed 3-D segments meet."""
    if _orient(p, q, a, b) != 0:
        return False
    m = _cross(_sub(q, p), _sub(b, a))
    if m != (0, 0, 0):
        k = max(range(3), key=lambda i: abs(m[i]))
        return _segments_2d(_drop(p, k), _drop(q, k), _drop(a, k), _drop(b, k))
    return (_point_on_segment(p, a, b) or _point_on_segment(q, a, b)
            or _point_on_segment(a, p, q) or _point_on_segment(b, p, q))


def exact_intersects(p, q, a, b, c) -> bool:
    """Closed segment [p, q] meets closed triangle (a, b, c)."""
    sp, sq = _orient(a, b, c, p), _orient(a, b, c, q)
    if sp * sq > 0:
        return False
    n = _cross(_sub(b, a), _sub(c, a))
    if n == (0, 0, 0):  # zero-area triangle: the union of its edges
        return _segments_3d(p, q, a, b) or _segments_3d(p, q, b, c) or _segments_3d(p, q, c, a)
    if sp != 0 or sq != 0:  # the line pq crosses the plane once: Pluecker side tests
        w = (_orient(a, b, p, q), _orient(b, c, p, q), _orient(c, a, p, q))
        return not (1 in w and -1 in w)
    k = max(range(3), key=lambda i: abs(n[i]))  # coplanar: project along the normal's largest axis
    p2, q2, a2, b2, c2 = (_drop(v, k) for v in (p, q, a, b, c))
    for x in (p2, q2):
        s = (_orient2(a2, b2, x), _orient2(b2, c2, x), _orient2(c2, a2, x))
        if not (1 in s and -1 in s):
            return True
    return _segments_2d(p2, q2, a2, b2) or _segments_2d(p2, q2, b2, c2) or _segments_2d(p2, q2, c2, a2)


def exact_batch(points: np.ndarray) -> np.ndarray:
    """Exact predicate over an (n, 5, 3) float32 batch."""
    return np.array([exact_intersects(*query) for query in _to_exact(points)], dtype=bool)


# ------------------------------------------------------------------------------------------------
# Float64 distance reference
# ------------------------------------------------------------------------------------------------


def _dot(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    return np.einsum("...i,...i->...", u, v)


def _point_segment_sq(p, a, b):
    ab = b - a
    den = _dot(ab, ab)
    t = np.where(den > 0, np.clip(_dot(p - a, ab) / np.where(den > 0, den, 1.0), 0.0, 1.0), 0.0)
    r = p - a - t[..., None] * ab
    return _dot(r, r)


def _point_triangle(p, a, b, c):
    best = np.minimum.reduce([_point_segment_sq(p, a, b), _point_segment_sq(p, b, c), _point_segment_sq(p, c, a)])
    n = np.cross(b - a, c - a)
    nn = _dot(n, n)
    inside = ((nn > 0) & (_dot(n, np.cross(c - b, p - b)) >= 0) & (_dot(n, np.cross(a - c, p - c)) >= 0)
              & (_dot(n, np.cross(b - a, p - a)) >= 0))
    plane = _dot(n, p - a) ** 2 / np.where(nn > 0, nn, 1.0)
    return np.sqrt(np.where(inside, np.minimum(best, plane), best))


def _segment_segment(a0, a1, b0, b1):
    best = np.minimum.reduce([_point_segment_sq(a0, b0, b1), _point_segment_sq(a1, b0, b1),
                              _point_segment_sq(b0, a0, a1), _point_segment_sq(b1, a0, a1)])
    ea, eb, r = a1 - a0, b1 - b0, a0 - b0
    n = np.cross(ea, eb)
    nn = _dot(n, n)
    safe = np.where(nn > 0, nn, 1.0)
    s, t = _dot(n, np.cross(eb, r)) / safe, _dot(n, np.cross(ea, r)) / safe
    inside = (nn > 0) & (s >= 0) & (s <= 1) & (t >= 0) & (t <= 1)
    return np.sqrt(np.where(inside, np.minimum(best, _dot(r, n) ** 2 / safe), best))


def distance64(points: np.ndarray, exact: np.ndarray) -> np.ndarray:
    """Segment-triangle distance in float64, 0 where ``exact`` says they meet."""
    P = np.asarray(points, dtype=np.float32).astype(np.float64)
    p, q, a, b, c = (P[:, i] for i in range(5))
    d = np.minimum.reduce([_point_triangle(p, a, b, c), _point_triangle(q, a, b, c), _segment_segment(p, q, a, b),
                           _segment_segment(p, q, b, c), _segment_segment(p, q, c, a)])
    return np.where(exact, 0.0, d)


def spread(points: np.ndarray) -> np.ndarray:
    """L: the largest coordinate spread of the five points of each query."""
    P = np.asarray(points, dtype=np.float32).astype(np.float64)
    return (P.max(axis=1) - P.min(axis=1)).max(axis=1)


def check_contract(points: np.ndarray, kinds: np.ndarray, bounds: np.ndarray) -> dict[str, int]:
    """Assert the conservative contract for a batch; return counts for further checks."""
    points = np.asarray(points, dtype=np.float32)
    exact = exact_batch(points)
    missed = exact & (kinds == MISS)
    assert not missed.any(), f"{missed.sum()} false negatives, first {points[np.argmax(missed)].tolist()}"
    wrong = (kinds == CROSSING) & ~exact
    assert not wrong.any(), f"{wrong.sum()} false certain crossings, first {points[np.argmax(wrong)].tolist()}"
    near = kinds == NEAR
    d64 = distance64(points, exact)
    L = spread(points)
    # The float64 distance itself carries ~1e-15 L of rounding.
    over = near & (d64 > bounds.astype(np.float64) + 1e-12 * L)
    assert not over.any(), f"{over.sum()} near pairs beyond their bound, first {points[np.argmax(over)].tolist()}"
    assert np.all(bounds[near] <= CAP * L[near]), f"bound / L up to {(bounds[near] / L[near]).max():.3g}"
    assert np.all(bounds[kinds == CROSSING] == 0) and np.all(bounds[kinds == MISS] < 0)
    return {"exact": int(exact.sum()), "near": int(near.sum()), "false_near": int((near & ~exact).sum())}


# ------------------------------------------------------------------------------------------------
# Query generators
# ------------------------------------------------------------------------------------------------


def _place(local: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Random rotation, scale 1e-3..1e3 and offset up to 1e3 of (n, 5, 3) local queries, as float32."""
    n = local.shape[0]
    rotation, _ = np.linalg.qr(rng.normal(size=(n, 3, 3)))
    scale = 10.0 ** rng.uniform(-3, 3, size=(n, 1, 1))
    offset = rng.uniform(-1, 1, size=(n, 1, 3)) * 10.0 ** rng.uniform(-2, 3, size=(n, 1, 1))
    return (np.einsum("nij,nkj->nki", rotation, local) * scale + offset).astype(np.float32)


def _generic(rng: np.random.Generator, n: int) -> np.ndarray:
    return _place(rng.uniform(-1, 1, size=(n, 5, 3)), rng)


def _touching(rng: np.random.Generator, n: int, where: str) -> np.ndarray:
    """Segments through or ending at a point of the face interior, an edge or a vertex, then moved
    off the plane by 0 or +-1e-8 .. 1e-3 (so rounding lands on both sides of touching)."""
    tri = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], float) + rng.normal(scale=0.2, size=(n, 3, 3)) * [1, 1, 0]
    weights = rng.dirichlet([1, 1, 1], size=n)
    if where == "edge":
        weights[:, 2] = 0
        weights /= weights.sum(axis=1, keepdims=True)
    elif where == "vertex":
        weights = np.eye(3)[rng.integers(0, 3, n)]
    x = np.einsum("ni,nij->nj", weights, tri)
    eps = rng.choice([0, 1e-8, 1e-7, 1e-6, 1e-5, 1e-4, 1e-3], size=n) * rng.choice([-1, 1], size=n)
    direction = rng.normal(size=(n, 3))
    direction /= np.linalg.norm(direction, axis=1, keepdims=True)
    before = np.where(rng.random(n) < 0.5, rng.uniform(0.1, 0.9, n), 0.0)  # 0: the segment ends at x
    p = x - before[:, None] * direction + eps[:, None] * [0, 0, 1]
    return _place(np.concatenate([p[:, None], (p + direction)[:, None], tri], axis=1), rng)


def _grazing(rng: np.random.Generator, n: int) -> np.ndarray:
    """Segments nearly in the plane and nearly parallel to an edge, just inside or outside it:
    the configurations float32 determinants resolve worst."""
    tz = 10.0 ** rng.uniform(-8, -1, n)
    offset = 10.0 ** rng.uniform(-7, -1, n) * rng.choice([-1, 1], size=n)
    ty = 10.0 ** rng.uniform(-8, -1, n) * rng.choice([-1, 0, 1], size=n)
    s0 = rng.uniform(-0.5, 0.5, n)
    p = np.stack([s0, offset - 0.5 * ty, -0.5 * tz], axis=1)
    q = np.stack([s0 + 1.0, offset + 0.5 * ty, 0.5 * tz], axis=1)
    tri = np.zeros((n, 3, 3))
    tri[:, 0] = [-0.2, 0, 0]
    tri[:, 1] = [1.2, 0, 0]
    tri[:, 2] = np.stack([np.full(n, 0.5), rng.uniform(0.01, 1, n), np.zeros(n)], axis=1)
    return _place(np.concatenate([p[:, None], q[:, None], tri], axis=1), rng)


def _near_coplanar(rng: np.random.Generator, n: int) -> np.ndarray:
    """All five points within 1e-9 .. 1e-2 of a plane; every other triangle is thin."""
    local = rng.uniform(-1, 1, size=(n, 5, 3))
    local[..., 2] *= 10.0 ** rng.uniform(-9, -2, size=(n, 1))
    thin = rng.random(n) < 0.5
    local[thin, 4] = (local[thin, 2] + (local[thin, 3] - local[thin, 2]) * rng.uniform(0, 1, (thin.sum(), 1))
                      + rng.normal(size=(thin.sum(), 3)) * 10.0 ** rng.uniform(-8, -1, (thin.sum(), 1)))
    return _place(local, rng)


def _lattice(rng: np.random.Generator, n: int) -> np.ndarray:
    """Small-integer coordinates, scaled by a power of two and shifted by an exact dyadic offset:
    exact coplanarity, collinearity, shared points and zero-area triangles are common."""
    local = rng.integers(-2, 3, size=(n, 5, 3)).astype(np.float64)
    flat = rng.random(n) < 0.5
    local[flat, :, 2] = 0.0
    scale = 2.0 ** rng.integers(-10, 10, size=(n, 1, 1))
    offset = rng.integers(-64, 64, size=(n, 1, 3)) * 2.0 ** rng.integers(-6, 2, size=(n, 1, 1))
    return (local * scale + offset).astype(np.float32)


GENERATORS = {
    "generic": _generic,
    "touch_face": lambda rng, n: _touching(rng, n, "face"),
    "touch_edge": lambda rng, n: _touching(rng, n, "edge"),
    "touch_vertex": lambda rng, n: _touching(rng, n, "vertex"),
    "grazing": _grazing,
    "near_coplanar": _near_coplanar,
    "lattice": _lattice,
}


# ------------------------------------------------------------------------------------------------
# Segment-triangle primitive
# ------------------------------------------------------------------------------------------------

TRI = [[0, 0, 0], [1, 0, 0], [0, 1, 0]]

NAMED_CASES = {
    # name: ([p, q, a, b, c], expected kind)
    "proper_crossing": ([[0.25, 0.25, -1], [0.25, 0.25, 1], *TRI], CROSSING),
    "above_parallel": ([[0.1, 0.1, 0.2], [0.5, 0.1, 0.2], *TRI], MISS),
    "beside_crossing_plane": ([[2, 2, -1], [2, 2, 1], *TRI], MISS),
    "same_side": ([[0.2, 0.2, 0.5], [0.3, 0.1, 2], *TRI], MISS),
    "through_vertex": ([[1, 0, -1], [1, 0, 1], *TRI], NEAR),
    "through_edge_point": ([[0.5, 0, -1], [0.5, 0, 1], *TRI], NEAR),
    "endpoint_on_face": ([[0.25, 0.25, 0], [0.25, 0.25, 1], *TRI], NEAR),
    "endpoint_on_vertex": ([[0, 1, 0], [-1, 2, 3], *TRI], NEAR),
    "along_edge_coplanar": ([[0.25, 0, 0], [0.75, 0, 0], *TRI], NEAR),
    "overlapping_edge_coplanar": ([[-1, 0, 0], [2, 0, 0], *TRI], NEAR),
    "in_plane_inside": ([[0.1, 0.1, 0], [0.3, 0.2, 0], *TRI], NEAR),
    "in_plane_across": ([[-1, 0.25, 0], [2, 0.25, 0], *TRI], NEAR),
    "in_plane_outside": ([[1, 1, 0], [2, 0.5, 0], *TRI], MISS),
    "in_plane_parallel_to_edge": ([[0, -0.25, 0], [1, -0.25, 0], *TRI], MISS),
    "collinear_with_edge_apart": ([[2, 0, 0], [3, 0, 0], *TRI], MISS),
    "zero_area_crossed": ([[0.5, -1, 0], [0.5, 1, 0], [0, 0, 0], [1, 0, 0], [3, 0, 0]], NEAR),
    "zero_area_crossed_off_plane": ([[0.5, 0, -1], [0.5, 0, 1], [0, 0, 0], [1, 0, 0], [3, 0, 0]], NEAR),
    "zero_area_missed": ([[0.5, 0.5, -1], [0.5, 0.5, 1], [0, 0, 0], [1, 0, 0], [3, 0, 0]], MISS),
    "coincident_face_on_segment": ([[0, 0, 0], [2, 2, 2], [1, 1, 1], [1, 1, 1], [1, 1, 1]], NEAR),
    "coincident_face_off_segment": ([[0, 0, 0], [2, 2, 2], [1, 1, 2], [1, 1, 2], [1, 1, 2]], MISS),
    "zero_length_on_face": ([[0.2, 0.2, 0], [0.2, 0.2, 0], *TRI], NEAR),
    "zero_length_above": ([[0.2, 0.2, 0.1], [0.2, 0.2, 0.1], *TRI], MISS),
    "gap_1e-3_above_face": ([[0.25, 0.25, 1e-3], [0.25, 0.25, 1], *TRI], MISS),
    "gap_1e-3_beside_edge": ([[0.5, -1e-3, -1], [0.5, -1e-3, 1], *TRI], MISS),
}


@pytest.mark.parametrize("name", sorted(NAMED_CASES))
def test_named_cases(name: str, device: str) -> None:
    points, expected = NAMED_CASES[name]
    batch = np.array([points], dtype=np.float32)
    kinds, bounds = st.segment_triangle_intersections(batch, device=device)
    assert kinds[0] == expected
    assert exact_batch(batch)[0] == (expected != MISS)  # the reference agrees with the intent
    check_contract(batch, kinds, bounds)
    if expected == NEAR:  # touching configurations: bound at the float32 noise level
        assert bounds[0] <= 1e-5 * spread(batch)[0]


def test_named_cases_transformed(device: str) -> None:
    """The named cases, rotated, scaled and shifted (rounding breaks the exact degeneracies)."""
    rng = np.random.default_rng(7)
    base = np.array([case[0] for case in NAMED_CASES.values()], dtype=np.float64)
    batch = _place(np.repeat(base, 40, axis=0), rng)
    kinds, bounds = st.segment_triangle_intersections(batch, device=device)
    check_contract(batch, kinds, bounds)
    # Far configurations stay misses after the transform.
    far = np.array([name.startswith(("beside", "same_side", "above_parallel", "gap_", "in_plane_outside"))
                    for name in NAMED_CASES])
    assert np.all(kinds[np.repeat(far, 40)] == MISS)


@pytest.mark.parametrize("generator", sorted(GENERATORS))
def test_random_queries_against_exact_reference(generator: str, device: str) -> None:
    rng = np.random.default_rng(sorted(GENERATORS).index(generator))
    batch = GENERATORS[generator](rng, 10000)
    kinds, bounds = st.segment_triangle_intersections(batch, device=device)
    counts = check_contract(batch, kinds, bounds)
    # Each family exercises what it is meant to: both outcomes occur, and the hard families
    # really produce undecided pairs.
    assert 0 < counts["exact"] < len(batch)
    if generator in ("touch_face", "touch_edge", "touch_vertex", "grazing", "lattice"):
        assert counts["near"] > 0
    if generator == "generic":  # well-separated input is decided by the signs alone
        assert counts["near"] <= 0.01 * len(batch)


def test_batch_input_errors() -> None:
    with pytest.raises(InputError):
        st.segment_triangle_intersections(np.zeros((3, 4, 3)))
    bad = np.zeros((1, 5, 3))
    bad[0, 2, 1] = np.nan
    with pytest.raises(InputError):
        st.segment_triangle_intersections(bad)
    kinds, bounds = st.segment_triangle_intersections(np.zeros((0, 5, 3)))
    assert kinds.shape == bounds.shape == (0,)


# ------------------------------------------------------------------------------------------------
# IntersectionCheck
# ------------------------------------------------------------------------------------------------


def ipctk_has_intersections(vertices: np.ndarray, faces: np.ndarray) -> bool:
    faces = np.asarray(faces, dtype=np.int32)
    V = np.asarray(vertices, dtype=np.float32).astype(np.float64)
    return bool(ipctk.has_intersections(ipctk.CollisionMesh(V, ipctk.edges(faces), faces), V))


def _pair_points(vertices: np.ndarray, edges: np.ndarray, faces: np.ndarray, pairs: np.ndarray) -> np.ndarray:
    V = np.asarray(vertices, dtype=np.float32)
    return np.concatenate([V[edges[pairs[:, 0]]], V[faces[pairs[:, 1]]]], axis=1)


def reference_pairs(vertices: np.ndarray, faces: np.ndarray, edges: np.ndarray) -> np.ndarray:
    """Brute force: every (edge, face) pair without a shared vertex that exactly intersects, sorted."""
    V = np.asarray(vertices, dtype=np.float32)
    face_lower, face_upper = V[faces].min(axis=1), V[faces].max(axis=1)
    edge_lower, edge_upper = V[edges].min(axis=1), V[edges].max(axis=1)
    candidates = []
    for start in range(0, len(edges), 256):
        e = slice(start, start + 256)
        overlap = np.all((edge_lower[e, None] <= face_upper[None]) & (face_lower[None] <= edge_upper[e, None]), axis=2)
        shared = (edges[e, None, :, None] == faces[None, :, None, :]).any(axis=(2, 3))
        ei, fi = np.nonzero(overlap & ~shared)
        candidates.append(np.stack([ei + start, fi], axis=1))
    cand = np.concatenate(candidates).astype(np.int64)
    if len(cand) == 0:
        return np.zeros((0, 2), dtype=np.int32)
    hit = exact_batch(_pair_points(V, edges, faces, cand))
    return cand[hit].astype(np.int32)


def check_mesh(check: IntersectionCheck, vertices: np.ndarray, faces: np.ndarray,
               reference: bool = True) -> tuple[np.ndarray, np.ndarray | None]:
    """find() against the contract: ipctk => reported; exact pairs reported; extras within bounds."""
    any_hit = check.has_intersections(vertices)
    found = check.find(vertices)
    assert any_hit == (len(found) > 0)
    kinds, bounds = check.details()
    edges = check.edge_vertices
    assert found.dtype == np.int32 and found.shape[1] == 2
    assert len(np.unique(found, axis=0)) == len(found)  # each pair once
    assert np.array_equal(found, found[np.lexsort((found[:, 1], found[:, 0]))])  # sorted
    assert not (edges[found[:, 0], :, None] == faces[found[:, 1], None, :]).any()  # no shared vertex
    points = _pair_points(vertices, edges, faces, found)
    check_contract(points, kinds, bounds)
    if ipctk_has_intersections(vertices, faces):
        assert len(found) > 0, "ipctk finds an intersection that was not reported"
    expected = None
    if reference:
        expected = reference_pairs(vertices, faces, edges)
        # Every exact intersection is reported; everything else reported is a near pair (checked above).
        reported = {tuple(row) for row in found.tolist()}
        missing = [tuple(row) for row in expected.tolist() if tuple(row) not in reported]
        assert not missing, f"{len(missing)} exact intersections not reported, e.g. {missing[:3]}"
    return found, expected


def _crumpled(nx: int, amplitude: float, seed: int) -> tuple[np.ndarray, np.ndarray]:
    vertices, faces, _ = grid_sheet(nx, nx)
    rng = np.random.default_rng(seed)
    h = 1.0 / nx
    shaken = vertices + rng.normal(scale=amplitude * h, size=vertices.shape)
    return shaken.astype(np.float32), faces


def test_flat_sheet_reports_nothing(device: str) -> None:
    """Exactly coplanar neighbours (the rest state of cloth) are not intersections, in any plane."""
    vertices, faces, _ = grid_sheet(16, 16)
    check = IntersectionCheck(faces, len(vertices), device)
    assert check.find(vertices).shape == (0, 2)
    assert check.stats.face_pairs > 0
    rng = np.random.default_rng(3)
    rotation, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    tilted = (vertices.astype(np.float64) @ rotation.T * 7.0 + [100.0, -3.0, 0.5]).astype(np.float32)
    assert check.find(tilted).shape == (0, 2)
    assert not ipctk_has_intersections(tilted, faces)


@pytest.mark.parametrize("seed", [0, 1, 2, 3])
def test_crumpled_sheets_against_ipctk_and_brute_force(seed: int, device: str) -> None:
    nx = 10
    vertices, faces, _ = grid_sheet(nx, nx)
    check = IntersectionCheck(faces, len(vertices), device)
    # Lightly shaken: no intersection, and nothing near one.
    light, _ = _crumpled(nx, 0.05, seed)
    found, expected = check_mesh(check, light, faces)
    assert len(found) == 0 and len(expected) == 0
    assert not ipctk_has_intersections(light, faces)
    # Moderately shaken: a few intersections or none, many close calls.
    medium, _ = _crumpled(nx, 0.35, seed)
    check_mesh(check, medium, faces)
    # Heavily shaken (out of plane too): intersecting.
    heavy, _ = _crumpled(nx, 0.8, seed)
    found, expected = check_mesh(check, heavy, faces)
    assert len(expected) > 0 and ipctk_has_intersections(heavy, faces)
    assert check.stats.crossings > 0


@pytest.mark.parametrize(("gap", "touching"), [(1e-4, False), (0.0, True)])
def test_stacked_sheets(gap: float, touching: bool, device: str) -> None:
    """Two sheets shifted in-plane, a tiny gap apart (nothing) or coplanar (overlapping: reported)."""
    v0, f0, _ = grid_sheet(8, 8)
    v1 = v0 + np.array([0.3 / 8, 0.45 / 8, gap], dtype=np.float32)
    vertices = np.concatenate([v0, v1]).astype(np.float32)
    faces = np.concatenate([f0, f0 + len(v0)])
    check = IntersectionCheck(faces, len(vertices), device)
    found, expected = check_mesh(check, vertices, faces)
    assert (len(expected) > 0) == touching
    assert (len(found) > 0) == touching
    if not touching:
        assert not ipctk_has_intersections(vertices, faces)


def test_two_interpenetrating_sheets(device: str) -> None:
    v0, f0, _ = grid_sheet(8, 8)
    v1 = v0.copy()
    v1[:, 2] = 0.6 * (v1[:, 0] - 0.5) + 0.013  # tilted sheet cutting through the first
    v1[:, 1] += 0.031
    vertices = np.concatenate([v0, v1]).astype(np.float32)
    faces = np.concatenate([f0, f0 + len(v0)])
    objects = np.repeat([0, 1], len(f0))
    check = IntersectionCheck(faces, len(vertices), device, object_ids=objects)
    found, expected = check_mesh(check, vertices, faces)
    assert ipctk_has_intersections(vertices, faces) and len(expected) > 0
    np.testing.assert_array_equal(check.object_pairs(found), [[0, 1]])
    # Lifted clear of the first sheet: nothing.
    apart = vertices.copy()
    apart[len(v0):, 2] += 1.0
    found, expected = check_mesh(check, apart, faces)
    assert len(found) == 0 and not ipctk_has_intersections(apart, faces)


@pytest.mark.parametrize("seed", [0, 1])
def test_folded_sheet(seed: int, device: str) -> None:
    mesh = folded_sheet(2000, layers=3, seed=seed)
    check = IntersectionCheck(mesh.faces, mesh.vertex_count, device)
    found, expected = check_mesh(check, mesh.vertices, mesh.faces)
    assert len(found) == 0 and len(expected) == 0
    assert not ipctk_has_intersections(mesh.vertices, mesh.faces)
    found, expected = check_mesh(check, mesh.vertices_end, mesh.faces)
    assert len(expected) > 0 and ipctk_has_intersections(mesh.vertices_end, mesh.faces)


def _tetrahedron(apex_z: float) -> tuple[np.ndarray, np.ndarray]:
    base = [[0.3, 0.3, 0.4], [0.7, 0.35, 0.4], [0.45, 0.7, 0.4]]
    vertices = np.array([*base, [0.49, 0.46, apex_z]], dtype=np.float32)
    faces = np.array([[0, 2, 1], [0, 1, 3], [1, 2, 3], [2, 0, 3]], dtype=np.int32)
    return vertices, faces


@pytest.mark.parametrize(("apex_z", "pierced"), [(-0.3, True), (0.0, True), (0.1, False)])
def test_sheet_pierced_by_tetrahedron(apex_z: float, pierced: bool, device: str) -> None:
    """Apex below the sheet (pierced), exactly on it (touching: reported), above it (clear)."""
    sheet, sheet_faces, _ = grid_sheet(12, 12)
    tet, tet_faces = _tetrahedron(apex_z)
    vertices = np.concatenate([sheet, tet]).astype(np.float32)
    faces = np.concatenate([sheet_faces, tet_faces + len(sheet)])
    objects = np.repeat([0, 1], [len(sheet_faces), len(tet_faces)])
    check = IntersectionCheck(faces, len(vertices), device, object_ids=objects)
    found, expected = check_mesh(check, vertices, faces)
    assert (len(expected) > 0) == pierced
    assert (len(found) > 0) == pierced
    if pierced:
        np.testing.assert_array_equal(check.object_pairs(found), [[0, 1]])
    if apex_z < 0:
        assert ipctk_has_intersections(vertices, faces)
        # Three tetrahedron edges pierce the sheet (one face each) and sheet edges cross the
        # three side faces of the tetrahedron.
        tet_edges = check.edge_vertices[found[:, 0]].min(axis=1) >= len(sheet)
        assert tet_edges.sum() == 3 and (~tet_edges).sum() > 0


def test_deterministic_and_capacity_growth(device: str) -> None:
    heavy, faces = _crumpled(12, 1.0, 5)
    check = IntersectionCheck(faces, len(heavy), device)
    first = check.find(heavy)
    kinds, bounds = (a.copy() for a in check.details())
    assert len(first) > 10
    np.testing.assert_array_equal(check.find(heavy), first)
    np.testing.assert_array_equal(check.details()[0], kinds)
    np.testing.assert_array_equal(check.details()[1], bounds)
    # A one-slot buffer grows to the exact count and re-runs: same result, nothing lost.
    small = IntersectionCheck(faces, len(heavy), device, hit_capacity=1)
    np.testing.assert_array_equal(small.find(heavy), first)
    assert small.stats.reruns == 1 and small.hit_capacity >= len(first)
    assert small.stats.hits == len(first) == small.stats.crossings + small.stats.near
    # Positions already on the device give the same answer.
    on_device = wp.array(heavy, dtype=wp.vec3, device=device)
    np.testing.assert_array_equal(small.find(on_device), first)


def test_small_meshes_and_input_errors(device: str) -> None:
    one = IntersectionCheck(np.array([[0, 1, 2]]), 3, device)
    assert one.find(np.eye(3)).shape == (0, 2) and not one.has_intersections(np.eye(3))
    vertices, faces, _ = grid_sheet(2, 2)
    check = IntersectionCheck(faces, len(vertices), device)
    with pytest.raises(InputError):
        check.find(vertices[:-1])
    bad = vertices.copy()
    bad[0, 0] = np.inf
    with pytest.raises(InputError):
        check.find(bad)
    with pytest.raises(InputError):
        check.find(wp.zeros(3, dtype=wp.vec3, device=device))
    with pytest.raises(InputError):
        IntersectionCheck(np.array([[0, 1, 1]]), 3, device)
    with pytest.raises(InputError):
        IntersectionCheck(faces, len(vertices), device, object_ids=np.zeros(3))
    with pytest.raises(InputError):
        IntersectionCheck(faces, -1, device)
