"""The rest shape of a mesh piece of a scene file: its UV layout, its own rest coordinates, its best-fit
plane or its own 3-D shape (``rest`` in ``docs/scene-files.md``), with the checks that refuse a rest shape
the cloth model could not use, naming the scene file and the key."""

from __future__ import annotations

from typing import Any

import numpy as np

from pscc.mesh.mesh_data import MeshData
from pscc.scenes.table_reader import TableReader
from pscc.sim.config import SIM_MIN_REST_AREA_RATIO

FLATNESS_TOLERANCE: float = 1.0e-4
"""A mesh counts as flat (so its rest shape can be its projection onto the best-fit plane) when no
vertex is farther from that plane than this fraction of the mesh's largest extent. Dimensionless."""

REST_MODES: tuple[str, ...] = ("auto", "uv", "file", "plane", "mesh")
"""Values of a mesh piece's ``rest`` key."""

REST_BENDING: tuple[str, ...] = ("mesh", "flat")
"""Values of ``rest_bending`` (with ``rest = "mesh"``)."""

UV_AREA_RATIO_LIMIT: float = 4.0
"""``rest = "uv"`` is refused when the pattern's area (times ``uv_scale`` squared) and the mesh's differ by
more than this factor: the texture coordinates are then not in metres (the message gives the
``uv_scale`` that matches the areas)."""


class RestShapes(TableReader):
    """The rest-shape part of :class:`pscc.scenes.scene_builder.SceneBuilder`."""

    def mesh_rest(self, mesh: Any, mode: str, scale: float, uv_scale: float, piece_key: str,
                  mesh_path: str) -> tuple[np.ndarray, str]:
        """Rest coordinates of a mesh piece and the resolved mode.

        ``uv``: the file's texture coordinates times ``uv_scale`` (metres per uv unit); ``file``: the NPZ
        ``rest`` times the placement scale; ``plane``: the positions projected onto their best-fit plane;
        ``mesh``: the positions themselves, (n, 3) (each triangle keeps its own rest shape). ``auto`` takes
        uv, then the NPZ rest, then the plane when the mesh is flat, and refuses a curved mesh without
        either.
        """
        key = f"{piece_key}.rest"
        if mode == "uv" or (mode == "auto" and mesh.uv is not None):
            if mesh.uv is None and mesh.uv_issue is not None:
                raise self.error(key, f"rest = \"uv\" but the texture coordinates of {mesh_path!r} are not one (u, v) "
                                 f"per vertex: {mesh.uv_issue}",
                                 "split the vertices along the UV seams (one vertex per texture coordinate, as sewn-"
                                 "pattern garment files do) and join the pieces with stitches, or use rest = \"mesh\"")
            if mesh.uv is None:
                raise self.error(key, f"rest = \"uv\" but {mesh_path!r} has no texture coordinates",
                                 "export the garment with its UV layout (OBJ 'vt' lines and f v/vt faces, PLY s,t "
                                 "properties or an NPZ 'uv' key), or use rest = \"mesh\" to take the mesh's own shape")
            return self.uv_rest(mesh, scale, uv_scale, piece_key, mesh_path), "uv"
        if mode == "mesh":
            return mesh.vertices.astype(np.float64) * scale, "mesh"
        has_rest = mesh.rest is not None
        if mode == "file" or (mode == "auto" and has_rest):
            if not has_rest:
                raise self.error(key, f"rest = \"file\" but {mesh_path!r} has no rest coordinates",
                                 "use an NPZ file with a 'rest' key of (n, 2) (u, v) coordinates in metres, or "
                                 "rest = \"plane\" to project the positions onto their best-fit plane")
            file_rest = mesh.rest.astype(np.float64) * scale
            if file_rest.shape[1] == 2:
                return file_rest, "file"
            flat, distance, size = plane_coordinates(file_rest)
            if distance > FLATNESS_TOLERANCE * size:
                raise self.error(key, f"the 3-D rest coordinates in {mesh_path!r} are not flat (a vertex is "
                                 f"{distance:.3g} m from their best-fit plane)",
                                 "store (n, 2) (u, v) rest coordinates in the NPZ 'rest' key")
            return flat, "file"
        positions = mesh.vertices.astype(np.float64) * scale
        flat, distance, size = plane_coordinates(positions)
        if mode == "auto" and distance > FLATNESS_TOLERANCE * size:
            unusable = "" if mesh.uv_issue is None else f" (its texture coordinates cannot be: {mesh.uv_issue})"
            raise self.error(key, f"{mesh_path!r} has no usable texture or rest coordinates{unusable} and is not flat "
                             f"(a vertex is {distance:.3g} m from the best-fit plane of the positions, more than "
                             f"{FLATNESS_TOLERANCE:g} x the mesh size), so its rest shape is unknown",
                             "set rest = \"mesh\" to take the mesh's own curved shape as the rest shape (what "
                             "cloth tools do for a garment without a pattern), give the file its UV layout "
                             "(rest = \"uv\"), or set rest = \"plane\" to use the projection onto the best-fit "
                             "plane anyway (this distorts the rest lengths of curved parts)")
        return flat, "plane"

    def uv_rest(self, mesh: Any, scale: float, uv_scale: float, piece_key: str, mesh_path: str) -> np.ndarray:
        """The texture coordinates times ``uv_scale`` as the pattern, refused when their area and the placed
        mesh's differ by more than :data:`UV_AREA_RATIO_LIMIT` (uv not in metres: the message gives the
        ``uv_scale`` that matches the areas)."""
        pattern = mesh.uv.astype(np.float64) * uv_scale
        corners = pattern[mesh.faces.astype(np.int64)]
        e1, e2 = corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]
        pattern_area = 0.5 * float(np.abs(e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]).sum())
        placed = mesh.vertices.astype(np.float64)[mesh.faces.astype(np.int64)] * scale
        mesh_area = 0.5 * float(np.linalg.norm(np.cross(placed[:, 1] - placed[:, 0], placed[:, 2] - placed[:, 0]),
                                               axis=1).sum())
        if pattern_area > 0.0 and mesh_area > 0.0:
            ratio = pattern_area / mesh_area
            if not 1.0 / UV_AREA_RATIO_LIMIT <= ratio <= UV_AREA_RATIO_LIMIT:
                matching = uv_scale * (mesh_area / pattern_area) ** 0.5
                raise self.error(f"{piece_key}.uv_scale", f"the texture coordinates of {mesh_path!r} times uv_scale = "
                                 f"{uv_scale:g} cover {pattern_area:.4g} m^2, {ratio:.3g} times the mesh's "
                                 f"{mesh_area:.4g} m^2: they are not a pattern in metres",
                                 f"set uv_scale = {matching:.6g} (metres per uv unit; this matches the areas), or use "
                                 "rest = \"mesh\"")
        return pattern

    def check_rest_triangles(self, rest: np.ndarray, mesh: MeshData, requested: str, mode: str, key: str,
                             mesh_path: str) -> None:
        """Refuse a rest shape with a zero-area triangle here, naming the scene file and ``key``.

        The solver's cloth model refuses it too (same bound, ``SIM_MIN_REST_AREA_RATIO``), but there
        the message can only say ``argument: rest``. Causes: a curved mesh projected with
        ``rest = "plane"``, degenerate rest coordinates in the file, or a zero-area face in the mesh.
        """
        bad = zero_area_faces(np.asarray(rest, dtype=np.float32), mesh.faces)  # float32: what the model sees
        if not bad.size:
            return
        face = int(bad[0])
        where = f"face {face} {mesh.faces[face].tolist()} of {mesh_path!r} ({bad.size} of {mesh.face_count} faces)"
        if mode == "plane" and face in set(zero_area_faces(mesh.vertices, mesh.faces).tolist()):
            raise self.error(key, f"{where} has zero area in the mesh itself, so it has no rest shape",
                             "remove the zero-area faces from the mesh, or store (n, 2) (u, v) rest coordinates in "
                             "an NPZ 'rest' key and use rest = \"file\"")
        if mode == "plane":
            how = "rest = \"plane\"" if requested == "plane" else "rest = \"auto\" (the mesh looks flat)"
            raise self.error(key, f"{how} projects the mesh onto its best-fit plane, which folds {where} to zero "
                             "area: the mesh is too curved for that projection to be its rest shape",
                             "store (n, 2) (u, v) rest coordinates (e.g. its UV unwrap, in metres) in an NPZ "
                             "'rest' key and use rest = \"file\"")
        if mode == "uv":
            raise self.error(key, f"the texture coordinates give {where} zero area",
                             "give every face three distinct, non-collinear (u, v) in the UV layout, or use "
                             "rest = \"mesh\"")
        if mode == "mesh":
            raise self.error(key, f"rest = \"mesh\" takes the mesh's own shape, in which {where} has zero area",
                             "remove the zero-area faces from the mesh, or give it a UV layout (rest = \"uv\")")
        raise self.error(key, f"the rest coordinates in the file give {where} zero area",
                         "give every face three non-collinear (u, v) rest coordinates in the NPZ 'rest' key, or "
                         "remove that face")


def zero_area_faces(coords: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Faces whose triangle in ``coords`` (2-D or 3-D) has twice its area at most
    ``SIM_MIN_REST_AREA_RATIO`` x its longest edge squared: the cloth model's test (``pscc.sim.model``)."""
    corners = np.asarray(coords, dtype=np.float64)[np.asarray(faces, dtype=np.int64)]
    e1, e2 = corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]
    if corners.shape[2] == 2:
        twice_area = np.abs(e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0])
    else:
        twice_area = np.linalg.norm(np.cross(e1, e2), axis=1)
    edges = corners[:, [1, 2, 0]] - corners
    longest_sq = np.max(np.einsum("mkd,mkd->mk", edges, edges), axis=1)
    return np.flatnonzero(~(twice_area > SIM_MIN_REST_AREA_RATIO * longest_sq))


def plane_coordinates(points: np.ndarray) -> tuple[np.ndarray, float, float]:
    """(u, v) coordinates of points in their best-fit plane, the largest distance to it, and the size.

    The plane goes through the centroid; its normal is the direction of least variance, oriented so
    that its largest component is positive. The u axis is the x axis projected onto the plane (the
    y axis when the plane is nearly perpendicular to x), v = normal x u. For points in a plane
    z = const this gives u = x - mean(x), v = y - mean(y).
    """
    points = np.asarray(points, dtype=np.float64)
    centred = points - points.mean(axis=0)
    _, _, basis = np.linalg.svd(centred, full_matrices=False)
    normal = basis[-1] if basis.shape[0] == 3 else np.array([0.0, 0.0, 1.0])
    normal = normal / np.linalg.norm(normal)
    if normal[int(np.argmax(np.abs(normal)))] < 0.0:
        normal = -normal
    for axis in (np.array([1.0, 0.0, 0.0]), np.array([0.0, 1.0, 0.0])):
        u = axis - float(axis @ normal) * normal
        if np.linalg.norm(u) > 0.5:
            break
    u = u / np.linalg.norm(u)
    v = np.cross(normal, u)
    flat = np.stack([centred @ u, centred @ v], axis=1)
    distance = float(np.abs(centred @ normal).max()) if centred.size else 0.0
    size = float(np.ptp(points, axis=0).max()) if points.size else 0.0
    return flat, distance, size
