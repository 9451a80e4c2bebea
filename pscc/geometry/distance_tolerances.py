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

EDGE_PARALLEL_REL_SQ: float = 1.0e-10
"""Parallel threshold on ``|e_a x e_b|^2 / (|e_a|^2 |e_b|^2)`` = ``sin^2(angle)`` (dimensionless).

At or below it the two edges are treated as parallel: the first edge's start is fixed, the
second edge's parameter is optimised, and then the first edge's parameter is re-optimised,
which finds a true minimising pair for parallel segments. Rationale: the line-line solution
loses about ``EPS32 / sin(angle)`` relative accuracy, while the parallel treatment of edges at
angle ``< 1e-5`` rad costs at most ``sin(angle) * L``; ``1e-10`` keeps both around ``1e-5 * L``.
"""

DISTANCE_ERROR_CONST: float = 16.0
"""The constant ``C`` of the documented bound ``|d_float32 - d_exact| <= C * EPS32 * L``.

It holds for well-shaped queries (triangle flatness ratio above ``1e-4`` and edge angles above
about ``1e-2`` rad) whose exact answer was computed in float64 from the same float32 inputs.
Rationale: each of the few float32 operations between the input and the distance rounds with
relative error ``EPS32 / 2`` of quantities of size ``L``; the largest error measured over the
randomised tests is about ``3 * EPS32 * L``, and 16 leaves a safety factor of about 5.
"""

ILL_CONDITIONED_REL_ERROR: float = 1.0e-3
"""Relative error bound ``|d_float32 - d_exact| / L`` for near-degenerate queries (dimensionless).

Near-degenerate means nearly flat triangles and nearly parallel edges, where the closest point
itself is ill-conditioned. The computed closest point is always a point of both primitives
(up to rounding), so the computed distance is never below ``d_exact - C * EPS32 * L``; it can
be too large by up to about ``sqrt(EPS32) * L``. Rationale: the worst over-estimate measured in
the randomised near-degenerate tests is below ``4e-4 * L``.
"""
