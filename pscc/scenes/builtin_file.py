"""Resolved scene files of built-in scenes: the builder, its size and every setting, as TOML.

A built-in scene is procedural, so its resolved file names the builder instead of listing meshes:

.. code-block:: toml

    [builtin]
    scene = "twist"        # a name of ``pscc scenes``
    triangles = 2000       # or: scale = 0.05 (the paper's scenes)
    frames = 30

    [scene]                # frame_time [s], steps_per_frame
    [material]             # ClothMaterial fields ([[material]] per cloth piece when they differ)
    [solver]               # SolverConfig fields
    [contact]              # ContactConfig fields

``pscc simulate run/scene.toml`` loads it back (:func:`load_builtin_file`) and reproduces the run.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any

from pscc.errors import InputError
from pscc.scenes.toml_text import config_to_toml, dump_toml
from pscc.sim.config import ClothMaterial, SolverConfig
from pscc.sim.contact_config import ContactConfig
from pscc.sim.scene import Scene

_SIZE_KEYS = ("triangles", "scale")


def builtin_scene_toml(name: str, size: dict[str, float | int], frames: int, scene: Scene,
                       contact: ContactConfig) -> str:
    """The resolved TOML text of a built-in scene run.

    Args:
        name: the builder's name.
        size: ``{"triangles": T}`` or ``{"scale": S}``, as given to the builder.
        frames: frames of the run.
        scene: the built scene (its material, solver and time stepping are written).
        contact: the contact settings used.
    """
    materials = scene.material if isinstance(scene.material, list) else None
    data: dict[str, Any] = {
        "builtin": {"scene": name, **size, "frames": int(frames)},
        "scene": {"frame_time": float(scene.frame_time), "steps_per_frame": int(scene.steps_per_frame)},
    }
    if materials is None:
        data["material"] = config_to_toml(scene.material)
    else:
        data["material"] = [config_to_toml(m) for m in materials]
    data["solver"] = config_to_toml(scene.solver)
    data["contact"] = config_to_toml(contact)
    header = (f"# Resolved scene file of the built-in scene {name!r}, written by pscc simulate.\n"
              "# `pscc simulate scene.toml` reproduces the run. Format: pscc/scenes/builtin_file.py.\n")
    return header + dump_toml(data)


def _config(cls: type, table: Any, source: str, key: str) -> Any:
    if not isinstance(table, dict):
        raise InputError(source, key, "is not a table", f"write [{key}] with the fields of {cls.__name__}")
    names = {f.name for f in dataclasses.fields(cls)}
    unknown = sorted(set(table) - names)
    if unknown:
        renamed = getattr(cls, "renamed_fields", {})
        fix = (f"it was replaced by {renamed[unknown[0]]!r}" if unknown[0] in renamed
               else f"use one of {', '.join(sorted(names))}")
        raise InputError(source, f"{key}.{unknown[0]}", "is not a field of " + cls.__name__, fix)
    values = {k: (None if v == "auto" else tuple(v) if isinstance(v, list) else v) for k, v in table.items()}
    try:
        return cls(**values).validate()
    except InputError as error:
        raise InputError(source, f"{key}.{error.field}", error.problem, error.fix) from None
    except TypeError as error:
        raise InputError(source, key, str(error), f"give the fields of {cls.__name__}") from None


def load_builtin_file(path: Path, raw: dict[str, Any], build: Any) -> tuple[Scene, ContactConfig, dict[str, Any]]:
    """Build the scene a resolved built-in file describes.

    Args:
        path: the file (for messages).
        raw: its parsed TOML.
        build: ``build(name, triangles=..., scale=...) -> Scene`` (the scene registry).

    Returns:
        ``(scene, contact, options)`` with ``options = {"frames": ..., "source": ..., "builtin": {...}}``.

    Raises:
        InputError: unknown keys, an unknown scene, or invalid settings (naming the key and the fix).
    """
    source = str(path)
    unknown = sorted(set(raw) - {"builtin", "scene", "material", "solver", "contact"})
    if unknown:
        raise InputError(source, unknown[0], "is not a table of a built-in scene file",
                         "use [builtin], [scene], [material], [solver] and [contact]")
    head = raw["builtin"]
    if not isinstance(head, dict) or "scene" not in head:
        raise InputError(source, "builtin.scene", "is missing", 'write scene = "drape" (see pscc scenes)')
    extra = sorted(set(head) - {"scene", "frames", *_SIZE_KEYS})
    if extra:
        raise InputError(source, f"builtin.{extra[0]}", "is not a key of [builtin]",
                         "use scene, frames and triangles or scale")
    size = {k: head[k] for k in _SIZE_KEYS if k in head}
    scene = build(str(head["scene"]), **size)
    timing = raw.get("scene", {})
    if not isinstance(timing, dict) or sorted(set(timing) - {"frame_time", "steps_per_frame"}):
        raise InputError(source, "scene", "holds keys other than frame_time and steps_per_frame",
                         "keep only frame_time and steps_per_frame in [scene]")
    frame_time = timing.get("frame_time", scene.frame_time)
    steps = timing.get("steps_per_frame", scene.steps_per_frame)
    if not isinstance(frame_time, int | float) or not frame_time > 0:
        raise InputError(source, "scene.frame_time", f"{frame_time!r} is not a time > 0", "give seconds, e.g. 0.0333")
    if isinstance(steps, bool) or not isinstance(steps, int) or steps < 1:
        raise InputError(source, "scene.steps_per_frame", f"{steps!r} is not an integer >= 1", "give e.g. 8")
    scene.frame_time, scene.steps_per_frame = float(frame_time), steps
    if "material" in raw:
        material = raw["material"]
        if isinstance(material, list):
            scene.material = [_config(ClothMaterial, m, source, f"material[{i}]") for i, m in enumerate(material)]
        else:
            scene.material = _config(ClothMaterial, material, source, "material")
    if "solver" in raw:
        scene.solver = _config(SolverConfig, raw["solver"], source, "solver")
    contact = _config(ContactConfig, raw["contact"], source, "contact") if "contact" in raw else ContactConfig()
    frames = head.get("frames", 30)
    if isinstance(frames, bool) or not isinstance(frames, int) or frames < 1:
        raise InputError(source, "builtin.frames", f"{frames!r} is not an integer >= 1", "give e.g. 30")
    return scene, contact, {"frames": frames, "source": source, "builtin": {"scene": head["scene"], **size}}
