"""Named tolerances of the DCD distance primitives in :mod:`pscc.geometry.distance`.

All tolerances except :data:`MIN_LOCAL_SCALE` are dimensionless. The kernels first scale each
query by ``1 / L``, where ``L`` is the largest absolute coordinate difference between the anchor
point (the triangle's first vertex or the first edge's first endpoint) and the other three
points, so a relative tolerance compares quantities measured in units of the query's own size.
"""

from __future__ import annotations

EPS32: float = 2.0**-23
"""Machine epsilon of float32 (dimensionless): the gap between 1.0 and the next float32."""

MIN_LOCAL_SCALE: float = 1.0e-30
"""Smallest local scale ``L`` (length units) that is resolved; below it the query is one point.

Rationale: ``1 / L`` must stay a finite normal float32 (``1 / 1e-30 = 1e30 < 3.4e38``). Queries
whose four points all lie within ``1e-30`` of each other report the anchor as the closest point;
the distance error this causes is below ``1e-30`` length units.
"""

TRIANGLE_DEGENERATE_REL_SQ: float = 1.0e-8
"""Zero-area threshold on ``|ab x ac|^2 / max_edge_length^4`` (dimensionless).

The ratio equals ``(2 * area / max_edge_length^2)^2``, the squared sine-like "flatness" of the
triangle (about ``(height / longest edge)^2``). At or below the threshold the triangle is
treated as the union of its three edges (segments), whose closest points need no division by
the area. Rationale: the Voronoi-region barycentric weights lose about ``EPS32 / ratio``
relative accuracy, while treating a flat triangle as its edges costs at most its height,
``sqrt(ratio) * max_edge_length``. ``1e-8`` (height ``1e-4`` of the longest edge) keeps both
effects at the ``1e-4`` relative level at the switch-over and away from NaN/Inf for exactly
degenerate input.
"""

EDGE_DEGENERATE_REL_SQ: float = EPS32 * EPS32
"""Zero-length threshold on ``|edge|^2 / L^2`` (dimensionless).

An edge shorter than ``EPS32 * L`` is treated as its first endpoint. Rationale: such an edge
is below the rounding noise of the query's coordinates, so collapsing it moves the closest
point by at most ``EPS32 * L``, inside the documented error bound.
"""

EDGE_PARALLEL_REL_SQ: float = EPS32 * EPS32
"""Parallel threshold on ``|e_a x e_b|^2 / (|e_a|^2 |e_b|^2)`` = ``sin^2(angle)`` (dimensionless).

At or below it the line-line solution is skipped (it would divide by a vanishing
``|e_a x e_b|^2``) and the search starts from ``s = 0``: the second edge's parameter is
optimised for it and, if clamped, the first edge's parameter is re-optimised. For parallel
segments every start gives a true minimising pair, and for edges at an angle below ``EPS32``
the start costs at most ``sin(angle) * L <= EPS32 * L``. Rationale: the line-line parameter is
written with cross products, ``s = (n . (e_b x r)) / |n|^2``, which stays accurate down to
angles of about ``EPS32`` (measured), so the threshold only has to keep the division finite.
"""

WELL_SHAPED_MIN_FLATNESS: float = 1.0e-2
"""Smallest triangle flatness ``|ab x ac|^2 / max_edge_length^4`` that counts as well-shaped.

Dimensionless; ``1e-3`` means a height of about 3 % of the longest edge (an equilateral
triangle has ``0.75``). Zero-area triangles (flatness exactly 0) count as well-shaped too,
since they are handled exactly. Every edge pair counts as well-shaped. Rationale: below it the
vertex-face error grows like ``0.2 * EPS32 * L / sqrt(flatness)`` (measured) and can exceed
:data:`DISTANCE_ERROR_CONST`.
"""

DISTANCE_ERROR_CONST: float = 16.0
"""The constant ``C`` of the bound ``|d_float32 - d_exact| <= C * EPS32 * L`` (dimensionless).

``d_exact`` is the exact distance between the float32 input points and ``L`` the largest
absolute coordinate difference among the four points. The bound holds for well-shaped
queries (see :data:`WELL_SHAPED_MIN_FLATNESS`). Rationale: about ten float32 operations, each
with relative rounding error ``EPS32 / 2`` on quantities of size ``L``, separate the input from
the distance; the largest error measured over millions of random queries is about
``6 * EPS32 * L``, so 16 leaves a safety factor of more than 2.
"""

ILL_CONDITIONED_REL_ERROR: float = 1.0e-3
"""Bound on ``(d_float32 - d_exact) / L`` for nearly flat triangles (dimensionless).

For triangles of flatness below :data:`WELL_SHAPED_MIN_FLATNESS` the closest point, not the
distance, is ill-conditioned. The computed weights are always a convex combination, so the
computed distance is never below ``d_exact - C * EPS32 * L``; it can be too large, by about
``0.2 * EPS32 * L / sqrt(flatness)`` above :data:`TRIANGLE_DEGENERATE_REL_SQ` and by at most
half the triangle's height below it, which meet at about ``sqrt(EPS32) * L``. Rationale: the
worst over-estimate measured is about ``2.5e-4 * L``; ``1e-3`` leaves a factor of 4.
"""
