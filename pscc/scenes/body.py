"""A procedural, articulated humanoid skeleton for the garment benchmarks (``kungfu``, ``falling``, ``dance``).

The body is a small joint hierarchy (forward kinematics) carrying rigid parts. Every part is a
*sphere-swept core*: the set of points within ``radius`` of a segment (a capsule: limbs, pelvis,
head) or of a rectangle (a rounded slab: the torso). The parts are the shape the garment scenes'
mannequin is built from (:func:`pscc.scenes.mannequin.mannequin`: their smooth union, bridged at the
joints, skinned to the joints' motions); the garments are fitted to them and anchored to their joints.

Each child limb hangs on a *ball joint*: its first end is a sphere centred on the joint pivot, and the
parent stops :data:`JOINT_GAP` short of it, so the parts themselves never overlap in the rest pose
(the mannequin's smooth union closes the gaps).

Coordinates (metres): z up, the body faces +y, its left side is +x. In the rest pose (the pose at
t = 0 of every animation here) the body stands with the feet 0.04 m above z = 0, legs slightly
apart and the arms 45 degrees away from the torso (an A-pose), so garments fit around the limbs.

Motion: each joint's *local* rotation (a callable ``t -> (3, 3)``, expressed in the rest-pose axes
of the world, about the joint pivot) and the root's translation (``t -> (3,)``). A joint's world
transform is its parent's composed with its local rotation about its pivot; a part moves with its
joint, ``x(t) = R(t) x_rest + c(t)``. :class:`EasedMotion` gives keyframed tracks (slerp between
keyframes with a smoothstep ease, so every keyframe is reached with zero velocity and a motion
starting at a keyframe starts at rest); :func:`spin` gives a smooth turn about a fixed axis.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from pscc.errors import InputError
from pscc.sim.obstacles import (
    Transform,
    quaternion_from_rotation_vector,
    quaternion_matrix,
    rotation_from_axis_angle,
    slerp,
)

RotationTrack = Callable[[float], np.ndarray]
"""A joint's local rotation over time: ``t [s] -> (3, 3)`` rotation matrix."""

TranslationTrack = Callable[[float], np.ndarray]
"""The root's translation over time: ``t [s] -> (3,)`` [m]."""

JOINT_GAP: float = 0.012
"""Gap [m] between a limb's ball-joint sphere and its parent part in the rest pose (the mannequin's
bridges and smooth union close it)."""


# ---------------------------------------------------------------------------------------------- motion


def smoothstep(x: float) -> float:
    """``3 x^2 - 2 x^3`` on [0, 1], clamped outside: 0 -> 0 and 1 -> 1 with zero slope at both ends."""
    x = min(max(float(x), 0.0), 1.0)
    return x * x * (3.0 - 2.0 * x)


class EasedMotion:
    """Keyframed rigid motion: slerp (rotation) and linear (translation) between keyframes, eased.

    Inside each keyframe interval the interpolation parameter is ``smoothstep`` of the normalised
    time, so the motion is C1: every keyframe is passed with zero velocity (a short hold), and a
    motion that starts at its first keyframe starts at rest. Before the first keyframe the pose is
    the first one, after the last the last one. Each interval should turn by less than 180 degrees
    (slerp takes the short way).

    Args:
        times: (k,) increasing keyframe times [s].
        translations: (k, 3) translations [m]; default zeros.
        rotations: (k, 3) rotation vectors (axis times angle) [rad]; default zeros.

    Raises:
        InputError: times not increasing, or arrays of the wrong shape.
    """

    def __init__(self, times: Sequence[float] | np.ndarray, translations: np.ndarray | None = None,
                 rotations: np.ndarray | None = None) -> None:
        self.times = np.asarray(times, dtype=np.float64).reshape(-1)
        k = self.times.shape[0]
        if k == 0 or not np.all(np.isfinite(self.times)) or np.any(np.diff(self.times) <= 0.0):
            raise InputError("motion", "times", "keyframe times must be a non-empty, finite, increasing list",
                             "give increasing times in seconds")
        self.translations = np.zeros((k, 3)) if translations is None else np.asarray(translations, np.float64)
        self.rotations = np.zeros((k, 3)) if rotations is None else np.asarray(rotations, np.float64)
        for name, value in (("translations", self.translations), ("rotations", self.rotations)):
            if value.shape != (k, 3) or not np.all(np.isfinite(value)):
                raise InputError("motion", name, f"shape {value.shape} is not ({k}, 3) finite values",
                                 f"give one finite 3-vector per keyframe ({k})")
        self._quaternions = [quaternion_from_rotation_vector(r) for r in self.rotations]

    def _segment(self, t: float) -> tuple[int, float]:
        times = self.times
        if t <= times[0]:
            return 0, 0.0
        if t >= times[-1]:
            return len(times) - 1, 0.0
        i = int(np.searchsorted(times, t, side="right")) - 1
        return i, smoothstep((t - times[i]) / (times[i + 1] - times[i]))

    def rotation(self, t: float) -> np.ndarray:
        """(3, 3) rotation at time ``t`` [s]."""
        i, s = self._segment(float(t))
        if s == 0.0:
            return quaternion_matrix(self._quaternions[i])
        return quaternion_matrix(slerp(self._quaternions[i], self._quaternions[i + 1], s))

    def translation(self, t: float) -> np.ndarray:
        """(3,) translation at time ``t`` [s]."""
        i, s = self._segment(float(t))
        if s == 0.0:
            return self.translations[i].copy()
        return (1.0 - s) * self.translations[i] + s * self.translations[i + 1]

    def __call__(self, t: float) -> Transform:
        """The pose ``(R, c)`` at time ``t`` [s] (rotation about the origin, then translation)."""
        return self.rotation(t), self.translation(t)

    @property
    def duration(self) -> float:
        """Time of the last keyframe [s]."""
        return float(self.times[-1])


def spin(axis: Sequence[float], turns: float, start: float, duration: float) -> RotationTrack:
    """A turn about a fixed ``axis`` by ``turns`` full turns during [start, start + duration] [s].

    The angle is ``2 pi turns smoothstep((t - start) / duration)``: at rest before and after, the
    peak angular speed (mid-way) is 1.5 times the mean.
    """
    direction = np.asarray(axis, dtype=np.float64)
    direction = direction / np.linalg.norm(direction)
    total = 2.0 * math.pi * float(turns)

    def track(t: float) -> np.ndarray:
        return rotation_from_axis_angle(direction * total * smoothstep((float(t) - start) / duration))

    return track


# ---------------------------------------------------------------------------------------------- geometry


def _frame(core: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Origin and orthonormal axes (ex along the first edge, ez normal to the core) of a core."""
    origin = core[0]
    first = core[1] - core[0]
    ex = first / np.linalg.norm(first)
    if core.shape[0] == 4:
        ez = np.cross(first, core[3] - core[0])
    else:
        helper = np.array([0.0, 0.0, 1.0]) if abs(ex[2]) < 0.9 else np.array([1.0, 0.0, 0.0])
        ez = np.cross(ex, helper)
    ez = ez / np.linalg.norm(ez)
    ey = np.cross(ez, ex)
    return origin, ex, ey, ez


def rounded_core_mesh(core: np.ndarray, radius: float, around: int = 24,
                      rings: int = 8) -> tuple[np.ndarray, np.ndarray]:
    """A closed, outward-oriented mesh of the points within ``radius`` of a segment or a rectangle.

    The mesh is a latitude-longitude sphere (poles along the core's normal) whose vertices are
    pushed out to the core corner whose normal cone holds their direction; flat strips join the
    corners and the rectangle's two faces are flat. All vertices lie on the exact surface, so the
    mesh lies inside it.

    Args:
        core: (2, 3) segment end points or (4, 3) rectangle corners in order (c0 -> c1 and c0 -> c3
            perpendicular) [m].
        radius: sweep radius [m] (> 0).
        around: vertices around the equator (>= 8).
        rings: latitude intervals from pole to pole (>= 3).

    Returns:
        ``(vertices, faces)``: (n, 3) float32 and (m, 3) int32.

    Raises:
        InputError: a core that is not 2 or 4 points, a degenerate core or a bad size.
    """
    core = np.asarray(core, dtype=np.float64)
    if core.ndim != 2 or core.shape[0] not in (2, 4) or core.shape[1] != 3:
        raise InputError("argument", "core", f"shape {core.shape} is not (2, 3) or (4, 3)",
                         "give a segment or a rectangle's four corners")
    if not radius > 0.0 or around < 8 or rings < 3:
        raise InputError("argument", "radius", f"radius {radius}, around {around}, rings {rings}",
                         "use radius > 0, around >= 8, rings >= 3")
    origin, ex, ey, ez = _frame(core)
    corners = np.stack([[(p - origin) @ ex, (p - origin) @ ey] for p in core])  # CCW in (ex, ey)
    k = corners.shape[0]
    edges = np.roll(corners, -1, axis=0) - corners
    if np.any(np.linalg.norm(edges, axis=1) < 1e-9):
        raise InputError("argument", "core", "two core points coincide", "give distinct points")
    normal_angles = np.arctan2(-edges[:, 0], edges[:, 1])  # outward normal (dy, -dx) of edge i
    columns: list[tuple[int, float]] = []  # (corner, azimuth)
    for i in range(k):
        begin = normal_angles[i - 1]
        end = normal_angles[i]
        while end <= begin + 1e-12:
            end += 2.0 * math.pi
        steps = max(1, math.ceil((end - begin) / (2.0 * math.pi) * around - 1e-9))
        columns += [(i, begin + (end - begin) * j / steps) for j in range(steps + 1)]
    count = len(columns)
    corner_of = np.array([c for c, _ in columns])
    phi = np.array([a for _, a in columns])
    theta = math.pi * np.arange(1, rings) / rings
    local = corners[corner_of]  # (count, 2)
    points = []
    for th in theta:
        direction = (np.sin(th) * np.cos(phi))[:, None] * ex + (np.sin(th) * np.sin(phi))[:, None] * ey \
            + math.cos(th) * ez
        points.append(origin + local[:, :1] * ex + local[:, 1:] * ey + radius * direction)
    corners_3d = origin + corners[:, :1] * ex + corners[:, 1:] * ey
    top = corners_3d + radius * ez
    bottom = corners_3d - radius * ez
    vertices = np.concatenate([*points, top, bottom])
    ring_base = [r * count for r in range(rings - 1)]
    top_base = (rings - 1) * count
    bottom_base = top_base + k
    faces: list[tuple[int, int, int]] = []
    for r in range(rings - 2):
        for j in range(count):
            a, b = ring_base[r] + j, ring_base[r] + (j + 1) % count
            c, d = ring_base[r + 1] + (j + 1) % count, ring_base[r + 1] + j
            faces += [(a, b, c), (a, c, d)]
    first, last = ring_base[0], ring_base[-1]
    for j in range(count):
        j1 = (j + 1) % count
        ci, cn = int(corner_of[j]), int(corner_of[j1])
        if ci == cn:
            faces.append((top_base + ci, first + j1, first + j))
            faces.append((bottom_base + ci, last + j, last + j1))
        else:
            faces += [(top_base + ci, top_base + cn, first + j1), (top_base + ci, first + j1, first + j)]
            faces += [(bottom_base + ci, last + j, last + j1), (bottom_base + ci, last + j1, bottom_base + cn)]
    for i in range(1, k - 1):
        faces.append((top_base, top_base + i + 1, top_base + i))
        faces.append((bottom_base, bottom_base + i, bottom_base + i + 1))
    faces_array = np.asarray(faces, dtype=np.int32)
    tri = vertices[faces_array]
    volume = np.einsum("ij,ij->i", tri[:, 0], np.cross(tri[:, 1], tri[:, 2])).sum() / 6.0
    if volume < 0.0:
        faces_array = faces_array[:, ::-1].copy()
    return vertices.astype(np.float32), faces_array


def core_distance(points: np.ndarray, core: np.ndarray) -> np.ndarray:
    """(n,) distances [m] from points (n, 3) to a segment (2, 3) or rectangle (4, 3) core."""
    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    core = np.asarray(core, dtype=np.float64)
    rel = points - core[0]
    if core.shape[0] == 2:
        axis = core[1] - core[0]
        s = np.clip(rel @ axis / (axis @ axis), 0.0, 1.0)
        return np.linalg.norm(rel - s[:, None] * axis, axis=1)
    e1, e2 = core[1] - core[0], core[3] - core[0]
    s = np.clip(rel @ e1 / (e1 @ e1), 0.0, 1.0)
    u = np.clip(rel @ e2 / (e2 @ e2), 0.0, 1.0)
    return np.linalg.norm(rel - s[:, None] * e1 - u[:, None] * e2, axis=1)


# ---------------------------------------------------------------------------------------------- body


@dataclass(frozen=True)
class Joint:
    """A joint of the hierarchy.

    Attributes:
        name: unique name.
        parent: the parent joint's name, ``None`` for the root.
        pivot: (3,) rest-pose position of the rotation centre [m].
    """

    name: str
    parent: str | None
    pivot: tuple[float, float, float]


@dataclass(frozen=True)
class BodyPart:
    """A rigid part: the points within ``radius`` of ``core``, carried by ``joint``.

    Attributes:
        name: unique name (also the obstacle's name).
        joint: the joint whose world transform moves the part.
        core: (2, 3) segment or (4, 3) rectangle (rest pose) [m].
        radius: sweep radius [m].
    """

    name: str
    joint: str
    core: np.ndarray
    radius: float

    def mesh(self, around: int = 24, rings: int = 8) -> tuple[np.ndarray, np.ndarray]:
        """Closed rest-pose mesh ``(vertices, faces)`` (see :func:`rounded_core_mesh`)."""
        return rounded_core_mesh(self.core, self.radius, around, rings)

    def surface_distance(self, points: np.ndarray) -> np.ndarray:
        """(n,) signed distances [m] of rest-pose points to the part's exact surface (< 0 inside)."""
        return core_distance(points, self.core) - self.radius


class Body:
    """An articulated body: joints, the parts they carry and their animation.

    Args:
        joints: the hierarchy, parents before children, exactly one root.
        parts: rigid parts; each names a joint.
        rotations: local rotation track per joint name (joints without one keep the identity).
        translation: the root's translation track (default: none).

    Raises:
        InputError: duplicate names, unknown parents or joints, or a hierarchy out of order.
    """

    def __init__(self, joints: Sequence[Joint], parts: Sequence[BodyPart],
                 rotations: Mapping[str, RotationTrack] | None = None,
                 translation: TranslationTrack | None = None) -> None:
        self.joints = list(joints)
        self.parts = {p.name: p for p in parts}
        self.rotations = dict(rotations or {})
        self.translation = translation
        names: set[str] = set()
        roots = 0
        for joint in self.joints:
            if joint.name in names:
                raise InputError("body", "joints", f"joint {joint.name!r} is listed twice", "give unique names")
            if joint.parent is None:
                roots += 1
            elif joint.parent not in names:
                raise InputError("body", "joints", f"joint {joint.name!r} comes before its parent {joint.parent!r}",
                                 "list parents first")
            names.add(joint.name)
        if roots != 1:
            raise InputError("body", "joints", f"{roots} root joints", "give exactly one joint without a parent")
        if len(self.parts) != len(parts):
            raise InputError("body", "parts", "a part name is listed twice", "give unique names")
        for part in parts:
            if part.joint not in names:
                raise InputError("body", "parts", f"part {part.name!r} names unknown joint {part.joint!r}",
                                 f"use one of {sorted(names)}")
        for name in self.rotations:
            if name not in names:
                raise InputError("body", "rotations", f"unknown joint {name!r}", f"use one of {sorted(names)}")
        self._cache: dict[float, dict[str, Transform]] = {}

    def animated(self, rotations: Mapping[str, RotationTrack] | None = None,
                 translation: TranslationTrack | None = None) -> Body:
        """The same joints and parts with another animation."""
        return Body(self.joints, list(self.parts.values()), rotations, translation)

    def pose(self, t: float) -> dict[str, Transform]:
        """World transform ``(R, c)`` of every joint at time ``t`` [s]: ``x = R x_rest + c``."""
        t = float(t)
        cached = self._cache.get(t)
        if cached is not None:
            return cached
        out: dict[str, Transform] = {}
        for joint in self.joints:
            track = self.rotations.get(joint.name)
            local = np.eye(3) if track is None else np.asarray(track(t), dtype=np.float64)
            pivot = np.asarray(joint.pivot, dtype=np.float64)
            if joint.parent is None:
                shift = np.zeros(3) if self.translation is None else np.asarray(self.translation(t), np.float64)
                out[joint.name] = (local, pivot - local @ pivot + shift)
            else:
                parent_rotation, parent_translation = out[joint.parent]
                out[joint.name] = (parent_rotation @ local, parent_rotation @ (pivot - local @ pivot)
                                   + parent_translation)
        if len(self._cache) > 16:
            self._cache.clear()
        self._cache[t] = out
        return out

    def transform(self, name: str, t: float) -> Transform:
        """World transform of a joint or a part (its joint's) at time ``t`` [s]."""
        joint = self.parts[name].joint if name in self.parts else name
        rotation, translation = self.pose(t)[joint]
        return rotation.copy(), translation.copy()

    def motion(self, name: str) -> Callable[[float], Transform]:
        """The rigid motion ``t -> (R, c)`` of a part or joint (for obstacles and garment anchors).

        Raises:
            InputError: unknown name.
        """
        if name not in self.parts and name not in {j.name for j in self.joints}:
            raise InputError("body", "name", f"unknown part or joint {name!r}", f"use one of {sorted(self.parts)}")

        def motion(t: float) -> Transform:
            return self.transform(name, t)

        return motion

    def surface_distance(self, points: np.ndarray, t: float) -> dict[str, np.ndarray]:
        """Signed distances [m] of world points (n, 3) at time ``t`` to each part's exact surface."""
        points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        out = {}
        for name, part in self.parts.items():
            rotation, translation = self.transform(name, t)
            out[name] = part.surface_distance((points - translation) @ rotation)
        return out

    def descendants(self, joint: str) -> set[str]:
        """Names of ``joint`` and every joint below it."""
        out = {joint}
        for item in self.joints:
            if item.parent in out:
                out.add(item.name)
        return out


# ---------------------------------------------------------------------------------------------- humanoid

ARM_ABDUCTION_DEG: float = 45.0
"""Rest-pose angle between the upper arms and the vertical (A-pose) [deg]."""

_PELVIS_Z = 0.98  # pelvis core height; also the root pivot and the spine pivot
_PELVIS_HALF, _PELVIS_R = 0.06, 0.105
_TORSO_HALF, _TORSO_R, _TORSO_TOP = 0.08, 0.10, 1.38
_HEAD_R = 0.10
_THIGH_R, _SHIN_R = 0.065, 0.05
_UPPER_ARM_R, _FOREARM_R = 0.045, 0.038
_UPPER_ARM_LENGTH, _FOREARM_LENGTH = 0.28, 0.24
_SHOULDER_Z = 1.36
_SHOULDER_OUT = 0.03  # gap between the torso's side and the shoulder sphere


def _limb(start: np.ndarray, end: np.ndarray, next_radius: float, radius: float) -> np.ndarray:
    """Core of a limb from its pivot ``start`` towards the next pivot ``end``, leaving the joint gap."""
    direction = (end - start) / np.linalg.norm(end - start)
    return np.stack([start, end - (next_radius + radius + JOINT_GAP) * direction])


HUMANOID_JOINTS: tuple[str, ...] = ("pelvis", "spine", "neck", "hip_l", "knee_l", "hip_r", "knee_r",
                                    "shoulder_l", "elbow_l", "shoulder_r", "elbow_r")
"""Joint names of :func:`humanoid` (``_l`` = the body's left, +x). ``pelvis`` is the root."""


def humanoid(rotations: Mapping[str, RotationTrack] | None = None,
             translation: TranslationTrack | None = None) -> Body:
    """The procedural humanoid (1.74 m, 11 parts) in its rest pose, with an optional animation.

    Parts (capsules unless noted; radius in m): ``pelvis`` (horizontal, 0.105, 0.33 m wide),
    ``torso`` (rounded slab 0.36 x 0.20 m, from z = 1.11 to 1.48), ``head`` (0.10), ``thigh_l/r``
    (0.065), ``shin_l/r`` (0.05), ``upper_arm_l/r`` (0.045), ``forearm_l/r`` (0.038, hand included).
    Joints: see :data:`HUMANOID_JOINTS`; the root ``pelvis`` and ``spine`` pivot on the pelvis core
    centre (0, 0, 0.98); ``neck`` on the torso core's top edge; hips, knees, shoulders and elbows at
    the centre of the child limb's first sphere.

    Args:
        rotations: local rotation tracks by joint name (rest-pose world axes, about the pivot).
        translation: root translation track.
    """
    pelvis_centre = np.array([0.0, 0.0, _PELVIS_Z])
    joints = [Joint("pelvis", None, tuple(pelvis_centre)), Joint("spine", "pelvis", tuple(pelvis_centre))]
    torso_bottom = _PELVIS_Z + _PELVIS_R + _TORSO_R + 0.025
    torso_core = np.array([[-_TORSO_HALF, 0.0, torso_bottom], [_TORSO_HALF, 0.0, torso_bottom],
                           [_TORSO_HALF, 0.0, _TORSO_TOP], [-_TORSO_HALF, 0.0, _TORSO_TOP]])
    head_bottom = _TORSO_TOP + _TORSO_R + _HEAD_R + 0.02
    parts = [
        BodyPart("pelvis", "pelvis", np.array([[-_PELVIS_HALF, 0.0, _PELVIS_Z], [_PELVIS_HALF, 0.0, _PELVIS_Z]]),
                 _PELVIS_R),
        BodyPart("torso", "spine", torso_core, _TORSO_R),
        BodyPart("head", "neck", np.array([[0.0, 0.0, head_bottom], [0.0, 0.0, head_bottom + 0.04]]), _HEAD_R),
    ]
    joints.append(Joint("neck", "spine", (0.0, 0.0, _TORSO_TOP)))
    hip_z = _PELVIS_Z - _PELVIS_R - _THIGH_R - JOINT_GAP - 0.006
    abduction = math.radians(ARM_ABDUCTION_DEG)
    for side, sign in (("l", 1.0), ("r", -1.0)):
        hip = np.array([sign * 0.09, 0.0, hip_z])
        knee = np.array([sign * 0.10, 0.0, 0.46])
        ankle = np.array([sign * 0.105, 0.0, 0.09])
        joints += [Joint(f"hip_{side}", "pelvis", tuple(hip)), Joint(f"knee_{side}", f"hip_{side}", tuple(knee))]
        parts.append(BodyPart(f"thigh_{side}", f"hip_{side}", _limb(hip, knee, _SHIN_R, _THIGH_R), _THIGH_R))
        parts.append(BodyPart(f"shin_{side}", f"knee_{side}", np.stack([knee, ankle]), _SHIN_R))
        shoulder = np.array([sign * (_TORSO_HALF + _TORSO_R + _SHOULDER_OUT + _UPPER_ARM_R), 0.0, _SHOULDER_Z])
        direction = np.array([sign * math.sin(abduction), 0.0, -math.cos(abduction)])
        elbow = shoulder + _UPPER_ARM_LENGTH * direction
        joints += [Joint(f"shoulder_{side}", "spine", tuple(shoulder)),
                   Joint(f"elbow_{side}", f"shoulder_{side}", tuple(elbow))]
        parts.append(BodyPart(f"upper_arm_{side}", f"shoulder_{side}",
                              _limb(shoulder, elbow, _FOREARM_R, _UPPER_ARM_R), _UPPER_ARM_R))
        parts.append(BodyPart(f"forearm_{side}", f"elbow_{side}",
                              np.stack([elbow, elbow + _FOREARM_LENGTH * direction]), _FOREARM_R))
    return Body(joints, parts, rotations, translation)


def arm_direction(side: str) -> np.ndarray:
    """Rest-pose unit direction from shoulder to elbow of arm ``side`` (``"l"`` or ``"r"``)."""
    sign = 1.0 if side == "l" else -1.0
    a = math.radians(ARM_ABDUCTION_DEG)
    return np.array([sign * math.sin(a), 0.0, -math.cos(a)])


def elbow_axis(side: str) -> np.ndarray:
    """Unit axis about which a positive elbow rotation bends the forearm forward (+y)."""
    axis = np.cross(arm_direction(side), np.array([0.0, 1.0, 0.0]))
    return axis / np.linalg.norm(axis)
