"""Rest shapes a garment file really has: its UV layout (``rest = "uv"``, ``uv_scale``) or its own curved
shape (``rest = "mesh"``, ``rest_bending``), and ``auto`` choosing between them (issue 13)."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

from pscc.errors import InputError
from pscc.mesh.generate import grid_sheet
from pscc.scenes.scene_file import load_scene_file, read_scene_file
from pscc.sim.solver import ClothSolver
from tests.scenes.test_scene_file import _assert_same_scene, _edge_lengths, _round_trip, _write, _write_obj


def _curved(nx: int = 8) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A half-cylinder patch (radius 0.3 m, 0.5 m long) and the flat pattern it unrolls to (in metres)."""
    flat, faces, _ = grid_sheet(nx, nx, np.pi * 0.3, 0.5)
    angle = flat[:, 0] / 0.3
    curved = np.stack([0.3 * np.sin(angle), flat[:, 1], 0.3 * np.cos(angle)], axis=1)
    return curved, faces, flat[:, :2].astype(np.float64)


def _write_uv_obj(path: Path, vertices: np.ndarray, faces: np.ndarray, uv: np.ndarray) -> Path:
    lines = [f"v {x!r} {y!r} {z!r}" for x, y, z in np.asarray(vertices, np.float64).tolist()]
    lines += [f"vt {u!r} {v!r}" for u, v in np.asarray(uv, np.float64).tolist()]
    lines += [f"f {a + 1}/{a + 1} {b + 1}/{b + 1} {c + 1}/{c + 1}" for a, b, c in faces]
    path.write_text("\n".join(lines) + "\n")
    return path


def test_auto_takes_the_uv_layout_of_a_curved_garment(tmp_path: Path) -> None:
    curved, faces, pattern = _curved()
    _write_uv_obj(tmp_path / "panel.obj", curved, faces, pattern / 2.0)  # uv in half-metres
    loaded = read_scene_file(_write(tmp_path, '[[cloth]]\nmesh = "panel.obj"\nuv_scale = 2.0\n'))
    assert loaded.spec["cloth"][0]["rest"] == "uv" and loaded.spec["cloth"][0]["uv_scale"] == 2.0
    np.testing.assert_allclose(loaded.scene.rest, pattern, atol=1e-6)
    # The pattern's edge lengths are the curved mesh's (the unrolled cylinder, up to chord vs arc).
    np.testing.assert_allclose(_edge_lengths(loaded.scene.rest, faces), _edge_lengths(curved, faces), rtol=2e-2)
    _round_trip(tmp_path / "scene.toml", tmp_path)


def test_uv_not_in_metres_is_refused_with_the_matching_scale(tmp_path: Path) -> None:
    curved, faces, pattern = _curved()
    _write_uv_obj(tmp_path / "panel.obj", curved, faces, pattern / 25.0)  # e.g. a 0..1 texture atlas
    path = _write(tmp_path, '[[cloth]]\nmesh = "panel.obj"\nrest = "uv"\n')
    with pytest.raises(InputError) as info:
        load_scene_file(path)
    assert str(info.value).startswith(f"{path}: cloth[0].uv_scale: "), str(info.value)
    suggested = float(re.search(r"set uv_scale = ([0-9.]+)", info.value.fix).group(1))
    assert suggested == pytest.approx(25.0, rel=2e-2)
    scene, _, _ = load_scene_file(_write(tmp_path, f'[[cloth]]\nmesh = "panel.obj"\nuv_scale = {suggested}\n'))
    np.testing.assert_allclose(scene.rest, pattern * suggested / 25.0, atol=1e-6)


def test_rest_from_the_mesh_keeps_its_shape_and_bends_flat_on_request(tmp_path: Path) -> None:
    curved, faces, _ = _curved(6)
    _write_obj(tmp_path / "shell.obj", curved, faces)
    text = ('[solver]\ngravity = [0.0, 0.0, 0.0]\n[[cloth]]\nmesh = "shell.obj"\nscale = 2.0\nrest = "mesh"\n'
            'pins = { side = "left" }\n')
    loaded = read_scene_file(_write(tmp_path, text))
    scene = loaded.scene
    assert scene.rest.shape == (len(curved), 3) and loaded.spec["cloth"][0]["rest_bending"] == "mesh"
    np.testing.assert_allclose(scene.rest, 2.0 * curved, atol=1e-6)
    assert scene.flat_bending is None
    # The left side of the shell's best-fit plane: one column of the grid (7 vertices).
    assert scene.handles[0].vertices.size == 7
    solver = ClothSolver(scene)
    angles = solver.model.hinges.rest_angle.numpy()
    assert np.abs(angles).max() > 0.1  # the cylinder's folds are its rest
    state, scratch = solver.initial_state(), solver.initial_state()
    solver.advance_frame(state, scratch, scene.time_step, scene.steps_per_frame)
    # At rest in its own shape, without gravity: nothing moves.
    np.testing.assert_allclose(state.positions.numpy(), scene.vertices, atol=1e-5)

    flat = read_scene_file(_write(tmp_path, text + 'rest_bending = "flat"\n')).scene
    assert flat.flat_bending is not None and flat.flat_bending.all()
    solver = ClothSolver(flat)
    assert np.abs(solver.model.hinges.rest_angle.numpy()).max() == 0.0
    state, scratch = solver.initial_state(), solver.initial_state()
    for _ in range(3):
        solver.advance_frame(state, scratch, flat.time_step, flat.steps_per_frame)
    # Bending towards flat, the free side opens out (ten times more than the at-rest shell's tolerance).
    assert np.abs(state.positions.numpy() - flat.vertices).max() > 1e-4
    _round_trip(tmp_path / "scene.toml", tmp_path)


def test_a_flat_pattern_and_a_mesh_rest_in_one_scene(tmp_path: Path) -> None:
    curved, faces, _ = _curved(4)
    _write_obj(tmp_path / "shell.obj", curved, faces)
    text = ('[[cloth]]\nname = "sheet"\ntranslate = [0.0, 0.0, 1.0]\n[cloth.sheet]\nsize = [0.5, 0.5]\n'
            'cells = [2, 2]\n[[cloth]]\nmesh = "shell.obj"\nrest = "mesh"\nrest_bending = "flat"\n')
    first = read_scene_file(_write(tmp_path, text)).scene
    assert first.rest.shape == (9 + len(curved), 3)
    np.testing.assert_array_equal(first.rest[:9, 2], 0.0)  # the sheet's pattern at z = 0
    np.testing.assert_array_equal(first.flat_bending, [False] * 8 + [True] * len(faces))
    ClothSolver(first)  # builds: the sheet keeps its flat rest, the shell its triangles
    _assert_same_scene(first, read_scene_file(tmp_path / "scene.toml").scene)


@pytest.mark.parametrize(("extra", "key", "pattern"), [
    ('rest = "uv"\n', "rest", r'rest = "uv" but .* has no texture coordinates.*Fix: .*rest = "mesh"'),
    ('rest = "plane"\nuv_scale = 2.0\n', "uv_scale", r'uv_scale applies to rest = "uv" only'),
    ('rest = "plane"\nrest_bending = "flat"\n', "rest_bending", r'rest_bending applies to rest = "mesh" only'),
    ('rest = "mesh"\nrest_bending = "flatter"\n', "rest_bending", r"'flatter' is not one of"),
    ('rest = "uv"\nuv_scale = 0.0\n', "uv_scale", r"0"),
])
def test_bad_garment_rest_keys(tmp_path: Path, extra: str, key: str, pattern: str) -> None:
    curved, faces, _ = _curved(3)
    _write_obj(tmp_path / "shell.obj", curved, faces)
    path = _write(tmp_path, '[[cloth]]\nmesh = "shell.obj"\n' + extra)
    with pytest.raises(InputError) as info:
        load_scene_file(path)
    assert str(info.value).startswith(f"{path}: cloth[0].{key}: "), str(info.value)
    assert re.search(pattern, str(info.value), re.S), str(info.value)


def test_sheet_refuses_mesh_rest_keys(tmp_path: Path) -> None:
    for key, value in (("uv_scale", "2.0"), ("rest_bending", '"flat"')):
        path = _write(tmp_path, f'[[cloth]]\n{key} = {value}\n[cloth.sheet]\nsize = [1.0, 1.0]\ncells = [2, 2]\n')
        with pytest.raises(InputError, match=rf"cloth\[0\]\.{key}: {key} applies to mesh pieces only"):
            load_scene_file(path)


def test_curved_mesh_without_uv_or_rest_names_every_way_out(tmp_path: Path) -> None:
    curved, faces, _ = _curved(3)
    _write_obj(tmp_path / "shell.obj", curved, faces)
    path = _write(tmp_path, '[[cloth]]\nmesh = "shell.obj"\n')
    with pytest.raises(InputError) as info:
        load_scene_file(path)
    assert all(word in info.value.fix for word in ('rest = "mesh"', 'rest = "uv"', 'rest = "plane"'))


def test_uv_seam_through_a_vertex_is_named_when_the_uv_is_the_rest(tmp_path: Path) -> None:
    curved, faces, pattern = _curved(3)
    path = _write_uv_obj(tmp_path / "seam.obj", curved, faces, pattern)
    # Corner 1 of the first face takes another vertex's vt: one vertex, two (u, v).
    lines = path.read_text().splitlines()
    first_face = next(k for k, line in enumerate(lines) if line.startswith("f "))
    corners = lines[first_face].split()
    corners[1] = corners[1].split("/")[0] + "/" + corners[2].split("/")[1]
    lines[first_face] = " ".join(corners)
    path.write_text("\n".join(lines) + "\n")
    scene_path = _write(tmp_path, '[[cloth]]\nmesh = "seam.obj"\nrest = "uv"\n')
    with pytest.raises(InputError) as info:
        load_scene_file(scene_path)
    message = str(info.value)
    assert message.startswith(f"{scene_path}: cloth[0].rest: "), message
    assert "vertex 1 has texture coordinates" in message and f"in the face at line {first_face + 1}" in message
    assert "two different (u, v)" in message
    assert "stitches" in info.value.fix and 'rest = "mesh"' in info.value.fix
    # auto on that curved mesh: refused, saying why the uv could not serve.
    with pytest.raises(InputError, match=r"texture coordinates cannot be: line"):
        load_scene_file(_write(tmp_path, '[[cloth]]\nmesh = "seam.obj"\n'))
