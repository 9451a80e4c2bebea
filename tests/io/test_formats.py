"""OBJ / PLY / USD output formats and FrameWriter: exact float32 round trips, atomic writes, --format parsing."""

from __future__ import annotations

import errno
import os
from pathlib import Path

import numpy as np
import pytest
from pxr import Sdf, Usd, UsdGeom, UsdValidation

from pscc.errors import InputError, OutputError
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
from pscc.tolerances import MAX_COORDINATE

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


def in_detector_range(points: np.ndarray) -> np.ndarray:
    """``points`` with magnitudes above ``MAX_COORDINATE`` clamped (``load_mesh`` refuses larger ones)."""
    limit = np.float32(MAX_COORDINATE)
    return np.where(np.abs(points) > limit, np.copysign(limit, points), points).astype(np.float32)


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
    cloth, others = in_detector_range(cloth), in_detector_range(others)  # load_mesh checks the range
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
    cloth, others = in_detector_range(cloth), in_detector_range(others)  # load_mesh checks the range
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
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(os, "replace", broken_replace)
    writer = UsdAnimationWriter(path, CLOTH_FACES, CLOTH_IDS, None, FPS, resume_from=1)
    writer.add_frame(1, *data[1])
    with pytest.raises(OutputError, match="animation.usd: path: cannot be written: the disk is full"):
        writer.save()
    with pytest.raises(OutputError, match="frame_00000.obj: path: cannot be written: the disk is full"):
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


# --------------------------------------------------------------------------------------------
# Frame readers: integers that overflow, counts the file cannot hold, non-finite coordinates
# --------------------------------------------------------------------------------------------

_OBJ_TRIANGLE = "o cloth_0\nv 0 0 0\nv 1 0 0\nv 0 1 0\n"


@pytest.mark.parametrize(("text", "line", "words"), [
    (_OBJ_TRIANGLE + "f 1 2 99999999999999999999999\n", 5, ("99999999999999999999999", "out of range")),
    (_OBJ_TRIANGLE + "f 1 2 -2147483649\n", 5, ("-2147483649", "out of range")),
    ("o cloth_99999999999999999999\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n", 1, ("object id", "2147483647")),
    ("o cloth_" + "7" * 5000 + "\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n", 1, ("object id", "(5000 characters)")),
    ("o cloth_0\nv 0 0 0\nv 1e999 0 0\nv 0 1 0\nf 1 2 3\n", 3, ("NaN or Inf",)),
    ("o cloth_0\nv 0 0 0\nv 1 0 0\nv 0 1e300 0\nf 1 2 3\n", 4, ("NaN or Inf",)),
    (_OBJ_TRIANGLE + "f 1 2 3\no obstacles\nv 0 0 0\nv 0 -inf 0\n", 8, ("NaN or Inf",)),
])
def test_obj_frame_reader_refuses_overflow_and_non_finite(tmp_path: Path, text: str, line: int,
                                                          words: tuple[str, ...]) -> None:
    path = tmp_path / "frame.obj"
    path.write_text(text)
    with pytest.raises(InputError) as info:
        read_obj_frame(path)
    error = info.value
    assert (error.source, error.field) == (str(path), f"line {line}"), str(error)
    assert all(word in error.problem for word in words), str(error)
    assert error.fix and len(str(error)) < 400


def _ply_frame_bytes(vertex_count: object = 3, face_count: object = 1, *, index_type: str = "int",
                     id_type: str | None = None, points: np.ndarray | None = None, face: bytes | None = None,
                     comment: str = "") -> bytes:
    header = (f"ply\nformat binary_little_endian 1.0\n{comment}element vertex {vertex_count}\nproperty float x\n"
              f"property float y\nproperty float z\nelement face {face_count}\n"
              f"property list uchar {index_type} vertex_indices\n"
              + (f"property {id_type} object_id\n" if id_type else "") + "end_header\n")
    if points is None:
        points = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]])
    if face is None:
        face = np.array([3], "u1").tobytes() + np.array([0, 1, 2], "<i4").tobytes()
    return header.encode() + np.asarray(points, "<f4").tobytes() + face


def _face(indices: list[int], index_type: str = "<i4", object_id: tuple[str, int] | None = None) -> bytes:
    data = np.array([3], "u1").tobytes() + np.array(indices, index_type).tobytes()
    return data + (np.array([object_id[1]], object_id[0]).tobytes() if object_id else b"")


@pytest.mark.parametrize(("data", "field", "words"), [
    (_ply_frame_bytes(vertex_count=99999999999999999999), "vertex", ("99999999999999999999 vertex rows",)),
    (_ply_frame_bytes(face_count=10**12), "face", ("1000000000000 face rows",)),
    (_ply_frame_bytes(face_count=-1), "header", ("'element face -1'", "count >= 0")),
    (_ply_frame_bytes(vertex_count="1e3"), "header", ("'element vertex 1e3'",)),
    (_ply_frame_bytes(comment="comment pscc cloth_vertices x cloth_faces 1\n"), "comment", ("not a count",)),
    (_ply_frame_bytes(index_type="uint", face=_face([0, 1, 2**32 - 1], "<u4")), "face 0",
     ("4294967295", "outside the cloth vertices [0, 3)")),
    (_ply_frame_bytes(face=_face([0, 1, 7])), "face 0", ("[0, 1, 7]", "outside the cloth vertices")),
    (_ply_frame_bytes(id_type="uint", face=_face([0, 1, 2], object_id=("<u4", 2**32 - 1))), "face 0",
     ("object id 4294967295", "[0, 2147483647]")),
    (_ply_frame_bytes(id_type="int", face=_face([0, 1, 2], object_id=("<i4", -4))), "face 0", ("object id -4",)),
    (_ply_frame_bytes(points=np.array([[0, 0, 0], [np.inf, 0, 0], [0, 1, 0]])), "vertex 1", ("NaN or Inf",)),
])
def test_ply_frame_reader_refuses_overflow_and_absurd_counts(tmp_path: Path, data: bytes, field: str,
                                                             words: tuple[str, ...]) -> None:
    path = tmp_path / "frame.ply"
    path.write_bytes(data)
    with pytest.raises(InputError) as info:
        read_ply_frame(path)
    error = info.value
    assert (error.source, error.field) == (str(path), field), str(error)
    assert all(word in error.problem for word in words), str(error)
    assert error.fix


def test_frame_readers_keep_the_largest_object_id(tmp_path: Path) -> None:
    (cloth, _), = frames(1, False)
    ids = np.array([0, 0, 2**31 - 1], dtype=np.int32)
    np.testing.assert_array_equal(read_obj_frame(write_obj_frame(tmp_path, 0, cloth, CLOTH_FACES, ids))["object_ids"],
                                  ids)
    path = tmp_path / "largest.ply"
    path.write_bytes(_ply_frame_bytes(id_type="int", face=_face([0, 1, 2], object_id=("<i4", 2**31 - 1))))
    assert read_ply_frame(path)["object_ids"].tolist() == [2**31 - 1]


def test_writers_give_obstacles_a_free_id_beside_the_largest_cloth_id(tmp_path: Path) -> None:
    (cloth, others), = frames(1, True)
    ids = np.array([0, 0, 2**31 - 1], dtype=np.int32)
    frame = read_ply_frame(write_ply_frame(tmp_path, 0, cloth, CLOTH_FACES, ids, others, OBSTACLE_FACES))
    assert frame["object_ids"].tolist() == ids.tolist()
    with UsdAnimationWriter(tmp_path / "a.usd", CLOTH_FACES, ids, OBSTACLE_FACES, FPS) as writer:
        writer.add_frame(0, cloth, others)
    assert len(read_usd_frames(tmp_path / "a.usd")) == 1
