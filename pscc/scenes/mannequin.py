"""A smooth, skinned mannequin: the garment scenes' body as one closed surface.

The articulated :func:`pscc.scenes.body.humanoid` is a hierarchy of rigid capsules with gaps at the
joints. Garments on it were caught between separately moving parts, and nobody takes a set of
capsules for a person. :func:`mannequin` turns the same skeleton and motions into one smooth, closed,
outward-oriented triangle mesh that deforms with the joints:

1. **Shape.** A signed distance field in the rest pose: the smooth union (polynomial smooth minimum
   of width :data:`BLEND`) of every part's sphere-swept core, with each parent limb's core reaching
   to its child's pivot and bridges where the capsule body has gaps (waist, neck, shoulders, hips).
   Where two pieces meet, the smooth minimum fills the crease with a fillet, so the surface has no
   edge.
2. **Mesh.** The zero level set is meshed by *surface nets* (one vertex per grid cell the surface
   crosses, at the mean of the cell's edge crossings; one quad per crossed grid edge, split along
   its shorter diagonal) and every vertex is then moved onto the level set by Newton steps along the
   field's gradient. The mesh is closed and consistently oriented (tests check both).
3. **Skinning.** Linear blend skinning: vertex ``i`` moves as ``x_i(t) = sum_j w_ij (R_j(t) x_i + c_j(t))``
   over the joints ``j`` of the body's forward kinematics. The weights fall off with the distance
   to each joint's part surface (:func:`skinning_weights`), so a vertex follows one joint except
   within a few centimetres of a joint, where it blends the two. The motion therefore
   bends the surface at the joints instead of opening gaps.

:class:`SkinnedMesh` is a non-rigid obstacle (like a mesh sequence): the solver reads its
``vertices``, ``faces``, ``name`` and ``positions(t)``; ``rigid`` is ``False``.

Units: metres. Coordinates as in :mod:`pscc.scenes.body` (z up, the body faces +y).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import ClassVar

import numpy as np

from pscc.errors import InputError, PsccError
from pscc.scenes.body import Body, core_distance
from pscc.sim.obstacles import Transform

__all__ = ["BLEND", "SKIN_FALLOFF", "FieldPiece", "SkinnedMesh", "mannequin", "mannequin_pieces",
           "project_to_level_set", "relax_on_level_set", "skinning_weights", "smooth_union", "surface_field",
           "surface_nets"]

BLEND: float = 0.03
"""Width [m] of the smooth minimum that joins the pieces (fillets of about ``BLEND / 4`` in creases)."""

SKIN_FALLOFF: float = 0.06
"""Distance [m] past the nearest part core over which a joint's skinning weight fades to 0."""

Field = Callable[[np.ndarray], np.ndarray]
"""A signed distance field: (n, 3) points -> (n,) values [m], negative inside."""


@dataclass(frozen=True)
class FieldPiece:
    """One sphere-swept core of the mannequin's shape.

    Attributes:
        core: (2, 3) segment or (4, 3) rectangle (rest pose) [m].
        radius: sweep radius [m].
    """

    core: np.ndarray
    radius: float

    def distance(self, points: np.ndarray) -> np.ndarray:
        """(n,) signed distances [m] of points (n, 3) to the piece's surface (< 0 inside)."""
        return core_distance(points, self.core) - self.radius


def _pivot(body: Body, joint: str) -> np.ndarray:
    return np.asarray(next(j.pivot for j in body.joints if j.name == joint), dtype=np.float64)


def mannequin_pieces(body: Body) -> list[FieldPiece]:
    """The pieces whose smooth union is the mannequin: the body's parts, limbs reaching their child's
    pivot, and bridges over the capsule body's joint gaps (waist, neck, shoulders, hips).

    Args:
        body: a :func:`pscc.scenes.body.humanoid` (its joint and part names are used).
    """
    parts = body.parts
    pieces = [FieldPiece(np.asarray(p.core, np.float64), float(p.radius)) for p in parts.values()]
    for side in ("l", "r"):
        thigh, shin = parts[f"thigh_{side}"], parts[f"shin_{side}"]
        upper, fore = parts[f"upper_arm_{side}"], parts[f"forearm_{side}"]
        knee, elbow = _pivot(body, f"knee_{side}"), _pivot(body, f"elbow_{side}")
        hip, shoulder = _pivot(body, f"hip_{side}"), _pivot(body, f"shoulder_{side}")
        # Limbs reach the child's pivot, tapering into the child's radius.
        pieces.append(FieldPiece(np.stack([thigh.core[1], knee]), 0.5 * (thigh.radius + shin.radius)))
        pieces.append(FieldPiece(np.stack([upper.core[1], elbow]), 0.5 * (upper.radius + fore.radius)))
        # Hip: from the hip pivot up into the pelvis.
        pelvis_core = np.asarray(parts["pelvis"].core, np.float64)
        pieces.append(FieldPiece(np.stack([hip, hip + np.array([0.0, 0.0, pelvis_core[0, 2] - hip[2]])]),
                                 thigh.radius))
        # Shoulder: from the torso's top corner out to the shoulder pivot.
        torso = np.asarray(parts["torso"].core, np.float64)
        top_side = torso[2] if np.sign(torso[2, 0]) == np.sign(shoulder[0]) else torso[3]
        pieces.append(FieldPiece(np.stack([top_side, shoulder]), upper.radius + 0.005))
    torso = np.asarray(parts["torso"].core, np.float64)
    pelvis_centre = np.asarray(parts["pelvis"].core, np.float64).mean(axis=0)
    torso_bottom = 0.5 * (torso[0] + torso[1])
    torso_top = 0.5 * (torso[2] + torso[3])
    head = np.asarray(parts["head"].core, np.float64)
    pieces.append(FieldPiece(np.stack([pelvis_centre, torso_bottom]), 0.095))  # waist
    pieces.append(FieldPiece(np.stack([torso_top, head[0]]), 0.05))  # neck
    return pieces


def smooth_union(values: list[np.ndarray], blend: float = BLEND) -> np.ndarray:
    """Polynomial smooth minimum of signed distances, folded left to right.

    ``smin(a, b) = min(a, b) - h^2 blend / 4`` with ``h = max(blend - |a - b|, 0) / blend``: equal
    to ``min`` where the two differ by more than ``blend``, and at most ``blend / 4`` below it.
    """
    out = values[0]
    for value in values[1:]:
        h = np.maximum(blend - np.abs(out - value), 0.0) / blend
        out = np.minimum(out, value) - h * h * blend * 0.25
    return out


def _field(pieces: list[FieldPiece], blend: float) -> Field:
    def evaluate(points: np.ndarray) -> np.ndarray:
        points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        return smooth_union([p.distance(points) for p in pieces], blend)

    return evaluate


# ---------------------------------------------------------------------------------------------- meshing

# Corner offsets of a cell and its 12 edges (pairs of corner ids).
_CORNERS = np.array([[i, j, k] for k in (0, 1) for j in (0, 1) for i in (0, 1)])
_CELL_EDGES = np.array([[0, 1], [2, 3], [4, 5], [6, 7], [0, 2], [1, 3], [4, 6], [5, 7],
                        [0, 4], [1, 5], [2, 6], [3, 7]])


def surface_nets(field_fn: Field, lower: np.ndarray, upper: np.ndarray,
                 cell: float) -> tuple[np.ndarray, np.ndarray]:
    """Mesh the zero level set of a field inside a box by surface nets.

    Args:
        field_fn: signed field (negative inside); must be positive on the box's boundary.
        lower, upper: (3,) box corners [m].
        cell: grid spacing [m].

    Returns:
        ``(vertices, faces)``: (n, 3) float64 and (m, 3) int32, outward-oriented (the normal of a face
        points to where the field grows).

    Raises:
        InputError: the field is not positive on the box's boundary (the surface would be cut open).
    """
    lower = np.asarray(lower, np.float64)
    counts = np.ceil((np.asarray(upper, np.float64) - lower) / cell).astype(int) + 1
    axes = [lower[a] + cell * np.arange(counts[a]) for a in range(3)]
    grid = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1)
    values = field_fn(grid.reshape(-1, 3)).reshape(tuple(counts))
    boundary = np.concatenate([values[[0, -1]].ravel(), values[:, [0, -1]].ravel(), values[:, :, [0, -1]].ravel()])
    if np.any(boundary <= 0.0):
        raise InputError("mannequin", "box", "the surface reaches the meshing box", "enlarge the box")
    nx, ny, nz = counts - 1
    corner_values = np.stack([values[i:i + nx, j:j + ny, k:k + nz] for i, j, k in _CORNERS], axis=-1)
    inside = corner_values < 0.0
    crossed = inside.any(axis=-1) & ~inside.all(axis=-1)
    cells = np.argwhere(crossed)
    cv = corner_values[crossed]  # (c, 8)
    a, b = cv[:, _CELL_EDGES[:, 0]], cv[:, _CELL_EDGES[:, 1]]  # (c, 12)
    sign_change = (a < 0.0) != (b < 0.0)
    t = np.where(sign_change, a / np.where(sign_change, a - b, 1.0), 0.0)
    offsets_a, offsets_b = _CORNERS[_CELL_EDGES[:, 0]], _CORNERS[_CELL_EDGES[:, 1]]  # (12, 3)
    local = offsets_a[None] + t[..., None] * (offsets_b - offsets_a)[None]  # (c, 12, 3)
    mean = (local * sign_change[..., None]).sum(axis=1) / sign_change.sum(axis=1)[:, None]
    vertices = lower + cell * (cells + mean)
    index = np.full((nx, ny, nz), -1, dtype=np.int64)
    index[tuple(cells.T)] = np.arange(cells.shape[0])
    quads = []
    for axis in range(3):
        u, v = (axis + 1) % 3, (axis + 2) % 3
        # Grid edges along `axis` strictly inside the grid in the two other directions.
        lo = [0, 0, 0]
        lo[u] = lo[v] = 1
        hi = list(counts)
        hi[axis] -= 1
        hi[u] -= 1
        hi[v] -= 1
        start = values[lo[0]:hi[0], lo[1]:hi[1], lo[2]:hi[2]]
        shift = [0, 0, 0]
        shift[axis] = 1
        end = values[lo[0] + shift[0]:hi[0] + shift[0], lo[1] + shift[1]:hi[1] + shift[1],
                     lo[2] + shift[2]:hi[2] + shift[2]]
        changes = (start < 0.0) != (end < 0.0)
        edge = np.argwhere(changes) + np.array(lo)
        outward = (start[changes] < 0.0)  # inside -> outside along +axis
        ring = []
        for du, dv in ((-1, -1), (0, -1), (0, 0), (-1, 0)):  # counter-clockwise about +axis
            c = edge.copy()
            c[:, u] += du
            c[:, v] += dv
            ring.append(index[c[:, 0], c[:, 1], c[:, 2]])
        quad = np.stack(ring, axis=1)
        quad[~outward] = quad[~outward][:, ::-1]
        quads.append(quad)
    quad = np.concatenate(quads)
    if np.any(quad < 0):
        raise PsccError("surface nets: a crossed edge without its four cells (internal error)")
    diagonal_02 = np.linalg.norm(vertices[quad[:, 0]] - vertices[quad[:, 2]], axis=1)
    diagonal_13 = np.linalg.norm(vertices[quad[:, 1]] - vertices[quad[:, 3]], axis=1)
    split = (diagonal_02 <= diagonal_13)[:, None]
    first = np.where(split, quad[:, [0, 1, 2]], quad[:, [0, 1, 3]])
    second = np.where(split, quad[:, [0, 2, 3]], quad[:, [1, 2, 3]])
    faces = np.concatenate([first, second]).astype(np.int32)
    return vertices, faces


def project_to_level_set(vertices: np.ndarray, field_fn: Field, iterations: int = 6,
                         step: float = 1e-4) -> np.ndarray:
    """Move points onto the field's zero level set by Newton steps along its gradient.

    The gradient is a central difference of width ``step`` [m]. Each step is clamped to 5 mm, so a
    point never jumps to another sheet of the surface.
    """
    points = np.asarray(vertices, dtype=np.float64).copy()
    offsets = np.eye(3) * step
    for _ in range(iterations):
        value = field_fn(points)
        gradient = np.stack([(field_fn(points + o) - field_fn(points - o)) / (2.0 * step) for o in offsets], axis=1)
        norm2 = np.maximum((gradient * gradient).sum(axis=1), 1e-12)
        move = -(value / norm2)[:, None] * gradient
        length = np.linalg.norm(move, axis=1)
        move *= np.minimum(1.0, 0.005 / np.maximum(length, 1e-12))[:, None]
        points += move
    return points


def relax_on_level_set(vertices: np.ndarray, faces: np.ndarray, field_fn: Field, iterations: int = 4) -> np.ndarray:
    """Even out a level-set mesh's vertex spacing: move each vertex half-way to the mean of its
    neighbours, then back onto the level set (:func:`project_to_level_set`); repeated ``iterations``
    times. Surface nets leave slivers where the surface grazes a grid corner; this removes them.
    """
    points = np.asarray(vertices, dtype=np.float64).copy()
    edges = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]]).astype(np.int64)
    degree = np.bincount(edges[:, 0], minlength=points.shape[0]).astype(np.float64)
    for _ in range(iterations):
        total = np.zeros_like(points)
        np.add.at(total, edges[:, 0], points[edges[:, 1]])
        points = 0.5 * points + 0.5 * total / degree[:, None]
        points = project_to_level_set(points, field_fn, iterations=3)
    return points


# ---------------------------------------------------------------------------------------------- skinning


def skinning_weights(vertices: np.ndarray, body: Body,
                     falloff: float = SKIN_FALLOFF) -> tuple[list[str], np.ndarray]:
    """Linear-blend-skinning weights of rest-pose points on the body's joints.

    Each part carries its joint. With ``d_p`` the distance from the point to part ``p``'s surface (0
    inside it), the part gets ``(d_p + 1 cm)^-4 * (1 - smoothstep((d_p - d_min) / falloff))``; a joint
    sums its parts; the weights are normalised to sum 1. A point therefore follows the part it lies on
    alone unless another part's surface is within ``falloff`` of it. (Distances to the surfaces, not
    to the cores: the side of the torso at the armpit is nearer the upper arm's core than the torso's,
    but it lies on the torso.)

    Returns:
        ``(joints, weights)``: the joint names and an (n, len(joints)) float64 array.
    """
    points = np.asarray(vertices, dtype=np.float64).reshape(-1, 3)
    joints = [j.name for j in body.joints]
    distance = np.stack([core_distance(points, np.asarray(p.core, np.float64)) - p.radius
                         for p in body.parts.values()], axis=1)
    distance = np.maximum(distance, 0.0)
    nearest = distance.min(axis=1, keepdims=True)
    x = np.clip((distance - nearest) / falloff, 0.0, 1.0)
    fade = 1.0 - x * x * (3.0 - 2.0 * x)
    part_weights = fade / (distance + 0.01) ** 4
    weights = np.zeros((points.shape[0], len(joints)))
    for column, part in enumerate(body.parts.values()):
        weights[:, joints.index(part.joint)] += part_weights[:, column]
    weights /= weights.sum(axis=1, keepdims=True)
    return joints, weights


@dataclass
class SkinnedMesh:
    """A non-rigid obstacle: a rest-pose mesh moved by linear blend skinning on a body's joints.

    It has the attributes the solver reads from an :class:`pscc.sim.obstacles.Obstacle` (``vertices``,
    ``faces``, ``name``, :meth:`positions`) and no rigid pose (:meth:`transform` raises), like
    :class:`pscc.scenes.scene_motions.SequenceObstacle`.

    Attributes:
        rest_vertices: (n, 3) float64 rest-pose positions [m].
        faces: (m, 3) int32 vertex ids.
        body: the skeleton and its animation.
        joints: joint names, one per weight column.
        weights: (n, len(joints)) float64 skinning weights (rows sum to 1).
        name: label used in error messages and stats.
    """

    rest_vertices: np.ndarray
    faces: np.ndarray
    body: Body
    joints: list[str]
    weights: np.ndarray
    name: str = "mannequin"
    _columns: list[int] = field(default_factory=list, repr=False)

    rigid: ClassVar[bool] = False
    """Always False: skinning bends the surface at the joints."""

    def __post_init__(self) -> None:
        self.rest_vertices = np.asarray(self.rest_vertices, dtype=np.float64)
        self.faces = np.asarray(self.faces, dtype=np.int32)
        self.weights = np.asarray(self.weights, dtype=np.float64)
        if self.weights.shape != (self.rest_vertices.shape[0], len(self.joints)):
            raise InputError(self.name, "weights", f"shape {self.weights.shape} is not "
                             f"({self.rest_vertices.shape[0]}, {len(self.joints)})", "give one weight per joint")
        self._columns = [j for j in range(len(self.joints)) if np.any(self.weights[:, j] > 0.0)]

    @property
    def vertices(self) -> np.ndarray:
        """(n, 3) float64 rest-pose positions [m] (the pose at t = 0 of every garment animation)."""
        return self.rest_vertices

    def positions(self, t: float) -> np.ndarray:
        """(n, 3) float32 skinned positions at time ``t`` [s]."""
        pose = self.body.pose(float(t))
        out = np.zeros_like(self.rest_vertices)
        for column in self._columns:
            rotation, translation = pose[self.joints[column]]
            w = self.weights[:, column:column + 1]
            out += w * (self.rest_vertices @ rotation.T + translation)
        return out.astype(np.float32)

    def transform(self, t: float) -> Transform:
        """Not available: a skinned mesh has no rigid pose.

        Raises:
            PsccError: always (the solver uses :meth:`positions` for non-rigid obstacles).
        """
        raise PsccError(f"obstacle {self.name!r} is skinned and has no rigid transform; use positions(t)")


def mannequin(body: Body, cell: float = 0.015, blend: float = BLEND, name: str = "mannequin") -> SkinnedMesh:
    """The body as one smooth, closed, skinned surface (see the module docstring).

    Args:
        body: a :func:`pscc.scenes.body.humanoid` with its animation.
        cell: meshing grid spacing [m] (edge lengths come out about this size).
        blend: smooth-minimum width [m].
        name: obstacle name.

    Raises:
        InputError: a cell outside [2 mm, 10 cm].
    """
    if not 0.002 <= cell <= 0.1:
        raise InputError(name, "cell", f"{cell!r} m is outside [0.002, 0.1]", "mesh with a cell of 5 mm to 3 cm")
    pieces = mannequin_pieces(body)
    field_fn = _field(pieces, blend)
    cores = np.concatenate([p.core for p in pieces])
    reach = max(p.radius for p in pieces) + 2.0 * cell + blend
    lower, upper = cores.min(axis=0) - reach, cores.max(axis=0) + reach
    vertices, faces = surface_nets(field_fn, lower, upper, cell)
    vertices = relax_on_level_set(project_to_level_set(vertices, field_fn), faces, field_fn)
    joints, weights = skinning_weights(vertices, body)
    return SkinnedMesh(vertices, faces, body, joints, weights, name=name)


def surface_field(body: Body, blend: float = BLEND) -> Field:
    """The mannequin's rest-pose signed distance field (negative inside) [m]."""
    return _field(mannequin_pieces(body), blend)

