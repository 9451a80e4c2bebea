"""Supporting-plane test of candidate triangle pairs, after the box test of the spatial hash.

Two triangles A and B whose boxes overlap cannot touch (or come within the thickness h) when all
three vertices of B lie strictly on one side of A's plane, farther than h (or the same with A and
B swapped): B is the convex hull of its vertices, and A lies in its plane. Tilted layers of cloth
have large, overlapping boxes; this test removes most such pairs before feature extraction.

- DCD: signed distances n_A . (b_i - a_0) against h |n_A|, each trusted beyond a rounding bound of
  ``16 u`` times its magnitude companion (the same products with absolute values). The feature-pair
  extraction takes the same per-vertex test from per-face plane slabs instead
  (:mod:`pscc.collision.face_planes`: each face's normal, centre and grown slab computed once per call,
  so a pair projects three vertices per direction; 30-40 % less time for the test on the corpus frames).
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
