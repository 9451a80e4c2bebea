"""Reading the values of a scene file's TOML tables, each checked where it stands.

:class:`TableReader` holds the checks every part of a scene file needs (tables and their keys, numbers,
integers, strings, vectors, rows, file paths, meshes, placements); each problem raises
:class:`pscc.errors.InputError` naming the scene file, the key path (``cloth[1].material.density``), the
problem and the fix. :class:`pscc.scenes.scene_builder.SceneBuilder` builds scenes on it.
"""

from __future__ import annotations

import difflib
import math
import os
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any

import numpy as np

from pscc.errors import InputError
from pscc.mesh.io import SUPPORTED_EXTENSIONS, load_mesh
from pscc.mesh.mesh_data import MeshData
from pscc.sim.obstacles import rotation_from_axis_angle

MAX_SCENE_NUMBER = 1.0e9
"""Largest magnitude of any number in a scene file (lengths, angles in degrees, times, rates): beyond it
positions leave the detector's float32 range (``tolerances.MAX_COORDINATE``)."""

PLACEMENT_KEYS = ("translate", "rotate", "scale")
"""Keys of a piece's or an obstacle's placement."""


def type_name(value: Any) -> str:
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


def show(value: Any, limit: int = 60) -> str:
    text = repr(value)
    return text if len(text) <= limit else text[: limit - 3] + "..."


class TableReader:
    """Checked access to the values of one scene file's tables (module docstring).

    Args:
        path: the scene file (messages name it; relative paths are relative to its folder).
    """

    def __init__(self, path: Path) -> None:
        self.path = path
        self.source = str(path)
        self.base = path.parent


    def error(self, key: str, problem: str, fix: str) -> InputError:
        return InputError(self.source, key, problem, fix)

    def rewrap(self, exc: InputError, key: str) -> InputError:
        """An InputError from a lower layer, reported at ``key`` of this file."""
        inner = "" if exc.source in ("argument", "motion", "ClothMaterial", "SolverConfig", "ContactConfig") \
            else f"{exc.source}: "
        return InputError(self.source, key, f"{inner}{exc.field}: {exc.problem}", exc.fix)

    def table(self, value: Any, key: str, example: str) -> dict[str, Any]:
        if not isinstance(value, dict):
            raise self.error(key, f"expected a table, got {type_name(value)} {show(value)}", f"write it as {example}")
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
            raise self.error(key, f"expected a number, got {type_name(value)} {show(value)}",
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
            raise self.error(key, f"expected an integer, got {type_name(value)} {show(value)}",
                             "write a whole number without a decimal point, e.g. 8")
        if (minimum is not None and value < minimum) or (maximum is not None and value > maximum):
            bounds = f"in [{minimum}, {maximum}]" if maximum is not None else f">= {minimum}"
            raise self.error(key, f"{value} is not {bounds}", f"write an integer {bounds}")
        return int(value)

    def string(self, value: Any, key: str, choices: Iterable[str] | None = None) -> str:
        if not isinstance(value, str):
            raise self.error(key, f"expected a string, got {type_name(value)} {show(value)}",
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
            raise self.error(key, f"expected true or false, got {type_name(value)} {show(value)}",
                             "write true or false (lower case, no quotes)")
        return value

    def vector(self, value: Any, key: str, length: int, *, minimum: float | None = None,
               example: str = "[0.0, 0.0, 0.0]") -> list[float]:
        if not isinstance(value, list) or len(value) != length:
            got = f"{len(value)} entries" if isinstance(value, list) else f"{type_name(value)} {show(value)}"
            raise self.error(key, f"expected an array of {length} numbers, got {got}", f"write e.g. {example}")
        return [self.number(item, f"{key}[{i}]", minimum=minimum) for i, item in enumerate(value)]

    def int_vector(self, value: Any, key: str, length: int, minimum: int, example: str) -> list[int]:
        if not isinstance(value, list) or len(value) != length:
            got = f"{len(value)} entries" if isinstance(value, list) else f"{type_name(value)} {show(value)}"
            raise self.error(key, f"expected an array of {length} integers, got {got}", f"write e.g. {example}")
        return [self.integer(item, f"{key}[{i}]", minimum=minimum) for i, item in enumerate(value)]

    def rows(self, value: Any, key: str, count: int, what: str) -> list[list[float]]:
        if not isinstance(value, list):
            raise self.error(key, f"expected an array of [x, y, z] rows, got {type_name(value)} {show(value)}",
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

    def rewrap_field(self, exc: InputError, key: str) -> InputError:
        return InputError(self.source, f"{key}.{exc.field}", exc.problem, exc.fix)

    def placement(self, table: Mapping[str, Any], key: str) -> tuple[dict[str, Any], np.ndarray, np.ndarray, float]:
        translate = self.vector(table.get("translate", [0.0, 0.0, 0.0]), f"{key}.translate", 3,
                                example="[0.0, 0.0, 0.5]  # metres")
        rotate = self.vector(table.get("rotate", [0.0, 0.0, 0.0]), f"{key}.rotate", 3,
                             example="[90.0, 0.0, 0.0]  # rotation vector in degrees")
        scale = self.number(table.get("scale", 1.0), f"{key}.scale", minimum=0.0, example="0.01")
        rotation = rotation_from_axis_angle(np.radians(np.asarray(rotate, dtype=np.float64)))
        spec = {"translate": translate, "rotate": rotate, "scale": scale}
        return spec, rotation, np.asarray(translate, dtype=np.float64), scale
