"""Conservative float32 segment-triangle intersection test (edge-face), for intersection checks.

An *edge-face* (EF) query asks whether the closed segment ``S = [p, q]`` meets the closed
triangle ``T = (a, b, c)``. The answer is one of three kinds (:class:`SegmentTriangleKind`):

* ``MISS``: certainly no intersection (for the exact real-number values of the float32 input);
* ``CROSSING``: certainly a proper crossing: ``p`` and ``q`` strictly on opposite sides of the
  plane of ``T`` and the line ``pq`` strictly inside all three edges;
* ``NEAR``: float32 cannot decide, and the pair is reported (conservatively) with a certified
  bound ``Delta`` on the distance between ``S`` and ``T``. It may or may not touch.

Guarantees (for finite input whose 5-point coordinate spread ``L`` lies in ``[1e-9, 1e9]``, so
that every product stays a normal float32):

* **No false negatives.** ``S`` and ``T`` intersect (touching counts) => the kind is not ``MISS``.
  The sign logic rests on Shewchuk's proven orientation bound (doubled); the distance gates of
  step 4 rest on the documented error of :mod:`pscc.geometry.distance` (measured with a safety
  factor of 4 there, doubled again here).
* **Bounded false positives.** A ``NEAR`` pair satisfies ``dist(S, T) <= Delta``, and ``Delta`` is
  returned with the kind. Typical ``Delta`` is a few ``1e-6 L``. Its worst case is of order
  ``sqrt(u) L`` (``u = 2**-24``), capped by :data:`NEAR_BOUND_CAP` ``= 1e-2``; it is reached only
  by segments that graze the plane nearly parallel to an edge and by near-coplanar thin
  triangles, where float32 determinants cannot resolve the side. Largest ``Delta / L`` measured
  over 1.4 million adversarial queries: ``1.1e-3``.

Method.

1. Orientation determinants (six times signed tetrahedron volumes) with Shewchuk's static error
   bound ``|det_float32 - det_exact| <= E = ORIENT3D_ERROR_FACTOR * permanent`` (the permanent is
   the same expansion with absolute values): ``s_p = det(b - a, c - a, p - a)`` and ``s_q`` (the
   endpoints against the plane), and ``w_xy = det(y - x, p - x, q - x)`` for the directed edges
   ``ab, bc, ca`` (the side of the line ``pq`` against each edge). A value is *certain* when
   ``|det| > E``; its sign is then the exact sign.
2. ``MISS`` when ``s_p`` and ``s_q`` are certainly of the same sign, or two ``w`` are certainly of
   opposite signs (the line passes outside an edge, or is parallel to the plane).
3. ``CROSSING`` when ``s_p`` and ``s_q`` are certainly of opposite signs and all ``w`` are certain.
4. Otherwise distance gates decide, with float32 distances ``d_EE`` (segment to the nearest
   triangle edge) and ``d_VF(e)`` (endpoint ``e`` to the triangle) from :mod:`pscc.geometry.distance`
   (error ``<= err = DISTANCE_ERROR_FACTOR * L``; ``err'`` adds :data:`THIN_TRIANGLE_VF_ERROR` ``* L``
   for thin triangles, whose vertex-face distance is ill-conditioned). With
   ``n = (b - a) x (c - a)`` and ``h_e = |s_e| / |n|`` the height of endpoint ``e`` over the plane,
   each gate is a necessary condition of an intersection evaluated with upper bounds
   (``|s_e| <= |s~_e| + E_e``, ``|n| >= |n~| - rounding``), so no intersecting pair fails it:

   * always: ``d_EE <= r + err``, ``r = |n| / perimeter`` the inradius: an intersection point lies
     within ``r`` of the triangle's boundary;
   * some endpoint with an uncertain ``s_e``: ``min(d_EE, d_VF(e) over those e) <= max h_e + err'``:
     the part of ``S`` between the plane and those endpoints stays within their height, and its
     projection onto the plane either ends inside ``T`` or crosses an edge of ``T``;
   * both ``s_e`` certain (a proper plane crossing), some ``w_xy`` uncertain:
     ``d_EE <= (|w_xy| + E_xy) / ((h_p + h_q) |y - x|) + err``, since the crossing point has
     in-plane distance ``|w_xy| / ((h_p + h_q) |y - x|)`` to the line ``xy``, hence to the boundary;
     and ``min(d_EE, d_VF(p), d_VF(q)) <= max(h_p, h_q) + err'`` (all of ``S`` lies within that
     height; this is the tight gate for grazing segments, the previous one for steep ones).

   A pair that passes every gate is ``NEAR`` with ``Delta = min(evaluated distances) + err``;
   the gates bound it by ``min(r, h, line gate) + 2 err'``.

Degenerate cases. Coplanar input (a flat sheet, cloth on a floor) has zero or uncertain
determinants and is decided by the gates: reported iff the segment is within ``h + err`` of the
triangle, where ``h`` is the float32 noise of the plane (0 for an axis-aligned plane, a few
``1e-6 L`` otherwise). A segment through a triangle vertex, through or along a triangle edge, or
ending on the triangle is ``NEAR`` with ``Delta ~ err``. A zero-area triangle (collinear or
coincident vertices) is the union of its edges: reported iff the segment is within about ``err``
of one of them. A zero-length segment is a point. These are the intersections ipctk's
``has_intersections`` counts too (closed segment, closed triangle).

Float32 rounding and FMA contraction (Warp's default ``fuse_fp``) only remove roundings, so the
bounds hold with or without fused multiply-adds. Device functions: :func:`segment_triangle_classify`,
:func:`segment_triangle_intersect`; host batch: :func:`segment_triangle_intersections`.
"""

from __future__ import annotations

import enum

import numpy as np
import warp as wp

from pscc._checks import check_points
from pscc.geometry import distance_tolerances as _dtol
from pscc.geometry.distance import edge_edge_distance_squared, vertex_face_distance_squared

wp.set_module_options({"enable_backward": False})

__all__ = [
    "DISTANCE_ERROR_FACTOR",
    "NEAR_BOUND_CAP",
    "NORMAL_ERROR_FACTOR",
    "ORIENT3D_ERROR_FACTOR",
    "SegmentTriangleKind",
    "segment_triangle_classify",
    "segment_triangle_intersect",
    "segment_triangle_intersections",
]

UNIT_ROUNDOFF: float = 2.0**-24
"""u: relative rounding error of one float32 operation (dimensionless)."""

ORIENT3D_ERROR_FACTOR: float = 16.0 * UNIT_ROUNDOFF
"""E / permanent for a 3x3 determinant of three float32 difference vectors (dimensionless).

Shewchuk's orient3d filter ``(7 u + 56 u^2) * permanent`` bounds the error of the expansion
``x . (y x z)`` including the rounding of the differences; 16 u doubles it as a margin (evaluation
order, fused multiply-adds, rounding of the permanent itself)."""

NORMAL_ERROR_FACTOR: float = 8.0 * UNIT_ROUNDOFF
"""Bound on each component error of ``n = (b - a) x (c - a)`` over the sum of its two absolute
products (dimensionless): two rounded differences, two products and one subtraction give 4 u,
doubled as a margin."""

LENGTH_ERROR_FACTOR: float = 8.0 * UNIT_ROUNDOFF
"""Relative error bound of a float32 Euclidean length or of a sum of three lengths (dimensionless)."""

DISTANCE_ERROR_FACTOR: float = 2.0 * _dtol.DISTANCE_ERROR_CONST * _dtol.EPS32
"""``err / L``: bound on the error of the float32 edge-edge and vertex-face distances of
:mod:`pscc.geometry.distance` (``C * EPS32 * L`` there, with ``C = 16``; doubled here, and ``L`` here is
the 5-point spread, at least the 4-point one). About ``3.8e-6`` (dimensionless)."""

THIN_TRIANGLE_VF_ERROR: float = _dtol.ILL_CONDITIONED_REL_ERROR
"""Extra ``/ L`` over-estimate of the vertex-face distance for triangles of flatness below
:data:`pscc.geometry.distance_tolerances.WELL_SHAPED_MIN_FLATNESS` (``1e-3``; dimensionless)."""

THRESHOLD_SLACK: float = 1.0 + 2.0**-12
"""Factor on the gate thresholds covering the few roundings made while forming them."""

NEAR_BOUND_CAP: float = 1.0e-2
"""Cap on ``Delta / L`` for near pairs (dimensionless): an order-of-magnitude derivation, not a proof.

The gates leave ``Delta <= min(h, beta, r) + err`` (module docstring). For a well-shaped triangle the
plane height ``h`` and the edge gate ``beta`` trade off as ``h * beta <~ 2 E / |edge| <~ 500 u L^2``,
so ``Delta <~ sqrt(500 u) L ~ 5.5e-3 L`` at worst (a segment grazing the plane nearly parallel to an
edge); for a thin triangle ``min(h + 1e-3 L, r)`` stays below about ``3.6e-3 L``; the cap doubles the
larger as a margin for the rough constants. The largest
``Delta / L`` measured over adversarial samples (grazing, near-parallel, thin, coplanar, touching) is
about ``1.1e-3``; typical near pairs have ``Delta`` of a few ``err``."""

NO_BOUND: float = 3.0e38
"""Stands for an infinite threshold (a bound that does not apply, e.g. a zero-area triangle's
plane height); finite so that no kernel handles Inf."""


class SegmentTriangleKind(enum.IntEnum):
    """Outcome of :func:`segment_triangle_classify` (stored as a float in the returned vec2)."""

    MISS = 0
    CROSSING = 1
    NEAR = 2


_ORIENT_ERR = wp.constant(wp.float32(ORIENT3D_ERROR_FACTOR))
_NORMAL_ERR = wp.constant(wp.float32(NORMAL_ERROR_FACTOR))
_LENGTH_ERR = wp.constant(wp.float32(LENGTH_ERROR_FACTOR))
_DISTANCE_ERR = wp.constant(wp.float32(DISTANCE_ERROR_FACTOR))
_THIN_VF_ERR = wp.constant(wp.float32(THIN_TRIANGLE_VF_ERROR))
_WELL_SHAPED = wp.constant(wp.float32(_dtol.WELL_SHAPED_MIN_FLATNESS))
_SLACK = wp.constant(wp.float32(THRESHOLD_SLACK))
_NO_BOUND = wp.constant(wp.float32(NO_BOUND))
_MISS = wp.constant(wp.float32(0.0))
_CROSSING = wp.constant(wp.float32(1.0))
_NEAR = wp.constant(wp.float32(2.0))


# ------------------------------------------------------------------------------------------------
# Device helpers
# ------------------------------------------------------------------------------------------------


@wp.func
def _orient(x: wp.vec3, y: wp.vec3, z: wp.vec3, w: wp.vec3) -> wp.vec2:
    """``det(y - x, z - x, w - x)`` and its rounding-error bound E (Shewchuk's static filter)."""
    u = y - x
    v = z - x
    t = w - x
    det = u[0] * (v[1] * t[2] - v[2] * t[1]) + u[1] * (v[2] * t[0] - v[0] * t[2]) + u[2] * (v[0] * t[1] - v[1] * t[0])
    perm = (
        wp.abs(u[0]) * (wp.abs(v[1] * t[2]) + wp.abs(v[2] * t[1]))
        + wp.abs(u[1]) * (wp.abs(v[2] * t[0]) + wp.abs(v[0] * t[2]))
        + wp.abs(u[2]) * (wp.abs(v[0] * t[1]) + wp.abs(v[1] * t[0]))
    )
    return wp.vec2(det, _ORIENT_ERR * perm)


@wp.func
def _sign_class(value: wp.vec2) -> int:
    """+1 / -1 when the determinant's sign is certain (``|det| > E``), 0 when it is not."""
    if value[0] > value[1]:
        return 1
    if value[0] < -value[1]:
        return -1
    return 0


@wp.func
def _spread(p: wp.vec3, q: wp.vec3, a: wp.vec3, b: wp.vec3, c: wp.vec3) -> float:
    """Largest coordinate spread L of the five points (max over axes of max - min)."""
    lo = wp.min(wp.min(wp.min(p, q), wp.min(a, b)), c)
    hi = wp.max(wp.max(wp.max(p, q), wp.max(a, b)), c)
    d = hi - lo
    return wp.max(wp.max(d[0], d[1]), d[2])


@wp.func
def _line_gate(w: wp.vec2, x: wp.vec3, y: wp.vec3, height_sum: float) -> float:
    """Bound on the crossing point's distance to edge line ``xy`` when ``w_xy`` is uncertain."""
    if _sign_class(w) != 0:
        return _NO_BOUND
    length = wp.length(y - x) * (1.0 - _LENGTH_ERR)
    if length > 0.0 and height_sum > 0.0:
        return (wp.abs(w[0]) + w[1]) / (height_sum * length)
    return _NO_BOUND


# ------------------------------------------------------------------------------------------------
# Public device functions
# ------------------------------------------------------------------------------------------------


@wp.func
def segment_triangle_classify(p: wp.vec3, q: wp.vec3, a: wp.vec3, b: wp.vec3, c: wp.vec3) -> wp.vec2:
    """Classify segment ``[p, q]`` against triangle ``(a, b, c)`` (method in the module docstring).

    Args:
        p: First segment endpoint.
        q: Second segment endpoint.
        a: First triangle vertex.
        b: Second triangle vertex.
        c: Third triangle vertex.

    Returns:
        ``(kind, bound)``: ``kind`` is a :class:`SegmentTriangleKind` value as a float (0 miss,
        1 certain crossing, 2 near); ``bound`` is 0 for a crossing, the certified distance bound
        ``Delta`` (length units) for a near pair, and -1 for a miss.
    """
    sp = _orient(a, b, c, p)
    sq = _orient(a, b, c, q)
    cp = _sign_class(sp)
    cq = _sign_class(sq)
    if cp != 0 and cp == cq:
        return wp.vec2(_MISS, -1.0)

    wab = _orient(a, b, p, q)
    wbc = _orient(b, c, p, q)
    wca = _orient(c, a, p, q)
    kab = _sign_class(wab)
    kbc = _sign_class(wbc)
    kca = _sign_class(wca)
    if (kab > 0 or kbc > 0 or kca > 0) and (kab < 0 or kbc < 0 or kca < 0):
        return wp.vec2(_MISS, -1.0)
    if cp * cq < 0 and kab != 0 and kbc != 0 and kca != 0:
        return wp.vec2(_CROSSING, 0.0)

    # Undecided by the signs: distance gates, each a necessary condition of an intersection.
    err = _DISTANCE_ERR * _spread(p, q, a, b, c)
    ab = b - a
    ac = c - a
    bc = c - b
    n = wp.cross(ab, ac)
    n_err = _NORMAL_ERR * (
        wp.abs(ab[1] * ac[2]) + wp.abs(ab[2] * ac[1])
        + wp.abs(ab[2] * ac[0]) + wp.abs(ab[0] * ac[2])
        + wp.abs(ab[0] * ac[1]) + wp.abs(ab[1] * ac[0])
    )
    n_len = wp.length(n)
    n_lo = n_len * (1.0 - _LENGTH_ERR) - n_err
    n_hi = n_len * (1.0 + _LENGTH_ERR) + n_err
    len_ab = wp.length(ab)
    len_ac = wp.length(ac)
    len_bc = wp.length(bc)
    perimeter_lo = (len_ab + len_ac + len_bc) * (1.0 - _LENGTH_ERR)
    inradius_hi = float(0.0)
    if perimeter_lo > 0.0:
        inradius_hi = n_hi / perimeter_lo

    d_ee = wp.sqrt(
        wp.min(
            wp.min(edge_edge_distance_squared(p, q, a, b), edge_edge_distance_squared(p, q, b, c)),
            edge_edge_distance_squared(p, q, c, a),
        )
    )
    if d_ee > inradius_hi * _SLACK + err:
        return wp.vec2(_MISS, -1.0)

    height = float(0.0)
    d_min = d_ee
    if cp == 0 or cq == 0:
        # An endpoint may lie on the plane: the part of S beyond the plane stays within its height.
        if cp == 0:
            height = wp.max(height, wp.abs(sp[0]) + sp[1])
            d_min = wp.min(d_min, wp.sqrt(vertex_face_distance_squared(p, a, b, c)))
        if cq == 0:
            height = wp.max(height, wp.abs(sq[0]) + sq[1])
            d_min = wp.min(d_min, wp.sqrt(vertex_face_distance_squared(q, a, b, c)))
    else:
        # A certain plane crossing with an uncertain edge side: the crossing point is near that edge.
        height_sum = ((wp.abs(sp[0]) - sp[1]) + (wp.abs(sq[0]) - sq[1])) / n_hi
        gate = wp.min(wp.min(_line_gate(wab, a, b, height_sum), _line_gate(wbc, b, c, height_sum)),
                      _line_gate(wca, c, a, height_sum))
        if gate < _NO_BOUND and d_ee > gate * _SLACK + err:
            return wp.vec2(_MISS, -1.0)
        # All of S lies within the larger endpoint height of the plane (tight for grazing segments).
        height = wp.max(wp.abs(sp[0]) + sp[1], wp.abs(sq[0]) + sq[1])
        d_min = wp.min(d_min, wp.sqrt(wp.min(vertex_face_distance_squared(p, a, b, c),
                                             vertex_face_distance_squared(q, a, b, c))))
    if n_lo > 0.0:
        max_edge = wp.max(wp.max(len_ab, len_ac), len_bc)
        vf_err = err
        if n_len * n_len < _WELL_SHAPED * max_edge * max_edge * max_edge * max_edge:
            vf_err = err + _THIN_VF_ERR * _spread(p, q, a, b, c)
        if d_min > (height / n_lo) * _SLACK + vf_err:
            return wp.vec2(_MISS, -1.0)
    return wp.vec2(_NEAR, d_min + err)


@wp.func
def segment_triangle_intersect(p: wp.vec3, q: wp.vec3, a: wp.vec3, b: wp.vec3, c: wp.vec3) -> bool:
    """Conservative test: True unless segment ``[p, q]`` certainly misses triangle ``(a, b, c)``.

    True for every intersecting (or touching) pair; false positives lie within the certified
    bound of :func:`segment_triangle_classify`.

    Args:
        p: First segment endpoint.
        q: Second segment endpoint.
        a: First triangle vertex.
        b: Second triangle vertex.
        c: Third triangle vertex.

    Returns:
        Whether the pair is reported (crossing or near).
    """
    return segment_triangle_classify(p, q, a, b, c)[0] > 0.5


# ------------------------------------------------------------------------------------------------
# Host batch
# ------------------------------------------------------------------------------------------------


@wp.kernel
def _classify_queries(
    # in:
    points: wp.array2d(dtype=wp.vec3),
    # out:
    kinds_out: wp.array(dtype=wp.int32),
    bounds_out: wp.array(dtype=float),
):
    """One thread per query i: points[i] = [p, q, a, b, c]."""
    i = wp.tid()
    r = segment_triangle_classify(points[i, 0], points[i, 1], points[i, 2], points[i, 3], points[i, 4])
    kinds_out[i] = int(r[0] + 0.5)
    bounds_out[i] = r[1]


def segment_triangle_intersections(points: object, *, device: wp.DeviceLike = None) -> tuple[np.ndarray, np.ndarray]:
    """Classify a batch of segment-triangle queries, one thread per query.

    Args:
        points: Array-like of shape (n, 5, 3): ``[p, q, a, b, c]`` per query (segment ``[p, q]``,
            triangle ``(a, b, c)``); converted to float32.
        device: Warp device to run on; ``None`` means Warp's default device.

    Returns:
        ``(kinds, bounds)``: (n,) int32 :class:`SegmentTriangleKind` values and (n,) float32
        bounds (0 for a crossing, the certified distance bound for a near pair, -1 for a miss).

    Raises:
        InputError: ``points`` has the wrong shape or dtype, or holds NaN or Inf.

    Allocates: yes (the batch and its results). Capture-safe: no.
    """
    host = check_points(points, "points", shape_tail=(5, 3))
    n = host.shape[0]
    if n == 0:
        return np.zeros(0, dtype=np.int32), np.zeros(0, dtype=np.float32)
    array = wp.array(host, dtype=wp.vec3, device=device)
    kinds = wp.empty(n, dtype=wp.int32, device=array.device)
    bounds = wp.empty(n, dtype=float, device=array.device)
    wp.launch(_classify_queries, dim=n, inputs=[array], outputs=[kinds, bounds], device=array.device)
    return kinds.numpy(), bounds.numpy()
