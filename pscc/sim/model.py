"""The static description of a cloth: rest shape, materials, masses, bending hinges and scripted vertices.

Everything here is computed once, with NumPy in float64, and uploaded to the device as float32:

=================  ======================  ==================================================================
device array       shape, dtype            meaning
=================  ======================  ==================================================================
faces.indices      (face_count,) vec3i     vertex ids of each triangle
faces.inv_rest     (face_count,) mat22     Dm^-1, Dm = [r1 - r0, r2 - r0] in the face's 2-D material frame
faces.rest_area    (face_count,) float     rest area [m^2]
faces.stiffness    (face_count,) vec4      (k_uu, k_vv, k_uv, k_shear) [N/m] of the face's material
faces.damping      (face_count,) float     membrane Rayleigh coefficient [s]
hinges.indices     (hinge_count,) vec4i    (x0, x1, x2, x3): edge x0 -> x1 as listed by the first face,
                                           x2 opposite in that face, x3 opposite in the other face
hinges.rest_angle  (hinge_count,) float    rest dihedral angle [rad] (0 for a flat rest shape)
hinges.rest_length (hinge_count,) float    rest edge length [m]
hinges.stiffness   (hinge_count,) float    bending * 3 |e|^2 / (A1 + A2) [N m]
hinges.damping     (hinge_count,) float    bending Rayleigh coefficient [s]
vertices.mass      (vertex_count,) float   lumped mass [kg]: density * area / 3 from every adjacent face
vertices.kind      (vertex_count,) int32   VERTEX_FREE, VERTEX_SCRIPTED (pinned or handle), VERTEX_MASSLESS
vertices.friction  (vertex_count,) float   Coulomb coefficient (largest over the adjacent faces' materials)
=================  ======================  ==================================================================

Material frames: with (n, 2) rest coordinates (UV) they are used directly. With an (n, 3) rest shape
(flat or curved; the default is the initial ``vertices``) each face gets an orthonormal 2-D frame in its
plane whose u axis is the world x axis projected into the plane (the y axis when the face is within
~8 degrees of perpendicular to x), so anisotropic stiffness follows a consistent warp direction.

Scripted vertices: ``pinned`` vertices stay at their initial positions; ``handles`` follow targets
given to each step. Both are Dirichlet constraints of the integrator. Vertices that belong to no face
have no mass; they are flagged ``VERTEX_MASSLESS`` and move ballistically.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
import warp as wp

from pscc._checks import as_numpy
from pscc.errors import InputError
from pscc.mesh.mesh_data import validate_mesh
from pscc.mesh.topology import MeshTopology
from pscc.sim.config import SIM_MIN_REST_AREA_RATIO, ClothMaterial

VERTEX_FREE: int = 0
"""Vertex kind: integrated by the implicit solve."""
VERTEX_SCRIPTED: int = 1
"""Vertex kind: position prescribed each step (pinned or handle)."""
VERTEX_MASSLESS: int = 2
"""Vertex kind: in no face, hence no mass; moves ballistically under gravity."""


@wp.struct
class FaceArrays:
    """Per-face device arrays (see the module docstring)."""

    indices: wp.array(dtype=wp.vec3i)
    inv_rest: wp.array(dtype=wp.mat22)
    rest_area: wp.array(dtype=float)
    stiffness: wp.array(dtype=wp.vec4)
    damping: wp.array(dtype=float)


@wp.struct
class HingeArrays:
    """Per-hinge (interior edge) device arrays (see the module docstring)."""

    indices: wp.array(dtype=wp.vec4i)
    rest_angle: wp.array(dtype=float)
    rest_length: wp.array(dtype=float)
    stiffness: wp.array(dtype=float)
    damping: wp.array(dtype=float)


@wp.struct
class VertexArrays:
    """Per-vertex device arrays (see the module docstring)."""

    mass: wp.array(dtype=float)
    kind: wp.array(dtype=wp.int32)
    friction: wp.array(dtype=float)


def _dihedral_angles(p0: np.ndarray, p1: np.ndarray, p2: np.ndarray, p3: np.ndarray) -> np.ndarray:
    """Float64 twin of :func:`pscc.sim.materials.dihedral_angle` for (k, 3) arrays."""
    e = p1 - p0
    n_a = np.cross(e, p2 - p0)
    n_b = np.cross(p3 - p1, e)
    sin_term = np.einsum("ij,ij->i", np.cross(n_a, n_b), e)
    cos_term = np.einsum("ij,ij->i", n_a, n_b) * np.linalg.norm(e, axis=1)
    return np.arctan2(sin_term, cos_term)


def _face_frames(rest: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """2-D material coordinates (m, 3, 2) of each face's corners (float64)."""
    corners = rest[faces]  # (m, 3, d)
    if rest.shape[1] == 2:
        return corners
    e1 = corners[:, 1] - corners[:, 0]
    e2 = corners[:, 2] - corners[:, 0]
    normal = np.cross(e1, e2)
    normal_length = np.linalg.norm(normal, axis=1, keepdims=True)
    normal = normal / np.where(normal_length > 0.0, normal_length, 1.0)
    axis = np.where(np.abs(normal[:, :1]) < 0.99, np.array([[1.0, 0.0, 0.0]]), np.array([[0.0, 1.0, 0.0]]))
    u = axis - normal * np.einsum("ij,ij->i", axis, normal)[:, None]
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    v = np.cross(normal, u)
    rel = corners - corners[:, :1]
    return np.stack([np.einsum("mkd,md->mk", rel, u), np.einsum("mkd,md->mk", rel, v)], axis=2)


def _vertex_ids(value: Any, name: str, n: int) -> np.ndarray:
    """Vertex ids from an id list or a boolean (n,) mask, sorted and unique."""
    array = as_numpy(value)
    if array.dtype == np.bool_:
        if array.shape != (n,):
            raise InputError("argument", name, f"boolean mask of shape {array.shape} does not match ({n},)",
                             f"pass one flag per vertex or a list of vertex ids for {name}")
        return np.flatnonzero(array).astype(np.int32)
    array = array.reshape(-1)
    if array.size == 0:
        return np.zeros(0, dtype=np.int32)
    if array.dtype.kind not in "iu":
        raise InputError("argument", name, f"dtype {array.dtype} is neither bool nor integer",
                         f"pass vertex ids (integers) or a boolean mask for {name}")
    if array.min() < 0 or array.max() >= n:
        raise InputError("argument", name, f"a vertex id is outside [0, {n})", f"pass valid 0-based ids for {name}")
    return np.unique(array).astype(np.int32)


class ClothModel:
    """Static cloth data on the device (layout in the module docstring).

    Args:
        vertices: (n, 3) initial positions [m].
        faces: (m, 3) vertex ids of the triangles.
        rest: Optional material coordinates: (n, 2) UV [m] or an (n, 3) rest shape [m]. Default: the
            initial ``vertices`` (the cloth starts at rest).
        materials: One :class:`ClothMaterial` for every face, or a sequence indexed by ``object_ids``.
            Default: ``ClothMaterial()``.
        object_ids: Optional (m,) material index of each face (zeros when omitted).
        pinned: Optional vertex ids or (n,) boolean mask of vertices held at their initial positions.
        handles: Optional vertex ids whose positions are prescribed at each step
            (see :meth:`pscc.sim.ImplicitEuler.step`); they start at their initial positions.
        flat_bending: Optional (m,) bool: faces whose hinges bend towards flat (rest angle 0) although
            ``rest`` is 3-D (a garment whose curved shape sets its rest lengths but not its folds).
        stitches: Optional (s, 4) rows ``(i, j, k, r)``: vertex i sewn to (1 - r) x_j + r x_k
            (:func:`pscc.mesh.mesh_data.check_stitches`); zero-length springs of the implicit system.
        device: Warp device.

    Raises:
        InputError: invalid mesh arrays (see :func:`pscc.validate_mesh`), a degenerate rest triangle,
            an object id without a material, an invalid material or an invalid vertex id.
    """

    def __init__(self, vertices: Any, faces: Any, *, rest: Any = None,
                 materials: ClothMaterial | Sequence[ClothMaterial] | None = None, object_ids: Any = None,
                 pinned: Any = None, handles: Any = None, flat_bending: Any = None, stitches: Any = None,
                 device: wp.DeviceLike = None) -> None:
        mesh = validate_mesh(vertices, faces, rest=rest, object_ids=object_ids, stitches=stitches)
        self.device = wp.get_device(device)
        self.mesh = mesh
        """The validated mesh (host arrays)."""
        n, m = mesh.vertex_count, mesh.face_count
        tris = mesh.faces.astype(np.int64)

        material_list = self._material_list(materials, mesh.object_ids)
        face_material = np.zeros(m, dtype=np.int64) if len(material_list) == 1 else mesh.object_ids.astype(np.int64)
        self.materials: tuple[ClothMaterial, ...] = tuple(material_list)
        """The materials, indexed by object id."""

        # --- membrane: material frames, Dm^-1, rest areas --------------------------------------------
        rest_coords = (mesh.rest if mesh.rest is not None else mesh.vertices).astype(np.float64)
        frames = _face_frames(rest_coords, tris)
        dm = np.stack([frames[:, 1] - frames[:, 0], frames[:, 2] - frames[:, 0]], axis=2)  # columns
        det = dm[:, 0, 0] * dm[:, 1, 1] - dm[:, 0, 1] * dm[:, 1, 0]
        area = 0.5 * np.abs(det)
        rest_edges = rest_coords[tris[:, [1, 2, 0]]] - rest_coords[tris]
        longest_sq = np.max(np.einsum("mkd,mkd->mk", rest_edges, rest_edges), axis=1)
        bad = np.flatnonzero(~(2.0 * area > SIM_MIN_REST_AREA_RATIO * longest_sq))
        if bad.size:
            face = int(bad[0])
            raise InputError("argument", "rest", f"rest triangle of face {face} {mesh.faces[face].tolist()} has "
                             f"zero area ({area[face]:.3g} m^2; {bad.size} such faces)",
                             "give that face non-collinear rest coordinates or remove it")
        safe_det = np.where(det != 0.0, det, 1.0)
        inv_rest = np.stack([np.stack([dm[:, 1, 1], -dm[:, 0, 1]], 1), np.stack([-dm[:, 1, 0], dm[:, 0, 0]], 1)], 1)
        inv_rest /= safe_det[:, None, None]

        params = np.array([[mat.stretch_u, mat.stretch_v, mat.stretch_uv, mat.shear, mat.stretch_damping,
                            mat.density, mat.friction, mat.bending, mat.bending_damping] for mat in material_list])
        face_params = params[face_material]

        # --- lumped masses, friction, vertex kinds ----------------------------------------------------
        mass = np.zeros(n, dtype=np.float64)
        friction = np.zeros(n, dtype=np.float64)
        for corner in range(3):
            np.add.at(mass, tris[:, corner], face_params[:, 5] * area / 3.0)
            np.maximum.at(friction, tris[:, corner], face_params[:, 6])
        pinned_ids = _vertex_ids(pinned, "pinned", n) if pinned is not None else np.zeros(0, np.int32)
        handle_ids = _vertex_ids(handles, "handles", n) if handles is not None else np.zeros(0, np.int32)
        kind = np.full(n, VERTEX_FREE, dtype=np.int32)
        kind[mass <= 0.0] = VERTEX_MASSLESS
        kind[pinned_ids] = VERTEX_SCRIPTED
        kind[handle_ids] = VERTEX_SCRIPTED

        # --- bending hinges ---------------------------------------------------------------------------
        topology = MeshTopology.from_faces(mesh.faces, n)
        face_counts = np.diff(topology.edge_face_offsets)
        interior = np.flatnonzero(face_counts == 2)
        first = topology.edge_face_indices[topology.edge_face_offsets[interior]].astype(np.int64)
        second = topology.edge_face_indices[topology.edge_face_offsets[interior] + 1].astype(np.int64)
        hinges = self._hinge_vertices(tris, topology.edges[interior].astype(np.int64), first, second)
        if rest_coords.shape[1] == 3:
            rest_angle = _dihedral_angles(*(rest_coords[hinges[:, k]] for k in range(4)))
            if flat_bending is not None:
                flat = np.asarray(flat_bending, dtype=bool).reshape(-1)
                if flat.shape[0] != m:
                    raise InputError("argument", "flat_bending", f"has {flat.shape[0]} entries for {m} faces",
                                     "give one bool per face")
                rest_angle = np.where(flat[first] | flat[second], 0.0, rest_angle)
        else:
            rest_angle = np.zeros(hinges.shape[0])
        rest_length = np.linalg.norm(rest_coords[hinges[:, 1]] - rest_coords[hinges[:, 0]], axis=1)
        weight = 3.0 * rest_length**2 / (area[first] + area[second])
        hinge_bending = 0.5 * (face_params[first, 7] + face_params[second, 7])
        hinge_damping = 0.5 * (face_params[first, 8] + face_params[second, 8])

        # --- host summaries ---------------------------------------------------------------------------
        self.vertex_count: int = n
        """Number of vertices n."""
        self.face_count: int = m
        """Number of triangles m."""
        self.hinge_count: int = int(hinges.shape[0])
        rows = mesh.stitches if mesh.stitches is not None else np.zeros((0, 4))
        self.stitches: np.ndarray = rows
        """(s, 4) float64 stitch rows ``(i, j, k, r)`` (host copy)."""
        self.stitch_count: int = int(rows.shape[0])
        ids = rows[:, :3].astype(np.int32)
        self.stitch_vertices = wp.array(np.concatenate([ids, ids[:, 1:2]], axis=1).reshape(-1, 4), dtype=wp.vec4i,
                                        device=self.device)
        """(s,) vec4i (i, j, k, j) of each stitch (the last weight is 0)."""
        r = rows[:, 3]
        weights = np.stack([np.ones_like(r), r - 1.0, -r, np.zeros_like(r)], axis=1).astype(np.float32)
        self.stitch_weights = wp.array(weights.reshape(-1, 4), dtype=wp.vec4, device=self.device)
        """(s,) vec4 (1, -(1 - r), -r, 0): sum_a w_a x_a is the offset of vertex i from its seam point."""
        """Number of interior edges with exactly two faces (bending elements)."""
        self.mass_host: np.ndarray = mass.astype(np.float32)
        """(n,) float32 lumped masses [kg] (host copy)."""
        self.kind_host: np.ndarray = kind
        """(n,) int32 vertex kinds (host copy)."""
        self.hinges_host: np.ndarray = hinges.astype(np.int32)
        """(hinge_count, 4) int32 hinge vertex ids (host copy)."""
        self.rest_area_host: np.ndarray = area.astype(np.float32)
        """(m,) float32 rest areas [m^2] (host copy)."""
        self.pinned_ids: np.ndarray = pinned_ids
        """Sorted ids of the pinned vertices (host)."""
        self.handle_ids_host: np.ndarray = handle_ids
        """Sorted ids of the handle vertices (host); targets passed to a step follow this order."""
        self.total_mass: float = float(mass.sum())
        """Total mass [kg]."""
        self.mean_free_mass: float = float(mass[kind == VERTEX_FREE].mean()) if np.any(kind == VERTEX_FREE) else 0.0
        """Mean lumped mass of the free vertices [kg]."""

        # --- device upload ----------------------------------------------------------------------------
        dev = self.device
        self.initial_positions = wp.array(mesh.vertices, dtype=wp.vec3, device=dev)
        """(n,) vec3 initial positions [m]; also the targets of pinned vertices."""
        self.handle_ids = wp.array(handle_ids, dtype=wp.int32, device=dev)
        """(handle_count,) int32 sorted handle vertex ids."""
        self.faces = FaceArrays()
        """Per-face arrays."""
        self.faces.indices = wp.array(mesh.faces, dtype=wp.vec3i, device=dev)
        self.faces.inv_rest = wp.array(inv_rest.astype(np.float32), dtype=wp.mat22, device=dev)
        self.faces.rest_area = wp.array(area.astype(np.float32), dtype=float, device=dev)
        self.faces.stiffness = wp.array(face_params[:, :4].astype(np.float32), dtype=wp.vec4, device=dev)
        self.faces.damping = wp.array(face_params[:, 4].astype(np.float32), dtype=float, device=dev)
        self.hinges = HingeArrays()
        """Per-hinge arrays."""
        self.hinges.indices = wp.array(hinges.astype(np.int32).reshape(-1, 4), dtype=wp.vec4i, device=dev)
        self.hinges.rest_angle = wp.array(rest_angle.astype(np.float32), dtype=float, device=dev)
        self.hinges.rest_length = wp.array(rest_length.astype(np.float32), dtype=float, device=dev)
        self.hinges.stiffness = wp.array((hinge_bending * weight).astype(np.float32), dtype=float, device=dev)
        self.hinges.damping = wp.array(hinge_damping.astype(np.float32), dtype=float, device=dev)
        self.vertices = VertexArrays()
        """Per-vertex arrays."""
        self.vertices.mass = wp.array(self.mass_host, dtype=float, device=dev)
        self.vertices.kind = wp.array(kind, dtype=wp.int32, device=dev)
        self.vertices.friction = wp.array(friction.astype(np.float32), dtype=float, device=dev)

    @property
    def handle_count(self) -> int:
        """Number of handle vertices."""
        return int(self.handle_ids_host.shape[0])

    @staticmethod
    def _material_list(materials: ClothMaterial | Sequence[ClothMaterial] | None,
                       object_ids: np.ndarray) -> list[ClothMaterial]:
        if materials is None:
            materials = ClothMaterial()
        if isinstance(materials, ClothMaterial):
            material_list = [materials]
        else:
            material_list = list(materials)
            if not material_list:
                raise InputError("argument", "materials", "the sequence is empty",
                                 "pass one ClothMaterial or one per object id")
        for index, material in enumerate(material_list):
            if not isinstance(material, ClothMaterial):
                raise InputError("argument", f"materials[{index}]", f"{type(material).__name__} is not a "
                                 "ClothMaterial", "pass pscc.sim.ClothMaterial instances")
            material.validate()
        if len(material_list) > 1 and object_ids.size and int(object_ids.max()) >= len(material_list):
            face = int(np.argmax(object_ids))
            raise InputError("argument", "object_ids", f"face {face} has object id {int(object_ids[face])} but only "
                             f"{len(material_list)} materials were given",
                             "pass one material per object id (or a single material for all faces)")
        return material_list

    @staticmethod
    def _hinge_vertices(tris: np.ndarray, edges: np.ndarray, first: np.ndarray, second: np.ndarray) -> np.ndarray:
        """(k, 4) hinge ids: the edge as oriented in ``first``, then the two opposite vertices."""
        k = edges.shape[0]
        if k == 0:
            return np.zeros((0, 4), dtype=np.int64)
        f_a = tris[first]
        low, high = edges[:, 0:1], edges[:, 1:2]
        starts_low = np.any((f_a == low) & (np.roll(f_a, -1, axis=1) == high), axis=1)
        x0 = np.where(starts_low, edges[:, 0], edges[:, 1])
        x1 = np.where(starts_low, edges[:, 1], edges[:, 0])
        x2 = f_a.sum(axis=1) - edges.sum(axis=1)
        x3 = tris[second].sum(axis=1) - edges.sum(axis=1)
        return np.stack([x0, x1, x2, x3], axis=1)
