"""Animated meshes in one file: an NPZ array of frames, or a USD mesh with time-sampled points.

Bodies that garments are draped on usually come as an animation: a character exported from a DCC tool
to USD, or a NumPy array of per-frame positions. :func:`load_animation` reads either into an
:class:`Animation` (positions of every frame, the triangles, and the file's frame rate when it has one),
which a scene file plays as a sequence obstacle (``sequence = "body.usd"``, ``docs/scene-files.md``).

* NPZ: keys ``frames`` (k, n, 3) and ``faces`` (m, 3); optional ``frame_rate`` (frames per second).
* USD (``.usd``, ``.usda``, ``.usdc``, ``.usdz``): the ``UsdGeom.Mesh`` at ``prim`` (default: the first
  mesh whose ``points`` are time-sampled, else the first mesh). Every face must be a triangle. Each time
  sample of ``points`` is a frame, moved by the prim's local-to-world transform at that time and scaled
  to metres by the stage's ``metersPerUnit``; the samples must be evenly spaced, and the frame rate is
  ``timeCodesPerSecond`` over their spacing. Skinned meshes (UsdSkel) must be baked to point samples.

Errors name the file, the key or prim, and the fix.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from pscc.errors import InputError
from pscc.mesh.io import open_usd_stage
from pscc.mesh.mesh_data import validate_mesh

__all__ = ["ANIMATION_EXTENSIONS", "Animation", "load_animation"]

ANIMATION_EXTENSIONS: tuple[str, ...] = (".npz", ".usd", ".usda", ".usdc", ".usdz")
"""Extensions :func:`load_animation` reads (case-insensitive)."""


@dataclass(frozen=True)
class Animation:
    """An animated triangle mesh.

    Attributes:
        frames: (k, n, 3) float64 positions of each frame, k >= 1.
        faces: (m, 3) int32 vertex ids, the same in every frame.
        frame_rate: frames per second the file gives, or None (the scene then decides).
        source: the file it came from.
    """

    frames: np.ndarray
    faces: np.ndarray
    frame_rate: float | None
    source: str


def load_animation(path: str | os.PathLike[str], prim: str | None = None) -> Animation:
    """Read an animated mesh from an NPZ or USD file (module docstring).

    Args:
        path: the file.
        prim: USD only: the path of the mesh prim (default: the first animated mesh).

    Returns:
        The :class:`Animation`; every frame passes :func:`pscc.mesh.validate_mesh` with the faces.

    Raises:
        InputError: the file is missing or unreadable, a key or the prim is missing, a face is not a
            triangle, frames differ in vertex count, coordinates are not finite, or USD time samples
            are unevenly spaced.
    """
    file = Path(path)
    source = str(file)
    extension = file.suffix.lower()
    if extension not in ANIMATION_EXTENSIONS:
        raise InputError(source, "path", f"extension {file.suffix!r} is not an animation format",
                         f"use one of {', '.join(ANIMATION_EXTENSIONS)}")
    if not file.is_file():
        raise InputError(source, "path", "does not exist or is not a file", "check the path")
    if extension == ".npz":
        if prim is not None:
            raise InputError(source, "prim", "applies to USD files only", "remove it")
        animation = _load_npz(file)
    else:
        animation = _load_usd(file, prim)
    for k in (0, animation.frames.shape[0] - 1):  # the mesh checks (ranges, faces) on the first and last frame
        validate_mesh(animation.frames[k], animation.faces, source=source)
    return animation


def _load_npz(file: Path) -> Animation:
    source = str(file)
    try:
        with np.load(file, allow_pickle=False) as archive:
            missing = [key for key in ("frames", "faces") if key not in archive.files]
            if missing:
                raise InputError(source, missing[0], f"required key {missing[0]!r} is missing (keys: "
                                 f"{sorted(archive.files)})", "save frames=(k, n, 3) positions and faces=(m, 3) ids")
            frames = np.asarray(archive["frames"], dtype=np.float64)
            faces = np.asarray(archive["faces"])
            rate = None
            if "frame_rate" in archive.files:
                rate = float(np.asarray(archive["frame_rate"]).reshape(-1)[0])
    except (OSError, ValueError, EOFError) as exc:
        raise InputError(source, "file", f"is not a readable NPZ archive ({exc})",
                         "write it with numpy.savez(path, frames=..., faces=...)") from exc
    if frames.ndim != 3 or frames.shape[0] < 1 or frames.shape[2] != 3:
        raise InputError(source, "frames", f"shape {frames.shape} is not (k, n, 3) with k >= 1",
                         "save one (n, 3) array of positions per frame, stacked: (frames, vertices, 3)")
    if not np.all(np.isfinite(frames)):
        frame = int(np.flatnonzero(~np.isfinite(frames).all(axis=(1, 2)))[0])
        raise InputError(source, "frames", f"frame {frame} holds NaN or Inf", "repair or drop that frame")
    if faces.dtype.kind not in "iu":
        raise InputError(source, "faces", f"dtype {faces.dtype} is not an integer type", "save integer vertex ids")
    if rate is not None and not (np.isfinite(rate) and rate > 0.0):
        raise InputError(source, "frame_rate", f"{rate!r} is not a number > 0", "save frames per second, e.g. 30")
    return Animation(frames=frames, faces=faces.astype(np.int32), frame_rate=rate, source=source)


def _load_usd(file: Path, prim_path: str | None) -> Animation:
    from pxr import Usd, UsdGeom

    source = str(file)
    stage = open_usd_stage(file, "export the body as USD (usda/usdc/usdz)")
    if prim_path is not None:
        prim = stage.GetPrimAtPath(prim_path)
        if not prim or not prim.IsA(UsdGeom.Mesh):
            meshes = [str(p.GetPath()) for p in stage.Traverse() if p.IsA(UsdGeom.Mesh)]
            raise InputError(source, "prim", f"{prim_path!r} is not a mesh prim of the stage (meshes: {meshes[:8]})",
                             "give the path of the body's UsdGeom.Mesh")
    else:
        meshes = [p for p in stage.Traverse() if p.IsA(UsdGeom.Mesh)]
        if not meshes:
            raise InputError(source, "file", "holds no UsdGeom.Mesh", "export the body as a polygon mesh")
        animated = [p for p in meshes if UsdGeom.Mesh(p).GetPointsAttr().GetNumTimeSamples() > 0]
        prim = (animated or meshes)[0]
    mesh = UsdGeom.Mesh(prim)
    where = str(prim.GetPath())
    counts = np.asarray(mesh.GetFaceVertexCountsAttr().Get() or [], dtype=np.int64)
    indices = np.asarray(mesh.GetFaceVertexIndicesAttr().Get() or [], dtype=np.int64)
    if counts.size == 0 or np.any(counts != 3):
        bad = int(np.flatnonzero(counts != 3)[0]) if counts.size else 0
        raise InputError(source, where, f"face {bad} has {int(counts[bad]) if counts.size else 0} vertices; faces "
                         "must be triangles", "triangulate the mesh before exporting it")
    faces = indices.reshape(-1, 3)
    points = mesh.GetPointsAttr()
    times = list(points.GetTimeSamples()) or [Usd.TimeCode.Default()]
    cache = UsdGeom.XformCache()
    scale = float(UsdGeom.GetStageMetersPerUnit(stage))
    frames = []
    for time in times:
        values = points.Get(time)
        if values is None:
            raise InputError(source, where, f"has no points at time {time}", "export the points at every frame")
        local = np.asarray(values, dtype=np.float64).reshape(-1, 3)
        cache.SetTime(time if isinstance(time, Usd.TimeCode) else Usd.TimeCode(time))
        matrix = np.asarray(cache.GetLocalToWorldTransform(prim), dtype=np.float64).reshape(4, 4)
        world = local @ matrix[:3, :3] + matrix[3, :3]  # USD matrices act on row vectors
        if frames and world.shape != frames[0].shape:
            raise InputError(source, where, f"the points at time {time} number {world.shape[0]}, not "
                             f"{frames[0].shape[0]}", "export every frame with the same vertices")
        frames.append(world * scale)
    rate = None
    if len(times) > 1:
        steps = np.diff(np.asarray(times, dtype=np.float64))
        if np.ptp(steps) > 1e-6 * float(steps.mean()):
            raise InputError(source, where, f"the time samples of its points are unevenly spaced (steps from "
                             f"{steps.min():g} to {steps.max():g} time codes)", "export one sample per frame")
        rate = float(stage.GetTimeCodesPerSecond()) / float(steps.mean())
    stacked = np.stack(frames)
    if not np.all(np.isfinite(stacked)):
        raise InputError(source, where, "a point holds NaN or Inf", "repair the exported points")
    return Animation(frames=stacked, faces=faces.astype(np.int32), frame_rate=rate, source=source)
