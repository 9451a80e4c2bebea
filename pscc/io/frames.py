"""NPZ frames and JSON stats, written atomically (a temporary file in the same folder, then a rename).

Frame contract of ``pscc simulate`` (kept by later formats): ``DIR/frames/frame_00000.npz``, ...
with the keys of :data:`FRAME_KEYS`:

==================  ============  ============================================
key                 shape, dtype  meaning
==================  ============  ============================================
vertices            (n, 3) f32    cloth vertex positions [m]
faces               (m, 3) i32    cloth triangles
object_ids          (m,) i32      cloth piece of each triangle
obstacle_vertices   (k, 3) f32    all obstacle vertices at the frame's time [m]
obstacle_faces      (l, 3) i32    obstacle triangles (ids into obstacle_vertices)
==================  ============  ============================================

Obstacle arrays are empty (shape (0, 3)) when the scene has none.
"""

from __future__ import annotations

import json
import os
import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import IO, Any

import numpy as np

FRAME_KEYS: tuple[str, ...] = ("vertices", "faces", "object_ids", "obstacle_vertices", "obstacle_faces")
"""Keys of every frame file, in this order."""


def _write_atomic(path: Path, write: Callable[[IO[bytes]], None]) -> None:
    """Write ``path`` through a temporary sibling and ``os.replace``: readers never see half a file."""
    path = Path(path)
    handle, temporary = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        # mkstemp creates 0600 files; give the finished file the permissions of an ordinary one.
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(temporary, 0o666 & ~umask)
        with os.fdopen(handle, "wb") as stream:
            write(stream)
            stream.flush()
            os.fsync(stream.fileno())
        os.replace(temporary, path)
    except BaseException:
        if os.path.exists(temporary):
            os.unlink(temporary)
        raise


def write_json_atomic(path: Path, data: Any) -> None:
    """Write ``data`` as indented JSON, atomically."""
    text = json.dumps(data, indent=1, sort_keys=False).encode()
    _write_atomic(Path(path), lambda stream: stream.write(text))


def frame_path(out_dir: Path, index: int) -> Path:
    """``out_dir/frames/frame_{index:05d}.npz``."""
    return Path(out_dir) / "frames" / f"frame_{index:05d}.npz"


def write_frame(out_dir: Path, index: int, vertices: np.ndarray, faces: np.ndarray, object_ids: np.ndarray,
                obstacle_vertices: np.ndarray | None = None, obstacle_faces: np.ndarray | None = None) -> Path:
    """Write one frame file (creating ``out_dir/frames``); returns its path.

    Raises:
        ValueError: non-finite vertices (a frame must never hold NaN or Inf).
    """
    vertices = np.ascontiguousarray(vertices, dtype=np.float32)
    if not np.all(np.isfinite(vertices)):
        raise ValueError(f"frame {index}: cloth vertices hold NaN or Inf; not written")
    arrays = {
        "vertices": vertices,
        "faces": np.ascontiguousarray(faces, dtype=np.int32),
        "object_ids": np.ascontiguousarray(object_ids, dtype=np.int32),
        "obstacle_vertices": np.zeros((0, 3), np.float32) if obstacle_vertices is None
        else np.ascontiguousarray(obstacle_vertices, dtype=np.float32),
        "obstacle_faces": np.zeros((0, 3), np.int32) if obstacle_faces is None
        else np.ascontiguousarray(obstacle_faces, dtype=np.int32),
    }
    path = frame_path(out_dir, index)
    path.parent.mkdir(parents=True, exist_ok=True)
    _write_atomic(path, lambda stream: np.savez(stream, **arrays))
    return path


def read_frame(path: Path) -> dict[str, np.ndarray]:
    """Read a frame file into a dict of arrays (the keys of :data:`FRAME_KEYS`)."""
    with np.load(path) as data:
        return {key: data[key] for key in FRAME_KEYS}
