"""Signed closest-point weights of a contact pair, shared by the contact springs and the projection.

A pair is four vertices x0..x3: a vertex-face pair (p, a, b, c) or an edge-edge pair (a0, a1, b0, b1).
Its weights w make ``sum_k w_k x_k`` the offset from the closest point of the second feature to
that of the first: vertex-face ``(1, -b_a, -b_b, -b_c)`` with the barycentric coordinates of the
closest face point, edge-edge ``(1 - s, s, -(1 - t), -t)`` with the closest-point parameters.
The weights of the first feature sum to 1 and those of the second to -1, so a correction along
``M^-1 w n`` keeps the total momentum when every vertex is free.
"""

from __future__ import annotations

import warp as wp

from pscc import tolerances
from pscc.geometry.distance import edge_edge_closest_point, vertex_face_closest_point

_MIN_OFFSET = wp.constant(tolerances.CONTACT_NORMAL_MIN_OFFSET)
_MIN_FALLBACK = wp.constant(tolerances.CONTACT_NORMAL_MIN_FALLBACK)


@wp.func
def pair_weights(x0: wp.vec3, x1: wp.vec3, x2: wp.vec3, x3: wp.vec3, edge_edge: int) -> wp.vec4:
    """Signed closest-point weights (module docstring); ``edge_edge`` 0: vertex-face, else edge-edge."""
    if edge_edge != 0:
        st = edge_edge_closest_point(x0, x1, x2, x3)
        return wp.vec4(1.0 - st[0], st[0], -(1.0 - st[1]), -st[1])
    w = vertex_face_closest_point(x0, x1, x2, x3)
    return wp.vec4(1.0, -w[0], -w[1], -w[2])


@wp.func
def weighted_sum(w: wp.vec4, x0: wp.vec3, x1: wp.vec3, x2: wp.vec3, x3: wp.vec3) -> wp.vec3:
    """``sum_k w_k x_k``: with :func:`pair_weights`, the closest-point offset of the pair."""
    return w[0] * x0 + w[1] * x1 + w[2] * x2 + w[3] * x3


@wp.func
def pair_plane_normal(x0: wp.vec3, x1: wp.vec3, x2: wp.vec3, x3: wp.vec3, edge_edge: int) -> wp.vec3:
    """Unnormalised fallback normal when the closest points coincide: the face normal
    ``(b - a) x (c - a)`` (vertex-face) or the edges' cross product ``(a1 - a0) x (b1 - b0)``."""
    if edge_edge != 0:
        return wp.cross(x1 - x0, x3 - x2)
    return wp.cross(x2 - x1, x3 - x1)


@wp.func
def contact_normal(offset: wp.vec3, fallback: wp.vec3, start_offset: wp.vec3) -> wp.vec3:
    """Unit contact normal of a pair: its closest-point ``offset`` (see :func:`weighted_sum`), or, when
    that is shorter than :data:`pscc.tolerances.CONTACT_NORMAL_MIN_OFFSET`, ``fallback`` (the pair's
    plane normal), else ``start_offset``, else +z, oriented like ``start_offset``."""
    length = wp.length(offset)
    if length > _MIN_OFFSET:
        return offset / length
    n = fallback
    if wp.length(n) <= _MIN_FALLBACK:
        n = start_offset
    if wp.length(n) <= _MIN_FALLBACK:
        n = wp.vec3(0.0, 0.0, 1.0)
    n = wp.normalize(n)
    if wp.dot(n, start_offset) < 0.0:
        n = -n
    return n
