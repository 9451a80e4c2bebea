"""Named tolerances and error constants of the DCD distance primitives (:mod:`pscc.geometry.distance`).

All values except :data:`MIN_LOCAL_SCALE` are dimensionless. The kernels shift each query to
its anchor point (the triangle's first vertex, or the first edge's first endpoint) and scale it
by ``1 / L``, where ``L`` is the largest absolute coordinate difference between the anchor and
the other three points; every relative threshold therefore compares quantities measured in
units of the query's own size. Triangle "flatness" is ``|ab x ac|^2 / max_edge_length^4``,
about ``(smallest height / longest edge)^2``: ``0.75`` for an equilateral triangle, ``0`` for a
zero-area one.
"""

from __future__ import annotations

EPS32: float = 2.0**-23
"""Machine epsilon of float32 (dimensionless): the gap between 1.0 and the next float32."""

MIN_LOCAL_SCALE: float = 1.0e-30
"""Smallest local scale ``L`` (length units) that is resolved; below it the query is one point.

Rationale: ``1 / L`` must stay a finite normal float32 (``1 / 1e-30 = 1e30 < 3.4e38``). Queries
whose four points all lie within ``1e-30`` of each other report the anchor as the closest point,
an error below ``1e-30`` length units.
"""

TRIANGLE_DEGENERATE_REL_SQ: float = 1.0e-8
"""Zero-area threshold on the triangle flatness ``|ab x ac|^2 / max_edge_length^4``.

At or below it the triangle is treated as the union of its three edges (segments), whose
closest points need no division by the area; collinear and coincident vertices land here.
Rationale: above it, the Voronoi-region weights are accurate to about
``0.4 * EPS32 / sqrt(flatness)`` (measured) relative to the triangle size; below it, treating
the triangle as its edges moves the closest point by at most the inradius, less than half the
smallest height ``sqrt(flatness) * max_edge_length``. ``1e-8`` (smallest height ``1e-4`` of the
longest edge) puts the switch where both effects are about ``sqrt(EPS32)`` relative.
"""

EDGE_DEGENERATE_REL_SQ: float = EPS32 * EPS32
"""Zero-length threshold on ``|edge|^2 / L^2``.

An edge shorter than ``EPS32 * L`` is treated as its first endpoint. Rationale: such an edge is
below the rounding noise of the query's coordinates, so collapsing it moves the closest point
by at most ``EPS32 * L``, inside the documented error bound.
"""

EDGE_PARALLEL_REL_SQ: float = EPS32 * EPS32
"""Parallel threshold on ``|e_a x e_b|^2 / (|e_a|^2 |e_b|^2)`` = ``sin^2(angle)``.

At or below it the line-line solution is skipped (it would divide by a vanishing
``|e_a x e_b|^2``) and the search starts from ``s = 0``: the second edge's parameter is
optimised for it and, if clamped, the first edge's parameter is re-optimised. For parallel
segments every start gives a true minimising pair, and for edges at an angle below ``EPS32``
the start costs at most ``sin(angle) * L <= EPS32 * L``. Rationale: the line-line parameter is
written with cross products, ``s = (n . (e_b x r)) / |n|^2``, which stays accurate down to
angles of about ``EPS32`` (measured), so the threshold only has to keep the division finite.
"""

WELL_SHAPED_MIN_FLATNESS: float = 1.0e-2
"""Smallest triangle flatness that counts as well-shaped for the error bound.

``1e-2`` is a smallest height of about 10 % of the longest edge. Zero-area triangles (flatness
exactly 0) count as well-shaped too, since they are handled exactly, and so does every edge
pair (the edge-edge bound was measured to hold for all angles). Rationale: below it the
vertex-face error grows like ``0.4 * EPS32 * L / sqrt(flatness)`` (measured) and would exceed
:data:`DISTANCE_ERROR_CONST` below a flatness of about ``1e-3``.
"""

DISTANCE_ERROR_CONST: float = 16.0
"""The constant ``C`` of the bound ``|d_float32 - d_exact| <= C * EPS32 * L``.

``d_exact`` is the exact distance between the float32 input points and ``L`` the largest
absolute coordinate difference among the four points. The bound holds for well-shaped
queries (see :data:`WELL_SHAPED_MIN_FLATNESS`). Rationale: about ten float32 operations, each
with relative rounding error ``EPS32 / 2`` on quantities of size ``L``, separate the input from
the distance, which gives ``C`` of a few units; the largest error measured over 7e7 random
queries of each kind is ``3.7 * EPS32 * L`` (vertex-face) and ``3.3 * EPS32 * L`` (edge-edge),
so 16 leaves a safety factor above 4.
"""

ILL_CONDITIONED_REL_ERROR: float = 1.0e-3
"""Bound on ``(d_float32 - d_exact) / L`` for triangles below :data:`WELL_SHAPED_MIN_FLATNESS`.

For nearly flat triangles the closest point, not the distance, is ill-conditioned. The computed
weights are always a convex combination, so the computed distance is never below
``d_exact - C * EPS32 * L``; it can be too large, by about ``0.4 * EPS32 * L / sqrt(flatness)``
above :data:`TRIANGLE_DEGENERATE_REL_SQ` and by at most half the smallest height below it; the
two meet at about ``sqrt(EPS32) * L ~ 3.5e-4 * L``. Rationale: the worst over-estimate measured
is ``2.9e-4 * L``; ``1e-3`` leaves a factor above 3.
"""

PROJECTION_SIDE_ERROR_PER_NORMAL: float = 84.0 * 2.0**-24
"""With :data:`PROJECTION_SIDE_ERROR_BASE`, the rounding bound on a signed face weight ``s = n . (e x
(p - v))`` of :func:`pscc.geometry.distance.projection_outside_triangle`:
``|s_float32 - s| <= E P (PROJECTION_SIDE_ERROR_PER_NORMAL N + PROJECTION_SIDE_ERROR_BASE)``, with ``N``,
``E`` and ``P`` the largest absolute components of ``n = ab x ac``, of the edge ``e`` and of ``p - v``, all in
coordinates shifted to ``a`` and scaled by ``1 / L`` (every component of ``ab``, ``ac``, ``ap`` at most 1).

Rationale, with unit roundoff ``u = 2**-24`` and the scaled coordinates taken as exact (they describe the
points as moved by the shift and scale, which the caller accounts for):
- a cross-product component ``x1 y2 - x2 y1`` rounds with error at most ``2u (|x1 y2| + |x2 y1|)``;
- so each component of ``n`` errs by at most ``4u`` (factors at most 1);
- each component of ``m = e x (p - v)`` errs by at most ``8u E P``, counting the rounding of ``e = ac -
  ab`` and ``p - v = ap - ab`` for edge ``bc`` (``u`` relative each);
- ``|m_i| <= 2 E P``, and ``|n_i| <= N``;
- the three-term dot product then errs by at most ``3 N 8u E P + 3 * 4u * 2 E P + 3u * 3 N 2 E P = u E P (42 N
  + 24)``.
Doubled, to cover the second-order terms and ``N``, ``E``, ``P`` taken from the rounded values: ``84`` and
``48``. The bound scales with the edge and the point's offset, so a vertex beside a sliver's short edge is
certified as readily as one beside its long edges.
"""

PROJECTION_SIDE_ERROR_BASE: float = 48.0 * 2.0**-24
"""The constant term of the side-weight rounding bound (:data:`PROJECTION_SIDE_ERROR_PER_NORMAL`)."""
