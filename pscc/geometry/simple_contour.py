"""The contour test without a reference point: is the projected contour loop a simple polygon?

The normal-cone certificate (:mod:`pscc.geometry.normal_cone`) needs (1) a direction l with l . n > 0
for every face normal n of a patch, and (2) the patch's one contour loop, projected along l, to be a
simple closed polygon. The star test there proves (2) with one point o that sees every contour edge
turn the same way. A contour can be simple without such a point: an L- or U-shaped panel, a notched
plate, a strip bent into a C. This module proves (2) directly, edge pair by edge pair.

**Why a simple projected contour is enough.** Project the patch along l. Every face is front facing
(condition 1), so each projected triangle is positively oriented and its winding number around a
point q of the plane is 1 inside it, 0 outside. The faces are consistently oriented and each interior
edge belongs to two of them, traversed in opposite directions, so summing the triangles' windings,
the interior edges cancel: the number of faces whose projection contains q equals the winding number
of the projected contour around q. A simple closed curve winds at most once around any point, so no
two faces overlap in projection, and two faces of the patch can only meet where the contour meets
itself, which a simple contour with a positive gap does not. Over a step (CCD) the same holds at every
instant t when the contour is simple at every t.

**The test.** Loop edges e_i = (v_i, v_{i+1}). For every pair of non-adjacent edges, some axis w in
the plane orthogonal to l must separate their projections with a gap: the interval of w . p over the
end points of one edge lies below that of the other by more than a rounding pad. Five axes are tried:
the line through the two edges' midpoints, each edge's in-plane normal l x e and each edge's own
in-plane direction (collinear edges, common on straight CAD borders). Two adjacent edges (a, v) and
(v, c) may meet only at v: S(a, v, c; l) has a strict sign, or the three points follow each other
along v - a (collinear, going on). For CCD every axis is fixed over the step (taken from the
positions at t = 1/2) and every end point moves linearly, so w . p(t) stays between its values at
t0 and t1: the intervals are taken over both ends. The adjacent-edge sign uses the quadratic
Bernstein form of :func:`pscc.geometry.normal_cone.swept_signed_area_sign`.

*Rounding.* Values are taken relative to a point r: one end point of the first edge of a pair in
:func:`edges_apart`, the loop's first vertex in :func:`contour_is_simple`'s first two axes. The pad of an
axis w is ``margin`` x |w| x (the largest |p - r| over the points projected: the pair's eight end points,
or every loop vertex at both ends of the step), with ``margin`` the normal-cone margin (1e-5, about 84
float32 units in the last place): it covers the float32 error of the differences and of the dot products
(under 4 u |w| |p - r|). Values inside the pad count as touching.

*Cost.* O(k^2) for k contour edges, each pair ending at its first separating axis (edge i's own normal
and direction first, computed once per i); the node test runs it only when the star test has failed and
k <= :data:`SIMPLE_CONTOUR_MAX_EDGES`.
"""

from __future__ import annotations

import warp as wp

from pscc.geometry import normal_cone as nc

wp.set_module_options({"enable_backward": False})

SIMPLE_CONTOUR_MAX_EDGES: int = 128
"""Longest contour (edges) that the node test checks edge pair by edge pair when its star test fails."""


@wp.func
def _interval(w: wp.vec3, r: wp.vec3, a0: wp.vec3, b0: wp.vec3, a1: wp.vec3, b1: wp.vec3) -> wp.vec2:
    """[min, max] of w . (p - r) over the four points."""
    pa0 = wp.dot(a0 - r, w)
    pb0 = wp.dot(b0 - r, w)
    pa1 = wp.dot(a1 - r, w)
    pb1 = wp.dot(b1 - r, w)
    return wp.vec2(wp.min(wp.min(pa0, pb0), wp.min(pa1, pb1)), wp.max(wp.max(pa0, pb0), wp.max(pa1, pb1)))


@wp.func
def _disjoint(x: wp.vec2, y: wp.vec2, pad: float) -> bool:
    """Whether the intervals [x0, x1] and [y0, y1] lie apart by more than ``pad``."""
    return x[1] + pad < y[0] or y[1] + pad < x[0]


@wp.func
def _separated(w: wp.vec3, r: wp.vec3, a0: wp.vec3, b0: wp.vec3, a1: wp.vec3, b1: wp.vec3, c0: wp.vec3,
               d0: wp.vec3, c1: wp.vec3, d1: wp.vec3, pad: float) -> bool:
    """Whether axis ``w`` separates {a0, b0, a1, b1} from {c0, d0, c1, d1} by more than ``pad``."""
    return _disjoint(_interval(w, r, a0, b0, a1, b1), _interval(w, r, c0, d0, c1, d1), pad)


@wp.func
def _in_plane(x: wp.vec3, l: wp.vec3) -> wp.vec3:
    """``x`` less its component along the unit direction ``l``."""
    return x - wp.dot(x, l) * l


@wp.func
def edges_apart(a0: wp.vec3, b0: wp.vec3, a1: wp.vec3, b1: wp.vec3, c0: wp.vec3, d0: wp.vec3, c1: wp.vec3,
                d1: wp.vec3, l: wp.vec3, margin: float) -> bool:
    """Whether the projections along ``l`` of segments ab and cd are disjoint (at t0 and t1, and so at
    every t between, for linearly moving end points; pass the same points twice for one instant)."""
    r = a0
    extent = wp.max(wp.max(wp.max(wp.length(b0 - r), wp.length(a1 - r)), wp.max(wp.length(b1 - r), wp.length(c0 - r))),
                    wp.max(wp.max(wp.length(d0 - r), wp.length(c1 - r)), wp.length(d1 - r)))
    e = 0.5 * ((b0 - a0) + (b1 - a1))
    f = 0.5 * ((d0 - c0) + (d1 - c1))
    centre = 0.25 * ((c0 + d0 + c1 + d1) - (a0 + b0 + a1 + b1))
    w = _in_plane(centre, l)
    if _separated(w, r, a0, b0, a1, b1, c0, d0, c1, d1, margin * wp.length(w) * extent):
        return True
    w = wp.cross(l, e)
    if _separated(w, r, a0, b0, a1, b1, c0, d0, c1, d1, margin * wp.length(w) * extent):
        return True
    w = wp.cross(l, f)
    if _separated(w, r, a0, b0, a1, b1, c0, d0, c1, d1, margin * wp.length(w) * extent):
        return True
    w = _in_plane(e, l)
    if _separated(w, r, a0, b0, a1, b1, c0, d0, c1, d1, margin * wp.length(w) * extent):
        return True
    w = _in_plane(f, l)
    return _separated(w, r, a0, b0, a1, b1, c0, d0, c1, d1, margin * wp.length(w) * extent)


@wp.func
def _going_on(a: wp.vec3, v: wp.vec3, c: wp.vec3, w: wp.vec3, pad: float) -> bool:
    """Whether a, v, c follow each other along ``w`` with gaps above ``pad``."""
    return wp.dot(v - a, w) > pad and wp.dot(c - v, w) > pad


@wp.func
def corner_apart(a0: wp.vec3, v0: wp.vec3, c0: wp.vec3, a1: wp.vec3, v1: wp.vec3, c1: wp.vec3, l: wp.vec3,
                 margin: float, swept: int) -> bool:
    """Whether the projected edges (a, v) and (v, c) meet only at v (at every t of the step when
    ``swept``)."""
    if swept == 1:
        if nc.swept_signed_area_sign(a0, v0, c0, a1, v1, c1, l, margin) != 0.0:
            return True
    elif nc.signed_area(a0, v0, c0, l, margin) != 0.0:
        return True
    w = _in_plane(0.5 * ((v0 - a0) + (v1 - a1)), l)
    extent = wp.max(wp.max(wp.length(v0 - a0), wp.length(c0 - a0)),
                    wp.max(wp.length(v1 - a0), wp.max(wp.length(c1 - a0), wp.length(a1 - a0))))
    pad = margin * wp.length(w) * extent
    return _going_on(a0, v0, c0, w, pad) and _going_on(a1, v1, c1, w, pad)


@wp.func
def contour_is_simple(
    loop: wp.array(dtype=wp.int32),
    begin: int,
    end: int,
    positions_t0: wp.array(dtype=wp.vec3),
    positions_t1: wp.array(dtype=wp.vec3),
    l: wp.vec3,
    margin: float,
    swept: int,
) -> bool:
    """Whether the loop ``loop[begin:end]`` projected along the unit direction ``l`` is a simple polygon
    with a gap (at t0, or at every t of a linear step from t0 to t1 when ``swept``).

    Edge i's two axes (its in-plane normal and direction) and its intervals on them are computed once;
    most later edges j lie on one side of edge i's line or beyond its ends, which two dot products per
    end show. Only the other pairs go through :func:`edges_apart`. The pads of these first two axes use
    the loop's extent around its first vertex (every |p - r|, both ends of a step), which bounds each
    pair's own, so they are at least as large as :func:`edges_apart`'s."""
    count = end - begin
    if count < 3:
        return False
    r = positions_t0[loop[begin]]
    extent = float(0.0)
    for i in range(count):
        v = loop[begin + i]
        extent = wp.max(extent, wp.length_sq(positions_t0[v] - r))
        if swept == 1:
            extent = wp.max(extent, wp.length_sq(positions_t1[v] - r))
    extent = wp.sqrt(extent)
    for i in range(count):
        ia = loop[begin + i]
        ib = loop[begin + (i + 1) % count]
        ic = loop[begin + (i + 2) % count]
        a0 = positions_t0[ia]
        b0 = positions_t0[ib]
        a1 = a0
        b1 = b0
        if swept == 1:
            a1 = positions_t1[ia]
            b1 = positions_t1[ib]
        c0 = positions_t0[ic]
        c1 = c0
        if swept == 1:
            c1 = positions_t1[ic]
        if not corner_apart(a0, b0, c0, a1, b1, c1, l, margin, swept):
            return False
        e = 0.5 * ((b0 - a0) + (b1 - a1))
        normal = wp.cross(l, e)
        along = _in_plane(e, l)
        normal_pad = margin * wp.length(normal) * extent
        along_pad = margin * wp.length(along) * extent
        edge_normal = _interval(normal, r, a0, b0, a1, b1)
        edge_along = _interval(along, r, a0, b0, a1, b1)
        # Non-adjacent edges j > i + 1; the last edge is adjacent to the first.
        last = count
        if i == 0:
            last = count - 1
        cj0 = c0
        cj1 = c1
        for j in range(i + 2, last):
            jd = loop[begin + (j + 1) % count]
            dj0 = positions_t0[jd]
            dj1 = dj0
            if swept == 1:
                dj1 = positions_t1[jd]
            apart = _disjoint(edge_normal, _interval(normal, r, cj0, dj0, cj1, dj1), normal_pad)
            if not apart:
                apart = _disjoint(edge_along, _interval(along, r, cj0, dj0, cj1, dj1), along_pad)
            if not apart:
                apart = edges_apart(a0, b0, a1, b1, cj0, dj0, cj1, dj1, l, margin)
            if not apart:
                return False
            cj0 = dj0
            cj1 = dj1
    return True
