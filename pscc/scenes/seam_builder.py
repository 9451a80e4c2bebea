"""Stitches between two boundaries of cloth pieces: order each boundary, then resample one along the other.

A scene file's ``[[cloth.stitches]]`` table names two sets of boundary vertices (a side of a pattern, an
armhole, a hem; see ``docs/scene-files.md``). :func:`boundary_path` orders each set along the mesh
boundary (an open path or a closed loop), and :func:`sew` sews every vertex of the first path to the point
of the second at the same fraction of its length, measured in the rest shape: stitch rows ``(i, j, k, r)``
as :attr:`pscc.sim.scene.Scene.stitches` takes them. Two boundaries of different lengths (a gathered
seam) are sewn proportionally. The second path is oriented so that its start is the nearer end (in the
placed positions) to the first path's start, unless the caller says otherwise.
"""

from __future__ import annotations

import numpy as np

__all__ = ["boundary_path", "sew"]


def boundary_path(faces: np.ndarray, vertices: np.ndarray) -> tuple[np.ndarray, bool]:
    """The selected vertices in order along the mesh boundary, and whether they form a closed loop.

    Args:
        faces: (m, 3) triangles of the piece.
        vertices: the selected vertex ids (any order).

    Returns:
        (ordered ids, closed). An open path starts at its end with the smaller id.

    Raises:
        ValueError: fewer than 2 vertices, a vertex that is not joined to the others by boundary edges
            (edges of one face), or a selection that is not one simple path or loop.
    """
    selected = np.unique(np.asarray(vertices, dtype=np.int64))
    if selected.size < 2:
        raise ValueError(f"selects {selected.size} vertex; a seam needs a boundary of at least 2")
    tris = np.asarray(faces, dtype=np.int64)
    edges = np.sort(np.concatenate([tris[:, [0, 1]], tris[:, [1, 2]], tris[:, [2, 0]]]), axis=1)
    unique, counts = np.unique(edges, axis=0, return_counts=True)
    boundary = unique[counts == 1]
    inside = np.isin(boundary, selected).all(axis=1)
    boundary = boundary[inside]
    neighbours: dict[int, list[int]] = {int(v): [] for v in selected}
    for a, b in boundary.tolist():
        neighbours[a].append(b)
        neighbours[b].append(a)
    lonely = [v for v, n in neighbours.items() if not n]
    if lonely:
        raise ValueError(f"vertex {lonely[0]} is not joined to the other selected vertices by a boundary edge "
                         "(select vertices of one boundary of the piece)")
    branching = [v for v, n in neighbours.items() if len(n) > 2]
    if branching:
        raise ValueError(f"the boundary edges between the selected vertices branch at vertex {branching[0]}")
    ends = sorted(v for v, n in neighbours.items() if len(n) == 1)
    closed = not ends
    if len(ends) not in (0, 2):
        raise ValueError(f"the selected vertices form {len(ends) // 2} separate pieces of boundary, not one")
    start = ends[0] if ends else int(selected[0])
    path = [start]
    previous = -1
    while True:
        step = [n for n in neighbours[path[-1]] if n != previous]
        if not step or (closed and step[0] == start):
            break
        previous = path[-1]
        path.append(step[0])
        if len(path) > selected.size:
            break
    if len(path) != selected.size:
        raise ValueError("the selected vertices do not lie on one boundary path or loop")
    return np.asarray(path, dtype=np.int64), closed


def _fractions(rest: np.ndarray, path: np.ndarray, closed: bool) -> np.ndarray:
    """Normalised rest arc length at each vertex of the path (and at the closing vertex of a loop)."""
    points = rest[np.concatenate([path, path[:1]]) if closed else path].astype(np.float64)
    lengths = np.linalg.norm(np.diff(points, axis=0), axis=1)
    total = float(lengths.sum())
    if total <= 0.0:
        raise ValueError("the boundary has zero rest length")
    return np.concatenate([[0.0], np.cumsum(lengths) / total])


def _arrange(target: np.ndarray, closed: bool, placed: np.ndarray, anchor: np.ndarray, follow: np.ndarray,
             reverse: bool | None) -> tuple[np.ndarray, bool]:
    """The target path to sew along, and whether it runs against its :func:`boundary_path` order.

    A loop starts at its vertex nearest ``anchor`` (the source's first vertex); with ``reverse`` None it
    runs towards ``follow`` (the source's second vertex), an open path starts at its end nearer ``anchor``.
    """
    if closed:
        base = np.roll(target, -int(np.argmin(np.linalg.norm(placed[target] - anchor, axis=1))))
        backwards = np.concatenate([base[:1], base[1:][::-1]])
        if reverse is None:
            reverse = bool(np.linalg.norm(placed[backwards[1]] - follow) < np.linalg.norm(placed[base[1]] - follow))
        return (backwards if reverse else base), reverse
    if reverse is None:
        reverse = bool(np.linalg.norm(placed[target[-1]] - anchor) < np.linalg.norm(placed[target[0]] - anchor))
    return (target[::-1] if reverse else target), reverse


def sew(source: np.ndarray, source_closed: bool, source_rest: np.ndarray, target: np.ndarray, target_closed: bool,
        target_rest: np.ndarray, source_positions: np.ndarray, target_positions: np.ndarray,
        reverse: bool | None = None) -> tuple[np.ndarray, bool]:
    """Stitch rows sewing every vertex of ``source`` to the point of ``target`` at the same fraction of
    its rest length.

    Args:
        source: ordered vertex ids of the first boundary (:func:`boundary_path`), in the first piece.
        source_closed: whether it is a loop.
        source_rest: the first piece's rest coordinates (lengths are measured there).
        target: ordered vertex ids of the second boundary, in the second piece.
        target_closed: whether it is a loop (both or neither must be).
        target_rest: the second piece's rest coordinates.
        source_positions: the first piece's placed start positions (to orient the second boundary).
        target_positions: the second piece's placed start positions.
        reverse: None: orient the second boundary by the positions (module docstring); True / False:
            run it against / along its :func:`boundary_path` order (a loop still starts at its vertex
            nearest the first boundary's start).

    Returns:
        (rows, reversed): (len(source), 4) float64 rows (i, j, k, r) with i in the first piece's ids and
        j, k in the second's, and whether the second boundary was run backwards.

    Raises:
        ValueError: a loop sewn to an open path.
    """
    if source_closed != target_closed:
        raise ValueError("sews a closed loop to an open boundary: select both as loops or both as paths")
    placed_source = np.asarray(source_positions, dtype=np.float64)
    ahead, reversed_ = _arrange(target, target_closed, np.asarray(target_positions, dtype=np.float64),
                                placed_source[source[0]], placed_source[source[1]], reverse)
    s = _fractions(source_rest, source, source_closed)[: len(source)]
    t = _fractions(target_rest, ahead, target_closed)
    loop = np.concatenate([ahead, ahead[:1]]) if target_closed else ahead
    rows = np.zeros((len(source), 4), dtype=np.float64)
    for a, fraction in enumerate(s):
        b = min(int(np.searchsorted(t, fraction, side="right")) - 1, len(t) - 2)
        span = t[b + 1] - t[b]
        r = 0.0 if span <= 0.0 else min(max((fraction - t[b]) / span, 0.0), 1.0)
        rows[a] = (source[a], loop[b], loop[b + 1], r)
    return rows, reversed_
