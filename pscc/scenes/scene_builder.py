"""Checking and building scene files: the TOML data of a scene file -> Scene, ContactConfig, resolved spec.

:class:`SceneBuilder` walks the tables of ``docs/scene-files.md`` key by key; every problem raises
:class:`pscc.errors.InputError` naming the scene file, the key path (``cloth[1].material.density``),
the problem and the fix. :mod:`pscc.scenes.scene_file` is the public entry point.
"""

from __future__ import annotations

import difflib
import math
import os
import re
from collections.abc import Iterable, Mapping
from dataclasses import Field, dataclass, field, fields
from pathlib import Path
from typing import Any

import numpy as np

from pscc._memory import SIMULATION_BYTES_PER_TRIANGLE, check_fits
from pscc.errors import InputError
from pscc.mesh.animation import ANIMATION_EXTENSIONS, Animation, load_animation
from pscc.mesh.generate import grid_sheet, icosphere
from pscc.mesh.io import SUPPORTED_EXTENSIONS, load_mesh
from pscc.mesh.mesh_data import MeshData
from pscc.scenes.scene_motions import PivotedMotion, SequenceObstacle
from pscc.scenes.seam_builder import boundary_path, sew
from pscc.scenes.toml_text import config_to_toml, field_kind
from pscc.sim.config import SIM_MIN_REST_AREA_RATIO, ClothMaterial, SolverConfig
from pscc.sim.contact_config import ContactConfig
from pscc.sim.obstacles import Handle, KeyframedMotion, Obstacle, rotation_from_axis_angle, static_motion
from pscc.sim.scene import Scene
from pscc.tolerances import MIN_COORDINATE_SCALE

DEFAULT_FRAMES: int = 30
"""Frames of a run when ``[scene] frames`` is not given."""

DEFAULT_FRAME_RATE: float = 30.0
"""Frames per second when neither ``frame_rate`` nor ``frame_time`` is given [1/s]."""

DEFAULT_STEPS_PER_FRAME: int = 8
"""Time steps per frame when ``steps_per_frame`` is not given."""

MAX_STEPS_PER_FRAME = 100_000
"""Largest ``steps_per_frame`` a scene file may ask for."""

MIN_TIME_STEP = 1.0e-7
"""Smallest time step [s] a scene file may ask for (below it a run of one second takes 10 million steps)."""

MAX_SCENE_NUMBER = 1.0e9
"""Largest magnitude of any number in a scene file (lengths, angles in degrees, times, rates): beyond it
positions leave the detector's float32 range (``tolerances.MAX_COORDINATE``)."""

FLATNESS_TOLERANCE: float = 1.0e-4
"""A mesh counts as flat (so its rest shape can be its projection onto the best-fit plane) when no
vertex is farther from that plane than this fraction of the mesh's largest extent. Dimensionless."""

SIDE_TOLERANCE: float = 1.0e-4
"""Default tolerance of the ``side`` selector, as a fraction of the piece's largest rest extent."""

POSE_TOLERANCE: float = 1.0e-9
"""A handle's keyframed pose at t = 0 must be the identity within this (rotation entries; translation
in metres): handle keyframes are displacements from the initial positions."""

SIDES: tuple[str, ...] = ("left", "right", "bottom", "top")
"""Side names of the ``side`` selector: smallest u, largest u, smallest v, largest v (rest coordinates)."""

CORNERS: tuple[str, ...] = ("bottom-left", "bottom-right", "top-left", "top-right")
"""Corner names of the ``corner`` selector (rest coordinates; bottom/top = v, left/right = u)."""

_REST_MODES: tuple[str, ...] = ("auto", "uv", "file", "plane", "mesh")
_REST_BENDING: tuple[str, ...] = ("mesh", "flat")
UV_AREA_RATIO_LIMIT: float = 4.0
"""``rest = "uv"`` is refused when the pattern's area (times ``uv_scale`` squared) and the mesh's differ by
more than this factor: the texture coordinates are then not in metres (the message gives the
``uv_scale`` that matches the areas)."""

_TOP_KEYS = ("scene", "solver", "contact", "cloth", "obstacle")
_SCENE_KEYS = ("name", "description", "frame_rate", "frame_time", "steps_per_frame", "frames")
_PLACEMENT_KEYS = ("translate", "rotate", "scale")
_CLOTH_KEYS = ("name", "mesh", "rest", "uv_scale", "rest_bending", "sheet", *_PLACEMENT_KEYS, "material", "pins",
               "handles", "stitches")
_STITCH_KEYS = ("vertices", "to", "to_piece", "reverse")
_SHEET_KEYS = ("size", "cells")
_HANDLE_KEYS = ("name", "vertices", "times", "translations", "rotations", "pivot")
_OBSTACLE_KEYS = ("name", "mesh", "sphere", "box", "sequence", "sequence_frame_rate", "sequence_prim",
                  *_PLACEMENT_KEYS, "keyframes")
_OBSTACLE_SHAPES = ("mesh", "sphere", "box", "sequence")
_SPHERE_KEYS = ("radius", "subdivisions")
_BOX_KEYS = ("size",)
_KEYFRAME_KEYS = ("times", "translations", "rotations")
_SELECTOR_KEYS = ("ids", "side", "corner", "box", "tolerance")



@dataclass
class SceneFile:
    """A loaded scene file.

    Attributes:
        path: absolute path of the TOML file.
        spec: the resolved scene as plain TOML data (every key with its value, defaults filled in,
            vertex selections as ids, paths absolute); :func:`resolved_scene_toml` writes it.
        scene: the scene to simulate.
        contact: the contact settings.
        options: run options: ``frames`` (default frame count) and ``source`` (``str(path)``).
    """

    path: Path
    spec: dict[str, Any]
    scene: Scene
    contact: ContactConfig
    options: dict[str, Any] = field(default_factory=dict)


@dataclass
class _Piece:
    """One cloth piece before concatenation (local vertex ids)."""

    name: str
    vertices: np.ndarray  # (n, 3) float32, placed
    faces: np.ndarray  # (m, 3) int32
    rest: np.ndarray  # (n, 2) pattern or (n, 3) rest shape, float32
    material: ClothMaterial
    flat_bending: bool = False  # rest angles 0 although the rest shape is 3-D
    stitches: np.ndarray | None = None  # (s, 4) rows (i, j, k, r), local ids
    seam_tables: list[dict[str, Any]] = field(default_factory=list)  # [[cloth.stitches]], resolved later
    handles: list[tuple[str, np.ndarray, Any]] = field(default_factory=list)  # (name, local ids, motion or None)


def _type_name(value: Any) -> str:
    if isinstance(value, bool):
        return "boolean"
    if isinstance(value, int):
        return "integer"
    if isinstance(value, float):
        return "float"
    if isinstance(value, str):
        return "string"
    if isinstance(value, list):
        return "array"
    if isinstance(value, dict):
        return "table"
    return type(value).__name__


def _show(value: Any, limit: int = 60) -> str:
    text = repr(value)
    return text if len(text) <= limit else text[: limit - 3] + "..."


class SceneBuilder:
    """Checks a parsed scene file and builds the scene and the resolved spec."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self.source = str(path)
        self.base = path.parent

    # ------------------------------------------------------------ error helpers

    def error(self, key: str, problem: str, fix: str) -> InputError:
        return InputError(self.source, key, problem, fix)

    def rewrap(self, exc: InputError, key: str) -> InputError:
        """An InputError from a lower layer, reported at ``key`` of this file."""
        inner = "" if exc.source in ("argument", "motion", "ClothMaterial", "SolverConfig", "ContactConfig") \
            else f"{exc.source}: "
        return InputError(self.source, key, f"{inner}{exc.field}: {exc.problem}", exc.fix)

    def table(self, value: Any, key: str, example: str) -> dict[str, Any]:
        if not isinstance(value, dict):
            raise self.error(key, f"expected a table, got {_type_name(value)} {_show(value)}", f"write it as {example}")
        return value

    def check_keys(self, table: Mapping[str, Any], allowed: Iterable[str], key: str,
                   hints: Mapping[str, str] | None = None) -> None:
        allowed = tuple(allowed)
        for name in table:
            if name in allowed:
                continue
            where = f"{key}.{name}" if key else name
            if hints and name in hints:
                raise self.error(where, f"unknown key {name!r} here", hints[name])
            close = difflib.get_close_matches(name, allowed, n=1, cutoff=0.6)
            listing = ", ".join(allowed)
            fix = (f"did you mean {close[0]!r}? (allowed keys here: {listing})" if close
                   else f"remove it or use one of the allowed keys: {listing}")
            raise self.error(where, f"unknown key {name!r}", fix)

    def number(self, value: Any, key: str, *, minimum: float | None = None, strict: bool = True,
               example: str = "1.0") -> float:
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise self.error(key, f"expected a number, got {_type_name(value)} {_show(value)}",
                             f"write a number, e.g. {key.rsplit('.', 1)[-1]} = {example}")
        number = float(value)
        if not math.isfinite(number):
            raise self.error(key, f"{value!r} is not finite", "write a finite number")
        if abs(number) > MAX_SCENE_NUMBER:
            raise self.error(key, f"{value!r} is beyond +-{MAX_SCENE_NUMBER:g}, outside what the simulator can "
                             "represent (tolerances.MAX_COORDINATE)", f"write a number of magnitude <= "
                             f"{MAX_SCENE_NUMBER:g}")
        if minimum is not None and (number <= minimum if strict else number < minimum):
            relation = ">" if strict else ">="
            raise self.error(key, f"{value!r} is not {relation} {minimum:g}", f"write a number {relation} {minimum:g}")
        return number

    def integer(self, value: Any, key: str, *, minimum: int | None = None, maximum: int | None = None) -> int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise self.error(key, f"expected an integer, got {_type_name(value)} {_show(value)}",
                             "write a whole number without a decimal point, e.g. 8")
        if (minimum is not None and value < minimum) or (maximum is not None and value > maximum):
            bounds = f"in [{minimum}, {maximum}]" if maximum is not None else f">= {minimum}"
            raise self.error(key, f"{value} is not {bounds}", f"write an integer {bounds}")
        return int(value)

    def string(self, value: Any, key: str, choices: Iterable[str] | None = None) -> str:
        if not isinstance(value, str):
            raise self.error(key, f"expected a string, got {_type_name(value)} {_show(value)}",
                             'write it in double quotes, e.g. "text"')
        if choices is not None:
            choices = tuple(choices)
            if value not in choices:
                close = difflib.get_close_matches(value, choices, n=1, cutoff=0.6)
                hint = f"did you mean {close[0]!r}? " if close else ""
                raise self.error(key, f"{value!r} is not one of {', '.join(map(repr, choices))}",
                                 f"{hint}use one of {', '.join(map(repr, choices))}")
        return value

    def boolean(self, value: Any, key: str) -> bool:
        if not isinstance(value, bool):
            raise self.error(key, f"expected true or false, got {_type_name(value)} {_show(value)}",
                             "write true or false (lower case, no quotes)")
        return value

    def vector(self, value: Any, key: str, length: int, *, minimum: float | None = None,
               example: str = "[0.0, 0.0, 0.0]") -> list[float]:
        if not isinstance(value, list) or len(value) != length:
            got = f"{len(value)} entries" if isinstance(value, list) else f"{_type_name(value)} {_show(value)}"
            raise self.error(key, f"expected an array of {length} numbers, got {got}", f"write e.g. {example}")
        return [self.number(item, f"{key}[{i}]", minimum=minimum) for i, item in enumerate(value)]

    def int_vector(self, value: Any, key: str, length: int, minimum: int, example: str) -> list[int]:
        if not isinstance(value, list) or len(value) != length:
            got = f"{len(value)} entries" if isinstance(value, list) else f"{_type_name(value)} {_show(value)}"
            raise self.error(key, f"expected an array of {length} integers, got {got}", f"write e.g. {example}")
        return [self.integer(item, f"{key}[{i}]", minimum=minimum) for i, item in enumerate(value)]

    def rows(self, value: Any, key: str, count: int, what: str) -> list[list[float]]:
        if not isinstance(value, list):
            raise self.error(key, f"expected an array of [x, y, z] rows, got {_type_name(value)} {_show(value)}",
                             f"write one [x, y, z] {what} per keyframe time")
        if len(value) != count:
            raise self.error(key, f"has {len(value)} rows but times has {count}",
                             f"give one [x, y, z] {what} per keyframe time ({count})")
        return [self.vector(row, f"{key}[{i}]", 3) for i, row in enumerate(value)]

    def file_path(self, value: Any, key: str) -> Path:
        text = self.string(value, key)
        if not text:
            raise self.error(key, "is empty", "write the path of a file, relative to the scene file")
        candidate = Path(os.path.expanduser(text))
        return Path(os.path.abspath(candidate if candidate.is_absolute() else self.base / candidate))

    def mesh(self, value: Any, key: str) -> tuple[Path, MeshData]:
        mesh_path = self.file_path(value, key)
        if mesh_path.suffix.lower() not in SUPPORTED_EXTENSIONS:
            raise self.error(key, f"{str(mesh_path)!r} has the extension {mesh_path.suffix or '(none)'!r}",
                             f"use a mesh file ending in one of {', '.join(SUPPORTED_EXTENSIONS)}")
        if not mesh_path.is_file():
            raise self.error(key, f"mesh file {str(mesh_path)!r} does not exist",
                             "check the path; relative paths are relative to the scene file's folder "
                             f"{str(self.base)!r}")
        try:
            return mesh_path, load_mesh(mesh_path)
        except InputError as exc:
            raise self.rewrap(exc, key) from exc

    # ------------------------------------------------------------ top level

    def build(self, raw: dict[str, Any]) -> SceneFile:
        self.check_keys(raw, _TOP_KEYS, "", hints={
            "clothes": "write each cloth piece as a [[cloth]] table", "cloths": "write each piece as [[cloth]]",
            "obstacles": "write each obstacle as an [[obstacle]] table",
            **{name: f"put {name} in the [scene] table" for name in _SCENE_KEYS},
        })
        spec: dict[str, Any] = {}
        scene_spec = self.scene_table(raw.get("scene", {}))
        spec["scene"] = scene_spec
        frame_time = (scene_spec["frame_time"] if "frame_time" in scene_spec else 1.0 / scene_spec["frame_rate"])
        solver, spec["solver"] = self.config(raw.get("solver", {}), "solver", SolverConfig)
        contact, spec["contact"] = self.config(raw.get("contact", {}), "contact", ContactConfig)

        if "cloth" not in raw:
            raise self.error("cloth", "the scene has no cloth", "add at least one [[cloth]] table with "
                             "mesh = \"file.obj\" or a [cloth.sheet] table")
        cloth_raw = raw["cloth"]
        if isinstance(cloth_raw, dict):
            raise self.error("cloth", "is a single [cloth] table", "write each piece as [[cloth]] (double brackets)")
        if not isinstance(cloth_raw, list) or not cloth_raw or not all(isinstance(c, dict) for c in cloth_raw):
            raise self.error("cloth", f"expected one or more [[cloth]] tables, got {_show(cloth_raw)}",
                             "write each cloth piece as a [[cloth]] table")
        pieces: list[_Piece] = []
        spec["cloth"] = []
        names: set[str] = set()
        for index, piece_raw in enumerate(cloth_raw):
            piece, piece_spec = self.cloth(piece_raw, index)
            if piece.name in names:
                raise self.error(f"cloth[{index}].name", f"the name {piece.name!r} is used twice",
                                 "give every cloth piece its own name")
            names.add(piece.name)
            pieces.append(piece)
            spec["cloth"].append(piece_spec)

        obstacle_raw = raw.get("obstacle", [])
        if isinstance(obstacle_raw, dict):
            raise self.error("obstacle", "is a single [obstacle] table",
                             "write each obstacle as [[obstacle]] (double brackets)")
        if not isinstance(obstacle_raw, list) or not all(isinstance(o, dict) for o in obstacle_raw):
            raise self.error("obstacle", f"expected [[obstacle]] tables, got {_show(obstacle_raw)}",
                             "write each obstacle as an [[obstacle]] table")
        obstacles: list[Any] = []
        spec["obstacle"] = []
        for index, obstacle_table in enumerate(obstacle_raw):
            obstacle, obstacle_spec = self.obstacle(obstacle_table, index, frame_time)
            if obstacle.name in names:
                raise self.error(f"obstacle[{index}].name", f"the name {obstacle.name!r} is used twice",
                                 "give every cloth piece and obstacle its own name")
            names.add(obstacle.name)
            obstacles.append(obstacle)
            spec["obstacle"].append(obstacle_spec)
        if not spec["obstacle"]:
            del spec["obstacle"]

        vertices, faces, rest, object_ids, handles, flat_bending, stitches = [], [], [], [], [], [], []
        offsets = np.cumsum([0] + [piece.vertices.shape[0] for piece in pieces])
        for index, piece in enumerate(pieces):
            spec["cloth"][index]["stitches"] = []
            for s_index, table in enumerate(piece.seam_tables):
                rows, resolved = self.seam(table, index, pieces, f"cloth[{index}].stitches[{s_index}]")
                target = [p.name for p in pieces].index(resolved["to_piece"])
                rows[:, 0] += offsets[index]
                rows[:, 1:3] += offsets[target]
                stitches.append(rows)
                spec["cloth"][index]["stitches"].append(resolved)
            if not spec["cloth"][index]["stitches"]:
                del spec["cloth"][index]["stitches"]
        offset = 0
        rest_dimension = max(piece.rest.shape[1] for piece in pieces)  # 3 when a piece keeps its 3-D shape
        for index, piece in enumerate(pieces):
            vertices.append(piece.vertices)
            faces.append(piece.faces + offset)
            # A flat pattern in a 3-D rest space: (u, v, 0), the same triangles and zero rest angles.
            rest.append(np.pad(piece.rest, ((0, 0), (0, rest_dimension - piece.rest.shape[1]))))
            flat_bending.append(np.full(piece.faces.shape[0], piece.flat_bending))
            if piece.stitches is not None and piece.stitches.shape[0]:
                stitches.append(piece.stitches + np.array([offset, offset, offset, 0.0]))
            object_ids.append(np.full(piece.faces.shape[0], index, dtype=np.int32))
            for name, ids, motion in piece.handles:
                handles.append(Handle(ids + offset, static_motion if motion is None else motion, name=name))
            offset += piece.vertices.shape[0]
        scene = Scene(
            name=scene_spec["name"], description=scene_spec["description"],
            vertices=np.ascontiguousarray(np.concatenate(vertices), dtype=np.float32),
            faces=np.ascontiguousarray(np.concatenate(faces), dtype=np.int32),
            rest=np.ascontiguousarray(np.concatenate(rest), dtype=np.float32),
            object_ids=np.concatenate(object_ids),
            material=[piece.material for piece in pieces], solver=solver, handles=handles,
            obstacles=obstacles, frame_time=frame_time, steps_per_frame=scene_spec["steps_per_frame"],
            flat_bending=np.concatenate(flat_bending) if any(piece.flat_bending for piece in pieces) else None,
            stitches=np.concatenate(stitches) if stitches else None,
        )
        options = {"frames": scene_spec["frames"], "source": self.source}
        return SceneFile(path=self.path, spec=spec, scene=scene, contact=contact, options=options)

    def scene_table(self, raw: Any) -> dict[str, Any]:
        table = self.table(raw, "scene", "[scene] with name, frame_rate, steps_per_frame, frames")
        solver_names = [f.name for f in fields(SolverConfig)]
        self.check_keys(table, _SCENE_KEYS, "scene",
                        hints={name: f"{name} belongs in the [solver] table" for name in solver_names})
        spec: dict[str, Any] = {
            "name": self.string(table.get("name", self.path.stem), "scene.name"),
            "description": self.string(table.get("description", ""), "scene.description"),
        }
        if "frame_rate" in table and "frame_time" in table:
            raise self.error("scene.frame_time", "both frame_rate and frame_time are given",
                             "give only one of them (frame_time = 1 / frame_rate)")
        if "frame_time" in table:
            spec["frame_time"] = self.number(table["frame_time"], "scene.frame_time", minimum=0.0,
                                             example="0.04  # seconds")
        else:
            spec["frame_rate"] = self.number(table.get("frame_rate", DEFAULT_FRAME_RATE), "scene.frame_rate",
                                             minimum=0.0, example="30  # frames per second")
        spec["steps_per_frame"] = self.integer(table.get("steps_per_frame", DEFAULT_STEPS_PER_FRAME),
                                               "scene.steps_per_frame", minimum=1, maximum=MAX_STEPS_PER_FRAME)
        frame_time = spec["frame_time"] if "frame_time" in spec else 1.0 / spec["frame_rate"]
        if frame_time / spec["steps_per_frame"] < MIN_TIME_STEP:
            raise self.error("scene.steps_per_frame", f"the time step frame_time / steps_per_frame = "
                             f"{frame_time / spec['steps_per_frame']:.3g} s is below {MIN_TIME_STEP:g} s (a run "
                             "would not finish)", "use fewer steps_per_frame or a longer frame_time")
        spec["frames"] = self.integer(table.get("frames", DEFAULT_FRAMES), "scene.frames", minimum=1)
        return spec

    def config(self, raw: Any, key: str, cls: type) -> tuple[Any, dict[str, Any]]:
        """A frozen config dataclass from a table of its fields; returns (config, resolved table)."""
        table = self.table(raw, key, f"[{key}] with fields of {cls.__name__}")
        config_fields = {f.name: f for f in fields(cls)}
        renamed = getattr(cls, "renamed_fields", {})
        hints = {old: f"it was replaced by {new!r}: write {new} = ... (docs/simulator.md)"
                 for old, new in renamed.items()}
        self.check_keys(table, config_fields, key, hints)
        values: dict[str, Any] = {}
        for name, value in table.items():
            values[name] = self.config_value(value, f"{key}.{name}", config_fields[name])
        try:
            config = cls(**values).validate()
        except InputError as exc:
            raise self.rewrap_field(exc, key) from exc
        return config, config_to_toml(config)

    def rewrap_field(self, exc: InputError, key: str) -> InputError:
        return InputError(self.source, f"{key}.{exc.field}", exc.problem, exc.fix)

    def config_value(self, value: Any, key: str, spec_field: Field) -> Any:
        kind = field_kind(spec_field)
        default = spec_field.default
        if kind == "vector":
            return tuple(self.vector(value, key, len(default)))
        if kind == "bool":
            return self.boolean(value, key)
        if kind == "int":
            return self.integer(value, key)
        if kind == "float":
            return self.number(value, key)
        if kind == "auto_float":
            if value == "auto":
                return None
            if isinstance(value, str):
                raise self.error(key, f"{value!r} is neither a number nor \"auto\"",
                                 "write a number or \"auto\" (the automatic value)")
            return self.number(value, key)
        if kind == "str":
            return self.string(value, key)
        return value

    # ------------------------------------------------------------ cloth

    def placement(self, table: Mapping[str, Any], key: str) -> tuple[dict[str, Any], np.ndarray, np.ndarray, float]:
        translate = self.vector(table.get("translate", [0.0, 0.0, 0.0]), f"{key}.translate", 3,
                                example="[0.0, 0.0, 0.5]  # metres")
        rotate = self.vector(table.get("rotate", [0.0, 0.0, 0.0]), f"{key}.rotate", 3,
                             example="[90.0, 0.0, 0.0]  # rotation vector in degrees")
        scale = self.number(table.get("scale", 1.0), f"{key}.scale", minimum=0.0, example="0.01")
        rotation = rotation_from_axis_angle(np.radians(np.asarray(rotate, dtype=np.float64)))
        spec = {"translate": translate, "rotate": rotate, "scale": scale}
        return spec, rotation, np.asarray(translate, dtype=np.float64), scale

    def cloth(self, raw: dict[str, Any], index: int) -> tuple[_Piece, dict[str, Any]]:
        key = f"cloth[{index}]"
        material_names = [f.name for f in fields(ClothMaterial)]
        self.check_keys(raw, _CLOTH_KEYS, key, hints={
            **{name: f"put {name} in the piece's [cloth.material] table ({key}.material.{name})"
               for name in material_names},
            "size": "put size in a [cloth.sheet] table", "cells": "put cells in a [cloth.sheet] table",
            "handle": "write each handle as a [[cloth.handles]] table", "pin": "did you mean 'pins'?",
        })
        name = self.string(raw.get("name", f"cloth{index}"), f"{key}.name")
        spec: dict[str, Any] = {"name": name}
        if ("mesh" in raw) == ("sheet" in raw):
            problem = "has both mesh and sheet" if "mesh" in raw else "has neither mesh nor sheet"
            raise self.error(key, problem, "give either mesh = \"file.obj\" or a [cloth.sheet] table "
                             "with size = [w, h] and cells = [nx, ny]")
        placement, rotation, translation, scale = self.placement(raw, key)
        if "sheet" in raw:
            for mesh_only in ("rest", "uv_scale", "rest_bending"):
                if mesh_only in raw:
                    raise self.error(f"{key}.{mesh_only}", f"{mesh_only} applies to mesh pieces only",
                                     "remove it (a sheet's rest shape is the flat grid)")
            sheet = self.table(raw["sheet"], f"{key}.sheet", "{ size = [1.0, 1.0], cells = [20, 20] }")
            self.check_keys(sheet, _SHEET_KEYS, f"{key}.sheet")
            for required in _SHEET_KEYS:
                if required not in sheet:
                    raise self.error(f"{key}.sheet.{required}", "is missing",
                                     "give size = [width, height] in metres and cells = [nx, ny]")
            size = self.vector(sheet["size"], f"{key}.sheet.size", 2, minimum=0.0, example="[1.0, 1.0]  # metres")
            if min(size) < MIN_COORDINATE_SCALE:
                raise self.error(f"{key}.sheet.size", f"{size} has a side below {MIN_COORDINATE_SCALE:g}, too "
                                 "small for float32 geometry (tolerances.MIN_COORDINATE_SCALE)",
                                 f"give the size in a unit where both sides are at least {MIN_COORDINATE_SCALE:g}")
            cells = self.int_vector(sheet["cells"], f"{key}.sheet.cells", 2, 1, "[20, 20]")
            triangles = 2 * int(cells[0]) * int(cells[1])
            check_fits(triangles * SIMULATION_BYTES_PER_TRIANGLE, what=f"a sheet of {triangles:,} triangles",
                       source=self.source, field=f"{key}.sheet.cells", fix="use fewer cells")
            local, faces, rest = grid_sheet(cells[0], cells[1], size[0], size[1])
            local = local.astype(np.float64) - np.array([size[0] / 2.0, size[1] / 2.0, 0.0])
            rest = rest.astype(np.float64) * scale
            spec["sheet"] = {"size": size, "cells": cells}
        else:
            mesh_path, mesh = self.mesh(raw["mesh"], f"{key}.mesh")
            mode = self.string(raw.get("rest", "auto"), f"{key}.rest", _REST_MODES)
            local = mesh.vertices.astype(np.float64)
            faces = mesh.faces
            requested = mode
            uv_scale = self.number(raw.get("uv_scale", 1.0), f"{key}.uv_scale", minimum=0.0)
            if "uv_scale" in raw and mode not in ("uv", "auto"):
                raise self.error(f"{key}.uv_scale", f"uv_scale applies to rest = \"uv\" only, not {mode!r}",
                                 "remove it, or set rest = \"uv\"")
            rest, mode = self.mesh_rest(mesh, mode, scale, uv_scale, key, str(mesh_path))
            self.check_rest_triangles(rest, mesh, requested, mode, f"{key}.rest", str(mesh_path))
            spec["mesh"] = str(mesh_path)
            spec["rest"] = mode
            if mode == "uv":
                spec["uv_scale"] = uv_scale
            if "rest_bending" in raw and mode != "mesh":
                raise self.error(f"{key}.rest_bending", f"rest_bending applies to rest = \"mesh\" only (this piece's "
                                 f"rest is {mode!r}, flat, so its bending rest angles are 0)",
                                 "remove it, or set rest = \"mesh\"")
            if mode == "mesh":
                spec["rest_bending"] = self.string(raw.get("rest_bending", "mesh"), f"{key}.rest_bending",
                                                   _REST_BENDING)
        vertices = (scale * local) @ rotation.T + translation
        spec.update(placement)
        material, spec["material"] = self.config(raw.get("material", {}), f"{key}.material", ClothMaterial)
        piece = _Piece(name=name, vertices=vertices.astype(np.float32), faces=np.asarray(faces, np.int32),
                       rest=np.asarray(rest, dtype=np.float32), material=material,
                       flat_bending=spec.get("rest_bending") == "flat",
                       stitches=None if "sheet" in raw else mesh.stitches)
        self.cloth_handles(raw, piece, key, spec)
        seams_raw = raw.get("stitches", [])
        if isinstance(seams_raw, dict) or not isinstance(seams_raw, list) or not all(isinstance(t, dict)
                                                                                    for t in seams_raw):
            raise self.error(f"{key}.stitches", f"expected [[cloth.stitches]] tables, got {_show(seams_raw)}",
                             "write each seam as a [[cloth.stitches]] table with vertices and to")
        piece.seam_tables = seams_raw
        return piece, spec

    def mesh_rest(self, mesh: Any, mode: str, scale: float, uv_scale: float, piece_key: str,
                  mesh_path: str) -> tuple[np.ndarray, str]:
        """Rest coordinates of a mesh piece and the resolved mode.

        ``uv``: the file's texture coordinates times ``uv_scale`` (metres per uv unit); ``file``: the NPZ
        ``rest`` times the placement scale; ``plane``: the positions projected onto their best-fit plane;
        ``mesh``: the positions themselves, (n, 3) (each triangle keeps its own rest shape). ``auto`` takes
        uv, then the NPZ rest, then the plane when the mesh is flat, and refuses a curved mesh without
        either.
        """
        key = f"{piece_key}.rest"
        if mode == "uv" or (mode == "auto" and mesh.uv is not None):
            if mesh.uv is None and mesh.uv_issue is not None:
                raise self.error(key, f"rest = \"uv\" but the texture coordinates of {mesh_path!r} are not one (u, v) "
                                 f"per vertex: {mesh.uv_issue}",
                                 "split the vertices along the UV seams (one vertex per texture coordinate, as sewn-"
                                 "pattern garment files do) and join the pieces with stitches, or use rest = \"mesh\"")
            if mesh.uv is None:
                raise self.error(key, f"rest = \"uv\" but {mesh_path!r} has no texture coordinates",
                                 "export the garment with its UV layout (OBJ 'vt' lines and f v/vt faces, PLY s,t "
                                 "properties or an NPZ 'uv' key), or use rest = \"mesh\" to take the mesh's own shape")
            return self.uv_rest(mesh, scale, uv_scale, piece_key, mesh_path), "uv"
        if mode == "mesh":
            return mesh.vertices.astype(np.float64) * scale, "mesh"
        has_rest = mesh.rest is not None
        if mode == "file" or (mode == "auto" and has_rest):
            if not has_rest:
                raise self.error(key, f"rest = \"file\" but {mesh_path!r} has no rest coordinates",
                                 "use an NPZ file with a 'rest' key of (n, 2) (u, v) coordinates in metres, or "
                                 "rest = \"plane\" to project the positions onto their best-fit plane")
            file_rest = mesh.rest.astype(np.float64) * scale
            if file_rest.shape[1] == 2:
                return file_rest, "file"
            flat, distance, size = _plane_coordinates(file_rest)
            if distance > FLATNESS_TOLERANCE * size:
                raise self.error(key, f"the 3-D rest coordinates in {mesh_path!r} are not flat (a vertex is "
                                 f"{distance:.3g} m from their best-fit plane)",
                                 "store (n, 2) (u, v) rest coordinates in the NPZ 'rest' key")
            return flat, "file"
        positions = mesh.vertices.astype(np.float64) * scale
        flat, distance, size = _plane_coordinates(positions)
        if mode == "auto" and distance > FLATNESS_TOLERANCE * size:
            unusable = "" if mesh.uv_issue is None else f" (its texture coordinates cannot be: {mesh.uv_issue})"
            raise self.error(key, f"{mesh_path!r} has no usable texture or rest coordinates{unusable} and is not flat "
                             f"(a vertex is {distance:.3g} m from the best-fit plane of the positions, more than "
                             f"{FLATNESS_TOLERANCE:g} x the mesh size), so its rest shape is unknown",
                             "set rest = \"mesh\" to take the mesh's own curved shape as the rest shape (what "
                             "cloth tools do for a garment without a pattern), give the file its UV layout "
                             "(rest = \"uv\"), or set rest = \"plane\" to use the projection onto the best-fit "
                             "plane anyway (this distorts the rest lengths of curved parts)")
        return flat, "plane"

    def uv_rest(self, mesh: Any, scale: float, uv_scale: float, piece_key: str, mesh_path: str) -> np.ndarray:
        """The texture coordinates times ``uv_scale`` as the pattern, refused when their area and the placed
        mesh's differ by more than :data:`UV_AREA_RATIO_LIMIT` (uv not in metres: the message gives the
        ``uv_scale`` that matches the areas)."""
        pattern = mesh.uv.astype(np.float64) * uv_scale
        corners = pattern[mesh.faces.astype(np.int64)]
        e1, e2 = corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]
        pattern_area = 0.5 * float(np.abs(e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]).sum())
        placed = mesh.vertices.astype(np.float64)[mesh.faces.astype(np.int64)] * scale
        mesh_area = 0.5 * float(np.linalg.norm(np.cross(placed[:, 1] - placed[:, 0], placed[:, 2] - placed[:, 0]),
                                               axis=1).sum())
        if pattern_area > 0.0 and mesh_area > 0.0:
            ratio = pattern_area / mesh_area
            if not 1.0 / UV_AREA_RATIO_LIMIT <= ratio <= UV_AREA_RATIO_LIMIT:
                matching = uv_scale * (mesh_area / pattern_area) ** 0.5
                raise self.error(f"{piece_key}.uv_scale", f"the texture coordinates of {mesh_path!r} times uv_scale = "
                                 f"{uv_scale:g} cover {pattern_area:.4g} m^2, {ratio:.3g} times the mesh's "
                                 f"{mesh_area:.4g} m^2: they are not a pattern in metres",
                                 f"set uv_scale = {matching:.6g} (metres per uv unit; this matches the areas), or use "
                                 "rest = \"mesh\"")
        return pattern

    def check_rest_triangles(self, rest: np.ndarray, mesh: MeshData, requested: str, mode: str, key: str,
                             mesh_path: str) -> None:
        """Refuse a rest shape with a zero-area triangle here, naming the scene file and ``key``.

        The solver's cloth model refuses it too (same bound, ``SIM_MIN_REST_AREA_RATIO``), but there
        the message can only say ``argument: rest``. Causes: a curved mesh projected with
        ``rest = "plane"``, degenerate rest coordinates in the file, or a zero-area face in the mesh.
        """
        bad = _zero_area_faces(np.asarray(rest, dtype=np.float32), mesh.faces)  # float32: what the model sees
        if not bad.size:
            return
        face = int(bad[0])
        where = f"face {face} {mesh.faces[face].tolist()} of {mesh_path!r} ({bad.size} of {mesh.face_count} faces)"
        if mode == "plane" and face in set(_zero_area_faces(mesh.vertices, mesh.faces).tolist()):
            raise self.error(key, f"{where} has zero area in the mesh itself, so it has no rest shape",
                             "remove the zero-area faces from the mesh, or store (n, 2) (u, v) rest coordinates in "
                             "an NPZ 'rest' key and use rest = \"file\"")
        if mode == "plane":
            how = "rest = \"plane\"" if requested == "plane" else "rest = \"auto\" (the mesh looks flat)"
            raise self.error(key, f"{how} projects the mesh onto its best-fit plane, which folds {where} to zero "
                             "area: the mesh is too curved for that projection to be its rest shape",
                             "store (n, 2) (u, v) rest coordinates (e.g. its UV unwrap, in metres) in an NPZ "
                             "'rest' key and use rest = \"file\"")
        if mode == "uv":
            raise self.error(key, f"the texture coordinates give {where} zero area",
                             "give every face three distinct, non-collinear (u, v) in the UV layout, or use "
                             "rest = \"mesh\"")
        if mode == "mesh":
            raise self.error(key, f"rest = \"mesh\" takes the mesh's own shape, in which {where} has zero area",
                             "remove the zero-area faces from the mesh, or give it a UV layout (rest = \"uv\")")
        raise self.error(key, f"the rest coordinates in the file give {where} zero area",
                         "give every face three non-collinear (u, v) rest coordinates in the NPZ 'rest' key, or "
                         "remove that face")

    def seam(self, table: Mapping[str, Any], index: int, pieces: list[_Piece], key: str) -> tuple[np.ndarray,
                                                                                                   dict[str, Any]]:
        """Stitch rows (local ids) of one [[cloth.stitches]] table of piece ``index`` and its resolved spec."""
        self.check_keys(table, _STITCH_KEYS, key)
        for required in ("vertices", "to"):
            if required not in table:
                raise self.error(f"{key}.{required}", "is missing", "give vertices = { side = \"right\" } (this "
                                 "piece's boundary) and to = { side = \"left\" } (the boundary it is sewn to)")
        piece = pieces[index]
        names = [p.name for p in pieces]
        target_name = self.string(table.get("to_piece", piece.name), f"{key}.to_piece")
        if target_name not in names:
            raise self.error(f"{key}.to_piece", f"no cloth piece is named {target_name!r}",
                             f"use one of {names}")
        target = pieces[names.index(target_name)]
        reverse = None
        if "reverse" in table:
            if not isinstance(table["reverse"], bool):
                raise self.error(f"{key}.reverse", f"expected true or false, got {_show(table['reverse'])}",
                                 "write reverse = true to run the second boundary the other way")
            reverse = table["reverse"]
        paths = []
        for name, owner in (("vertices", piece), ("to", target)):
            ids = self.select(table[name], owner, f"{key}.{name}")
            try:
                paths.append(boundary_path(owner.faces, ids))
            except ValueError as error:
                raise self.error(f"{key}.{name}", str(error), "select the vertices of one boundary of the piece "
                                 "(e.g. { side = \"left\" }), a path or a closed loop") from None
        (source, source_closed), (goal, goal_closed) = paths
        if target is piece and np.intersect1d(source, goal).size:
            raise self.error(f"{key}.to", "shares vertices with vertices", "sew two different boundaries")
        try:
            rows, reversed_ = sew(source, source_closed, piece.rest, goal, goal_closed, target.rest, piece.vertices,
                                  target.vertices, reverse)
        except ValueError as error:
            raise self.error(key, str(error), "select both boundaries as loops or both as paths") from None
        resolved = {"vertices": [int(v) for v in source], "to": [int(v) for v in goal], "to_piece": target_name,
                    "reverse": reversed_}
        return rows, resolved

    def cloth_handles(self, raw: Mapping[str, Any], piece: _Piece, key: str, spec: dict[str, Any]) -> None:
        """Pins and [[cloth.handles]] of a piece, into ``piece.handles`` and ``spec``."""
        owner: dict[int, str] = {}

        def claim(ids: np.ndarray, where: str) -> None:
            for vertex in ids.tolist():
                if vertex in owner:
                    raise self.error(where, f"vertex {vertex} is also selected by {owner[vertex]}",
                                     "select each vertex in only one of pins and the handles")
                owner[vertex] = where

        pins = np.zeros(0, dtype=np.int64)
        if "pins" in raw:
            pins = self.select(raw["pins"], piece, f"{key}.pins", allow_empty=True)
            claim(pins, f"{key}.pins")
            if pins.size:
                piece.handles.append((f"{piece.name}.pins", pins, None))
        spec["pins"] = [int(v) for v in pins]
        handles_raw = raw.get("handles", [])
        if isinstance(handles_raw, dict) or not isinstance(handles_raw, list) \
                or not all(isinstance(h, dict) for h in handles_raw):
            raise self.error(f"{key}.handles", f"expected [[cloth.handles]] tables, got {_show(handles_raw)}",
                             "write each handle as a [[cloth.handles]] table (double brackets)")
        spec["handles"] = []
        for j, handle_raw in enumerate(handles_raw):
            where = f"{key}.handles[{j}]"
            self.check_keys(handle_raw, _HANDLE_KEYS, where, hints={
                "keyframes": "a handle takes times, translations and rotations directly in its table",
                "ids": "write vertices = [ids] (or a selector table)"})
            name = self.string(handle_raw.get("name", f"{piece.name}.handles[{j}]"), f"{where}.name")
            if "vertices" not in handle_raw:
                raise self.error(f"{where}.vertices", "is missing",
                                 "select the handle's vertices, e.g. vertices = { side = \"left\" } or [0, 1, 2]")
            ids = self.select(handle_raw["vertices"], piece, f"{where}.vertices")
            claim(ids, f"{where}.vertices")
            keyframes = self.keyframes(handle_raw, where)
            if "pivot" in handle_raw:
                pivot = self.vector(handle_raw["pivot"], f"{where}.pivot", 3, example="[0.0, 0.0, 0.5]  # metres")
            else:
                pivot = [float(c) for c in piece.vertices[ids].astype(np.float64).mean(axis=0)]
            motion = PivotedMotion(self.keyframed_motion(keyframes, where), np.asarray(pivot, dtype=np.float64))
            rotation, translation = motion(0.0)
            if np.abs(rotation - np.eye(3)).max() > POSE_TOLERANCE or np.abs(translation).max() > POSE_TOLERANCE:
                raise self.error(f"{where}.translations", "the handle's keyframed pose at t = 0 is not the identity, "
                                 "so its vertices would jump at the start",
                                 "handle keyframes are displacements from the initial positions: make the "
                                 "translation and rotation at t = 0 zero")
            piece.handles.append((name, ids, motion))
            spec["handles"].append({"name": name, "vertices": [int(v) for v in ids], **keyframes, "pivot": pivot})

    def select(self, value: Any, piece: _Piece, key: str, allow_empty: bool = False) -> np.ndarray:
        """Sorted unique local vertex ids of a selection (ids, selector table, or a list of both)."""
        n = piece.vertices.shape[0]
        example = "[0, 1, 2] or { side = \"top\" }, { corner = \"top-left\" }, { box = [[x0, y0, z0], [x1, y1, z1]] }"
        items = value if isinstance(value, list) else [value]
        selected: list[np.ndarray] = []
        for i, item in enumerate(items):
            where = f"{key}[{i}]" if isinstance(value, list) else key
            if isinstance(item, bool) or not isinstance(item, int | dict):
                raise self.error(where, f"expected a vertex id or a selector table, got {_type_name(item)} "
                                 f"{_show(item)}", f"write e.g. {example}")
            if isinstance(item, int):
                selected.append(self.ids([item], n, where))
                continue
            self.check_keys(item, _SELECTOR_KEYS, where)
            chosen = [k for k in _SELECTOR_KEYS if k in item and k != "tolerance"]
            if not chosen:
                raise self.error(where, "the selector table selects nothing",
                                 f"give ids, side, corner or box: {example}")
            if "tolerance" in item and "side" not in item:
                raise self.error(f"{where}.tolerance", "tolerance applies to side only", "remove it or add side")
            if "ids" in item:
                if not isinstance(item["ids"], list):
                    raise self.error(f"{where}.ids", f"expected an array of vertex ids, got {_show(item['ids'])}",
                                     "write ids = [0, 1, 2]")
                selected.append(self.ids(item["ids"], n, f"{where}.ids"))
            if "side" in item or "corner" in item:
                rest = piece.rest.astype(np.float64)
                if rest.shape[1] == 3:  # a 3-D rest shape: sides and corners of its best-fit plane
                    rest = _plane_coordinates(rest)[0]
                low, high = rest.min(axis=0), rest.max(axis=0)
                extent = float((high - low).max())
            if "side" in item:
                tolerance = SIDE_TOLERANCE * extent
                if "tolerance" in item:
                    tolerance = self.number(item["tolerance"], f"{where}.tolerance", minimum=0.0, strict=False)
                for side in self.names(item["side"], f"{where}.side", SIDES):
                    axis = 0 if side in ("left", "right") else 1
                    if side in ("left", "bottom"):
                        ids = np.flatnonzero(rest[:, axis] <= low[axis] + tolerance)
                    else:
                        ids = np.flatnonzero(rest[:, axis] >= high[axis] - tolerance)
                    selected.append(ids)
            if "corner" in item:
                for corner in self.names(item["corner"], f"{where}.corner", CORNERS):
                    vertical, horizontal = corner.split("-")
                    target = np.array([low[0] if horizontal == "left" else high[0],
                                       low[1] if vertical == "bottom" else high[1]])
                    selected.append(np.array([int(np.argmin(((rest - target) ** 2).sum(axis=1)))]))
            if "box" in item:
                box = item["box"]
                if not isinstance(box, list) or len(box) != 2:
                    raise self.error(f"{where}.box", f"expected [[xmin, ymin, zmin], [xmax, ymax, zmax]], got "
                                     f"{_show(box)}", "write box = [[xmin, ymin, zmin], [xmax, ymax, zmax]] in metres")
                lower = np.array(self.vector(box[0], f"{where}.box[0]", 3))
                upper = np.array(self.vector(box[1], f"{where}.box[1]", 3))
                if np.any(lower > upper):
                    raise self.error(f"{where}.box", "a minimum corner coordinate exceeds the maximum",
                                     "write box = [[xmin, ymin, zmin], [xmax, ymax, zmax]] with min <= max")
                positions = piece.vertices.astype(np.float64)
                inside = np.all((positions >= lower) & (positions <= upper), axis=1)
                ids = np.flatnonzero(inside)
                if ids.size == 0:
                    raise self.error(f"{where}.box", "the box contains no vertex of the piece (placed positions: "
                                     f"{positions.min(axis=0).round(4).tolist()} to "
                                     f"{positions.max(axis=0).round(4).tolist()})",
                                     "enlarge or move the box; it is in scene coordinates, after the placement")
                selected.append(ids)
        result = np.unique(np.concatenate(selected)) if selected else np.zeros(0, dtype=np.int64)
        if result.size == 0 and not allow_empty:
            raise self.error(key, "selects no vertex", f"select at least one vertex, e.g. {example}")
        return result.astype(np.int64)

    def ids(self, values: list[Any], n: int, key: str) -> np.ndarray:
        out = []
        for i, value in enumerate(values):
            where = f"{key}[{i}]" if len(values) > 1 or key.endswith("ids") else key
            vertex = self.integer(value, where)
            if not 0 <= vertex < n:
                raise self.error(where, f"vertex id {vertex} is out of range: the piece has {n} vertices",
                                 f"use 0-based ids in [0, {n - 1}] (ids count within the piece, in its mesh order)")
            out.append(vertex)
        return np.asarray(out, dtype=np.int64)

    def names(self, value: Any, key: str, choices: tuple[str, ...]) -> list[str]:
        items = value if isinstance(value, list) else [value]
        if not items:
            raise self.error(key, "is empty", f"use one or more of {', '.join(map(repr, choices))}")
        return [self.string(item, f"{key}[{i}]" if isinstance(value, list) else key, choices)
                for i, item in enumerate(items)]

    # ------------------------------------------------------------ keyframes

    def keyframes(self, table: Mapping[str, Any], key: str) -> dict[str, Any]:
        """Resolved ``times`` / ``translations`` / ``rotations`` (degrees) of a table holding them."""
        if "times" not in table:
            raise self.error(f"{key}.times", "is missing",
                             "give the keyframe times in seconds, e.g. times = [0.0, 1.0]")
        times_raw = table["times"]
        if not isinstance(times_raw, list) or not times_raw:
            raise self.error(f"{key}.times", f"expected a non-empty array of times, got {_show(times_raw)}",
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
            self.check_keys(table, _KEYFRAME_KEYS, f"{key}.keyframes")
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
            raise self.error(key, f"expected a glob pattern or a non-empty array of files, got {_show(value)}",
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


def _zero_area_faces(coords: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Faces whose triangle in ``coords`` (2-D or 3-D) has twice its area at most
    ``SIM_MIN_REST_AREA_RATIO`` x its longest edge squared: the cloth model's test (``pscc.sim.model``)."""
    corners = np.asarray(coords, dtype=np.float64)[np.asarray(faces, dtype=np.int64)]
    e1, e2 = corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]
    if corners.shape[2] == 2:
        twice_area = np.abs(e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0])
    else:
        twice_area = np.linalg.norm(np.cross(e1, e2), axis=1)
    edges = corners[:, [1, 2, 0]] - corners
    longest_sq = np.max(np.einsum("mkd,mkd->mk", edges, edges), axis=1)
    return np.flatnonzero(~(twice_area > SIM_MIN_REST_AREA_RATIO * longest_sq))


def _plane_coordinates(points: np.ndarray) -> tuple[np.ndarray, float, float]:
    """(u, v) coordinates of points in their best-fit plane, the largest distance to it, and the size.

    The plane goes through the centroid; its normal is the direction of least variance, oriented so
    that its largest component is positive. The u axis is the x axis projected onto the plane (the
    y axis when the plane is nearly perpendicular to x), v = normal x u. For points in a plane
    z = const this gives u = x - mean(x), v = y - mean(y).
    """
    points = np.asarray(points, dtype=np.float64)
    centred = points - points.mean(axis=0)
    _, _, basis = np.linalg.svd(centred, full_matrices=False)
    normal = basis[-1] if basis.shape[0] == 3 else np.array([0.0, 0.0, 1.0])
    normal = normal / np.linalg.norm(normal)
    if normal[int(np.argmax(np.abs(normal)))] < 0.0:
        normal = -normal
    for axis in (np.array([1.0, 0.0, 0.0]), np.array([0.0, 1.0, 0.0])):
        u = axis - float(axis @ normal) * normal
        if np.linalg.norm(u) > 0.5:
            break
    u = u / np.linalg.norm(u)
    v = np.cross(normal, u)
    flat = np.stack([centred @ u, centred @ v], axis=1)
    distance = float(np.abs(centred @ normal).max()) if centred.size else 0.0
    size = float(np.ptp(points, axis=0).max()) if points.size else 0.0
    return flat, distance, size


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


