"""Every floating-point tolerance of pscc, with its unit and the guarantee it buys.

Device arithmetic is IEEE float32 with round-to-nearest. ``FLOAT32_UNIT_ROUNDOFF`` (u = 2^-24)
bounds the relative error of one operation. Kernels receive these values as arguments; no kernel
holds a literal epsilon.
"""

from __future__ import annotations

FLOAT32_UNIT_ROUNDOFF: float = 2.0**-24
"""u: the relative rounding error of one float32 operation (dimensionless)."""

CCD_ROUNDING_FACTOR: float = 80.0
"""Multiple of ``u * M`` that bounds the float32 error of one evaluation of the CCD function F.

F(t, u, v) = q(t) + u e1(t) + v e2(t) (see :mod:`pscc.geometry.ccd`) is evaluated from coordinates
translated by the query's first point; M is the largest |translated coordinate| on that axis.
A forward error analysis of the evaluation order gives |F_float32 - F_exact| <= 63 u M per axis,
plus 2 u M for the rounding of the translation itself: 65 u M. 80 leaves a margin for the
second-order terms and for M being read off rounded values. Dimensionless.
"""

COPLANARITY_ROUNDING_FACTOR: float = 16.0
"""Multiple of ``u`` times its magnitude companion beyond which a Bernstein coefficient of the
coplanarity cubic has a trusted sign (the filter that skips the CCD search for pairs that never
become coplanar; used when the minimum distance is 0).

Each coefficient is at most 10 roundings (translation, differences, cross products, dot products,
one sum) away from the exact float32 input, so its error is below gamma_10 ~ 10 u times the same
expression evaluated with absolute values. Dimensionless.
"""

CCD_CODOMAIN_TOLERANCE: float = 1.0e-5
"""Relative size (times the query's local scale M) below which a CCD box is not split further.

A box that cannot be excluded and whose image is this small is reported as a collision. False
positives therefore only occur for pairs whose minimal distance over the step is within about
``(2 * CCD_ROUNDING_FACTOR * u + CCD_CODOMAIN_TOLERANCE) * sqrt(3) * M`` of the requested minimum
distance. Dimensionless.
"""

CCD_DISTANCE_TOLERANCE: float = 0.1
"""With a minimum distance d_min > 0, how close to d_min a CCD query must resolve a contact, as a fraction
of d_min. A pair that starts farther than ``d_min (1 + sqrt 3 x tolerance)`` is decided by conservative
advancement in t (:mod:`pscc.geometry.ccd`): it is reported at the first time t its distance may be within
``d_min (1 + tolerance)``, a lower bound of its first contact. Where the advancement cannot decide, a box of
the search whose image is smaller than this fraction of d_min is split only along t, down to
:data:`CCD_TOI_TOLERANCE`, and reported at its start, so a reported contact may be up to about
``tolerance x sqrt 3 x d_min`` farther than d_min (plus the rounding term above); its time stays a lower
bound. A pair that starts closer is searched exactly (tolerance 0): a contact it reports at t = 0 could
never be resolved by moving end positions. 0 refines every contact to :data:`CCD_CODOMAIN_TOLERANCE`. At 0.1
the simulator's ``twisting`` at 5K runs at 1.01 s per frame instead of 3.87 (docs/ccd.md). Dimensionless."""

CCD_ADVANCE_STEPS: int = 64
"""With a distance tolerance on: the conservative-advancement steps a CCD query may take before the box
search takes over (:mod:`pscc.geometry.ccd`). A compile-time constant."""

CCD_MIN_PARAMETER_WIDTH: float = 2.0**-16
"""Smallest width of a (t, u, v) box along one parameter before that parameter is no longer split.

Bounds the depth of the search at 3 * 16 = 48 splits, so the fixed per-thread stack of
``CCD_STACK_SIZE`` boxes never overflows. Dimensionless (parameters live in [0, 1]).
"""

CCD_STACK_SIZE: int = 64
"""Boxes on the per-thread depth-first stack of the CCD search (a compile-time constant)."""

CCD_TOI_TOLERANCE: float = 2.0**-11
"""Once a contact of a query is known, boxes that start less than this before it are not refined:
the reported time of impact becomes their start. It stays a lower bound of the true first contact
(never late) and is at most this much too early. Fraction of the step (about 4.9e-4)."""

CCD_MAX_BOXES: int = 16384
"""Boxes one CCD query may examine; past this it stops and reports a collision at the earliest
time not yet excluded (conservative: never a miss, never a late time of impact)."""

DISTANCE_COMPARISON_MARGIN: float = 1.0e-6
"""Relative margin on squared-distance comparisons against the minimum distance.

Each side of ``gap^2 > d_min^2`` carries a few float32 roundings (relative error < 8 u ~ 5e-7),
so a box is only excluded when ``gap^2 (1 - margin) > d_min^2 (1 + margin)``. Dimensionless.
"""

BOX_RELATIVE_PAD: float = 2.0**-21
"""Relative growth (times the largest |coordinate| of a box) of every bounding box.

Growing a box by ``pad = d/2 + BOX_RELATIVE_PAD * max|x|`` and rounding ``min - pad`` or
``max + pad`` to float32 moves the face by at most u |x| = 2^-24 |x|, well inside the 8 u |x| added;
so a pair closer than d always has overlapping boxes. Dimensionless.
"""

GROUP_SLAB_RELATIVE_PAD: float = 2.0**-20
"""Relative growth of the group slabs of the spatial hash (:mod:`pscc.collision.spatial_hash`).

A group's slab is the interval of s = a . p over its faces' vertices p (both ends of the step) along
a unit axis a; each end is grown by ``d/2 (1 + pad) + pad (M + d/2)``, where M >= |p|_1 for every
vertex of the scene (from the scene box). The float32 dot product errs by at most
3 u sum_k |a_k p_k| <= 3 u (1 + 2u) M (|a_k| <= 1 + 2u for the normalised axis), the half distance
projected on the axis is at most d/2 |a| <= d/2 (1 + 2u), and the additions that grow the ends and
the comparison of the ends round by at most 2 u (|s| + d/2 + pad M); pad = 16 u covers all of it.
So two groups whose grown slabs miss each other hold no pair of faces closer than d, and the box
tests of their face pairs may be skipped. Dimensionless.
"""

GROUP_BOUND_RELATIVE_PAD: float = 2.0**-17
"""Extra growth, times M (as for :data:`GROUP_SLAB_RELATIVE_PAD`), of the interval the group slab test
bounds the smaller group by without projecting its vertices (:mod:`pscc.collision.spatial_hash`):
its own slab on its own axis a_h moved by c . (a - a_h) +- R |a - a_h| (or with -a_h), and its bounding
sphere c +- R on the larger group's axis a. The float32 errors: the sphere's centre (u M per
component, which R absorbs as about 2 u M), c . delta (3 u sum |c_k delta_k| <= 6.1 u M with |delta_k| <=
2 + 2u), R |delta| (about 4 u of R |delta| <= 2 M, with R <= M), and four additions of terms below 6 M
(24 u M): under 50 u M in all. 128 u = 2^-17 covers it with a factor above 2. Dimensionless.
"""

NORMAL_CONE_MARGIN: float = 1.0e-5
"""Relative margin of the normal-cone and contour sign tests (:mod:`pscc.geometry.normal_cone`).

A direction d counts as seeing a face only when d . n > margin |n|, and a signed area
S = ((o - b) x (a - b)) . l counts as non-zero only when |S| > margin |o - b| |a - b|. The float32
rounding of these dot and cross products is below 8 u (about 5e-7) of the same products of lengths,
so every sign the tests rely on is the true sign: the certificate is never granted by rounding.
Dimensionless.
"""

DEGENERATE_FACE_RATIO: float = 1.0e-10
"""A face with |n|^2 <= ratio |e1|^2 |e2|^2 (sine of its corner angle below 1e-5) is degenerate: its
normal is noise, so its normal-cone mask is empty and no node containing it is certified.
Dimensionless."""

SEAM_GAP_RATIO: float = 0.05
"""A sewn seam edge pair counts as interior to a normal-cone node (so the node may be certified across
the seam) only while both stitch gaps are at most this fraction of the shorter of the two seam edges,
at the start and, for CCD, at the end of the step (docs/bvh.md, "Sewn panels"). Dimensionless."""

CONTACT_NORMAL_MIN_OFFSET: float = 1.0e-12
"""A contact's closest-point offset shorter than this gives no direction (its float32 components are
noise); its normal is then the pair's plane normal, oriented like the offset at the start of the step.
Length units (m in the simulator; 1e-12 m is far below the smallest thickness, so any pair whose
offset is used is well resolved)."""

CONTACT_FEATURE_WEIGHT: float = 1.0e-5
"""A closest-point weight of a contact pair (a barycentric coordinate, or an edge parameter's distance
to 0 or 1) at most this small puts the closest point on the feature's boundary: an edge or corner of
the face, an end of the edge. float32 closest points put a point that is exactly on an edge up to
~1e-6 inside it; the rows of one such contact are merged into one spring (:mod:`pscc.sim.proximity`).
Dimensionless."""

CONTACT_NORMAL_MIN_FALLBACK: float = 1.0e-20
"""A fallback direction (plane normal, start offset) shorter than this is treated as missing, and the
last resort is +z. Squared-length scale of the products it comes from (cross products of edges);
only reached by degenerate (collapsed) features."""

MAX_COORDINATE: float = 1.0e9
"""Largest |coordinate| the collision detector accepts, in length units (the units of the positions).

Rationale: the kernels form products of up to four lengths in float32 (|n|^2 = |e1 x e2|^2 and
|e1|^2 |e2|^2 in the supporting-plane and normal-cone tests, the thickness squared in every distance
comparison, products of three coordinate differences in the CCD cubics). With |x| <= 1e9 every
difference is <= 2e9 and (2e9)^4 = 1.6e37 stays 20x below the float32 maximum 3.4e38. Measured on a
folded sheet scaled by 10^k (``docs/mesh-input.md``): the pair sets match unit scale up to |x| ~ 1e13;
beyond, the ``pscc`` certificate is refused (more pairs, still conservative), and from a thickness of
about sqrt(3.4e38) ~ 1.8e19 (|x| ~ 3e20) the thickness squared overflows and DCD misses every pair.
1e9 leaves four decades below the first change and ten below the first miss, and still admits
millimetre coordinates of a 1000 km scene.
"""

MIN_COORDINATE_SCALE: float = 1.0e-6
"""Smallest largest-|coordinate| of a position array the collision detector accepts (length units);
an array whose coordinates are all exactly 0 is accepted too.

Rationale: the same products of four lengths underflow below the smallest normal float32 (1.2e-38)
once the lengths fall below ~1.9e-10 and flush to 0 below ~6e-12; the supporting-plane test then
reads a zero normal and drops pairs within the thickness. Measured on the folded sheet (edges ~ 1/11
of |x|): the spatial-hash and ``pscc`` methods miss pairs from |x| ~ 2e-11 down, CCD from ~1e-14.
With |x| >= 1e-6, a mesh whose edges are at least 1e-3 of its size keeps them >= 1e-9 (fourth
power 1e-36, normal), 5 decades above the first miss. Express smaller scenes in a smaller unit.
"""

MAX_THICKNESS: float = MAX_COORDINATE
"""Largest thickness (proximity distance) the collision detector accepts, in length units.

Rationale: every DCD comparison squares the thickness; at 1e9 that is 1e18, far below the float32
maximum, whereas a thickness above ~1.8e19 overflows to Inf and DCD silently misses every pair. A
thickness larger than the coordinate range would not be meaningful anyway.
"""
