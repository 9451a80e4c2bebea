"""Key paths into a scene file's TOML document, and setting a value at one (a sweep's ``[batch.vary]``).

A key path names a value of a scene file the way its error messages do: table names joined by dots,
with a 0-based index after an array of tables or an array, e.g. ``cloth[1].material.density``,
``solver.gravity[2]`` or ``contact.method``. Without an index, a key path crosses an array of tables
as a whole: ``cloth.material.friction`` sets the friction of every ``[[cloth]]`` piece.

Built-in scenes are documents too: their resolved files (``pscc/scenes/builtin_file.py``) have the
tables ``[builtin]``, ``[scene]``, ``[material]`` (or one ``[[material]]`` per cloth piece),
``[solver]`` and ``[contact]``. So that one sweep can vary a scene file and a built-in scene alike,
the two spellings of a material are interchangeable:

* ``cloth.material.X`` is ``material.X`` in a built-in scene's file (every piece), and ``material.X``
  is ``cloth.material.X`` in a scene file;
* ``cloth[i].material.X`` is ``material[i].X`` in a built-in scene's file, whose shared
  ``[material]`` is first split into one per piece; ``material[i].X`` is ``cloth[i].material.X`` in a
  scene file.

``scene.frame_time`` and ``scene.frame_rate`` are one setting given two ways: setting one removes the
other from a scene file, and a built-in scene's file takes ``frame_rate`` as ``frame_time = 1 / rate``.
Keys the sweep itself sets (the frame count and the size) cannot be varied.
"""

from __future__ import annotations

import copy
import math
import re
from dataclasses import dataclass
from typing import Any

__all__ = ["KeyPathError", "Segment", "format_key_path", "parse_key_path", "set_key_path"]

_SEGMENT = re.compile(r"^(?P<name>[A-Za-z_][A-Za-z0-9_-]*)(?:\[(?P<index>[0-9]+)\])?$")

RESERVED: dict[str, str] = {
    "scene.frames": "the sweep sets it: write frames = N under [batch]",
    "builtin": "the sweep sets the scene and its size: write scenes, triangles or scale under [batch]",
}
"""Key paths (and their prefixes) a sweep may not vary, with the fix."""


class KeyPathError(ValueError):
    """A key path that is malformed or does not fit the document.

    Args:
        problem: what is wrong.
        fix: what to write instead.
    """

    def __init__(self, problem: str, fix: str) -> None:
        self.problem = problem
        self.fix = fix
        super().__init__(f"{problem}. Fix: {fix}")


@dataclass(frozen=True)
class Segment:
    """One step of a key path: a key, and an index into the array it names (``None``: no index)."""

    name: str
    index: int | None = None

    def __str__(self) -> str:
        return self.name if self.index is None else f"{self.name}[{self.index}]"


def format_key_path(path: tuple[Segment, ...]) -> str:
    """The text of a key path (``cloth[1].material.density``)."""
    return ".".join(str(segment) for segment in path)


def parse_key_path(text: str) -> tuple[Segment, ...]:
    """Split ``text`` into its segments.

    Raises:
        KeyPathError: an empty path or segment, a character other than letters, digits, ``_`` and
            ``-`` in a key, or an index that is not ``[N]`` with N >= 0; or a key the sweep sets itself.
    """
    if not isinstance(text, str) or not text.strip():
        raise KeyPathError("is an empty key path", 'write a key path of a scene file, e.g. "cloth.material.friction"')
    segments = []
    for part in text.split("."):
        match = _SEGMENT.match(part)
        if match is None:
            raise KeyPathError(f"{part!r} is not a key with an optional [index]",
                               'write keys joined by dots, with 0-based indices, e.g. "cloth[1].material.density"')
        segments.append(Segment(match["name"], None if match["index"] is None else int(match["index"])))
    path = tuple(segments)
    for reserved, fix in RESERVED.items():
        names = reserved.split(".")
        if [s.name for s in path[: len(names)]] == names:
            raise KeyPathError(f"{reserved} cannot be varied", fix)
    return path


def _kind(value: Any) -> str:
    if isinstance(value, bool):
        return "a boolean"
    if isinstance(value, int | float):
        return "a number"
    if isinstance(value, str):
        return "a string"
    if isinstance(value, list):
        return "an array"
    return "a table" if isinstance(value, dict) else type(value).__name__


def _is_table_array(value: Any) -> bool:
    return isinstance(value, list) and bool(value) and all(isinstance(item, dict) for item in value)


def _builtin_path(document: dict[str, Any], path: tuple[Segment, ...], pieces: int) -> tuple[Segment, ...]:
    """``path`` in a built-in scene's file: ``cloth[i].material`` becomes ``material[i]`` (splitting a
    shared ``[material]`` into one per piece when a piece is named)."""
    head, written = path[0], format_key_path(path)
    if head.name == "cloth":
        if len(path) < 2 or path[1].name != "material" or path[1].index is not None:
            raise KeyPathError(f"{format_key_path(path)} does not exist in a built-in scene, whose file has only the "
                               "tables [scene], [material], [solver] and [contact]",
                               "vary cloth.material.*, material.*, scene.*, solver.* or contact.* keys, or sweep over "
                               "a scene file instead")
        head = Segment("material", head.index)
        path = (head, *path[2:])
    if head.name == "material" and head.index is not None and isinstance(document.get("material"), dict):
        if head.index >= pieces:
            raise KeyPathError(f"{written} names piece {head.index}, but the scene has {pieces} cloth piece(s)",
                               f"use an index below {pieces}, or no index for every piece")
        document["material"] = [copy.deepcopy(document["material"]) for _ in range(pieces)]
    return path


def _file_path(document: dict[str, Any], path: tuple[Segment, ...]) -> tuple[Segment, ...]:
    """``path`` in a scene file: ``material[i]`` becomes ``cloth[i].material``; frame_time and frame_rate exclude
    each other."""
    head = path[0]
    if head.name == "material":
        path = (Segment("cloth", head.index), Segment("material"), *path[1:])
    if head.name == "scene" and len(path) == 2 and path[1].index is None and path[1].name in ("frame_time",
                                                                                              "frame_rate"):
        other = "frame_rate" if path[1].name == "frame_time" else "frame_time"
        if isinstance(document.get("scene"), dict):
            document["scene"].pop(other, None)
    return path


def set_key_path(document: dict[str, Any], path: tuple[Segment, ...], value: Any, *, pieces: int = 1) -> None:
    """Set ``value`` at ``path`` in ``document`` (in place); see the module docstring for the spellings.

    Tables missing along the path are created (the scene-file reader then names an unknown key with
    its "did you mean"); arrays and array elements must exist.

    Args:
        document: a parsed scene file, or a built-in scene's resolved file (it has ``[builtin]``).
        path: from :func:`parse_key_path`.
        value: a TOML value (copied in).
        pieces: the scene's cloth pieces (a built-in scene's ``cloth[i].material`` needs it).

    Raises:
        KeyPathError: an index past the end of an array, a key under a value that is not a table, an
            empty array of tables, or a ``cloth`` key other than its material in a built-in scene.
    """
    if "builtin" in document:
        if path == (Segment("scene"), Segment("frame_rate")):
            if isinstance(value, bool) or not isinstance(value, int | float) or not 0 < value < math.inf:
                raise KeyPathError(f"{value!r} is not a frame rate > 0", "write frames per second, e.g. 30")
            path, value = (Segment("scene"), Segment("frame_time")), 1.0 / value
        path = _builtin_path(document, path, pieces)
    else:
        path = _file_path(document, path)
    _set(document, path, value, ())


def _set(node: dict[str, Any], path: tuple[Segment, ...], value: Any, done: tuple[Segment, ...]) -> None:
    segment, rest = path[0], path[1:]
    where = format_key_path((*done, Segment(segment.name)))
    if segment.name not in node:
        if segment.index is not None:
            raise KeyPathError(f"{where} does not exist, so it has no element [{segment.index}]",
                               f"check the key path against the scene's resolved file ({where} is not there)")
        if not rest:
            node[segment.name] = copy.deepcopy(value)
            return
        node[segment.name] = {}
    item = node[segment.name]
    if segment.index is not None:
        if not isinstance(item, list):
            raise KeyPathError(f"{where} is {_kind(item)}, not an array, so it has no element [{segment.index}]",
                               f"write the key path without [{segment.index}]")
        if segment.index >= len(item):
            raise KeyPathError(f"{where} has {len(item)} element(s), so [{segment.index}] does not exist",
                               f"use an index from 0 to {len(item) - 1}" if item else f"leave out [{segment.index}]")
        if not rest:
            item[segment.index] = copy.deepcopy(value)
            return
        targets = [(item[segment.index], Segment(segment.name, segment.index))]
    elif not rest:
        node[segment.name] = copy.deepcopy(value)
        return
    elif _is_table_array(item):
        targets = [(element, Segment(segment.name, k)) for k, element in enumerate(item)]
    elif isinstance(item, list) and not item:
        raise KeyPathError(f"{where} is an empty array, so {format_key_path(path)} sets nothing",
                           "vary a key that the scene has (see its resolved scene.toml)")
    else:
        targets = [(item, Segment(segment.name))]
    for target, step in targets:
        if not isinstance(target, dict):
            shown = format_key_path((*done, step))
            raise KeyPathError(f"{shown} is {_kind(target)}, not a table, so it has no key {rest[0].name!r}",
                               f"end the key path at {shown}")
        _set(target, rest, value, (*done, step))
