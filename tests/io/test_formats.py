"""OBJ / PLY / USD output formats and FrameWriter: exact float32 round trips, atomic writes, --format parsing."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest
from pxr import Sdf, Usd, UsdGeom, UsdValidation

from pscc.errors import InputError
from pscc.io import formats
from pscc.io.formats import (
    FORMATS,
    FrameWriter,
    UsdAnimationWriter,
    obj_frame_path,
    parse_formats,
    ply_frame_path,
    read_obj_frame,
    read_ply_frame,
    read_usd_frames,
    usd_path,
    write_obj_frame,
    write_ply_frame,
)
from pscc.io.frames import FRAME_KEYS, frame_path, read_frame
from pscc.mesh import load_mesh

# Two cloth pieces (a square: ids 0, a triangle: id 3, ids need not be contiguous) and a tetrahedron.
CLOTH_FACES = np.array([[0, 1, 2], [0, 2, 3], [4, 5, 6]], dtype=np.int32)
CLOTH_IDS = np.array([0, 0, 3], dtype=np.int32)
OBSTACLE_FACES = np.array([[0, 2, 1], [0, 1, 3], [1, 2, 3], [0, 3, 2]], dtype=np.int32)
FPS = 24.0


def awkward_points(rng: np.random.Generator, count: int) -> np.ndarray:
    """float32 values across the whole range: tiny, subnormal, huge, negative zero, many digits."""
    values = rng.standard_normal((count, 3)) * 10.0 ** rng.uniform(-8, 6, (count, 3))
    points = values.astype(np.float32)
    flat = points.reshape(-1)
    flat[:6] = [np.float32(-0.0), np.float32(1e-40), np.finfo(np.float32).tiny, np.finfo(np.float32).max,
                np.float32(1 / 3), -np.finfo(np.float32).smallest_subnormal]
    return points


def same_bits(a: np.ndarray, b: np.ndarray) -> bool:
    """Equal as float32 bit patterns (so -0.0 and 0.0 differ)."""
    a, b = np.asarray(a), np.asarray(b)
    return a.dtype == b.dtype == np.float32 and a.shape == b.shape and np.array_equal(a.view(np.uint32),
                                                                                       b.view(np.uint32))


def frames(count: int, obstacles: bool, seed: int = 0) -> list[tuple[np.ndarray, np.ndarray | None]]:
    rng = np.random.default_rng(seed)
    return [(awkward_points(rng, 7), awkward_points(rng, 4) if obstacles else None) for _ in range(count)]


def hidden_files(root: Path) -> list[Path]:
    """Leftover temporary files (``.name.xxx.tmp`` siblings)."""
    return [p for p in root.rglob("*") if p.name.startswith(".") or ".tmp" in p.name]


def check_frame(frame: dict[str, np.ndarray], cloth: np.ndarray, obstacles: np.ndarray | None) -> None:
    assert set(frame) == set(FRAME_KEYS)
    assert same_bits(frame["vertices"], cloth)
    np.testing.assert_array_equal(frame["faces"], CLOTH_FACES)
    np.testing.assert_array_equal(frame["object_ids"], CLOTH_IDS)
    assert frame["faces"].dtype == frame["object_ids"].dtype == frame["obstacle_faces"].dtype == np.int32
    if obstacles is None:
        assert frame["obstacle_vertices"].shape == (0, 3) and frame["obstacle_faces"].shape == (0, 3)
    else:
        assert same_bits(frame["obstacle_vertices"], obstacles)
        np.testing.assert_array_equal(frame["obstacle_faces"], OBSTACLE_FACES)


# --------------------------------------------------------------------------------------------
# --format
# --------------------------------------------------------------------------------------------


def test_parse_formats_keeps_order_and_drops_repeats() -> None:
    assert parse_formats("npz,obj") == ("npz", "obj")
    assert parse_formats(" USD , npz,usd ") == ("usd", "npz")
    assert parse_formats(["ply", "obj,npz"]) == ("ply", "obj", "npz")
    assert parse_formats(",".join(FORMATS)) == FORMATS


@pytest.mark.parametrize("spec", ["npz,fbx", "abc", "npz,,obj", "", " "])
def test_parse_formats_rejects_bad_names(spec: str) -> None:
    with pytest.raises(InputError) as info:
        parse_formats(spec)
    error = info.value
    assert error.source == "argument" and error.field == "--format"
    assert str(error).startswith("argument: --format: ") and "Fix: " in str(error)
    assert all(name in error.fix for name in FORMATS)
    if "fbx" in spec:
        assert "'fbx'" in error.problem


# --------------------------------------------------------------------------------------------
# OBJ and PLY
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize("obstacles", [True, False], ids=["obstacles", "cloth-only"])
@pytest.mark.parametrize("kind", ["obj", "ply"])
def test_obj_ply_round_trip_is_exact(tmp_path: Path, kind: str, obstacles: bool) -> None:
    write, read, where = ((write_obj_frame, read_obj_frame, obj_frame_path) if kind == "obj"
                          else (write_ply_frame, read_ply_frame, ply_frame_path))
    for index, (cloth, others) in enumerate(frames(3, obstacles)):
        path = write(tmp_path, index, cloth, CLOTH_FACES, CLOTH_IDS, others, OBSTACLE_FACES if obstacles else None)
        assert path == where(tmp_path, index) and path.name == f"frame_{index:05d}.{kind}"
        check_frame(read(path), cloth, others)
    assert sorted(p.name for p in (tmp_path / kind).iterdir()) == [f"frame_0000{i}.{kind}" for i in range(3)]
    assert hidden_files(tmp_path) == []


def test_obj_layout_one_object_per_piece(tmp_path: Path) -> None:
    (cloth, others), = frames(1, True)
    path = write_obj_frame(tmp_path, 0, cloth, CLOTH_FACES, CLOTH_IDS, others, OBSTACLE_FACES)
    lines = path.read_text().splitlines()
    assert [line for line in lines if line.startswith("o ")] == ["o cloth_0", "o cloth_3", "o obstacles"]
    assert sum(line.startswith("v ") for line in lines) == 7 + 4
    assert lines[lines.index("o obstacles") + 5].startswith("f ")  # 4 obstacle vertices, then its faces
    # pscc's own mesh loader (ids by order of appearance) reads every vertex and face in order.
    mesh = load_mesh(path)
    assert same_bits(mesh.vertices, np.concatenate([cloth, others]))
    np.testing.assert_array_equal(mesh.faces, np.concatenate([CLOTH_FACES, OBSTACLE_FACES + 7]))
    np.testing.assert_array_equal(mesh.object_ids, [0, 0, 1, 2, 2, 2, 2])


def test_obj_sorts_interleaved_pieces_stably(tmp_path: Path) -> None:
    (cloth, _), = frames(1, False)
    ids = np.array([3, 0, 3], dtype=np.int32)
    frame = read_obj_frame(write_obj_frame(tmp_path, 0, cloth, CLOTH_FACES, ids))
    order = np.argsort(ids, kind="stable")
    np.testing.assert_array_equal(frame["faces"], CLOTH_FACES[order])
    np.testing.assert_array_equal(frame["object_ids"], ids[order])


def test_ply_object_ids_survive_trimesh(tmp_path: Path) -> None:
    """The per-face object_id (obstacles: max cloth id + 1) reads back through trimesh's PLY reader."""
    (cloth, others), = frames(1, True)
    path = write_ply_frame(tmp_path, 0, cloth, CLOTH_FACES, CLOTH_IDS, others, OBSTACLE_FACES)
    assert b"format binary_little_endian 1.0" in path.read_bytes()[:200]
    mesh = load_mesh(path)
    assert same_bits(mesh.vertices, np.concatenate([cloth, others]))
    np.testing.assert_array_equal(mesh.faces, np.concatenate([CLOTH_FACES, OBSTACLE_FACES + 7]))
    np.testing.assert_array_equal(mesh.object_ids, [0, 0, 3, 4, 4, 4, 4])


def test_readers_reject_foreign_files(tmp_path: Path) -> None:
    obj = tmp_path / "x.obj"
    obj.write_text("o teapot\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    with pytest.raises(InputError) as info:
        read_obj_frame(obj)
    assert info.value.field == "line 1"
    ply = tmp_path / "x.ply"
    ply.write_text("ply\nformat ascii 1.0\nelement vertex 0\nend_header\n")
    with pytest.raises(InputError) as info:
        read_ply_frame(ply)
    assert info.value.field == "format"
    (cloth, _), = frames(1, False)
    good = write_ply_frame(tmp_path, 0, cloth, CLOTH_FACES, CLOTH_IDS)
    good.write_bytes(good.read_bytes()[:-5])
    with pytest.raises(InputError, match="truncated"):
        read_ply_frame(good)


def test_writers_refuse_nan(tmp_path: Path) -> None:
    (cloth, _), = frames(1, False)
    cloth[2, 1] = np.nan
    for write in (write_obj_frame, write_ply_frame):
        with pytest.raises(ValueError, match="NaN"):
            write(tmp_path, 0, cloth, CLOTH_FACES, CLOTH_IDS)
    assert not list(tmp_path.rglob("*.obj")) and not list(tmp_path.rglob("*.ply"))


# --------------------------------------------------------------------------------------------
# USD
# --------------------------------------------------------------------------------------------


def open_stage(path: Path) -> Usd.Stage:
    """The stage at ``path``, read fresh (not from USD's layer registry)."""
    return Usd.Stage.Open(Sdf.Layer.OpenAsAnonymous(str(path)))


@pytest.mark.parametrize("obstacles", [True, False], ids=["obstacles", "cloth-only"])
def test_usd_round_trip_time_codes_and_topology(tmp_path: Path, obstacles: bool) -> None:
    data = frames(4, obstacles)
    path = tmp_path / "animation.usd"
    with UsdAnimationWriter(path, CLOTH_FACES, CLOTH_IDS, OBSTACLE_FACES if obstacles else None, FPS) as writer:
        for index, (cloth, others) in enumerate(data):
            writer.add_frame(index, cloth, others)
    assert path.read_bytes()[:8] == b"PXR-USDC" and hidden_files(tmp_path) == []

    read = read_usd_frames(path)
    assert len(read) == 4
    for (cloth, others), (got_cloth, got_others) in zip(data, read, strict=True):
        assert same_bits(got_cloth, cloth)
        assert same_bits(got_others, others) if obstacles else got_others.shape == (0, 3)

    stage = open_stage(path)
    assert (stage.GetStartTimeCode(), stage.GetEndTimeCode()) == (0, 3)
    assert stage.GetTimeCodesPerSecond() == FPS and stage.GetFramesPerSecond() == FPS
    assert UsdGeom.GetStageMetersPerUnit(stage) == 1.0 and UsdGeom.GetStageUpAxis(stage) == UsdGeom.Tokens.z
    assert stage.GetDefaultPrim().GetPath() == "/World"
    assert stage.GetPrimAtPath("/World/Obstacles").IsValid() == obstacles
    meshes = [("/World/Cloth", CLOTH_FACES, CLOTH_IDS, 0)]
    if obstacles:
        meshes.append(("/World/Obstacles", OBSTACLE_FACES, np.full(4, 4), 1))
    for prim_path, faces, ids, slot in meshes:
        mesh = UsdGeom.Mesh(stage.GetPrimAtPath(prim_path))
        for attr in (mesh.GetFaceVertexCountsAttr(), mesh.GetFaceVertexIndicesAttr()):
            assert attr.GetNumTimeSamples() == 0  # topology once
        np.testing.assert_array_equal(mesh.GetFaceVertexCountsAttr().Get(), np.full(len(faces), 3))
        np.testing.assert_array_equal(mesh.GetFaceVertexIndicesAttr().Get(), faces.ravel())
        primvar = UsdGeom.PrimvarsAPI(mesh.GetPrim()).GetPrimvar("object_id")
        assert primvar.GetInterpolation() == UsdGeom.Tokens.uniform
        np.testing.assert_array_equal(primvar.Get(), ids)
        assert mesh.GetSubdivisionSchemeAttr().Get() == UsdGeom.Tokens.none
        assert mesh.GetPointsAttr().GetTimeSamples() == [0.0, 1.0, 2.0, 3.0]
        for time, frame in enumerate(data):
            expected = UsdGeom.PointBased.ComputeExtent(mesh.GetPointsAttr().Get(time))
            assert mesh.GetExtentAttr().Get(time) == expected
            assert same_bits(np.array(mesh.GetPointsAttr().Get(time)), frame[slot])

    context = UsdValidation.ValidationContext(UsdValidation.ValidationRegistry().GetOrLoadAllValidators())
    assert [error.GetMessage() for error in context.Validate(stage)] == []


def test_usd_saves_every_k_frames_atomically(tmp_path: Path) -> None:
    data = frames(5, True)
    path = tmp_path / "animation.usd"
    writer = UsdAnimationWriter(path, CLOTH_FACES, CLOTH_IDS, OBSTACLE_FACES, FPS, save_every=2)
    writer.add_frame(0, *data[0])
    assert not path.exists()
    for index in (1, 2):
        writer.add_frame(index, *data[index])
    assert len(read_usd_frames(path)) == 2  # saved after frame 1; frame 2 is pending
    assert open_stage(path).GetEndTimeCode() == 1
    assert hidden_files(tmp_path) == []
    writer.close()
    writer.close()  # idempotent
    assert len(read_usd_frames(path)) == 3
    with pytest.raises(RuntimeError, match="closed"):
        writer.add_frame(3, *data[3])


def test_usd_resume_continues_the_same_file(tmp_path: Path) -> None:
    first, second = frames(5, True, seed=1), frames(4, True, seed=2)
    path = tmp_path / "animation.usd"
    with UsdAnimationWriter(path, CLOTH_FACES, CLOTH_IDS, OBSTACLE_FACES, FPS) as writer:
        for index, frame in enumerate(first):
            writer.add_frame(index, *frame)
    # A resumed run restarts at frame 3: frames >= 3 of the old run are dropped, 3..6 are new.
    with UsdAnimationWriter(path, CLOTH_FACES, CLOTH_IDS, OBSTACLE_FACES, FPS, resume_from=3) as writer:
        assert writer.frames == (0, 1, 2)
        for index, frame in enumerate(second, start=3):
            writer.add_frame(index, *frame)
    read = read_usd_frames(path)
    expected = first[:3] + second
    assert len(read) == 7
    for (cloth, others), (got_cloth, got_others) in zip(expected, read, strict=True):
        assert same_bits(got_cloth, cloth) and same_bits(got_others, others)
    stage = open_stage(path)
    assert (stage.GetStartTimeCode(), stage.GetEndTimeCode()) == (0, 6)
    assert UsdGeom.Mesh(stage.GetPrimAtPath("/World/Cloth")).GetExtentAttr().GetTimeSamples() == list(range(7))


@pytest.mark.parametrize("change", ["faces", "ids", "obstacles", "fps", "missing"])
def test_usd_resume_refuses_a_different_run(tmp_path: Path, change: str) -> None:
    path = tmp_path / "animation.usd"
    if change != "missing":
        with UsdAnimationWriter(path, CLOTH_FACES, CLOTH_IDS, OBSTACLE_FACES, FPS) as writer:
            writer.add_frame(0, *frames(1, True)[0])
    faces = CLOTH_FACES[::-1].copy() if change == "faces" else CLOTH_FACES
    ids = CLOTH_IDS + 1 if change == "ids" else CLOTH_IDS
    obstacle_faces = None if change == "obstacles" else OBSTACLE_FACES
    fps = 30.0 if change == "fps" else FPS
    with pytest.raises(InputError) as info:
        UsdAnimationWriter(path, faces, ids, obstacle_faces, fps, resume_from=1)
    assert info.value.source == str(path)


def test_failed_save_leaves_old_file_and_no_temporary(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    data = frames(2, False)
    path = tmp_path / "animation.usd"
    with UsdAnimationWriter(path, CLOTH_FACES, CLOTH_IDS, None, FPS) as writer:
        writer.add_frame(0, *data[0])
    before = path.read_bytes()
    obj = write_obj_frame(tmp_path, 0, data[0][0], CLOTH_FACES, CLOTH_IDS)
    obj_before = obj.read_bytes()

    def broken_replace(source: str, target: str) -> None:
        raise OSError("disk full")

    monkeypatch.setattr(os, "replace", broken_replace)
    writer = UsdAnimationWriter(path, CLOTH_FACES, CLOTH_IDS, None, FPS, resume_from=1)
    writer.add_frame(1, *data[1])
    with pytest.raises(OSError, match="disk full"):
        writer.save()
    with pytest.raises(OSError, match="disk full"):
        write_obj_frame(tmp_path, 0, data[1][0], CLOTH_FACES, CLOTH_IDS)
    assert path.read_bytes() == before and obj.read_bytes() == obj_before
    assert hidden_files(tmp_path) == []


# --------------------------------------------------------------------------------------------
# FrameWriter
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize("obstacles", [True, False], ids=["obstacles", "cloth-only"])
def test_frame_writer_writes_every_format(tmp_path: Path, obstacles: bool) -> None:
    data = frames(3, obstacles)
    with FrameWriter(tmp_path, "npz,obj,ply,usd", CLOTH_FACES, CLOTH_IDS, OBSTACLE_FACES if obstacles else None,
                     FPS) as writer:
        for index, (cloth, others) in enumerate(data):
            paths = writer.write(index, cloth, others)
            assert paths == {"npz": frame_path(tmp_path, index), "obj": obj_frame_path(tmp_path, index),
                             "ply": ply_frame_path(tmp_path, index), "usd": usd_path(tmp_path)}
    usd = read_usd_frames(usd_path(tmp_path))
    for index, (cloth, others) in enumerate(data):
        for frame in (read_frame(frame_path(tmp_path, index)), read_obj_frame(obj_frame_path(tmp_path, index)),
                      read_ply_frame(ply_frame_path(tmp_path, index))):
            check_frame(frame, cloth, others)
        assert same_bits(usd[index][0], cloth)
        assert same_bits(usd[index][1], others) if obstacles else usd[index][1].shape == (0, 3)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["animation.usd", "frames", "obj", "ply"]
    assert hidden_files(tmp_path) == []


def test_frame_writer_writes_only_what_was_asked(tmp_path: Path) -> None:
    (cloth, others), = frames(1, True)
    with FrameWriter(tmp_path, ("ply",), CLOTH_FACES, CLOTH_IDS, OBSTACLE_FACES, FPS) as writer:
        assert writer.write(0, cloth, others) == {"ply": ply_frame_path(tmp_path, 0)}
    assert [p.name for p in tmp_path.iterdir()] == ["ply"]
    with pytest.raises(InputError, match="--format"):
        FrameWriter(tmp_path, "npz,gltf", CLOTH_FACES, CLOTH_IDS)


def test_frame_writer_checks_before_writing(tmp_path: Path) -> None:
    (cloth, others), = frames(1, True)
    with FrameWriter(tmp_path, FORMATS, CLOTH_FACES, CLOTH_IDS, OBSTACLE_FACES, FPS) as writer:
        bad = others.copy()
        bad[0, 0] = np.inf
        with pytest.raises(ValueError, match="NaN or Inf"):
            writer.write(0, cloth, bad)
        with pytest.raises(ValueError, match="obstacle vertices"):
            writer.write(0, cloth, None)
        with pytest.raises(ValueError, match="refer to vertex 6"):
            writer.write(0, cloth[:5], others)
        assert [p for p in tmp_path.rglob("*") if p.is_file()] == []
    assert read_usd_frames(usd_path(tmp_path)) == []  # closed with no frames: an empty but valid stage


def test_frame_writer_resume_fills_usd_gap_from_npz(tmp_path: Path) -> None:
    """A crash after the last USD save loses USD frames; resuming fills them in from the NPZ frames."""
    data = frames(7, True)
    writer = FrameWriter(tmp_path, "npz,usd", CLOTH_FACES, CLOTH_IDS, OBSTACLE_FACES, FPS, usd_save_every=2)
    for index in range(5):
        writer.write(index, *data[index])
    del writer  # "crash": frames 0..3 were saved to USD, frame 4 only as NPZ
    assert len(read_usd_frames(usd_path(tmp_path))) == 4
    with FrameWriter(tmp_path, "npz,usd", CLOTH_FACES, CLOTH_IDS, OBSTACLE_FACES, FPS, resume_from=5,
                     usd_save_every=2) as writer:
        for index in (5, 6):
            writer.write(index, *data[index])
    read = read_usd_frames(usd_path(tmp_path))
    assert len(read) == 7
    for (cloth, others), (got_cloth, got_others) in zip(data, read, strict=True):
        assert same_bits(got_cloth, cloth) and same_bits(got_others, others)
    # Without the NPZ frames the gap cannot be filled: the error says which frames are missing.
    os.unlink(frame_path(tmp_path, 6))
    usd_path(tmp_path).unlink()
    with pytest.raises(InputError, match="missing") as info:
        FrameWriter(tmp_path, "usd", CLOTH_FACES, CLOTH_IDS, OBSTACLE_FACES, FPS, resume_from=7)
    assert info.value.field == "time samples" and "first: 6" in info.value.problem


def test_module_exports_are_documented() -> None:
    for name in formats.__all__:
        assert getattr(formats, name).__doc__ or name == "FORMATS", name
