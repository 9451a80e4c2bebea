"""Axis-aligned bounding boxes: device functions shared by every broad phase.

A box is a pair of ``wp.vec3`` (lower, upper). Boxes are grown by a distance and by a small relative
pad (:data:`pscc.tolerances.BOX_RELATIVE_PAD`) so that float32 rounding never shrinks them: two
primitives closer than the distance always have overlapping boxes.
"""

from __future__ import annotations

import warp as wp

wp.set_module_options({"enable_backward": False})


@wp.func
def grow_box_lower(lower: wp.vec3, upper: wp.vec3, half_distance: float, relative_pad: float) -> wp.vec3:
    """Lower corner of the box (lower, upper) grown by ``half_distance`` plus the relative pad."""
    size = wp.max(wp.max(wp.abs(lower[0]), wp.abs(upper[0])), wp.max(wp.abs(lower[1]), wp.abs(upper[1])))
    size = wp.max(size, wp.max(wp.abs(lower[2]), wp.abs(upper[2])))
    pad = half_distance + relative_pad * size
    return lower - wp.vec3(pad, pad, pad)


@wp.func
def grow_box_upper(lower: wp.vec3, upper: wp.vec3, half_distance: float, relative_pad: float) -> wp.vec3:
    """Upper corner of the box (lower, upper) grown by ``half_distance`` plus the relative pad."""
    size = wp.max(wp.max(wp.abs(lower[0]), wp.abs(upper[0])), wp.max(wp.abs(lower[1]), wp.abs(upper[1])))
    size = wp.max(size, wp.max(wp.abs(lower[2]), wp.abs(upper[2])))
    pad = half_distance + relative_pad * size
    return upper + wp.vec3(pad, pad, pad)


@wp.func
def boxes_overlap(lower_a: wp.vec3, upper_a: wp.vec3, lower_b: wp.vec3, upper_b: wp.vec3) -> bool:
    """True when the closed boxes a and b share at least one point."""
    return (
        lower_a[0] <= upper_b[0]
        and lower_b[0] <= upper_a[0]
        and lower_a[1] <= upper_b[1]
        and lower_b[1] <= upper_a[1]
        and lower_a[2] <= upper_b[2]
        and lower_b[2] <= upper_a[2]
    )
