"""Animated bodies from one file: an NPZ array of frames or a USD mesh with time-sampled points, and the
``sequence_frame_rate`` of a sequence whose frame rate differs from the scene's (issue 13)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from pscc.errors import InputError
from pscc.mesh.animation import load_animation
from pscc.mesh.generate import grid_sheet
from pscc.scenes.scene_file import SequenceObstacle, load_scene_file, read_scene_file
from tests.scenes.test_scene_file import SHEET, _round_trip, _sequence_files, _write


def _frames() -> tuple[np.ndarray, np.ndarray]:
    local, faces, _ = grid_sheet(2, 2, 0.4, 0.4)
    frames = np.stack([local.astype(np.float64) + [0.0, 0.0, 0.1 * k] for k in range(4)])
    frames[3, :, :2] *= 1.5  # non-rigid
    return frames, faces


def _write_usd(path: Path, frames: np.ndarray, faces: np.ndarray, *, codes_per_second: float = 24.0,
               step: float = 1.0, meters_per_unit: float = 1.0, offset: tuple[float, float, float] = (0, 0, 0),
               quads: bool = False) -> Path:
    from pxr import Gf, Sdf, Usd, UsdGeom, Vt

    stage = Usd.Stage.CreateNew(str(path))
    stage.SetTimeCodesPerSecond(codes_per_second)
    UsdGeom.SetStageMetersPerUnit(stage, meters_per_unit)
    UsdGeom.Xform.Define(stage, "/World")
    UsdGeom.Mesh.Define(stage, "/World/Floor")  # a static mesh before the body: not animated
    floor = UsdGeom.Mesh(stage.GetPrimAtPath("/World/Floor"))
    floor.CreatePointsAttr(Vt.Vec3fArray([Gf.Vec3f(0, 0, 0), Gf.Vec3f(1, 0, 0), Gf.Vec3f(0, 1, 0)]))
    floor.CreateFaceVertexCountsAttr(Vt.IntArray([3]))
    floor.CreateFaceVertexIndicesAttr(Vt.IntArray([0, 1, 2]))
    body = UsdGeom.Mesh.Define(stage, "/World/Body")
    UsdGeom.XformCommonAPI(body).SetTranslate(Gf.Vec3d(*offset))
    counts = [4] * (len(faces) // 2) if quads else [3] * len(faces)
    body.CreateFaceVertexCountsAttr(Vt.IntArray(counts))
    body.CreateFaceVertexIndicesAttr(Vt.IntArray(np.asarray(faces).reshape(-1).tolist()[:sum(counts)]))
    points = body.CreatePointsAttr()
    for k, frame in enumerate(frames):
        points.Set(Vt.Vec3fArray([Gf.Vec3f(*map(float, p)) for p in frame]), Usd.TimeCode(10.0 + k * step))
    stage.GetRootLayer().Save()
    assert Sdf.Layer.FindOrOpen(str(path)) is not None
    return path


def test_npz_animation_plays_as_a_body(tmp_path: Path) -> None:
    frames, faces = _frames()
    np.savez(tmp_path / "body.npz", frames=frames, faces=faces, frame_rate=20.0)
    text = SHEET + '[[obstacle]]\nname = "body"\nsequence = "body.npz"\ntranslate = [0.0, 0.0, -0.5]\n'
    loaded = read_scene_file(_write(tmp_path, text))
    (body,) = loaded.scene.obstacles
    assert isinstance(body, SequenceObstacle)
    np.testing.assert_allclose(body.times, [0.0, 0.05, 0.1, 0.15])  # the file's 20 frames per second
    np.testing.assert_allclose(body.positions(0.125), 0.5 * (frames[2] + frames[3]) + [0, 0, -0.5], atol=1e-6)
    assert loaded.spec["obstacle"][0]["sequence"] == str(tmp_path / "body.npz")
    assert loaded.spec["obstacle"][0]["sequence_frame_rate"] == 20.0
    _round_trip(tmp_path / "scene.toml", tmp_path)
    # The scene's key overrides the file's rate.
    body = load_scene_file(_write(tmp_path, text + "sequence_frame_rate = 40.0\n"))[0].obstacles[0]
    np.testing.assert_allclose(body.times, [0.0, 0.025, 0.05, 0.075])


def test_usd_animation_with_transform_units_and_rate(tmp_path: Path) -> None:
    frames, faces = _frames()
    _write_usd(tmp_path / "body.usda", frames * 100.0, faces, codes_per_second=24.0, step=2.0,
               meters_per_unit=0.01, offset=(0.0, 0.0, 50.0))  # centimetres, one sample every 2 codes: 12 fps
    animation = load_animation(tmp_path / "body.usda")
    assert animation.frame_rate == pytest.approx(12.0)
    np.testing.assert_allclose(animation.frames, frames + [0.0, 0.0, 0.5], atol=1e-6)
    np.testing.assert_array_equal(animation.faces, faces)
    text = SHEET + '[[obstacle]]\nname = "body"\nsequence = "body.usda"\n'
    loaded = read_scene_file(_write(tmp_path, text))
    np.testing.assert_allclose(loaded.scene.obstacles[0].times, np.arange(4) / 12.0)
    _round_trip(tmp_path / "scene.toml", tmp_path)
    # The prim by path; a frame rate for a file sequence of per-frame meshes.
    assert load_animation(tmp_path / "body.usda", "/World/Body").frames.shape == (4, 9, 3)
    _sequence_files(tmp_path)
    body = load_scene_file(_write(tmp_path, SHEET + '[[obstacle]]\nsequence = "body/frame_*.obj"\n'
                                  'sequence_frame_rate = 5.0\n'))[0].obstacles[0]
    np.testing.assert_allclose(body.times, [0.0, 0.2, 0.4])


def test_bad_animations_name_the_file_and_the_fix(tmp_path: Path) -> None:
    frames, faces = _frames()
    _write_usd(tmp_path / "quads.usda", frames, faces, quads=True)
    with pytest.raises(InputError, match=r"obstacle\[0\]\.sequence: .*quads\.usda.*/World/Body.*triangles.*Fix: "
                                         r"triangulate"):
        load_scene_file(_write(tmp_path, SHEET + '[[obstacle]]\nsequence = "quads.usda"\n'))
    with pytest.raises(InputError, match=r"obstacle\[0\]\.sequence: .*prim.*'/World/Nope' is not a mesh prim"):
        load_scene_file(_write(tmp_path, SHEET + '[[obstacle]]\nsequence = "quads.usda"\n'
                               'sequence_prim = "/World/Nope"\n'))
    np.savez(tmp_path / "flat.npz", frames=frames[0], faces=faces)
    with pytest.raises(InputError, match=r"frames: shape \(9, 3\) is not \(k, n, 3\)"):
        load_scene_file(_write(tmp_path, SHEET + '[[obstacle]]\nsequence = "flat.npz"\n'))
    with pytest.raises(InputError, match=r"obstacle\[0\]\.sequence_frame_rate: sequence_frame_rate applies to "
                                         r"sequence obstacles only"):
        load_scene_file(_write(tmp_path, SHEET + '[[obstacle]]\nsphere = { radius = 0.1 }\n'
                               'sequence_frame_rate = 10.0\n'))
    (tmp_path / "broken.usda").write_text("#usda 1.0\n{{{ not a layer")
    with pytest.raises(InputError, match=r"broken\.usda: file: cannot be opened as a USD stage \(.+\)\. Fix: "
                                         r"export the body"):
        load_animation(tmp_path / "broken.usda")
    np.savez(tmp_path / "body.npz", frames=frames, faces=faces)
    with pytest.raises(InputError, match=r"obstacle\[0\]\.sequence_frame_rate: "):
        load_scene_file(_write(tmp_path, SHEET + '[[obstacle]]\nsequence = "body.npz"\nsequence_frame_rate = 0\n'))
