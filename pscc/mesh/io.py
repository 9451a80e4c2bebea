"""Reading and writing triangle meshes: OBJ, PLY and NPZ.

Every loader keeps the file's vertex and face order (nothing is merged, reordered or
triangulated) and funnels the arrays through :func:`pscc.mesh.mesh_data.validate_mesh`, so a bad
file raises :class:`pscc.errors.InputError` whose message names the file, the field (an NPZ key,
an OBJ line, a PLY element) and the fix. See ``docs/mesh-input.md`` for the format details.
"""

from __future__ import annotations

import math
import os
import zipfile
from pathlib import Path
from typing import Any

import numpy as np

from pscc._atomic import write_atomic
from pscc._checks import INT32_MAX, check_coordinate_range, check_points, read_input_bytes, shorten
from pscc.errors import InputError
from pscc.mesh._ply import load_ply
from pscc.mesh.mesh_data import MeshData, _validate_mesh, check_stitches

SUPPORTED_EXTENSIONS: tuple[str, ...] = (".obj", ".ply", ".npz")
"""File extensions :func:`load_mesh` understands (matched case-insensitively)."""

_NPZ_REQUIRED = ("vertices", "faces")
_NPZ_OPTIONAL = ("vertices_end", "rest", "object_ids", "uv", "stitches")


# --------------------------------------------------------------------------------------------
# Public API
# --------------------------------------------------------------------------------------------


def open_usd_stage(path: str | os.PathLike[str], fix: str) -> Any:
    """Open a USD file as a ``Usd.Stage``; a file pxr cannot parse is an :class:`InputError` naming the file,
    pxr's reason and ``fix`` (pxr itself raises ``Tf.ErrorException`` or returns None).

    Raises:
        InputError: the stage cannot be opened.
    """
    import re

    from pxr import Usd

    source = str(path)
    try:
        stage = Usd.Stage.Open(source)
    except Exception as exc:  # Tf.ErrorException, which pxr does not expose as a base class to catch
        reasons = re.findall(r": '([^']*)'", str(exc))  # pxr's messages end in ": '<reason>'"
        reason = reasons[0] if reasons else " ".join(str(exc).split())[:200]
        raise InputError(source, "file", f"cannot be opened as a USD stage ({reason})", fix) from exc
    if stage is None:
        raise InputError(source, "file", "cannot be opened as a USD stage", fix)
    return stage


def load_mesh(path: str | os.PathLike[str]) -> MeshData:
    """Load a triangle mesh from an OBJ, PLY or NPZ file.

    The format is chosen from the extension (case-insensitive). Vertex and face order are kept.

    * ``.obj``: ``v`` and triangular ``f`` lines (``i``, ``i/j``, ``i//k``, ``i/j/k``, negative
      relative indices); each ``o`` or ``g`` line that follows a face starts a new object id; ``vt``
      lines referenced by the faces become the vertices' ``uv``; ``stitch i j k r`` lines (0-based ids,
      the convention of Codim-IPC's garment inputs) the ``stitches``.
    * ``.ply``: ASCII or binary; a face property ``object_id`` becomes the object ids, vertex
      properties ``s, t`` (or ``u, v``, ``texture_u, texture_v``) the ``uv``.
    * ``.npz``: keys ``vertices`` and ``faces``, optional ``vertices_end``, ``rest``, ``object_ids``,
      ``uv``, ``stitches``.

    Args:
        path: The mesh file.

    Returns:
        The validated mesh; its ``source`` is ``str(path)``.

    Raises:
        InputError: the file does not exist or cannot be read, the extension is not supported,
            the file is malformed (the message names the OBJ line or NPZ key), a face is not a
            triangle, or the mesh fails :func:`pscc.mesh.mesh_data.validate_mesh`.
    """
    file_path, extension = _check_path(path)
    if extension == ".obj":
        return _load_obj(file_path)
    if extension == ".ply":
        return load_ply(file_path)
    return _load_npz(file_path)


def load_positions(path: str | os.PathLike[str], vertex_count: int) -> np.ndarray:
    """Read vertex positions (e.g. the end of a step) from a second mesh file.

    For OBJ and PLY the file must be a valid mesh (its faces are validated but otherwise
    ignored); for NPZ only the ``vertices`` key is read. The positions must be in the same vertex
    order as the mesh they belong to.

    Args:
        path: An OBJ, PLY or NPZ file.
        vertex_count: The number of vertices the positions must have.

    Returns:
        (vertex_count, 3) float32 positions.

    Raises:
        InputError: any problem :func:`load_mesh` reports, or a vertex count that differs from
            ``vertex_count``.
    """
    if isinstance(vertex_count, bool) or not isinstance(vertex_count, int | np.integer) \
            or vertex_count < 0:
        raise InputError("argument", "vertex_count", f"{vertex_count!r} is not an integer >= 0",
                         "pass the vertex count of the mesh the positions belong to")
    file_path, extension = _check_path(path)
    source = str(file_path)
    if extension == ".npz":
        with _open_npz(file_path) as archive:
            raw = _npz_array(archive, "vertices", source, required=True)
        positions = check_points(raw, "vertices", shape_tail=(3,), source=source)
        positions = np.array(positions, dtype=np.float32, order="C", copy=True)
        check_coordinate_range(positions, "vertices", source=source)
    else:
        positions = load_mesh(file_path).vertices
    if positions.shape[0] != int(vertex_count):
        raise InputError(source, "vertices",
                         f"has {positions.shape[0]} vertices but the mesh has {int(vertex_count)}",
                         "use a file with the same vertices, in the same order, as the mesh")
    return positions


def save_mesh_npz(path: str | os.PathLike[str], mesh: MeshData) -> None:
    """Write a mesh to an NPZ file that :func:`load_mesh` reads back unchanged.

    The write is atomic: the data goes to a temporary file in the same directory, which then
    replaces ``path``. Optional arrays that are None are not written.

    Args:
        path: Destination file; give it the ``.npz`` extension so :func:`load_mesh` recognises it.
        mesh: The mesh to write.

    Raises:
        InputError: the destination directory does not exist.
        OutputError: the file system refused the write (full disk, no permission).
    """
    target = Path(path)
    directory = target.parent
    if not directory.is_dir():
        raise InputError(str(target), "path", f"directory {str(directory)!r} does not exist",
                         "create the directory first or choose another output path")
    arrays: dict[str, np.ndarray] = {
        "vertices": mesh.vertices,
        "faces": mesh.faces,
        "object_ids": mesh.object_ids,
    }
    if mesh.vertices_end is not None:
        arrays["vertices_end"] = mesh.vertices_end
    if mesh.rest is not None:
        arrays["rest"] = mesh.rest
    if mesh.uv is not None:
        arrays["uv"] = mesh.uv
    if mesh.stitches is not None:
        arrays["stitches"] = mesh.stitches
    write_atomic(target, lambda stream: np.savez(stream, **arrays))


# --------------------------------------------------------------------------------------------
# Shared helpers
# --------------------------------------------------------------------------------------------


def _check_path(path: str | os.PathLike[str]) -> tuple[Path, str]:
    """Return ``(path, lower-case extension)`` after checking the extension and existence."""
    try:
        file_path = Path(path)
    except TypeError as exc:
        raise InputError(repr(path), "path", "is not a file path",
                         "pass a str or pathlib.Path naming a mesh file") from exc
    extension = file_path.suffix.lower()
    if extension not in SUPPORTED_EXTENSIONS:
        shown = extension or "(none)"
        raise InputError(str(file_path), "extension", f"extension {shown} is not supported",
                         "use one of " + ", ".join(SUPPORTED_EXTENSIONS) + " (case-insensitive)")
    if not file_path.exists():
        if os.path.lexists(file_path):
            raise InputError(str(file_path), "path", "is a broken or looping link",
                             "point the link at a mesh file, or pass the mesh file itself")
        where = "" if file_path.is_absolute() else f" (relative to {os.getcwd()!r})"
        raise InputError(str(file_path), "path", "file does not exist",
                         f"check the path {str(file_path)!r}{where}")
    if not file_path.is_file():
        raise InputError(str(file_path), "path", "is not a regular file",
                         f"pass the path of a mesh file, not {str(file_path)!r}")
    return file_path, extension



# --------------------------------------------------------------------------------------------
# OBJ
# --------------------------------------------------------------------------------------------



def _obj_error(source: str, lineno: int, problem: str, fix: str) -> InputError:
    return InputError(source, f"line {lineno}", problem, fix)


def _load_obj(path: Path) -> MeshData:
    """Order-preserving OBJ parser that reports errors by line number."""
    source = str(path)
    data = read_input_bytes(path)
    if b"\x00" in data:
        raise InputError(source, "file", "contains NUL bytes; it is not a text OBJ file",
                         "export the mesh as a text Wavefront OBJ file")
    text = data.decode("utf-8", errors="replace")

    coords: list[float] = []
    vertex_count = 0
    texture: list[tuple[float, float]] = []  # the vt lines
    corner_texture: list[int] = []  # per face corner: 0-based vt id, or -1 when the corner has none
    uv_issue: str | None = None  # the first bad vt reference (the texture coordinates are then unusable)
    stitches: list[list[float]] = []  # 'stitch i j k r' lines
    stitch_lines: list[int] = []
    face_ids: list[int] = []
    face_lines: list[int] = []
    object_ids: list[int] = []
    current_object = 0
    face_since_object = False

    for lineno, line in enumerate(text.splitlines(), start=1):
        comment = line.find("#")
        if comment >= 0:
            line = line[:comment]
        parts = line.split()
        if not parts:
            continue
        keyword = parts[0]
        if keyword == "v":
            if len(parts) < 4:
                raise _obj_error(source, lineno, f"vertex line {line.strip()!r} has fewer than 3 "
                                 "coordinates", "write vertices as 'v x y z'")
            try:
                x, y, z = float(parts[1]), float(parts[2]), float(parts[3])
            except ValueError as exc:
                raise _obj_error(source, lineno, f"malformed number in vertex line {line.strip()!r}",
                                 "write vertices as 'v x y z' with decimal numbers") from exc
            if not (math.isfinite(x) and math.isfinite(y) and math.isfinite(z)):
                raise _obj_error(source, lineno,
                                 f"vertex {vertex_count + 1} holds NaN or Inf ({line.strip()!r})",
                                 "remove or repair non-finite coordinates")
            coords.extend((x, y, z))
            vertex_count += 1
        elif keyword == "f":
            corners = parts[1:]
            if len(corners) > 3:
                raise _obj_error(source, lineno, f"face has {len(corners)} vertices; faces must be "
                                 "triangles", "triangulate the mesh before loading it")
            if len(corners) < 3:
                raise _obj_error(source, lineno, f"face has only {len(corners)} vertices",
                                 "give each face exactly 3 vertex indices, 'f i j k'")
            for corner in corners:
                texture_id = _obj_texture_index(lineno, corner, len(texture))
                if isinstance(texture_id, str):
                    uv_issue = uv_issue or texture_id
                    texture_id = -1
                corner_texture.append(texture_id)
                head = corner.split("/", 1)[0]
                try:
                    index = int(head)
                except ValueError as exc:
                    raise _obj_error(source, lineno, f"malformed vertex index {corner!r} in face",
                                     "write faces as 'f i j k' (or i/j, i//k, i/j/k) with integer "
                                     "indices") from exc
                if abs(index) > INT32_MAX:
                    # pscc stores vertex ids as int32; a longer id cannot name a vertex (and would
                    # overflow the int64 face array).
                    raise _obj_error(source, lineno, f"vertex index {shorten(head)} in face is out of range "
                                     f"(more than {INT32_MAX} in magnitude; the file defines {vertex_count} "
                                     "vertices so far)", "use vertex indices between 1 and the number of 'v' lines")
                if index > 0:
                    index -= 1
                elif index < 0:
                    resolved = vertex_count + index
                    if resolved < 0:
                        raise _obj_error(source, lineno,
                                         f"relative vertex index {index} points before the first "
                                         f"vertex (only {vertex_count} vertices defined so far)",
                                         "fix the negative index or use absolute 1-based indices")
                    index = resolved
                else:
                    raise _obj_error(source, lineno, "vertex index 0 is invalid (OBJ indices start "
                                     "at 1)", "use 1-based vertex indices")
                face_ids.append(index)
            face_lines.append(lineno)
            object_ids.append(current_object)
            face_since_object = True
        elif keyword in ("o", "g"):
            if face_since_object:
                current_object += 1
                face_since_object = False
        elif keyword == "stitch":
            try:
                if len(parts) != 5:
                    raise ValueError
                stitches.append([float(int(parts[1])), float(int(parts[2])), float(int(parts[3])), float(parts[4])])
            except ValueError as exc:
                raise _obj_error(source, lineno, f"malformed stitch line {line.strip()!r}",
                                 "write stitches as 'stitch i j k r': 0-based vertex ids, vertex i sewn to "
                                 "(1 - r) x_j + r x_k") from exc
            stitch_lines.append(lineno)
        elif keyword == "vt":
            try:
                u, v = float(parts[1]), float(parts[2]) if len(parts) > 2 else 0.0
            except (IndexError, ValueError) as exc:
                raise _obj_error(source, lineno, f"malformed texture coordinate line {line.strip()!r}",
                                 "write texture coordinates as 'vt u v' with decimal numbers") from exc
            if not (math.isfinite(u) and math.isfinite(v)):
                raise _obj_error(source, lineno, f"texture coordinate {len(texture) + 1} holds NaN or Inf",
                                 "remove or repair non-finite texture coordinates")
            texture.append((u, v))
        # Everything else (vn, vp, usemtl, mtllib, s, l, ...) carries nothing pscc needs.

    vertices = np.asarray(coords, dtype=np.float64).reshape(-1, 3)
    faces = np.asarray(face_ids, dtype=np.int64).reshape(-1, 3)
    if faces.size:
        too_big = np.flatnonzero((faces >= vertex_count).any(axis=1))
        if too_big.size:
            row = int(too_big[0])
            index = int(faces[row].max()) + 1
            raise _obj_error(source, face_lines[row],
                             f"face refers to vertex {index} but the file defines only "
                             f"{vertex_count} vertices", "use vertex indices between 1 and the "
                             "number of 'v' lines")

    def face_label(row: int) -> str:
        return f"row {row} (line {face_lines[row]})"

    uv = None
    if uv_issue is None:
        uv, uv_issue = _obj_vertex_uv(np.asarray(corner_texture, dtype=np.int64).reshape(-1, 3), faces, texture,
                                      face_lines, vertex_count)
    stitch_rows = None
    if stitches:
        try:
            stitch_rows = check_stitches(np.asarray(stitches), vertex_count, source)
        except InputError as error:  # name the line: "stitch 3 ..." -> the file's line of stitch 3
            row = int(error.problem.split()[1]) if error.problem.startswith("stitch ") else 0
            raise _obj_error(source, stitch_lines[row], error.problem, error.fix) from None
    return _validate_mesh(vertices, faces, source=source, vertices_end=None, rest=None,
                          object_ids=np.asarray(object_ids, dtype=np.int64), face_label=face_label, uv=uv,
                          uv_issue=uv_issue, stitches=stitch_rows)


def _obj_texture_index(lineno: int, corner: str, texture_count: int) -> int | str:
    """0-based ``vt`` id of a face corner ``v/vt`` or ``v/vt/vn``; -1 for ``v`` or ``v//vn``; a message
    (naming the line) when the corner's ``vt`` index is malformed or names no ``vt`` line above it."""
    fields = corner.split("/")
    if len(fields) < 2 or fields[1] == "":
        return -1
    try:
        index = int(fields[1])
    except ValueError:
        return f"line {lineno}: malformed texture coordinate index in face corner {corner!r}"
    resolved = index - 1 if index > 0 else texture_count + index
    if index == 0 or not 0 <= resolved < texture_count:
        return (f"line {lineno}: face corner {corner!r} refers to texture coordinate {index}, but the file defines "
                f"{texture_count} 'vt' lines before it")
    return resolved


def _obj_vertex_uv(corner_texture: np.ndarray, faces: np.ndarray, texture: list[tuple[float, float]],
                   face_lines: list[int], vertex_count: int) -> tuple[np.ndarray | None, str | None]:
    """One (u, v) per vertex from the faces' ``v/vt`` corners, or None and why not.

    None without a reason when no face has texture coordinates; None with the reason (naming the line
    and the vertex) when a face lacks them next to faces with them, or a vertex is used with two
    different (u, v) (a UV seam through a shared vertex). Neither stops the mesh from loading: only a
    rest shape taken from the uv needs them. Vertices no face uses get (0, 0).
    """
    if corner_texture.size == 0 or (corner_texture < 0).all():
        return None, None
    missing = np.flatnonzero((corner_texture < 0).any(axis=1))
    if missing.size:
        row = int(missing[0])
        return None, (f"line {face_lines[row]}: this face has no texture coordinates (v/vt) while other faces "
                      "have them")
    table = np.asarray(texture, dtype=np.float64)
    corner_uv = table[corner_texture.reshape(-1)]
    vertex = faces.reshape(-1)
    uv = np.zeros((vertex_count, 2), dtype=np.float64)
    first = np.full(vertex_count, -1, dtype=np.int64)
    order = np.arange(vertex.shape[0])
    first[vertex[::-1]] = order[::-1]  # the first corner of each vertex
    uv[vertex] = corner_uv[first[vertex]]
    clash = np.flatnonzero((corner_uv != uv[vertex]).any(axis=1))
    if clash.size:
        corner = int(clash[0])
        v = int(vertex[corner])
        return None, (f"line {face_lines[corner // 3]}: vertex {v + 1} has texture coordinates "
                      f"{corner_uv[corner].tolist()} here but {uv[v].tolist()} in the face at line "
                      f"{face_lines[int(first[v]) // 3]}: one vertex with two different (u, v) (a UV seam through a "
                      "shared vertex)")
    return uv, None


# --------------------------------------------------------------------------------------------
# NPZ
# --------------------------------------------------------------------------------------------


def _open_npz(path: Path) -> Any:
    source = str(path)
    try:
        archive = np.load(path, allow_pickle=False)
    except OSError as exc:
        raise InputError(source, "file", f"cannot be read ({exc})",
                         "check the file permissions and that it is an NPZ archive") from exc
    except (ValueError, EOFError, zipfile.BadZipFile) as exc:
        raise InputError(source, "file", f"is not a readable NPZ archive ({exc})",
                         "write it with numpy.savez or pscc.mesh.save_mesh_npz") from exc
    if not hasattr(archive, "files"):
        raise InputError(source, "file", "holds a single .npy array, not an NPZ archive",
                         "write it with numpy.savez(path, vertices=..., faces=...)")
    return archive


def _npz_array(archive: Any, key: str, source: str, *, required: bool) -> np.ndarray | None:
    if key not in archive.files:
        if required:
            raise InputError(source, key, f"required key {key!r} is missing (keys: "
                             f"{sorted(archive.files)})", f"save the array under the key {key!r}")
        return None
    try:
        return np.asarray(archive[key])
    except (ValueError, OSError, EOFError, zipfile.BadZipFile) as exc:
        raise InputError(source, key, f"cannot be read ({exc})",
                         "store a plain numeric array (no Python objects) under this key") from exc


def _load_npz(path: Path) -> MeshData:
    source = str(path)
    with _open_npz(path) as archive:
        arrays = {key: _npz_array(archive, key, source, required=True) for key in _NPZ_REQUIRED}
        arrays.update({key: _npz_array(archive, key, source, required=False) for key in _NPZ_OPTIONAL})
    return _validate_mesh(arrays["vertices"], arrays["faces"], source=source,
                          vertices_end=arrays["vertices_end"], rest=arrays["rest"],
                          object_ids=arrays["object_ids"], face_label=None, uv=arrays["uv"],
                          stitches=arrays["stitches"])
