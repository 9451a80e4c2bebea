"""Motions and obstacles that scene files create: keyframes about a pivot, and per-frame mesh sequences."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from pscc.errors import InputError, PsccError
from pscc.sim.obstacles import KeyframedMotion, Transform

__all__ = ["PivotedMotion", "SequenceObstacle"]


@dataclass(frozen=True)
class PivotedMotion:
    """Keyframes that rotate about a pivot: ``x(t) = R_k(t) (x_init - pivot) + pivot + c_k(t)``.

    This is the motion of a scene-file handle: ``R_k`` and ``c_k`` come from ``keyframes`` (rotation
    vectors in radians, translations in metres), so keyframe rotations turn the handle about
    ``pivot`` [m] and keyframe translations are displacements from the initial positions.

    Attributes:
        keyframes: the keyframed rotation and translation.
        pivot: (3,) float64 centre of the keyframe rotations [m].
    """

    keyframes: KeyframedMotion
    pivot: np.ndarray

    def __call__(self, t: float) -> Transform:
        """The pose ``(R, c)`` at time ``t`` [s], in the convention ``x(t) = R x_init + c``."""
        rotation, translation = self.keyframes(t)
        pivot = np.asarray(self.pivot, dtype=np.float64)
        return rotation, pivot - rotation @ pivot + translation


@dataclass
class SequenceObstacle:
    """A non-rigid obstacle that plays a per-frame mesh sequence (same topology in every frame).

    Frame k is the obstacle's shape at time ``start_time + k * frame_time``; between two frames every
    vertex moves linearly, before the first frame the shape is the first one, after the last frame
    the last one. It has the attributes the solver reads from an :class:`Obstacle` (``vertices``,
    ``faces``, ``name``, :meth:`positions`), but no rigid pose: :meth:`transform` raises.

    Attributes:
        frames: (k, n, 3) float64 positions of each frame [m], k >= 1.
        faces: (m, 3) int32 vertex ids.
        frame_time: time between frames [s] (> 0).
        name: label used in error messages and stats.
        start_time: time of frame 0 [s].
    """

    frames: np.ndarray
    faces: np.ndarray
    frame_time: float
    name: str = "sequence"
    start_time: float = 0.0

    rigid: ClassVar[bool] = False
    """Always False: the solver cannot describe this obstacle's motion by one rigid transform."""

    def __post_init__(self) -> None:
        frames = np.asarray(self.frames, dtype=np.float64)
        faces = np.asarray(self.faces)
        if frames.ndim != 3 or frames.shape[0] < 1 or frames.shape[2] != 3 or not np.all(np.isfinite(frames)):
            raise InputError(self.name, "frames", f"shape {frames.shape} is not (k, n, 3) finite values, k >= 1",
                             "give one (n, 3) array of positions per frame")
        if faces.ndim != 2 or faces.shape[1] != 3 or faces.shape[0] == 0 or faces.dtype.kind not in "iu":
            raise InputError(self.name, "faces", f"shape {faces.shape} / dtype {faces.dtype} is not (m, 3) ints",
                             "give triangles as an (m, 3) integer array")
        if faces.min() < 0 or faces.max() >= frames.shape[1]:
            raise InputError(self.name, "faces", "a vertex id is out of range", f"use ids in [0, {frames.shape[1]})")
        frame_time = float(self.frame_time)
        if not math.isfinite(frame_time) or frame_time <= 0.0:
            raise InputError(self.name, "frame_time", f"{self.frame_time!r} is not a finite number > 0",
                             "give the time between frames in seconds")
        self.frames = frames
        self.faces = faces.astype(np.int32)
        self.frame_time = frame_time
        self.start_time = float(self.start_time)

    @property
    def vertices(self) -> np.ndarray:
        """(n, 3) float64 positions of frame 0 [m]."""
        return self.frames[0]

    @property
    def times(self) -> np.ndarray:
        """(k,) float64 time of each frame [s]."""
        return self.start_time + self.frame_time * np.arange(self.frames.shape[0], dtype=np.float64)

    def positions(self, t: float) -> np.ndarray:
        """(n, 3) float32 positions at time ``t`` [s], linearly interpolated between frames."""
        last = self.frames.shape[0] - 1
        s = (float(t) - self.start_time) / self.frame_time
        if not s > 0.0:  # also NaN
            return self.frames[0].astype(np.float32)
        if s >= last:
            return self.frames[last].astype(np.float32)
        i = min(int(math.floor(s)), last - 1)
        w = s - i
        return ((1.0 - w) * self.frames[i] + w * self.frames[i + 1]).astype(np.float32)

    def transform(self, t: float) -> Transform:
        """Not available: a mesh sequence has no rigid pose.

        Raises:
            PsccError: always (the solver must use :meth:`positions` for non-rigid obstacles).
        """
        raise PsccError(f"obstacle {self.name!r} is a non-rigid mesh sequence and has no rigid transform; "
                        "the solver must treat it per vertex (use positions(t))")


