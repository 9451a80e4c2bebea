"""The validated triangle mesh every pscc entry point works on, and its single validator.

:func:`validate_mesh` is the one place where mesh arrays are checked, whether they come from a
file loader (:mod:`pscc.mesh.io`) or are passed directly to the collision detector. Everything
after it may assume the invariants listed on :class:`MeshData`.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from pscc._checks import as_numpy, check_coordinate_range, check_object_ids, check_points
from pscc.errors import InputError


@dataclass(frozen=True, eq=False)
class MeshData:
    """A validated triangle mesh, optionally with the positions at the end of a time step.

    Invariants (established by :func:`validate_mesh`):

    * ``vertices`` is a C-contiguous (n, 3) float32 array of finite numbers, n >= 1, whose largest
      |coordinate| is 0 or in [``MIN_COORDINATE_SCALE``, ``MAX_COORDINATE``] (:mod:`pscc.tolerances`).
    * ``faces`` is a C-contiguous (m, 3) int32 array, m >= 1, every index in [0, n), the three ids
      of a face distinct and no two faces made of the same three vertex ids.
    * ``vertices_end`` is None or a finite (n, 3) float32 array in the same vertex order, in the same
      coordinate range.
    * ``rest`` is None or a finite (n, 2) or (n, 3) float32 array of material coordinates.
    * ``object_ids`` is an (m,) int32 array of ids in [0, 2**31 - 1] (all zero unless given); they
      need not be contiguous.

    Vertices are never reordered or merged: row i of every per-vertex array is vertex i of the
    input. Zero-area faces and non-manifold edges are allowed.

    The arrays are owned by the instance (copied on validation); do not modify them in place.

    Attributes:
        vertices: (n, 3) float32 positions at the start of the step.
        faces: (m, 3) int32 vertex ids of each triangle.
        vertices_end: (n, 3) float32 positions at the end of the step, or None.
        rest: (n, 2) or (n, 3) float32 material-space coordinates, or None.
        object_ids: (m,) int32 object id of each face.
        source: The file path the mesh came from, or ``"argument"``.
        uv: (n, 2) float32 texture coordinates of each vertex (OBJ ``vt``, PLY ``s, t`` or ``u, v``,
            NPZ ``uv``), or None. Scene files can take a garment's rest shape from them
            (``rest = "uv"``).
        uv_issue: why the file's texture coordinates are not one (u, v) per vertex (then ``uv`` is
            None), naming the line and the vertex; None when they are or when there are none. Only a
            rest shape taken from the uv needs them, so this does not stop the mesh from loading.
        stitches: (s, 4) float64 rows ``(i, j, k, r)``: vertex i is sewn to the point (1 - r) x_j + r x_k
            (OBJ ``stitch i j k r`` lines with 0-based ids, NPZ ``stitches``), or None. Ids are distinct,
            in range, and r is in [0, 1].
    """

    vertices: np.ndarray
    faces: np.ndarray
    vertices_end: np.ndarray | None
    rest: np.ndarray | None
    object_ids: np.ndarray
    source: str
    uv: np.ndarray | None = None
    uv_issue: str | None = None
    stitches: np.ndarray | None = None

    @property
    def vertex_count(self) -> int:
        """Number of vertices n."""
        return int(self.vertices.shape[0])

    @property
    def face_count(self) -> int:
        """Number of triangles m."""
        return int(self.faces.shape[0])

    @property
    def object_count(self) -> int:
        """``max(object_ids) + 1``: one past the largest id (ids need not all be used).

        This is not the number of distinct objects (``np.unique(object_ids).size``); never size a
        per-object table by it, since an id may be as large as 2**31 - 1.
        """
        if self.object_ids.size == 0:
            return 0
        return int(self.object_ids.max()) + 1


def _to_array(value: Any, name: str, source: str, expected: str) -> np.ndarray:
    """Convert ``value`` to a NumPy array, turning ragged or odd input into an InputError."""
    try:
        return as_numpy(value)
    except (TypeError, ValueError) as exc:
        raise InputError(source, name, f"cannot be read as a rectangular array ({exc})",
                         f"pass a numeric array of shape {expected}") from exc


def _check_point_array(value: Any, name: str, source: str, tail: tuple[int, ...]) -> np.ndarray:
    """Validate a float point array like :func:`check_points` and return an owned float32 copy."""
    expected = "(n, " + ", ".join(str(s) for s in tail) + ")"
    array = _to_array(value, name, source, expected)
    with np.errstate(over="ignore"):  # values beyond float32 become Inf and are reported as such
        checked = check_points(array, name, shape_tail=tail, source=source)
    # check_points may return the caller's own buffer; the mesh must own its arrays.
    return np.array(checked, dtype=np.float32, order="C", copy=True)


def _default_row_label(row: int) -> str:
    return f"row {row}"


def _validate_mesh(
    vertices: Any,
    faces: Any,
    *,
    source: str,
    vertices_end: Any,
    rest: Any,
    object_ids: Any,
    face_label: Callable[[int], str] | None,
    uv: Any = None,
    uv_issue: str | None = None,
    stitches: Any = None,
) -> MeshData:
    """Implementation of :func:`validate_mesh`; ``face_label`` names a face row in messages.

    Loaders pass ``face_label`` to point at the file line of a face instead of its row number.
    """
    source = str(source)
    label = face_label if face_label is not None else _default_row_label

    # --- vertices -------------------------------------------------------------------------
    vertex_array = _to_array(vertices, "vertices", source, "(n, 3)")
    if vertex_array.size == 0:
        raise InputError(source, "vertices", "the mesh has no vertices (empty mesh)",
                         "pass a non-empty (n, 3) vertex array")
    verts = _check_point_array(vertex_array, "vertices", source, (3,))
    check_coordinate_range(verts, "vertices", source=source)
    n = verts.shape[0]

    # --- faces ----------------------------------------------------------------------------
    face_array = _to_array(faces, "faces", source, "(m, 3)")
    if face_array.size == 0:
        raise InputError(source, "faces", "the mesh has no faces (empty mesh)",
                         "pass a non-empty (m, 3) array of triangle vertex ids")
    if face_array.dtype.kind not in "iu":
        raise InputError(source, "faces", f"dtype {face_array.dtype} is not an integer type",
                         "pass integer vertex ids, e.g. faces.astype(np.int32) after checking that "
                         "they are whole numbers")
    if face_array.ndim != 2:
        raise InputError(source, "faces", f"shape {face_array.shape} is not (m, 3)",
                         "pass a 2-D (m, 3) array with one triangle per row")
    if face_array.shape[1] != 3:
        raise InputError(source, "faces",
                         f"shape {face_array.shape} has {face_array.shape[1]} vertex ids per face; "
                         "faces must be triangles",
                         "triangulate the mesh so every face has exactly 3 vertex ids")
    if face_array.dtype.kind == "u":
        out_of_range = face_array >= n
    else:
        out_of_range = (face_array < 0) | (face_array >= n)
    bad_rows = np.flatnonzero(out_of_range.any(axis=1))
    if bad_rows.size:
        row = int(bad_rows[0])
        col = int(np.flatnonzero(out_of_range[row])[0])
        raise InputError(source, "faces",
                         f"face {label(row)} {face_array[row].tolist()} has vertex index "
                         f"{int(face_array[row, col])} outside [0, {n}) ({n} vertices)",
                         "use 0-based vertex ids smaller than the vertex count")
    tris = np.array(face_array, dtype=np.int32, order="C", copy=True)
    m = tris.shape[0]

    repeated = (tris[:, 0] == tris[:, 1]) | (tris[:, 1] == tris[:, 2]) | (tris[:, 0] == tris[:, 2])
    bad_rows = np.flatnonzero(repeated)
    if bad_rows.size:
        row = int(bad_rows[0])
        raise InputError(source, "faces",
                         f"face {label(row)} {tris[row].tolist()} lists the same vertex id twice "
                         "(invalid topology)",
                         "remove that face or give it three distinct vertex ids (zero-area faces "
                         "made of distinct vertices are accepted)")

    if m > 1:
        keys = np.sort(tris, axis=1)
        order = np.lexsort((keys[:, 2], keys[:, 1], keys[:, 0]))  # stable: equal rows ascending
        sorted_keys = keys[order]
        same = np.flatnonzero(np.all(sorted_keys[1:] == sorted_keys[:-1], axis=1))
        if same.size:
            # Report the earliest row that repeats a previous one, with that previous row.
            k = int(same[np.argmin(order[same + 1])])
            first, second = int(order[k]), int(order[k + 1])
            raise InputError(source, "faces",
                             f"faces {label(first)} and {label(second)} use the same three vertex ids "
                             f"{sorted(tris[first].tolist())} (duplicate face)",
                             "remove one of the duplicate faces")

    # --- optional per-vertex arrays -------------------------------------------------------
    end = None
    if vertices_end is not None:
        end = _check_point_array(vertices_end, "vertices_end", source, (3,))
        check_coordinate_range(end, "vertices_end", source=source)
        if end.shape != verts.shape:
            raise InputError(source, "vertices_end",
                             f"shape {end.shape} does not match vertices shape {verts.shape}",
                             "give one end position per vertex, in the same order as vertices")

    rest_arr = None
    if rest is not None:
        raw_rest = _to_array(rest, "rest", source, "(n, 2) or (n, 3)")
        if raw_rest.ndim != 2 or raw_rest.shape[1] not in (2, 3):
            raise InputError(source, "rest", f"shape {raw_rest.shape} is not (n, 2) or (n, 3)",
                             "pass 2-D (uv) or 3-D material coordinates, one row per vertex")
        rest_arr = _check_point_array(raw_rest, "rest", source, (int(raw_rest.shape[1]),))
        if rest_arr.shape[0] != n:
            raise InputError(source, "rest",
                             f"has {rest_arr.shape[0]} rows but the mesh has {n} vertices",
                             "give one rest coordinate per vertex, in the same order as vertices")

    uv_arr = None
    if uv is not None:
        uv_arr = _check_point_array(uv, "uv", source, (2,))
        if uv_arr.shape[0] != n:
            raise InputError(source, "uv", f"has {uv_arr.shape[0]} rows but the mesh has {n} vertices",
                             "give one (u, v) texture coordinate per vertex, in the same order as vertices")

    stitch_rows = None if stitches is None else check_stitches(stitches, n, source)

    # --- object ids -----------------------------------------------------------------------
    if object_ids is None:
        ids = np.zeros(m, dtype=np.int32)
    else:
        ids = check_object_ids(object_ids, m, source=source, row_label=label)

    return MeshData(vertices=verts, faces=tris, vertices_end=end, rest=rest_arr, object_ids=ids,
                    source=source, uv=uv_arr, uv_issue=uv_issue, stitches=stitch_rows)


def check_stitches(stitches: Any, vertex_count: int, source: str, field: str = "stitches") -> np.ndarray:
    """Check (s, 4) stitch rows ``(i, j, k, r)`` (vertex i sewn to (1 - r) x_j + r x_k) and return them as
    float64 with whole-number ids. An empty array is fine.

    Raises:
        InputError: not (s, 4) finite numbers, an id that is not a whole number in [0, vertex_count),
            i equal to j or k, or r outside [0, 1]; the message names the row.
    """
    rows = _to_array(stitches, field, source, "(s, 4)")
    if rows.size == 0:
        return np.zeros((0, 4), dtype=np.float64)
    if rows.ndim != 2 or rows.shape[1] != 4 or rows.dtype.kind not in "iuf":
        raise InputError(source, field, f"shape {rows.shape} / dtype {rows.dtype} is not (s, 4) numbers",
                         "give one row (i, j, k, r) per stitch: vertex i sewn to (1 - r) x_j + r x_k")
    rows = rows.astype(np.float64)
    if not np.all(np.isfinite(rows)):
        row = int(np.flatnonzero(~np.isfinite(rows).all(axis=1))[0])
        raise InputError(source, field, f"stitch {row} holds NaN or Inf", "repair that stitch")
    ids = rows[:, :3]
    bad = np.flatnonzero(((ids != np.round(ids)) | (ids < 0) | (ids >= vertex_count)).any(axis=1))
    if bad.size:
        row = int(bad[0])
        raise InputError(source, field, f"stitch {row} {rows[row].tolist()} has a vertex id that is not a whole "
                         f"number in [0, {vertex_count})", "use 0-based vertex ids of the mesh")
    bad = np.flatnonzero((ids[:, 0] == ids[:, 1]) | (ids[:, 0] == ids[:, 2]))
    if bad.size:
        row = int(bad[0])
        raise InputError(source, field, f"stitch {row} {rows[row].tolist()} sews vertex {int(ids[row, 0])} to itself",
                         "sew a vertex to a point of another edge")
    bad = np.flatnonzero((rows[:, 3] < 0.0) | (rows[:, 3] > 1.0))
    if bad.size:
        row = int(bad[0])
        raise InputError(source, field, f"stitch {row} has r = {rows[row, 3]!r} outside [0, 1]",
                         "give r in [0, 1]: the point (1 - r) x_j + r x_k of the edge")
    return rows


def validate_mesh(
    vertices: Any,
    faces: Any,
    *,
    source: str = "argument",
    vertices_end: Any = None,
    rest: Any = None,
    object_ids: Any = None,
    uv: Any = None,
    stitches: Any = None,
) -> MeshData:
    """Check mesh arrays and return them as a :class:`MeshData`.

    This is the single validator of pscc: loaders and the collision detector both call it.
    NumPy arrays, Warp arrays and nested sequences are accepted. The arrays are copied and
    converted (float32 coordinates, int32 ids); vertices are never reordered or merged.

    Accepted on purpose: zero-area faces (three distinct vertices at coinciding or collinear
    positions) and non-manifold edges (an edge shared by three or more faces).

    Args:
        vertices: (n, 3) real positions at the start of the step.
        faces: (m, 3) integer vertex ids, 0-based.
        source: File path or ``"argument"``; every error message starts with it.
        vertices_end: Optional (n, 3) real positions at the end of the step.
        rest: Optional (n, 2) or (n, 3) real material-space coordinates.
        object_ids: Optional (m,) integer object id >= 0 per face; zeros when omitted.
        uv: Optional (n, 2) real texture coordinates, one per vertex.
        stitches: Optional (s, 4) rows ``(i, j, k, r)``: vertex i sewn to (1 - r) x_j + r x_k
            (:func:`check_stitches`).

    Returns:
        The validated mesh.

    Raises:
        InputError: empty mesh; non-numeric dtype; wrong shape (including non-triangle faces);
            non-integer face or object id dtype; a vertex id out of range; a face that lists a
            vertex id twice; two faces with the same three vertex ids; NaN or Inf coordinates;
            ``vertices`` or ``vertices_end`` whose largest |coordinate| lies outside the range the
            collision kernels support (:data:`pscc.tolerances.MAX_COORDINATE`,
            :data:`pscc.tolerances.MIN_COORDINATE_SCALE`; all-zero arrays are accepted);
            per-vertex or per-face arrays whose length does not match; negative object ids.
            The message names the source, the field, the first offending row and the fix.

    Example:
        >>> mesh = validate_mesh([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 2]])
        >>> mesh.vertex_count, mesh.face_count, mesh.object_count
        (3, 1, 1)
    """
    return _validate_mesh(vertices, faces, source=source, vertices_end=vertices_end, rest=rest,
                          object_ids=object_ids, face_label=None, uv=uv, stitches=stitches)
