"""Sweep files (``pscc batch SWEEP.toml``): read and check them, and expand them into checked runs.

A sweep file has one table, ``[batch]`` (format: ``docs/batch.md``)::

    [batch]
    scenes = ["drape", "twist"]      # built-in names or scene files (relative to the sweep file)
    frames = 2                       # default: each scene's own
    triangles = 300                  # or scale = 0.5 (built-in scenes; a scene file fixes its own size)
    checkpoint_every = 10
    formats = ["npz"]
    max_retries = 3                  # retries of a run whose worker died

    [batch.vary]                     # the cartesian product of these lists
    "cloth.material.friction" = [0.1, 0.5]

:func:`load_sweep` checks the file itself; :func:`expand_runs` applies every combination of values to
every scene and loads the result with the normal scene-file reader, so a bad key path or a bad value
is an :class:`~pscc.errors.InputError` naming the sweep file, the key (``batch.vary."cloth.material.friction"[1]``),
the problem and the fix before any run starts.
"""

from __future__ import annotations

import copy
import difflib
import hashlib
import itertools
import json
import math
import os
import re
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from pscc.batch.key_paths import KeyPathError, parse_key_path, set_key_path
from pscc.errors import InputError
from pscc.scenes.registry import SCENE_NAMES, SceneSource, build, open_scene, source_from_toml
from pscc.sim.contact_config import ContactConfig
from pscc.sim.scene import Scene

__all__ = ["BATCH_KEYS", "Run", "Sweep", "expand_runs", "load_sweep", "run_id"]

BATCH_KEYS: tuple[str, ...] = ("scenes", "frames", "triangles", "scale", "checkpoint_every", "formats",
                               "max_retries", "vary")
"""Keys of ``[batch]``."""

DEFAULT_CHECKPOINT_EVERY = 10
"""Frames between checkpoints of each run (``checkpoint_every``)."""

DEFAULT_MAX_RETRIES = 3
"""Times a run is started again after its worker died (``max_retries``)."""

MAX_ID_LENGTH = 100
"""Longest run id written out in full; a longer one is cut and ends in a hash of the run."""

_SAFE = re.compile(r"[^A-Za-z0-9._,+=-]+")


@dataclass(frozen=True)
class Sweep:
    """A checked sweep file.

    Attributes:
        path: the sweep file (absolute).
        scenes: the ``scenes`` entries as written (built-in names or paths).
        frames: frames of every run (``None``: each scene's own).
        triangles: cloth triangles of the built-in scenes (``None``: ``scale`` or their default).
        scale: size of the built-in scenes as a fraction of their default (or of the paper's).
        checkpoint_every: frames between checkpoints.
        formats: output formats of every run (``pscc.io.formats.FORMATS``).
        max_retries: times a run whose worker died is started again.
        vary: ``(key path, values)`` pairs in file order; the runs are their cartesian product.
    """

    path: Path
    scenes: tuple[str, ...]
    frames: int | None = None
    triangles: int | None = None
    scale: float | None = None
    checkpoint_every: int = DEFAULT_CHECKPOINT_EVERY
    formats: tuple[str, ...] = ("npz",)
    max_retries: int = DEFAULT_MAX_RETRIES
    vary: tuple[tuple[str, tuple[Any, ...]], ...] = ()

    @property
    def combinations(self) -> int:
        """Combinations of values per scene."""
        return math.prod(len(values) for _, values in self.vary)


@dataclass(frozen=True)
class Run:
    """One run of a sweep: a scene with one combination of values, checked and ready to simulate.

    Plain data, sent to the worker that runs it (:func:`pscc.batch.task.run_task`).

    Attributes:
        run_id: the name of its folder ``DIR/runs/<run_id>`` (stable between invocations).
        scene: the scene's label (a built-in name or the scene file's name without ``.toml``).
        values: ``{key path: value}`` of this combination, in ``[batch.vary]`` order.
        document: the scene's resolved TOML document with the values applied.
        origin: the file the document stands for (its scene file, or the sweep file for a built-in scene).
        frames: frames to simulate.
        checkpoint_every: frames between checkpoints.
        formats: output formats.
        identity: the run identity its folder must hold (:meth:`pscc.scenes.registry.SceneSource.run_identity`).
    """

    run_id: str
    scene: str
    values: dict[str, Any]
    document: dict[str, Any]
    origin: str
    frames: int
    checkpoint_every: int
    formats: tuple[str, ...]
    identity: dict[str, Any] = field(repr=False)


# ---------------------------------------------------------------------------------------------------
# The sweep file
# ---------------------------------------------------------------------------------------------------


def _is_int(value: Any) -> bool:
    return isinstance(value, int) and not isinstance(value, bool)


def _vary_field(key: str, index: int | None = None) -> str:
    return f"batch.vary.{json.dumps(key)}" + ("" if index is None else f"[{index}]")


def load_sweep(path: str | os.PathLike[str]) -> Sweep:
    """Read and check a sweep file (its own keys; the scenes are checked by :func:`expand_runs`).

    Raises:
        InputError: the file is missing or not TOML; a table other than ``[batch]``; a key of
            ``[batch]`` unknown, missing (``scenes``) or of the wrong type; ``triangles`` together with
            ``scale``; a ``[batch.vary]`` key that is not a key path, or values that are not a non-empty
            array without repeats. The message names the sweep file, the key, the problem and the fix.
    """
    file_path = Path(os.path.abspath(os.path.expanduser(os.fspath(path))))
    source = str(file_path)

    def error(key: str, problem: str, fix: str) -> InputError:
        return InputError(source, key, problem, fix)

    if not file_path.is_file():
        problem = "is a folder" if file_path.is_dir() else "is not a regular file" if file_path.exists() \
            else "file does not exist"
        raise error("path", problem, "pass the path of a sweep file (.toml)")
    try:
        raw = tomllib.loads(file_path.read_text(encoding="utf-8"))
    except OSError as exc:
        raise error("file", f"cannot be read ({exc.strerror or exc})", "check the file permissions") from None
    except tomllib.TOMLDecodeError as exc:
        raise error("file", f"is not valid TOML ({exc})", "fix the syntax at the line and column named") from None
    except UnicodeDecodeError as exc:
        raise error("file", f"is not UTF-8 text ({exc})", "save the sweep file as UTF-8") from None
    for key in raw:
        if key != "batch":
            raise error(key, "is not a table of a sweep file", "put the sweep under [batch] and [batch.vary]")
    head = raw.get("batch")
    if not isinstance(head, dict):
        raise error("batch", "is missing" if head is None else "is not a table",
                    'write a [batch] table with scenes = ["drape"] (see docs/batch.md)')
    for key in head:
        if key not in BATCH_KEYS:
            close = difflib.get_close_matches(key, BATCH_KEYS, n=1, cutoff=0.6)
            hint = f"did you mean {close[0]!r}? " if close else ""
            raise error(f"batch.{key}", f"unknown key {key!r}", f"{hint}use one of {', '.join(BATCH_KEYS)}")

    scenes = head.get("scenes")
    if not isinstance(scenes, list) or not scenes:
        raise error("batch.scenes", "is missing" if scenes is None else "is not a non-empty array",
                    'list built-in scene names or scene files, e.g. scenes = ["drape", "my-scene.toml"]')
    for index, entry in enumerate(scenes):
        if not isinstance(entry, str) or not entry.strip():
            raise error(f"batch.scenes[{index}]", f"{entry!r} is not a scene name or a file",
                        'write a built-in name (pscc scenes) or a path ending in .toml, in double quotes')
        if scenes.index(entry) != index:
            raise error(f"batch.scenes[{index}]", f"repeats {entry!r}", "list each scene once")

    frames = head.get("frames")
    if frames is not None and (not _is_int(frames) or frames < 1):
        raise error("batch.frames", f"{frames!r} is not an integer >= 1", "write e.g. frames = 30")
    triangles, scale = head.get("triangles"), head.get("scale")
    if triangles is not None and scale is not None:
        raise error("batch.scale", "both triangles and scale are given", "keep one of them")
    if triangles is not None and (not _is_int(triangles) or triangles < 1):
        raise error("batch.triangles", f"{triangles!r} is not an integer >= 1", "write e.g. triangles = 2000")
    if scale is not None and (isinstance(scale, bool) or not isinstance(scale, int | float) or not scale > 0
                              or not math.isfinite(scale)):
        raise error("batch.scale", f"{scale!r} is not a number > 0", "write e.g. scale = 0.5")
    every = head.get("checkpoint_every", DEFAULT_CHECKPOINT_EVERY)
    if not _is_int(every) or every < 1:
        raise error("batch.checkpoint_every", f"{every!r} is not an integer >= 1", "write e.g. checkpoint_every = 10")
    retries = head.get("max_retries", DEFAULT_MAX_RETRIES)
    if not _is_int(retries) or retries < 0:
        raise error("batch.max_retries", f"{retries!r} is not an integer >= 0", "write e.g. max_retries = 3")
    formats = _formats(head.get("formats", ["npz"]), error)
    vary = _vary(head.get("vary", {}), error)
    return Sweep(file_path, tuple(scenes), frames, triangles, None if scale is None else float(scale), every,
                 formats, retries, vary)


def _formats(value: Any, error: Any) -> tuple[str, ...]:
    from pscc.io.formats import FORMATS, parse_formats

    if not isinstance(value, list) or not value or not all(isinstance(item, str) for item in value):
        raise error("batch.formats", f"{value!r} is not a non-empty array of format names",
                    f'write e.g. formats = ["npz", "usd"] (from {", ".join(FORMATS)})')
    try:
        return tuple(dict.fromkeys(("npz", *parse_formats(value))))
    except InputError as exc:
        raise error("batch.formats", exc.problem, f"use names from {', '.join(FORMATS)}") from None


def _vary(table: Any, error: Any) -> tuple[tuple[str, tuple[Any, ...]], ...]:
    if not isinstance(table, dict):
        raise error("batch.vary", "is not a table", 'write [batch.vary] with "key.path" = [values] lines')
    vary = []
    for key, values in table.items():
        if isinstance(values, dict):
            raise error(_vary_field(key), "is a table: a dotted key path was written without quotes",
                        f'write the key path in double quotes, e.g. "{key}.{next(iter(values), "x")}" = [...]')
        try:
            parse_key_path(key)
        except KeyPathError as exc:
            raise error(_vary_field(key), exc.problem, exc.fix) from None
        if not isinstance(values, list) or not values:
            raise error(_vary_field(key), f"{values!r} is not a non-empty array of values",
                        f'write the values to try as an array, e.g. "{key}" = [0.1, 0.5]')
        seen: list[str] = []
        for index, value in enumerate(values):
            text = json.dumps(value, sort_keys=True)
            if text in seen:
                raise error(_vary_field(key, index), f"repeats the value {value!r}", "list each value once")
            seen.append(text)
        vary.append((key, tuple(values)))
    return tuple(vary)


# ---------------------------------------------------------------------------------------------------
# Run ids
# ---------------------------------------------------------------------------------------------------


def _value_text(value: Any) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        return repr(value)
    if isinstance(value, int | str):
        return str(value)
    if isinstance(value, list):
        return ",".join(_value_text(item) for item in value)
    return json.dumps(value, sort_keys=True, separators=(",", ":"))


def _label(segments: tuple[Any, ...]) -> str:
    return ".".join(s.name if s.index is None else f"{s.name}_{s.index}" for s in segments)


def _key_labels(keys: list[str]) -> dict[str, str]:
    """Names of the varied keys in run ids: the last key of each path (``gravity[2]`` as ``gravity_2``), or the
    whole path where two paths end alike (``cloth_1.material.friction``)."""
    paths = {key: parse_key_path(key) for key in keys}
    last = {key: _label(path[-1:]) for key, path in paths.items()}
    return {key: last[key] if list(last.values()).count(last[key]) == 1 else _label(paths[key]) for key in keys}


def run_id(scene: str, values: dict[str, Any], labels: dict[str, str] | None = None) -> str:
    """The folder name of a run: ``<scene>-<key>=<value>-...`` (``drape-friction=0.1``).

    Characters other than letters, digits and ``._,+=-`` become ``_``, and then (or when the name is
    longer than :data:`MAX_ID_LENGTH`) a hash of the scene and the values is appended, so that two runs
    never share a name. The name depends only on the scene and the values, so it is the same in
    every invocation of a sweep (``--resume`` finds the run again).
    """
    labels = labels or _key_labels(list(values))
    text = "-".join([scene, *(f"{labels[key]}={_value_text(value)}" for key, value in values.items())])
    safe = _SAFE.sub("_", text)
    if safe != text or len(safe) > MAX_ID_LENGTH:
        digest = hashlib.sha256(json.dumps([scene, values], sort_keys=True).encode()).hexdigest()[:8]
        safe = f"{safe[:MAX_ID_LENGTH - 9]}-{digest}"
    return safe


# ---------------------------------------------------------------------------------------------------
# Expanding and checking the runs
# ---------------------------------------------------------------------------------------------------


class _CachedBuild:
    """``registry.build`` that builds each built-in scene size once and hands out copies."""

    def __init__(self) -> None:
        self._scenes: dict[str, Scene] = {}

    @staticmethod
    def _key(name: str, size: dict[str, Any]) -> str:
        return json.dumps([name, size], sort_keys=True)

    def keep(self, name: str, size: dict[str, Any], scene: Scene) -> None:
        """Remember a scene built already (a copy of it)."""
        self._scenes.setdefault(self._key(name, size), copy.deepcopy(scene))

    def __call__(self, name: str, **size: Any) -> Scene:
        key = self._key(name, size)
        if key not in self._scenes:
            self._scenes[key] = build(name, **size)
        return copy.deepcopy(self._scenes[key])


@dataclass
class _Base:
    """One ``scenes`` entry, opened: its label, resolved document and what a variant is checked against."""

    index: int
    label: str
    document: dict[str, Any]
    origin: Path
    pieces: int
    frames: int


def _open_base(sweep: Sweep, index: int, cache: _CachedBuild) -> _Base:
    entry = sweep.scenes[index]
    where = f"batch.scenes[{index}]"
    is_file = entry.lower().endswith(".toml")
    try:
        if is_file:
            path = Path(os.path.expanduser(entry))
            path = path if path.is_absolute() else sweep.path.parent / path
            base: SceneSource = open_scene(str(path))
        else:
            if entry not in SCENE_NAMES:
                close = difflib.get_close_matches(entry, SCENE_NAMES, n=1, cutoff=0.6)
                hint = f"did you mean {close[0]!r}? " if close else ""
                raise InputError(str(sweep.path), where, f"unknown scene {entry!r}",
                                 f"{hint}use a name of `pscc scenes` ({', '.join(SCENE_NAMES)}) or a path ending "
                                 "in .toml")
            base = open_scene(entry, triangles=sweep.triangles, scale=sweep.scale)
    except InputError as exc:
        if exc.source == str(sweep.path):
            raise
        size_field = {"--triangles": "batch.triangles", "triangles": "batch.triangles", "--scale": "batch.scale",
                      "scale": "batch.scale"}.get(exc.field)
        if exc.source == "argument" and size_field is not None:
            fix = exc.fix.replace("pass --", "write ").replace("--triangles", "triangles").replace("--scale", "scale")
            raise InputError(str(sweep.path), size_field, f"{exc.problem} (scene {entry})", fix) from None
        inner = "" if exc.source == "argument" else f"{exc.source}: "
        raise InputError(str(sweep.path), where, f"{inner}{exc.field}: {exc.problem}", exc.fix) from None
    frames = sweep.frames if sweep.frames is not None else base.frames
    contact = base.contact or ContactConfig()
    document = tomllib.loads(base.resolved_toml(frames, contact))
    if is_file:
        label, origin = Path(base.detail.path).stem, Path(base.detail.path)
    else:
        label, origin = entry, sweep.path
        cache.keep(entry, base.detail[1], base.scene)  # its variants start from copies of this build
    pieces = int(base.scene.object_ids.max()) + 1 if base.scene.object_ids.size else 1
    return _Base(index, label, document, origin, pieces, frames)


def _apply(sweep: Sweep, base: _Base, values: dict[str, Any]) -> dict[str, Any]:
    """A copy of ``base``'s document with ``values`` set.

    Raises:
        InputError: a key path that does not fit the scene (naming its ``[batch.vary]`` key).
    """
    document = copy.deepcopy(base.document)
    for key, value in values.items():
        try:
            set_key_path(document, parse_key_path(key), value, pieces=base.pieces)
        except KeyPathError as exc:
            raise InputError(str(sweep.path), _vary_field(key), f"in scene {base.label}: {exc.problem}",
                             exc.fix) from None
    return document


def _load(sweep: Sweep, base: _Base, values: dict[str, Any], cache: _CachedBuild) -> SceneSource:
    """The scene of ``base`` with ``values`` applied, loaded by the scene-file reader.

    Raises:
        InputError: naming the ``[batch.vary]`` value at fault (the one that fails on its own), the
            combination (values that fail only together) or the scene (no values).
    """
    document = _apply(sweep, base, values)
    try:
        return source_from_toml(document, base.origin, build=cache)
    except InputError as exc:
        problem, fix = f"{exc.field}: {exc.problem}", exc.fix
    if not values:
        raise InputError(str(sweep.path), f"batch.scenes[{base.index}]", problem, fix)
    if len(values) > 1:
        for key, value in values.items():
            _load(sweep, base, {key: value}, cache)  # raises for a value that fails on its own
        shown = ", ".join(f"{key} = {json.dumps(value)}" for key, value in values.items())
        raise InputError(str(sweep.path), "batch.vary", f"the combination {shown} in scene {base.label}: {problem}",
                         fix)
    ((key, value),) = values.items()
    text = json.dumps(value, sort_keys=True)
    position = next(k for k, item in enumerate(dict(sweep.vary)[key]) if json.dumps(item, sort_keys=True) == text)
    raise InputError(str(sweep.path), _vary_field(key, position), f"{json.dumps(value)} in scene {base.label}: "
                     f"{problem}", fix)


def expand_runs(sweep: Sweep) -> list[Run]:
    """Every run of ``sweep``: each scene with each combination of the ``[batch.vary]`` values.

    Each combination is applied to the scene's resolved file and loaded by the scene-file reader
    (building the scene), so every run is known to load before any starts. Runs are ordered by
    scene, then by the combinations in ``[batch.vary]`` order (the last key varying fastest).

    Raises:
        InputError: an unknown scene or bad size (``batch.scenes[i]``, ``batch.triangles``), two scene
            files with one name, a key path that does not fit a scene or a value the scene-file reader
            refuses (``batch.vary."key"[i]``, or ``batch.vary`` for a combination of values that fails
            only together), all naming the sweep file and the fix.
    """
    cache = _CachedBuild()
    keys = [key for key, _ in sweep.vary]
    labels = _key_labels(keys)
    runs: list[Run] = []
    seen: dict[str, int] = {}
    for index in range(len(sweep.scenes)):
        base = _open_base(sweep, index, cache)
        if base.label in seen:
            raise InputError(str(sweep.path), f"batch.scenes[{index}]", f"is named {base.label!r} like "
                             f"batch.scenes[{seen[base.label]}], so their runs would share folders",
                             "give the scene files different names")
        seen[base.label] = index
        for combination in itertools.product(*(values for _, values in sweep.vary)):
            values = dict(zip(keys, combination, strict=True))
            source = _load(sweep, base, values, cache)
            document = _apply(sweep, base, values)  # the reader may have changed the one it loaded
            identity = source.run_identity(source.contact or ContactConfig())
            runs.append(Run(run_id(base.label, values, labels), base.label, values, document, str(base.origin),
                            base.frames, sweep.checkpoint_every, sweep.formats, identity))
    ids = [run.run_id for run in runs]
    for run in runs:  # e.g. the boolean true and the string "true" of one key: one text
        if ids.count(run.run_id) > 1:
            raise InputError(str(sweep.path), "batch.vary", f"two runs would share the folder runs/{run.run_id}",
                             "give the values of one key distinct texts")
    return runs

