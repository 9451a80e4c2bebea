"""Material coordinates for a mesh that has none: an embedding of its surface, not of its folds.

PSCC builds its BVH in material space (rest or UV coordinates), where neighbouring nodes are
neighbouring patches of cloth, so a node's normal cone measures how much its patch bends. A mesh
given without rest coordinates (frames from another system, a scanned garment) used to be built in
its first 3-D shape: folded layers lying on each other then fall into the same nodes, whose cones
span both layers and never pass, and culling nearly vanishes.

:func:`intrinsic_coordinates` places every vertex by its distances *along the surface* instead
(landmark Isomap, de Silva and Tenenbaum 2003):

1. Edge graph of the mesh weighted by 3-D edge lengths; each connected piece is embedded alone.
2. ``landmarks`` vertices by farthest-point sampling of graph distances (the first is the vertex
   farthest from the piece's lowest vertex id, so the choice is deterministic), and Dijkstra's
   distances from each to every vertex.
3. Classical multidimensional scaling of the landmarks' squared distances gives their 3-D
   coordinates; every other vertex is placed by the landmarks' distance-based triangulation.
4. The third coordinate is kept only where it earns its place (:data:`THIRD_AXIS_GAIN`): the
   distances along a surface are two-dimensional wherever the surface can be laid flat, which a
   cloth panel or a sheet, however folded, can. There the third axis holds only the errors of the
   graph distances (on the corpus frame `twisting f48`, 0.22 of the first axis's extent), and the
   BVH's splits along the longest extent then follow that noise once nodes get small: its test
   front held 397 nodes, 308 with the piece laid flat (273 over the true rest). A sewn garment,
   closed around a body, cannot be laid flat: its third axis halves the error and is kept.

Two layers folded onto each other are far apart along the surface, so they land far apart in the
embedding, while a developable sheet embeds close to its flat layout. Only the BVH's grouping uses
the coordinates: the normal-cone and contour tests run on the actual positions, so the embedding's
distortion costs culling, never correctness.

Runs once, on the host (scipy's Dijkstra), when a detector is set up without rest coordinates:
about 0.04 s for 20K triangles.
"""

from __future__ import annotations

import numpy as np

__all__ = ["DEFAULT_LANDMARKS", "FLAT_RATIO", "THIRD_AXIS_GAIN", "bvh_material", "intrinsic_coordinates",
           "landmark_stress"]

DEFAULT_LANDMARKS: int = 12
"""Landmarks per connected piece (fewer for pieces with fewer vertices)."""

FLAT_RATIO: float = 0.01
"""A connected piece of 3-D rest coordinates is flat when the smallest of its three principal extents
(singular values of its centred vertices) is at most this share of the largest."""


THIRD_AXIS_GAIN: float = 1.0 / 3.0
"""An embedded piece keeps its third coordinate only when that removes at least this share of the
distance error of its first two (:func:`landmark_stress`); otherwise the piece is laid flat (third
coordinate 0). Measured shares: the sewn `unisex_shirt` 0.54, tubes 40 x 40 cells of circumference 1
and length 0.5-4 0.45-0.57 (kept: laid flat, a tube's two sides would fall on each other); the
corpus's sheets and garment panels -0.29 to 0.09, Newton's stretched `cloth_twist` sheet 0.27, and a
ring of circumference 2 and height 0.5 0.29 (laid flat, where the ring becomes an annulus)."""


def landmark_stress(coords: np.ndarray, landmark_ids: np.ndarray, distances: np.ndarray) -> float:
    """Relative distance error of an embedding against the distances along the surface:
    ``|E - D| / |D|`` (Frobenius) with ``D = distances`` (L, m) from each landmark to every vertex and
    ``E`` the same distances between the embedded points ``coords`` (m, k).

    Args:
        coords: (m, k) embedded coordinates of the piece's vertices.
        landmark_ids: (L,) the landmarks' vertex indices into ``coords``.
        distances: (L, m) distances along the surface.
    """
    embedded = np.linalg.norm(coords[landmark_ids][:, None, :] - coords[None, :, :], axis=2)
    scale = float(np.sqrt(np.sum(distances**2)))
    if scale == 0.0:
        return 0.0
    return float(np.sqrt(np.sum((embedded - distances) ** 2))) / scale


def _edge_graph(faces: np.ndarray, positions: np.ndarray) -> object:
    """Symmetric sparse matrix of the mesh's edges weighted by their 3-D lengths (at least 1e-12)."""
    import scipy.sparse as sparse

    n = positions.shape[0]
    edges = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]]).astype(np.int64)
    lengths = np.maximum(np.linalg.norm(positions[edges[:, 0]] - positions[edges[:, 1]], axis=1), 1e-12)
    graph = sparse.coo_matrix((lengths, (edges[:, 0], edges[:, 1])), shape=(n, n)).tocsr()
    return graph.maximum(graph.T)


def _embed_piece(graph: object, landmarks: int) -> np.ndarray:
    """Landmark-MDS coordinates (m, 3) of one connected piece given its edge graph (m x m)."""
    from scipy.sparse.csgraph import dijkstra

    m = graph.shape[0]
    start = int(np.argmax(dijkstra(graph, indices=[0])[0]))
    chosen = [start]
    rows = [dijkstra(graph, indices=[start])[0]]
    nearest = rows[0].copy()
    for _ in range(min(landmarks, m) - 1):
        far = int(np.argmax(nearest))
        if nearest[far] <= 0.0:
            break
        chosen.append(far)
        rows.append(dijkstra(graph, indices=[far])[0])
        nearest = np.minimum(nearest, rows[-1])
    distances = np.stack(rows)  # (L, m)
    count = len(chosen)
    squared = distances[:, chosen] ** 2
    centring = np.eye(count) - 1.0 / count
    gram = -0.5 * centring @ squared @ centring
    values, vectors = np.linalg.eigh(gram)
    order = np.argsort(values)[::-1][:3]
    values, vectors = values[order], vectors[:, order]
    keep = values > 1e-12 * max(float(values[0]), 1e-300) if values.size else np.zeros(0, dtype=bool)
    out = np.zeros((m, 3))
    if not np.any(keep):
        return out
    pseudo_inverse = vectors[:, keep] / np.sqrt(values[keep])  # (L, k)
    mean = squared.mean(axis=1)
    out[:, : int(keep.sum())] = -0.5 * ((distances**2) - mean[:, None]).T @ pseudo_inverse
    if int(keep.sum()) == 3:
        landmark_ids = np.asarray(chosen)
        flat = landmark_stress(out[:, :2], landmark_ids, distances)
        if landmark_stress(out, landmark_ids, distances) > (1.0 - THIRD_AXIS_GAIN) * flat:
            out[:, 2] = 0.0
    return out


def intrinsic_coordinates(faces: np.ndarray, positions: np.ndarray,
                          landmarks: int = DEFAULT_LANDMARKS) -> np.ndarray:
    """(n, 3) float64 material coordinates from distances along the surface (module docstring).

    Connected pieces are embedded one by one and set side by side along x, one piece's extent apart.
    Vertices in no face keep their positions' coordinates, moved past the last piece.

    Args:
        faces: (m, 3) vertex ids.
        positions: (n, 3) positions (the mesh's first shape).
        landmarks: landmarks per piece (>= 3 for a 3-D embedding).
    """
    from scipy.sparse.csgraph import connected_components

    faces = np.asarray(faces, dtype=np.int64).reshape(-1, 3)
    positions = np.asarray(positions, dtype=np.float64).reshape(-1, 3)
    n = positions.shape[0]
    out = positions.copy()
    if faces.shape[0] == 0:
        return out
    graph = _edge_graph(faces, positions)
    count, label = connected_components(graph, directed=False)
    used = np.zeros(n, dtype=bool)
    used[faces.reshape(-1)] = True
    offset = 0.0
    for piece in range(count):
        ids = np.flatnonzero((label == piece) & used)
        if ids.size == 0:
            continue
        if ids.size < 4:
            coords = positions[ids] - positions[ids].min(axis=0)
        else:
            coords = _embed_piece(graph[ids][:, ids], landmarks)
            coords -= coords.min(axis=0)
        extent = float(np.ptp(coords, axis=0).max()) if ids.size > 1 else 0.0
        coords[:, 0] += offset
        out[ids] = coords
        offset += float(np.ptp(coords[:, 0])) + max(extent, 1e-6)
    loose = ~used
    if np.any(loose):
        out[loose] = positions[loose] - positions[loose].min(axis=0) + [offset, 0.0, 0.0]
    return out


def bvh_material(faces: np.ndarray, rest: np.ndarray | None, positions: np.ndarray) -> np.ndarray:
    """The material coordinates the BVH is built over.

    - 2-D rest coordinates, and 3-D ones of a flat piece (:data:`FLAT_RATIO`), are used as given.
    - A piece whose 3-D rest shape is not flat is embedded by distances along that rest shape
      (:func:`intrinsic_coordinates`). Such a "rest" is often another system's first frame, cloth
      already wound or folded. In 3-D its layers would share nodes. On Newton's `cloth_rollers` frame
      the test front held 7,722 nodes over its 3-D rest and 647 over the embedding (3.2M BV tests
      instead of 4.2M).
    - Without rest coordinates, the first positions are embedded the same way.

    Args:
        faces: (m, 3) vertex ids.
        rest: (n, 2) or (n, 3) rest coordinates, or None.
        positions: (n, 3) first positions (used only without rest).

    Returns:
        (n, 2) or (n, 3) coordinates: ``rest`` itself when nothing is embedded.
    """
    if rest is None:
        return intrinsic_coordinates(faces, positions)
    rest = np.asarray(rest)
    if rest.ndim != 2 or rest.shape[1] != 3:
        return rest
    from scipy.sparse.csgraph import connected_components

    faces = np.asarray(faces, dtype=np.int64).reshape(-1, 3)
    coords = rest.astype(np.float64)
    count, label = connected_components(_edge_graph(faces, coords), directed=False)
    used = np.zeros(coords.shape[0], dtype=bool)
    used[faces.reshape(-1)] = True
    curved = np.zeros(coords.shape[0], dtype=bool)
    for piece in range(count):
        ids = np.flatnonzero((label == piece) & used)
        if ids.size < 4:
            continue
        extents = np.linalg.svd(coords[ids] - coords[ids].mean(axis=0), compute_uv=False)
        if extents[-1] > FLAT_RATIO * max(float(extents[0]), 1e-300):
            curved[ids] = True
    if not curved.any():
        return rest
    embedded = intrinsic_coordinates(faces, coords)
    out = coords.copy()
    out[curved] = embedded[curved]
    return out
