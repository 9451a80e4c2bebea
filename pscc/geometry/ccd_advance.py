"""Conservative advancement of the CCD with a distance tolerance (:mod:`pscc.geometry.ccd`, docs/ccd.md):
the start-band guard that leaves pairs starting near the minimum distance to the exact search, and the
advancement in t that decides the others."""

from __future__ import annotations

import warp as wp

from pscc import tolerances
from pscc.geometry import distance_tolerances
from pscc.geometry.ccd_base import (
    DISTANCE_RELATIVE_ERROR,
    MOTION_MARGIN,
    WELL_SHAPED_DISTANCE_ERROR,
    CcdParameters,
    lerp,
)
from pscc.geometry.ccd_filters import largest_motion
from pscc.geometry.distance import edge_edge_distance_squared, vertex_face_distance_squared

_SQRT3 = wp.constant(1.7320508)
_ADVANCE_STEPS = wp.constant(tolerances.CCD_ADVANCE_STEPS)
_WELL_SHAPED_FLATNESS_CHECK = wp.constant(2.0 * distance_tolerances.WELL_SHAPED_MIN_FLATNESS)

wp.set_module_options({"enable_backward": False})

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
            return DISTANCE_RELATIVE_ERROR * 4.0 * scale
    return WELL_SHAPED_DISTANCE_ERROR * 4.0 * scale



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
def advance_to_contact(
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
    :func:`motion_cannot_reach`, grown by twice the rounding bound). Every step therefore excludes
    [t, t + (D(t) - d_min) / speed) and jumps to its end. The advancement stops with a contact at t once
    D(t) is within half the tolerance of d_min: the exact distance at t is then below
    ``d_min (1 + distance_tolerance)`` (the bound's own error is required to be below a quarter of the
    tolerance, else the search is left to the boxes). The reported t is a lower bound of the first contact,
    as for a box the search reports at its start.
    """
    slack = wp.length(err)
    motion = largest_motion(q0, e10, e20, q1, e11, e21, triangle_domain)
    speed = (motion + 2.0 * slack) * (1.0 + MOTION_MARGIN)
    floor = minimum_distance * (1.0 + MOTION_MARGIN)
    band = 0.5 * distance_tolerance * minimum_distance
    t = float(0.0)
    for _step in range(_ADVANCE_STEPS):
        q = lerp(q0, q1, t)
        e1 = lerp(e10, e11, t)
        e2 = lerp(e20, e21, t)
        # The float32 distance errs by the distance function's bound, and its input differs from the exact
        # F by the rounding bound err (counted twice, as in motion_cannot_reach). That error must leave
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
        t = t + (gap / speed) * (1.0 - MOTION_MARGIN)
    return -1.0 - t



@wp.func
def query_distance_tolerance(distance_squared_t0: float, err: wp.vec3, scale: float, minimum_distance: float,
                              params: CcdParameters) -> float:
    """The distance tolerance of one query: ``params.distance_tolerance``, or 0 when the pair may start
    inside the band the tolerance leaves ambiguous.

    A coarse box is reported when it is within about ``d_min (1 + tol sqrt 3)``; a pair that starts that
    close (but farther than d_min) would be reported at t = 0 whatever the response does to its end
    positions, round after round. So a pair whose start distance is not provably above
    ``d_min (1 + 2 tol sqrt 3)`` (lower bound as in :func:`motion_cannot_reach`) is refined exactly, and
    the tolerance only speeds up pairs that start clear of the band.
    """
    tolerance = params.distance_tolerance
    if tolerance > 0.0:
        lower = wp.sqrt(wp.max(distance_squared_t0, 0.0)) - DISTANCE_RELATIVE_ERROR * scale - 2.0 * wp.length(err)
        if lower <= minimum_distance * (1.0 + 1.0 * _SQRT3 * tolerance) * (1.0 + MOTION_MARGIN):
            tolerance = 0.0
    return tolerance
