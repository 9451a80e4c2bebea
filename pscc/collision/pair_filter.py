"""Supporting-plane test of candidate triangle pairs, after the box test of the spatial hash.

Two triangles A and B whose boxes overlap cannot touch (or come within the thickness h) when all
three vertices of B lie strictly on one side of A's plane, farther than h (or the same with A and
B swapped): B is the convex hull of its vertices, and A lies in its plane. Tilted layers of cloth
have large, overlapping boxes; this test removes most such pairs before feature extraction.

- DCD: signed distances n_A . (b_i - a_0) against h |n_A|, each trusted beyond a rounding bound of
  ``16 u`` times its magnitude companion (the same products with absolute values). The feature-pair
  extraction takes the same per-vertex test from per-face plane slabs instead
  (:mod:`pscc.collision.face_planes`: each face's normal, centre and grown slab computed once per call,
  so a pair projects three vertices per direction: on `twisting f48` the test took 1.07 instead of 1.6 ms).
- CCD with thickness 0: the vertex stays strictly on one side of the moving plane during the whole
  step (:func:`pscc.geometry.ccd.vertex_plane_side`, a Bernstein sign test of the coplanarity
  cubic), for the three vertices with the same side.
- CCD with thickness > 0: no pair is removed.

Triangle pairs that share a vertex are never removed (the shared vertex lies on the plane).
The test runs inside the feature-pair extraction (:mod:`pscc.collision.feature_pairs`), so it
needs no buffer of its own. It is taken per vertex (:func:`plane_sides`): the extraction also leaves
out the vertex-face pairs of a vertex beyond the other face's plane, and the edge-edge pairs of an
edge whose two ends are beyond it on one side (the triangle pair is dropped when all three vertices
are, :func:`sides_agree`). On `twisting f48` that took the candidates from 23.6K to 17.8K, on
`cloth_rollers f3` from 113.7K to 90.3K; the contacts among them are the same.
"""

from __future__ import annotations

import warp as wp

from pscc.geometry.ccd import CcdParameters, vertex_plane_side

wp.set_module_options({"enable_backward": False})


@wp.func
def _static_sides(a: wp.vec3, b: wp.vec3, c: wp.vec3, p0: wp.vec3, p1: wp.vec3, p2: wp.vec3,
                  thickness: float, factor: float) -> wp.vec3:
    """Per vertex p_k: +1 when it is certified farther than ``thickness`` above the plane of (a, b, c),
    -1 below, 0 when it may be within. Without branches (a pair's sides are hard to predict, and
    mispredicted branches cost more than the arithmetic): p_k is above when s_k - m_k > 0 and below when
    s_k + m_k < 0, with m_k the grown limit; in IEEE arithmetic x - y > 0 exactly when x > y."""
    e1 = b - a
    e2 = c - a
    n = wp.cross(e1, e2)
    mn = wp.vec3(wp.abs(e1[1] * e2[2]) + wp.abs(e1[2] * e2[1]), wp.abs(e1[2] * e2[0]) + wp.abs(e1[0] * e2[2]),
                 wp.abs(e1[0] * e2[1]) + wp.abs(e1[1] * e2[0]))
    limit = thickness * wp.length(n) * (1.0 + factor)
    d0 = p0 - a
    d1 = p1 - a
    d2 = p2 - a
    s = wp.vec3(wp.dot(n, d0), wp.dot(n, d1), wp.dot(n, d2))
    m = wp.vec3(limit + factor * wp.dot(mn, wp.abs(d0)), limit + factor * wp.dot(mn, wp.abs(d1)),
                limit + factor * wp.dot(mn, wp.abs(d2)))
    return wp.vec3(wp.where(s[0] - m[0] > 0.0, 1.0, wp.where(s[0] + m[0] < 0.0, -1.0, 0.0)),
                   wp.where(s[1] - m[1] > 0.0, 1.0, wp.where(s[1] + m[1] < 0.0, -1.0, 0.0)),
                   wp.where(s[2] - m[2] > 0.0, 1.0, wp.where(s[2] + m[2] < 0.0, -1.0, 0.0)))


@wp.func
def plane_sides(
    fa: wp.vec3i,
    fb: wp.vec3i,
    positions_t0: wp.array(dtype=wp.vec3),
    positions_t1: wp.array(dtype=wp.vec3),
    swept: int,
    thickness: float,
    factor: float,
    params: CcdParameters,
) -> wp.vec3:
    """The side of each vertex of face ``fb`` with respect to the supporting plane of face ``fa``: +1 or
    -1 when the vertex is certified farther than ``thickness`` from it on that side (DCD; with
    ``swept``, strictly on that side over the whole step, only for thickness 0), 0 otherwise.

    A vertex with a non-zero side is farther than the thickness from every point of face ``fa``, and
    an edge of ``fb`` whose two ends have the same non-zero side is farther than it from every edge of
    ``fa`` (they lie in the plane): :mod:`pscc.collision.feature_pairs` drops those feature pairs, and
    the triangle pair when all three sides agree (:func:`sides_agree`)."""
    if swept == 0:
        return _static_sides(positions_t0[fa[0]], positions_t0[fa[1]], positions_t0[fa[2]], positions_t0[fb[0]],
                             positions_t0[fb[1]], positions_t0[fb[2]], thickness, factor)
    if thickness != 0.0:
        return wp.vec3(0.0, 0.0, 0.0)
    a0 = positions_t0[fa[0]]
    b0 = positions_t0[fa[1]]
    c0 = positions_t0[fa[2]]
    a1 = positions_t1[fa[0]]
    b1 = positions_t1[fa[1]]
    c1 = positions_t1[fa[2]]
    sides = wp.vec3(0.0, 0.0, 0.0)
    for k in range(3):
        v = fb[k]
        sides[k] = vertex_plane_side(positions_t0[v], a0, b0, c0, positions_t1[v], a1, b1, c1, params)
    return sides


@wp.func
def sides_agree(sides: wp.vec3) -> bool:
    """All three sides are the same non-zero side: the plane separates the face."""
    return sides[0] != 0.0 and sides[0] == sides[1] and sides[1] == sides[2]


_UNIT_ROUNDOFF = 2.0**-24
# 16 u: a projection's rounding bound is 4.01 u |n|_1 |d|_inf; the difference of two projections and its own
# rounding stay under 10.1 u of it; the rest absorbs the roundings of the bound itself.
_SEGMENT_ERROR_FACTOR = wp.constant(16.0 * _UNIT_ROUNDOFF)
_SEGMENT_GROW_FACTOR = wp.constant(1.0 + 8.0 * _UNIT_ROUNDOFF)
_SEGMENT_TINY_ERROR = wp.constant(1.0e-35)


@wp.func
def _inf_norm(v: wp.vec3) -> float:
    return wp.max(wp.max(wp.abs(v[0]), wp.abs(v[1])), wp.abs(v[2]))


@wp.func
def segments_separated(a0: wp.vec3, a1: wp.vec3, b0: wp.vec3, b1: wp.vec3, thickness: float) -> bool:
    """Whether segments [a0, a1] and [b0, b1] are certified farther apart than ``thickness`` by the plane
    normal to both (the direction n = (a1 - a0) x (b1 - b0), as float32 computes it; any direction would
    do): the projections of the two segments onto n, each within its rounding bound, are more than
    ``thickness |n|`` apart.

    Rounding (float32, unit roundoff u, with or without fused multiply-adds): each projection
    fl(n . fl(p - b0)) is within 4.01 u |n|_1 |p - b0|_inf of the exact n . (p - b0), and the projection of
    b0 is exactly 0; the gap between the two intervals, computed with one more subtraction, is within
    10.1 u |n|_1 max |p - b0|_inf of the exact gap, and the margin subtracted from it is
    16 u |n|_1 max |p - b0|_inf + thickness |n|_2 (1 + 8 u), enough for the roundings of the margin itself. The
    final comparison, fl(gap - margin) > 0, is exact in sign. Parallel or degenerate segments (n = 0) and
    NaN are never separated. The discrete feature pass leaves such edge pairs out
    (:mod:`pscc.collision.feature_pairs`)."""
    n = wp.cross(a1 - a0, b1 - b0)
    d0 = a0 - b0
    d1 = a1 - b0
    d3 = b1 - b0
    s0 = wp.dot(n, d0)
    s1 = wp.dot(n, d1)
    s3 = wp.dot(n, d3)
    reach = wp.max(wp.max(_inf_norm(d0), _inf_norm(d1)), _inf_norm(d3))
    error = _SEGMENT_ERROR_FACTOR * (wp.abs(n[0]) + wp.abs(n[1]) + wp.abs(n[2])) * reach + _SEGMENT_TINY_ERROR
    margin = error + thickness * wp.length(n) * _SEGMENT_GROW_FACTOR
    above = wp.min(s0, s1) - wp.max(0.0, s3)
    below = wp.min(0.0, s3) - wp.max(s0, s1)
    return wp.max(above - margin, below - margin) > 0.0
