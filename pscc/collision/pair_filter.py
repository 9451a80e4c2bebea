"""Supporting-plane test of candidate triangle pairs, after the box test of the spatial hash.

Two triangles A and B whose boxes overlap cannot touch (or come within the thickness h) when all
three vertices of B lie strictly on one side of A's plane, farther than h (or the same with A and
B swapped): B is the convex hull of its vertices, and A lies in its plane. Tilted layers of cloth
have large, overlapping boxes; this test removes most such pairs before feature extraction.

- DCD: signed distances n_A . (b_i - a_0) against h |n_A|, each trusted beyond a rounding bound of
  ``16 u`` times its magnitude companion (the same products with absolute values).
- CCD with thickness 0: the vertex stays strictly on one side of the moving plane during the whole
  step (:func:`pscc.geometry.ccd.vertex_plane_side`, a Bernstein sign test of the coplanarity
  cubic), for the three vertices with the same side.
- CCD with thickness > 0: no pair is removed.

Triangle pairs that share a vertex are never removed (the shared vertex lies on the plane).
The test runs inside the feature-pair extraction (:mod:`pscc.collision.feature_pairs`), so it
needs no buffer of its own.
"""

from __future__ import annotations

import warp as wp

from pscc.geometry.ccd import CcdParameters, vertex_plane_side

wp.set_module_options({"enable_backward": False})


@wp.func
def _plane_separates_static(a: wp.vec3, b: wp.vec3, c: wp.vec3, p0: wp.vec3, p1: wp.vec3, p2: wp.vec3,
                            thickness: float, factor: float) -> bool:
    """All of p0, p1, p2 farther than ``thickness`` from the plane of (a, b, c), on one side.

    Without branches per vertex (a pair's sides are hard to predict, and mispredicted branches cost
    more than the arithmetic): vertex k is above when s_k - m_k > 0 and below when s_k + m_k < 0, with
    m_k the grown limit; in IEEE arithmetic x - y > 0 exactly when x > y."""
    e1 = b - a
    e2 = c - a
    n = wp.cross(e1, e2)
    mn = wp.vec3(wp.abs(e1[1] * e2[2]) + wp.abs(e1[2] * e2[1]), wp.abs(e1[2] * e2[0]) + wp.abs(e1[0] * e2[2]),
                 wp.abs(e1[0] * e2[1]) + wp.abs(e1[1] * e2[0]))
    limit = thickness * wp.length(n) * (1.0 + factor)
    d0 = p0 - a
    d1 = p1 - a
    d2 = p2 - a
    s0 = wp.dot(n, d0)
    s1 = wp.dot(n, d1)
    s2 = wp.dot(n, d2)
    m0 = limit + factor * wp.dot(mn, wp.abs(d0))
    m1 = limit + factor * wp.dot(mn, wp.abs(d1))
    m2 = limit + factor * wp.dot(mn, wp.abs(d2))
    above = wp.min(wp.min(s0 - m0, s1 - m1), s2 - m2)
    below = wp.max(wp.max(s0 + m0, s1 + m1), s2 + m2)
    return above > 0.0 or below < 0.0


@wp.func
def _plane_separates_swept(fa: wp.vec3i, fb: wp.vec3i, positions_t0: wp.array(dtype=wp.vec3),
                           positions_t1: wp.array(dtype=wp.vec3), params: CcdParameters) -> bool:
    """All vertices of face ``fb`` stay strictly on one side of the moving plane of face ``fa``."""
    a0 = positions_t0[fa[0]]
    b0 = positions_t0[fa[1]]
    c0 = positions_t0[fa[2]]
    a1 = positions_t1[fa[0]]
    b1 = positions_t1[fa[1]]
    c1 = positions_t1[fa[2]]
    side = float(0.0)
    for k in range(3):
        v = fb[k]
        current = vertex_plane_side(positions_t0[v], a0, b0, c0, positions_t1[v], a1, b1, c1, params)
        if current == 0.0:
            return False
        if k > 0 and current != side:
            return False
        side = current
    return True


@wp.func
def triangle_pair_separated(
    fa: wp.vec3i,
    fb: wp.vec3i,
    positions_t0: wp.array(dtype=wp.vec3),
    positions_t1: wp.array(dtype=wp.vec3),
    swept: int,
    thickness: float,
    factor: float,
    params: CcdParameters,
) -> bool:
    """True when a supporting plane of face ``fa`` or ``fb`` separates the two (module docstring).

    ``swept`` = 0: static test at ``positions_t0`` with the thickness; 1: over the step (only with
    thickness 0; with a thickness the pair is never separated).
    """
    if swept == 0:
        a0 = positions_t0[fa[0]]
        a1 = positions_t0[fa[1]]
        a2 = positions_t0[fa[2]]
        b0 = positions_t0[fb[0]]
        b1 = positions_t0[fb[1]]
        b2 = positions_t0[fb[2]]
        if _plane_separates_static(a0, a1, a2, b0, b1, b2, thickness, factor):
            return True
        return _plane_separates_static(b0, b1, b2, a0, a1, a2, thickness, factor)
    if thickness != 0.0:
        return False
    if _plane_separates_swept(fa, fb, positions_t0, positions_t1, params):
        return True
    return _plane_separates_swept(fb, fa, positions_t0, positions_t1, params)
