"""Your own frames in the corpus comparison: reading OBJ, NPZ, corpus NPZ and USD files, the errors, and
``python -m pscc.bench --frames`` end to end."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from pscc.bench import corpus_bench, user_frames
from pscc.bench.__main__ import main
from pscc.bench.corpus import CorpusFrame, half_median_edge
from pscc.errors import InputError
from pscc.mesh import folded_sheet


def _folded():
    return folded_sheet(300, layers=3, seed=4)


def _write_obj(path: Path, vertices: np.ndarray, faces: np.ndarray, uv: np.ndarray, split: int) -> None:
    """Faces before ``split`` in group ``o a``, the rest in ``o b``; ``vt`` k belongs to vertex k."""
    lines = [f"v {x:.9g} {y:.9g} {z:.9g}" for x, y, z in vertices]
    lines += [f"vt {u:.9g} {v:.9g}" for u, v in uv]
    for k, (a, b, c) in enumerate(faces + 1):
        if k in (0, split):
            lines.append("o a" if k == 0 else "o b")
        lines.append(f"f {a}/{a} {b}/{b} {c}/{c}")
    path.write_text("\n".join(lines) + "\n")


def test_obj_texture_coordinates_become_the_rest_shape(tmp_path: Path) -> None:
    mesh = _folded()
    path = tmp_path / "garment.obj"
    _write_obj(path, mesh.vertices_end, mesh.faces, mesh.rest, split=100)
    frame = user_frames.load_user_frame(path)
    assert frame.name == "garment"
    np.testing.assert_allclose(frame.positions, mesh.vertices_end, rtol=1e-6, atol=1e-7)
    np.testing.assert_array_equal(frame.faces, mesh.faces)
    np.testing.assert_allclose(frame.rest, mesh.rest, rtol=1e-6, atol=1e-7)
    assert np.unique(frame.object_ids[:100]).size == 1 and frame.object_ids[100] != frame.object_ids[0]
    assert frame.radius == pytest.approx(half_median_edge(frame.positions, frame.faces))
    assert "texture coordinates as rest coordinates" in frame.source


def test_npz_rest_and_a_given_radius(tmp_path: Path) -> None:
    mesh = _folded()
    path = tmp_path / "frame.npz"
    np.savez(path, vertices=mesh.vertices_end, faces=mesh.faces, rest=mesh.rest)
    frame = user_frames.load_user_frame(path, radius=0.004)
    np.testing.assert_array_equal(frame.rest, mesh.rest)
    assert frame.radius == 0.004 and "0.004 (given)" in frame.source
    assert frame.object_ids is None
    without = tmp_path / "plain.npz"
    np.savez(without, vertices=mesh.vertices_end, faces=mesh.faces)
    assert user_frames.load_user_frame(without).rest is None


def test_a_cached_corpus_frame_reads_back(tmp_path: Path) -> None:
    mesh = _folded()
    ids = (np.arange(mesh.faces.shape[0]) % 2).astype(np.int32)
    CorpusFrame("sheet f3", "a test", mesh.vertices_end, mesh.faces, mesh.rest, ids, 0.01).save(tmp_path / "c.npz")
    frame = user_frames.load_user_frame(tmp_path / "c.npz")
    np.testing.assert_array_equal(frame.positions, mesh.vertices_end)
    np.testing.assert_array_equal(frame.object_ids, ids)
    assert "sheet f3" in frame.source and frame.rest is not None
    np.savez(tmp_path / "bare.npz", positions=mesh.vertices_end)
    with pytest.raises(InputError, match=r"bare\.npz: faces: is missing .*Fix: add the \(m, 3\) triangles"):
        user_frames.load_user_frame(tmp_path / "bare.npz")


def test_usd_meshes_merge_as_objects_in_world_coordinates(tmp_path: Path) -> None:
    from pxr import Gf, Usd, UsdGeom

    path = tmp_path / "scene.usda"
    stage = Usd.Stage.CreateNew(str(path))
    cloth = UsdGeom.Mesh.Define(stage, "/World/Cloth")
    cloth.GetPointsAttr().Set([(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0)])
    cloth.GetFaceVertexCountsAttr().Set([4])  # a quad: two triangles
    cloth.GetFaceVertexIndicesAttr().Set([0, 1, 2, 3])
    body = UsdGeom.Mesh.Define(stage, "/World/Body")
    body.AddTranslateOp().Set(Gf.Vec3d(0.0, 0.0, 2.0))
    # Points only at time samples: the first sample is read.
    body.GetPointsAttr().Set([(0, 0, 0), (1, 0, 0), (0, 1, 0)], 1.0)
    body.GetPointsAttr().Set([(5, 5, 5), (6, 5, 5), (5, 6, 5)], 2.0)
    body.GetFaceVertexCountsAttr().Set([3])
    body.GetFaceVertexIndicesAttr().Set([0, 1, 2])
    stage.GetRootLayer().Save()
    frame = user_frames.load_user_frame(path)
    assert frame.faces.tolist() == [[0, 1, 2], [0, 2, 3], [4, 5, 6]]
    np.testing.assert_allclose(frame.positions[4:], [[0, 0, 2], [1, 0, 2], [0, 1, 2]])
    assert frame.object_ids.tolist() == [0, 0, 1] and frame.rest is None
    assert "2 meshes" in frame.source
    later = user_frames.load_user_frame(path, usd_time=2.0)
    np.testing.assert_allclose(later.positions[4:], [[5, 5, 7], [6, 5, 7], [5, 6, 7]])
    with pytest.raises(InputError, match="--usd-time 9"):
        user_frames.load_user_frame(path, usd_time=9.0)


def test_usd_polygons_that_repeat_a_corner_leave_out_their_degenerate_triangles(tmp_path: Path) -> None:
    """A pentagon that visits corner 1 twice (as exporters write polygons that touch themselves) fans into the
    triangles (1, 2, 1) and (1, 1, 3) with no area: they are left out and counted, and so is a triangle given
    twice; the rest are kept."""
    from pxr import Usd, UsdGeom

    path = tmp_path / "spike.usda"
    stage = Usd.Stage.CreateNew(str(path))
    mesh = UsdGeom.Mesh.Define(stage, "/World/Cloth")
    mesh.GetPointsAttr().Set([(0, 0, 0), (1, 0, 0), (2, 0.5, 0), (1, 1, 0), (0, 1, 0)])
    mesh.GetFaceVertexCountsAttr().Set([5, 3, 3])
    mesh.GetFaceVertexIndicesAttr().Set([1, 2, 1, 3, 4, 0, 1, 4, 4, 0, 1])  # the last: the second again
    stage.GetRootLayer().Save()
    frame = user_frames.load_user_frame(path)
    assert frame.faces.tolist() == [[1, 3, 4], [0, 1, 4]]
    assert "2 fan triangles that repeat a vertex" in frame.source
    assert "1 triangle over the same three corners as another left out" in frame.source
    all_spikes = tmp_path / "spikes.usda"
    stage = Usd.Stage.CreateNew(str(all_spikes))
    mesh = UsdGeom.Mesh.Define(stage, "/World/Spike")
    mesh.GetPointsAttr().Set([(0, 0, 0), (1, 0, 0)])
    mesh.GetFaceVertexCountsAttr().Set([3])
    mesh.GetFaceVertexIndicesAttr().Set([0, 1, 0])
    stage.GetRootLayer().Save()
    with pytest.raises(InputError, match="faceVertexIndices.*no triangle is left"):
        user_frames.load_user_frame(all_spikes)


@pytest.mark.parametrize("case", ["missing", "extension", "radius", "not npz", "no mesh", "bad faces", "not usd"])
def test_bad_input_names_the_file_and_the_fix(tmp_path: Path, case: str) -> None:
    path, radius = tmp_path / "frame.obj", None
    if case == "extension":
        path = tmp_path / "frame.stl"
        path.write_text("solid")
    elif case == "radius":
        mesh = _folded()
        path = tmp_path / "frame.npz"
        np.savez(path, vertices=mesh.vertices_end, faces=mesh.faces)
        radius = -1.0
    elif case == "not npz":
        path = tmp_path / "frame.npz"
        path.write_text("not a zip")
    elif case == "no mesh":
        from pxr import Usd, UsdGeom

        path = tmp_path / "empty.usda"
        stage = Usd.Stage.CreateNew(str(path))
        UsdGeom.Xform.Define(stage, "/World")
        stage.GetRootLayer().Save()
    elif case == "not usd":
        path = tmp_path / "broken.usda"
        path.write_text("#usda 1.0\n{{{ not a layer")
    elif case == "bad faces":
        path = tmp_path / "frame.npz"
        np.savez(path, vertices=np.zeros((3, 3), np.float32), faces=np.array([[0, 1, 5]]))
    with pytest.raises(InputError) as error:
        user_frames.load_user_frame(path, radius)
    message = str(error.value)
    assert ("--frame-radius" if case == "radius" else path.name) in message and "Fix:" in message


def test_bench_frames_refuses_bad_input_before_writing(tmp_path: Path, capsys) -> None:
    mesh = _folded()
    good = tmp_path / "good.npz"
    np.savez(good, vertices=mesh.vertices_end, faces=mesh.faces)
    out = tmp_path / "report.md"
    assert main(["--frames", str(good), str(tmp_path / "missing.obj"), "--out", str(out)]) == 2
    assert "missing.obj" in capsys.readouterr().err
    assert main(["--frames", str(good), "--out", str(tmp_path)]) == 2
    assert main(["--frames", str(good), "--out", str(tmp_path / "report.txt")]) == 2
    assert list(tmp_path.iterdir()) == [good]


def test_bench_frames_end_to_end(tmp_path: Path) -> None:
    mesh = _folded()
    path = tmp_path / "layers.npz"
    np.savez(path, vertices=mesh.vertices_end, faces=mesh.faces, rest=mesh.rest)
    out = tmp_path / "out" / "frames.md"
    assert main(["--frames", str(path), "--frame-radius", "0.01", "--out", str(out), "--repeats", "1",
                 "--no-newton"]) == 0
    text = out.read_text()
    assert f"## {corpus_bench.USER_FRAMES_TITLE}" in text and "| layers | 300 | pscc (rest) |" in text
    assert "| layers | pscc (no rest) |" in text and "Targets met:" in text and "0.01 (given)" in text
    assert "](frames.png)" in text and out.with_suffix(".png").stat().st_size > 0  # the targets, drawn
    results = json.loads(out.with_suffix(".json").read_text())
    (entry,) = results["corpus"]["frames"]
    assert entry["radius"] == 0.01 and entry["rest"] is True
    for name in ("pscc", "pscc-no-rest"):
        assert entry["ratios"][name]["subset_of_spatial_hash"] is True
    assert {r["method"] for r in entry["rows"]} >= {"pscc", "pscc-no-rest", "spatial-hash", "ipctk-lbvh-1"}
    assert all(r["graph_matches"] for r in entry["rows"] if "graph_matches" in r)
