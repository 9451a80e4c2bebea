"""Float64 reference for two faces that share a vertex or an edge: do they meet only in what they share?

Independent of :mod:`pscc.collision.shared_vertex` (no direction masks, no projection):

- shared edge b c: A = (a, b, c) and B lie in two half planes bounded by the line bc, which meet outside
  the line only when they coincide. With consistent orientation that is when the normals are opposite;
  with the edge in the same direction in both faces, when they are equal.
- shared vertex v only: A and B meet elsewhere iff some point v + s1 (a1 - v) + s2 (a2 - v) =
  v + t1 (b1 - v) + t2 (b2 - v) with s, t >= 0 not all zero (both faces are convex and hold v), a
  linear feasibility problem (scipy's ``linprog``, s1 + s2 + t1 + t2 = 1).
"""

from __future__ import annotations

import numpy as np
from scipy.optimize import linprog


def shared_vertex_ids(ta, tb) -> list[int]:
    """Vertex ids the two faces have in common."""
    return sorted(set(int(v) for v in ta) & set(int(v) for v in tb))


def meet_only_in_shared(ta, tb, x: np.ndarray, parallel_tolerance: float = 1e-9) -> bool:
    """Whether faces ``ta`` and ``tb`` (vertex ids into ``x``) intersect only in their shared vertex or
    edge; False when they share nothing or all three vertices."""
    x = np.asarray(x, dtype=np.float64)
    shared = shared_vertex_ids(ta, tb)
    if len(shared) == 0 or len(shared) == 3:
        return False
    ta = [int(v) for v in ta]
    tb = [int(v) for v in tb]
    na = np.cross(x[ta[1]] - x[ta[0]], x[ta[2]] - x[ta[0]])
    nb = np.cross(x[tb[1]] - x[tb[0]], x[tb[2]] - x[tb[0]])
    la, lb = np.linalg.norm(na), np.linalg.norm(nb)
    if la == 0.0 or lb == 0.0:
        return False
    cosine = float(na @ nb) / (la * lb)
    if len(shared) == 2:
        p, q = shared
        forward_a = any(ta[i] == p and ta[(i + 1) % 3] == q for i in range(3))
        forward_b = any(tb[i] == p and tb[(i + 1) % 3] == q for i in range(3))
        if forward_a != forward_b:  # consistent: the half planes coincide only with opposite normals
            return cosine > -1.0 + parallel_tolerance
        return cosine < 1.0 - parallel_tolerance
    v = shared[0]
    pa = [x[w] - x[v] for w in ta if w != v]
    pb = [x[w] - x[v] for w in tb if w != v]
    scale = max(np.abs(np.array(pa + pb)).max(), 1e-300)
    columns = np.stack([pa[0], pa[1], -pb[0], -pb[1]], axis=1) / scale
    a_eq = np.vstack([columns, np.ones((1, 4))])
    b_eq = np.array([0.0, 0.0, 0.0, 1.0])
    result = linprog(np.zeros(4), A_eq=a_eq, b_eq=b_eq, bounds=[(0.0, None)] * 4, method="highs")
    return result.status == 2  # infeasible: no common point besides v
