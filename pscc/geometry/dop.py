"""Diagonal slabs of a face: the ten extra axes of a 26-DOP, beside its axis-aligned box.

A face's box bounds its projections on x, y and z. Thin tilted triangles (layers of cloth at an angle
to the axes) have loose boxes: two faces of stacked layers overlap in x, y and z while a diagonal axis
separates them. :func:`face_diagonal_slabs` gives a face's interval along the ten diagonals

    x + y, x - y, x + z, x - z, y + z, y - z, x + y + z, x + y - z, x - y + z, -x + y + z

(unnormalised: entries 0 or +-1), over its vertices at both ends of the step, grown for proximity. With
the box, that is the face's 26-DOP (k-DOP with k = 26: 13 axes, two planes each; Klosowski et al.,
"Efficient collision detection using bounding volume hierarchies of k-DOPs", 1998).
:func:`diagonal_slabs_overlap` is the extra test a pair of overlapping boxes then passes.

*Why no pair that can touch is lost.* Two faces closer than d = 2 h have points p, q with |p - q| < d,
so along an axis a, |a . p - a . q| < d |a|; every point of a face (over the step, of the moving face)
is a convex combination of its vertex positions, so its projection lies in the interval of theirs.
Growing each interval by h |a| makes the two overlap.

*Local frame.* :class:`pscc.collision.boxes.PrimitiveBoxes` passes the vertices relative to one origin o
per call (vertex 0's position at t0, the same for every face): q = fl(p - o). Along an axis every
exact projection then moves by the same a . o, so two faces' exact intervals overlap in the local frame
exactly when they do in the world's, and the rounding pads below scale with the scene's extent, not
with its distance from the origin. (The corpus frame `twisting f48`, layers 2 mm apart, moved 1,000
units away: pscc's triangle pairs went from 30,489 to 47,069 with world-frame slabs, to 31,586 with
local ones.) A non-finite origin makes every slab NaN, which culls nothing.

*Rounding.* The float32 difference q errs from p - o by at most u |p_i - o_i| <= u (1 + u) |q_i| per
coordinate, so a . q errs from a . (p - o) by at most 1.01 u M_f, with M_f >= |q|_1 for every vertex q
of the face (computed from the q); the float32 sum of two or three coordinates of q errs by at most
2 u M_f more; the grown ends are ``min - g`` and ``max + g``,
``g = h |a| (1 + rho) + rho (M_f + h |a|)`` with rho = :data:`pscc.tolerances.GROUP_SLAB_RELATIVE_PAD`
(16 u), |a| rounded up (sqrt 2, sqrt 3), and the rounding of g and of the final addition (at most
u (M_f + g) each) stays inside the 16 u (about 5 u M_f + 2 u g in all). So the stored interval contains
the exact grown one of the face's vertices in the local frame, and a culled pair is farther apart than
d over the whole step.
"""

from __future__ import annotations

import warp as wp

wp.set_module_options({"enable_backward": False})

DIAGONAL_AXES = 10
"""Number of diagonal axes: six edge diagonals (norm sqrt 2) and four corner diagonals (norm sqrt 3)."""

vec10 = wp.types.vector(length=DIAGONAL_AXES, dtype=wp.float32)
"""One float32 per diagonal axis (a slab end)."""

_SQRT2_UP = 1.4142137
"""sqrt 2 rounded up in float32."""

_SQRT3_UP = 1.7320509
"""sqrt 3 rounded up in float32."""


@wp.func
def diagonal_projections(p: wp.vec3) -> vec10:
    """p projected on the ten (unnormalised) diagonal axes, in the module docstring's order."""
    x = p[0]
    y = p[1]
    z = p[2]
    return vec10(x + y, x - y, x + z, x - z, y + z, y - z, x + y + z, x + y - z, x - y + z, y + z - x)


@wp.func
def _l1(p: wp.vec3) -> float:
    """|p|_1."""
    return wp.abs(p[0]) + wp.abs(p[1]) + wp.abs(p[2])


@wp.func
def face_diagonal_slabs(a: wp.vec3, b: wp.vec3, c: wp.vec3, a1: wp.vec3, b1: wp.vec3, c1: wp.vec3,
                        swept: int, half_distance: float, relative_pad: float):
    """(lower, upper) ends of the face's diagonal slabs over its vertices a, b, c at t0 and
    (``swept`` != 0) a1, b1, c1 at t1, grown as the module docstring says."""
    l1_bound = wp.max(wp.max(_l1(a), _l1(b)), _l1(c))
    if swept != 0:
        l1_bound = wp.max(l1_bound, wp.max(wp.max(_l1(a1), _l1(b1)), _l1(c1)))
    # Grown by h |a| (1 + rho) + rho (M_f + h |a|) on the edge (|a| = sqrt 2) and corner (sqrt 3) axes.
    reach2 = half_distance * float(_SQRT2_UP)
    reach3 = half_distance * float(_SQRT3_UP)
    g2 = reach2 * (1.0 + relative_pad) + relative_pad * (l1_bound + reach2)
    g3 = reach3 * (1.0 + relative_pad) + relative_pad * (l1_bound + reach3)
    grow = vec10(g2, g2, g2, g2, g2, g2, g3, g3, g3, g3)
    # Each vertex's projections are grown before the min and max: the same float32 ends as growing the
    # min and max afterwards (rounding is monotone), but the CPU build runs this form faster (the face-box
    # kernel with slabs: 180 against 200 us for 5K faces; the min-max-grow part alone 52 against 105 us).
    sa = diagonal_projections(a)
    sb = diagonal_projections(b)
    sc = diagonal_projections(c)
    lo = wp.min(wp.min(sa - grow, sb - grow), sc - grow)
    hi = wp.max(wp.max(sa + grow, sb + grow), sc + grow)
    if swept != 0:
        sa = diagonal_projections(a1)
        sb = diagonal_projections(b1)
        sc = diagonal_projections(c1)
        lo = wp.min(lo, wp.min(wp.min(sa - grow, sb - grow), sc - grow))
        hi = wp.max(hi, wp.max(wp.max(sa + grow, sb + grow), sc + grow))
    return lo, hi


@wp.func
def diagonal_slabs_overlap(lower_a: vec10, upper_a: vec10, lower_b: vec10, upper_b: vec10) -> bool:
    """True when the two faces' slabs overlap on every diagonal axis (closed intervals)."""
    for k in range(DIAGONAL_AXES):
        if lower_a[k] > upper_b[k] or lower_b[k] > upper_a[k]:
            return False
    return True
