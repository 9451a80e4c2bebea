"""Independent intersection check with ipctk (the test oracle), leaving out the pairs a seam joins.

``ipctk.has_intersections`` reports any edge touching a triangle, so a closed seam (a sewn vertex lying on
the other panel's edge) counts as a crossing there. :func:`crossings` asks ipctk's own broad phase for
edge-face candidates and ipctk's exact ``is_edge_intersecting_triangle`` for each, and leaves out the pairs
that share a vertex (as ipctk does) or that a stitch joins: an end of the edge stitched to a vertex of
the face (the rule of :mod:`pscc.collision.seams`, decided here on the host from the stitch rows). Used by
the tests of sewn garments and by the bench; needs the ``test`` extra (ipctk).
"""

from __future__ import annotations

import numpy as np

__all__ = ["crossings"]


def crossings(positions: np.ndarray, faces: np.ndarray, stitches: np.ndarray | None = None) -> np.ndarray:
    """Edge-face crossings by ipctk, without the pairs that share a vertex or that a stitch joins.

    Args:
        positions: (n, 3) vertex positions.
        faces: (m, 3) triangles.
        stitches: optional (s, 4) rows ``(i, j, k, r)`` (vertex i sewn to the edge j-k).

    Returns:
        (c, 3) int64 rows ``(edge vertex a, edge vertex b, face id)``, sorted.
    """
    import ipctk

    x = np.asfortranarray(np.asarray(positions, dtype=np.float64))
    tris = np.asfortranarray(np.asarray(faces, dtype=np.int32))
    edges = np.asfortranarray(ipctk.edges(tris).astype(np.int32))
    partners: dict[int, set[int]] = {}
    for i, j, k in (np.zeros((0, 3)) if stitches is None else np.asarray(stitches)[:, :3]).astype(np.int64).tolist():
        for a, b in ((i, j), (i, k)):
            partners.setdefault(a, set()).add(b)
            partners.setdefault(b, set()).add(a)
    grid = ipctk.HashGrid()
    grid.build(x, edges, tris, 0.0)
    found = []
    for candidate in grid.detect_edge_face_candidates():
        a, b = (int(v) for v in edges[candidate.edge_id])
        face = tris[candidate.face_id]
        corners = {int(v) for v in face}
        if a in corners or b in corners:
            continue
        if corners & (partners.get(a, set()) | partners.get(b, set())):
            continue
        if ipctk.is_edge_intersecting_triangle(x[a], x[b], x[face[0]], x[face[1]], x[face[2]]):
            found.append((min(a, b), max(a, b), int(candidate.face_id)))
    return np.array(sorted(found), dtype=np.int64).reshape(-1, 3)


def cloth_crossings(positions: np.ndarray, faces: np.ndarray, cloth_vertices: int, cloth_faces: int,
                    stitches: np.ndarray | None = None) -> np.ndarray:
    """The :func:`crossings` that involve the cloth: its edges through any face, any edge through its faces.

    The cloth's vertices and faces come first in ``positions`` and ``faces``; the rest is obstacles, which may
    cross each other or themselves (a skinned body folds into itself at a bent knee) without harm.
    """
    found = crossings(positions, faces, stitches)
    return found[(found[:, 0] < cloth_vertices) | (found[:, 2] < cloth_faces)]
