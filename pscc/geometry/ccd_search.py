"""The box search of the conservative CCD (:mod:`pscc.geometry.ccd`, "Search"): a depth-first search over
(t, u, v) boxes with a fixed per-thread stack, excluding boxes whose images provably stay farther than the
minimum distance."""

from __future__ import annotations

import warp as wp

from pscc import tolerances
from pscc.geometry.ccd_base import CcdParameters, gap_squared, lerp

_STACK = tolerances.CCD_STACK_SIZE
_stack_vector = wp.types.vector(length=_STACK, dtype=wp.float32)

wp.set_module_options({"enable_backward": False})

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
    return wp.max(gap_squared(low_lo, low_hi, err), gap_squared(high_lo, high_hi, err))



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
    qa = lerp(q0, q1, 0.0)
    qb = lerp(q0, q1, 1.0)
    e1a = lerp(e10, e11, 0.0)
    e1b = lerp(e10, e11, 1.0)
    e2a = lerp(e20, e21, 0.0)
    e2b = lerp(e20, e21, 1.0)
    lo = wp.min(wp.min(qa, qa + e1a), wp.min(qa + e2a, qa + e1a + e2a))
    hi = wp.max(wp.max(qa, qa + e1a), wp.max(qa + e2a, qa + e1a + e2a))
    lo = wp.min(lo, wp.min(wp.min(qb, qb + e1b), wp.min(qb + e2b, qb + e1b + e2b)))
    hi = wp.max(hi, wp.max(wp.max(qb, qb + e1b), wp.max(qb + e2b, qb + e1b + e2b)))
    return gap_squared(lo, hi, err)



@wp.func
def ccd_search(
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
        qa = lerp(q0, q1, t0)
        qb = lerp(q0, q1, t1)
        e1a = lerp(e10, e11, t0)
        e1b = lerp(e10, e11, t1)
        e2a = lerp(e20, e21, t0)
        e2b = lerp(e20, e21, t1)
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

        gap_sq = gap_squared(lo, hi, err)
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
