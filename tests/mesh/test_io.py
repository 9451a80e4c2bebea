"""Mesh validation and the OBJ / PLY / NPZ loaders: good files load unchanged, bad ones say why."""

from __future__ import annotations

import os
import struct
from pathlib import Path

import numpy as np
import pytest
import warp as wp

from pscc.errors import InputError
from pscc.mesh import (
    MeshData,
    load_mesh,
    load_positions,
    save_mesh_npz,
    validate_mesh,
)

SQUARE_V = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], dtype=np.float32)
SQUARE_F = np.array([[0, 1, 2], [0, 2, 3]], dtype=np.int32)


def expect_error(call, *, source: str, field: str, words: tuple[str, ...] = (),
                 fix_words: tuple[str, ...] = ()) -> InputError:
    """Run ``call`` and check the InputError names the source, the field, the problem and a fix."""
    with pytest.raises(InputError) as info:
        call()
    error = info.value
    message = str(error)
    assert error.source == source
    assert error.field == field
    assert message.startswith(f"{source}: {field}: ")
    assert "Fix: " in message and error.fix
    for word in words:
        assert word in error.problem, (word, message)
    for word in fix_words:
        assert word in error.fix, (word, message)
    return error


def write(path: Path, text: str) -> Path:
    path.write_text(text)
    return path


# --------------------------------------------------------------------------------------------
# validate_mesh
# --------------------------------------------------------------------------------------------


def test_validate_accepts_and_converts() -> None:
    mesh = validate_mesh(SQUARE_V.astype(np.float64), SQUARE_F.astype(np.int64))
    assert isinstance(mesh, MeshData)
    assert mesh.vertices.dtype == np.float32 and mesh.vertices.flags.c_contiguous
    assert mesh.faces.dtype == np.int32
    assert mesh.object_ids.dtype == np.int32 and mesh.object_ids.tolist() == [0, 0]
    assert (mesh.vertex_count, mesh.face_count, mesh.object_count) == (4, 2, 1)
    assert mesh.source == "argument" and mesh.vertices_end is None and mesh.rest is None
    np.testing.assert_array_equal(mesh.vertices, SQUARE_V)
    np.testing.assert_array_equal(mesh.faces, SQUARE_F)


def test_validate_copies_and_keeps_order() -> None:
    vertices = np.array([[0, 0, 0], [0, 0, 0], [1, 0, 0], [0, 1, 0], [5, 5, 5]], dtype=np.float32)
    faces = np.array([[3, 2, 0], [1, 2, 3]], dtype=np.int32)
    mesh = validate_mesh(vertices, faces)
    vertices[0, 0] = 9.0
    faces[0, 0] = 4
    assert mesh.vertices[0, 0] == 0.0 and mesh.faces[0, 0] == 3
    assert mesh.vertex_count == 5  # the coinciding and the unused vertex are kept


def test_validate_optional_arrays() -> None:
    end = SQUARE_V + 0.5
    mesh = validate_mesh(SQUARE_V, SQUARE_F, vertices_end=end, rest=SQUARE_V[:, :2],
                         object_ids=np.array([0, 3], dtype=np.uint8), source="x.npz")
    np.testing.assert_array_equal(mesh.vertices_end, end)
    assert mesh.rest.shape == (4, 2) and mesh.rest.dtype == np.float32
    assert mesh.object_ids.tolist() == [0, 3] and mesh.object_count == 4
    assert mesh.source == "x.npz"
    assert validate_mesh(SQUARE_V, SQUARE_F, rest=SQUARE_V).rest.shape == (4, 3)


def test_validate_accepts_warp_and_lists() -> None:
    mesh = validate_mesh(wp.array(SQUARE_V, dtype=wp.vec3, device="cpu"), SQUARE_F.tolist())
    np.testing.assert_array_equal(mesh.vertices, SQUARE_V)


def test_validate_accepts_zero_area_and_non_manifold() -> None:
    vertices = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, 0]], float)
    faces = np.array([[0, 1, 2], [1, 0, 3], [0, 1, 4], [0, 5, 2]])  # edge (0,1) has 3 faces
    mesh = validate_mesh(vertices, faces)
    assert mesh.face_count == 4
    collinear = validate_mesh([[0, 0, 0], [1, 0, 0], [2, 0, 0]], [[0, 1, 2]])
    assert collinear.face_count == 1


@pytest.mark.parametrize(
    ("vertices", "faces", "field", "words", "fix_words"),
    [
        (np.zeros((0, 3)), SQUARE_F, "vertices", ("no vertices", "empty"), ()),
        (SQUARE_V, np.zeros((0, 3), np.int32), "faces", ("no faces", "empty"), ()),
        (SQUARE_V, np.array([[0, 1, 2, 3]]), "faces", ("triangles",), ("triangulate",)),
        (SQUARE_V, np.array([0, 1, 2]), "faces", ("(3,)",), ()),
        (SQUARE_V, SQUARE_F.astype(np.float64), "faces", ("float64", "not an integer"), ("integer",)),
        (SQUARE_V, np.array([[0, 1, 2], [0, 2, -1]]), "faces", ("row 1", "-1", "outside"), ("0-based",)),
        (SQUARE_V, np.array([[0, 1, 4], [0, 2, 3]]), "faces", ("row 0", "4", "outside [0, 4)"), ()),
        (SQUARE_V, np.array([[0, 1, 2], [3, 3, 1]]), "faces", ("row 1", "twice"), ("distinct",)),
        (SQUARE_V, np.array([[0, 1, 2], [1, 3, 2], [2, 0, 1]]), "faces", ("row 0", "row 2", "duplicate"),
         ("remove",)),
        (SQUARE_V[:, :2], SQUARE_F, "vertices", ("shape (4, 2)",), ("(n, 3)",)),
        (np.array([["a", "b", "c"]] * 4), SQUARE_F, "vertices", ("dtype",), ("float",)),
        (np.array([[0, 0, 0], [1, 0, np.nan], [0, 1, 0], [1, 1, 0]]), SQUARE_F, "vertices",
         ("row 1", "NaN"), ()),
        (np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 1e300]]), SQUARE_F, "vertices",
         ("row 3", "Inf"), ()),
        ([[0, 0, 0], [1, 0], [0, 1, 0]], [[0, 1, 2]], "vertices", ("rectangular",), ("(n, 3)",)),
    ],
)
def test_validate_rejects(vertices, faces, field, words, fix_words) -> None:
    expect_error(lambda: validate_mesh(vertices, faces, source="mesh.obj"), source="mesh.obj",
                 field=field, words=words, fix_words=fix_words)


@pytest.mark.parametrize(
    ("kwargs", "field", "words"),
    [
        ({"vertices_end": SQUARE_V[:3]}, "vertices_end", ("(3, 3)", "(4, 3)")),
        ({"vertices_end": np.where(np.arange(12).reshape(4, 3) == 7, np.inf, 0.0)}, "vertices_end",
         ("row 2",)),
        ({"rest": SQUARE_V[:3, :2]}, "rest", ("3 rows", "4 vertices")),
        ({"rest": np.zeros((4, 4))}, "rest", ("(4, 4)",)),
        ({"rest": np.where(np.arange(8).reshape(4, 2) == 0, np.nan, 0.0)}, "rest", ("row 0",)),
        ({"object_ids": [0, 1, 2]}, "object_ids", ("(3,)", "(2,)")),
        ({"object_ids": [0, -2]}, "object_ids", ("row 1", "-2")),
        ({"object_ids": [0.0, 1.0]}, "object_ids", ("float64", "integer")),
        ({"object_ids": [0, 2**40]}, "object_ids", ("row 1",)),
    ],
)
def test_validate_rejects_optional(kwargs, field, words) -> None:
    expect_error(lambda: validate_mesh(SQUARE_V, SQUARE_F, source="argument", **kwargs),
                 source="argument", field=field, words=words)


# --------------------------------------------------------------------------------------------
# Paths and extensions
# --------------------------------------------------------------------------------------------


def test_missing_file(tmp_path: Path) -> None:
    path = tmp_path / "nope.obj"
    error = expect_error(lambda: load_mesh(path), source=str(path), field="path",
                         words=("does not exist",))
    assert str(path) in error.fix


def test_unknown_extension(tmp_path: Path) -> None:
    path = write(tmp_path / "mesh.stl", "solid x")
    expect_error(lambda: load_mesh(path), source=str(path), field="extension",
                 words=(".stl",), fix_words=(".obj", ".ply", ".npz"))


def test_directory_is_rejected(tmp_path: Path) -> None:
    path = tmp_path / "dir.obj"
    path.mkdir()
    expect_error(lambda: load_mesh(path), source=str(path), field="path", words=("not a regular file",))


def test_extension_is_case_insensitive(tmp_path: Path) -> None:
    path = write(tmp_path / "MESH.OBJ", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    assert load_mesh(str(path)).face_count == 1


# --------------------------------------------------------------------------------------------
# OBJ
# --------------------------------------------------------------------------------------------

OBJ_FORMS = """# all face forms
mtllib cube.mtl
v 0 0 0
v 1 0 0
v 1 1 0
v 0 1 0
v 0 0 1   1.0
vt 0 0
vt 1 0
vt 1 1
vn 0 0 1
usemtl red
s off
f 1 2 3
f 1/1 3/3 4/1
f 1//1 2//1 5//1
f 2/2/1 3/3/1 5/1/1   # trailing comment
"""


def test_obj_face_forms(tmp_path: Path) -> None:
    mesh = load_mesh(write(tmp_path / "forms.obj", OBJ_FORMS))
    assert mesh.vertex_count == 5
    np.testing.assert_array_equal(mesh.faces, [[0, 1, 2], [0, 2, 3], [0, 1, 4], [1, 2, 4]])
    np.testing.assert_array_equal(mesh.vertices[4], [0, 0, 1])
    assert mesh.object_ids.tolist() == [0, 0, 0, 0]
    assert mesh.source == str(tmp_path / "forms.obj")


def test_obj_negative_indices(tmp_path: Path) -> None:
    text = "v 0 0 0\nv 1 0 0\nv 0 1 0\nf -3 -2 -1\nv 1 1 0\nf -3/1 -1/2 -2//3\n"
    mesh = load_mesh(write(tmp_path / "neg.obj", text))
    np.testing.assert_array_equal(mesh.faces, [[0, 1, 2], [1, 3, 2]])


def test_obj_objects_and_groups(tmp_path: Path) -> None:
    text = (
        "o first\n"  # leading o: no empty object
        "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\nv 2 0 0\nv 2 1 0\n"
        "f 1 2 3\n"
        "g a\n"
        "g b\n"  # two group lines without a face in between: one new object
        "f 2 4 3\n"
        "f 2 5 4\n"
        "o third\n"
        "f 5 6 4\n"
    )
    mesh = load_mesh(write(tmp_path / "objects.obj", text))
    assert mesh.object_ids.tolist() == [0, 1, 1, 2]
    assert mesh.object_count == 3


def test_obj_faces_before_group_are_object_zero(tmp_path: Path) -> None:
    text = "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\nf 1 2 3\ng g1\nf 2 4 3\n"
    assert load_mesh(write(tmp_path / "g.obj", text)).object_ids.tolist() == [0, 1]


@pytest.mark.parametrize(
    ("body", "line", "words", "fix_words"),
    [
        ("v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\n\nf 1 2 3 4\n", 6, ("4 vertices", "triangles"),
         ("triangulate",)),
        ("v 0 0 0\nv 1 0 0\nf 1 2\n", 3, ("only 2",), ("3 vertex",)),
        ("v 0 0 0\nv 1 0.x 0\n", 2, ("malformed number",), ()),
        ("v 0 0\n", 1, ("fewer than 3",), ("v x y z",)),
        ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 three\n", 4, ("malformed vertex index",), ()),
        ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 0 1 2\n", 4, ("index 0",), ("1-based",)),
        ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf -4 -2 -1\n", 4, ("-4", "before the first vertex"), ()),
        ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 4\n", 4, ("vertex 4", "only 3"), ()),
        ("v 0 0 0\nv nan 0 0\nv 0 1 0\nf 1 2 3\n", 2, ("NaN",), ("non-finite",)),
    ],
)
def test_obj_rejects_with_line_number(tmp_path: Path, body, line, words, fix_words) -> None:
    path = write(tmp_path / "bad.obj", body)
    expect_error(lambda: load_mesh(path), source=str(path), field=f"line {line}", words=words,
                 fix_words=fix_words)


@pytest.mark.parametrize("index", ["99999999999999999999999", "2147483648", "-99999999999999999999999", "9" * 200])
def test_obj_face_index_too_large_is_refused(tmp_path: Path, index: str) -> None:
    """A face index beyond int32 names no vertex; it used to overflow into an OverflowError traceback."""
    path = write(tmp_path / "big.obj", f"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 {index}\n")
    error = expect_error(lambda: load_mesh(path), source=str(path), field="line 4",
                         words=("vertex index", "out of range", "2147483647"), fix_words=("between 1 and",))
    assert len(str(error)) < 400


@pytest.mark.parametrize(("coordinate", "field"), [("1e999", "line 2"), ("-inf", "line 2"), ("1e300", "vertices")])
def test_obj_coordinates_beyond_float32_are_refused(tmp_path: Path, coordinate: str, field: str) -> None:
    path = write(tmp_path / "far.obj", f"v 0 0 0\nv {coordinate} 0 0\nv 0 1 0\nf 1 2 3\n")
    expect_error(lambda: load_mesh(path), source=str(path), field=field, words=("Inf",))


def test_obj_duplicate_face_names_lines(tmp_path: Path) -> None:
    path = write(tmp_path / "dup.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n# x\nf 3 1 2\n")
    expect_error(lambda: load_mesh(path), source=str(path), field="faces",
                 words=("line 4", "line 6", "duplicate"))


def test_obj_repeated_vertex_names_line(tmp_path: Path) -> None:
    path = write(tmp_path / "rep.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\nf 2 2 3\n")
    expect_error(lambda: load_mesh(path), source=str(path), field="faces", words=("line 5", "twice"))


def test_obj_without_faces_is_empty(tmp_path: Path) -> None:
    path = write(tmp_path / "points.obj", "v 0 0 0\nv 1 0 0\n")
    expect_error(lambda: load_mesh(path), source=str(path), field="faces", words=("empty",))


def test_obj_binary_garbage(tmp_path: Path) -> None:
    path = tmp_path / "garbage.obj"
    path.write_bytes(b"\x00\x01\x02binary")
    expect_error(lambda: load_mesh(path), source=str(path), field="file", words=("NUL",))


# --------------------------------------------------------------------------------------------
# PLY
# --------------------------------------------------------------------------------------------


def ascii_ply(vertices: list[str], faces: list[str], *, object_id: bool = False) -> str:
    header = [
        "ply", "format ascii 1.0", f"element vertex {len(vertices)}",
        "property float x", "property float y", "property float z",
        f"element face {len(faces)}", "property list uchar int vertex_indices",
    ]
    if object_id:
        header.append("property int object_id")
    return "\n".join(header + ["end_header"] + vertices + faces) + "\n"


SQUARE_PLY_V = ["0 0 0", "1 0 0", "1 1 0", "0 1 0", "0 0 0"]


def test_ply_ascii_with_object_ids(tmp_path: Path) -> None:
    path = write(tmp_path / "tri.ply",
                 ascii_ply(SQUARE_PLY_V, ["3 0 1 2 7", "3 0 2 3 2"], object_id=True))
    mesh = load_mesh(path)
    assert mesh.vertex_count == 5  # the duplicate, unused vertex 4 is kept
    np.testing.assert_array_equal(mesh.faces, [[0, 1, 2], [0, 2, 3]])
    assert mesh.object_ids.tolist() == [7, 2]


def test_ply_single_face(tmp_path: Path) -> None:
    mesh = load_mesh(write(tmp_path / "one.ply", ascii_ply(SQUARE_PLY_V[:3], ["3 2 1 0"])))
    np.testing.assert_array_equal(mesh.faces, [[2, 1, 0]])


def test_ply_binary_round_trip(tmp_path: Path) -> None:
    header = (b"ply\nformat binary_little_endian 1.0\nelement vertex 4\nproperty float x\n"
              b"property float y\nproperty float z\nelement face 2\n"
              b"property list uchar int vertex_indices\nproperty int object_id\nend_header\n")
    faces = struct.pack("<B3ii", 3, 0, 1, 2, 1) + struct.pack("<B3ii", 3, 0, 2, 3, 4)
    path = tmp_path / "bin.ply"
    path.write_bytes(header + SQUARE_V.astype("<f4").tobytes() + faces)
    mesh = load_mesh(path)
    np.testing.assert_array_equal(mesh.vertices, SQUARE_V)
    np.testing.assert_array_equal(mesh.faces, SQUARE_F)
    assert mesh.object_ids.tolist() == [1, 4]


def test_ply_ascii_quads_rejected(tmp_path: Path) -> None:
    path = write(tmp_path / "quad.ply", ascii_ply(SQUARE_PLY_V[:4], ["4 0 1 2 3"]))
    expect_error(lambda: load_mesh(path), source=str(path), field="face 0",
                 words=("4 vertices", "triangles"), fix_words=("triangulate",))


def test_ply_ascii_mixed_faces_rejected(tmp_path: Path) -> None:
    path = write(tmp_path / "mixed.ply", ascii_ply(SQUARE_PLY_V, ["3 0 1 2", "4 0 2 3 4"]))
    expect_error(lambda: load_mesh(path), source=str(path), field="face 1",
                 words=("4 vertices", "triangles"), fix_words=("triangulate",))


def test_ply_binary_quads_rejected(tmp_path: Path) -> None:
    header = (b"ply\nformat binary_little_endian 1.0\nelement vertex 4\nproperty float x\n"
              b"property float y\nproperty float z\nelement face 1\n"
              b"property list uchar int vertex_indices\nend_header\n")
    path = tmp_path / "binquad.ply"
    path.write_bytes(header + SQUARE_V.astype("<f4").tobytes() + struct.pack("<B4i", 4, 0, 1, 2, 3))
    expect_error(lambda: load_mesh(path), source=str(path), field="face 0",
                 words=("4 vertices",), fix_words=("triangulate",))


def test_ply_binary_mixed_rejected(tmp_path: Path) -> None:
    header = (b"ply\nformat binary_little_endian 1.0\nelement vertex 5\nproperty float x\n"
              b"property float y\nproperty float z\nelement face 2\n"
              b"property list uchar int vertex_indices\nend_header\n")
    faces = struct.pack("<B3i", 3, 0, 1, 2) + struct.pack("<B4i", 4, 0, 2, 3, 4)
    path = tmp_path / "binmixed.ply"
    path.write_bytes(header + np.zeros((5, 3), "<f4").tobytes() + faces)
    expect_error(lambda: load_mesh(path), source=str(path), field="file", fix_words=("triangulate",))


def test_ply_corrupt(tmp_path: Path) -> None:
    path = tmp_path / "junk.ply"
    path.write_bytes(b"this is not a ply file\n")
    expect_error(lambda: load_mesh(path), source=str(path), field="file", words=("PLY",))


def test_ply_truncated(tmp_path: Path) -> None:
    text = ascii_ply(SQUARE_PLY_V[:4], ["3 0 1 2", "3 0 2 3"])
    path = write(tmp_path / "cut.ply", text[: text.index("3 0 2 3")])
    with pytest.raises(InputError) as info:
        load_mesh(path)
    assert info.value.source == str(path)


def test_ply_without_faces(tmp_path: Path) -> None:
    text = "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\n" \
           "property float z\nend_header\n0 0 0\n"
    path = write(tmp_path / "cloud.ply", text)
    expect_error(lambda: load_mesh(path), source=str(path), field="faces", words=("empty",))


def test_ply_bad_index(tmp_path: Path) -> None:
    path = write(tmp_path / "idx.ply", ascii_ply(SQUARE_PLY_V[:3], ["3 0 1 5"]))
    expect_error(lambda: load_mesh(path), source=str(path), field="faces", words=("row 0", "5"))


# --------------------------------------------------------------------------------------------
# NPZ and save_mesh_npz
# --------------------------------------------------------------------------------------------


def test_npz_round_trip(tmp_path: Path) -> None:
    mesh = validate_mesh(SQUARE_V, SQUARE_F, vertices_end=SQUARE_V * 2, rest=SQUARE_V[:, :2],
                         object_ids=[1, 0])
    path = tmp_path / "mesh.npz"
    save_mesh_npz(path, mesh)
    loaded = load_mesh(path)
    for name in ("vertices", "faces", "vertices_end", "rest", "object_ids"):
        np.testing.assert_array_equal(getattr(loaded, name), getattr(mesh, name))
        assert getattr(loaded, name).dtype == getattr(mesh, name).dtype
    assert loaded.source == str(path)
    assert sorted(os.listdir(tmp_path)) == ["mesh.npz"]  # no temporary file left behind


def test_npz_round_trip_minimal_and_overwrite(tmp_path: Path) -> None:
    path = tmp_path / "mesh.npz"
    path.write_bytes(b"old content")
    save_mesh_npz(path, validate_mesh(SQUARE_V, SQUARE_F))
    loaded = load_mesh(path)
    assert loaded.vertices_end is None and loaded.rest is None
    np.testing.assert_array_equal(loaded.faces, SQUARE_F)


def test_save_npz_missing_directory(tmp_path: Path) -> None:
    path = tmp_path / "missing" / "mesh.npz"
    expect_error(lambda: save_mesh_npz(path, validate_mesh(SQUARE_V, SQUARE_F)), source=str(path),
                 field="path", words=("does not exist",), fix_words=("create",))


def test_npz_missing_key(tmp_path: Path) -> None:
    path = tmp_path / "nofaces.npz"
    np.savez(path, vertices=SQUARE_V, extra=np.zeros(3))
    expect_error(lambda: load_mesh(path), source=str(path), field="faces",
                 words=("missing",), fix_words=("'faces'",))


def test_npz_unknown_keys_ignored(tmp_path: Path) -> None:
    path = tmp_path / "extra.npz"
    np.savez(path, vertices=SQUARE_V, faces=SQUARE_F, colors=np.ones((4, 3)))
    assert load_mesh(path).face_count == 2


def test_npz_bad_array_names_key(tmp_path: Path) -> None:
    path = tmp_path / "bad.npz"
    np.savez(path, vertices=SQUARE_V, faces=SQUARE_F, rest=np.zeros((4, 5)))
    expect_error(lambda: load_mesh(path), source=str(path), field="rest", words=("(4, 5)",))


def test_npz_object_array_rejected(tmp_path: Path) -> None:
    path = tmp_path / "pickled.npz"
    np.savez(path, vertices=SQUARE_V, faces=np.array([[0, 1, 2], None], dtype=object))
    expect_error(lambda: load_mesh(path), source=str(path), field="faces", words=("cannot be read",))


@pytest.mark.parametrize("content", [b"not a zip", b"PK\x03\x04broken"])
def test_npz_corrupt(tmp_path: Path, content: bytes) -> None:
    path = tmp_path / "corrupt.npz"
    path.write_bytes(content)
    expect_error(lambda: load_mesh(path), source=str(path), field="file")


def test_npz_single_npy(tmp_path: Path) -> None:
    path = tmp_path / "array.npz"
    with open(path, "wb") as handle:
        np.save(handle, SQUARE_V)
    expect_error(lambda: load_mesh(path), source=str(path), field="file", words=("single",))


# --------------------------------------------------------------------------------------------
# load_positions
# --------------------------------------------------------------------------------------------


def test_load_positions_formats(tmp_path: Path) -> None:
    end = SQUARE_V + np.array([0, 0, 1], np.float32)
    npz = tmp_path / "end.npz"
    np.savez(npz, vertices=end)  # faces are not needed in an NPZ of positions
    np.testing.assert_array_equal(load_positions(npz, 4), end)
    obj = write(tmp_path / "end.obj", "".join(f"v {x} {y} {z}\n" for x, y, z in end) + "f 1 2 3\n")
    np.testing.assert_array_equal(load_positions(obj, 4), end)
    ply = write(tmp_path / "end.ply", ascii_ply([f"{x} {y} {z}" for x, y, z in end], ["3 0 1 2"]))
    positions = load_positions(ply, 4)
    assert positions.dtype == np.float32 and positions.shape == (4, 3)
    np.testing.assert_array_equal(positions, end)


def test_load_positions_count_mismatch(tmp_path: Path) -> None:
    path = tmp_path / "end.npz"
    np.savez(path, vertices=SQUARE_V)
    expect_error(lambda: load_positions(path, 5), source=str(path), field="vertices",
                 words=("4 vertices", "5"), fix_words=("same vertices",))


def test_load_positions_obj_needs_faces(tmp_path: Path) -> None:
    path = write(tmp_path / "end.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\n")
    expect_error(lambda: load_positions(path, 3), source=str(path), field="faces", words=("empty",))


def test_load_positions_npz_missing_vertices(tmp_path: Path) -> None:
    path = tmp_path / "end.npz"
    np.savez(path, positions=SQUARE_V)
    expect_error(lambda: load_positions(path, 4), source=str(path), field="vertices",
                 words=("missing",))


def test_load_positions_bad_count_argument(tmp_path: Path) -> None:
    path = tmp_path / "end.npz"
    np.savez(path, vertices=SQUARE_V)
    expect_error(lambda: load_positions(path, -1), source="argument", field="vertex_count")


# --------------------------------------------------------------------------------------------
# PLY: absurd counts and integers that overflow
# --------------------------------------------------------------------------------------------

PLY_HEADER = ("ply\nformat {fmt} 1.0\nelement vertex {vertices}\nproperty float x\nproperty float y\n"
              "property float z\nelement face {faces}\nproperty list {count} int vertex_indices\nend_header\n")
TRIANGLE_ASCII = "0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n"
TRIANGLE_BINARY = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], "<f4").tobytes() + struct.pack("<B3i", 3, 0, 1, 2)


def ply_bytes(fmt: str, vertices: object = 3, faces: object = 1, count: str = "uchar",
              body: bytes | None = None) -> bytes:
    header = PLY_HEADER.format(fmt=fmt, vertices=vertices, faces=faces, count=count).encode()
    if body is None:
        body = TRIANGLE_ASCII.encode() if fmt == "ascii" else TRIANGLE_BINARY
    return header + body


@pytest.mark.parametrize("fmt", ["ascii", "binary_little_endian"])
@pytest.mark.parametrize(("element", "count"), [("vertex", 99999999999999999999), ("vertex", 2**33),
                                                ("face", 10**9), ("face", 99999999999999999999)])
def test_ply_counts_the_file_cannot_hold_are_refused(tmp_path: Path, fmt: str, element: str, count: int) -> None:
    """Checked against the file size before anything is read or allocated."""
    path = tmp_path / "absurd.ply"
    path.write_bytes(ply_bytes(fmt, **{"vertices" if element == "vertex" else "faces": count}))
    expect_error(lambda: load_mesh(path), source=str(path), field=element,
                 words=(f"declares {count} {element} rows", "more than the file can hold"), fix_words=("re-export",))


@pytest.mark.parametrize("fmt", ["ascii", "binary_little_endian"])
@pytest.mark.parametrize("line", ["element vertex -3", "element face -1", "element vertex 1e3", "element vertex"])
def test_ply_malformed_counts_are_refused(tmp_path: Path, fmt: str, line: str) -> None:
    data = ply_bytes(fmt).decode("latin-1")
    target = "element vertex 3" if "vertex" in line else "element face 1"
    path = tmp_path / "negative.ply"
    path.write_bytes(data.replace(target, line).encode("latin-1"))
    lineno = 3 if "vertex" in line else 7
    expect_error(lambda: load_mesh(path), source=str(path), field=f"header line {lineno}",
                 words=(repr(line), "count >= 0"), fix_words=("element NAME COUNT",))


@pytest.mark.parametrize(("face_line", "words"), [
    ("99999999999999999999 0 1 2", ("list length of vertex_indices", "uchar [0, 255]")),
    ("255 0 1 2", ("declares 255 values", "holds 3")),
    ("3 0 1 99999999999999999999", ("vertex index 1e+20", "int [-2147483648, 2147483647]")),
    ("3 0 1 2147483648", ("vertex index 2147483648", "int [")),
    ("3 0 1 2.5", ("vertex index 2.5",)),
])
def test_ply_ascii_integers_are_checked_against_their_type(tmp_path: Path, face_line: str,
                                                           words: tuple[str, ...]) -> None:
    """trimesh ignored the list length and wrapped huge indices to -2147483648; pscc reads ASCII itself."""
    path = tmp_path / "huge.ply"
    path.write_bytes(ply_bytes("ascii", body=f"0 0 0\n1 0 0\n0 1 0\n{face_line}\n".encode()))
    error = expect_error(lambda: load_mesh(path), source=str(path), field="face 0", words=words,
                         fix_words=("re-export",))
    assert len(str(error)) < 400


@pytest.mark.parametrize(("count_type", "packed"), [("int", struct.pack("<i", 2**31 - 1)),
                                                    ("uint", struct.pack("<I", 2**32 - 1)),
                                                    ("int", struct.pack("<i", -5))])
def test_ply_binary_list_length_is_checked_before_trimesh_sizes_rows(tmp_path: Path, count_type: str,
                                                                     packed: bytes) -> None:
    vertices = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], "<f4").tobytes()
    path = tmp_path / "list.ply"
    path.write_bytes(ply_bytes("binary_little_endian", count=count_type,
                               body=vertices + packed + struct.pack("<3i", 0, 1, 2)))
    length = struct.unpack("<i" if count_type == "int" else "<I", packed)[0]
    expect_error(lambda: load_mesh(path), source=str(path), field="face 0",
                 words=(f"face has {length} vertices", "triangles"), fix_words=("triangulate",))


def test_ply_ascii_object_ids_and_extra_properties_still_load(tmp_path: Path) -> None:
    text = ("ply\nformat ascii 1.0\ncomment made by hand\nelement vertex 4\nproperty float x\nproperty float y\n"
            "property float z\nproperty uchar red\nelement face 2\nproperty int object_id\n"
            "property list uchar int vertex_indices\nproperty list uchar float texcoord\n"
            "element edge 1\nproperty int vertex1\nproperty int vertex2\nend_header\n"
            "0 0 0 255\n1 0 0 3\n1 1 0 4\n0 1 0 5\n5 3 0 1 2 6 0 0 1 0 1 1\n2147483647 3 0 2 3 0\n0 1\n")
    mesh = load_mesh(write(tmp_path / "extra.ply", text))
    np.testing.assert_array_equal(mesh.faces, SQUARE_F)
    np.testing.assert_array_equal(mesh.vertices, SQUARE_V)
    assert mesh.object_ids.tolist() == [5, 2**31 - 1]


@pytest.mark.parametrize(("vertex_line", "field", "words"), [
    ("1e999 0 0", "vertices", ("NaN or Inf",)),
    ("1 0", "vertex 1", ("ends before property z",)),
    ("1 0 0 7", "vertex 1", ("holds 4 values", "1 more than its properties")),
    ("1 zero 0", "vertex 1", ("'zero'", "not a number")),
])
def test_ply_ascii_bad_vertex_rows(tmp_path: Path, vertex_line: str, field: str, words: tuple[str, ...]) -> None:
    path = tmp_path / "rows.ply"
    path.write_bytes(ply_bytes("ascii", body=f"0 0 0\n{vertex_line}\n0 1 0\n3 0 1 2\n".encode()))
    expect_error(lambda: load_mesh(path), source=str(path), field=field, words=words)
