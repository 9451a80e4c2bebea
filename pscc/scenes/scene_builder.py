"""Checking and building scene files: the TOML data of a scene file -> Scene, ContactConfig, resolved spec.

:class:`SceneBuilder` walks the tables of ``docs/scene-files.md`` key by key; every problem raises
:class:`pscc.errors.InputError` naming the scene file, the key path (``cloth[1].material.density``),
the problem and the fix. :mod:`pscc.scenes.scene_file` is the public entry point.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import Field, dataclass, field, fields
from pathlib import Path
from typing import Any

import numpy as np

from pscc._memory import SIMULATION_BYTES_PER_TRIANGLE, check_fits
from pscc.errors import InputError
from pscc.mesh.generate import grid_sheet
from pscc.scenes.obstacle_tables import ObstacleTables
from pscc.scenes.rest_shapes import FLATNESS_TOLERANCE, REST_BENDING, REST_MODES, RestShapes, plane_coordinates
from pscc.scenes.scene_motions import PivotedMotion
from pscc.scenes.seam_builder import boundary_path, sew
from pscc.scenes.table_reader import PLACEMENT_KEYS, show, type_name
from pscc.scenes.toml_text import config_to_toml, field_kind
from pscc.sim.config import ClothMaterial, SolverConfig
from pscc.sim.contact_config import ContactConfig
from pscc.sim.obstacles import Handle, static_motion
from pscc.sim.scene import Scene
from pscc.tolerances import MIN_COORDINATE_SCALE

__all__ = ["FLATNESS_TOLERANCE", "SceneBuilder", "SceneFile"]

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

SIDE_TOLERANCE: float = 1.0e-4
"""Default tolerance of the ``side`` selector, as a fraction of the piece's largest rest extent."""

POSE_TOLERANCE: float = 1.0e-9
"""A handle's keyframed pose at t = 0 must be the identity within this (rotation entries; translation
in metres): handle keyframes are displacements from the initial positions."""

SIDES: tuple[str, ...] = ("left", "right", "bottom", "top")
"""Side names of the ``side`` selector: smallest u, largest u, smallest v, largest v (rest coordinates)."""

CORNERS: tuple[str, ...] = ("bottom-left", "bottom-right", "top-left", "top-right")
"""Corner names of the ``corner`` selector (rest coordinates; bottom/top = v, left/right = u)."""

_TOP_KEYS = ("scene", "solver", "contact", "cloth", "obstacle")
_SCENE_KEYS = ("name", "description", "frame_rate", "frame_time", "steps_per_frame", "frames")
_CLOTH_KEYS = ("name", "mesh", "rest", "uv_scale", "rest_bending", "sheet", *PLACEMENT_KEYS, "material", "pins",
               "handles", "stitches")
_STITCH_KEYS = ("vertices", "to", "to_piece", "reverse")
_SHEET_KEYS = ("size", "cells")
_HANDLE_KEYS = ("name", "vertices", "times", "translations", "rotations", "pivot")
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


class SceneBuilder(RestShapes, ObstacleTables):
    """Checks a parsed scene file and builds the scene and the resolved spec (the value checks are
    :class:`~pscc.scenes.table_reader.TableReader`'s, the rest shapes :class:`~pscc.scenes.rest_shapes.RestShapes`',
    the obstacles and keyframes :class:`~pscc.scenes.obstacle_tables.ObstacleTables`').

    Args:
        path: the scene file.
    """

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
            raise self.error("cloth", f"expected one or more [[cloth]] tables, got {show(cloth_raw)}",
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
            raise self.error("obstacle", f"expected [[obstacle]] tables, got {show(obstacle_raw)}",
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
            mode = self.string(raw.get("rest", "auto"), f"{key}.rest", REST_MODES)
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
                                                   REST_BENDING)
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
            raise self.error(f"{key}.stitches", f"expected [[cloth.stitches]] tables, got {show(seams_raw)}",
                             "write each seam as a [[cloth.stitches]] table with vertices and to")
        piece.seam_tables = seams_raw
        return piece, spec

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
                raise self.error(f"{key}.reverse", f"expected true or false, got {show(table['reverse'])}",
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
            raise self.error(f"{key}.handles", f"expected [[cloth.handles]] tables, got {show(handles_raw)}",
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
                raise self.error(where, f"expected a vertex id or a selector table, got {type_name(item)} "
                                 f"{show(item)}", f"write e.g. {example}")
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
                    raise self.error(f"{where}.ids", f"expected an array of vertex ids, got {show(item['ids'])}",
                                     "write ids = [0, 1, 2]")
                selected.append(self.ids(item["ids"], n, f"{where}.ids"))
            if "side" in item or "corner" in item:
                rest = piece.rest.astype(np.float64)
                if rest.shape[1] == 3:  # a 3-D rest shape: sides and corners of its best-fit plane
                    rest = plane_coordinates(rest)[0]
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
                                     f"{show(box)}", "write box = [[xmin, ymin, zmin], [xmax, ymax, zmax]] in metres")
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



