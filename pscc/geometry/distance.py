"""Discrete collision detection (DCD) distance primitives in float32 on the device.

Two primitive pairs are supported:

* vertex-face: the closest point of triangle ``(a, b, c)`` to a point ``p``, as barycentric
  weights ``(w0, w1, w2)`` with ``w0 + w1 + w2 = 1`` and all ``w >= 0``;
* edge-edge: the closest points ``a0 + s (a1 - a0)`` and ``b0 + t (b1 - b0)`` of two segments,
  as parameters ``(s, t)`` in ``[0, 1]^2``.

The ``@wp.func`` functions (:func:`vertex_face_closest_point`, :func:`vertex_face_distance_squared`,
:func:`edge_edge_closest_point`, :func:`edge_edge_distance_squared`) are meant to be called from
other kernels. The host functions (:func:`vertex_face_distance`, :func:`edge_edge_distance`,
:func:`vertex_face_closest_points`, :func:`edge_edge_closest_points`) evaluate a batch of
queries with one thread per query.

Method. Every query is first shifted to its anchor (``a`` or ``a0``) and scaled by ``1 / L``,
``L`` being the largest absolute coordinate difference between the anchor and the other three
points, so the arithmetic is translation- and scale-invariant: the host functions are accurate
for ``1e-30 <= L <= 1e36`` and the squared ``@wp.func`` distances for about
``1e-18 <= L <= 1e18`` (where the square stays a normal float32). Regular triangles use the
Voronoi-region method (vertex, edge and face regions decided by dot products), with the signed
face weights written in the Lagrange form ``(ab x ac) . (ab x ap)`` instead of the usual
products of dot products, which squares the condition number of thin triangles. Triangles of
flatness ``|ab x ac|^2 / max_edge^4`` at most
:data:`~pscc.geometry.distance_tolerances.TRIANGLE_DEGENERATE_REL_SQ` (collinear or coincident
vertices) are treated as their three edges, and zero-length edges as points. Edge pairs use the
line-line solution written with cross products, clamped to ``[0, 1]`` and then re-optimised
one parameter at a time; parallel pairs start from ``s = 0``, which still finds a minimising
pair. Every division is guarded, so input with finite coordinates never yields NaN or Inf.

Float32 error bound. Let ``d_exact`` be the exact distance between the float32 input points
(rounding float64 input to float32 is the caller's and comes on top) and ``L`` the largest
absolute coordinate difference among the four points (the local scale, independent of where
the query sits in space). For well-shaped queries::

    |d_float32 - d_exact| <= C * EPS32 * L,    C = 16,  EPS32 = 2**-23 ~ 1.19e-7

Well-shaped means a triangle flatness of at least
:data:`~pscc.geometry.distance_tolerances.WELL_SHAPED_MIN_FLATNESS` (``1e-2``: smallest height
about 10 % of the longest edge) or exactly zero area; every edge pair qualifies. Derivation:
after the shift, every quantity has size ``L`` (or a power of it), the weights come from a few
dot and cross products, each rounding with relative error ``EPS32 / 2``, and the distance is
the length of ``p - closest`` formed from shifted coordinates, so ``C`` is a few units for a
well-conditioned closest point. Measured over 7e7 random queries of each kind (boxes of size
``1e-3 .. 1e3`` at offsets up to ``1e3``, points near the face or near crossing, thin
triangles, near-parallel edges, integer-grid degeneracies, repeated coordinates): at most
``3.7 * EPS32 * L`` (vertex-face) and ``3.3 * EPS32 * L`` (edge-edge).

Ill-conditioned input. For nearly flat triangles the closest point, not the distance, is
ill-conditioned. The computed weights are always a convex combination, so the computed closest
point is a point of the triangle up to rounding and the computed distance is never below
``d_exact - C * EPS32 * L`` (measured: at most ``2.4 * EPS32 * L`` below). It can be too large,
by about ``0.4 * EPS32 * L / sqrt(flatness)``, up to about ``sqrt(EPS32) * L ~ 3.5e-4 * L``
near the zero-area threshold; the worst measured is ``2.9e-4 * L``
(:data:`~pscc.geometry.distance_tolerances.ILL_CONDITIONED_REL_ERROR` bounds it by ``1e-3 * L``).
Edge pairs showed no such loss: the cross-product form keeps the bound down to parallel edges.
"""

from __future__ import annotations

import numpy as np
import warp as wp

from pscc._checks import check_points
from pscc.geometry import distance_tolerances as _tol

wp.set_module_options({"enable_backward": False})

__all__ = [
    "edge_edge_closest_point",
    "edge_edge_closest_points",
    "edge_edge_distance",
    "edge_edge_distance_squared",
    "projection_outside_triangle",
    "vertex_face_closest_point",
    "vertex_face_closest_points",
    "vertex_face_distance",
    "vertex_face_distance_squared",
]

_MIN_LOCAL_SCALE = wp.constant(wp.float32(_tol.MIN_LOCAL_SCALE))
_TRIANGLE_DEGENERATE_REL_SQ = wp.constant(wp.float32(_tol.TRIANGLE_DEGENERATE_REL_SQ))
_EDGE_DEGENERATE_REL_SQ = wp.constant(wp.float32(_tol.EDGE_DEGENERATE_REL_SQ))
_EDGE_PARALLEL_REL_SQ = wp.constant(wp.float32(_tol.EDGE_PARALLEL_REL_SQ))
_SIDE_ERROR_PER_NORMAL = wp.constant(wp.float32(_tol.PROJECTION_SIDE_ERROR_PER_NORMAL))
_SIDE_ERROR_BASE = wp.constant(wp.float32(_tol.PROJECTION_SIDE_ERROR_BASE))


# ------------------------------------------------------------------------------------------------
# Device helpers
# ------------------------------------------------------------------------------------------------


@wp.func
def _max_abs(v: wp.vec3) -> float:
    """Largest absolute component of ``v``."""
    return wp.max(wp.max(wp.abs(v[0]), wp.abs(v[1])), wp.abs(v[2]))


@wp.func
def _robust_length(v: wp.vec3) -> float:
    """Euclidean length of ``v`` without underflow or overflow of the squared components."""
    m = _max_abs(v)
    if m > 0.0:
        # Divide (not multiply by 1 / m): 1 / m overflows for subnormal m.
        return m * wp.length(v / m)
    return 0.0


@wp.func
def _clamped_ratio(num: float, den: float) -> float:
    """``clamp(num / den, 0, 1)``, or 0 when ``den`` is not positive."""
    if den > 0.0:
        return wp.clamp(num / den, 0.0, 1.0)
    return 0.0


@wp.func
def _segment_param(ap: wp.vec3, ab: wp.vec3) -> float:
    """Parameter in [0, 1] of the point of segment ``a + t ab`` closest to ``a + ap``."""
    return _clamped_ratio(wp.dot(ap, ab), wp.dot(ab, ab))


@wp.func
def _triangle_edges_closest_point(ap: wp.vec3, ab: wp.vec3, ac: wp.vec3) -> wp.vec3:
    """Barycentric weights of the closest point to ``p`` over the three edges of a triangle.

    Coordinates are relative to vertex ``a``. Used for zero-area triangles.
    """
    t_ab = _segment_param(ap, ab)
    r_ab = ap - t_ab * ab
    best = wp.dot(r_ab, r_ab)
    weights = wp.vec3(1.0 - t_ab, t_ab, 0.0)

    bp = ap - ab
    bc = ac - ab
    t_bc = _segment_param(bp, bc)
    r_bc = bp - t_bc * bc
    d_bc = wp.dot(r_bc, r_bc)
    if d_bc < best:
        best = d_bc
        weights = wp.vec3(0.0, 1.0 - t_bc, t_bc)

    cp = ap - ac
    t_ca = _segment_param(cp, -ac)
    r_ca = cp + t_ca * ac
    d_ca = wp.dot(r_ca, r_ca)
    if d_ca < best:
        weights = wp.vec3(t_ca, 0.0, 1.0 - t_ca)
    return weights


@wp.func
def _triangle_voronoi_closest_point(
    ap: wp.vec3, ab: wp.vec3, ac: wp.vec3, bc: wp.vec3, n: wp.vec3
) -> wp.vec3:
    """Barycentric weights of the closest point of a regular triangle, by Voronoi regions.

    Coordinates are relative to vertex ``a``; ``bc = ac - ab`` and ``n = ab x ac``. The region
    tests of the edges use the signed face weights in the Lagrange form ``n . (ab x ap)`` (equal
    to the usual ``d1 d4 - d3 d2`` products of dot products, but with error ``EPS32 / sin`` rather
    than ``EPS32 / sin^2`` for a triangle of flatness ``sin^2``). Falls back to the edge method if
    rounding makes the face region empty.
    """
    # Vertex a.
    d1 = wp.dot(ab, ap)
    d2 = wp.dot(ac, ap)
    if d1 <= 0.0 and d2 <= 0.0:
        return wp.vec3(1.0, 0.0, 0.0)

    # Vertex b.
    bp = ap - ab
    d3 = wp.dot(ab, bp)
    e3 = wp.dot(bc, bp)
    if d3 >= 0.0 and e3 <= 0.0:
        return wp.vec3(0.0, 1.0, 0.0)

    # Edge ab: outside the face across ab (vc <= 0) and between the vertex regions of a and b.
    vc = wp.dot(n, wp.cross(ab, ap))
    if vc <= 0.0 and d1 >= 0.0 and d3 <= 0.0:
        v = _clamped_ratio(d1, wp.dot(ab, ab))
        return wp.vec3(1.0 - v, v, 0.0)

    # Vertex c.
    cp = ap - ac
    d6 = wp.dot(ac, cp)
    e6 = wp.dot(bc, cp)
    if d6 >= 0.0 and e6 >= 0.0:
        return wp.vec3(0.0, 0.0, 1.0)

    # Edge ac.
    vb = wp.dot(n, wp.cross(ap, ac))
    if vb <= 0.0 and d2 >= 0.0 and d6 <= 0.0:
        w = _clamped_ratio(d2, wp.dot(ac, ac))
        return wp.vec3(1.0 - w, 0.0, w)

    # Edge bc.
    va = wp.dot(n, wp.cross(bc, bp))
    if va <= 0.0 and e3 >= 0.0 and e6 <= 0.0:
        w = _clamped_ratio(e3, wp.dot(bc, bc))
        return wp.vec3(0.0, 1.0 - w, w)

    # Face region. Rounding can leave a weight slightly negative; clamp and renormalise.
    va = wp.max(va, 0.0)
    vb = wp.max(vb, 0.0)
    vc = wp.max(vc, 0.0)
    total = va + vb + vc
    if total > 0.0:
        return wp.vec3(va / total, vb / total, vc / total)
    return _triangle_edges_closest_point(ap, ab, ac)


@wp.func
def _vertex_face_offset(p: wp.vec3, a: wp.vec3, b: wp.vec3, c: wp.vec3, w: wp.vec3) -> wp.vec3:
    """Vector from the closest point (barycentric weights ``w``) to ``p``."""
    return (p - a) - (w[1] * (b - a) + w[2] * (c - a))


@wp.func
def _edge_edge_offset(a0: wp.vec3, a1: wp.vec3, b0: wp.vec3, b1: wp.vec3, st: wp.vec2) -> wp.vec3:
    """Vector between the closest points ``b0 + t (b1 - b0)`` and ``a0 + s (a1 - a0)``."""
    return (a0 - b0) + st[0] * (a1 - a0) - st[1] * (b1 - b0)


# ------------------------------------------------------------------------------------------------
# Public device functions
# ------------------------------------------------------------------------------------------------


@wp.func
def vertex_face_closest_point(p: wp.vec3, a: wp.vec3, b: wp.vec3, c: wp.vec3) -> wp.vec3:
    """Barycentric weights of the point of triangle ``(a, b, c)`` closest to ``p``.

    Robust for zero-area triangles (collinear or coincident vertices): they are treated as the
    union of their edges, and zero-length edges as points. Never returns NaN or Inf for finite
    input.

    Args:
        p: The query point.
        a: First triangle vertex.
        b: Second triangle vertex.
        c: Third triangle vertex.

    Returns:
        ``(w0, w1, w2)`` with ``w0 + w1 + w2 = 1`` (up to rounding) and all ``w >= 0``; the
        closest point is ``w0 a + w1 b + w2 c``.
    """
    ab = b - a
    ac = c - a
    ap = p - a
    scale = wp.max(wp.max(_max_abs(ab), _max_abs(ac)), _max_abs(ap))
    if not (scale > _MIN_LOCAL_SCALE):
        return wp.vec3(1.0, 0.0, 0.0)
    inv = 1.0 / scale
    ab = ab * inv
    ac = ac * inv
    ap = ap * inv

    n = wp.cross(ab, ac)
    area_sq = wp.dot(n, n)
    bc = ac - ab
    edge_sq = wp.max(wp.max(wp.dot(ab, ab), wp.dot(ac, ac)), wp.dot(bc, bc))
    if area_sq <= _TRIANGLE_DEGENERATE_REL_SQ * edge_sq * edge_sq:
        return _triangle_edges_closest_point(ap, ab, ac)
    return _triangle_voronoi_closest_point(ap, ab, ac, bc, n)


@wp.func
def vertex_face_distance_squared(p: wp.vec3, a: wp.vec3, b: wp.vec3, c: wp.vec3) -> float:
    """Squared distance from point ``p`` to triangle ``(a, b, c)``.

    Args:
        p: The query point.
        a: First triangle vertex.
        b: Second triangle vertex.
        c: Third triangle vertex.

    Returns:
        The squared Euclidean distance (length units squared).
    """
    return vertex_face_distance_squared_at(p, a, b, c, vertex_face_closest_point(p, a, b, c))


@wp.func
def vertex_face_distance_squared_at(p: wp.vec3, a: wp.vec3, b: wp.vec3, c: wp.vec3, w: wp.vec3) -> float:
    """Squared distance from ``p`` to the point of triangle ``(a, b, c)`` with barycentric weights ``w``
    (with ``w`` from :func:`vertex_face_closest_point`: :func:`vertex_face_distance_squared`, for callers
    that need the weights too)."""
    r = _vertex_face_offset(p, a, b, c, w)
    return wp.dot(r, r)


@wp.func
def edge_edge_closest_point(a0: wp.vec3, a1: wp.vec3, b0: wp.vec3, b1: wp.vec3) -> wp.vec2:
    """Parameters of the closest points of segments ``[a0, a1]`` and ``[b0, b1]``.

    Robust for parallel, collinear and zero-length edges (for parallel edges one minimising
    pair is returned). Never returns NaN or Inf for finite input.

    Args:
        a0: First endpoint of edge a.
        a1: Second endpoint of edge a.
        b0: First endpoint of edge b.
        b1: Second endpoint of edge b.

    Returns:
        ``(s, t)`` in ``[0, 1]^2``; the closest points are ``a0 + s (a1 - a0)`` and
        ``b0 + t (b1 - b0)``.
    """
    ea = a1 - a0
    eb = b1 - b0
    r = a0 - b0
    scale = wp.max(wp.max(_max_abs(ea), _max_abs(b0 - a0)), _max_abs(b1 - a0))
    if not (scale > _MIN_LOCAL_SCALE):
        return wp.vec2(0.0, 0.0)
    inv = 1.0 / scale
    ea = ea * inv
    eb = eb * inv
    r = r * inv

    aa = wp.dot(ea, ea)
    bb = wp.dot(eb, eb)
    a_short = aa <= _EDGE_DEGENERATE_REL_SQ
    b_short = bb <= _EDGE_DEGENERATE_REL_SQ
    if a_short and b_short:
        return wp.vec2(0.0, 0.0)
    if a_short:
        return wp.vec2(0.0, _clamped_ratio(wp.dot(eb, r), bb))
    ar = wp.dot(ea, r)
    if b_short:
        return wp.vec2(_clamped_ratio(-ar, aa), 0.0)

    # Line-line solution s = ((ea x eb) . (eb x r)) / |ea x eb|^2, clamped to [0, 1].
    n = wp.cross(ea, eb)
    nn = wp.dot(n, n)
    s = float(0.0)
    if nn > _EDGE_PARALLEL_REL_SQ * aa * bb:
        s = wp.clamp(wp.dot(n, wp.cross(eb, r)) / nn, 0.0, 1.0)
    # Best t for this s; if it leaves [0, 1], clamp it and take the best s for that t.
    ab = wp.dot(ea, eb)
    t = (ab * s + wp.dot(eb, r)) / bb
    if t < 0.0:
        t = 0.0
        s = _clamped_ratio(-ar, aa)
    elif t > 1.0:
        t = 1.0
        s = _clamped_ratio(ab - ar, aa)
    return wp.vec2(s, t)


@wp.func
def edge_edge_distance_squared(a0: wp.vec3, a1: wp.vec3, b0: wp.vec3, b1: wp.vec3) -> float:
    """Squared distance between segments ``[a0, a1]`` and ``[b0, b1]``.

    Args:
        a0: First endpoint of edge a.
        a1: Second endpoint of edge a.
        b0: First endpoint of edge b.
        b1: Second endpoint of edge b.

    Returns:
        The squared Euclidean distance (length units squared).
    """
    return edge_edge_distance_squared_at(a0, a1, b0, b1, edge_edge_closest_point(a0, a1, b0, b1))


@wp.func
def edge_edge_distance_squared_at(a0: wp.vec3, a1: wp.vec3, b0: wp.vec3, b1: wp.vec3, st: wp.vec2) -> float:
    """Squared distance between the points of parameters ``st`` on the two segments (with ``st`` from
    :func:`edge_edge_closest_point`: :func:`edge_edge_distance_squared`, for callers that need the
    parameters too)."""
    r = _edge_edge_offset(a0, a1, b0, b1, st)
    return wp.dot(r, r)


@wp.func
def _beyond_edge(n: wp.vec3, normal_max: float, edge: wp.vec3, offset: wp.vec3) -> bool:
    """Whether the signed face weight ``n . (edge x offset)`` is below minus its rounding bound
    (:data:`~pscc.geometry.distance_tolerances.PROJECTION_SIDE_ERROR_PER_NORMAL`), so that the point is
    certified on the outer side of the edge's line, in the triangle's plane. ``edge x offset`` is the edge
    vector crossed with the point's offset from one of the edge's ends (any cross product of equal value will
    do: for edge c -> a the caller passes ``(-ac) x ap``, equal to ``(a - c) x (p - c)``)."""
    bound = _max_abs(edge) * _max_abs(offset) * (_SIDE_ERROR_PER_NORMAL * normal_max + _SIDE_ERROR_BASE)
    return wp.dot(n, wp.cross(edge, offset)) < -bound


@wp.func
def projection_outside_triangle(p: wp.vec3, a: wp.vec3, b: wp.vec3, c: wp.vec3) -> bool:
    """Whether ``p``'s projection onto the plane of triangle ``(a, b, c)`` is certified to lie outside
    the triangle, so that the closest point of the triangle to ``p`` lies on one of its edges.

    Thin triangles make the closest point ill-conditioned, but not this side test: each edge's signed
    face weight ``n . (e x (p - v))`` (``n = ab x ac``; coordinates shifted to ``a`` and scaled by the
    local scale ``L``) must be below minus its rounding bound, which scales with the edge and the point's
    offset (:data:`~pscc.geometry.distance_tolerances.PROJECTION_SIDE_ERROR_PER_NORMAL`). The answer holds
    for the points as the shift and scale round them, each moved by at most ``2 sqrt(3) * 2**-24 * L``: a
    distance decided from it is off by at most twice that
    (:func:`pscc.collision.narrow_phase.vertex_face_proximity_toi`). ``False`` ("not certified", never a
    wrong ``True``) also for zero-area triangles and a zero local scale.
    """
    ab = b - a
    ac = c - a
    ap = p - a
    scale = wp.max(wp.max(_max_abs(ab), _max_abs(ac)), _max_abs(ap))
    if not (scale > _MIN_LOCAL_SCALE):
        return False
    inv = 1.0 / scale
    ab = ab * inv
    ac = ac * inv
    ap = ap * inv
    n = wp.cross(ab, ac)
    normal_max = _max_abs(n)
    if _beyond_edge(n, normal_max, ab, ap):
        return True
    # Edge c -> a: (a - c) x (p - c) = ap x ac = (-ac) x ap.
    if _beyond_edge(n, normal_max, -ac, ap):
        return True
    return _beyond_edge(n, normal_max, ac - ab, ap - ab)


# ------------------------------------------------------------------------------------------------
# Kernels
# ------------------------------------------------------------------------------------------------


@wp.kernel
def _vertex_face_distance_kernel(points: wp.array2d(dtype=wp.vec3), distances: wp.array(dtype=float)):
    """One thread per query i: distance from points[i, 0] to triangle points[i, 1:4]."""
    i = wp.tid()
    p = points[i, 0]
    a = points[i, 1]
    b = points[i, 2]
    c = points[i, 3]
    w = vertex_face_closest_point(p, a, b, c)
    distances[i] = _robust_length(_vertex_face_offset(p, a, b, c, w))


@wp.kernel
def _vertex_face_closest_point_kernel(
    points: wp.array2d(dtype=wp.vec3),
    distances: wp.array(dtype=float),
    weights: wp.array(dtype=wp.vec3),
):
    """One thread per query i: distance and closest-point weights for points[i]."""
    i = wp.tid()
    p = points[i, 0]
    a = points[i, 1]
    b = points[i, 2]
    c = points[i, 3]
    w = vertex_face_closest_point(p, a, b, c)
    distances[i] = _robust_length(_vertex_face_offset(p, a, b, c, w))
    weights[i] = w


@wp.kernel
def _edge_edge_distance_kernel(points: wp.array2d(dtype=wp.vec3), distances: wp.array(dtype=float)):
    """One thread per query i: distance between edges points[i, 0:2] and points[i, 2:4]."""
    i = wp.tid()
    a0 = points[i, 0]
    a1 = points[i, 1]
    b0 = points[i, 2]
    b1 = points[i, 3]
    st = edge_edge_closest_point(a0, a1, b0, b1)
    distances[i] = _robust_length(_edge_edge_offset(a0, a1, b0, b1, st))


@wp.kernel
def _edge_edge_closest_point_kernel(
    points: wp.array2d(dtype=wp.vec3),
    distances: wp.array(dtype=float),
    params: wp.array(dtype=wp.vec2),
):
    """One thread per query i: distance and closest-point parameters for points[i]."""
    i = wp.tid()
    a0 = points[i, 0]
    a1 = points[i, 1]
    b0 = points[i, 2]
    b1 = points[i, 3]
    st = edge_edge_closest_point(a0, a1, b0, b1)
    distances[i] = _robust_length(_edge_edge_offset(a0, a1, b0, b1, st))
    params[i] = st


# ------------------------------------------------------------------------------------------------
# Host wrappers
# ------------------------------------------------------------------------------------------------


def _upload(points: object, device: wp.DeviceLike) -> tuple[wp.array, int]:
    """Validate a (n, 4, 3) query batch and copy it to ``device`` as an (n, 4) vec3 array."""
    host = check_points(points, "points", shape_tail=(4, 3))
    return wp.array(host, dtype=wp.vec3, device=device), host.shape[0]


def _run_distance(kernel: wp.Kernel, points: object, device: wp.DeviceLike) -> np.ndarray:
    """Launch a distance-only kernel over a batch and return the distances on the host."""
    array, n = _upload(points, device)
    if n == 0:
        return np.zeros(0, dtype=np.float32)
    distances = wp.empty(n, dtype=float, device=array.device)
    wp.launch(kernel, dim=n, inputs=[array], outputs=[distances], device=array.device)
    return distances.numpy()


def _run_closest(
    kernel: wp.Kernel, points: object, device: wp.DeviceLike, dtype: type, width: int
) -> tuple[np.ndarray, np.ndarray]:
    """Launch a closest-point kernel over a batch and return (distances, coefficients)."""
    array, n = _upload(points, device)
    if n == 0:
        return np.zeros(0, dtype=np.float32), np.zeros((0, width), dtype=np.float32)
    distances = wp.empty(n, dtype=float, device=array.device)
    coefficients = wp.empty(n, dtype=dtype, device=array.device)
    wp.launch(kernel, dim=n, inputs=[array], outputs=[distances, coefficients], device=array.device)
    return distances.numpy(), coefficients.numpy()


def vertex_face_distance(points: object, *, device: wp.DeviceLike = None) -> np.ndarray:
    """Distances from vertices to triangles, one query per row.

    Args:
        points: Array-like of shape (n, 4, 3): ``[vertex, f0, f1, f2]`` per query (converted to
            float32; a Warp array is accepted too).
        device: Warp device to run on; ``None`` means Warp's default device.

    Returns:
        float32 array of shape (n,): Euclidean distances (not squared).

    Raises:
        InputError: ``points`` has the wrong shape or dtype, or holds NaN or Inf.
    """
    return _run_distance(_vertex_face_distance_kernel, points, device)


def vertex_face_closest_points(
    points: object, *, device: wp.DeviceLike = None
) -> tuple[np.ndarray, np.ndarray]:
    """Distances and closest-point barycentric weights for vertex-triangle queries.

    Args:
        points: Array-like of shape (n, 4, 3): ``[vertex, f0, f1, f2]`` per query.
        device: Warp device to run on; ``None`` means Warp's default device.

    Returns:
        ``(distances, weights)``: float32 arrays of shapes (n,) and (n, 3). The closest point
        of query ``i`` is ``weights[i] @ points[i, 1:4]``; the weights are in [0, 1] and sum to 1.

    Raises:
        InputError: ``points`` has the wrong shape or dtype, or holds NaN or Inf.
    """
    return _run_closest(_vertex_face_closest_point_kernel, points, device, wp.vec3, 3)


def edge_edge_distance(points: object, *, device: wp.DeviceLike = None) -> np.ndarray:
    """Distances between pairs of edges (segments), one query per row.

    Args:
        points: Array-like of shape (n, 4, 3): ``[a0, a1, b0, b1]`` per query (converted to
            float32; a Warp array is accepted too).
        device: Warp device to run on; ``None`` means Warp's default device.

    Returns:
        float32 array of shape (n,): Euclidean distances (not squared).

    Raises:
        InputError: ``points`` has the wrong shape or dtype, or holds NaN or Inf.
    """
    return _run_distance(_edge_edge_distance_kernel, points, device)


def edge_edge_closest_points(
    points: object, *, device: wp.DeviceLike = None
) -> tuple[np.ndarray, np.ndarray]:
    """Distances and closest-point parameters for edge-edge queries.

    Args:
        points: Array-like of shape (n, 4, 3): ``[a0, a1, b0, b1]`` per query.
        device: Warp device to run on; ``None`` means Warp's default device.

    Returns:
        ``(distances, params)``: float32 arrays of shapes (n,) and (n, 2). The closest points of
        query ``i`` are ``a0 + s (a1 - a0)`` and ``b0 + t (b1 - b0)`` with ``(s, t) = params[i]``
        in ``[0, 1]^2``.

    Raises:
        InputError: ``points`` has the wrong shape or dtype, or holds NaN or Inf.
    """
    return _run_closest(_edge_edge_closest_point_kernel, points, device, wp.vec2, 2)
