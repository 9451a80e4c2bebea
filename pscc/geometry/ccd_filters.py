"""Filters of the conservative CCD (:mod:`pscc.geometry.ccd`) that exclude a whole query before any search:
the swept-box filter, the motion bound, and the Bernstein sign tests of the moving plane (coplanarity,
plane distance, vertex side). Each is conservative: it excludes only pairs that provably never come
within the requested distance."""

from __future__ import annotations

import warp as wp

from pscc.geometry.ccd_base import DISTANCE_RELATIVE_ERROR, MOTION_MARGIN, CcdParameters

wp.set_module_options({"enable_backward": False})

@wp.func
def _abs_cross(a: wp.vec3, b: wp.vec3) -> wp.vec3:
    """Componentwise |a_y b_z| + |a_z b_y| etc.: the magnitude companion of a cross product."""
    return wp.vec3(
        wp.abs(a[1] * b[2]) + wp.abs(a[2] * b[1]),
        wp.abs(a[2] * b[0]) + wp.abs(a[0] * b[2]),
        wp.abs(a[0] * b[1]) + wp.abs(a[1] * b[0]),
    )



@wp.func
def _abs_dot(a: wp.vec3, b: wp.vec3) -> float:
    return wp.abs(a[0] * b[0]) + wp.abs(a[1] * b[1]) + wp.abs(a[2] * b[2])



@wp.func
def _strict_sign(value: float, magnitude: float, factor: float) -> float:
    """Sign of ``value`` when it exceeds its rounding bound ``factor * magnitude``, else 0."""
    bound = factor * magnitude
    if value > bound:
        return 1.0
    if value < -bound:
        return -1.0
    return 0.0



@wp.func
def coplanarity_sign(
    q0: wp.vec3, e10: wp.vec3, e20: wp.vec3, q1: wp.vec3, e11: wp.vec3, e21: wp.vec3, factor: float
) -> float:
    """Strict sign that (e1(t) x e2(t)) . q(t) keeps over the whole step, or 0 if not provable.

    This coplanarity function is a cubic with Bernstein coefficients k0 = n0.q0,
    3 k1 = 2 nX.q0 + n0.q1, 3 k2 = 2 nX.q1 + n1.q0, k3 = n1.q1 (nX the middle control normal).
    When all four have one strict sign, the cubic keeps that sign on [0, 1]: for q = p - a,
    e1 = a - b, e2 = a - c, the point p stays strictly on one side of the moving plane of (a, b, c).
    Each value is trusted only beyond ``factor x`` its magnitude companion (the same sums of
    products with absolute values): at most 10 roundings separate each value from the exact float32
    input, so its error is below gamma_10 = 10 u times that companion; ``factor`` = 16 u covers it
    (see ``docs/ccd.md``).
    """
    de1 = e11 - e10
    de2 = e21 - e20
    n0 = wp.cross(e10, e20)
    n1 = wp.cross(e11, e21)
    nx = 0.5 * ((n0 + n1) - wp.cross(de1, de2))
    m0 = _abs_cross(e10, e20)
    m1 = _abs_cross(e11, e21)
    mx = 0.5 * ((m0 + m1) + _abs_cross(de1, de2))
    s0 = _strict_sign(wp.dot(n0, q0), _abs_dot(m0, q0), factor)
    if s0 == 0.0:
        return 0.0
    s3 = _strict_sign(wp.dot(n1, q1), _abs_dot(m1, q1), factor)
    if s3 != s0:
        return 0.0
    s1 = _strict_sign(2.0 * wp.dot(nx, q0) + wp.dot(n0, q1), 2.0 * _abs_dot(mx, q0) + _abs_dot(m0, q1), factor)
    if s1 != s0:
        return 0.0
    s2 = _strict_sign(2.0 * wp.dot(nx, q1) + wp.dot(n1, q0), 2.0 * _abs_dot(mx, q1) + _abs_dot(m1, q0), factor)
    if s2 != s0:
        return 0.0
    return s0



@wp.func
def _beyond(value: float, threshold: float, magnitude: float, factor: float, side: float) -> bool:
    """Whether ``side * value`` provably exceeds ``threshold`` (>= 0) despite ``value``'s rounding
    (``factor x magnitude``) and the one rounding of the comparison's subtraction."""
    return side * value - threshold * (1.0 + MOTION_MARGIN) > factor * magnitude * (1.0 + MOTION_MARGIN)



@wp.func
def plane_keeps_distance(
    q0: wp.vec3, e10: wp.vec3, e20: wp.vec3, q1: wp.vec3, e11: wp.vec3, e21: wp.vec3, distance: float,
    factor: float,
) -> bool:
    """True when q(t) stays farther than ``distance`` from the moving plane spanned by e1(t) and e2(t)
    over the whole step (the deforming non-penetration filter of Tang et al. 2010, with a distance).

    The plane's distance is (n . q) / |n| with n(t) = e1(t) x e2(t), a quadratic whose Bernstein control
    points are n0, nX, n1, so |n(t)| <= N = max(|n0|, |nX|, |n1|) (each grown by its rounding bound);
    n . q is the cubic of :func:`coplanarity_sign` with Bernstein coefficients k0..k3. If every k_i
    exceeds ``distance x N`` with one sign, then |n . q| > distance |n| for every t in [0, 1]. The point
    (vertex-face) or the line (edge-edge) then stays farther than ``distance`` from the plane holding the
    triangle (the other line), so from the triangle (the other edge). Each k_i is trusted beyond
    ``factor x`` its magnitude companion, as in :func:`coplanarity_sign`.
    """
    de1 = e11 - e10
    de2 = e21 - e20
    n0 = wp.cross(e10, e20)
    n1 = wp.cross(e11, e21)
    nx = 0.5 * ((n0 + n1) - wp.cross(de1, de2))
    m0 = _abs_cross(e10, e20)
    m1 = _abs_cross(e11, e21)
    mx = 0.5 * ((m0 + m1) + _abs_cross(de1, de2))
    normal_bound = wp.max(wp.length(n0) + factor * wp.length(m0),
                          wp.max(wp.length(nx) + factor * wp.length(mx), wp.length(n1) + factor * wp.length(m1)))
    reach = distance * normal_bound * (1.0 + MOTION_MARGIN)
    value0 = wp.dot(n0, q0)
    side = float(1.0)
    if value0 < 0.0:
        side = -1.0
    if not _beyond(value0, reach, _abs_dot(m0, q0), factor, side):
        return False
    if not _beyond(wp.dot(n1, q1), reach, _abs_dot(m1, q1), factor, side):
        return False
    if not _beyond(2.0 * wp.dot(nx, q0) + wp.dot(n0, q1), 3.0 * reach, 2.0 * _abs_dot(mx, q0) + _abs_dot(m0, q1),
                   factor, side):
        return False
    return _beyond(2.0 * wp.dot(nx, q1) + wp.dot(n1, q0), 3.0 * reach, 2.0 * _abs_dot(mx, q1) + _abs_dot(m1, q0),
                   factor, side)



@wp.func
def never_coplanar(
    q0: wp.vec3, e10: wp.vec3, e20: wp.vec3, q1: wp.vec3, e11: wp.vec3, e21: wp.vec3, factor: float
) -> bool:
    """True when the four points provably never become coplanar during the step."""
    return coplanarity_sign(q0, e10, e20, q1, e11, e21, factor) != 0.0



@wp.func
def vertex_plane_side(
    p_t0: wp.vec3,
    a_t0: wp.vec3,
    b_t0: wp.vec3,
    c_t0: wp.vec3,
    p_t1: wp.vec3,
    a_t1: wp.vec3,
    b_t1: wp.vec3,
    c_t1: wp.vec3,
    params: CcdParameters,
) -> float:
    """+1 or -1 when vertex p provably stays strictly on that side of the moving plane of triangle
    (a, b, c) during the whole step (coordinates translated to ``a_t0`` first), else 0."""
    r = a_t0
    ya0 = a_t0 - r
    ya1 = a_t1 - r
    return coplanarity_sign((p_t0 - r) - ya0, ya0 - (b_t0 - r), ya0 - (c_t0 - r),
                            (p_t1 - r) - ya1, ya1 - (b_t1 - r), ya1 - (c_t1 - r), params.coplanarity_factor)



@wp.func
def features_apart(
    lo_a: wp.vec3, hi_a: wp.vec3, lo_b: wp.vec3, hi_b: wp.vec3, extra_error: float, minimum_distance: float
) -> bool:
    """Swept-box exclusion (module docstring): True when boxes [lo_a, hi_a] and [lo_b, hi_b] of two
    features' start and end positions are provably farther apart than ``minimum_distance``.

    Each axis gap is computed with one rounding (relative error at most 2^-24), reduced by twice the
    input rounding ``extra_error`` (with the margin), squared and summed (a few more roundings); the
    relative margin :data:`MOTION_MARGIN` (1e-5) covers them all. Coordinates must be finite, as
    for the whole CCD (the host API refuses others; the broad phase flags their boxes).
    """
    slack = 2.0 * extra_error * (1.0 + MOTION_MARGIN)
    gap_squared = float(0.0)
    for k in range(3):
        d = wp.max(wp.max(lo_b[k] - hi_a[k], lo_a[k] - hi_b[k]) - slack, 0.0)
        gap_squared += d * d
    return gap_squared > minimum_distance * minimum_distance * (1.0 + MOTION_MARGIN)



@wp.func
def largest_motion(q0: wp.vec3, e10: wp.vec3, e20: wp.vec3, q1: wp.vec3, e11: wp.vec3, e21: wp.vec3,
                    triangle_domain: int) -> float:
    """max over the (u, v) domain of |F(1, u, v) - F(0, u, v)|: dF is linear in (u, v) and |dF| convex, so
    the maximum is at a corner of the domain (three for a triangle, four for the unit square)."""
    motion00 = q1 - q0
    motion10 = motion00 + (e11 - e10)
    motion01 = motion00 + (e21 - e20)
    motion = wp.max(wp.length(motion00), wp.max(wp.length(motion10), wp.length(motion01)))
    if triangle_domain == 0:
        motion = wp.max(motion, wp.length(motion10 + (e21 - e20)))
    return motion



@wp.func
def motion_cannot_reach(
    distance_squared_t0: float,
    q0: wp.vec3,
    e10: wp.vec3,
    e20: wp.vec3,
    q1: wp.vec3,
    e11: wp.vec3,
    e21: wp.vec3,
    triangle_domain: int,
    err: wp.vec3,
    scale: float,
    minimum_distance: float,
) -> bool:
    """Motion-bound exclusion: True when the pair provably stays farther than ``minimum_distance``.

    With F(t, u, v) = F0(u, v) + t dF(u, v), |F| >= dist_t0 - max |dF| for t in [0, 1], and |dF| is
    convex and linear in (u, v), so its maximum over the domain is at a corner. ``dist_t0`` is bounded
    from below by the float32 distance minus the distance functions' documented error
    (``ILL_CONDITIONED_REL_ERROR + 16 EPS32`` times the local scale) and the rounding bound of F;
    |dF| is bounded from above by its corner values plus twice that rounding bound, with a relative
    margin. A resting or slowly moving pair whose gap exceeds its motion is thus excluded without the
    box search (the costly case of grazing contacts); any pair that could come within
    ``minimum_distance`` is left to the search.
    """
    slack = wp.length(err)
    lower = wp.sqrt(wp.max(distance_squared_t0, 0.0)) - DISTANCE_RELATIVE_ERROR * scale - 2.0 * slack
    motion = largest_motion(q0, e10, e20, q1, e11, e21, triangle_domain)
    reach = (motion + 2.0 * slack) * (1.0 + MOTION_MARGIN)
    return lower - reach > minimum_distance * (1.0 + MOTION_MARGIN)
