"""Turn each panel's material coordinates so that its mesh lines run along the axes, for the BVH's splits.

:class:`pscc.collision.bvh.MaterialBvh` cuts a panel at the median along an axis of its material
coordinates, and moves the cut to the widest gap between face centroids, so that on a structured mesh
it falls between two rows of cells. Then every node is a rectangle of whole cells: a single edge loop
whose contour test can pass. That works only when the rows run along the axes. A sheet whose material
coordinates are turned by 30 degrees is cut across its rows into ragged patches: on the corpus frame
`twisting f48` the test front then held 936 nodes instead of 301 (307 with this module). Turned
coordinates are common: UV charts laid out at an angle, and the intrinsic embedding of a mesh without
rest coordinates (:mod:`pscc.collision.intrinsic`), whose axes follow its landmarks (916 nodes; 429
with this module).

:func:`aligned_face_corners` measures each panel's dominant edge direction, modulo 90 degrees.
It builds a length-weighted histogram of the edge angles, finds the 9-degree window that holds the
most length, and takes ``phi``, the circular mean (period 90 degrees) of the edges in that window. On
a grid of cells cut into triangles, that window holds the cell sides, whatever the cells' aspect; the
diagonals lie elsewhere. For 3-D material coordinates, the angles are measured in the plane of the
panel's two largest principal axes. A panel whose edges show no dominant direction is left as it is:
an irregular triangulation, where less than :data:`MIN_COHERENCE` of the edge length lies in the
window.

The panel's frame is its mesh lines (the plane's axes turned by ``phi``) and, in 3-D, its normal.
Of the signed orderings of the coordinate axes, the one nearest that frame receives it, so a panel
already on the axes, in any order, is left alone. The move is a rotation, or a rotation and a mirror,
about each panel's own centroid. Panel centres, their order and every distance within a panel are
unchanged. Only the choice of cuts sees the turned coordinates; contours and reference vertices use
the given ones.
"""

from __future__ import annotations

import itertools

import numpy as np

__all__ = ["ALIGNED_TOLERANCE", "MIN_COHERENCE", "WINDOW_DEGREES", "aligned_face_corners"]

MIN_COHERENCE = 0.25
"""Least share of a panel's edge length whose direction lies within the dominant direction's window
(:data:`WINDOW_DEGREES`, modulo 90 degrees) for the panel to be turned. A grid of cells cut into
triangles scores about 2/3: its cell sides, whatever the cells' aspect. An irregular triangulation
scores about 9/90."""
WINDOW_DEGREES = 9
"""Width of the window around the dominant direction, in one-degree bins."""
ALIGNED_TOLERANCE = 1e-9
"""A panel whose turned frame differs from the axes by at most this much in every entry is not turned."""


def _per_panel(values: np.ndarray, panel: np.ndarray, count: int) -> np.ndarray:
    """Sums of ``values`` (rows, ...) per panel id of each row: (count, ...)."""
    flat = values.reshape(values.shape[0], -1)
    sums = np.stack([np.bincount(panel, weights=flat[:, k], minlength=count) for k in range(flat.shape[1])], axis=1)
    return sums.reshape((count, *values.shape[1:]))


def aligned_face_corners(faces: np.ndarray, material: np.ndarray, panel_of_face: np.ndarray) -> np.ndarray:
    """Each face's corners in material coordinates, turned with its panel (module docstring).

    Args:
        faces: (m, 3) int64 vertex ids.
        material: (n, 2) or (n, 3) float64 material coordinates.
        panel_of_face: (m,) panel index of each face, in ``[0, panel_count)``.

    Returns:
        (m, 3, dim) float64 corners. A panel with no dominant edge direction, or one already on the
        axes, keeps its coordinates bit for bit.
    """
    corners = material[faces]
    m, _, dim = corners.shape
    if m == 0:
        return corners
    panel = np.asarray(panel_of_face, dtype=np.int64)
    count = int(panel.max()) + 1
    faces_per_panel = np.bincount(panel, minlength=count).astype(np.float64)
    centroid = _per_panel(corners.mean(axis=1), panel, count) / faces_per_panel[:, None]
    edges = corners[:, [1, 2, 0]] - corners  # (m, 3, dim): every edge, interior ones from both sides
    if dim == 2:
        first = np.tile(np.eye(2)[0], (count, 1))
        second = np.tile(np.eye(2)[1], (count, 1))
    else:
        # The panel's plane: its two largest principal axes (face centroids, each face once).
        offsets = corners.mean(axis=1) - centroid[panel]
        covariance = _per_panel(offsets[:, :, None] * offsets[:, None, :], panel, count)
        _, vectors = np.linalg.eigh(covariance)  # ascending eigenvalues: columns 2 and 1 are the largest
        first, second = vectors[:, :, 2], vectors[:, :, 1]
    along = np.einsum("fkd,fd->fk", edges, first[panel])
    across = np.einsum("fkd,fd->fk", edges, second[panel])
    length = np.hypot(along, across).reshape(-1)
    degrees = np.degrees(np.arctan2(across, along)).reshape(-1) % 90.0  # mesh-line angles are modulo 90
    edge_panel = np.repeat(panel, 3)
    # Length-weighted histogram of the angles per panel (1-degree bins), summed over a window of
    # WINDOW_DEGREES bins around each bin (circularly): its peak is the dominant direction.
    bins = np.minimum(degrees.astype(np.int64), 89)
    histogram = np.bincount(edge_panel * 90 + bins, weights=length, minlength=count * 90).reshape(count, 90)
    half = WINDOW_DEGREES // 2
    window = sum(np.roll(histogram, shift, axis=1) for shift in range(-half, half + 1))
    peak = np.argmax(window, axis=1)
    total = np.maximum(histogram.sum(axis=1), np.finfo(np.float64).tiny)
    coherence = window[np.arange(count), peak] / total
    # The angle: the length-weighted circular mean (period 90 degrees) of the edges in the peak's window.
    offset = (degrees - (peak[edge_panel] + 0.5) + 45.0) % 90.0 - 45.0
    inside = np.abs(offset) <= half + 0.5
    weight = np.where(inside, length, 0.0)
    radians = np.radians(4.0 * degrees)
    real = np.bincount(edge_panel, weights=weight * np.cos(radians), minlength=count)
    imag = np.bincount(edge_panel, weights=weight * np.sin(radians), minlength=count)
    phi = np.arctan2(imag, real) / 4.0
    cos, sin = np.cos(phi), np.sin(phi)
    # The panel's frame, one row per axis: its mesh lines (the plane's axes turned by +phi) and, in 3-D,
    # the plane's normal. Taking coordinates in it puts the mesh lines on the axes.
    new_first = cos[:, None] * first + sin[:, None] * second
    new_second = -sin[:, None] * first + cos[:, None] * second
    rows_of_frame = [new_first, new_second] + ([np.cross(new_first, new_second)] if dim == 3 else [])
    frame = np.stack(rows_of_frame, axis=1)  # (count, dim, dim)
    # Which coordinate axis each frame row becomes: the signed permutation nearest the frame, so that a
    # panel already on the axes (in any order) is left alone, and others move as little as possible.
    best_score = np.full(count, -np.inf)
    nearest = np.zeros_like(frame)
    for order in itertools.permutations(range(dim)):
        picked = frame[:, np.arange(dim), list(order)]  # (count, dim): F[i, order[i]]
        score = np.abs(picked).sum(axis=1)
        better = score > best_score
        best_score = np.where(better, score, best_score)
        candidate = np.zeros_like(frame)
        candidate[:, np.arange(dim), list(order)] = np.where(picked >= 0.0, 1.0, -1.0)
        nearest[better] = candidate[better]
    rotation = np.einsum("pji,pjk->pik", nearest, frame)  # P^T F: frame row i goes to P's axis for row i
    # A panel already on the axes (within ALIGNED_TOLERANCE) keeps its coordinates: a turn by a rounding
    # error would only reorder ties between the centroids the cuts sort.
    on_axes = np.abs(rotation - np.eye(dim)).max(axis=(1, 2)) <= ALIGNED_TOLERANCE
    turned = (coherence >= MIN_COHERENCE) & ~on_axes
    if not turned.any():
        return corners
    result = corners.copy()
    rows = turned[panel]
    centre = centroid[panel][rows][:, None, :]
    result[rows] = centre + np.einsum("fij,fkj->fki", rotation[panel][rows], corners[rows] - centre)
    return result
