"""Normal-cone certificates for two faces that share a vertex or an edge (issue 14).

The test front certifies a BVH node's patch as free of self-intersection, so no pair of faces inside
one front node is ever tested. Faces that share a vertex but sit in two front nodes were still paired
by the spatial hash, even where the paper's certificate applied to just those two faces holds. This
module is that certificate for a pair of faces, used by the hash's face test
(:class:`pscc.collision.spatial_hash.SpatialHash` with ``certify_shared=True``), once a pair has passed
every other test:

- **Shared edge.** Faces A = (a, b, c) and B, consistently oriented across their shared edge bc (B
  holds it as c -> b), and a direction d with d . n_A > 0 and d . n_B > 0. A lies in a half plane
  bounded by the line bc, B in another; two such half planes meet outside the line only when they
  coincide, which makes the faces coplanar with a and d on one side of bc, i.e. with opposite normals
  (consistent orientation). A common direction rules that out, so A and B meet only along bc.
- **Shared vertex only.** Faces A = (v, a1, a2) and B = (v, b1, b2) (rotated so the shared vertex
  comes first) with a common direction d as above. Seen along d each face is a positively oriented
  triangle inside the sector at v spanned by its two edges from v (narrower than a half turn). With
  s(x, y) = d . ((x - v) x (y - v)), a ray r from v lies outside A's closed sector when
  s(a1, r) < 0 or s(r, a2) < 0. When both of B's edge rays lie outside A's sector and both of A's
  outside B's, the two sectors meet only at v (two arcs of a circle that overlap hold an end of one
  another), the projection along d is one-to-one on each face, so A and B meet only at v.
- **Over a step (CCD).** d must see each face's normal at every time of the linear motion: its three
  quadratic Bernstein control normals n0, nX, n1 (d . n0 > 0, d . n1 > 0, d . nX >= 0), and each
  s(., .) must keep one strict sign over the step (its quadratic Bernstein coefficients,
  :func:`~pscc.geometry.normal_cone.swept_signed_area_sign`), so the argument holds at every time.

The direction tried is the sum of the two faces' unit normals (at both ends of the step for CCD): for
two normals the best one there is. Both normals must lie within :data:`CONE_HALF_ANGLE_DEGREES` of it,
as in a front node: the half-plane argument alone would certify a hinge until it is folded shut, and a
simulator's CCD would then meet the fold only once its faces lie on each other. Both tests are about
intersection, like the node test: two faces that share a vertex and are closer than the thickness
elsewhere (a sharp fold) are certified as a front node holding them both would be. Rounding: a sign is
trusted only beyond the relative margin :data:`~pscc.tolerances.NORMAL_CONE_MARGIN` of the products of
lengths it is made of, above the float32 rounding of the cross and dot products (so a face of
near-zero area is never certified). Pairs that share three vertices, or an edge in the same direction
(inconsistent orientation), are never certified.
"""

from __future__ import annotations

import numpy as np
import warp as wp

from pscc.geometry import normal_cone as nc

wp.set_module_options({"enable_backward": False})

SHARED_KEEP: int = wp.constant(0)
"""Pairs that share a vertex are kept (plain hashing)."""
SHARED_SKIP: int = wp.constant(1)
"""Pairs that share a vertex are dropped (``SpatialHash(skip_adjacent=True)``)."""
SHARED_CERTIFY: int = wp.constant(2)
"""Pairs that share a vertex are dropped when :func:`shared_pair_certified` holds."""

CONE_HALF_ANGLE_DEGREES: float = 76.0
"""The widest cone of normals (half-angle about the common direction) that certifies two faces: the
cone every front node of up to that half-angle passes with (the node test's 128 sample directions
cover the sphere within 13.7 degrees, :mod:`pscc.geometry.normal_cone`). So a hinge is certified until
its faces' normals are 152 degrees apart (opened 28 degrees), as a front node holding both would be:
a simulator's CCD then sees the fold closing before the faces come within a thickness of each other,
as it did before this certificate (the exact half-plane argument would allow almost 180)."""

_CONE_COS = wp.constant(float(np.cos(np.radians(CONE_HALF_ANGLE_DEGREES))))


@wp.struct
class SharedVertexArgs:
    """What the face test reads for pairs that share a vertex, bundled for the kernel.

    ``mode`` is one of :data:`SHARED_KEEP`, :data:`SHARED_SKIP`, :data:`SHARED_CERTIFY`; ``swept`` (0/1)
    says whether ``positions_t1`` holds the step's end positions (CCD); ``margin`` is the relative
    margin of every sign test (:data:`~pscc.tolerances.NORMAL_CONE_MARGIN`)."""

    mode: wp.int32
    faces: wp.array(dtype=wp.vec3i)
    swept: wp.int32
    positions_t0: wp.array(dtype=wp.vec3)
    positions_t1: wp.array(dtype=wp.vec3)
    margin: wp.float32


@wp.func
def shares_vertex(ta: wp.vec3i, tb: wp.vec3i) -> bool:
    """Whether two faces (vertex ids) have a vertex id in common."""
    shared = False
    for u in range(3):
        for v in range(3):
            if ta[u] == tb[v]:
                shared = True
    return shared


@wp.func
def _sees(d: wp.vec3, n: wp.vec3, scale: float, margin: float, allow_zero: bool) -> bool:
    """d . n > margin |d| scale (>= with ``allow_zero``), with ``scale`` the sum of the edge-length
    products that n is made of: beyond the float32 rounding of n and of the dot product (below 8 u of the
    same products of lengths, :data:`~pscc.tolerances.NORMAL_CONE_MARGIN`), so the true sign is the sign
    tested. Without ``allow_zero`` n must also lie within :data:`CONE_HALF_ANGLE_DEGREES` of d. Lengths,
    not their squares: the bounds stay normal float32 numbers over the whole coordinate range
    (products of two lengths, :data:`~pscc.tolerances.MIN_COORDINATE_SCALE`)."""
    value = wp.dot(d, n)
    length_d = wp.length(d)
    bound = margin * length_d * scale
    if allow_zero:
        return value >= bound
    return value > wp.max(bound, _CONE_COS * length_d * wp.length(n))


@wp.func
def _unit(n: wp.vec3) -> wp.vec3:
    """n / |n|, or zero."""
    length = wp.length(n)
    if length > 0.0:
        return n / length
    return wp.vec3(0.0, 0.0, 0.0)


@wp.func
def _swept_face_seen(x0: wp.array(dtype=wp.vec3), x1: wp.array(dtype=wp.vec3), t: wp.vec3i, d: wp.vec3,
                     margin: float) -> bool:
    """d . n(t) > 0 at every time of the step: d sees the three quadratic Bernstein control normals
    n0, n1 and nX = (e1(0) x e2(1) + e1(1) x e2(0)) / 2 (the last one may be zero)."""
    e10 = x0[t[1]] - x0[t[0]]
    e20 = x0[t[2]] - x0[t[0]]
    e11 = x1[t[1]] - x1[t[0]]
    e21 = x1[t[2]] - x1[t[0]]
    l10 = wp.length(e10)
    l20 = wp.length(e20)
    l11 = wp.length(e11)
    l21 = wp.length(e21)
    if not _sees(d, wp.cross(e10, e20), l10 * l20, margin, False):
        return False
    if not _sees(d, wp.cross(e11, e21), l11 * l21, margin, False):
        return False
    nx = 0.5 * (wp.cross(e10, e21) + wp.cross(e11, e20))
    return _sees(d, nx, 0.5 * (l10 * l21 + l11 * l20), margin, True)


@wp.func
def _face_normal(x: wp.array(dtype=wp.vec3), t: wp.vec3i) -> wp.vec3:
    return wp.cross(x[t[1]] - x[t[0]], x[t[2]] - x[t[0]])


@wp.func
def _common_direction(x0: wp.array(dtype=wp.vec3), x1: wp.array(dtype=wp.vec3), swept: int, margin: float,
                      ta: wp.vec3i, tb: wp.vec3i) -> wp.vec3:
    """A direction seeing both faces (at every time of the step for CCD), or zero: the sum of their unit
    normals (at both ends of the step for CCD), checked with :func:`_sees`."""
    zero = wp.vec3(0.0, 0.0, 0.0)
    if swept == 1:
        d = _unit(_face_normal(x0, ta)) + _unit(_face_normal(x0, tb))
        d += _unit(_face_normal(x1, ta)) + _unit(_face_normal(x1, tb))
        if _swept_face_seen(x0, x1, ta, d, margin) and _swept_face_seen(x0, x1, tb, d, margin):
            return d
        return zero
    ea1 = x0[ta[1]] - x0[ta[0]]
    ea2 = x0[ta[2]] - x0[ta[0]]
    eb1 = x0[tb[1]] - x0[tb[0]]
    eb2 = x0[tb[2]] - x0[tb[0]]
    na = wp.cross(ea1, ea2)
    nb = wp.cross(eb1, eb2)
    d = _unit(na) + _unit(nb)
    if (_sees(d, na, wp.length(ea1) * wp.length(ea2), margin, False)
            and _sees(d, nb, wp.length(eb1) * wp.length(eb2), margin, False)):
        return d
    return zero


@wp.func
def _sector_sign(x0: wp.array(dtype=wp.vec3), x1: wp.array(dtype=wp.vec3), swept: int, margin: float, v: int,
                 x: int, y: int, d: wp.vec3) -> float:
    """Strict sign of s(x, y) = d . ((x - v) x (y - v)) at t0 (beyond the margin times
    |d| |x - v| |y - v|), or over the whole step (d then a unit vector); 0 when it is within the
    rounding margin or changes."""
    if swept == 1:
        return nc.swept_signed_area_sign(x0[x], x0[y], x0[v], x1[x], x1[y], x1[v], d, margin)
    p = x0[x] - x0[v]
    q = x0[y] - x0[v]
    value = wp.dot(d, wp.cross(p, q))
    if wp.abs(value) <= margin * wp.length(d) * wp.length(p) * wp.length(q):
        return 0.0
    return wp.sign(value)


@wp.func
def _next(u: int) -> int:
    if u == 2:
        return 0
    return u + 1


@wp.func
def _sign_beyond(value: float, bound: float) -> float:
    """The sign of ``value`` when |value| > ``bound``, else 0."""
    if wp.abs(value) <= bound:
        return 0.0
    return wp.sign(value)


@wp.func
def _certified_at_rest(x: wp.array(dtype=wp.vec3), margin: float, ta: wp.vec3i, tb: wp.vec3i, ua: int, ub: int,
                       edge: bool) -> bool:
    """:func:`certified_in` at rest (DCD), for faces that share vertex ``ta[ua]`` = ``tb[ub]`` (and an edge
    when ``edge``): the same tests as :func:`_common_direction` and :func:`_sector_sign` with every length
    taken once. Both faces' normals are made from their edges at the shared vertex v, so each margin is
    the product of the lengths of the edges from v it is made of (the rounding argument of :func:`_sees`
    holds for any two edges of a face)."""
    v = x[ta[ua]]
    a1 = x[ta[_next(ua)]] - v
    a2 = x[ta[_next(_next(ua))]] - v
    b1 = x[tb[_next(ub)]] - v
    b2 = x[tb[_next(_next(ub))]] - v
    la1 = wp.length(a1)
    la2 = wp.length(a2)
    lb1 = wp.length(b1)
    lb2 = wp.length(b2)
    na = wp.cross(a1, a2)
    nb = wp.cross(b1, b2)
    lna = wp.length(na)
    lnb = wp.length(nb)
    if not (lna > 0.0 and lnb > 0.0):
        return False
    d = na / lna + nb / lnb
    ld = wp.length(d)
    # _sees(d, n, scale, margin, False) for both faces.
    if not wp.dot(d, na) > wp.max(margin * ld * (la1 * la2), _CONE_COS * ld * lna):
        return False
    if not wp.dot(d, nb) > wp.max(margin * ld * (lb1 * lb2), _CONE_COS * ld * lnb):
        return False
    if edge:
        return True
    bound = margin * ld
    w11 = _sign_beyond(wp.dot(d, wp.cross(a1, b1)), bound * la1 * lb1)
    w12 = _sign_beyond(wp.dot(d, wp.cross(b1, a2)), bound * lb1 * la2)
    w21 = _sign_beyond(wp.dot(d, wp.cross(a1, b2)), bound * la1 * lb2)
    w22 = _sign_beyond(wp.dot(d, wp.cross(b2, a2)), bound * lb2 * la2)
    return ((w11 < 0.0 or w12 < 0.0) and (w21 < 0.0 or w22 < 0.0) and (w11 > 0.0 or w21 < 0.0)
            and (w12 < 0.0 or w22 > 0.0))


@wp.func
def certified_in(x0: wp.array(dtype=wp.vec3), x1: wp.array(dtype=wp.vec3), swept: int, margin: float,
                 ta: wp.vec3i, tb: wp.vec3i) -> bool:
    """:func:`shared_pair_certified` with the arguments unpacked (positions at t0 and, when ``swept``
    is 1, at t1; the relative margin), for kernels that read them out of the struct once."""
    shared = int(0)
    ua = int(0)
    ub = int(0)
    edge = False
    for u in range(3):
        for v in range(3):
            if ta[u] == tb[v]:
                shared += 1
                ua = u
                ub = v
                # A's edge ta[u] -> ta[u+1] run backwards in B: tb[v-1] (= tb[v+2]) == ta[u+1].
                if ta[_next(u)] == tb[_next(_next(v))]:
                    edge = True
    if shared == 0 or shared > 2 or (shared == 2 and not edge):
        return False
    if swept == 0:
        return _certified_at_rest(x0, margin, ta, tb, ua, ub, shared == 2)
    d = _common_direction(x0, x1, swept, margin, ta, tb)
    if wp.length_sq(d) == 0.0:
        return False
    if shared == 2:
        return True
    if swept == 1:
        d = wp.normalize(d)
    v = ta[ua]
    a1 = ta[_next(ua)]
    a2 = ta[_next(_next(ua))]
    b1 = tb[_next(ub)]
    b2 = tb[_next(_next(ub))]
    # Four signs decide the four rays (s(x, y) = -s(y, x)):
    # b1 outside A: s(a1, b1) < 0 or s(b1, a2) < 0;  b2 outside A: s(a1, b2) < 0 or s(b2, a2) < 0;
    # a1 outside B: s(a1, b1) > 0 or s(a1, b2) < 0;  a2 outside B: s(b1, a2) < 0 or s(b2, a2) > 0.
    w11 = _sector_sign(x0, x1, swept, margin, v, a1, b1, d)
    w12 = _sector_sign(x0, x1, swept, margin, v, b1, a2, d)
    w21 = _sector_sign(x0, x1, swept, margin, v, a1, b2, d)
    w22 = _sector_sign(x0, x1, swept, margin, v, b2, a2, d)
    return ((w11 < 0.0 or w12 < 0.0) and (w21 < 0.0 or w22 < 0.0) and (w11 > 0.0 or w21 < 0.0)
            and (w12 < 0.0 or w22 > 0.0))


@wp.func
def shared_pair_certified(args: SharedVertexArgs, ta: wp.vec3i, tb: wp.vec3i) -> bool:
    """Whether faces ``ta`` and ``tb`` (vertex ids) are certified to meet only in what they share (see
    the module docstring); False when they share no vertex."""
    return certified_in(args.positions_t0, args.positions_t1, args.swept, args.margin, ta, tb)
