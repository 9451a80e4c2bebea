"""Reading and writing triangle meshes: OBJ, PLY and NPZ.

Every loader keeps the file's vertex and face order (nothing is merged, reordered or
triangulated) and funnels the arrays through :func:`pscc.mesh.mesh_data.validate_mesh`, so a bad
file raises :class:`pscc.errors.InputError` whose message names the file, the field (an NPZ key,
an OBJ line, a PLY element) and the fix. See ``docs/mesh-input.md`` for the format details.
"""

from __future__ import annotations

import math
import os
import tempfile
import warnings
import zipfile
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from pscc._checks import check_points
from pscc.errors import InputError
from pscc.mesh.mesh_data import MeshData, _validate_mesh

SUPPORTED_EXTENSIONS: tuple[str, ...] = (".obj", ".ply", ".npz")
"""File extensions :func:`load_mesh` understands (matched case-insensitively)."""

_NPZ_REQUIRED = ("vertices", "faces")
_NPZ_OPTIONAL = ("vertices_end", "rest", "object_ids")
_PLY_INDEX_NAMES = ("vertex_indices", "vertex_index")


# --------------------------------------------------------------------------------------------
# Public API
# --------------------------------------------------------------------------------------------


def load_mesh(path: str | os.PathLike[str]) -> MeshData:
    """Load a triangle mesh from an OBJ, PLY or NPZ file.

    The format is chosen from the extension (case-insensitive). Vertex and face order are kept.

    * ``.obj``: ``v`` and triangular ``f`` lines (``i``, ``i/j``, ``i//k``, ``i/j/k``, negative
      relative indices); each ``o`` or ``g`` line that follows a face starts a new object id.
    * ``.ply``: ASCII or binary; a face property ``object_id`` becomes the object ids.
    * ``.npz``: keys ``vertices`` and ``faces``, optional ``vertices_end``, ``rest``, ``object_ids``.

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
        return _load_ply(file_path)
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
        OSError: the file system refused the write.
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
    mode = target.stat().st_mode & 0o777 if target.exists() else 0o644
    fd, temp_name = tempfile.mkstemp(dir=directory, prefix=f".{target.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "wb") as handle:
            np.savez(handle, **arrays)
            handle.flush()
            os.fsync(handle.fileno())
        os.chmod(temp_name, mode)
        os.replace(temp_name, target)
    except BaseException:
        try:
            os.unlink(temp_name)
        except FileNotFoundError:
            pass
        raise


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
        where = "" if file_path.is_absolute() else f" (relative to {os.getcwd()!r})"
        raise InputError(str(file_path), "path", "file does not exist",
                         f"check the path {str(file_path)!r}{where}")
    if not file_path.is_file():
        raise InputError(str(file_path), "path", "is not a regular file",
                         f"pass the path of a mesh file, not {str(file_path)!r}")
    return file_path, extension


def _read_bytes(path: Path) -> bytes:
    try:
        return path.read_bytes()
    except OSError as exc:
        raise InputError(str(path), "file", f"cannot be read ({exc.strerror or exc})",
                         "check the file permissions and that the file is not locked") from exc


# --------------------------------------------------------------------------------------------
# OBJ
# --------------------------------------------------------------------------------------------


def _obj_error(source: str, lineno: int, problem: str, fix: str) -> InputError:
    return InputError(source, f"line {lineno}", problem, fix)


def _load_obj(path: Path) -> MeshData:
    """Order-preserving OBJ parser that reports errors by line number."""
    source = str(path)
    data = _read_bytes(path)
    if b"\x00" in data:
        raise InputError(source, "file", "contains NUL bytes; it is not a text OBJ file",
                         "export the mesh as a text Wavefront OBJ file")
    text = data.decode("utf-8", errors="replace")

    coords: list[float] = []
    vertex_count = 0
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
                head = corner.split("/", 1)[0]
                try:
                    index = int(head)
                except ValueError as exc:
                    raise _obj_error(source, lineno, f"malformed vertex index {corner!r} in face",
                                     "write faces as 'f i j k' (or i/j, i//k, i/j/k) with integer "
                                     "indices") from exc
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
        # Everything else (vt, vn, vp, usemtl, mtllib, s, l, ...) carries nothing pscc needs.

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

    return _validate_mesh(vertices, faces, source=source, vertices_end=None, rest=None,
                          object_ids=np.asarray(object_ids, dtype=np.int64), face_label=face_label)


# --------------------------------------------------------------------------------------------
# PLY
# --------------------------------------------------------------------------------------------


def _ply_property(data: Any, name: str) -> np.ndarray:
    """Column ``name`` of a trimesh raw PLY element (a dict for ASCII, a record array for binary)."""
    return np.asarray(data[name])


def _ply_vertices(source: str, elements: Mapping[str, Any]) -> np.ndarray:
    element = elements.get("vertex")
    if element is None or not element.get("length"):
        return np.zeros((0, 3), dtype=np.float32)
    data = element.get("data")
    missing = [c for c in "xyz" if c not in element.get("properties", {})]
    if missing:
        raise InputError(source, "vertex", f"vertex element has no property {missing[0]!r}",
                         "write vertex positions as float properties x, y and z")
    if data is None:
        raise InputError(source, "vertex", "vertex data could not be read (file corrupt)",
                         "re-export the PLY file")
    try:
        columns = [_ply_property(data, c).astype(np.float64).reshape(-1) for c in "xyz"]
    except (KeyError, TypeError, ValueError) as exc:
        raise InputError(source, "vertex", "vertex data is malformed or truncated",
                         "re-export the PLY file") from exc
    length = int(element["length"])
    if any(c.shape[0] != length for c in columns):
        raise InputError(source, "vertex", f"header declares {length} vertices but the data holds "
                         "a different number (file truncated or corrupt)", "re-export the PLY file")
    return np.column_stack(columns)


def _ply_faces(source: str, elements: Mapping[str, Any]) -> tuple[np.ndarray, np.ndarray | None]:
    """Raw face index rows and optional object ids, rejecting any non-triangle face."""
    element = elements.get("face")
    if element is None or not element.get("length"):
        return np.zeros((0, 3), dtype=np.int64), None
    length = int(element["length"])
    properties: Mapping[str, str] = element.get("properties", {})
    data = element.get("data")
    name = next((n for n in _PLY_INDEX_NAMES if n in properties), None)
    if name is None:
        raise InputError(source, "face", "face element has no 'vertex_indices' list property",
                         "write faces as 'property list uchar int vertex_indices'")
    if data is None:
        raise InputError(source, "face", "face data could not be read (file corrupt)",
                         "re-export the PLY file")
    not_triangles = "faces must be triangles"
    fix_triangulate = "triangulate the mesh before exporting it"

    if isinstance(data, np.ndarray) and data.dtype.names is not None:
        # Binary PLY: a record array; the list is a record of (count 'f0', indices 'f1').
        record = data[name]
        if record.dtype.names is None or "f0" not in record.dtype.names:
            raise InputError(source, "face", "vertex_indices is not a list property",
                             "write faces as 'property list uchar int vertex_indices'")
        counts = np.asarray(record["f0"]).reshape(-1)
        bad = np.flatnonzero(counts != 3)
        if bad.size:
            row = int(bad[0])
            raise InputError(source, f"face {row}", f"face has {int(counts[row])} vertices; "
                             f"{not_triangles}", fix_triangulate)
        indices = np.asarray(record["f1"])
    else:
        # ASCII PLY: a dict of columns; equal-length lists give a 2-D array, mixed ones an
        # object array of per-face arrays.
        try:
            indices = _ply_property(data, name)
        except (KeyError, TypeError, ValueError) as exc:
            raise InputError(source, "face", "face data is malformed or truncated",
                             "re-export the PLY file") from exc
        if indices.dtype == object:
            lengths = np.fromiter((np.size(row) for row in indices.reshape(-1)), dtype=np.int64,
                                  count=indices.size)
            bad = np.flatnonzero(lengths != 3)
            if bad.size:
                row = int(bad[0])
                raise InputError(source, f"face {row}", f"face has {int(lengths[row])} vertices; "
                                 f"{not_triangles}", fix_triangulate)
            try:
                indices = np.stack([np.asarray(row).reshape(3) for row in indices.reshape(-1)])
            except (TypeError, ValueError) as exc:
                raise InputError(source, "face", "face data is malformed", "re-export the PLY file") \
                    from exc
        elif indices.ndim == 1 and length == 1:
            indices = indices.reshape(1, -1)  # trimesh squeezes a single face to 1-D
    if indices.ndim != 2 or indices.shape[0] != length:
        raise InputError(source, "face", f"header declares {length} faces but the data holds "
                         "a different number (file truncated or corrupt)", "re-export the PLY file")
    if indices.shape[1] != 3:
        raise InputError(source, "face 0", f"faces have {indices.shape[1]} vertices; {not_triangles}",
                         fix_triangulate)

    object_ids = None
    if "object_id" in properties:
        try:
            object_ids = _ply_property(data, "object_id").reshape(-1)
        except (KeyError, TypeError, ValueError) as exc:
            raise InputError(source, "object_id", "face property object_id is malformed",
                             "write object_id as one integer scalar per face") from exc
        if object_ids.dtype == object or object_ids.shape[0] != length:
            raise InputError(source, "object_id", "face property object_id is not one integer per "
                             "face", "write object_id as 'property int object_id' on the face element")
    return indices, object_ids


def _load_ply(path: Path) -> MeshData:
    """Load a PLY through trimesh's raw element data (no triangulation, merging or reordering)."""
    from trimesh.exchange.ply import load_ply

    source = str(path)
    try:
        with open(path, "rb") as handle, warnings.catch_warnings():
            warnings.simplefilter("ignore")
            loaded = load_ply(handle, fix_texture=False, prefer_color=None, skip_materials=True)
    except OSError as exc:
        raise InputError(source, "file", f"cannot be read ({exc.strerror or exc})",
                         "check the file permissions") from exc
    except Exception as exc:  # trimesh raises assorted errors on corrupt files
        raise InputError(source, "file", f"is not a readable PLY file ({exc})",
                         "re-export the mesh as a PLY file with triangle faces; mixed triangle and "
                         "quad faces in binary PLY also end up here: triangulate the mesh") from exc
    elements = loaded.get("metadata", {}).get("_ply_raw")
    if elements is None:
        raise InputError(source, "file", "trimesh returned no raw PLY elements",
                         "install a trimesh version >= 4.0")
    vertices = _ply_vertices(source, elements)
    faces, object_ids = _ply_faces(source, elements)
    return _validate_mesh(vertices, faces, source=source, vertices_end=None, rest=None,
                          object_ids=object_ids, face_label=None)


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
                          object_ids=arrays["object_ids"], face_label=None)
