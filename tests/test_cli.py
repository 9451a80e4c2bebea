"""``pscc detect`` and ``pscc demo``: outputs, JSON stats, and bad input (exit 2, nothing written)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from pscc.cli import main
from pscc.mesh import folded_sheet


@pytest.fixture(scope="module")
def sheet():
    return folded_sheet(1000, layers=3, seed=0)


def _write_obj(path: Path, vertices: np.ndarray, faces: np.ndarray) -> None:
    lines = [f"v {x} {y} {z}" for x, y, z in vertices] + [f"f {a + 1} {b + 1} {c + 1}" for a, b, c in faces]
    path.write_text("\n".join(lines) + "\n")


def test_detect_npz_with_end_positions(tmp_path: Path, sheet, capsys) -> None:
    mesh = tmp_path / "sheet.npz"
    np.savez(mesh, vertices=sheet.vertices, faces=sheet.faces, vertices_end=sheet.vertices_end)
    out = tmp_path / "pairs.npz"
    assert main(["detect", str(mesh), "--out", str(out), "--json"]) == 0
    stats = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert stats["mode"] == "ccd" and stats["method"] == "pscc"
    with np.load(out) as pairs:
        assert set(pairs.files) == {"vertex_face", "edge_edge", "vertex_face_toi", "edge_edge_toi"}
        assert pairs["vertex_face"].shape == (stats["vertex_face_pairs"], 2)
        assert pairs["edge_edge"].shape == (stats["edge_edge_pairs"], 4)
        assert stats["vertex_face_pairs"] + stats["edge_edge_pairs"] > 0


def test_detect_obj_with_separate_end_mesh_and_dcd(tmp_path: Path, sheet, capsys) -> None:
    start = tmp_path / "start.obj"
    end = tmp_path / "end.obj"
    _write_obj(start, sheet.vertices, sheet.faces)
    _write_obj(end, sheet.vertices_end, sheet.faces)
    assert main(["detect", str(start), "--end", str(end), "--json"]) == 0
    ccd = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert ccd["mode"] == "ccd"
    out = tmp_path / "dcd.npz"
    assert main(["detect", str(start), "--thickness", "0.01", "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "dcd" in printed and "pairs written" in printed
    with np.load(out) as pairs:
        assert set(pairs.files) == {"vertex_face", "edge_edge"}


BAD_FILES = {
    "missing.obj": None,
    "mesh.stl": "solid x\nendsolid x\n",
    "quad.obj": "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf 1 2 3 4\n",
    "range.obj": "v 0 0 0\nv 1 0 0\nv 1 1 0\nf 1 2 7\n",
    "nan.obj": "v 0 0 0\nv nan 0 0\nv 1 1 0\nf 1 2 3\n",
    "dup.obj": "v 0 0 0\nv 1 0 0\nv 1 1 0\nf 1 2 3\nf 3 1 2\n",
    "empty.obj": "# nothing\n",
}


@pytest.mark.parametrize("name", sorted(BAD_FILES))
def test_bad_input_exits_2_and_writes_nothing(tmp_path: Path, name: str, capsys) -> None:
    path = tmp_path / name
    if BAD_FILES[name] is not None:
        path.write_text(BAD_FILES[name])
    out = tmp_path / "pairs.npz"
    assert main(["detect", str(path), "--out", str(out)]) == 2
    captured = capsys.readouterr()
    lines = captured.err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("pscc: error: ") and "Fix:" in lines[0]
    assert name in lines[0]
    assert not out.exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == ([name] if BAD_FILES[name] is not None else [])


def test_bad_npz_fields(tmp_path: Path, capsys) -> None:
    path = tmp_path / "bad.npz"
    np.savez(path, vertices=np.zeros((3, 3)), faces=np.array([[0, 1, 2]]), vertices_end=np.zeros((4, 3)))
    assert main(["detect", str(path), "--out", str(tmp_path / "p.npz")]) == 2
    err = capsys.readouterr().err
    assert "vertices_end" in err and "Fix:" in err
    assert not (tmp_path / "p.npz").exists()


def test_bad_options(tmp_path: Path, sheet, capsys) -> None:
    mesh = tmp_path / "sheet.npz"
    np.savez(mesh, vertices=sheet.vertices, faces=sheet.faces)
    assert main(["detect", str(mesh), "--thickness", "-1"]) == 2
    assert "thickness" in capsys.readouterr().err
    assert main(["detect", str(mesh), "--out", str(tmp_path / "p.txt")]) == 2
    assert "--out" in capsys.readouterr().err
    assert main(["detect", str(mesh), "--device", "cuda:9"]) == 2
    assert "device" in capsys.readouterr().err


def test_demo_writes_frames_picture_video_and_stats(tmp_path: Path, capsys) -> None:
    out = tmp_path / "demo"
    assert main(["demo", "--triangles", "100", "--frames", "2", "--out-dir", str(out), "--no-progress"]) == 0
    printed = capsys.readouterr().out
    for name in ("preview.png", "animation.mp4", "stats.json", "frame_00002.npz"):
        assert name in printed
    assert (out / "preview.png").stat().st_size > 0 and (out / "animation.mp4").stat().st_size > 0
    assert len(json.loads((out / "stats.json").read_text())["frames"]) == 2
    assert main(["demo", "--triangles", "100", "--frames", "1", "--out-dir", str(out), "--no-progress"]) == 0


def test_simulate_writes_frames_and_stats(tmp_path: Path, capsys) -> None:
    out = tmp_path / "run"
    assert main(["simulate", "drape", "--frames", "2", "--triangles", "200", "--out-dir", str(out),
                 "--no-progress"]) == 0
    assert "s per frame" in capsys.readouterr().out
    frames = sorted((out / "frames").glob("frame_*.npz"))
    assert [f.name for f in frames] == ["frame_00000.npz", "frame_00001.npz", "frame_00002.npz"]
    with np.load(frames[-1]) as frame:
        assert set(frame.files) == {"vertices", "faces", "object_ids", "obstacle_vertices", "obstacle_faces"}
        assert frame["vertices"].shape[0] == frame["faces"].max() + 1  # cloth vertices only
        assert frame["vertices"].dtype == np.float32 and frame["vertices"].shape[1] == 3
        assert frame["faces"].shape == (frame["object_ids"].shape[0], 3)
        assert frame["obstacle_faces"].shape[0] > 0 and frame["obstacle_vertices"].dtype == np.float32
        assert frame["obstacle_faces"].max() < frame["obstacle_vertices"].shape[0]
        assert np.all(np.isfinite(frame["vertices"]))
    stats = json.loads((out / "stats.json").read_text())
    assert stats["scene"] == "drape" and len(stats["frames"]) == 2 and stats["graph"] == "replayed"
    for record in stats["frames"]:
        assert record["seconds"]["total"] > 0.0
        if record["counts"]["device_fallbacks"]:  # the host path times its stages
            assert set(record["seconds"]) >= {"integration", "broad_phase", "narrow_phase", "penetration"}
        assert record["counts"]["broad_phases"] >= record["steps"]
        assert record["counts"]["ccd_rounds"] >= record["steps"]


def test_simulate_without_obstacles_writes_empty_obstacle_arrays(tmp_path: Path) -> None:
    out = tmp_path / "twist"
    assert main(["simulate", "twist", "--frames", "1", "--triangles", "100", "--out-dir", str(out),
                 "--no-progress"]) == 0
    with np.load(out / "frames" / "frame_00001.npz") as frame:
        assert frame["obstacle_vertices"].shape == (0, 3) and frame["obstacle_faces"].shape == (0, 3)


def test_simulate_all_formats_and_render(tmp_path: Path) -> None:
    from pscc.io.formats import read_obj_frame, read_ply_frame, read_usd_frames

    out = tmp_path / "run"
    assert main(["simulate", "drape", "--frames", "2", "--triangles", "100", "--out-dir", str(out), "--no-progress",
                 "--format", "npz,obj,ply,usd", "--render"]) == 0
    with np.load(out / "frames" / "frame_00002.npz") as frame:
        expected = frame["vertices"]
        obstacles = frame["obstacle_vertices"]
    np.testing.assert_array_equal(read_obj_frame(out / "obj" / "frame_00002.obj")["vertices"], expected)
    np.testing.assert_array_equal(read_ply_frame(out / "ply" / "frame_00002.ply")["obstacle_vertices"], obstacles)
    usd = read_usd_frames(out / "animation.usd")
    assert len(usd) == 3
    np.testing.assert_array_equal(usd[2][0], expected)
    assert (out / "preview.png").stat().st_size > 0 and (out / "animation.mp4").stat().st_size > 0


@pytest.mark.parametrize("arguments, message", [
    (["--frames", "0"], "--frames"),
    (["--format", "npz,fbx"], "--format"),
    (["--triangles", "3"], "triangles"),
])
def test_simulate_bad_options_exit_2_and_write_nothing(tmp_path: Path, arguments, message, capsys) -> None:
    out = tmp_path / "run"
    assert main(["simulate", "drape", "--out-dir", str(out), "--no-progress", *arguments]) == 2
    assert message in capsys.readouterr().err
    assert not out.exists()


def test_resolved_scene_toml_reproduces_a_builtin_run(tmp_path: Path) -> None:
    first = tmp_path / "first"
    assert main(["simulate", "twist", "--frames", "2", "--scale", "0.05", "--out-dir", str(first),
                 "--no-progress", "--method", "spatial-hash"]) == 0
    resolved = (first / "scene.toml").read_text()
    assert 'scene = "twist"' in resolved and 'method = "spatial-hash"' in resolved
    again = tmp_path / "again"
    assert main(["simulate", str(first / "scene.toml"), "--out-dir", str(again), "--no-progress"]) == 0
    for name in ("frame_00001.npz", "frame_00002.npz"):
        with np.load(first / "frames" / name) as a, np.load(again / "frames" / name) as b:
            np.testing.assert_array_equal(a["vertices"], b["vertices"])


def test_resolved_builtin_file_of_an_earlier_version_names_the_renamed_key(tmp_path: Path, capsys) -> None:
    first = tmp_path / "first"
    assert main(["simulate", "twist", "--frames", "1", "--scale", "0.05", "--out-dir", str(first),
                 "--no-progress"]) == 0
    old = tmp_path / "old.toml"
    old.write_text((first / "scene.toml").read_text().replace("projection_rounds", "impulse_rounds"))
    assert main(["simulate", str(old), "--out-dir", str(tmp_path / "again"), "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert "contact.impulse_rounds" in err and "replaced by 'projection_rounds'" in err


def test_simulate_scene_file_and_its_resolved_copy(tmp_path: Path) -> None:
    example = Path(__file__).resolve().parents[1] / "examples" / "drape.toml"
    out = tmp_path / "file"
    assert main(["simulate", str(example), "--frames", "1", "--out-dir", str(out), "--no-progress"]) == 0
    again = tmp_path / "again"
    assert main(["simulate", str(out / "scene.toml"), "--out-dir", str(again), "--no-progress"]) == 0
    with np.load(out / "frames" / "frame_00001.npz") as a, np.load(again / "frames" / "frame_00001.npz") as b:
        np.testing.assert_array_equal(a["vertices"], b["vertices"])


def test_bad_scene_file_names_the_key(tmp_path: Path, capsys) -> None:
    bad = tmp_path / "bad.toml"
    bad.write_text('[scene]\nname = "x"\n\n[[cloth]]\n[cloth.sheet]\nsize = [1.0, 1.0]\ncells = [4, 4]\n'
                   '[cloth.material]\ndensty = 0.2\n')
    out = tmp_path / "out"
    assert main(["simulate", str(bad), "--out-dir", str(out), "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert "cloth[0].material.densty" in err and "density" in err
    assert not out.exists()


def test_scenes_lists_every_scene(capsys) -> None:
    assert main(["scenes", "--json"]) == 0
    rows = json.loads(capsys.readouterr().out)
    names = {row["name"] for row in rows}
    assert names == {"drape", "stack", "twist", "sphere", "twisting", "flag", "sphere-drop", "kungfu", "falling",
                     "dance"}
    sphere = next(row for row in rows if row["name"] == "sphere")
    assert sphere["triangles"]["1"] == 200_000
