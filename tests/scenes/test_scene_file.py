"""Scene files (TOML): the example loads into the expected scene, every cloth / obstacle kind builds,
the resolved file round-trips, sequences interpolate and bad files say which key is wrong and how to fix it."""

from __future__ import annotations

import dataclasses
import math
import re
import tomllib
from pathlib import Path

import numpy as np
import pytest

from pscc.errors import InputError
from pscc.mesh.generate import grid_sheet
from pscc.scenes.scene_file import (
    PivotedMotion,
    SequenceObstacle,
    load_scene_file,
    read_scene_file,
    resolved_scene_toml,
)
from pscc.sim.config import ClothMaterial, SolverConfig
from pscc.sim.contact_config import ContactConfig
from pscc.sim.obstacles import KeyframedMotion, Obstacle, rotation_from_axis_angle
from pscc.sim.scene import Scene

EXAMPLE = Path(__file__).resolve().parents[2] / "examples" / "drape.toml"

SHEET = """
[[cloth]]
name = "sheet"
[cloth.sheet]
size = [1.0, 0.5]
cells = [4, 2]
"""


def _write(directory: Path, text: str, name: str = "scene.toml") -> Path:
    path = directory / name
    path.write_text(text)
    return path


def _write_obj(path: Path, vertices: np.ndarray, faces: np.ndarray) -> Path:
    lines = [f"v {x!r} {y!r} {z!r}" for x, y, z in np.asarray(vertices, dtype=np.float64).tolist()]
    lines += [f"f {a + 1} {b + 1} {c + 1}" for a, b, c in faces]
    path.write_text("\n".join(lines) + "\n")
    return path


def _edge_lengths(points: np.ndarray, faces: np.ndarray) -> np.ndarray:
    edges = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    return np.linalg.norm(points[edges[:, 0]] - points[edges[:, 1]], axis=1)


def _assert_same_scene(a: Scene, b: Scene) -> None:
    assert (a.name, a.description, a.frame_time, a.steps_per_frame) == (b.name, b.description, b.frame_time,
                                                                         b.steps_per_frame)
    for name in ("vertices", "faces", "rest", "object_ids"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name), err_msg=name)
    assert (a.flat_bending is None) == (b.flat_bending is None)
    if a.flat_bending is not None:
        np.testing.assert_array_equal(a.flat_bending, b.flat_bending)
    assert a.material == b.material and a.solver == b.solver
    assert [h.name for h in a.handles] == [h.name for h in b.handles]
    times = (0.0, 0.013, 0.5, 1.7, 10.0)
    for ha, hb in zip(a.handles, b.handles, strict=True):
        np.testing.assert_array_equal(ha.vertices, hb.vertices)
        for t in times:
            for x, y in zip(ha.transform(t), hb.transform(t), strict=True):
                np.testing.assert_array_equal(x, y)
    assert [o.name for o in a.obstacles] == [o.name for o in b.obstacles]
    for oa, ob in zip(a.obstacles, b.obstacles, strict=True):
        assert type(oa) is type(ob)
        np.testing.assert_array_equal(oa.faces, ob.faces)
        for t in times:
            np.testing.assert_array_equal(oa.positions(t), ob.positions(t))


# --------------------------------------------------------------------------------------------
# The example
# --------------------------------------------------------------------------------------------


def test_example_loads_into_the_expected_scene() -> None:
    scene, contact, options = load_scene_file(EXAMPLE)
    assert scene.name == "drape-file" and "sphere" in scene.description
    assert options == {"frames": 60, "source": str(EXAMPLE)}
    assert scene.frame_time == pytest.approx(1.0 / 30.0) and scene.steps_per_frame == 8
    assert contact == ContactConfig(method="pscc")
    assert scene.solver == SolverConfig(gravity=(0.0, 0.0, -9.81), air_drag=0.05)

    # Two pieces: a 24 x 24 generated sheet and the 10 x 10 OBJ square, one object id and material each.
    assert scene.vertices.shape == (625 + 121, 3) and scene.faces.shape == (1152 + 200, 3)
    assert scene.vertices.dtype == np.float32 and scene.faces.dtype == np.int32 and scene.rest.dtype == np.float32
    np.testing.assert_array_equal(np.bincount(scene.object_ids), [1152, 200])
    assert scene.faces[:1152].max() < 625 <= scene.faces[1152:].min()
    assert isinstance(scene.material, list) and len(scene.material) == 2
    assert scene.material[0] == ClothMaterial(density=0.187, bending=5e-5, friction=0.3)
    assert scene.material[1].density == 0.08 and scene.material[1].bending == 1e-5
    cotton = scene.vertices[:625]
    np.testing.assert_allclose(cotton.astype(np.float64).mean(axis=0), [0.05, 0.0, 0.33], atol=1e-6)
    np.testing.assert_allclose(np.ptp(cotton, axis=0), [0.9, 0.9, 0.0], atol=1e-6)
    # Rest shapes are isometric to the flat initial positions (the silk is rotated by 15 degrees).
    for lo, hi in ((0, 625), (625, 746)):
        piece_faces = scene.faces[(scene.faces >= lo).all(axis=1) & (scene.faces < hi).all(axis=1)]
        np.testing.assert_allclose(_edge_lengths(scene.rest, piece_faces),
                                   _edge_lengths(scene.vertices, piece_faces), atol=1e-6)

    # The pin: the silk's top-left corner (largest v, smallest u), a static handle.
    (pins,) = scene.handles
    assert pins.name == "silk.pins"
    np.testing.assert_array_equal(pins.vertices, [625 + 110])
    rotation, translation = pins.transform(1.0)
    np.testing.assert_array_equal(rotation, np.eye(3))
    np.testing.assert_array_equal(translation, np.zeros(3))

    # The keyframed sphere: rises 5 cm and turns 30 degrees about its centre over 2 s.
    (sphere,) = scene.obstacles
    assert isinstance(sphere, Obstacle) and isinstance(sphere.motion, KeyframedMotion)
    assert sphere.name == "sphere" and sphere.faces.shape == (320, 3)
    start, end = sphere.positions(0.0).astype(np.float64), sphere.positions(2.0).astype(np.float64)
    np.testing.assert_allclose(np.linalg.norm(start, axis=1), 0.25, rtol=1e-6)
    np.testing.assert_allclose(end.mean(axis=0) - start.mean(axis=0), [0.0, 0.0, 0.05], atol=1e-6)
    turn = rotation_from_axis_angle(np.radians([0.0, 0.0, 30.0]))
    np.testing.assert_allclose(end, start @ turn.T + [0.0, 0.0, 0.05], atol=1e-6)


def test_example_builds_a_solver_and_steps_one_frame() -> None:
    from pscc.sim.simulation import Simulation
    from pscc.sim.solver import ClothSolver

    scene, contact, _ = load_scene_file(EXAMPLE)
    simulation = Simulation(scene, device="cpu", contact=contact)
    assert isinstance(simulation.solver, ClothSolver)
    assert simulation.solver.model.vertex_count == scene.vertices.shape[0] + scene.obstacles[0].vertices.shape[0]
    record = simulation.step_frame()
    assert record["steps"] == scene.steps_per_frame
    assert simulation.time == pytest.approx(scene.frame_time)
    positions = simulation.state.positions.numpy()
    assert np.all(np.isfinite(positions))
    np.testing.assert_array_equal(positions[scene.handles[0].vertices], scene.vertices[scene.handles[0].vertices])
    assert positions[:625, 2].max() < 0.33  # the cotton fell


# --------------------------------------------------------------------------------------------
# Cloth pieces
# --------------------------------------------------------------------------------------------


def test_generated_sheet_placement_scale_and_rest(tmp_path: Path) -> None:
    text = """
[[cloth]]
translate = [1.0, 2.0, 3.0]
rotate = [90.0, 0.0, 0.0]
scale = 2.0
[cloth.sheet]
size = [1.0, 0.5]
cells = [4, 2]
"""
    scene, _, options = load_scene_file(_write(tmp_path, text))
    assert scene.name == "scene" and options["frames"] == 30 and scene.steps_per_frame == 8
    local, faces, rest = grid_sheet(4, 2, 1.0, 0.5)
    centred = local.astype(np.float64) - [0.5, 0.25, 0.0]
    rotation = rotation_from_axis_angle(np.radians([90.0, 0.0, 0.0]))
    np.testing.assert_allclose(scene.vertices, (2.0 * centred) @ rotation.T + [1.0, 2.0, 3.0], atol=1e-6)
    np.testing.assert_array_equal(scene.faces, faces)
    np.testing.assert_allclose(scene.rest, 2.0 * rest, atol=1e-7)
    np.testing.assert_allclose(np.ptp(scene.vertices, axis=0), [2.0, 0.0, 1.0], atol=1e-6)  # hangs in the xz plane
    assert scene.material == [ClothMaterial()] and scene.handles == [] and scene.obstacles == []


def test_flat_obj_cloth_gets_its_in_plane_rest_shape(tmp_path: Path) -> None:
    local, faces, _ = grid_sheet(3, 3, 0.3, 0.3)
    tilt = rotation_from_axis_angle(np.radians([20.0, -35.0, 10.0]))
    _write_obj(tmp_path / "tilted.obj", local.astype(np.float64) @ tilt.T + [0.1, 0.2, 0.3], faces)
    text = '[[cloth]]\nmesh = "tilted.obj"\nscale = 0.5\n'
    loaded = read_scene_file(_write(tmp_path, text))
    scene = loaded.scene
    assert loaded.spec["cloth"][0]["rest"] == "plane"
    assert loaded.spec["cloth"][0]["mesh"] == str(tmp_path / "tilted.obj")
    np.testing.assert_allclose(_edge_lengths(scene.rest, faces), 0.5 * _edge_lengths(local, faces), atol=1e-6)


def test_npz_cloth_uses_its_rest_coordinates(tmp_path: Path) -> None:
    local, faces, rest = grid_sheet(4, 4, 1.0, 1.0)
    curved = local.copy()
    curved[:, 2] = 0.2 * np.sin(np.pi * local[:, 0])  # not flat: the rest must come from the file
    np.savez(tmp_path / "curved.npz", vertices=curved, faces=faces, rest=rest)
    text = '[[cloth]]\nmesh = "curved.npz"\nscale = 2.0\npins = { side = "left" }\n'
    loaded = read_scene_file(_write(tmp_path, text))
    assert loaded.spec["cloth"][0]["rest"] == "file"
    np.testing.assert_allclose(loaded.scene.rest, 2.0 * rest, atol=1e-7)
    np.testing.assert_allclose(loaded.scene.vertices, 2.0 * curved, atol=1e-6)
    np.testing.assert_array_equal(loaded.scene.handles[0].vertices, [0, 5, 10, 15, 20])


def test_curved_mesh_without_rest_is_refused_unless_projected(tmp_path: Path) -> None:
    local, faces, _ = grid_sheet(4, 4, 1.0, 1.0)
    local[:, 2] = 0.2 * np.sin(np.pi * local[:, 0])
    _write_obj(tmp_path / "curved.obj", local, faces)
    path = _write(tmp_path, '[[cloth]]\nmesh = "curved.obj"\n')
    with pytest.raises(InputError, match=r"cloth\[0\]\.rest: .*not flat.*Fix: .*rest = \"plane\""):
        load_scene_file(path)
    scene, _, _ = load_scene_file(_write(tmp_path, '[[cloth]]\nmesh = "curved.obj"\nrest = "plane"\n'))
    np.testing.assert_allclose(scene.rest, local[:, :2] - local[:, :2].mean(axis=0), atol=1e-6)


def _rest_cases(directory: Path) -> dict[str, tuple[str, str]]:
    """Scene texts whose rest shape has a zero-area triangle, and a word each message must hold."""
    local, faces, rest = grid_sheet(4, 4, 1.0, 1.0)
    tube = local.astype(np.float64)
    angle = 1.9 * np.pi * local[:, 0]  # rolled almost all the way round: the projection folds it flat
    tube[:, 0], tube[:, 2] = np.cos(angle), np.sin(angle)
    np.savez(directory / "tube.npz", vertices=tube, faces=faces)
    collapsed = rest.copy()
    collapsed[:, 1] = 0.0  # every rest triangle collinear
    np.savez(directory / "collapsed.npz", vertices=local, faces=faces, rest=collapsed)
    sliver = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [2, 0, 0]], dtype=np.float64)
    _write_obj(directory / "sliver.obj", sliver, np.array([[0, 1, 2], [0, 1, 3]]))  # face 1 has zero area
    return {
        "plane on a curved mesh": ('[[cloth]]\nmesh = "tube.npz"\nrest = "plane"\n', "too curved"),
        "degenerate rest in the file": ('[[cloth]]\nmesh = "collapsed.npz"\nrest = "file"\n', "rest coordinates"),
        "auto on a zero-area face": ('[[cloth]]\nmesh = "sliver.obj"\n', "zero area in the mesh itself"),
    }


@pytest.mark.parametrize("case", ["plane on a curved mesh", "degenerate rest in the file", "auto on a zero-area face"])
def test_zero_area_rest_triangles_name_the_scene_file_and_key(tmp_path: Path, case: str) -> None:
    """Used to surface only when the solver was built, as 'argument: rest: ...'."""
    text, word = _rest_cases(tmp_path)[case]
    path = _write(tmp_path, text)
    with pytest.raises(InputError) as info:
        load_scene_file(path)
    error = info.value
    assert (error.source, error.field) == (str(path), "cloth[0].rest"), str(error)
    assert str(error).startswith(f"{path}: cloth[0].rest: ") and "argument" not in str(error)
    assert word in error.problem and "zero area" in error.problem and error.fix, str(error)


def test_bad_rest_values_name_the_scene_file_and_key(tmp_path: Path) -> None:
    local, faces, _ = grid_sheet(2, 2, 1.0, 1.0)
    np.savez(tmp_path / "flat.npz", vertices=local, faces=faces)
    for value, pattern in (('"plan"', r"'plan' is not one of.*did you mean 'plane'"),
                           ("3", r"expected a string, got integer 3"),
                           ('"file"', r'rest = "file" but .*flat\.npz.* has no rest coordinates')):
        path = _write(tmp_path, f'[[cloth]]\nmesh = "flat.npz"\nrest = {value}\n')
        with pytest.raises(InputError) as info:
            load_scene_file(path)
        assert str(info.value).startswith(f"{path}: cloth[0].rest: "), str(info.value)
        assert re.search(pattern, str(info.value)), str(info.value)


def test_vertex_selectors(tmp_path: Path) -> None:
    # 4 x 2 cells: vertex j * 5 + i at (i / 4, j / 4) before centring; rest = those coordinates.
    text = SHEET.replace("[cloth.sheet]", 'pins = [3, { side = ["top", "left"] }, { corner = "bottom-right" }, '
                         '{ box = [[-0.01, -0.3, -1.0], [0.01, 0.3, 1.0]] }]\n[cloth.sheet]')
    scene, _, _ = load_scene_file(_write(tmp_path, text))
    top, left, corner, middle_column = [10, 11, 12, 13, 14], [0, 5, 10], [4], [2, 7, 12]
    np.testing.assert_array_equal(scene.handles[0].vertices, sorted({3, *top, *left, *corner, *middle_column}))


def test_handle_rotates_about_its_pivot(tmp_path: Path) -> None:
    text = SHEET + """
[[cloth.handles]]
name = "right end"
vertices = { side = "right" }
times = [0.0, 1.0]
translations = [[0.0, 0.0, 0.0], [0.0, 0.0, 0.2]]
rotations = [[0.0, 0.0, 0.0], [90.0, 0.0, 0.0]]

[[cloth.handles]]
vertices = [0]
times = [0.5]
pivot = [0.0, 0.0, 0.0]
"""
    loaded = read_scene_file(_write(tmp_path, text))
    right, fixed = loaded.scene.handles
    assert right.name == "right end" and fixed.name == "sheet.handles[1]"
    np.testing.assert_array_equal(right.vertices, [4, 9, 14])
    assert isinstance(right.motion, PivotedMotion)
    pivot = loaded.scene.vertices[[4, 9, 14]].astype(np.float64).mean(axis=0)
    np.testing.assert_allclose(loaded.spec["cloth"][0]["handles"][0]["pivot"], pivot)
    rotation, translation = right.transform(1.0)
    moved = loaded.scene.vertices[[4, 9, 14]] @ rotation.T + translation
    turn = rotation_from_axis_angle(np.radians([90.0, 0.0, 0.0]))
    np.testing.assert_allclose(moved, (loaded.scene.vertices[[4, 9, 14]] - pivot) @ turn.T + pivot + [0, 0, 0.2],
                               atol=1e-6)
    np.testing.assert_allclose(moved.mean(axis=0), pivot + [0.0, 0.0, 0.2], atol=1e-6)  # turns about its centre
    assert loaded.spec["cloth"][0]["handles"][1]["translations"] == [[0.0, 0.0, 0.0]]


def test_obstacle_primitives_meshes_and_keyframes(tmp_path: Path) -> None:
    ball, ball_faces, _ = grid_sheet(2, 2, 0.2, 0.2)
    _write_obj(tmp_path / "plate.obj", ball, ball_faces)
    text = SHEET.replace('name = "sheet"', 'name = "sheet"\ntranslate = [0.0, 0.0, 1.0]') + """
[[obstacle]]
name = "ground"
box = { size = [2.0, 1.0, 0.1] }
translate = [0.0, 0.0, -0.05]

[[obstacle]]
mesh = "plate.obj"
translate = [0.0, 0.0, 0.5]
keyframes = { times = [0.0, 1.0], rotations = [[0.0, 0.0, 0.0], [0.0, 0.0, 180.0]] }
"""
    scene, _, _ = load_scene_file(_write(tmp_path, text))
    ground, plate = scene.obstacles
    assert plate.name == "obstacle1"
    box = ground.positions(0.0).astype(np.float64)
    np.testing.assert_allclose(box.min(axis=0), [-1.0, -0.5, -0.1], atol=1e-7)
    np.testing.assert_allclose(box.max(axis=0), [1.0, 0.5, 0.0], atol=1e-7)
    a, b, c = (box[ground.faces[:, k]] for k in range(3))
    volume = np.einsum("ij,ij->i", a, np.cross(b, c)).sum() / 6.0  # outward faces: positive volume
    assert volume == pytest.approx(2.0 * 1.0 * 0.1)
    np.testing.assert_allclose(plate.positions(0.0), ball + [0.0, 0.0, 0.5], atol=1e-6)
    np.testing.assert_allclose(plate.positions(1.0), ball * [-1.0, -1.0, 1.0] + [0.0, 0.0, 0.5], atol=1e-6)


# --------------------------------------------------------------------------------------------
# Sequences
# --------------------------------------------------------------------------------------------


def _sequence_files(directory: Path) -> tuple[np.ndarray, list[np.ndarray]]:
    local, faces, _ = grid_sheet(2, 2, 0.4, 0.4)
    frames = [local.astype(np.float64) + [0.0, 0.0, 0.1 * k] for k in range(3)]
    frames[2][:, :2] *= 1.5  # non-rigid: the last frame is stretched
    (directory / "body").mkdir()
    for k, name in enumerate(("frame_8.obj", "frame_9.obj", "frame_10.obj")):  # natural order, not lexical
        _write_obj(directory / "body" / name, frames[k], faces)
    return faces, frames


def test_sequence_obstacle_interpolates_between_frames(tmp_path: Path) -> None:
    faces, frames = _sequence_files(tmp_path)
    text = ('[scene]\nframe_rate = 10\n' + SHEET.replace('name = "sheet"', 'name = "sheet"\ntranslate = [0, 0, 1]')
            + '[[obstacle]]\nname = "body"\nsequence = "body/frame_*.obj"\ntranslate = [0.0, 0.0, -0.5]\n')
    loaded = read_scene_file(_write(tmp_path, text))
    (body,) = loaded.scene.obstacles
    assert isinstance(body, SequenceObstacle) and not body.rigid and body.name == "body"
    assert loaded.spec["obstacle"][0]["sequence"] == [str(tmp_path / "body" / f"frame_{k}.obj") for k in (8, 9, 10)]
    np.testing.assert_array_equal(body.faces, faces)
    np.testing.assert_allclose(body.times, [0.0, 0.1, 0.2])
    placed = [f + [0.0, 0.0, -0.5] for f in frames]
    np.testing.assert_allclose(body.positions(0.0), placed[0], atol=1e-6)
    np.testing.assert_allclose(body.positions(0.05), 0.5 * (placed[0] + placed[1]), atol=1e-6)
    np.testing.assert_allclose(body.positions(0.175), 0.25 * placed[1] + 0.75 * placed[2], atol=1e-6)
    np.testing.assert_allclose(body.positions(-1.0), placed[0], atol=1e-6)
    np.testing.assert_allclose(body.positions(5.0), placed[2], atol=1e-6)
    assert body.positions(0.05).dtype == np.float32
    with pytest.raises(Exception, match="non-rigid"):
        body.transform(0.0)


def test_sequence_with_a_different_topology_is_refused(tmp_path: Path) -> None:
    _sequence_files(tmp_path)
    other, other_faces, _ = grid_sheet(3, 2, 0.4, 0.4)
    _write_obj(tmp_path / "body" / "frame_9.obj", other, other_faces)
    text = SHEET + '[[obstacle]]\nsequence = "body/frame_*.obj"\n'
    with pytest.raises(InputError, match=r"obstacle\[0\]\.sequence: .*frame_9\.obj.*topology.*Fix: export every"):
        load_scene_file(_write(tmp_path, text))


# --------------------------------------------------------------------------------------------
# Resolved scene files
# --------------------------------------------------------------------------------------------


def _round_trip(source: Path, directory: Path) -> None:
    first = read_scene_file(source)
    text = resolved_scene_toml(first)
    resolved = directory / "out" / "scene.toml"  # another folder: the paths must be absolute
    resolved.parent.mkdir(exist_ok=True)
    resolved.write_text(text)
    second = read_scene_file(resolved)
    _assert_same_scene(first.scene, second.scene)
    assert first.contact == second.contact
    assert second.options == {**first.options, "source": str(resolved)}
    assert second.spec == first.spec == tomllib.loads(text)
    assert resolved_scene_toml(second).split("\n", 1)[1] == text.split("\n", 1)[1]  # only the origin differs


def test_resolved_example_round_trips(tmp_path: Path) -> None:
    _round_trip(EXAMPLE, tmp_path)


def test_resolved_file_round_trips_every_kind(tmp_path: Path) -> None:
    _sequence_files(tmp_path)
    local, faces, rest = grid_sheet(3, 3, 0.3, 0.3)
    np.savez(tmp_path / "patch.npz", vertices=local, faces=faces, rest=rest)
    text = """
[scene]
name = "every kind"
description = "quotes \\" and unicode \u00e9"
frame_time = 0.04
steps_per_frame = 3
[solver]
contact_stiffness = 2000
wind = [1, 0, 0]
[contact]
method = "brute-force"
projection_rounds = 2
""" + SHEET.replace("[cloth.sheet]", 'translate = [0.0, 0.0, 1.0]\nrotate = [10.0, 20.0, 30.0]\n'
                    'pins = { corner = ["top-left", "top-right"] }\n[cloth.sheet]') + """
[[cloth.handles]]
vertices = { box = [[-1, -1, -1], [0.0, 0.0, 1.0]] }
times = [0.0, 0.5, 1.0]
rotations = [[0, 0, 0], [0, 45, 0], [0, 90, 0]]

[[cloth]]
mesh = "patch.npz"
translate = [0.0, 0.0, 1.5]
[cloth.material]
density = 0.1
thickness = 0.003

[[obstacle]]
sphere = { radius = 0.1 }
keyframes = { times = [0.0, 1.0], translations = [[0, 0, 0], [0.1, 0, 0]] }
[[obstacle]]
sequence = "body/frame_*.obj"
scale = 0.5
"""
    _round_trip(_write(tmp_path, text), tmp_path)
    spec = read_scene_file(tmp_path / "scene.toml").spec
    assert spec["solver"]["contact_stiffness"] == 2000.0 and spec["scene"]["frame_time"] == 0.04


def test_resolved_file_records_overrides(tmp_path: Path) -> None:
    text = resolved_scene_toml(EXAMPLE, frames=5, contact=ContactConfig(method="spatial-hash"))
    path = _write(tmp_path, text)
    _, contact, options = load_scene_file(path)
    assert options["frames"] == 5 and contact == ContactConfig(method="spatial-hash")
    with pytest.raises(InputError, match="frames"):
        resolved_scene_toml(EXAMPLE, frames=0)


# --------------------------------------------------------------------------------------------
# Bad files
# --------------------------------------------------------------------------------------------

BAD_FILES: dict[str, tuple[str, str, str]] = {
    # case: (file text, key path the error names, a regex the message must match)
    "unknown key with suggestion": ("[scene]\nframe_rat = 30\n" + SHEET, "scene.frame_rat",
                                    r"unknown key 'frame_rat'.*Fix: did you mean 'frame_rate'"),
    "unknown top-level table": ("[solvr]\ngravity = [0, 0, -1]\n" + SHEET, "solvr", r"did you mean 'solver'"),
    "renamed contact key": ("[contact]\nimpulse_rounds = 3\n" + SHEET, "contact.impulse_rounds",
                            r"replaced by 'projection_rounds'"),
    "unknown material key": (SHEET + "[cloth.material]\ndensty = 0.2\n", "cloth[0].material.densty",
                             r"did you mean 'density'"),
    "material key on the piece": (SHEET.replace("[cloth.sheet]", "density = 0.2\n[cloth.sheet]"),
                                  "cloth[0].density", r"Fix: put density in .*cloth\[0\]\.material\.density"),
    "wrong type": ("[scene]\nsteps_per_frame = \"8\"\n" + SHEET, "scene.steps_per_frame",
                   r"expected an integer, got string '8'.*Fix: write a whole number"),
    "float where an integer is needed": (SHEET.replace("cells = [4, 2]", "cells = [4.0, 2]"),
                                         "cloth[0].sheet.cells[0]", r"expected an integer, got float"),
    "negative density": (SHEET + SHEET.replace('"sheet"', '"second"') + "[cloth.material]\ndensity = -0.1\n",
                         "cloth[1].material.density", r"-0\.1 is not > 0.*Fix: set density to a value > 0"),
    "non-convex membrane": (SHEET + "[cloth.material]\nstretch_uv = 5000.0\n", "cloth[0].material.stretch_uv",
                            r"not convex"),
    "missing mesh file": ('[[cloth]]\nmesh = "nowhere/cloth.obj"\n', "cloth[0].mesh",
                          r"nowhere/cloth\.obj' does not exist.*Fix: check the path"),
    "unsupported mesh extension": ('[[cloth]]\nmesh = "cloth.stl"\n', "cloth[0].mesh", r"\.stl.*Fix: use a mesh"),
    "pin id out of range": (SHEET.replace("[cloth.sheet]", "pins = [0, 15]\n[cloth.sheet]"), "cloth[0].pins[1]",
                            r"vertex id 15 is out of range: the piece has 15 vertices.*Fix: use 0-based ids in "
                            r"\[0, 14\]"),
    "bad side name": (SHEET.replace("[cloth.sheet]", 'pins = { side = "tpo" }\n[cloth.sheet]'), "cloth[0].pins.side",
                      r"did you mean 'top'"),
    "empty box selection": (SHEET.replace("[cloth.sheet]", "pins = { box = [[5, 5, 5], [6, 6, 6]] }\n[cloth.sheet]"),
                            "cloth[0].pins.box", r"contains no vertex.*Fix: enlarge or move the box"),
    "vertex in a pin and a handle": (SHEET.replace("[cloth.sheet]", "pins = [0]\n[cloth.sheet]")
                                     + "[[cloth.handles]]\nvertices = [0, 1]\ntimes = [0.0]\n",
                                     "cloth[0].handles[0].vertices", r"vertex 0 is also selected by cloth\[0\]\.pins"),
    "non-increasing keyframe times": (SHEET + "[[obstacle]]\nsphere = { radius = 0.1 }\nkeyframes = { times = "
                                      "[0.0, 1.0, 1.0], translations = [[0, 0, 0], [0, 0, 1], [0, 0, 2]] }\n",
                                      "obstacle[0].keyframes.times", r"times\[2\] = 1 is not greater than times\[1\]"
                                      r".*Fix: list the keyframe times in strictly increasing order"),
    "keyframe rows do not match the times": (SHEET + "[[obstacle]]\nsphere = { radius = 0.1 }\nkeyframes = { "
                                             "times = [0.0, 1.0], translations = [[0, 0, 0]] }\n",
                                             "obstacle[0].keyframes.translations", r"has 1 rows but times has 2"),
    "handle that jumps at the start": (SHEET + "[[cloth.handles]]\nvertices = [0]\ntimes = [0.0, 1.0]\n"
                                       "translations = [[0, 0, 0.1], [0, 0, 0.2]]\n",
                                       "cloth[0].handles[0].translations", r"not the identity.*Fix: handle keyframes "
                                       r"are displacements"),
    "zero frame rate": ("[scene]\nframe_rate = 0\n" + SHEET, "scene.frame_rate", r"0 is not > 0"),
    "infinite frame rate": ("[scene]\nframe_rate = inf\n" + SHEET, "scene.frame_rate", r"is not finite"),
    "frame rate and frame time": ("[scene]\nframe_rate = 30\nframe_time = 0.03\n" + SHEET, "scene.frame_time",
                                  r"both frame_rate and frame_time.*Fix: give only one"),
    "bad solver value": ("[solver]\npreconditioner = \"jacobi\"\n" + SHEET, "solver.preconditioner",
                         r"'jacobi' is not one of"),
    "solver vector of the wrong length": ("[solver]\ngravity = [0, -9.81]\n" + SHEET, "solver.gravity",
                                          r"expected an array of 3 numbers, got 2 entries"),
    "bad contact value": ("[contact]\nseparation_ratio = 0.05\n" + SHEET, "contact.separation_ratio",
                          r"is not in \(ccd_distance_ratio, 1\]"),
    "single cloth table": ('[cloth]\nmesh = "a.obj"\n', "cloth", r"single \[cloth\] table.*Fix: write each piece "
                           r"as \[\[cloth\]\]"),
    "no cloth": ("[scene]\nname = \"x\"\n", "cloth", r"the scene has no cloth"),
    "mesh and sheet": (SHEET.replace("[cloth.sheet]", 'mesh = "a.obj"\n[cloth.sheet]'), "cloth[0]",
                       r"has both mesh and sheet"),
    "two obstacle shapes": (SHEET + "[[obstacle]]\nsphere = { radius = 0.1 }\nbox = { size = [1, 1, 1] }\n",
                            "obstacle[0]", r"has sphere and box.*Fix: give exactly one of"),
    "sequence matches nothing": (SHEET + '[[obstacle]]\nsequence = "missing/frame_*.obj"\n', "obstacle[0].sequence",
                                 r"matches no file"),
    "not TOML": ("[scene\nname = 1\n", "file", r"is not valid TOML.*line 1"),
}


@pytest.mark.parametrize("case", list(BAD_FILES))
def test_bad_files_name_the_key_and_the_fix(tmp_path: Path, case: str) -> None:
    text, key, pattern = BAD_FILES[case]
    path = _write(tmp_path, text)
    with pytest.raises(InputError) as info:
        load_scene_file(path)
    error = info.value
    assert error.source == str(path), str(error)
    assert error.field == key, str(error)
    assert error.fix and "Fix: " in str(error)
    assert str(error).startswith(f"{path}: {key}: ")
    assert len(str(error)) < 600
    assert re.search(pattern, str(error), flags=re.DOTALL), str(error)


def test_missing_scene_file(tmp_path: Path) -> None:
    with pytest.raises(InputError, match=r"missing\.toml: path: file does not exist"):
        load_scene_file(tmp_path / "missing.toml")


def test_every_config_field_is_accepted(tmp_path: Path) -> None:
    """Each SolverConfig / ContactConfig / ClothMaterial field can be set (the format follows the dataclasses)."""
    spec = read_scene_file(EXAMPLE).spec
    assert list(spec["solver"]) == [f for f in SolverConfig.__dataclass_fields__]
    assert list(spec["contact"]) == [f.name for f in dataclasses.fields(ContactConfig)]
    assert list(spec["cloth"][0]["material"]) == [f for f in ClothMaterial.__dataclass_fields__]
    text = SHEET + "[cloth.material]\n" + "".join(f"{f} = 0.01\n" for f in ClothMaterial.__dataclass_fields__)
    scene, _, _ = load_scene_file(_write(tmp_path, text))
    assert all(math.isclose(getattr(scene.material[0], f), 0.01) for f in ClothMaterial.__dataclass_fields__)
