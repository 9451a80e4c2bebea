"""Scene files: TOML descriptions of a cloth simulation that users write (``pscc simulate scene.toml``).

The format is documented in ``docs/scene-files.md``; ``examples/drape.toml`` is a complete example.
In short, a file has the tables

* ``[scene]``: name, description, ``frame_rate`` [1/s] or ``frame_time`` [s], ``steps_per_frame``,
  ``frames`` (the default frame count of a run);
* ``[solver]``: any :class:`pscc.sim.config.SolverConfig` field; ``[contact]``: any
  :class:`pscc.sim.contact_config.ContactConfig` field;
* ``[[cloth]]`` (one or more pieces): ``mesh = "file"`` or ``[cloth.sheet]``, placement
  (``translate``, ``rotate`` in degrees, ``scale``), ``[cloth.material]``, ``pins`` and
  ``[[cloth.handles]]``;
* ``[[obstacle]]``: ``mesh``, ``sphere``, ``box`` or a per-frame mesh ``sequence``, placement and
  ``keyframes``.

Every key is checked: an unknown key (with a "did you mean" suggestion), a value of the wrong type or
out of range, a missing file or an out-of-range vertex id raises :class:`pscc.errors.InputError`
whose message names the scene file, the key path (``cloth[1].material.density``, 0-based indices),
the problem and the fix.

Public API:

* :func:`load_scene_file`: ``path -> (Scene, ContactConfig, options)``.
* :func:`read_scene_file`: the same as one :class:`SceneFile` that also holds the resolved spec.
* :func:`resolved_scene_toml`: the fully resolved file (every key with its value, defaults filled in,
  selections as vertex ids, paths absolute); loading it gives the same scene.
* :class:`SequenceObstacle`: a non-rigid obstacle that plays a per-frame mesh sequence.
"""

from __future__ import annotations

import copy
import os
import tomllib
from pathlib import Path
from typing import Any

import numpy as np

from pscc.errors import InputError
from pscc.scenes.scene_builder import (
    CORNERS,
    DEFAULT_FRAME_RATE,
    DEFAULT_FRAMES,
    DEFAULT_STEPS_PER_FRAME,
    FLATNESS_TOLERANCE,
    POSE_TOLERANCE,
    SIDE_TOLERANCE,
    SIDES,
    SceneBuilder,
    SceneFile,
)
from pscc.scenes.scene_motions import PivotedMotion, SequenceObstacle
from pscc.scenes.toml_text import config_to_toml, dump_toml
from pscc.sim.contact_config import ContactConfig
from pscc.sim.scene import Scene

__all__ = [
    "DEFAULT_FRAMES",
    "DEFAULT_FRAME_RATE",
    "DEFAULT_STEPS_PER_FRAME",
    "FLATNESS_TOLERANCE",
    "POSE_TOLERANCE",
    "SIDE_TOLERANCE",
    "SIDES",
    "CORNERS",
    "PivotedMotion",
    "SceneFile",
    "SequenceObstacle",
    "load_scene_file",
    "read_scene_file",
    "resolved_scene_toml",
]




def read_scene_file(path: str | os.PathLike[str]) -> SceneFile:
    """Parse, check and build a scene file.

    Args:
        path: the TOML file; relative mesh paths in it are relative to its folder.

    Returns:
        The scene, its contact settings, the run options and the resolved spec.

    Raises:
        InputError: the file is missing or not TOML, or any key is unknown, of the wrong type, out of
            range, names a missing or bad mesh file or an out-of-range vertex id. The message names
            the file, the key path, the problem and the fix.
    """
    file_path = Path(os.path.abspath(os.path.expanduser(os.fspath(path))))
    source = str(file_path)
    if not file_path.exists():
        raise InputError(source, "path", "file does not exist", "check the path of the scene file")
    if not file_path.is_file():
        raise InputError(source, "path", "is not a regular file", "pass the path of a .toml scene file")
    try:
        with open(file_path, "rb") as handle:
            raw = tomllib.load(handle)
    except OSError as exc:
        raise InputError(source, "file", f"cannot be read ({exc.strerror or exc})",
                         "check the file permissions") from exc
    except tomllib.TOMLDecodeError as exc:
        raise InputError(source, "file", f"is not valid TOML ({exc})",
                         "fix the syntax at the line and column named (see https://toml.io)") from exc
    except UnicodeDecodeError as exc:
        raise InputError(source, "file", f"is not UTF-8 text ({exc})", "save the scene file as UTF-8") from exc
    return SceneBuilder(file_path).build(raw)


def load_scene_file(path: str | os.PathLike[str]) -> tuple[Scene, ContactConfig, dict[str, Any]]:
    """Load a scene file (format: ``docs/scene-files.md``).

    Args:
        path: the TOML file; relative mesh paths in it are relative to its folder.

    Returns:
        ``(scene, contact, options)``; ``options`` holds ``frames`` (the default frame count of a run)
        and ``source`` (the absolute path of the file).

    Raises:
        InputError: see :func:`read_scene_file`.
    """
    loaded = read_scene_file(path)
    return loaded.scene, loaded.contact, dict(loaded.options)


def resolved_scene_toml(source: SceneFile | str | os.PathLike[str], *, frames: int | None = None,
                        contact: ContactConfig | None = None) -> str:
    """The fully resolved scene file, as TOML text.

    Every key is written with its value (defaults filled in), vertex selections (``pins``, handle
    ``vertices``) as explicit ids, handle pivots explicitly, mesh paths and sequences as absolute file
    paths. :func:`load_scene_file` on this text gives the same scene, contact settings and options.
    ``pscc simulate`` writes it next to its outputs so that the run can be reproduced.

    Args:
        source: a :class:`SceneFile` or the path of a scene file.
        frames: the frame count actually run, when it differs from the file's (e.g. ``--frames``).
        contact: the contact settings actually used, when they differ from the file's (e.g. ``--method``).

    Returns:
        The TOML text (UTF-8, ends with a newline).

    Raises:
        InputError: ``source`` cannot be loaded, or ``frames`` / ``contact`` is invalid.
    """
    loaded = source if isinstance(source, SceneFile) else read_scene_file(source)
    spec = copy.deepcopy(loaded.spec)
    if frames is not None:
        if isinstance(frames, bool) or not isinstance(frames, int | np.integer) or frames < 1:
            raise InputError("argument", "frames", f"{frames!r} is not an integer >= 1", "pass 1 or more frames")
        spec["scene"]["frames"] = int(frames)
    if contact is not None:
        if not isinstance(contact, ContactConfig):
            raise InputError("argument", "contact", f"{type(contact).__name__} is not a ContactConfig",
                             "pass a pscc.sim.contact_config.ContactConfig")
        contact.validate()
        spec["contact"] = config_to_toml(contact)
    header = (f"# Resolved scene file, written by pscc from {loaded.path}.\n"
              "# Every setting is explicit (defaults filled in, selections as vertex ids, absolute paths):\n"
              "# loading this file gives the same scene. Format: docs/scene-files.md.\n")
    return header + dump_toml(spec)


