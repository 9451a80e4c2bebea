"""Stitches in mesh files: OBJ ``stitch i j k r`` lines (0-based ids), NPZ ``stitches``; bad rows named."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from pscc.mesh import load_mesh, save_mesh_npz, validate_mesh
from pscc.mesh.mesh_data import check_stitches
from tests.mesh.test_io import expect_error, write

TWO_TRIANGLES = "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1.1 0 0\nv 2 0 0\nv 1.1 1 0\nf 1 2 3\nf 4 5 6\n"


def test_obj_stitch_lines(tmp_path: Path) -> None:
    mesh = load_mesh(write(tmp_path / "sewn.obj", TWO_TRIANGLES + "stitch 3 1 2 0.0\nstitch 5 1 2 0.25 # comment\n"))
    np.testing.assert_array_equal(mesh.stitches, [[3, 1, 2, 0.0], [5, 1, 2, 0.25]])
    assert load_mesh(write(tmp_path / "plain.obj", TWO_TRIANGLES)).stitches is None


@pytest.mark.parametrize(("line", "words"), [
    ("stitch 3 1 2", ("malformed stitch line",)),
    ("stitch 3 1 x 0.5", ("malformed stitch line",)),
    ("stitch 3 1 9 0.5", ("[0, 6)",)),
    ("stitch 3 3 2 0.5", ("sews vertex 3 to itself",)),
    ("stitch 3 1 2 1.5", ("outside [0, 1]",)),
])
def test_obj_bad_stitch_lines_name_the_line(tmp_path: Path, line: str, words: tuple[str, ...]) -> None:
    path = write(tmp_path / "bad.obj", TWO_TRIANGLES + "stitch 4 0 1 0.5\n" + line + "\n")
    expect_error(lambda: load_mesh(path), source=str(path), field="line 10", words=words)


def test_npz_stitches_round_trip_and_checks(tmp_path: Path) -> None:
    vertices = [[0, 0, 0], [1, 0, 0], [0, 1, 0], [1.1, 0, 0], [2, 0, 0], [1.1, 1, 0]]
    faces = [[0, 1, 2], [3, 4, 5]]
    mesh = validate_mesh(vertices, faces, stitches=[[3, 1, 2, 0.5]])
    save_mesh_npz(tmp_path / "sewn.npz", mesh)
    np.testing.assert_array_equal(load_mesh(tmp_path / "sewn.npz").stitches, [[3, 1, 2, 0.5]])
    expect_error(lambda: validate_mesh(vertices, faces, stitches=[[3, 1, 2]]), source="argument", field="stitches",
                 words=("(s, 4)",))
    expect_error(lambda: validate_mesh(vertices, faces, stitches=[[3.5, 1, 2, 0.5]]), source="argument",
                 field="stitches", words=("whole number",))
    assert check_stitches(np.zeros((0, 4)), 6, "argument").shape == (0, 4)
