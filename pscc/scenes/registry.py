"""Every scene ``pscc simulate`` can run: the test scenes, the paper's scenes, and scene files.

* Test scenes (``drape``, ``stack``, ``twist``; :mod:`pscc.scenes.builtin`) are sized by cloth
  triangles (``--triangles``) or by ``--scale`` (a fraction of their default size).
* Paper scenes (``sphere``, ``twisting``, ``flag``, ``sphere-drop``, ``kungfu``, ``falling``,
  ``dance``; :mod:`pscc.scenes.paper`, :mod:`pscc.scenes.garments`) are sized by ``--scale``, the
  fraction of the paper's resolution (1 = the paper's triangle count), or by ``--triangles``.
* A path ending in ``.toml`` is a scene file (:mod:`pscc.scenes.scene_file`) or the resolved file of
  a built-in scene run (:mod:`pscc.scenes.builtin_file`).
"""

from __future__ import annotations

import hashlib
import json
import os
import tomllib
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from pscc._memory import SIMULATION_BYTES_PER_TRIANGLE, check_fits
from pscc.errors import InputError
from pscc.scenes import builtin, paper
from pscc.scenes.builtin_file import builtin_scene_toml, load_builtin_file
from pscc.scenes.scene_builder import SceneBuilder
from pscc.scenes.scene_file import resolved_scene_toml
from pscc.sim.contact_config import ContactConfig
from pscc.sim.scene import Scene

TEST_SCENES: tuple[str, ...] = tuple(builtin.SCENES)
PAPER_SCENE_NAMES: tuple[str, ...] = tuple(paper.PAPER_SCENES)
SCENE_NAMES: tuple[str, ...] = TEST_SCENES + PAPER_SCENE_NAMES
"""Every built-in scene name."""

DEFAULT_FRAMES: dict[str, int] = {"drape": 45, "stack": 45, "twist": 60, "sphere": 60, "twisting": 90, "flag": 60,
                                  "sphere-drop": 45, "kungfu": 85, "falling": 48, "dance": 72}
"""Frames of a run when ``--frames`` is not given."""


def build(name: str, *, triangles: int | None = None, scale: float | None = None) -> Scene:
    """Build a built-in scene by triangle count or scale (at most one of them).

    Raises:
        InputError: unknown scene, both sizes given, or a size out of range.
    """
    if name not in SCENE_NAMES:
        raise InputError("argument", "scene", f"unknown scene {name!r}",
                         f"use one of {', '.join(SCENE_NAMES)} or a .toml scene file")
    if triangles is not None and scale is not None:
        raise InputError("argument", "--scale", "both --triangles and --scale are given", "pass only one of them")
    if name in PAPER_SCENE_NAMES:
        if triangles is not None:
            if isinstance(triangles, bool) or not isinstance(triangles, int):
                raise InputError("argument", "--triangles", f"{triangles!r} is not an integer", "pass an integer")
            scale = triangles / paper.PAPER_TRIANGLES[name]
            low, high = (round(v * paper.PAPER_TRIANGLES[name]) for v in (paper.min_scale(name), paper.MAX_SCALE))
            if not low <= triangles <= high:
                raise InputError("argument", "--triangles", f"{triangles} is outside [{low}, {high}] for {name}",
                                 f"pass --triangles between {low} and {high} (the paper's is "
                                 f"{paper.PAPER_TRIANGLES[name]})")
        value = paper.min_scale(name) if scale is None else paper.check_scale(name, scale)
        count = round(value * paper.PAPER_TRIANGLES[name])
        check_fits(count * SIMULATION_BYTES_PER_TRIANGLE, what=f"the {name} scene at scale {value:g} (about "
                   f"{count:,} triangles)", source="argument", field="--scale" if triangles is None else "--triangles",
                   fix="pass a smaller --scale or fewer --triangles")
        return paper.PAPER_SCENES[name](value)
    if scale is not None:
        try:
            value = float(scale)
        except (TypeError, ValueError):
            value = float("nan")
        if not value > 0.0 or value > 100.0:
            raise InputError("argument", "--scale", f"{scale!r} is not in (0, 100]",
                             f"pass a fraction of the default {builtin.DEFAULT_TRIANGLES[name]} triangles")
        triangles = round(value * builtin.DEFAULT_TRIANGLES[name])
        if triangles < builtin.MIN_TRIANGLES:
            smallest = builtin.MIN_TRIANGLES / builtin.DEFAULT_TRIANGLES[name]
            raise InputError("argument", "--scale", f"{scale!r} gives {triangles} triangles, fewer than "
                             f"{builtin.MIN_TRIANGLES}", f"pass --scale {smallest:.3g} or more")
    return builtin.build_scene(name, triangles)


@dataclass
class SceneSource:
    """A scene ready to run, with what is needed to write its resolved ``scene.toml``.

    Attributes:
        scene: the scene.
        contact: contact settings from a scene file (``None``: the defaults / command line).
        frames: default frame count.
        identity: what makes two runs of it the same run.
        kind: ``"builtin"`` or ``"file"``.
        detail: the builder's name and size, or the loaded scene file.
    """

    scene: Scene
    contact: ContactConfig | None
    frames: int
    identity: dict[str, Any]
    kind: str
    detail: Any = field(default=None)

    def resolved_toml(self, frames: int, contact: ContactConfig) -> str:
        """The fully resolved scene file of a run of ``frames`` frames with ``contact``."""
        if self.kind == "file":
            return resolved_scene_toml(self.detail, frames=frames, contact=contact)
        name, size = self.detail
        return builtin_scene_toml(name, size, frames, self.scene, contact)

    def run_identity(self, contact: ContactConfig) -> dict[str, Any]:
        """What makes two runs of this scene the same run (``run.json``; ``--resume`` compares it).

        That is :attr:`identity`, every key of the resolved scene file but the frame count (so a
        resumed run may go on for more frames) by key path, the SHA-256 of every file the scene
        reads (meshes, sequences) and a SHA-256 of the built scene's arrays
        (:func:`pscc.sim.simulation.scene_identity`), which also catches changes no key shows.
        """
        from pscc.sim.simulation import scene_identity

        settings = _flatten_settings(tomllib.loads(self.resolved_toml(1, contact)))
        for key in FRAME_COUNT_KEYS:
            settings.pop(key, None)
        files = {}
        for value in settings.values():
            for item in value if isinstance(value, list) else [value]:
                if isinstance(item, str) and os.path.isabs(item) and os.path.isfile(item) and item not in files:
                    files[item] = _file_sha256(Path(item))
        for key, value in settings.items():
            text = json.dumps(value)
            if len(text) > LONG_SETTING:  # long lists (pins, sequences): their hash
                settings[key] = "sha256:" + hashlib.sha256(text.encode()).hexdigest()
        return {**self.identity, "method": contact.method, "settings": settings, "files": files,
                "scene_sha256": scene_identity(self.scene, contact)["scene_sha256"]}


FRAME_COUNT_KEYS: tuple[str, ...] = ("builtin.frames", "scene.frames")
"""Keys of a resolved scene file left out of a run's identity (a resumed run may run longer)."""

LONG_SETTING = 200
"""Settings whose JSON is longer than this many characters are kept in ``run.json`` as a SHA-256."""


def _flatten_settings(value: Any, prefix: str = "") -> dict[str, Any]:
    """Scene-file keys as key paths: ``cloth[0].material.density`` -> value (arrays of tables indexed)."""
    if isinstance(value, dict):
        flat: dict[str, Any] = {}
        for key, item in value.items():
            flat.update(_flatten_settings(item, f"{prefix}.{key}" if prefix else str(key)))
        return flat
    if isinstance(value, list) and value and all(isinstance(item, dict) for item in value):
        flat = {}
        for index, item in enumerate(value):
            flat.update(_flatten_settings(item, f"{prefix}[{index}]"))
        return flat
    return {prefix: value}


def _file_sha256(path: Path) -> str:
    digest = hashlib.sha256()
    with open(path, "rb") as stream:
        for block in iter(lambda: stream.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def open_scene(spec: str, *, triangles: int | None = None, scale: float | None = None) -> SceneSource:
    """A built-in scene name or a ``.toml`` file, ready to run.

    Raises:
        InputError: unknown scene, bad size, or a bad scene file (naming its key and the fix).
    """
    if spec.lower().endswith(".toml"):
        path = Path(spec).expanduser().resolve()
        if triangles is not None or scale is not None:
            raise InputError("argument", "--triangles/--scale", "a scene file fixes its own size",
                             "leave out --triangles and --scale, or edit the file")
        if not path.is_file():
            problem = ("is a folder" if path.is_dir() else "is not a regular file" if path.exists()
                       else "is a broken or looping link" if os.path.lexists(path) else "file does not exist")
            raise InputError(str(path), "path", problem, "pass the path of a .toml scene file")
        try:
            raw = tomllib.loads(path.read_text(encoding="utf-8"))
        except (tomllib.TOMLDecodeError, UnicodeDecodeError) as error:
            raise InputError(str(path), "file", f"is not valid TOML ({error})", "fix the syntax") from None
        return source_from_toml(raw, path)
    scene = build(spec, triangles=triangles, scale=scale)
    if scale is not None:
        size: dict[str, Any] = {"scale": float(scale)}
    elif triangles is not None:
        size = {"triangles": int(triangles)}
    elif spec in PAPER_SCENE_NAMES:
        size = {"scale": paper.min_scale(spec)}
    else:
        size = {"triangles": builtin.DEFAULT_TRIANGLES[spec]}
    identity = {"scene": spec, "cloth_triangles": int(scene.faces.shape[0])}
    return SceneSource(scene, None, DEFAULT_FRAMES.get(spec, 30), identity, "builtin", (spec, size))


def source_from_toml(raw: dict[str, Any], path: Path, *, build: Callable[..., Scene] = build) -> SceneSource:
    """The scene a parsed scene file describes (a scene file, or a resolved built-in file with ``[builtin]``).

    This is what :func:`open_scene` does with a ``.toml`` file once it is parsed; ``pscc batch`` calls
    it on scene files with the values of a sweep applied.

    Args:
        raw: the parsed TOML document.
        path: the file it stands for: error messages name it, a scene file's relative paths are
            relative to its folder, and a scene file's run identity records it.
        build: ``build(name, triangles=..., scale=...) -> Scene`` for a built-in file (default
            :func:`build`; a caller checking many variants of one scene may pass a cached one).

    Raises:
        InputError: any key of the document is unknown, of the wrong type or out of range (naming
            ``path``, the key path and the fix).
    """
    if "builtin" in raw:
        scene, contact, options = load_builtin_file(path, raw, build)
        head = options["builtin"]
        size = {k: v for k, v in head.items() if k != "scene"}
        identity = {"scene": head["scene"], "cloth_triangles": int(scene.faces.shape[0])}
        return SceneSource(scene, contact, options["frames"], identity, "builtin", (head["scene"], size))
    loaded = SceneBuilder(path).build(raw)
    identity = {"scene": loaded.scene.name, "file": str(path), "cloth_triangles": int(loaded.scene.faces.shape[0])}
    return SceneSource(loaded.scene, loaded.contact, int(loaded.options["frames"]), identity, "file", loaded)


def scene_rows(scales: tuple[float, ...] = (0.05, 0.25, 1.0)) -> list[dict[str, Any]]:
    """One row per built-in scene for ``pscc scenes``: name, kind, description and triangles per scale.

    Paper scenes: cloth triangles at their smallest scale and at ``scales`` (1 = the paper's);
    test scenes: at their default size. Counts are estimated without building the meshes.
    """
    rows = []
    for name in TEST_SCENES:
        doc = (builtin.SCENES[name].__doc__ or "").strip().splitlines()[0]
        rows.append({"name": name, "kind": "test", "description": doc,
                     "triangles": {"default": builtin.DEFAULT_TRIANGLES[name]}})
    for name in PAPER_SCENE_NAMES:
        doc = (paper.PAPER_SCENES[name].__doc__ or "").strip().splitlines()[0]
        counts = {f"{paper.min_scale(name):.3g} (min)": paper.MIN_TRIANGLES}
        counts.update({f"{s:g}": round(s * paper.PAPER_TRIANGLES[name]) for s in scales
                       if s >= paper.min_scale(name)})
        rows.append({"name": name, "kind": "paper", "description": doc, "triangles": counts})
    return rows
