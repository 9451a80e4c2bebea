"""Shared pieces of the conservative CCD (:mod:`pscc.geometry.ccd`): its parameters, margins and the two
evaluations every stage uses (F at a time t, and the gap of a box of F values from the origin)."""

from __future__ import annotations

import warp as wp

from pscc import tolerances
from pscc.geometry import distance_tolerances

wp.set_module_options({"enable_backward": False})

NO_HIT: float = 2.0
"""Value the device functions return as time of impact when there is no collision."""

DISTANCE_RELATIVE_ERROR = wp.constant(distance_tolerances.ILL_CONDITIONED_REL_ERROR
                                      + distance_tolerances.DISTANCE_ERROR_CONST * distance_tolerances.EPS32)
"""How far the float32 distance of :mod:`pscc.geometry.distance` may exceed the exact one, relative to the
query's size, for any input (nearly flat triangles included)."""
WELL_SHAPED_DISTANCE_ERROR = wp.constant(distance_tolerances.DISTANCE_ERROR_CONST * distance_tolerances.EPS32)
"""The same for edge pairs and well-shaped triangles."""
MOTION_MARGIN = wp.constant(1.0e-5)
"""Relative margin of the motion-bound comparisons (far above their float32 rounding)."""


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
def lerp(x0: wp.vec3, x1: wp.vec3, t: float) -> wp.vec3:
    """x0 + t (x1 - x0): a point at time t, in the evaluation order the rounding bound was derived for."""
    return x0 + t * (x1 - x0)


@wp.func
def gap_squared(lo: wp.vec3, hi: wp.vec3, err: wp.vec3) -> float:
    """Squared distance from the origin to the box [lo - err, hi + err]."""
    g = float(0.0)
    for k in range(3):
        below = lo[k] - err[k]
        above = -(hi[k] + err[k])
        d = wp.max(wp.max(below, above), 0.0)
        g += d * d
    return g
