"""PLY input of :func:`pscc.mesh.load_mesh` (ASCII and binary; see ``docs/mesh-input.md``).

The header is parsed and checked first, so an element count the file cannot hold is refused before
anything is allocated; ASCII bodies are read here with every integer checked against its declared
type, binary bodies go through trimesh's raw element data. Errors name the file, the element and
the fix.
"""

from __future__ import annotations

import io
import re
import warnings
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from pscc._checks import read_input_bytes, shorten
from pscc.errors import InputError
from pscc.mesh.mesh_data import MeshData, _validate_mesh

_PLY_INDEX_NAMES = ("vertex_indices", "vertex_index")
_PLY_UV_NAMES = (("s", "t"), ("u", "v"), ("texture_u", "texture_v"), ("texture_s", "texture_t"))
"""Vertex property pairs read as texture coordinates (the first pair present), as PLY exporters write them."""


def _uv_pair(names: Any) -> tuple[str, str] | None:
    """The first texture-coordinate property pair among ``names``, or None."""
    return next((pair for pair in _PLY_UV_NAMES if pair[0] in names and pair[1] in names), None)



# PLY scalar types: size in bytes and, for integer types, the NumPy type whose range a value must fit.
_PLY_TYPES: dict[str, tuple[int, type[np.integer] | None]] = {
    "char": (1, np.int8), "int8": (1, np.int8), "uchar": (1, np.uint8), "uint8": (1, np.uint8),
    "short": (2, np.int16), "int16": (2, np.int16), "ushort": (2, np.uint16), "uint16": (2, np.uint16),
    "int": (4, np.int32), "int32": (4, np.int32), "uint": (4, np.uint32), "uint32": (4, np.uint32),
    "float": (4, None), "float32": (4, None), "double": (8, None), "float64": (8, None),
}
_PLY_FORMATS = ("ascii", "binary_little_endian", "binary_big_endian")
_PLY_REEXPORT = "re-export the PLY file (it is truncated or its header is corrupt)"
_PLY_BAD_DATA = "re-export the PLY file (its data does not match the types and counts its header declares)"
_NOT_TRIANGLES = "faces must be triangles"
_TRIANGULATE = "triangulate the mesh before exporting it"


@dataclass(frozen=True)
class _PlyProperty:
    """One ``property`` line: a scalar (``count_type`` None) or a list of ``value_type`` values."""

    name: str
    value_type: str
    count_type: str | None


@dataclass
class _PlyElement:
    """One ``element`` line and its properties."""

    name: str
    count: int
    properties: list[_PlyProperty] = field(default_factory=list)

    def min_row_bytes(self, is_ascii: bool) -> int:
        """Fewest bytes one row can take: a value (or list length) per property, empty lists."""
        if is_ascii:  # a digit and a separator per property; a row is at least its line break
            return max(2 * len(self.properties), 1)
        return max(sum(_PLY_TYPES[p.count_type or p.value_type][0] for p in self.properties), 1)

    def find(self, names: tuple[str, ...]) -> _PlyProperty | None:
        return next((p for p in self.properties if p.name in names), None)


def _ply_header(source: str, data: bytes) -> tuple[str, list[_PlyElement], int]:
    """Format, elements and body offset of a PLY file, checked before anything is allocated.

    Every element count must be a plain non-negative integer whose rows fit in the bytes after the
    header (:meth:`_PlyElement.min_row_bytes` each), so an absurd count is refused here and never
    reaches an allocation.
    """
    if not data.startswith(b"ply"):
        raise InputError(source, "file", "is not a PLY file (it does not start with 'ply')",
                         "re-export the mesh as a PLY file with triangle faces")
    end = data.find(b"end_header")
    if end < 0:
        raise InputError(source, "header", "the PLY header has no 'end_header' line", _PLY_REEXPORT)
    newline = data.find(b"\n", end)
    body = len(data) if newline < 0 else newline + 1
    file_format = None
    elements: list[_PlyElement] = []
    for lineno, line in enumerate(data[:end].decode("ascii", errors="replace").splitlines()[1:], start=2):
        tokens = line.split()
        where = f"header line {lineno}"
        if not tokens or tokens[0] in ("comment", "obj_info"):
            continue
        if tokens[0] == "format":
            file_format = tokens[1] if len(tokens) > 1 else ""
            if file_format not in _PLY_FORMATS:
                raise InputError(source, where, f"format {shorten(file_format)!r} is not one of "
                                 f"{', '.join(_PLY_FORMATS)}", "re-export the mesh as an ASCII or binary PLY file")
        elif tokens[0] == "element":
            if len(tokens) != 3 or not re.fullmatch(r"[0-9]+", tokens[2]):
                raise InputError(source, where, f"{shorten(line.strip(), 60)!r} does not give an element name "
                                 "and a count >= 0", "write 'element NAME COUNT'; " + _PLY_REEXPORT)
            elements.append(_PlyElement(tokens[1], int(tokens[2])))
        elif tokens[0] == "property":
            if not elements:
                raise InputError(source, where, "property line before any element line", _PLY_REEXPORT)
            if len(tokens) == 5 and tokens[1] == "list":
                prop = _PlyProperty(tokens[4], tokens[3], tokens[2])
            elif len(tokens) == 3:
                prop = _PlyProperty(tokens[2], tokens[1], None)
            else:
                raise InputError(source, where, f"malformed property line {shorten(line.strip(), 60)!r}",
                                 "write 'property TYPE NAME' or 'property list COUNT_TYPE TYPE NAME'")
            for name in (prop.value_type, prop.count_type):
                if name is not None and name not in _PLY_TYPES:
                    raise InputError(source, where, f"unknown property type {shorten(name)!r}",
                                     f"use one of {', '.join(_PLY_TYPES)}")
            if prop.count_type is not None and _PLY_TYPES[prop.count_type][1] is None:
                raise InputError(source, where, f"list length type {prop.count_type} is not an integer type",
                                 "write list lengths as uchar or int")
            elements[-1].properties.append(prop)
    if file_format is None:
        raise InputError(source, "header", "the PLY header has no 'format' line", _PLY_REEXPORT)
    remaining = len(data) - body
    is_ascii = file_format == "ascii"
    needed = -1 if is_ascii else 0  # the last ASCII row needs no line break
    for element in elements:
        row = element.min_row_bytes(is_ascii)
        needed += element.count * row
        if needed > remaining:
            raise InputError(source, element.name, f"header declares {element.count} {element.name} rows, more "
                             f"than the file can hold ({remaining} bytes after the header; a row takes at least "
                             f"{row})", _PLY_REEXPORT)
    return file_format, elements, body


def _ply_integers(source: str, field_name: str, values: np.ndarray, ply_type: str, what: str,
                  rows: list[list[str]], first: int = 0) -> np.ndarray:
    """(count, k) float values of an integer property as int64, refusing any value its type cannot hold."""
    info = np.iinfo(_PLY_TYPES[ply_type][1] or np.int32)
    with np.errstate(invalid="ignore"):
        bad = ~(np.isfinite(values) & (values == np.floor(values)) & (values >= info.min) & (values <= info.max))
    if bad.any():
        row = int(np.flatnonzero(bad.any(axis=1))[0])
        raise InputError(source, f"{field_name} {first + row}", f"{what} {values[row][bad[row]][0]:.17g} in data line "
                         f"{shorten(' '.join(rows[row]), 60)!r} is not an integer that fits the declared type "
                         f"{ply_type} [{info.min}, {info.max}]", _PLY_BAD_DATA)
    return values.astype(np.int64)


def _ascii_element(source: str, element: _PlyElement, lines: list[str]) -> tuple[list[list[str]], dict[str, Any]]:
    """Token rows and per-property values of an ASCII PLY element.

    A scalar property gives a (count, 1) float64 array; a list gives ``(lengths, values)``: (count,)
    int64 list lengths and a (count, k) float64 array when every row has k values, else the row arrays.
    Every list length is checked against the values its row holds.
    """
    rows = [line.split() for line in lines]
    lists = [p for p in element.properties if p.count_type is not None]
    widths = np.fromiter((len(r) for r in rows), dtype=np.int64, count=len(rows))
    values: dict[str, Any] = {}
    if len(lists) <= 1 and (widths.size == 0 or np.all(widths == widths[0])):
        width = int(widths[0]) if widths.size else len(element.properties)
        scalars = len(element.properties) - len(lists)
        if width < scalars + len(lists) or (not lists and width != scalars):
            raise InputError(source, f"{element.name} 0", f"data line {shorten(' '.join(rows[0]), 60)!r} holds "
                             f"{width} values but the header declares {len(element.properties)} properties",
                             _PLY_BAD_DATA)
        table = _ascii_floats(source, element.name, rows, width)
        column = 0
        for prop in element.properties:
            if prop.count_type is None:
                values[prop.name] = table[:, column:column + 1]
                column += 1
                continue
            k = width - scalars - 1
            lengths = _ply_integers(source, element.name, table[:, column:column + 1], prop.count_type,
                                    f"list length of {prop.name}", rows)[:, 0]
            wrong = np.flatnonzero(lengths != k)
            if wrong.size:
                row = int(wrong[0])
                raise InputError(source, f"{element.name} {row}", f"list {prop.name} declares {int(lengths[row])} "
                                 f"values but data line {shorten(' '.join(rows[row]), 60)!r} holds {k}", _PLY_BAD_DATA)
            values[prop.name] = (lengths, table[:, column + 1:column + 1 + k])
            column += 1 + k
        return rows, values
    # Lists of varying length: walk each row.
    walked: dict[str, list[Any]] = {p.name: [] for p in element.properties}
    for index, row in enumerate(rows):
        position = 0
        for prop in element.properties:
            count = 1
            if prop.count_type is not None and position < len(row):
                head = _ascii_floats(source, element.name, [row[position:position + 1]], 1, first=index)
                count = int(_ply_integers(source, element.name, head, prop.count_type,
                                          f"list length of {prop.name}", [row], first=index)[0, 0])
                position += 1
            elif prop.count_type is not None:
                count = len(row) + 1  # no list length: reported below
            if position + count > len(row):
                raise InputError(source, f"{element.name} {index}", f"data line {shorten(' '.join(row), 60)!r} "
                                 f"ends before property {prop.name}", _PLY_BAD_DATA)
            walked[prop.name].append(_ascii_floats(source, element.name, [row[position:position + count]], count,
                                                   first=index)[0])
            position += count
        if position != len(row):
            raise InputError(source, f"{element.name} {index}", f"data line {shorten(' '.join(row), 60)!r} holds "
                             f"{len(row)} values, {len(row) - position} more than its properties take", _PLY_BAD_DATA)
    for prop in element.properties:
        if prop.count_type is None:
            values[prop.name] = np.asarray(walked[prop.name], dtype=np.float64).reshape(-1, 1)
        else:
            lengths = np.fromiter((a.size for a in walked[prop.name]), dtype=np.int64, count=len(rows))
            values[prop.name] = (lengths, walked[prop.name])
    return rows, values


def _ascii_floats(source: str, name: str, rows: list[list[str]], width: int, first: int = 0) -> np.ndarray:
    """Tokens of ``rows`` (each ``width`` long) as a (len(rows), width) float64 array."""
    try:
        return np.array([token for row in rows for token in row], dtype=np.float64).reshape(len(rows), width)
    except ValueError:
        for index, row in enumerate(rows):
            for token in row:
                try:
                    float(token)
                except ValueError as exc:
                    raise InputError(source, f"{name} {first + index}", f"{shorten(token)!r} in data line "
                                     f"{shorten(' '.join(row), 60)!r} is not a number", _PLY_BAD_DATA) from exc
        raise


def _read_ply_ascii(source: str, elements: list[_PlyElement], text: str) -> tuple[np.ndarray, np.ndarray,
                                                                                   np.ndarray | None,
                                                                                   np.ndarray | None]:
    """Vertices, faces, optional object ids and optional uv of an ASCII PLY body (one line per element row)."""
    lines = text.splitlines()
    vertices = np.zeros((0, 3), dtype=np.float64)
    faces = np.zeros((0, 3), dtype=np.int64)
    object_ids = None
    uv = None
    start = 0
    for element in elements:
        chunk = lines[start:start + element.count]
        start += element.count
        if len(chunk) < element.count:
            raise InputError(source, element.name, f"header declares {element.count} {element.name} rows but the "
                             f"file ends after {len(chunk)}", _PLY_REEXPORT)
        if element.name == "vertex" and element.count:
            props = {p.name: p for p in element.properties}
            for axis in "xyz":
                if axis not in props or props[axis].count_type is not None:
                    raise InputError(source, "vertex", f"vertex element has no scalar property {axis!r}",
                                     "write vertex positions as float properties x, y and z")
            _, values = _ascii_element(source, element, chunk)
            vertices = np.concatenate([values[axis] for axis in "xyz"], axis=1)
            pair = _uv_pair({name for name, p in props.items() if p.count_type is None})
            if pair is not None:
                uv = np.concatenate([values[name] for name in pair], axis=1)
        elif element.name == "face" and element.count:
            faces, object_ids = _ascii_faces(source, element, chunk)
    return vertices, faces, object_ids, uv


def _ascii_faces(source: str, element: _PlyElement, lines: list[str]) -> tuple[np.ndarray, np.ndarray | None]:
    """Face index rows (int64) and optional object ids of an ASCII PLY face element."""
    prop = element.find(_PLY_INDEX_NAMES)
    if prop is None or prop.count_type is None:
        raise InputError(source, "face", "face element has no 'vertex_indices' list property",
                         "write faces as 'property list uchar int vertex_indices'")
    rows, values = _ascii_element(source, element, lines)
    lengths, indices = values[prop.name]
    bad = np.flatnonzero(lengths != 3)
    if bad.size:
        row = int(bad[0])
        raise InputError(source, f"face {row}", f"face has {int(lengths[row])} vertices; {_NOT_TRIANGLES}",
                         _TRIANGULATE)
    indices = np.asarray(indices, dtype=np.float64).reshape(-1, 3)
    faces = _ply_integers(source, "face", indices, prop.value_type, "vertex index", rows)
    object_ids = None
    ids = element.find(("object_id",))
    if ids is not None:
        if ids.count_type is not None:
            raise InputError(source, "object_id", "face property object_id is not one integer per face",
                             "write object_id as 'property int object_id' on the face element")
        object_ids = _ply_integers(source, "face", values["object_id"], ids.value_type, "object id", rows)[:, 0]
    return faces, object_ids


def _check_binary_face_lists(source: str, file_format: str, elements: list[_PlyElement], data: bytes,
                             body: int) -> None:
    """Refuse a binary face element whose first index list is not a triangle, before trimesh sizes its
    rows by it (trimesh assumes every row has the first row's list length)."""
    offset = body
    for element in elements:
        if element.name == "face":
            break
        if any(p.count_type is not None for p in element.properties):
            return  # rows of varying size before the faces: trimesh's own checks apply
        offset += element.count * element.min_row_bytes(False)
    else:
        return
    if element.count == 0:
        return
    endian = ">" if file_format == "binary_big_endian" else "<"
    for prop in element.properties:
        if prop.count_type is None:
            offset += _PLY_TYPES[prop.value_type][0]
            continue
        size, kind = _PLY_TYPES[prop.count_type]
        if prop.name not in _PLY_INDEX_NAMES or offset + size > len(data):
            return
        count = int(np.frombuffer(data, dtype=np.dtype(kind).newbyteorder(endian), count=1, offset=offset)[0])
        if count != 3:
            raise InputError(source, "face 0", f"face has {count} vertices; {_NOT_TRIANGLES}", _TRIANGULATE)
        return


def _ply_property(data: Any, name: str) -> np.ndarray:
    """Column ``name`` of a trimesh raw PLY element (a record array: pscc reads only binary PLY with trimesh)."""
    return np.asarray(data[name])


def _ply_vertices(source: str, elements: Mapping[str, Any]) -> tuple[np.ndarray, np.ndarray | None]:
    """Positions and optional texture coordinates of a binary PLY's vertex element."""
    element = elements.get("vertex")
    if element is None or not element.get("length"):
        return np.zeros((0, 3), dtype=np.float32), None
    data = element.get("data")
    missing = [c for c in "xyz" if c not in element.get("properties", {})]
    if missing:
        raise InputError(source, "vertex", f"vertex element has no property {missing[0]!r}",
                         "write vertex positions as float properties x, y and z")
    if data is None:
        raise InputError(source, "vertex", "vertex data could not be read (file corrupt)",
                         "re-export the PLY file")
    try:
        pair = _uv_pair(element.get("properties", {}))
        names = "xyz" if pair is None else ("x", "y", "z", *pair)
        columns = [_ply_property(data, c).astype(np.float64).reshape(-1) for c in names]
    except (KeyError, TypeError, ValueError) as exc:
        raise InputError(source, "vertex", "vertex data is malformed or truncated",
                         "re-export the PLY file") from exc
    length = int(element["length"])
    if any(c.shape[0] != length for c in columns):
        raise InputError(source, "vertex", f"header declares {length} vertices but the data holds "
                         "a different number (file truncated or corrupt)", "re-export the PLY file")
    return np.column_stack(columns[:3]), (None if pair is None else np.column_stack(columns[3:]))


def _ply_faces(source: str, elements: Mapping[str, Any]) -> tuple[np.ndarray, np.ndarray | None]:
    """Raw face index rows and optional object ids of a binary PLY, rejecting any non-triangle face."""
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
    if not (isinstance(data, np.ndarray) and data.dtype.names is not None):
        raise InputError(source, "face", "face data is malformed", "re-export the PLY file")
    # A record array; the list is a record of (count 'f0', indices 'f1').
    record = data[name]
    if record.dtype.names is None or "f0" not in record.dtype.names:
        raise InputError(source, "face", "vertex_indices is not a list property",
                         "write faces as 'property list uchar int vertex_indices'")
    counts = np.asarray(record["f0"]).reshape(-1)
    bad = np.flatnonzero(counts != 3)
    if bad.size:
        row = int(bad[0])
        raise InputError(source, f"face {row}", f"face has {int(counts[row])} vertices; {_NOT_TRIANGLES}",
                         _TRIANGULATE)
    indices = np.asarray(record["f1"])
    if indices.ndim != 2 or indices.shape[0] != length:
        raise InputError(source, "face", f"header declares {length} faces but the data holds "
                         "a different number (file truncated or corrupt)", "re-export the PLY file")
    if indices.shape[1] != 3:
        raise InputError(source, "face 0", f"faces have {indices.shape[1]} vertices; {_NOT_TRIANGLES}",
                         _TRIANGULATE)

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


def load_ply(path: Path) -> MeshData:
    """Load a PLY file (no triangulation, merging or reordering).

    The header is parsed and checked here first, so an element count the file cannot hold is refused
    before anything is allocated. ASCII bodies are read here too, every integer checked against its
    declared type (a list length must match its row); binary bodies go through trimesh's raw element
    data.
    """
    from trimesh.exchange.ply import load_ply

    source = str(path)
    data = read_input_bytes(path)
    file_format, header_elements, body = _ply_header(source, data)
    if file_format == "ascii":
        text = data[body:].decode("utf-8", errors="replace")
        vertices, faces, object_ids, uv = _read_ply_ascii(source, header_elements, text)
        return _validate_mesh(vertices, faces, source=source, vertices_end=None, rest=None,
                              object_ids=object_ids, face_label=None, uv=uv)
    _check_binary_face_lists(source, file_format, header_elements, data, body)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            loaded = load_ply(io.BytesIO(data), fix_texture=False, prefer_color=None, skip_materials=True)
    except Exception as exc:  # trimesh raises assorted errors on corrupt files
        raise InputError(source, "file", f"is not a readable PLY file ({exc})",
                         "re-export the mesh as a PLY file with triangle faces; mixed triangle and "
                         "quad faces in binary PLY also end up here: triangulate the mesh") from exc
    elements = loaded.get("metadata", {}).get("_ply_raw")
    if elements is None:
        raise InputError(source, "file", "trimesh returned no raw PLY elements",
                         "install a trimesh version >= 4.0")
    vertices, uv = _ply_vertices(source, elements)
    faces, object_ids = _ply_faces(source, elements)
    return _validate_mesh(vertices, faces, source=source, vertices_end=None, rest=None,
                          object_ids=object_ids, face_label=None, uv=uv)
