"""Your own frames in the corpus comparison (``python -m pscc.bench --frames FILE ...``).

The corpus section (:mod:`pscc.bench.corpus_bench`) measures frames that we chose. This module reads frames
that a user brings, exported by any system, into the same :class:`~pscc.bench.corpus.CorpusFrame`, so
that they are benched side by side with the same methods, rows and targets:

* ``.obj``, ``.ply``, ``.npz`` (keys ``vertices`` and ``faces``): read by :func:`pscc.mesh.load_mesh`, with
  its checks and messages. Object ids come from the file (OBJ ``o``/``g`` groups, a PLY face property,
  the NPZ key). Rest coordinates: the NPZ's ``rest``, else the file's texture coordinates when there is
  one (u, v) per vertex (OBJ ``vt``, PLY ``s, t``, NPZ ``uv``): the flat pattern of a garment exported
  with its UV layout. Without either the frame is benched without rest coordinates only.
* ``.npz`` with a ``positions`` key: a cached corpus frame (:meth:`CorpusFrame.save`).
* ``.usd``, ``.usda``, ``.usdc``, ``.usdz``: every ``UsdGeom.Mesh`` of the stage, one object each, its
  points at the time code ``usd_time`` when given (an animation: the frame to bench), else at the default
  time when authored, else at their first time sample (:data:`USD_TIME_NOTE`), moved by the prim's
  local-to-world transform at that time and fan-triangulated; no rest coordinates.

The contact radius is ``radius`` when given, else half the frame's median edge length
(:func:`pscc.bench.corpus.half_median_edge`), as for the shipped meshes of the corpus. Every problem
raises :class:`~pscc.errors.InputError` naming the file, the field and the fix.
"""

from __future__ import annotations

import math
import os
from pathlib import Path

import numpy as np

from pscc.bench.corpus import USD_TIME_NOTE, CorpusFrame, half_median_edge, read_usd_meshes
from pscc.errors import InputError
from pscc.mesh.io import load_mesh
from pscc.mesh.mesh_data import validate_mesh

__all__ = ["FRAME_EXTENSIONS", "USD_EXTENSIONS", "USD_TIME_NOTE", "load_user_frame", "load_user_frames"]

USD_EXTENSIONS: tuple[str, ...] = (".usd", ".usda", ".usdc", ".usdz")
"""Extensions read as USD stages."""

FRAME_EXTENSIONS: tuple[str, ...] = (".obj", ".ply", ".npz", *USD_EXTENSIONS)
"""Every extension :func:`load_user_frame` reads (case-insensitive)."""


def load_user_frame(path: str | os.PathLike[str], radius: float | None = None,
                    usd_time: float | None = None) -> CorpusFrame:
    """Read one frame from a mesh file (module docstring).

    Args:
        path: the file.
        radius: the DCD contact radius (length units of the file); None: half the median edge length.
        usd_time: USD only: the time code whose points are benched (None: :data:`USD_TIME_NOTE`).

    Returns:
        The frame, named after the file; its ``source`` says what was read and which radius is used.

    Raises:
        InputError: the file is missing, unreadable, of another format, or not a valid triangle mesh; or
            ``radius`` is not a positive finite number.
    """
    file = Path(path)
    if radius is not None and not (math.isfinite(radius) and radius > 0.0):
        raise InputError("argument", "--frame-radius", f"is {radius!r}", "give a positive contact radius")
    extension = file.suffix.lower()
    if extension not in FRAME_EXTENSIONS:
        raise InputError(str(file), "extension", f"{file.suffix or 'no extension'} is not a frame format",
                         f"export the frame as one of {', '.join(FRAME_EXTENSIONS)}")
    if not file.is_file():
        raise InputError(str(file), "file", "does not exist or is not a file", "check the path")
    if extension in USD_EXTENSIONS:
        frame = _usd_frame(file, usd_time)
    elif extension == ".npz" and _is_corpus_npz(file):
        frame = _corpus_npz_frame(file)
    else:
        frame = _mesh_frame(file)
    if radius is None:
        return CorpusFrame(frame.name, f"{frame.source}; contact radius: half its median edge length",
                           frame.positions, frame.faces, frame.rest, frame.object_ids, frame.radius)
    return CorpusFrame(frame.name, f"{frame.source}; contact radius: {radius:g} (given)", frame.positions,
                       frame.faces, frame.rest, frame.object_ids, float(radius))


def load_user_frames(paths: list[str], radius: float | None = None, usd_time: float | None = None) -> list[CorpusFrame]:
    """:func:`load_user_frame` for every path, all read before any is benched (a bad file stops the run
    before it starts). Frames whose file names repeat get the parent folder in their name."""
    frames = [load_user_frame(p, radius, usd_time) for p in paths]
    names = [f.name for f in frames]
    out = []
    for path, frame in zip(paths, frames, strict=True):
        if names.count(frame.name) > 1:
            name = f"{Path(path).parent.name}/{frame.name}"
            frame = CorpusFrame(name, frame.source, frame.positions, frame.faces, frame.rest, frame.object_ids,
                                frame.radius)
        out.append(frame)
    return out


def _mesh_frame(file: Path) -> CorpusFrame:
    mesh = load_mesh(file)
    rest, what = mesh.rest, "its rest coordinates"
    if rest is None and mesh.uv is not None:
        rest, what = mesh.uv, "its texture coordinates as rest coordinates"
    elif rest is None:
        what = "no rest coordinates" + (f" ({mesh.uv_issue})" if mesh.uv_issue else "")
    ids = mesh.object_ids if np.any(mesh.object_ids != mesh.object_ids[0]) else None
    source = f"`{file.name}` ({mesh.vertices.shape[0]:,} vertices), {what}"
    return CorpusFrame(file.stem, source, mesh.vertices, mesh.faces, rest, ids,
                       half_median_edge(mesh.vertices, mesh.faces))


def _is_corpus_npz(file: Path) -> bool:
    try:
        with np.load(file) as data:
            return "positions" in data.files
    except (OSError, ValueError) as exc:
        raise InputError(str(file), "file", f"cannot be read as NPZ ({exc})", "write it with numpy.savez") from exc


def _corpus_npz_frame(file: Path) -> CorpusFrame:
    """An NPZ in the corpus layout (:meth:`CorpusFrame.save`): ``positions`` and ``faces``, optional ``rest``,
    ``object_ids`` and the ``name`` and ``source`` of a cached frame."""
    with np.load(file) as data:
        if "faces" not in data.files:
            raise InputError(str(file), "faces", "is missing (the file has positions, so it was read as a corpus "
                             "frame)", "add the (m, 3) triangles as key faces, or name the positions vertices")
        arrays = {key: data[key] for key in ("positions", "faces", "rest", "object_ids") if key in data.files}
        origin = f" ({data['name']}: {data['source']})" if "name" in data.files and "source" in data.files else ""
    mesh = validate_mesh(arrays["positions"], arrays["faces"], source=str(file), rest=arrays.get("rest"),
                         object_ids=arrays.get("object_ids"))
    ids = mesh.object_ids if "object_ids" in arrays else None
    return CorpusFrame(file.stem, f"corpus frame `{file.name}`{origin}", mesh.vertices, mesh.faces, mesh.rest, ids,
                       half_median_edge(mesh.vertices, mesh.faces))


def _usd_frame(file: Path, usd_time: float | None) -> CorpusFrame:
    positions, faces, object_ids, what = read_usd_meshes(file, usd_time)
    return CorpusFrame(file.stem, f"`{file.name}`: {what}", positions, faces, None, object_ids,
                       half_median_edge(positions, faces))
