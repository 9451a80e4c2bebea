"""Output formats besides NPZ: OBJ and PLY frame sequences and one animated USD stage.

Layout under the output folder ``DIR`` (``docs/output-formats.md`` has the details):

=======  ==================================  ====================================================
format   files                               content
=======  ==================================  ====================================================
npz      ``DIR/frames/frame_00000.npz``, ... the frame contract of :mod:`pscc.io.frames`
obj      ``DIR/obj/frame_00000.obj``, ...    ``o cloth_<id>`` per cloth piece, then ``o obstacles``
ply      ``DIR/ply/frame_00000.ply``, ...    one binary mesh, per-face ``object_id`` (obstacles:
                                             ``max(cloth ids) + 1``), cloth rows first
usd      ``DIR/animation.usd``               ``/World/Cloth`` and ``/World/Obstacles`` meshes, topology
                                             once, ``points`` and ``extent`` sampled per frame
=======  ==================================  ====================================================

Every file is written atomically (a temporary sibling, then ``os.replace``): a reader sees the old
file or the new one, never half a file, and a failed write leaves no temporary file behind.
Vertex coordinates round-trip exactly as float32 (OBJ writes ``%.9g``, the others binary float32).

:class:`FrameWriter` writes any set of formats frame by frame; :func:`parse_formats` turns the
``--format`` option into a tuple of names.
"""

from __future__ import annotations

import math
import re
from collections.abc import Iterable
from pathlib import Path
from types import TracebackType
from typing import Any

import numpy as np

from pscc._atomic import atomic_output, write_atomic
from pscc._checks import INT32_MAX, unused_object_ids
from pscc.errors import InputError
from pscc.io.frames import frame_path, read_frame, write_frame

__all__ = [
    "FORMATS",
    "FrameWriter",
    "UsdAnimationWriter",
    "obj_frame_path",
    "parse_formats",
    "ply_frame_path",
    "read_obj_frame",
    "read_ply_frame",
    "read_usd_frames",
    "usd_path",
    "write_obj_frame",
    "write_ply_frame",
]

FORMATS: tuple[str, ...] = ("npz", "obj", "ply", "usd")
"""Names accepted by ``--format`` (and :func:`parse_formats`), in canonical order."""

USD_FILE_NAME = "animation.usd"
"""Name of the USD stage inside the output folder."""

CLOTH_PRIM = "/World/Cloth"
"""Path of the cloth mesh in the USD stage."""

OBSTACLES_PRIM = "/World/Obstacles"
"""Path of the obstacle mesh in the USD stage (absent when the scene has no obstacles)."""

_EMPTY_VERTICES = np.zeros((0, 3), np.float32)
_EMPTY_FACES = np.zeros((0, 3), np.int32)


# --------------------------------------------------------------------------------------------
# --format and paths
# --------------------------------------------------------------------------------------------


def parse_formats(spec: str | Iterable[str]) -> tuple[str, ...]:
    """Parse ``--format`` (``"npz,obj"``; case and spaces ignored) into a tuple of names from :data:`FORMATS`.

    A sequence of strings is accepted too (each may itself hold commas). Order is kept, repeats dropped.

    Raises:
        InputError: an unknown or empty name (source ``argument``, field ``--format``).
    """
    items = [spec] if isinstance(spec, str) else list(spec)
    names: list[str] = []
    for item in items:
        for raw in str(item).split(","):
            name = raw.strip().lower()
            if not name:
                raise InputError("argument", "--format", f"{str(spec)!r} holds an empty format name",
                                 f"pass a comma-separated list of {', '.join(FORMATS)}, e.g. --format npz,usd")
            if name not in FORMATS:
                raise InputError("argument", "--format", f"unknown format {raw.strip()!r}",
                                 f"choose from {', '.join(FORMATS)} (comma-separated, e.g. --format npz,usd)")
            if name not in names:
                names.append(name)
    if not names:
        raise InputError("argument", "--format", "no format given",
                         f"pass a comma-separated list of {', '.join(FORMATS)}, e.g. --format npz,usd")
    return tuple(names)


def obj_frame_path(out_dir: Path, index: int) -> Path:
    """``out_dir/obj/frame_{index:05d}.obj``."""
    return Path(out_dir) / "obj" / f"frame_{index:05d}.obj"


def ply_frame_path(out_dir: Path, index: int) -> Path:
    """``out_dir/ply/frame_{index:05d}.ply``."""
    return Path(out_dir) / "ply" / f"frame_{index:05d}.ply"


def usd_path(out_dir: Path) -> Path:
    """``out_dir/animation.usd`` (binary crate format)."""
    return Path(out_dir) / USD_FILE_NAME


# --------------------------------------------------------------------------------------------
# Array checks shared by the writers
# --------------------------------------------------------------------------------------------


def _points(value: Any, name: str, index: int) -> np.ndarray:
    """``value`` as contiguous (n, 3) float32 without NaN or Inf (``ValueError`` otherwise)."""
    array = np.ascontiguousarray(value, dtype=np.float32)
    if array.ndim != 2 or array.shape[1] != 3:
        raise ValueError(f"frame {index}: {name} has shape {array.shape}, expected (n, 3)")
    if not np.all(np.isfinite(array)):
        raise ValueError(f"frame {index}: {name} hold NaN or Inf; not written")
    return array


def _triangles(value: Any, name: str) -> np.ndarray:
    """``value`` as contiguous (m, 3) int32 with non-negative ids (``ValueError`` otherwise)."""
    if value is None:
        return _EMPTY_FACES
    array = np.asarray(value)
    if array.size == 0:
        return _EMPTY_FACES
    if not np.issubdtype(array.dtype, np.integer) or array.ndim != 2 or array.shape[1] != 3:
        raise ValueError(f"{name}: expected an integer (m, 3) array, got {array.dtype} {array.shape}")
    if array.min() < 0:
        raise ValueError(f"{name}: negative vertex id {int(array.min())}")
    return np.ascontiguousarray(array, dtype=np.int32)


def _object_ids(value: Any, face_count: int) -> np.ndarray:
    """``value`` as (m,) int32 non-negative ids, one per cloth face (``ValueError`` otherwise)."""
    array = np.asarray(value)
    if array.size == 0 and face_count == 0:
        return np.zeros(0, np.int32)
    if not np.issubdtype(array.dtype, np.integer) or array.shape != (face_count,):
        raise ValueError(f"object_ids: expected an integer ({face_count},) array, got {array.dtype} {array.shape}")
    if array.min() < 0:
        raise ValueError(f"object_ids: negative id {int(array.min())}")
    return np.ascontiguousarray(array, dtype=np.int32)


def _check_ids_in_range(faces: np.ndarray, vertex_count: int, name: str, index: int) -> None:
    if faces.size and int(faces.max()) >= vertex_count:
        raise ValueError(f"frame {index}: {name} refer to vertex {int(faces.max())} but there are {vertex_count}")


def _frame(index: int, vertices: Any, faces: Any, object_ids: Any, obstacle_vertices: Any,
           obstacle_faces: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Checked, normalised arrays of one frame (obstacles empty when absent)."""
    vertices = _points(vertices, "cloth vertices", index)
    faces = _triangles(faces, "faces")
    object_ids = _object_ids(object_ids, faces.shape[0])
    obstacle_faces = _triangles(obstacle_faces, "obstacle_faces")
    obstacle_vertices = _EMPTY_VERTICES if obstacle_vertices is None else np.asarray(obstacle_vertices)
    if obstacle_vertices.size == 0:
        obstacle_vertices = _EMPTY_VERTICES
    obstacle_vertices = _points(obstacle_vertices, "obstacle vertices", index)
    _check_ids_in_range(faces, vertices.shape[0], "faces", index)
    _check_ids_in_range(obstacle_faces, obstacle_vertices.shape[0], "obstacle_faces", index)
    return vertices, faces, object_ids, obstacle_vertices, obstacle_faces


def _obstacle_object_id(object_ids: np.ndarray) -> int:
    """Object id given to obstacle faces in PLY and USD: one past the largest cloth id (a free id when that
    would not fit in int32)."""
    return int(unused_object_ids(object_ids, 1)[0])


# --------------------------------------------------------------------------------------------
# OBJ
# --------------------------------------------------------------------------------------------

_OBJ_PIECE = re.compile(r"cloth(?:_(\d+))?")


def _obj_lines(tag: str, fmt: str, rows: np.ndarray) -> str:
    """``rows`` as OBJ statements, formatted in one C-level ``%`` call."""
    if rows.shape[0] == 0:
        return ""
    return ((f"{tag} {fmt} {fmt} {fmt}\n") * rows.shape[0]) % tuple(rows.ravel().tolist())


def _obj_text(index: int, vertices: np.ndarray, faces: np.ndarray, object_ids: np.ndarray,
              obstacle_vertices: np.ndarray, obstacle_faces: np.ndarray) -> str:
    n, k = vertices.shape[0], obstacle_vertices.shape[0]
    parts = [
        f"# pscc frame {index}: {n} cloth vertices, {faces.shape[0]} cloth faces, "
        f"{k} obstacle vertices, {obstacle_faces.shape[0]} obstacle faces; units: metres\n",
        "# objects: cloth_<object id> (faces sorted by id, stable), then obstacles\n",
    ]
    order = np.argsort(object_ids, kind="stable")
    faces, object_ids = faces[order] + 1, object_ids[order]
    pieces, starts = np.unique(object_ids, return_index=True)
    ends = np.append(starts[1:], faces.shape[0])
    parts.append(f"o cloth_{int(pieces[0])}\n" if pieces.size else "o cloth\n")
    parts.append(_obj_lines("v", "%.9g", vertices))
    for number, (piece, start, end) in enumerate(zip(pieces, starts, ends, strict=True)):
        if number:
            parts.append(f"o cloth_{int(piece)}\n")
        parts.append(_obj_lines("f", "%d", faces[start:end]))
    if k or obstacle_faces.shape[0]:
        parts.append("o obstacles\n")
        parts.append(_obj_lines("v", "%.9g", obstacle_vertices))
        parts.append(_obj_lines("f", "%d", obstacle_faces + (n + 1)))
    return "".join(parts)


def write_obj_frame(out_dir: Path, index: int, vertices: np.ndarray, faces: np.ndarray, object_ids: np.ndarray,
                    obstacle_vertices: np.ndarray | None = None, obstacle_faces: np.ndarray | None = None) -> Path:
    """Write frame ``index`` as ``out_dir/obj/frame_{index:05d}.obj`` (atomically); return its path.

    Layout: all cloth vertices (under the first cloth object), then one ``o cloth_<id>`` object per
    cloth piece holding that piece's faces (faces stably sorted by object id; the order is unchanged
    when ids never decrease), then ``o obstacles`` with the obstacle vertices and faces. Coordinates
    are written with ``%.9g``: every float32 value reads back bit for bit.

    Raises:
        ValueError: NaN or Inf, bad shapes, or face ids out of range.
    """
    arrays = _frame(index, vertices, faces, object_ids, obstacle_vertices, obstacle_faces)
    data = _obj_text(index, *arrays).encode("ascii")
    return write_atomic(obj_frame_path(out_dir, index), lambda stream: stream.write(data))


def _short(value: object, limit: int = 40) -> str:
    """``str(value)`` cut to ``limit`` characters, so that a huge token keeps a message short."""
    text = str(value)
    return text if len(text) <= limit else f"{text[:limit - 3]}... ({len(text)} characters)"


def read_obj_frame(path: Path) -> dict[str, np.ndarray]:
    """Read an OBJ frame written by :func:`write_obj_frame` into the keys of :data:`pscc.io.frames.FRAME_KEYS`.

    Objects named ``cloth_<id>`` (or ``cloth``, id 0) are cloth pieces, ``obstacles`` the obstacles;
    faces before any ``o`` line are cloth with id 0. Corners may be ``i``, ``i/j``, ``i//k`` or
    ``i/j/k``; negative ids count back from the latest vertex. Cloth faces come back in file order
    (sorted by object id, see :func:`write_obj_frame`). Other OBJ files: use :func:`pscc.mesh.load_mesh`.

    Raises:
        InputError: unreadable file, unknown object name, malformed line or vertex id.
    """
    source = str(path)
    try:
        text = Path(path).read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(source, "file", f"cannot be read ({exc})", "pass an OBJ frame written by pscc") from exc
    coords: list[list[str]] = [[], []]  # cloth, obstacles
    vertex_lines: list[list[int]] = [[], []]
    face_rows: list[list[list[int]]] = [[], []]
    face_lines: list[list[int]] = [[], []]
    ids: list[int] = []
    section, piece = 0, 0
    for lineno, line in enumerate(text.splitlines(), 1):
        tokens = line.split()
        if not tokens or tokens[0].startswith("#"):
            continue
        tag = tokens[0]
        if tag == "o":
            name = " ".join(tokens[1:])
            match = _OBJ_PIECE.fullmatch(name)
            if name == "obstacles":
                section = 1
            elif match:
                digits = match.group(1) or "0"
                if len(digits) > 10 or int(digits) > INT32_MAX:  # int32 on output; refuse before int() of a huge string
                    raise InputError(source, f"line {lineno}", f"object id {_short(digits)} of {_short(name)!r} is "
                                     f"larger than {INT32_MAX}", "use cloth_<id> with ids that fit a 32-bit integer")
                section, piece = 0, int(digits)
            else:
                raise InputError(source, f"line {lineno}", f"object {name!r} is neither cloth_<id> nor obstacles",
                                 "read OBJ files pscc did not write with pscc.mesh.load_mesh")
        elif tag == "v":
            if len(tokens) < 4:
                raise InputError(source, f"line {lineno}", "vertex line has fewer than 3 coordinates",
                                 "write vertices as 'v x y z'")
            if section == 0 and coords[1]:
                raise InputError(source, f"line {lineno}", "cloth vertex after obstacle vertices",
                                 "write all cloth vertices before the obstacles")
            coords[section].extend(tokens[1:4])
            vertex_lines[section].append(lineno)
        elif tag == "f":
            if len(tokens) != 4:
                raise InputError(source, f"line {lineno}", f"face has {len(tokens) - 1} vertices, not 3",
                                 "write triangles only")
            defined = (len(coords[0]) + len(coords[1])) // 3
            try:
                corners = [int(token.split("/", 1)[0]) for token in tokens[1:]]
            except ValueError as exc:
                raise InputError(source, f"line {lineno}", "face vertex id is not an integer",
                                 "write faces as 'f a b c' with 1-based vertex ids") from exc
            if 0 in corners:
                raise InputError(source, f"line {lineno}", "vertex id 0 (OBJ ids start at 1)",
                                 "write 1-based vertex ids")
            if any(abs(c) > INT32_MAX for c in corners):  # would overflow the int64 face array
                raise InputError(source, f"line {lineno}", f"face vertex id {_short(max(corners, key=abs))} is out "
                                 f"of range (more than {INT32_MAX} in magnitude)", "write 1-based vertex ids "
                                 "between 1 and the number of 'v' lines")
            face_rows[section].append([c - 1 if c > 0 else defined + c for c in corners])
            face_lines[section].append(lineno)
            if section == 0:
                ids.append(piece)
    try:
        with np.errstate(over="ignore"):  # beyond float32 becomes Inf, refused below
            vertices, obstacle_vertices = (np.array(c, dtype=np.float64).astype(np.float32).reshape(-1, 3)
                                           for c in coords)
    except ValueError as exc:
        raise InputError(source, "v", "a vertex coordinate is not a number", "write 'v x y z' with numbers") from exc
    for points, lines in ((vertices, vertex_lines[0]), (obstacle_vertices, vertex_lines[1])):
        bad = np.flatnonzero(~np.isfinite(points).all(axis=1))
        if bad.size:
            raise InputError(source, f"line {lines[int(bad[0])]}", "vertex holds NaN or Inf (after conversion to "
                             "float32)", "write finite coordinates within the float32 range")
    n, k = vertices.shape[0], obstacle_vertices.shape[0]
    faces = np.array(face_rows[0], dtype=np.int64).reshape(-1, 3)
    obstacle_faces = np.array(face_rows[1], dtype=np.int64).reshape(-1, 3) - n
    checks = ((faces, face_lines[0], n, "cloth"), (obstacle_faces, face_lines[1], k, "obstacle"))
    for rows, lines, count, what in checks:
        bad = np.flatnonzero(np.any((rows < 0) | (rows >= count), axis=1))
        if bad.size:
            raise InputError(source, f"line {lines[int(bad[0])]}", f"face refers to a vertex outside the {count} "
                             f"{what} vertices", "let cloth faces use cloth vertices and obstacle faces obstacle ones")
    return {
        "vertices": vertices,
        "faces": faces.astype(np.int32),
        "object_ids": np.array(ids, dtype=np.int32),
        "obstacle_vertices": obstacle_vertices,
        "obstacle_faces": obstacle_faces.astype(np.int32),
    }


# --------------------------------------------------------------------------------------------
# PLY
# --------------------------------------------------------------------------------------------

_PLY_TYPES = {
    "char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1", "short": "<i2", "int16": "<i2",
    "ushort": "<u2", "uint16": "<u2", "int": "<i4", "int32": "<i4", "uint": "<u4", "uint32": "<u4",
    "float": "<f4", "float32": "<f4", "double": "<f8", "float64": "<f8",
}
_PLY_FACE_DTYPE = np.dtype([("count", "u1"), ("vertex_indices", "<i4", (3,)), ("object_id", "<i4")])


def _ply_bytes(index: int, vertices: np.ndarray, faces: np.ndarray, object_ids: np.ndarray,
               obstacle_vertices: np.ndarray, obstacle_faces: np.ndarray) -> bytes:
    n, m = vertices.shape[0], faces.shape[0]
    obstacle_id = _obstacle_object_id(object_ids)
    records = np.empty(m + obstacle_faces.shape[0], dtype=_PLY_FACE_DTYPE)
    records["count"] = 3
    records["vertex_indices"][:m] = faces
    records["vertex_indices"][m:] = obstacle_faces + n
    records["object_id"][:m] = object_ids
    records["object_id"][m:] = obstacle_id
    header = (
        "ply\nformat binary_little_endian 1.0\n"
        f"comment pscc frame {index}; units: metres\n"
        f"comment pscc cloth_vertices {n} cloth_faces {m} obstacle_object_id {obstacle_id}\n"
        f"element vertex {n + obstacle_vertices.shape[0]}\n"
        "property float x\nproperty float y\nproperty float z\n"
        f"element face {records.shape[0]}\n"
        "property list uchar int vertex_indices\nproperty int object_id\nend_header\n"
    ).encode("ascii")
    points = np.concatenate([vertices, obstacle_vertices]).astype("<f4", copy=False)
    return header + points.tobytes() + records.tobytes()


def write_ply_frame(out_dir: Path, index: int, vertices: np.ndarray, faces: np.ndarray, object_ids: np.ndarray,
                    obstacle_vertices: np.ndarray | None = None, obstacle_faces: np.ndarray | None = None) -> Path:
    """Write frame ``index`` as ``out_dir/ply/frame_{index:05d}.ply`` (binary little-endian, atomically).

    One mesh: the cloth vertices then the obstacle vertices (float32 ``x y z``), the cloth faces
    then the obstacle faces (``list uchar int vertex_indices``, ids into the joint vertex list) and
    a per-face ``int object_id``: the cloth's ids, and ``max(cloth ids) + 1`` for every obstacle
    face. A header comment ``pscc cloth_vertices N cloth_faces M obstacle_object_id K`` lets
    :func:`read_ply_frame` split cloth and obstacles again. Returns the path.

    Raises:
        ValueError: NaN or Inf, bad shapes, or face ids out of range.
    """
    arrays = _frame(index, vertices, faces, object_ids, obstacle_vertices, obstacle_faces)
    data = _ply_bytes(index, *arrays)
    return write_atomic(ply_frame_path(out_dir, index), lambda stream: stream.write(data))


def _ply_header(source: str, data: bytes) -> tuple[list[tuple[str, int, list[list[str]]]], dict[str, int], int]:
    """Elements (name, count, property lines), pscc comment values and the offset of the body.

    Counts must be plain non-negative integers (the caller checks them against the file size).
    """
    end = data.find(b"end_header")
    if not data.startswith(b"ply") or end < 0:
        raise InputError(source, "header", "not a PLY file (no 'ply' ... 'end_header')", "pass a PLY frame")
    newline = data.find(b"\n", end)
    body = len(data) if newline < 0 else newline + 1
    elements: list[tuple[str, int, list[list[str]]]] = []
    comments: dict[str, int] = {}
    for line in data[:end].decode("ascii", errors="replace").splitlines()[1:]:
        tokens = line.split()
        if not tokens:
            continue
        if tokens[0] == "format" and tokens[1:2] != ["binary_little_endian"]:
            raise InputError(source, "format", f"{_short(' '.join(tokens[1:]))} is not supported here",
                             "read other PLY files with pscc.mesh.load_mesh")
        if tokens[0] == "comment" and tokens[1:2] == ["pscc"] and "cloth_vertices" in tokens:
            values = tokens[3::2]
            if not all(re.fullmatch(r"[0-9]{1,18}", value) for value in values):
                raise InputError(source, "comment", f"pscc comment {_short(line.strip(), 60)!r} holds a value that is "
                                 "not a count >= 0", "write the frame again")
            comments = {key: int(value) for key, value in zip(tokens[2::2], values, strict=False)}
        elif tokens[0] == "element":
            if len(tokens) != 3 or not re.fullmatch(r"[0-9]+", tokens[2]):
                raise InputError(source, "header", f"{_short(line.strip(), 60)!r} does not give an element name and "
                                 "a count >= 0", "write the frame again")
            elements.append((tokens[1], int(tokens[2]), []))
        elif tokens[0] == "property" and elements:
            elements[-1][2].append(tokens[1:])
    return elements, comments, body


def read_ply_frame(path: Path) -> dict[str, np.ndarray]:
    """Read a binary little-endian PLY frame (as :func:`write_ply_frame` writes it) into the frame keys.

    Without the pscc header comment, every vertex and face is taken for cloth. The face element
    must hold triangles; an ``object_id`` face property becomes the object ids (zeros if absent).

    Raises:
        InputError: not a binary little-endian triangle PLY, or a truncated file.
    """
    source = str(path)
    try:
        data = Path(path).read_bytes()
    except OSError as exc:
        raise InputError(source, "file", f"cannot be read ({exc})", "pass a PLY frame written by pscc") from exc
    elements, comments, offset = _ply_header(source, data)
    arrays: dict[str, np.ndarray] = {}
    for name, count, properties in elements:
        fields: list[tuple[Any, ...]] = []
        for prop in properties:
            try:
                if prop[0] == "list":
                    if prop[-1] not in ("vertex_indices", "vertex_index"):
                        raise KeyError(prop[-1])
                    fields += [("count", _PLY_TYPES[prop[1]]), ("vertex_indices", _PLY_TYPES[prop[2]], (3,))]
                else:
                    fields.append((prop[1], _PLY_TYPES[prop[0]]))
            except (KeyError, IndexError) as exc:
                raise InputError(source, name, f"property {' '.join(prop)!r} is not supported",
                                 "read this file with pscc.mesh.load_mesh") from exc
        dtype = np.dtype(fields)
        if dtype.itemsize == 0:  # no properties: the rows take no bytes, and hold nothing to read
            if count and name in ("vertex", "face"):
                raise InputError(source, name, f"element {name!r} has no properties",
                                 "pass a PLY frame written by pscc")
            continue
        if offset + count * dtype.itemsize > len(data):  # Python ints: an absurd count cannot overflow
            raise InputError(source, name, f"header declares {count} {name} rows but the file ends inside them "
                             f"(truncated, or the count is corrupt)", "write the frame again")
        arrays[name] = np.frombuffer(data, dtype=dtype, count=count, offset=offset)
        offset += count * dtype.itemsize
    vertex, face = arrays.get("vertex"), arrays.get("face")
    if vertex is None or any(c not in (vertex.dtype.names or ()) for c in "xyz"):
        raise InputError(source, "vertex", "no vertex element with x, y, z", "pass a PLY frame written by pscc")
    with np.errstate(over="ignore"):  # doubles beyond float32 become Inf, refused below
        points = np.column_stack([vertex[c] for c in "xyz"]).astype(np.float32).reshape(-1, 3)
    bad = np.flatnonzero(~np.isfinite(points).all(axis=1))
    if bad.size:
        raise InputError(source, f"vertex {int(bad[0])}", "holds NaN or Inf (after conversion to float32)",
                         "write finite coordinates within the float32 range")
    if face is None or face.size == 0:
        rows, ids = np.zeros((0, 3), np.int64), np.zeros(0, np.int64)
    else:
        if "count" not in (face.dtype.names or ()):
            raise InputError(source, "face", "no vertex_indices list property", "pass a PLY frame written by pscc")
        bad = np.flatnonzero(face["count"] != 3)
        if bad.size:
            raise InputError(source, f"face {int(bad[0])}", "face is not a triangle (or its list length varies)",
                             "triangulate the mesh, or read it with pscc.mesh.load_mesh")
        rows = face["vertex_indices"].astype(np.int64)
        ids = face["object_id"].astype(np.int64) if "object_id" in face.dtype.names else np.zeros(len(rows), np.int64)
    n = comments.get("cloth_vertices", points.shape[0])
    m = comments.get("cloth_faces", rows.shape[0])
    if not (0 <= n <= points.shape[0] and 0 <= m <= rows.shape[0]):
        raise InputError(source, "comment", "pscc counts exceed the element sizes", "write the frame again")
    # Indices and ids are int32 in the frame contract: refuse what would wrap, and faces that leave their part.
    for what, part, low, high in (("cloth", rows[:m], 0, n), ("obstacle", rows[m:], n, points.shape[0])):
        bad = np.flatnonzero(np.any((part < low) | (part >= high), axis=1))
        if bad.size:
            row = int(bad[0]) + (0 if what == "cloth" else m)
            raise InputError(source, f"face {row}", f"{what} face {rows[row].tolist()} refers to a vertex outside "
                             f"the {what} vertices [{low}, {high})", "write the frame again")
    bad = np.flatnonzero((ids[:m] < 0) | (ids[:m] > INT32_MAX))
    if bad.size:
        raise InputError(source, f"face {int(bad[0])}", f"object id {int(ids[int(bad[0])])} is outside "
                         f"[0, {INT32_MAX}]", "write the frame again with non-negative 32-bit object ids")
    return {
        "vertices": np.ascontiguousarray(points[:n]),
        "faces": rows[:m].astype(np.int32),
        "object_ids": ids[:m].astype(np.int32),
        "obstacle_vertices": np.ascontiguousarray(points[n:]),
        "obstacle_faces": (rows[m:] - n).astype(np.int32),
    }


# --------------------------------------------------------------------------------------------
# USD
# --------------------------------------------------------------------------------------------


def _export_layer_atomic(layer: Any, path: Path) -> None:
    """Export a USD layer to ``path`` atomically (:func:`pscc._atomic.atomic_output`).

    USD writes layers by file name (not into a Python stream); the temporary name keeps the
    extension, which selects the file format.
    """
    with atomic_output(path) as temporary:
        if not layer.Export(str(temporary)):
            raise OSError(f"USD could not write {temporary}")


def _open_usd(path: Path, detach: bool = False) -> Any:
    """Open a USD file as a stage over an anonymous layer (no layer-registry caching).

    ``detach`` copies the content into a fresh in-memory layer, so that the stage does not read
    lazily from the file that later saves replace.
    """
    from pxr import Sdf, Usd

    source = str(path)
    if not Path(path).is_file():
        raise InputError(source, "file", "does not exist", "pass the animation.usd that pscc wrote")
    try:
        layer = Sdf.Layer.OpenAsAnonymous(source)
    except Exception as exc:  # pxr raises Tf.ErrorException on unreadable files
        raise InputError(source, "file", f"is not a readable USD file ({exc})", "write the stage again") from exc
    if layer is None:
        raise InputError(source, "file", "is not a readable USD file", "write the stage again")
    if detach:
        copy = Sdf.Layer.CreateAnonymous(Path(path).suffix or ".usd")
        copy.TransferContent(layer)
        layer = copy
    return Usd.Stage.Open(layer)


def _usd_array(value: Any, dtype: type, shape: tuple[int, ...]) -> np.ndarray:
    return np.array(value if value is not None else [], dtype=dtype).reshape(shape)


class UsdAnimationWriter:
    """One animated USD stage, written frame by frame.

    The stage holds ``/World`` (an Xform, the default prim), ``/World/Cloth`` and, when the scene
    has obstacle faces, ``/World/Obstacles``: standard ``UsdGeom.Mesh`` prims whose topology
    (``faceVertexCounts``, ``faceVertexIndices``, a uniform ``primvars:object_id`` per face,
    ``subdivisionScheme = none``) is written once, and whose ``points`` and ``extent`` get one time
    sample per frame at time code = frame index. Stage metadata: ``startTimeCode``/``endTimeCode``
    (smallest and largest frame written), ``timeCodesPerSecond = framesPerSecond = fps``,
    ``metersPerUnit = 1``, ``upAxis = Z``.

    Frames are kept in memory and the file is replaced atomically (:func:`_export_layer_atomic`)
    every ``save_every`` frames and at :meth:`close`: the file on disk is always a complete stage,
    holding every frame up to the last save. A crash loses at most ``save_every - 1`` frames of it.
    Each save rewrites the whole file, so small ``save_every`` values cost time on long runs.

    Args:
        path: the ``.usd`` / ``.usdc`` / ``.usda`` file (the extension chooses the encoding).
        cloth_faces: (m, 3) cloth triangles.
        cloth_object_ids: (m,) cloth piece of each triangle.
        obstacle_faces: (l, 3) obstacle triangles, or ``None`` / empty for no obstacles.
        fps: frames per second (time codes per second).
        resume_from: ``None`` starts a new stage (replacing any file at ``path``). A frame index
            ``k`` re-opens the existing stage to continue a resumed run: its topology and fps must
            match, samples at time codes ``>= k`` are dropped and frames ``k, k+1, ...`` follow.
        save_every: frames between saves (>= 1).

    Raises:
        InputError: resuming a missing stage, or one whose fps or topology differ.
        ValueError: bad arrays, ``fps`` not positive, ``save_every`` below 1.
    """

    def __init__(self, path: Path, cloth_faces: np.ndarray, cloth_object_ids: np.ndarray,
                 obstacle_faces: np.ndarray | None = None, fps: float = 30.0, *,
                 resume_from: int | None = None, save_every: int = 10) -> None:
        if not (math.isfinite(float(fps)) and float(fps) > 0):
            raise ValueError(f"fps must be a positive number, got {fps!r}")
        if int(save_every) < 1:
            raise ValueError(f"save_every must be >= 1, got {save_every!r}")
        self.path = Path(path)
        self.fps = float(fps)
        self.save_every = int(save_every)
        self._faces = _triangles(cloth_faces, "cloth_faces")
        self._object_ids = _object_ids(cloth_object_ids, self._faces.shape[0])
        self._obstacle_faces = _triangles(obstacle_faces, "obstacle_faces")
        self._times: set[int] = set()
        self._unsaved = 0
        self._closed = False
        if resume_from is None:
            self._stage = self._create()
        else:
            self._stage = self._reopen(int(resume_from))
        self._cloth = self._mesh(CLOTH_PRIM)
        self._obstacles = self._mesh(OBSTACLES_PRIM) if self._obstacle_faces.size else None

    @property
    def frames(self) -> tuple[int, ...]:
        """Frame indices (time codes) the stage holds now, kept from a resumed file or added, ascending."""
        return tuple(sorted(self._times))

    def _mesh(self, prim_path: str) -> Any:
        from pxr import UsdGeom

        return UsdGeom.Mesh(self._stage.GetPrimAtPath(prim_path))

    def _define_mesh(self, stage: Any, prim_path: str, faces: np.ndarray, object_ids: np.ndarray) -> None:
        from pxr import Sdf, UsdGeom, Vt

        mesh = UsdGeom.Mesh.Define(stage, prim_path)
        mesh.CreateFaceVertexCountsAttr(Vt.IntArray.FromNumpy(np.full(faces.shape[0], 3, np.int32)))
        mesh.CreateFaceVertexIndicesAttr(Vt.IntArray.FromNumpy(faces.ravel()))
        mesh.CreateSubdivisionSchemeAttr(UsdGeom.Tokens.none)
        mesh.CreateOrientationAttr(UsdGeom.Tokens.rightHanded)
        mesh.CreateDoubleSidedAttr(True)
        mesh.CreatePointsAttr()
        mesh.CreateExtentAttr()
        primvar = UsdGeom.PrimvarsAPI(mesh.GetPrim()).CreatePrimvar(
            "object_id", Sdf.ValueTypeNames.IntArray, UsdGeom.Tokens.uniform)
        primvar.Set(Vt.IntArray.FromNumpy(np.ascontiguousarray(object_ids, dtype=np.int32)))

    def _create(self) -> Any:
        from pxr import Usd, UsdGeom

        stage = Usd.Stage.CreateInMemory()
        UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.z)
        UsdGeom.SetStageMetersPerUnit(stage, 1.0)
        stage.SetTimeCodesPerSecond(self.fps)
        stage.SetFramesPerSecond(self.fps)
        stage.SetStartTimeCode(0)
        stage.SetEndTimeCode(0)
        stage.GetRootLayer().documentation = "pscc cloth simulation: time code = frame index, units: metres"
        world = UsdGeom.Xform.Define(stage, "/World")
        stage.SetDefaultPrim(world.GetPrim())
        self._define_mesh(stage, CLOTH_PRIM, self._faces, self._object_ids)
        if self._obstacle_faces.size:
            obstacle_ids = np.full(self._obstacle_faces.shape[0], _obstacle_object_id(self._object_ids), np.int32)
            self._define_mesh(stage, OBSTACLES_PRIM, self._obstacle_faces, obstacle_ids)
        return stage

    def _reopen(self, resume_from: int) -> Any:
        from pxr import UsdGeom

        source = str(self.path)
        if not self.path.is_file():
            raise InputError(source, "file", "there is no USD stage to continue",
                             "start a new run, or leave usd out of --format when resuming")
        stage = _open_usd(self.path, detach=True)
        if stage.GetTimeCodesPerSecond() != self.fps:
            raise InputError(source, "timeCodesPerSecond", f"is {stage.GetTimeCodesPerSecond():g}, the run has "
                             f"{self.fps:g} frames per second", "resume with the scene the stage was written for")
        expected = {CLOTH_PRIM: (self._faces, self._object_ids)}
        if self._obstacle_faces.size:
            expected[OBSTACLES_PRIM] = (self._obstacle_faces, None)
        elif stage.GetPrimAtPath(OBSTACLES_PRIM):
            raise InputError(source, OBSTACLES_PRIM, "the stage has obstacles, the run has none",
                             "resume with the scene the stage was written for")
        for prim_path, (faces, ids) in expected.items():
            prim = stage.GetPrimAtPath(prim_path)
            mesh = UsdGeom.Mesh(prim)
            stored = _usd_array(mesh.GetFaceVertexIndicesAttr().Get() if prim else None, np.int32, (-1,))
            same = stored.shape == (faces.size,) and np.array_equal(stored, faces.ravel())
            if same and ids is not None:
                primvar = UsdGeom.PrimvarsAPI(prim).GetPrimvar("object_id")
                same = np.array_equal(_usd_array(primvar.Get() if primvar else None, np.int32, (-1,)), ids)
            if not same:
                raise InputError(source, prim_path, "topology (faces or object ids) differs from the run's",
                                 "resume with the scene the stage was written for, or start a new run")
            for attr in (mesh.GetPointsAttr(), mesh.GetExtentAttr()):
                for time in attr.GetTimeSamples():
                    if time >= resume_from:
                        attr.ClearAtTime(time)
            if prim_path == CLOTH_PRIM:
                self._times = {int(round(t)) for t in mesh.GetPointsAttr().GetTimeSamples()}
        return stage

    def add_frame(self, index: int, cloth_vertices: np.ndarray, obstacle_vertices: np.ndarray | None = None) -> None:
        """Add (or replace) the time samples of frame ``index``; saves when ``save_every`` frames are pending.

        Raises:
            ValueError: NaN or Inf, a vertex count that does not fit the faces, missing obstacle vertices.
            RuntimeError: the writer is closed.
        """
        from pxr import Vt

        if self._closed:
            raise RuntimeError(f"{self.path}: writer is closed")
        index = int(index)
        if index < 0:
            raise ValueError(f"frame index {index} is negative")
        cloth = _points(cloth_vertices, "cloth vertices", index)
        _check_ids_in_range(self._faces, cloth.shape[0], "cloth faces", index)
        samples = [(self._cloth, cloth)]
        if self._obstacles is not None:
            if obstacle_vertices is None:
                raise ValueError(f"frame {index}: the stage has obstacles but no obstacle vertices were given")
            obstacles = _points(obstacle_vertices, "obstacle vertices", index)
            _check_ids_in_range(self._obstacle_faces, obstacles.shape[0], "obstacle faces", index)
            samples.append((self._obstacles, obstacles))
        for mesh, points in samples:
            mesh.GetPointsAttr().Set(Vt.Vec3fArray.FromNumpy(points), float(index))
            if points.shape[0]:
                bounds = np.stack([points.min(axis=0), points.max(axis=0)])
                mesh.GetExtentAttr().Set(Vt.Vec3fArray.FromNumpy(bounds), float(index))
        self._times.add(index)
        self._unsaved += 1
        if self._unsaved >= self.save_every:
            self.save()

    def save(self) -> None:
        """Update the start/end time codes and replace the file atomically with the current stage."""
        if self._times:
            self._stage.SetStartTimeCode(min(self._times))
            self._stage.SetEndTimeCode(max(self._times))
        _export_layer_atomic(self._stage.GetRootLayer(), self.path)
        self._unsaved = 0

    def close(self) -> None:
        """Save (always, so that even a stage without frames exists) and release the stage; idempotent."""
        if self._closed:
            return
        self.save()
        self._closed = True
        self._cloth = self._obstacles = self._stage = None

    def __enter__(self) -> UsdAnimationWriter:
        return self

    def __exit__(self, kind: type[BaseException] | None, error: BaseException | None,
                 traceback: TracebackType | None) -> None:
        self.close()


def read_usd_frames(path: Path) -> list[tuple[np.ndarray, np.ndarray]]:
    """Read every frame of a stage written by :class:`UsdAnimationWriter`.

    Returns:
        One ``(cloth_vertices (n, 3) f32, obstacle_vertices (k, 3) f32)`` pair per time sample of the
        cloth points, in time-code order (element ``i`` is frame ``start + i`` when no frame is
        missing). Obstacle vertices are empty (0, 3) when the stage has no ``/World/Obstacles``.

    Raises:
        InputError: missing or unreadable file, or no ``/World/Cloth`` mesh.
    """
    from pxr import UsdGeom

    stage = _open_usd(Path(path))
    cloth = stage.GetPrimAtPath(CLOTH_PRIM)
    if not cloth:
        raise InputError(str(path), CLOTH_PRIM, "the stage has no cloth mesh", "pass the animation.usd pscc wrote")
    points = UsdGeom.Mesh(cloth).GetPointsAttr()
    obstacles = stage.GetPrimAtPath(OBSTACLES_PRIM)
    obstacle_points = UsdGeom.Mesh(obstacles).GetPointsAttr() if obstacles else None
    frames = []
    for time in points.GetTimeSamples():
        vertices = _usd_array(points.Get(time), np.float32, (-1, 3))
        others = (_usd_array(obstacle_points.Get(time), np.float32, (-1, 3)) if obstacle_points is not None
                  else _EMPTY_VERTICES.copy())
        frames.append((vertices, others))
    return frames


# --------------------------------------------------------------------------------------------
# All formats at once
# --------------------------------------------------------------------------------------------


class FrameWriter:
    """Write each frame in every requested format.

    Args:
        out_dir: output folder (created as needed).
        formats: names from :data:`FORMATS` (a tuple, or a ``--format`` string for :func:`parse_formats`).
        cloth_faces: (m, 3) cloth triangles (fixed over the run).
        cloth_object_ids: (m,) cloth piece of each triangle.
        obstacle_faces: (l, 3) obstacle triangles, or ``None`` / empty when the scene has none.
        fps: frames per second (``1 / scene.frame_time``), used by USD.
        resume_from: first frame index of a resumed run (``None``: a new run). Per-frame files are
            simply (over)written, and OBJ / PLY files of earlier frames that are missing (a format
            added on resume) are written from the NPZ frames; the USD stage is re-opened (see
            :class:`UsdAnimationWriter`) and any frame before ``resume_from`` it lacks (lost since its
            last save) is filled in from the NPZ frame files on disk.
        usd_save_every: frames between saves of the USD stage.

    Raises:
        InputError: an unknown format; resuming a USD stage that cannot be continued or completed.
        ValueError: bad arrays or settings.
    """

    def __init__(self, out_dir: Path, formats: str | Iterable[str], cloth_faces: np.ndarray,
                 cloth_object_ids: np.ndarray, obstacle_faces: np.ndarray | None = None, fps: float = 30.0, *,
                 resume_from: int | None = None, usd_save_every: int = 10) -> None:
        self.out_dir = Path(out_dir)
        self.formats = parse_formats(formats)
        self.faces = _triangles(cloth_faces, "cloth_faces")
        self.object_ids = _object_ids(cloth_object_ids, self.faces.shape[0])
        self.obstacle_faces = _triangles(obstacle_faces, "obstacle_faces")
        self._usd: UsdAnimationWriter | None = None
        if "usd" in self.formats:
            path = usd_path(self.out_dir)
            resume = resume_from if resume_from is not None and path.is_file() else None
            self._usd = UsdAnimationWriter(path, self.faces, self.object_ids, self.obstacle_faces, fps,
                                           resume_from=resume, save_every=usd_save_every)
            if resume_from is not None:
                self._backfill_usd(int(resume_from))
        if resume_from is not None:
            self._backfill_files(int(resume_from))

    def _backfill_files(self, resume_from: int) -> None:
        """Write the OBJ / PLY files of frames ``0 .. resume_from - 1`` that are missing, from the NPZ frames
        (a run resumed with a format it did not write before)."""
        writers = {"obj": (obj_frame_path, write_obj_frame), "ply": (ply_frame_path, write_ply_frame)}
        for name in self.formats:
            if name not in writers:
                continue
            path_of, write = writers[name]
            for index in range(resume_from):
                if path_of(self.out_dir, index).is_file():
                    continue
                source = frame_path(self.out_dir, index)
                if not source.is_file():
                    raise InputError(str(source), "frames", f"is missing, so the {name} file of frame {index} "
                                     "cannot be filled in", f"start a new run, or leave {name} out of --format")
                frame = read_frame(source)
                write(self.out_dir, index, frame["vertices"], self.faces, self.object_ids,
                      frame["obstacle_vertices"], self.obstacle_faces)

    def _backfill_usd(self, resume_from: int) -> None:
        """Add frames ``0 .. resume_from - 1`` the USD stage lacks, from the NPZ frame files."""
        assert self._usd is not None
        missing = sorted(set(range(resume_from)) - set(self._usd.frames))
        absent = [i for i in missing if not frame_path(self.out_dir, i).is_file()]
        if absent:
            raise InputError(str(self._usd.path), "time samples", f"{len(absent)} frame(s) before frame "
                             f"{resume_from} are missing (first: {absent[0]}) and have no NPZ frame to fill them in",
                             "resume from an earlier frame, start a new run, or leave usd out of --format")
        if not missing:
            return
        save_every, self._usd.save_every = self._usd.save_every, len(missing) + 1  # one save at the end
        try:
            for index in missing:
                frame = read_frame(frame_path(self.out_dir, index))
                self._usd.add_frame(index, frame["vertices"], frame["obstacle_vertices"])
        finally:
            self._usd.save_every = save_every
        self._usd.save()

    def write(self, index: int, cloth_vertices: np.ndarray, obstacle_vertices: np.ndarray | None = None
              ) -> dict[str, Path]:
        """Write frame ``index`` in every format; return ``{format: path}`` (USD: the stage file).

        The arrays are checked first, so a bad frame writes nothing.

        Raises:
            ValueError: NaN or Inf, wrong shapes, missing obstacle vertices.
        """
        index = int(index)
        if self.obstacle_faces.size and obstacle_vertices is None:
            raise ValueError(f"frame {index}: the scene has obstacles but no obstacle vertices were given")
        if not self.obstacle_faces.size and obstacle_vertices is not None and np.size(obstacle_vertices):
            raise ValueError(f"frame {index}: obstacle vertices given but the writer has no obstacle faces")
        cloth, _, _, obstacles, _ = _frame(index, cloth_vertices, self.faces, self.object_ids, obstacle_vertices,
                                           self.obstacle_faces)
        arrays = (cloth, self.faces, self.object_ids, obstacles, self.obstacle_faces)
        paths: dict[str, Path] = {}
        for name in self.formats:
            if name == "npz":
                paths[name] = write_frame(self.out_dir, index, *arrays)
            elif name == "obj":
                paths[name] = write_obj_frame(self.out_dir, index, *arrays)
            elif name == "ply":
                paths[name] = write_ply_frame(self.out_dir, index, *arrays)
            elif name == "usd" and self._usd is not None:
                self._usd.add_frame(index, cloth, obstacles)
                paths[name] = self._usd.path
        return paths

    def close(self) -> None:
        """Save and close the USD stage (the per-frame files are complete already); idempotent."""
        if self._usd is not None:
            self._usd.close()

    def __enter__(self) -> FrameWriter:
        return self

    def __exit__(self, kind: type[BaseException] | None, error: BaseException | None,
                 traceback: TracebackType | None) -> None:
        self.close()
