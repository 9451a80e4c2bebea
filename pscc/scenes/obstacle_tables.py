"""The obstacles of a scene file (``[[obstacle]]``: meshes, spheres, boxes, per-frame sequences and animation
files) and the keyframed motions of obstacles and cloth handles, checked key by key
(``docs/scene-files.md``)."""

from __future__ import annotations

import re
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from pscc.errors import InputError
from pscc.mesh.animation import ANIMATION_EXTENSIONS, Animation, load_animation
from pscc.mesh.generate import icosphere
from pscc.scenes.scene_motions import SequenceObstacle
from pscc.scenes.table_reader import PLACEMENT_KEYS, TableReader, show
from pscc.sim.obstacles import KeyframedMotion, Obstacle

_OBSTACLE_KEYS = ("name", "mesh", "sphere", "box", "sequence", "sequence_frame_rate", "sequence_prim",
                  *PLACEMENT_KEYS, "keyframes")
_OBSTACLE_SHAPES = ("mesh", "sphere", "box", "sequence")
_SPHERE_KEYS = ("radius", "subdivisions")
_BOX_KEYS = ("size",)
KEYFRAME_KEYS = ("times", "translations", "rotations")
"""Keys of a keyframes table (obstacles) and of a cloth handle's motion."""


class ObstacleTables(TableReader):
    """The obstacle and keyframe part of :class:`pscc.scenes.scene_builder.SceneBuilder`."""

    # ------------------------------------------------------------ keyframes

    def keyframes(self, table: Mapping[str, Any], key: str) -> dict[str, Any]:
        """Resolved ``times`` / ``translations`` / ``rotations`` (degrees) of a table holding them."""
        if "times" not in table:
            raise self.error(f"{key}.times", "is missing",
                             "give the keyframe times in seconds, e.g. times = [0.0, 1.0]")
        times_raw = table["times"]
        if not isinstance(times_raw, list) or not times_raw:
            raise self.error(f"{key}.times", f"expected a non-empty array of times, got {show(times_raw)}",
                             "write times = [0.0, 1.0] (seconds, increasing)")
        times = [self.number(t, f"{key}.times[{i}]") for i, t in enumerate(times_raw)]
        for i in range(1, len(times)):
            if not times[i] > times[i - 1]:
                raise self.error(f"{key}.times", f"times[{i}] = {times[i]:g} is not greater than times[{i - 1}] = "
                                 f"{times[i - 1]:g}", "list the keyframe times in strictly increasing order")
        zeros = [[0.0, 0.0, 0.0] for _ in times]
        translations = self.rows(table.get("translations", zeros), f"{key}.translations", len(times), "translation")
        rotations = self.rows(table.get("rotations", zeros), f"{key}.rotations", len(times), "rotation vector")
        return {"times": times, "translations": translations, "rotations": rotations}

    def keyframed_motion(self, keyframes: Mapping[str, Any], key: str,
                         offset: np.ndarray | None = None) -> KeyframedMotion:
        translations = np.asarray(keyframes["translations"], dtype=np.float64)
        if offset is not None:
            translations = translations + offset
        try:
            return KeyframedMotion(times=np.asarray(keyframes["times"], dtype=np.float64), translations=translations,
                                   rotations=np.radians(np.asarray(keyframes["rotations"], dtype=np.float64)))
        except InputError as exc:
            raise self.rewrap_field(exc, key) from exc

    # ------------------------------------------------------------ obstacles

    def obstacle(self, raw: dict[str, Any], index: int, frame_time: float) -> tuple[Any, dict[str, Any]]:
        key = f"obstacle[{index}]"
        self.check_keys(raw, _OBSTACLE_KEYS, key, hints={
            "times": "put times in the keyframes table: keyframes = { times = [...], translations = [...] }",
            "translations": "put translations in the keyframes table",
            "rotations": "put rotations in the keyframes table",
            "radius": "write sphere = { radius = 0.25 }", "material": "obstacles have no material"})
        name = self.string(raw.get("name", f"obstacle{index}"), f"{key}.name")
        spec: dict[str, Any] = {"name": name}
        shapes = [s for s in _OBSTACLE_SHAPES if s in raw]
        if len(shapes) != 1:
            problem = f"has {' and '.join(shapes)}" if shapes else "has no shape"
            raise self.error(key, problem, "give exactly one of mesh = \"file.obj\", sphere = { radius = 0.25 }, "
                             "box = { size = [1.0, 1.0, 0.1] } or sequence = \"body/frame_*.obj\"")
        shape = shapes[0]
        placement, rotation, translation, scale = self.placement(raw, key)
        for sequence_only in ("sequence_frame_rate", "sequence_prim"):
            if sequence_only in raw and shape != "sequence":
                raise self.error(f"{key}.{sequence_only}", f"{sequence_only} applies to sequence obstacles only",
                                 "remove it, or give the body as sequence = \"body.usd\" (or frame files)")
        if shape == "sequence":
            if "keyframes" in raw:
                raise self.error(f"{key}.keyframes", "a mesh sequence cannot also have keyframes",
                                 "remove keyframes (the sequence's files give the motion) or use mesh = \"file\"")
            animation = self.animation(raw, key)
            if animation is not None:
                frames, faces, file_rate = animation.frames, animation.faces, animation.frame_rate
                spec["sequence"] = animation.source
                if "sequence_prim" in raw:
                    spec["sequence_prim"] = raw["sequence_prim"]
            else:
                files, frames, faces = self.sequence(raw["sequence"], f"{key}.sequence")
                spec["sequence"] = [str(f) for f in files]
                file_rate = None
            rate = file_rate
            if "sequence_frame_rate" in raw:
                rate = self.number(raw["sequence_frame_rate"], f"{key}.sequence_frame_rate", minimum=0.0,
                                   example="30.0")
            sequence_time = frame_time  # frame k of the sequence plays at scene frame k
            if rate is not None:
                sequence_time = 1.0 / rate
                spec["sequence_frame_rate"] = rate
            placed = (scale * frames) @ rotation.T + translation
            spec.update(placement)
            return SequenceObstacle(placed, faces, frame_time=sequence_time, name=name), spec
        if shape == "mesh":
            mesh_path, mesh = self.mesh(raw["mesh"], f"{key}.mesh")
            local, faces = mesh.vertices.astype(np.float64), mesh.faces
            spec["mesh"] = str(mesh_path)
        elif shape == "sphere":
            table = self.table(raw["sphere"], f"{key}.sphere", "sphere = { radius = 0.25, subdivisions = 2 }")
            self.check_keys(table, _SPHERE_KEYS, f"{key}.sphere")
            if "radius" not in table:
                raise self.error(f"{key}.sphere.radius", "is missing", "write sphere = { radius = 0.25 } (metres)")
            radius = self.number(table["radius"], f"{key}.sphere.radius", minimum=0.0, example="0.25")
            subdivisions = self.integer(table.get("subdivisions", 2), f"{key}.sphere.subdivisions",
                                        minimum=0, maximum=5)
            local, faces = icosphere(radius, subdivisions)
            local = local.astype(np.float64)
            spec["sphere"] = {"radius": radius, "subdivisions": subdivisions}
        else:
            table = self.table(raw["box"], f"{key}.box", "box = { size = [1.0, 1.0, 0.1] }")
            self.check_keys(table, _BOX_KEYS, f"{key}.box")
            if "size" not in table:
                raise self.error(f"{key}.box.size", "is missing", "write box = { size = [sx, sy, sz] } (metres)")
            size = self.vector(table["size"], f"{key}.box.size", 3, minimum=0.0, example="[1.0, 1.0, 0.1]")
            local, faces = _box(size)
            spec["box"] = {"size": size}
        spec.update(placement)
        shaped = (scale * local) @ rotation.T
        if "keyframes" in raw:
            table = self.table(raw["keyframes"], f"{key}.keyframes",
                               "keyframes = { times = [0.0, 1.0], translations = [[0, 0, 0], [0, 0, 0.1]] }")
            self.check_keys(table, KEYFRAME_KEYS, f"{key}.keyframes")
            keyframes = self.keyframes(table, f"{key}.keyframes")
            spec["keyframes"] = keyframes
            motion = self.keyframed_motion(keyframes, f"{key}.keyframes", offset=translation)
            return Obstacle(shaped, faces, motion=motion, name=name), spec
        return Obstacle(shaped + translation, faces, name=name), spec

    def animation(self, raw: Mapping[str, Any], key: str) -> Animation | None:
        """The animation file of ``sequence = "body.usd"`` (or an NPZ with a ``frames`` key), or None when
        the sequence is a list or pattern of per-frame mesh files."""
        value = raw["sequence"]
        if not isinstance(value, str) or any(c in value for c in "*?[") \
                or Path(value).suffix.lower() not in ANIMATION_EXTENSIONS:
            if "sequence_prim" in raw:
                raise self.error(f"{key}.sequence_prim", "sequence_prim applies to a USD animation only",
                                 "remove it, or give the body as sequence = \"body.usd\"")
            return None
        path = self.file_path(value, f"{key}.sequence")
        if path.suffix.lower() == ".npz":
            try:
                with np.load(path, allow_pickle=False) as archive:
                    if "frames" not in archive.files:
                        return None  # one mesh file: a sequence of one frame
            except (OSError, ValueError, EOFError):
                return None  # the mesh loader names the problem
        prim = None
        if "sequence_prim" in raw:
            prim = self.string(raw["sequence_prim"], f"{key}.sequence_prim")
        try:
            return load_animation(path, prim)
        except InputError as error:
            raise self.error(f"{key}.sequence", f"{str(path)!r}: {error.field}: {error.problem}", error.fix) from None

    def sequence(self, value: Any, key: str) -> tuple[list[Path], np.ndarray, np.ndarray]:
        """Files, (k, n, 3) float64 positions and faces of a mesh sequence (glob pattern or list of files)."""
        if isinstance(value, str):
            pattern = self.file_path(value, key)
            try:
                files = _natural_sorted(_glob(pattern))
            except OSError as error:
                raise self.error(key, f"the pattern {str(pattern)!r} cannot be searched ({error.strerror or error} "
                                 f"at {error.filename})", "use a pattern that stays inside the folder of the "
                                 "body's frames, e.g. \"body/frame_*.obj\"") from None
            if not files:
                raise self.error(key, f"the pattern {str(pattern)!r} matches no file",
                                 "check the pattern; it is relative to the scene file's folder, e.g. "
                                 "\"body/frame_*.obj\"")
        elif isinstance(value, list) and value:
            files = [self.file_path(item, f"{key}[{i}]") for i, item in enumerate(value)]
        else:
            raise self.error(key, f"expected a glob pattern or a non-empty array of files, got {show(value)}",
                             "write sequence = \"body/frame_*.obj\" (one mesh file per frame)")
        frames: list[np.ndarray] = []
        faces: np.ndarray | None = None
        for i, file in enumerate(files):
            where = f"{key}[{i}]" if isinstance(value, list) else key
            _, mesh = self.mesh(str(file), where)
            if faces is None:
                faces = mesh.faces
            elif mesh.vertex_count != frames[0].shape[0] or not np.array_equal(mesh.faces, faces):
                raise self.error(where, f"{str(file)!r} (frame {i}) does not have the topology of frame 0 "
                                 f"{str(files[0])!r} ({mesh.vertex_count} vertices / {mesh.face_count} faces vs "
                                 f"{frames[0].shape[0]} / {faces.shape[0]})",
                                 "export every frame with the same vertices and faces, in the same order")
            frames.append(mesh.vertices.astype(np.float64))
        assert faces is not None
        return files, np.stack(frames), faces


def _box(size: list[float]) -> tuple[np.ndarray, np.ndarray]:
    """A closed box centred at the origin: 8 vertices, 12 outward (counter-clockwise) triangles."""
    half = np.asarray(size, dtype=np.float64) / 2.0
    corners = np.array([[x, y, z] for x in (-1.0, 1.0) for y in (-1.0, 1.0) for z in (-1.0, 1.0)]) * half
    faces = np.array([[0, 1, 3], [0, 3, 2], [4, 6, 7], [4, 7, 5], [0, 4, 5], [0, 5, 1],
                      [2, 3, 7], [2, 7, 6], [0, 2, 6], [0, 6, 4], [1, 5, 7], [1, 7, 3]], dtype=np.int32)
    return corners, faces


def _glob(pattern: Path) -> list[Path]:
    """Files matching ``pattern`` (``OSError`` when a folder on the way cannot be searched)."""
    anchor = Path(pattern.anchor)
    relative = str(pattern.relative_to(anchor))
    return [p for p in anchor.glob(relative) if p.is_file()]


def _natural_sorted(paths: list[Path]) -> list[Path]:
    """Sorted so that ``frame_2`` comes before ``frame_10``."""

    def key(path: Path) -> list[Any]:
        return [(0, int(part), "") if part.isdigit() else (1, 0, part) for part in re.split(r"(\d+)", str(path))]

    return sorted(paths, key=key)
