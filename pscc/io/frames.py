"""NPZ frames and JSON stats, written atomically (:mod:`pscc._atomic`: a temporary sibling, then a rename).

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

from pathlib import Path

import numpy as np

from pscc._atomic import write_atomic, write_json_atomic
from pscc.errors import InputError

__all__ = ["FRAME_KEYS", "frame_path", "read_frame", "write_frame", "write_json_atomic"]

FRAME_KEYS: tuple[str, ...] = ("vertices", "faces", "object_ids", "obstacle_vertices", "obstacle_faces")
"""Keys of every frame file, in this order."""


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
    return write_atomic(frame_path(out_dir, index), lambda stream: np.savez(stream, **arrays))


def read_frame(path: Path) -> dict[str, np.ndarray]:
    """Read a frame file into a dict of arrays (the keys of :data:`FRAME_KEYS`).

    Raises:
        InputError: the file is missing, damaged or lacks a key.
    """
    try:
        with np.load(path, allow_pickle=False) as data:
            missing = [key for key in FRAME_KEYS if key not in data.files]
            if missing:
                raise InputError(str(path), missing[0], "is missing", "pass a frame file written by pscc simulate")
            return {key: data[key] for key in FRAME_KEYS}
    except InputError:
        raise
    except Exception as error:  # zipfile.BadZipFile, EOFError, OSError, ValueError, zlib.error: damaged file
        raise InputError(str(path), "file", f"is not a readable frame file ({type(error).__name__}: {error})",
                         "write the frame again (pscc simulate --overwrite)") from None
