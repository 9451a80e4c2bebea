"""Conservative continuous collision detection (CCD) for vertex-face and edge-edge pairs.

Vertices move linearly over the step, x(t) = (1 - t) x_t0 + t x_t1 with t in [0, 1]. Both primitive
pairs reduce to the roots of one multilinear function of three parameters (the formulation of
Tight Inclusion, Wang et al. 2021):

- vertex-face (p; a, b, c):   F(t, u, v) = (p - a) + u (a - b) + v (a - c),  u, v >= 0, u + v <= 1
- edge-edge (a0 a1; b0 b1):   F(t, u, v) = (a0 - b0) + u (a1 - a0) + v (b0 - b1),  u, v in [0, 1]

with every point taken at time t. The pair comes within distance ``d_min`` at time t exactly when
|F(t, u, v)| <= d_min for some admissible (u, v). F is linear in each parameter separately, so over
a box of parameters its values lie in the bounding box of its 8 corner values.

**Swept-box filter.** First of all, a pair is excluded when the bounding boxes of its two features'
start and end positions are farther apart than ``d_min``. A vertex moving linearly stays in the box of
its start and end, so every point of a feature stays in its box over the whole step, and the distance
between the boxes bounds the distance of the features from below. The boxes are taken on the input
coordinates (minimum and maximum are exact), each axis gap is reduced by twice the input rounding
``extra_error`` and the comparison carries a relative margin far above float32 rounding, so a pair that
could come within ``d_min`` is never excluded. This is the common case of a step's candidates: the broad
phase pairs features whose boxes come within the thickness h, and the CCD tests the much smaller
``d_min``; the test costs a few comparisons where the distance below costs tens of operations.

**Motion-bound filter.** Next, a pair is excluded when its distance at t0, bounded
from below with the distance functions' documented float32 error, exceeds ``d_min`` plus the largest
motion of F over the step (|F(t)| >= |F(0)| - max |F(1) - F(0)|, the maximum taken at the corners of
the (u, v) domain). Resting and slowly moving pairs, the grazing queries that cost the search the most
boxes, end here.

**Plane filter** (minimum distance > 0). Then a pair is excluded when its first feature provably stays
farther than ``d_min`` from the moving plane of the second (:func:`plane_keeps_distance`, docs/ccd.md).

**Conservative advancement** (minimum distance > 0 with the distance tolerance
:data:`pscc.tolerances.CCD_DISTANCE_TOLERANCE` on, for a pair that starts clear of the tolerance's band).
For fixed (u, v), F is linear in t, so the pair's distance at time s is at least its distance at t minus
|s - t| times the largest |dF/dt| (a corner value). Starting at t = 0, every step bounds the distance
from below with the closest-point functions of :mod:`pscc.geometry.distance` (their documented error and
``err`` subtracted), excludes the time that distance minus ``d_min`` buys at that speed and jumps there.
It reports a contact at t once the bound is within half the tolerance of ``d_min``, ``NO_HIT`` once the
rest of the step is excluded, and hands the rest of the step to the search below after
:data:`pscc.tolerances.CCD_ADVANCE_STEPS` steps. A reported time is a lower bound of the first contact,
and the pair is then within ``d_min (1 + tolerance)`` of touching. On a late `twisting` frame this decides
the pairs that come within ``d_min`` in 3-5 µs each where the search took 50-150 µs.

**Search.** A depth-first search over (t, u, v) boxes with a fixed per-thread stack. A box is
*excluded* when the bounding box of its corner values, grown by the rounding bound ``err``, stays
farther than ``d_min`` from the origin (Euclidean). Boxes are split along the parameter whose
change moves F the most; the earlier half in t is searched first, and once a collision time
``toi`` is known every box starting at or after it is skipped. A box that is too small to split
(see :mod:`pscc.tolerances`) is reported as a collision at its start time. If the stack or the box
budget runs out, the search stops and reports the earliest start time among the boxes not yet
excluded. Hence:

- a pair that truly comes within ``d_min`` is never missed, and
- the reported time of impact is never later than the true first time of contact,

provided ``err`` bounds the float32 rounding of F. That bound is derived in
:data:`pscc.tolerances.CCD_ROUNDING_FACTOR`: per axis, ``err = 80 u M`` where u = 2^-24 and M is
the largest coordinate magnitude after translating the query to its first point. The host
wrappers add the rounding of float64 input to float32 when the input is not exactly float32, so
the answer is conservative for the input as given.

Every function here runs unchanged on CUDA and on the CPU.
"""

from __future__ import annotations

import numpy as np
import warp as wp

from pscc import tolerances
from pscc._checks import check_nonnegative, check_points
from pscc.geometry import distance_tolerances
from pscc.geometry.distance import edge_edge_distance_squared, vertex_face_distance_squared

wp.set_module_options({"enable_backward": False})

_STACK = tolerances.CCD_STACK_SIZE
_stack_vector = wp.types.vector(length=_STACK, dtype=wp.float32)

NO_HIT: float = 2.0
"""Value the device functions return as time of impact when there is no collision."""


@wp.struct
class CcdParameters:
    """Tolerances of the CCD search (see :mod:`pscc.tolerances`), passed to every CCD kernel."""

    rounding_factor: wp.float32
    codomain_tolerance: wp.float32
    min_parameter_width: wp.float32
    comparison_margin: wp.float32
    max_boxes: wp.int32
    coplanarity_factor: wp.float32
    toi_tolerance: wp.float32
    plane_filter: wp.int32
    distance_tolerance: wp.float32


def ccd_parameters() -> CcdParameters:
    """Return the default :class:`CcdParameters` filled from :mod:`pscc.tolerances`."""
    params = CcdParameters()
    params.rounding_factor = tolerances.CCD_ROUNDING_FACTOR * tolerances.FLOAT32_UNIT_ROUNDOFF
    params.codomain_tolerance = tolerances.CCD_CODOMAIN_TOLERANCE
    params.min_parameter_width = tolerances.CCD_MIN_PARAMETER_WIDTH
    params.comparison_margin = tolerances.DISTANCE_COMPARISON_MARGIN
    params.max_boxes = tolerances.CCD_MAX_BOXES
    params.coplanarity_factor = tolerances.COPLANARITY_ROUNDING_FACTOR * tolerances.FLOAT32_UNIT_ROUNDOFF
    params.toi_tolerance = tolerances.CCD_TOI_TOLERANCE
    params.plane_filter = 1
    params.distance_tolerance = tolerances.CCD_DISTANCE_TOLERANCE
    return params


@wp.func
def _abs_max(m: wp.vec3, x: wp.vec3) -> wp.vec3:
    return wp.vec3(wp.max(m[0], wp.abs(x[0])), wp.max(m[1], wp.abs(x[1])), wp.max(m[2], wp.abs(x[2])))


@wp.func
def _lerp(x0: wp.vec3, x1: wp.vec3, t: float) -> wp.vec3:
    # x0 + t (x1 - x0): the evaluation order the rounding bound was derived for.
    return x0 + t * (x1 - x0)


@wp.func
def _gap_squared(lo: wp.vec3, hi: wp.vec3, err: wp.vec3) -> float:
    """Squared distance from the origin to the box [lo - err, hi + err]."""
    g = float(0.0)
    for k in range(3):
        below = lo[k] - err[k]
        above = -(hi[k] + err[k])
        d = wp.max(wp.max(below, above), 0.0)
        g += d * d
    return g


@wp.func
def _largest_change(
    a0: wp.vec3, a1: wp.vec3, b0: wp.vec3, b1: wp.vec3, c0: wp.vec3, c1: wp.vec3, d0: wp.vec3, d1: wp.vec3
) -> float:
    """Largest |component| of the differences x1 - x0 over four corner pairs along one parameter."""
    m = wp.max(wp.max(wp.abs(a1 - a0), wp.abs(b1 - b0)), wp.max(wp.abs(c1 - c0), wp.abs(d1 - d0)))
    return wp.max(m[0], wp.max(m[1], m[2]))


@wp.func
def _best_half_gap(
    a0: wp.vec3,
    a1: wp.vec3,
    b0: wp.vec3,
    b1: wp.vec3,
    c0: wp.vec3,
    c1: wp.vec3,
    d0: wp.vec3,
    d1: wp.vec3,
    err: wp.vec3,
) -> float:
    """Larger squared gap of the two halves of a box split between the corner pairs (x0, x1).

    Used only to choose the split (a heuristic): exclusion always re-evaluates F.
    """
    ma = 0.5 * (a0 + a1)
    mb = 0.5 * (b0 + b1)
    mc = 0.5 * (c0 + c1)
    md = 0.5 * (d0 + d1)
    mid_lo = wp.min(wp.min(ma, mb), wp.min(mc, md))
    mid_hi = wp.max(wp.max(ma, mb), wp.max(mc, md))
    low_lo = wp.min(mid_lo, wp.min(wp.min(a0, b0), wp.min(c0, d0)))
    low_hi = wp.max(mid_hi, wp.max(wp.max(a0, b0), wp.max(c0, d0)))
    high_lo = wp.min(mid_lo, wp.min(wp.min(a1, b1), wp.min(c1, d1)))
    high_hi = wp.max(mid_hi, wp.max(wp.max(a1, b1), wp.max(c1, d1)))
    return wp.max(_gap_squared(low_lo, low_hi, err), _gap_squared(high_lo, high_hi, err))


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
    return side * value - threshold * (1.0 + _MOTION_MARGIN) > factor * magnitude * (1.0 + _MOTION_MARGIN)


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
    reach = distance * normal_bound * (1.0 + _MOTION_MARGIN)
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
def _never_coplanar(
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
def _direction_separates(
    d: wp.vec3,
    f000: wp.vec3,
    f010: wp.vec3,
    f001: wp.vec3,
    f011: wp.vec3,
    f100: wp.vec3,
    f110: wp.vec3,
    f101: wp.vec3,
    f111: wp.vec3,
    lo: wp.vec3,
    hi: wp.vec3,
    err: wp.vec3,
    minimum_distance: float,
    params: CcdParameters,
) -> bool:
    """True when every corner projects onto ``d`` beyond ``minimum_distance |d|``, with bounds.

    The exact corner values differ from the computed ones by at most ``err`` per axis, and each
    computed projection (3 products, 2 sums) by at most 4 u times sum |d_k| max|f_k|; both are
    subtracted before the comparison (4 u is written as 2^-22).
    """
    m = wp.min(wp.min(wp.min(wp.dot(d, f000), wp.dot(d, f010)), wp.min(wp.dot(d, f001), wp.dot(d, f011))),
               wp.min(wp.min(wp.dot(d, f100), wp.dot(d, f110)), wp.min(wp.dot(d, f101), wp.dot(d, f111))))
    if m <= 0.0:
        return False
    magnitude = wp.max(wp.abs(lo), wp.abs(hi))
    slack = float(0.0)
    for k in range(3):
        slack += wp.abs(d[k]) * (err[k] + 2.384185791015625e-07 * magnitude[k])
    bound = minimum_distance * wp.length(d) * (1.0 + params.comparison_margin)
    return (m - slack) * (1.0 - params.comparison_margin) > bound


@wp.func
def _root_gap_squared(q0: wp.vec3, e10: wp.vec3, e20: wp.vec3, q1: wp.vec3, e11: wp.vec3, e21: wp.vec3,
                      err: wp.vec3) -> float:
    """Squared gap of the whole (t, u, v) in [0, 1]^3 box, evaluated exactly as the search does."""
    qa = _lerp(q0, q1, 0.0)
    qb = _lerp(q0, q1, 1.0)
    e1a = _lerp(e10, e11, 0.0)
    e1b = _lerp(e10, e11, 1.0)
    e2a = _lerp(e20, e21, 0.0)
    e2b = _lerp(e20, e21, 1.0)
    lo = wp.min(wp.min(qa, qa + e1a), wp.min(qa + e2a, qa + e1a + e2a))
    hi = wp.max(wp.max(qa, qa + e1a), wp.max(qa + e2a, qa + e1a + e2a))
    lo = wp.min(lo, wp.min(wp.min(qb, qb + e1b), wp.min(qb + e2b, qb + e1b + e2b)))
    hi = wp.max(hi, wp.max(wp.max(qb, qb + e1b), wp.max(qb + e2b, qb + e1b + e2b)))
    return _gap_squared(lo, hi, err)


@wp.func
def _ccd_search(
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
    distance_tolerance: float,
    t_start: float,
    params: CcdParameters,
) -> float:
    """Earliest t >= ``t_start`` at which |q(t) + u e1(t) + v e2(t)| <= d_min may hold; ``NO_HIT`` if never
    (earlier times must be excluded already).

    q, e1, e2 are given at t = 0 and t = 1 and are evaluated at t by the exact expressions the
    rounding bound assumes. ``triangle_domain`` = 1 restricts (u, v) to u + v <= 1.
    ``distance_tolerance`` is this query's :data:`~pscc.tolerances.CCD_DISTANCE_TOLERANCE` (0: exact
    refinement).
    """
    ms_sq = minimum_distance * minimum_distance * (1.0 + params.comparison_margin)
    # Most candidate pairs are excluded by the whole box already: test it before building the stack.
    if _root_gap_squared(q0, e10, e20, q1, e11, e21, err) * (1.0 - params.comparison_margin) > ms_sq:
        return 2.0
    stack_t0 = _stack_vector()
    stack_t1 = _stack_vector()
    stack_u0 = _stack_vector()
    stack_u1 = _stack_vector()
    stack_v0 = _stack_vector()
    stack_v1 = _stack_vector()
    stack_t0[0] = t_start
    stack_t1[0] = 1.0
    stack_u0[0] = 0.0
    stack_u1[0] = 1.0
    stack_v0[0] = 0.0
    stack_v1[0] = 1.0
    count = int(1)
    best = float(2.0)
    boxes = int(0)
    tolerance = params.codomain_tolerance * scale
    # With d_min > 0 a box whose image is below a fraction of d_min is only refined in t, down to the
    # time-of-impact tolerance (its reported start time stays that close to the box's contact).
    coarse_tolerance = wp.max(tolerance, distance_tolerance * minimum_distance)
    min_width = params.min_parameter_width

    while count > 0:
        count -= 1
        t0 = stack_t0[count]
        t1 = stack_t1[count]
        u0 = stack_u0[count]
        u1 = stack_u1[count]
        v0 = stack_v0[count]
        v1 = stack_v1[count]
        if t0 >= best:
            continue
        if best <= 1.0 and t0 >= best - params.toi_tolerance:
            # A contact is already known; this box could only move it earlier by less than the
            # time-of-impact tolerance, so report the box's start instead of refining it.
            best = t0
            continue
        # Only times before the best collision found so far still matter.
        t1 = wp.min(t1, best)
        if triangle_domain == 1 and u0 + v0 > 1.0:
            continue
        boxes += 1
        if boxes > params.max_boxes:
            # Budget spent: report the earliest time not yet excluded (conservative).
            best = wp.min(best, t0)
            for s in range(count):
                best = wp.min(best, stack_t0[s])
            count = 0
            continue

        # F at the 8 corners, named f_<t><u><v> with 0 = lower and 1 = upper end of the range.
        qa = _lerp(q0, q1, t0)
        qb = _lerp(q0, q1, t1)
        e1a = _lerp(e10, e11, t0)
        e1b = _lerp(e10, e11, t1)
        e2a = _lerp(e20, e21, t0)
        e2b = _lerp(e20, e21, t1)
        f000 = qa + u0 * e1a + v0 * e2a
        f010 = qa + u1 * e1a + v0 * e2a
        f001 = qa + u0 * e1a + v1 * e2a
        f011 = qa + u1 * e1a + v1 * e2a
        f100 = qb + u0 * e1b + v0 * e2b
        f110 = qb + u1 * e1b + v0 * e2b
        f101 = qb + u0 * e1b + v1 * e2b
        f111 = qb + u1 * e1b + v1 * e2b
        lo_a = wp.min(wp.min(f000, f010), wp.min(f001, f011))
        lo = wp.min(lo_a, wp.min(wp.min(f100, f110), wp.min(f101, f111)))
        hi_a = wp.max(wp.max(f000, f010), wp.max(f001, f011))
        hi = wp.max(hi_a, wp.max(wp.max(f100, f110), wp.max(f101, f111)))

        gap_sq = _gap_squared(lo, hi, err)
        if gap_sq * (1.0 - params.comparison_margin) > ms_sq:
            continue  # certainly farther than d_min everywhere in this box
        # The image of F over the box lies in the convex hull of its 8 corner values (F is
        # multilinear), so any direction d whose corner projections all exceed d_min |d| separates
        # the box from the origin. d = F at the box centre sees gaps along tilted directions that
        # the axis-aligned test above misses.
        d = 0.125 * (((f000 + f010) + (f001 + f011)) + ((f100 + f110) + (f101 + f111)))
        if _direction_separates(d, f000, f010, f001, f011, f100, f110, f101, f111, lo, hi, err, minimum_distance,
                                params):
            continue

        width = hi - lo
        small = width[0] <= tolerance and width[1] <= tolerance and width[2] <= tolerance
        # Largest change of F along each parameter (F is linear in each one).
        change_t = _largest_change(f000, f100, f010, f110, f001, f101, f011, f111)
        coarse = width[0] <= coarse_tolerance and width[1] <= coarse_tolerance and width[2] <= coarse_tolerance
        if coarse and ((t1 - t0) <= params.toi_tolerance or change_t == 0.0):
            small = True  # (F constant in t: a contact in the box is there at t0 already)
        change_u = _largest_change(f000, f010, f100, f110, f001, f011, f101, f111)
        change_v = _largest_change(f000, f001, f100, f101, f010, f011, f110, f111)
        can_t = (t1 - t0) > min_width and change_t > 0.0
        can_u = (u1 - u0) > min_width and change_u > 0.0
        can_v = (v1 - v0) > min_width and change_v > 0.0
        if small or not (can_t or can_u or can_v) or count + 2 > _STACK:
            best = wp.min(best, t0)  # cannot exclude and cannot (or need not) refine: collision
            continue

        # Choose the split: t when one of its halves can be excluded at once (the halves' corner
        # values are averages of the parent's, as F is linear in t), else the parameter that
        # moves F the most.
        axis = int(-1)
        biggest = float(-1.0)
        if coarse and (t1 - t0) > params.toi_tolerance:
            axis = 0  # small enough in F: only its start time is still too coarse
        elif can_t:
            gain_t = _best_half_gap(f000, f100, f010, f110, f001, f101, f011, f111, err)
            if gain_t * (1.0 - params.comparison_margin) > ms_sq:
                axis = 0
        if axis < 0:
            if can_t and change_t > biggest:
                axis = 0
                biggest = change_t
            if can_u and change_u > biggest:
                axis = 1
                biggest = change_u
            if can_v and change_v > biggest:
                axis = 2
                biggest = change_v
        # Push the later half first so the earlier one is searched first.
        for half in range(2):
            nt0 = t0
            nt1 = t1
            nu0 = u0
            nu1 = u1
            nv0 = v0
            nv1 = v1
            if axis == 0:
                mid = 0.5 * (t0 + t1)
                if half == 0:
                    nt0 = mid
                else:
                    nt1 = mid
            elif axis == 1:
                mid = 0.5 * (u0 + u1)
                if half == 0:
                    nu0 = mid
                else:
                    nu1 = mid
            else:
                mid = 0.5 * (v0 + v1)
                if half == 0:
                    nv0 = mid
                else:
                    nv1 = mid
            stack_t0[count] = nt0
            stack_t1[count] = nt1
            stack_u0[count] = nu0
            stack_u1[count] = nu1
            stack_v0[count] = nv0
            stack_v1[count] = nv1
            count += 1
    return best


@wp.func
def _query_error(scale_axes: wp.vec3, extra_error: float, params: CcdParameters) -> wp.vec3:
    """Per-axis bound on |F_float32 - F_exact| for a query of per-axis magnitude ``scale_axes``."""
    return params.rounding_factor * scale_axes + wp.vec3(extra_error, extra_error, extra_error)


_DISTANCE_RELATIVE_ERROR = wp.constant(distance_tolerances.ILL_CONDITIONED_REL_ERROR
                                       + distance_tolerances.DISTANCE_ERROR_CONST * distance_tolerances.EPS32)
_MOTION_MARGIN = wp.constant(1.0e-5)
_SQRT3 = wp.constant(1.7320508)
_WELL_SHAPED_DISTANCE_ERROR = wp.constant(distance_tolerances.DISTANCE_ERROR_CONST * distance_tolerances.EPS32)
_ADVANCE_STEPS = wp.constant(tolerances.CCD_ADVANCE_STEPS)
_WELL_SHAPED_FLATNESS_CHECK = wp.constant(2.0 * distance_tolerances.WELL_SHAPED_MIN_FLATNESS)


@wp.func
def _features_apart(
    lo_a: wp.vec3, hi_a: wp.vec3, lo_b: wp.vec3, hi_b: wp.vec3, extra_error: float, minimum_distance: float
) -> bool:
    """Swept-box exclusion (module docstring): True when boxes [lo_a, hi_a] and [lo_b, hi_b] of two
    features' start and end positions are provably farther apart than ``minimum_distance``.

    Each axis gap is computed with one rounding (relative error at most 2^-24), reduced by twice the
    input rounding ``extra_error`` (with the margin), squared and summed (a few more roundings); the
    relative margin :data:`_MOTION_MARGIN` (1e-5) covers them all. Coordinates must be finite, as
    for the whole CCD (the host API refuses others; the broad phase flags their boxes).
    """
    slack = 2.0 * extra_error * (1.0 + _MOTION_MARGIN)
    gap_squared = float(0.0)
    for k in range(3):
        d = wp.max(wp.max(lo_b[k] - hi_a[k], lo_a[k] - hi_b[k]) - slack, 0.0)
        gap_squared += d * d
    return gap_squared > minimum_distance * minimum_distance * (1.0 + _MOTION_MARGIN)


@wp.func
def _largest_motion(q0: wp.vec3, e10: wp.vec3, e20: wp.vec3, q1: wp.vec3, e11: wp.vec3, e21: wp.vec3,
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
def _motion_cannot_reach(
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
    lower = wp.sqrt(wp.max(distance_squared_t0, 0.0)) - _DISTANCE_RELATIVE_ERROR * scale - 2.0 * slack
    motion = _largest_motion(q0, e10, e20, q1, e11, e21, triangle_domain)
    reach = (motion + 2.0 * slack) * (1.0 + _MOTION_MARGIN)
    return lower - reach > minimum_distance * (1.0 + _MOTION_MARGIN)


@wp.func
def _distance_error(e1: wp.vec3, e2: wp.vec3, triangle_domain: int, scale: float) -> float:
    """How far the float32 distance of :mod:`pscc.geometry.distance` may exceed the exact distance of its
    input, for F = q + u e1 + v e2 seen as a point and a triangle (q against 0, -e1, -e2) or as two segments
    (q to q + e1 against 0 to -e2).

    Its documented bounds: ``DISTANCE_ERROR_CONST EPS32 L`` for edge pairs and for well-shaped triangles
    (flatness |e1 x e2|^2 / longest edge^4 at least ``WELL_SHAPED_MIN_FLATNESS``, here required twice over so
    that the float32 flatness cannot pass a triangle that is not), ``ILL_CONDITIONED_REL_ERROR L`` for the
    others. L <= 4 ``scale``: every coordinate of q, e1, e2 is a difference of two coordinates of at most
    ``scale``.
    """
    if triangle_domain == 1:
        n = wp.cross(e1, e2)
        e3 = e1 - e2
        longest = wp.max(wp.dot(e1, e1), wp.max(wp.dot(e2, e2), wp.dot(e3, e3)))
        if not (wp.dot(n, n) >= _WELL_SHAPED_FLATNESS_CHECK * longest * longest):
            return _DISTANCE_RELATIVE_ERROR * 4.0 * scale
    return _WELL_SHAPED_DISTANCE_ERROR * 4.0 * scale


@wp.func
def _distance_at(q: wp.vec3, e1: wp.vec3, e2: wp.vec3, triangle_domain: int) -> float:
    """The float32 min |F| over the (u, v) domain (see :func:`_distance_error` for the two views)."""
    zero = wp.vec3(0.0, 0.0, 0.0)
    distance_squared = float(0.0)
    if triangle_domain == 1:
        distance_squared = vertex_face_distance_squared(q, zero, -e1, -e2)
    else:
        distance_squared = edge_edge_distance_squared(q, q + e1, zero, -e2)
    return wp.sqrt(wp.max(distance_squared, 0.0))


@wp.func
def _advance_to_contact(
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
    distance_tolerance: float,
) -> float:
    """Conservative advancement in t (with a distance tolerance): the first time the pair may come within
    ``minimum_distance``, or ``NO_HIT``, or ``-1 - t`` when undecided after ``_ADVANCE_STEPS`` steps (all of
    [0, t) is then excluded).

    For fixed (u, v), F is linear in t, so min |F| at time s is at least the lower bound D(t) at time t
    minus |s - t| times the largest |dF/dt| over the domain (a corner value, see
    :func:`_motion_cannot_reach`, grown by twice the rounding bound). Every step therefore excludes
    [t, t + (D(t) - d_min) / speed) and jumps to its end. The advancement stops with a contact at t once
    D(t) is within half the tolerance of d_min: the exact distance at t is then below
    ``d_min (1 + distance_tolerance)`` (the bound's own error is required to be below a quarter of the
    tolerance, else the search is left to the boxes). The reported t is a lower bound of the first contact,
    as for a box the search reports at its start.
    """
    slack = wp.length(err)
    motion = _largest_motion(q0, e10, e20, q1, e11, e21, triangle_domain)
    speed = (motion + 2.0 * slack) * (1.0 + _MOTION_MARGIN)
    floor = minimum_distance * (1.0 + _MOTION_MARGIN)
    band = 0.5 * distance_tolerance * minimum_distance
    t = float(0.0)
    for _step in range(_ADVANCE_STEPS):
        q = _lerp(q0, q1, t)
        e1 = _lerp(e10, e11, t)
        e2 = _lerp(e20, e21, t)
        # The float32 distance errs by the distance function's bound, and its input differs from the exact
        # F by the rounding bound err (counted twice, as in _motion_cannot_reach). That error must leave
        # room in the band, else the boxes take over from t.
        error = _distance_error(e1, e2, triangle_domain, scale) + 2.0 * slack
        if 2.0 * error > band:
            return -1.0 - t
        gap = _distance_at(q, e1, e2, triangle_domain) - error - floor
        if gap <= band:
            return t
        if gap >= speed * (1.0 - t):
            return 2.0  # the rest of the step is excluded at once (also when nothing moves)
        # [t, t + gap / speed) is excluded; shortened by a relative 1e-5 against the rounding of the sum.
        t = t + (gap / speed) * (1.0 - _MOTION_MARGIN)
    return -1.0 - t


@wp.func
def _query_distance_tolerance(distance_squared_t0: float, err: wp.vec3, scale: float, minimum_distance: float,
                              params: CcdParameters) -> float:
    """The distance tolerance of one query: ``params.distance_tolerance``, or 0 when the pair may start
    inside the band the tolerance leaves ambiguous.

    A coarse box is reported when it is within about ``d_min (1 + tol sqrt 3)``; a pair that starts that
    close (but farther than d_min) would be reported at t = 0 whatever the response does to its end
    positions, round after round. So a pair whose start distance is not provably above
    ``d_min (1 + 2 tol sqrt 3)`` (lower bound as in :func:`_motion_cannot_reach`) is refined exactly, and
    the tolerance only speeds up pairs that start clear of the band.
    """
    tolerance = params.distance_tolerance
    if tolerance > 0.0:
        lower = wp.sqrt(wp.max(distance_squared_t0, 0.0)) - _DISTANCE_RELATIVE_ERROR * scale - 2.0 * wp.length(err)
        if lower <= minimum_distance * (1.0 + 1.0 * _SQRT3 * tolerance) * (1.0 + _MOTION_MARGIN):
            tolerance = 0.0
    return tolerance


@wp.func
def _ccd_from_differences(
    q0: wp.vec3,
    e10: wp.vec3,
    e20: wp.vec3,
    q1: wp.vec3,
    e11: wp.vec3,
    e21: wp.vec3,
    triangle_domain: int,
    magnitude: wp.vec3,
    extra_error: float,
    minimum_distance: float,
    distance_squared_t0: float,
    params: CcdParameters,
) -> float:
    """Shared tail of the two CCD functions: rounding bound, motion-bound and coplanarity filters,
    then the search.

    ``magnitude`` is the per-axis largest |translated coordinate| of the query (M in the bound);
    ``distance_squared_t0`` the float32 squared distance of the pair at t0 (translated points).
    """
    err = _query_error(magnitude, extra_error, params)
    scale = wp.max(magnitude[0], wp.max(magnitude[1], magnitude[2]))
    if _motion_cannot_reach(distance_squared_t0, q0, e10, e20, q1, e11, e21, triangle_domain, err, scale,
                            minimum_distance):
        return 2.0
    if minimum_distance == 0.0 and extra_error == 0.0:
        if _never_coplanar(q0, e10, e20, q1, e11, e21, params.coplanarity_factor):
            return 2.0
    elif params.plane_filter != 0:
        # F_exact differs from F evaluated on the float inputs by at most |err| (twice, as in the motion bound).
        if plane_keeps_distance(q0, e10, e20, q1, e11, e21,
                                minimum_distance * (1.0 + _MOTION_MARGIN) + 2.0 * wp.length(err),
                                params.coplanarity_factor):
            return 2.0
    distance_tolerance = _query_distance_tolerance(distance_squared_t0, err, scale, minimum_distance, params)
    t_start = float(0.0)
    if distance_tolerance > 0.0:
        t_start = _advance_to_contact(q0, e10, e20, q1, e11, e21, triangle_domain, err, scale, minimum_distance,
                                      distance_tolerance)
        if t_start >= 0.0:
            return t_start  # a contact (or NO_HIT, 2.0) decided by the advancement
        t_start = -t_start - 1.0  # undecided: the box search goes on from there
    return _ccd_search(q0, e10, e20, q1, e11, e21, triangle_domain, err, scale, minimum_distance,
                       distance_tolerance, t_start, params)


@wp.func
def vertex_face_ccd_toi(
    p_t0: wp.vec3,
    a_t0: wp.vec3,
    b_t0: wp.vec3,
    c_t0: wp.vec3,
    p_t1: wp.vec3,
    a_t1: wp.vec3,
    b_t1: wp.vec3,
    c_t1: wp.vec3,
    minimum_distance: float,
    extra_error: float,
    params: CcdParameters,
) -> float:
    """Conservative first time (in [0, 1]) at which vertex p comes within ``minimum_distance`` of
    triangle (a, b, c); returns ``NO_HIT`` (2.0) when it provably never does.

    ``extra_error`` is an absolute per-axis amount added to the rounding bound (e.g. for input
    that was rounded to float32). With p_t1 = p_t0 etc. this is a conservative static proximity
    test whose answer is 0 (hit) or ``NO_HIT``.
    """
    face_lo = wp.min(wp.min(wp.min(a_t0, b_t0), wp.min(c_t0, a_t1)), wp.min(b_t1, c_t1))
    face_hi = wp.max(wp.max(wp.max(a_t0, b_t0), wp.max(c_t0, a_t1)), wp.max(b_t1, c_t1))
    if _features_apart(wp.min(p_t0, p_t1), wp.max(p_t0, p_t1), face_lo, face_hi, extra_error, minimum_distance):
        return 2.0
    r = p_t0
    yp0 = p_t0 - r
    ya0 = a_t0 - r
    yb0 = b_t0 - r
    yc0 = c_t0 - r
    yp1 = p_t1 - r
    ya1 = a_t1 - r
    yb1 = b_t1 - r
    yc1 = c_t1 - r
    m = wp.vec3(0.0, 0.0, 0.0)
    m = _abs_max(m, yp0)
    m = _abs_max(m, ya0)
    m = _abs_max(m, yb0)
    m = _abs_max(m, yc0)
    m = _abs_max(m, yp1)
    m = _abs_max(m, ya1)
    m = _abs_max(m, yb1)
    m = _abs_max(m, yc1)
    return _ccd_from_differences(yp0 - ya0, ya0 - yb0, ya0 - yc0, yp1 - ya1, ya1 - yb1, ya1 - yc1, 1, m,
                                 extra_error, minimum_distance, vertex_face_distance_squared(yp0, ya0, yb0, yc0),
                                 params)


@wp.func
def edge_edge_ccd_toi(
    a0_t0: wp.vec3,
    a1_t0: wp.vec3,
    b0_t0: wp.vec3,
    b1_t0: wp.vec3,
    a0_t1: wp.vec3,
    a1_t1: wp.vec3,
    b0_t1: wp.vec3,
    b1_t1: wp.vec3,
    minimum_distance: float,
    extra_error: float,
    params: CcdParameters,
) -> float:
    """Conservative first time (in [0, 1]) at which edge (a0, a1) comes within
    ``minimum_distance`` of edge (b0, b1); ``NO_HIT`` (2.0) when it provably never does.

    See :func:`vertex_face_ccd_toi` for ``extra_error`` and the static use.
    """
    if _features_apart(wp.min(wp.min(a0_t0, a1_t0), wp.min(a0_t1, a1_t1)),
                       wp.max(wp.max(a0_t0, a1_t0), wp.max(a0_t1, a1_t1)),
                       wp.min(wp.min(b0_t0, b1_t0), wp.min(b0_t1, b1_t1)),
                       wp.max(wp.max(b0_t0, b1_t0), wp.max(b0_t1, b1_t1)), extra_error, minimum_distance):
        return 2.0
    r = a0_t0
    ya00 = a0_t0 - r
    ya10 = a1_t0 - r
    yb00 = b0_t0 - r
    yb10 = b1_t0 - r
    ya01 = a0_t1 - r
    ya11 = a1_t1 - r
    yb01 = b0_t1 - r
    yb11 = b1_t1 - r
    m = wp.vec3(0.0, 0.0, 0.0)
    m = _abs_max(m, ya00)
    m = _abs_max(m, ya10)
    m = _abs_max(m, yb00)
    m = _abs_max(m, yb10)
    m = _abs_max(m, ya01)
    m = _abs_max(m, ya11)
    m = _abs_max(m, yb01)
    m = _abs_max(m, yb11)
    return _ccd_from_differences(ya00 - yb00, ya10 - ya00, yb00 - yb10, ya01 - yb01, ya11 - ya01, yb01 - yb11, 0,
                                 m, extra_error, minimum_distance,
                                 edge_edge_distance_squared(ya00, ya10, yb00, yb10), params)


@wp.kernel
def _vertex_face_ccd_kernel(
    # in:
    points_t0: wp.array2d(dtype=wp.vec3),
    points_t1: wp.array2d(dtype=wp.vec3),
    extra_error: wp.array(dtype=wp.float32),
    minimum_distance: float,
    params: CcdParameters,
    # out:
    toi_out: wp.array(dtype=wp.float32),
):
    """One thread per vertex-face query."""
    i = wp.tid()
    toi_out[i] = vertex_face_ccd_toi(
        points_t0[i, 0], points_t0[i, 1], points_t0[i, 2], points_t0[i, 3],
        points_t1[i, 0], points_t1[i, 1], points_t1[i, 2], points_t1[i, 3],
        minimum_distance, extra_error[i], params,
    )


@wp.kernel
def _edge_edge_ccd_kernel(
    # in:
    points_t0: wp.array2d(dtype=wp.vec3),
    points_t1: wp.array2d(dtype=wp.vec3),
    extra_error: wp.array(dtype=wp.float32),
    minimum_distance: float,
    params: CcdParameters,
    # out:
    toi_out: wp.array(dtype=wp.float32),
):
    """One thread per edge-edge query."""
    i = wp.tid()
    toi_out[i] = edge_edge_ccd_toi(
        points_t0[i, 0], points_t0[i, 1], points_t0[i, 2], points_t0[i, 3],
        points_t1[i, 0], points_t1[i, 1], points_t1[i, 2], points_t1[i, 3],
        minimum_distance, extra_error[i], params,
    )


def input_rounding_error(points_t0: np.ndarray, points_t1: np.ndarray) -> np.ndarray:
    """Per-query bound on how much rounding the input to float32 can move F, per axis.

    Zero for queries whose coordinates are exactly float32. Otherwise 2 u max|x| (F is affine in
    the 8 points with coefficients whose absolute values sum to at most 2 per axis, and rounding
    moves each coordinate by at most u |x|), enlarged by 1 % for the float32 evaluation.

    Args:
        points_t0: (n, 4, 3) array of any real dtype, as the user gave it.
        points_t1: (n, 4, 3) array, likewise.

    Returns:
        (n,) float32 absolute error per query.
    """
    error = np.zeros(points_t0.shape[0], dtype=np.float32)
    for points in (points_t0, points_t1):
        as_given = np.asarray(points, dtype=np.float64)
        changed = (as_given != as_given.astype(np.float32).astype(np.float64)).reshape(len(as_given), -1)
        inexact = changed.any(axis=1)
        if inexact.any():
            magnitude = np.abs(as_given).reshape(len(as_given), -1).max(axis=1)
            bound = 2.02 * tolerances.FLOAT32_UNIT_ROUNDOFF * magnitude
            error = np.maximum(error, np.where(inexact, bound, 0.0).astype(np.float32))
    return error


def _run_ccd(kernel, points_t0, points_t1, minimum_distance, device,
             plane_filter: bool = True, distance_tolerance: float | None = None) -> tuple[np.ndarray, np.ndarray]:
    raw_t0 = np.asarray(points_t0.numpy() if isinstance(points_t0, wp.array) else points_t0)
    raw_t1 = np.asarray(points_t1.numpy() if isinstance(points_t1, wp.array) else points_t1)
    x0 = check_points(raw_t0, "points_t0", shape_tail=(4, 3))
    x1 = check_points(raw_t1, "points_t1", shape_tail=(4, 3))
    if x0.shape != x1.shape:
        from pscc.errors import InputError

        raise InputError("argument", "points_t1", f"shape {x1.shape} differs from points_t0 {x0.shape}",
                         "pass start and end positions of the same queries")
    distance = check_nonnegative(minimum_distance, "minimum_distance")
    count = x0.shape[0]
    if count == 0:
        return np.zeros(0, dtype=bool), np.zeros(0, dtype=np.float32)
    extra = input_rounding_error(raw_t0, raw_t1)
    device = wp.get_device(device)
    toi = wp.empty(count, dtype=wp.float32, device=device)
    params = ccd_parameters()
    params.plane_filter = int(bool(plane_filter))
    if distance_tolerance is not None:
        params.distance_tolerance = float(check_nonnegative(distance_tolerance, "distance_tolerance"))
    wp.launch(
        kernel,
        dim=count,
        inputs=[
            wp.array(x0, dtype=wp.vec3, device=device),
            wp.array(x1, dtype=wp.vec3, device=device),
            wp.array(extra, dtype=wp.float32, device=device),
            float(distance),
            params,
        ],
        outputs=[toi],
        device=device,
    )
    toi_host = toi.numpy()
    hit = toi_host <= 1.0
    return hit, np.where(hit, toi_host, np.float32(np.inf)).astype(np.float32)


def vertex_face_ccd(
    points_t0: np.ndarray | wp.array,
    points_t1: np.ndarray | wp.array,
    minimum_distance: float = 0.0,
    *,
    device: str | None = None,
    plane_filter: bool = True,
    distance_tolerance: float | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Batched conservative vertex-face CCD.

    Args:
        points_t0: (n, 4, 3) positions at t = 0, ordered [vertex, f0, f1, f2].
        points_t1: (n, 4, 3) positions at t = 1, same order.
        minimum_distance: report the pair when the vertex comes within this Euclidean distance of
            the triangle (0 = touching), in the units of the points.
        device: Warp device to run on (default: Warp's default device).
        plane_filter: exclude pairs whose features provably stay farther than ``minimum_distance`` from
            each other's moving plane before the search (:func:`plane_keeps_distance`; False: the
            search decides every pair, for comparisons).
        distance_tolerance: :data:`pscc.tolerances.CCD_DISTANCE_TOLERANCE` for this call (``None``: the
            default).

    Returns:
        ``(hit, toi)``: (n,) bool and (n,) float32. ``toi`` is a lower bound of the first time of
        contact for hits and ``inf`` otherwise. Never misses a contact of the input as given.

    Raises:
        InputError: bad shapes, NaN/Inf, or a negative ``minimum_distance``.
    """
    return _run_ccd(_vertex_face_ccd_kernel, points_t0, points_t1, minimum_distance, device, plane_filter,
                    distance_tolerance)


def edge_edge_ccd(
    points_t0: np.ndarray | wp.array,
    points_t1: np.ndarray | wp.array,
    minimum_distance: float = 0.0,
    *,
    device: str | None = None,
    plane_filter: bool = True,
    distance_tolerance: float | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Batched conservative edge-edge CCD.

    Args:
        points_t0: (n, 4, 3) positions at t = 0, ordered [a0, a1, b0, b1].
        points_t1: (n, 4, 3) positions at t = 1, same order.
        minimum_distance: Euclidean distance at which the edges count as colliding (0 = touching).
        device: Warp device to run on.
        plane_filter: as in :func:`vertex_face_ccd`.
        distance_tolerance: as in :func:`vertex_face_ccd`.

    Returns:
        ``(hit, toi)`` as in :func:`vertex_face_ccd`.

    Raises:
        InputError: bad shapes, NaN/Inf, or a negative ``minimum_distance``.
    """
    return _run_ccd(_edge_edge_ccd_kernel, points_t0, points_t1, minimum_distance, device, plane_filter,
                    distance_tolerance)
