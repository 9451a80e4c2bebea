"""Texture coordinates (``MeshData.uv``) from OBJ ``vt``, PLY ``s, t`` / ``u, v`` and NPZ ``uv``."""

from __future__ import annotations

import struct
from pathlib import Path

import numpy as np
import pytest

from pscc.mesh import load_mesh, save_mesh_npz, validate_mesh
from tests.mesh.test_io import expect_error, write

# Two panels of a pattern: each vertex has one (u, v), the vt list is in another order than the vertices.
PANELS_OBJ = """\
v 0 0 0
v 1 0 0
v 0 1 0
v 2 0 0.5
v 3 0 0.5
v 2 1 0.5
vt 0.5 0.5
vt 0.1 0.0
vt 0.2 0.0
vt 0.1 0.1
vt 0.6 0.5
vt 0.5 0.6
o front
f 1/2 2/3/1 3/4
o back
f 4/-6//1 5/5 6/6
"""
PANELS_UV = [[0.1, 0.0], [0.2, 0.0], [0.1, 0.1], [0.5, 0.5], [0.6, 0.5], [0.5, 0.6]]


def test_obj_texture_coordinates_become_vertex_uv(tmp_path: Path) -> None:
    mesh = load_mesh(write(tmp_path / "panels.obj", PANELS_OBJ.replace("4/-6//1", "4/1")))
    np.testing.assert_allclose(mesh.uv, PANELS_UV, rtol=0, atol=1e-7)
    assert mesh.uv.dtype == np.float32 and mesh.object_ids.tolist() == [0, 1]


def test_obj_relative_texture_indices_and_no_texture(tmp_path: Path) -> None:
    # -6 counts back from the 6 vt lines above the face: vt 1.
    assert load_mesh(write(tmp_path / "relative.obj", PANELS_OBJ.replace("4/-6//1", "4/-6"))).uv[3].tolist() == \
        [0.5, 0.5]
    plain = load_mesh(write(tmp_path / "plain.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nf 1 2 3\n"))
    assert plain.uv is None


def test_obj_unused_vertex_gets_zero_uv(tmp_path: Path) -> None:
    text = "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 5 5 5\nvt 0.3 0.4\nvt 0.5 0.4\nvt 0.3 0.6\nf 1/1 2/2 3/3\n"
    mesh = load_mesh(write(tmp_path / "unused.obj", text))
    np.testing.assert_allclose(mesh.uv, [[0.3, 0.4], [0.5, 0.4], [0.3, 0.6], [0.0, 0.0]], atol=1e-7)


def test_obj_uv_seam_through_a_vertex_is_explained_not_refused(tmp_path: Path) -> None:
    # Vertex 1 is used with vt 1 = (0.5, 0.5) in line 16 and with vt 2 = (0.1, 0) in line 14: the mesh loads
    # (bodies and obstacles have such seams), its uv is None and uv_issue says why.
    mesh = load_mesh(write(tmp_path / "seam.obj", PANELS_OBJ.replace("f 4/-6//1", "f 1/1")))
    assert mesh.uv is None
    assert mesh.uv_issue.startswith("line 16: vertex 1 has texture coordinates [0.5, 0.5]")
    assert "line 14" in mesh.uv_issue and "two different (u, v)" in mesh.uv_issue
    mixed = load_mesh(write(tmp_path / "mixed.obj", PANELS_OBJ.replace("f 4/-6//1 5/5 6/6", "f 4 5 6")))
    assert mixed.uv is None and mixed.uv_issue.startswith("line 16: this face has no texture coordinates")


@pytest.mark.parametrize(("face", "words"), [
    ("f 4/7 5/5 6/6", ("texture coordinate 7", "6 'vt' lines")),
    ("f 4/0 5/5 6/6", ("texture coordinate 0",)),
    ("f 4/x 5/5 6/6", ("malformed texture coordinate index",)),
])
def test_obj_bad_texture_references_leave_no_uv(tmp_path: Path, face: str, words: tuple[str, ...]) -> None:
    mesh = load_mesh(write(tmp_path / "bad.obj", PANELS_OBJ.replace("f 4/-6//1 5/5 6/6", face)))
    assert mesh.uv is None and mesh.uv_issue.startswith("line 16: ")
    assert all(word in mesh.uv_issue for word in words), mesh.uv_issue


def test_obj_bad_vt_line(tmp_path: Path) -> None:
    path = write(tmp_path / "badvt.obj", PANELS_OBJ.replace("vt 0.6 0.5", "vt 0.6 nan"))
    expect_error(lambda: load_mesh(path), source=str(path), field="line 11", words=("NaN or Inf",))
    path = write(tmp_path / "badvt2.obj", PANELS_OBJ.replace("vt 0.6 0.5", "vt zero 0.5"))
    expect_error(lambda: load_mesh(path), source=str(path), field="line 11", words=("malformed",))


@pytest.mark.parametrize("names", [("s", "t"), ("u", "v"), ("texture_u", "texture_v")])
def test_ply_ascii_texture_coordinates(tmp_path: Path, names: tuple[str, str]) -> None:
    text = "\n".join([
        "ply", "format ascii 1.0", "element vertex 3", "property float x", "property float y", "property float z",
        f"property float {names[0]}", f"property float {names[1]}", "element face 1",
        "property list uchar int vertex_indices", "end_header",
        "0 0 0 0.1 0.2", "1 0 0 0.3 0.2", "0 1 0 0.1 0.4", "3 0 1 2", ""])
    mesh = load_mesh(write(tmp_path / "uv.ply", text))
    np.testing.assert_allclose(mesh.uv, [[0.1, 0.2], [0.3, 0.2], [0.1, 0.4]], atol=1e-7)


def test_ply_binary_texture_coordinates(tmp_path: Path) -> None:
    header = (b"ply\nformat binary_little_endian 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
              b"property float z\nproperty float s\nproperty float t\nelement face 1\n"
              b"property list uchar int vertex_indices\nend_header\n")
    rows = [(0, 0, 0, 0.1, 0.2), (1, 0, 0, 0.3, 0.2), (0, 1, 0, 0.1, 0.4)]
    body = b"".join(struct.pack("<5f", *row) for row in rows) + struct.pack("<B3i", 3, 0, 1, 2)
    path = tmp_path / "uv_bin.ply"
    path.write_bytes(header + body)
    mesh = load_mesh(path)
    np.testing.assert_allclose(mesh.uv, [[0.1, 0.2], [0.3, 0.2], [0.1, 0.4]], atol=1e-7)
    np.testing.assert_allclose(mesh.vertices[1], [1, 0, 0])


def test_npz_uv_round_trip_and_checks(tmp_path: Path) -> None:
    mesh = validate_mesh([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 2]], uv=[[0, 0], [2, 0], [0, 2]])
    save_mesh_npz(tmp_path / "uv.npz", mesh)
    np.testing.assert_array_equal(load_mesh(tmp_path / "uv.npz").uv, mesh.uv)
    expect_error(lambda: validate_mesh([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 2]], uv=[[0, 0], [1, 0]]),
                 source="argument", field="uv", words=("2 rows", "3 vertices"))
    expect_error(lambda: validate_mesh([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 2]],
                                       uv=[[0, 0], [1, np.nan], [0, 1]]), source="argument", field="uv")
