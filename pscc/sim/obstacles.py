"""Animated rigid obstacles: triangle meshes moved by prescribed rigid motions.

An obstacle is kinematic: the simulator never changes its motion, cloth responds to it. Its pose
at time t is ``x(t) = R(t) x_rest + c(t)``; during a step the collision detector sees every
obstacle vertex move on the straight line between its poses at the step's start and end (the
same linear trajectories as the cloth), which is the affine family ``(1 - s) I + s R`` of an
intersection-free start, so an obstacle never folds through itself.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from pscc.errors import InputError

Transform = tuple[np.ndarray, np.ndarray]
"""A rigid transform ``(R, c)``: (3, 3) rotation and (3,) translation, float64."""


def rotation_from_axis_angle(rotation_vector: np.ndarray) -> np.ndarray:
    """(3, 3) rotation matrix of a rotation vector (axis times angle in radians; Rodrigues)."""
    w = np.asarray(rotation_vector, dtype=np.float64)
    angle = float(np.linalg.norm(w))
    if angle < 1e-15:
        return np.eye(3)
    k = w / angle
    cross = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    return np.eye(3) + math.sin(angle) * cross + (1.0 - math.cos(angle)) * cross @ cross


def quaternion_from_rotation_vector(rotation_vector: np.ndarray) -> np.ndarray:
    """Unit quaternion (w, x, y, z) of a rotation vector (axis times angle [rad])."""
    w = np.asarray(rotation_vector, dtype=np.float64)
    angle = float(np.linalg.norm(w))
    if angle < 1e-15:
        return np.array([1.0, 0.0, 0.0, 0.0])
    return np.concatenate([[math.cos(angle / 2.0)], math.sin(angle / 2.0) * w / angle])


def quaternion_matrix(q: np.ndarray) -> np.ndarray:
    """3x3 rotation matrix of a quaternion (w, x, y, z), normalised first."""
    w, x, y, z = q / np.linalg.norm(q)
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
    ])


def slerp(q0: np.ndarray, q1: np.ndarray, s: float) -> np.ndarray:
    """Spherical linear interpolation of unit quaternions at s in [0, 1] (the shorter arc)."""
    dot = float(np.dot(q0, q1))
    if dot < 0.0:
        q1, dot = -q1, -dot
    if dot > 0.9995:
        q = q0 + s * (q1 - q0)
        return q / np.linalg.norm(q)
    theta = math.acos(min(dot, 1.0))
    return (math.sin((1.0 - s) * theta) * q0 + math.sin(s * theta) * q1) / math.sin(theta)


@dataclass(frozen=True)
class KeyframedMotion:
    """A rigid motion through keyframes: translation interpolated linearly, rotation by slerp.

    Before the first keyframe the pose is the first one; after the last, the last one.

    Attributes:
        times: (k,) increasing keyframe times [s].
        translations: (k, 3) translations c [m].
        rotations: (k, 3) rotation vectors (axis x angle) [rad]; rotations act about the
            obstacle's own origin (its rest-pose coordinates), before the translation.
    """

    times: np.ndarray
    translations: np.ndarray
    rotations: np.ndarray = field(default=None)  # type: ignore[assignment]

    def __post_init__(self) -> None:
        times = np.asarray(self.times, dtype=np.float64).reshape(-1)
        translations = np.asarray(self.translations, dtype=np.float64)
        rotations = np.zeros_like(translations) if self.rotations is None else np.asarray(self.rotations, np.float64)
        k = times.shape[0]
        if k == 0 or not np.all(np.isfinite(times)) or np.any(np.diff(times) <= 0.0):
            raise InputError("motion", "times", "keyframe times must be a non-empty, finite, increasing list",
                             "give increasing times in seconds")
        for name, value in (("translations", translations), ("rotations", rotations)):
            if value.shape != (k, 3) or not np.all(np.isfinite(value)):
                raise InputError("motion", name, f"shape {value.shape} is not ({k}, 3) finite values",
                                 f"give one finite 3-vector per keyframe ({k})")
        object.__setattr__(self, "times", times)
        object.__setattr__(self, "translations", translations)
        object.__setattr__(self, "rotations", rotations)

    def __call__(self, t: float) -> Transform:
        """The pose at time ``t`` [s]."""
        times = self.times
        if t <= times[0]:
            return rotation_from_axis_angle(self.rotations[0]), self.translations[0].copy()
        if t >= times[-1]:
            return rotation_from_axis_angle(self.rotations[-1]), self.translations[-1].copy()
        i = int(np.searchsorted(times, t, side="right")) - 1
        s = (t - times[i]) / (times[i + 1] - times[i])
        c = (1.0 - s) * self.translations[i] + s * self.translations[i + 1]
        q = slerp(quaternion_from_rotation_vector(self.rotations[i]),
                  quaternion_from_rotation_vector(self.rotations[i + 1]), s)
        return quaternion_matrix(q), c


def static_motion(t: float) -> Transform:
    """The identity pose at every time."""
    return np.eye(3), np.zeros(3)


@dataclass
class Obstacle:
    """A rigid triangle mesh with a prescribed motion.

    Attributes:
        vertices: (n, 3) rest-pose positions [m].
        faces: (m, 3) vertex ids.
        motion: callable ``t -> (R, c)`` (e.g. :class:`KeyframedMotion`); default: static.
        name: label used in error messages and stats.
    """

    vertices: np.ndarray
    faces: np.ndarray
    motion: Callable[[float], Transform] = static_motion
    name: str = "obstacle"

    def __post_init__(self) -> None:
        vertices = np.asarray(self.vertices, dtype=np.float64)
        faces = np.asarray(self.faces)
        if vertices.ndim != 2 or vertices.shape[1] != 3 or not np.all(np.isfinite(vertices)):
            raise InputError(self.name, "vertices", f"shape {vertices.shape} is not (n, 3) finite values",
                             "give the obstacle's rest positions as an (n, 3) array")
        if faces.ndim != 2 or faces.shape[1] != 3 or faces.shape[0] == 0 or faces.dtype.kind not in "iu":
            raise InputError(self.name, "faces", f"shape {faces.shape} / dtype {faces.dtype} is not (m, 3) ints",
                             "give triangles as an (m, 3) integer array")
        if faces.min() < 0 or faces.max() >= vertices.shape[0]:
            raise InputError(self.name, "faces", "a vertex id is out of range",
                             f"use ids in [0, {vertices.shape[0]})")
        self.vertices = vertices
        self.faces = faces.astype(np.int32)

    def transform(self, t: float) -> Transform:
        """The pose ``(R, c)`` at time ``t`` [s], validated."""
        rotation, translation = self.motion(float(t))
        rotation = np.asarray(rotation, dtype=np.float64)
        translation = np.asarray(translation, dtype=np.float64).reshape(3)
        if rotation.shape != (3, 3) or not np.all(np.isfinite(rotation)) or not np.all(np.isfinite(translation)):
            raise InputError(self.name, "motion", f"the motion returned a bad pose at t={t:g}",
                             "return a finite (3, 3) rotation and a 3-vector")
        return rotation, translation

    def positions(self, t: float) -> np.ndarray:
        """(n, 3) float32 positions at time ``t`` [s]."""
        rotation, translation = self.transform(t)
        return (self.vertices @ rotation.T + translation).astype(np.float32)


@dataclass
class Handle:
    """Cloth vertices whose motion is prescribed (pins are handles with the static motion).

    The vertices follow ``x(t) = R(t) x_init + c(t)``, where ``x_init`` are their positions in the
    initial state and ``(R, c) = motion(t)``.

    Attributes:
        vertices: (k,) cloth vertex ids.
        motion: callable ``t -> (R, c)``; default: static (pinned).
        name: label used in error messages and stats.
    """

    vertices: np.ndarray
    motion: Callable[[float], Transform] = static_motion
    name: str = "handle"

    def __post_init__(self) -> None:
        vertices = np.asarray(self.vertices)
        if vertices.ndim != 1 or vertices.size == 0 or vertices.dtype.kind not in "iu":
            raise InputError(self.name, "vertices", f"shape {vertices.shape} / dtype {vertices.dtype} is not (k,) ints",
                             "give the handle's cloth vertex ids as a non-empty integer list")
        if np.unique(vertices).size != vertices.size:
            raise InputError(self.name, "vertices", "a vertex id is listed twice", "list each vertex once")
        self.vertices = vertices.astype(np.int64)

    def transform(self, t: float) -> Transform:
        """The pose ``(R, c)`` at time ``t`` [s], validated."""
        rotation, translation = self.motion(float(t))
        rotation = np.asarray(rotation, dtype=np.float64)
        translation = np.asarray(translation, dtype=np.float64).reshape(3)
        if rotation.shape != (3, 3) or not np.all(np.isfinite(rotation)) or not np.all(np.isfinite(translation)):
            raise InputError(self.name, "motion", f"the motion returned a bad pose at t={t:g}",
                             "return a finite (3, 3) rotation and a 3-vector")
        return rotation, translation


def step_map(transform_t0: Transform, transform_t1: Transform) -> tuple[np.ndarray, np.ndarray]:
    """The map ``x1 = A x0 + b`` taking a point's pose at t0 to its pose at t1 (same rest point)."""
    r0, c0 = transform_t0
    r1, c1 = transform_t1
    matrix = r1 @ r0.T
    return matrix, c1 - matrix @ c0
