"""The cloth solver of PSCC section 5: implicit integration, proximity springs, CCD penetration handling.

One :meth:`ClothSolver.step` (the paper's Figure 8b pipeline, details in ``docs/simulator.md``):

1. **Integration**: linearised backward Euler (:class:`pscc.sim.ImplicitEuler`) with the contact
   springs found by DCD at the end of the previous step, gravity, wind, drag and the prescribed
   handle and obstacle positions at t + dt -> predicted end positions.
2. **Broad phase**, once: swept boxes over [x_t, x_pred] grown by the thickness h (normal-cone
   front, {cell, node} hashing, feature pairs).
3. **CCD + penetration handling** on those candidates: every pair coming closer than delta during
   the step becomes a linear constraint on the end positions, and the end positions are projected
   onto all constraints found so far in the step (the inelastic projection); after
   ``projection_rounds`` rounds the colliding vertices are merged into rigid impact zones, until
   CCD finds nothing.
4. When the response moved anything, the final trajectory is **certified** by one more broad phase
   over it (the candidates and the normal-cone front of step 2 were computed for the predicted
   trajectory) and CCD again; the loop continues if that finds a collision.
5. **DCD** at the end positions on the same (last) broad phase -> contact springs for the next step.
6. The **independent intersection check** of the end state (:class:`IntersectionCheck`); a
   crossing, NaN/Inf, a zone that cannot move rigidly or too many rounds reject the step, which is
   then split into two half steps (``max_step_halvings`` times at most).

Index space: the solver's state holds the cloth vertices followed by every obstacle's vertices.
Obstacle vertices are handles of the integrator (kinematic, prescribed each step), so proximity
springs between cloth and obstacles need no special case.
"""

from __future__ import annotations

import math
import time
import warnings
from typing import Any

import numpy as np
import warp as wp

from pscc._checks import check_coordinate_range, check_object_ids, unused_object_ids
from pscc._memory import SIMULATION_BYTES_PER_TRIANGLE, check_fits
from pscc.collision.detector import CollisionDetector
from pscc.collision.intersection import IntersectionCheck
from pscc.collision.spatial_hash_settings import fitted_capacities
from pscc.errors import InputError, PsccError
from pscc.geometry.distance import edge_edge_distance, vertex_face_distance
from pscc.sim.contact_config import CCD_INSIDE_SHARE, ContactConfig
from pscc.sim.device_step import (
    CANDIDATE_PEAKS,
    CG_FAILED,
    CONTACTS,
    FLAG_NAMES,
    FLAG_OVERFLOW,
    HASH_PEAKS,
    PROJECTION_PEAK,
    DeviceStep,
    _velocities_from_positions,
    report_counts,
)
from pscc.sim.impact_response import ImpactZoneFailure, ImpactZones
from pscc.sim.inelastic_projection import InelasticProjection
from pscc.sim.integrator import ImplicitEuler
from pscc.sim.memory import warp_array_bytes
from pscc.sim.model import VERTEX_FREE, ClothModel
from pscc.sim.obstacles import step_map
from pscc.sim.proximity import ProximityContacts
from pscc.sim.scene import Scene
from pscc.sim.state import ClothState
from pscc.sim.untangle import Untangler
from pscc.tolerances import CCD_DISTANCE_TOLERANCE, MAX_COORDINATE

wp.set_module_options({"enable_backward": False})


TRIM_FRAMES: int = 8
"""Device frames in a row that must leave the projection's buffers (under a sixteenth used) or the hash
tables (under two thirds used) mostly empty before they shrink."""

TRIM_SLACK: int = 1024
"""Slots a hash table keeps beyond its trim rule (small tables are never trimmed)."""


class SimulationError(PsccError):
    """A step could not be completed free of intersections even after the allowed step halvings."""


class GraphUnavailableWarning(UserWarning):
    """The device could not record a frame into a graph: every later frame of the run launches eagerly
    (same results, slower; on CUDA an eager ``wp.capture_while`` synchronizes once per iteration)."""


RESPONSE_TOLERANCE_SHARE: float = 0.7
"""The inelastic projection stops once no gap is more than this share of (separation - CCD distance) below
the separation (and no pushed constraint that much above it). At the defaults (0.2 h and 0.1 h) the gaps then
end at least 0.13 h apart, above the 0.117 h within which the CCD may still report a pair (its distance
tolerance, ``d_min (1 + sqrt 3 x 0.1)``, :data:`pscc.tolerances.CCD_DISTANCE_TOLERANCE`), so a solved pair is
not found again. At 0.5 (gaps of 0.15 h) ``twisting`` at 5K ran 404K projection iterations and 4,357 CCD
rounds over its 90 frames; at 0.7, with checks every 8 iterations, 293K and 3,973 (docs/simulator.md). The
worst seam gap of the ``dance`` garment at 20K went from 0.65 h to 1.36 h with it (issue 13 allows 2 h), through
the changed trajectory: a tolerance of 0.5 for the seams' constraints alone left it at 1.36 h. Where this share
would leave gaps within (or within 15 % of) the CCD's band, :func:`response_tolerance` falls back towards 0.5."""


def response_tolerance(separation: float, ccd_distance: float) -> float:
    """The inelastic projection's KKT tolerance [m] for a ``separation`` and a CCD distance [m].

    :data:`RESPONSE_TOLERANCE_SHARE` of the band ``separation - ccd_distance`` where the gaps it leaves,
    ``separation - tolerance``, stay clear of the CCD's reporting band ``ccd_distance (1 + sqrt 3 x``
    :data:`pscc.tolerances.CCD_DISTANCE_TOLERANCE` ``)`` by 15 % of what lies between it and the separation;
    else the larger of that bound and half the band (the rule before the share was raised, which close
    separations already met inside the CCD's band). At the defaults (0.2 h, 0.1 h) it is the share's 0.07 h
    (the bound is 0.0703 h)."""
    band = separation - ccd_distance
    reported = ccd_distance * (1.0 + math.sqrt(3.0) * CCD_DISTANCE_TOLERANCE)
    clear = 0.85 * (separation - reported)
    return min(RESPONSE_TOLERANCE_SHARE * band, max(0.5 * band, clear))


def _finite_in_range(positions: np.ndarray) -> bool:
    """Whether every coordinate is finite and within :data:`pscc.tolerances.MAX_COORDINATE` (the detector's range)."""
    if positions.size == 0:
        return True
    largest, smallest = float(positions.max()), float(positions.min())  # NaN propagates into both
    return math.isfinite(largest) and math.isfinite(smallest) and max(largest, -smallest) <= MAX_COORDINATE


class _StepRejected(Exception):
    """Internal: this attempt failed; retry with half the step."""


def _new_stats() -> dict[str, Any]:
    seconds = {k: 0.0 for k in ("integration", "broad_phase", "narrow_phase", "penetration", "proximity",
                                 "intersection_check", "total")}
    counts = {k: 0 for k in ("cg_iterations", "broad_phases", "ccd_rounds", "ccd_hits", "projection_rounds",
                             "projection_iterations", "zone_rounds", "halvings", "contacts", "front_size",
                             "dcd_vertex_face", "dcd_edge_edge")}
    return {"seconds": seconds, "counts": counts}


class ClothSolver:
    """Steps a :class:`pscc.scenes.Scene` with every step ending free of intersections.

    Args:
        scene: cloth, material, handles, obstacles and solver settings.
        device: Warp device (``None``: Warp's default).
        contact: contact settings (default :class:`ContactConfig`).

    Raises:
        InputError: invalid scene data, or an initial state that already intersects (unless
            ``contact.allow_initial_intersections``).
    """

    def __init__(self, scene: Scene, *, device: str | None = None, contact: ContactConfig | None = None) -> None:
        self.scene = scene
        self.contact = (contact if contact is not None else ContactConfig()).validate()
        per_object = isinstance(scene.material, list | tuple)
        materials = [m.validate() for m in scene.material] if per_object else [scene.material.validate()]
        if per_object and (not materials or int(np.max(scene.object_ids, initial=0)) >= len(materials)):
            raise InputError(scene.name, "material", f"{len(materials)} materials for object ids up to "
                             f"{int(np.max(scene.object_ids, initial=0))}", "give one material per cloth piece")
        self.device = wp.get_device(device)
        self.time = 0.0
        cloth_count = int(scene.vertices.shape[0])
        self.cloth_vertex_count = cloth_count

        triangles = int(scene.faces.shape[0]) + sum(int(o.faces.shape[0]) for o in scene.obstacles)
        check_fits(triangles * SIMULATION_BYTES_PER_TRIANGLE, what=f"simulating {triangles:,} triangles",
                   source=scene.name, field="faces", fix="simulate a coarser mesh or use a device with more memory",
                   device=str(self.device))

        # Index space: cloth vertices, then the vertices of each obstacle.
        obstacle_positions = [o.positions(0.0) for o in scene.obstacles]
        offsets = np.cumsum([cloth_count] + [p.shape[0] for p in obstacle_positions])
        self._obstacle_offsets = offsets
        vertices = np.concatenate([np.asarray(scene.vertices, np.float32), *obstacle_positions], axis=0)
        rest = np.asarray(scene.rest, dtype=np.float32)
        if rest.ndim != 2 or rest.shape[0] != cloth_count or rest.shape[1] not in (2, 3):
            raise InputError(scene.name, "rest", f"shape {rest.shape} is not ({cloth_count}, 2) or ({cloth_count}, 3)",
                             "give (u, v) pattern coordinates or a 3-D rest position per cloth vertex")
        rest_all = np.concatenate([rest, *(p[:, :rest.shape[1]] for p in obstacle_positions)], axis=0)
        flat_bending = None
        if scene.flat_bending is not None:
            flat_bending = np.asarray(scene.flat_bending, dtype=bool).reshape(-1)
            if flat_bending.shape[0] != scene.faces.shape[0]:
                raise InputError(scene.name, "flat_bending", f"has {flat_bending.shape[0]} entries for "
                                 f"{scene.faces.shape[0]} cloth faces", "give one bool per cloth face, or None")
        handle_ids = [h.vertices for h in scene.handles]
        for handle in scene.handles:
            if handle.vertices.max() >= cloth_count:
                raise InputError(scene.name, f"handles[{handle.name}].vertices", "a vertex id is not a cloth vertex",
                                 f"use ids below {cloth_count}")
        obstacle_ids = [np.arange(offsets[k], offsets[k + 1]) for k in range(len(scene.obstacles))]
        all_handles = np.concatenate(handle_ids + obstacle_ids) if handle_ids or obstacle_ids else None
        if all_handles is not None and np.unique(all_handles).size != all_handles.size:
            raise InputError(scene.name, "handles", "a vertex belongs to two handles", "list each vertex in one handle")
        try:
            self.model = ClothModel(vertices, scene.faces, rest=rest_all,
                                    materials=materials if per_object else materials[0],
                                    object_ids=scene.object_ids if per_object else None,
                                    handles=all_handles, flat_bending=flat_bending, stitches=scene.stitches,
                                    device=self.device)
        except InputError as error:
            if error.source != "argument":
                raise
            raise InputError(scene.name, error.field, error.problem, error.fix) from None
        self.integrator = ImplicitEuler(self.model, scene.solver, self.device)
        n = self.model.vertex_count

        # Kinematic groups: each handle, then each obstacle.
        self.kinematic_group = np.full(n, -1, dtype=np.int64)
        for group, ids in enumerate(handle_ids + obstacle_ids):
            self.kinematic_group[ids] = group
        self._initial = vertices.astype(np.float64)
        masses = self.model.mass_host.astype(np.float64)
        free = (self.model.kind_host == VERTEX_FREE) & (masses > 0.0)
        inverse_mass = np.where(free, 1.0 / np.where(masses > 0.0, masses, 1.0), 0.0)
        self._masses = masses
        self._kinematic = ~free

        # Collision mesh: cloth faces, then obstacle faces; one object per cloth piece and per obstacle.
        cloth_objects = check_object_ids(scene.object_ids, int(scene.faces.shape[0]), source=scene.name)
        obstacle_objects = unused_object_ids(cloth_objects, len(scene.obstacles))
        faces = [np.asarray(scene.faces, np.int32)]
        objects = [cloth_objects]
        for k, obstacle in enumerate(scene.obstacles):
            faces.append(obstacle.faces + offsets[k])
            objects.append(np.full(obstacle.faces.shape[0], obstacle_objects[k], dtype=np.int32))
        self.collision_faces = np.concatenate(faces).astype(np.int32)
        collision_objects = np.concatenate(objects)
        rigid = [int(v) for v in obstacle_objects]
        self.detector = CollisionDetector(self.collision_faces, method=self.contact.method,
                                          object_ids=collision_objects, rest=rest_all, rigid_objects=rigid,
                                          device=str(self.device), stitches=scene.stitches)
        # The BSR values are dead from the end of one integration to the start of the next, the stretch
        # in which the detector hashes; the candidate pairs and times of impact are dead from the step's
        # DCD (the springs are built from it) to the next broad phase, which rewrites them from the hash's
        # pairs. The hash's per-call tables live there (SpatialHash.lend_scratch): so every user of the
        # detector's hash (the intersection check too) runs after the DCD's rows are consumed.
        self.detector.lend_scratch(self.integrator.system.matrix.values, pair_buffers=True)
        self.thickness = max(float(m.thickness) for m in materials)
        if self.thickness <= 0.0:
            raise InputError(scene.name, "material.thickness", "is 0", "give the cloth a thickness > 0 [m]")
        self.ccd_distance = self.contact.ccd_distance_ratio * self.thickness
        self.separation = self.contact.separation_ratio * self.thickness
        self.response_tolerance = response_tolerance(self.separation, self.ccd_distance)
        """KKT tolerance of the inelastic projection (:func:`response_tolerance`)."""
        self.cloth_face_count = int(scene.faces.shape[0])
        self.projection = InelasticProjection(inverse_mass, self.device,
                                              max_iterations=self.contact.projection_iterations)
        # Room for contact before it happens (the device path flags an overflow and redoes the frame): the
        # collisions, the proximity constraints of the springs' initial capacity, and the six constraints of
        # every stitch.
        self.projection.reserve(self._projection_floor(self.cloth_face_count // 4)
                                + 6 * int(np.asarray(scene.stitches).shape[0] if scene.stitches is not None else 0))
        extent = vertices.max(axis=0) - vertices.min(axis=0)
        self._scale = float(np.linalg.norm(extent))
        self._scratch: dict[int, ClothState] = {}
        self._near_off = False  # a rejected step is retried without the proximity constraints (_advance)
        self._device_step: DeviceStep | None = None
        self._frame_graph: tuple[tuple[Any, ...], Any] | None = None
        self._frame_graph_warm: tuple[Any, ...] | None = None
        self._projection_peaks: list[int] = []
        self._hash_peaks: list[list[int]] = []
        self._spring_peaks: list[int] = []
        self._candidate_peaks: list[list[int]] = []
        self.graph_unavailable: str | None = None
        """Why frames cannot be recorded into a graph on this device (``None``: they can); the frames then
        run eagerly, with the same results."""

        check_coordinate_range(vertices, "vertices (cloth and obstacles at t = 0)", source=scene.name)
        self.detector.prepare(vertices)
        # One copy of the collision mesh's connectivity on the device, shared by the detector, the
        # contact springs and the intersection check.
        shared = self.detector.device_topology
        self.proximity = ProximityContacts(self.collision_faces, self._kinematic, self.thickness, self.device,
                                           device_topology=shared)
        # Room for contact before it happens (the device path flags an overflow and redoes the frame).
        self.proximity.springs.ensure(self.cloth_face_count // 4)
        # The springs are built after the integration, when the BSR values are dead: their merge table
        # lives there (ContactSprings.lend_merge_table).
        self.proximity.springs.lend_merge_table(self.integrator.system.matrix.values)
        # The check runs after the step's pairs were consumed, so it borrows the detector's hash tables, and
        # its face boxes (computed anew by every broad phase).
        self.intersection_check = IntersectionCheck(self.collision_faces, n, self.device,
                                                    spatial_hash=getattr(self.detector, "spatial_hash", None),
                                                    device_topology=shared,
                                                    face_boxes=(self.detector.boxes.face_lower,
                                                                self.detector.boxes.face_upper),
                                                    seams=self.detector.seams)
        initial = self._cloth_crossings(vertices)
        self.initial_crossings = int(initial.shape[0])
        """Edge-face crossings of the initial state (non-zero only with ``allow_initial_intersections``)."""
        if initial.shape[0] and not self.contact.allow_initial_intersections:
            edge, face = (int(v) for v in initial[0][:2])
            raise InputError(scene.name, "vertices",
                             f"the initial state intersects itself: {initial.shape[0]} edge-face crossings "
                             f"(first: edge {edge} through face {face})",
                             "separate the surfaces in the input; to start anyway set allow_initial_intersections "
                             "= true under [contact] in the scene file (ContactConfig(allow_initial_intersections"
                             "=True) in Python), which lets crossing surfaces start, exempt from collision handling "
                             "until they come apart, the side that passed through pushed back")
        self._untangle_check: IntersectionCheck | None = None
        self.untangler: Untangler | None = None
        """The global intersection analysis that pushes crossing surfaces apart (:mod:`pscc.sim.untangle`), while
        crossings remain and ``contact.untangle_speed > 0``; else ``None``."""
        self.intersecting_pairs = int(initial.shape[0])
        """Edge-face crossings (involving the cloth) left from a tangled start (:meth:`update_tangles`)."""
        if initial.shape[0]:
            self._untangle_check = IntersectionCheck(self.collision_faces, n, self.device)
            if self.contact.untangle_speed > 0.0:
                self.untangler = Untangler(shared.edges, shared.faces, masses, free, self.contact.untangle_speed,
                                           self.device)
            self._join_crossings(initial)
            self._push_apart(vertices, initial)
        self.start_contacts = self._ease_start_contacts(vertices)
        """Cloth vertices that start closer than the thickness to another surface (eased apart)."""

    def update_tangles(self, state: ClothState) -> int:
        """After a frame: the edge-face crossings left from a tangled start, and the pairs exempt from collision
        handling set to them.

        With ``allow_initial_intersections``, the crossings of the initial state are found and their
        vertex pairs (each end of the crossing edge with each vertex of the face) are left out of the
        broad phase and the intersection check, like a stitch's (:mod:`pscc.collision.seams`): the
        collision response then does not hold the crossing features where they are, and the cloth's own
        forces (stretch and bending towards its rest shape) can take them apart. After every frame this
        method counts the crossings that remain with a check that exempts nothing and narrows the exempt
        pairs to them; at 0 the exemption ends and only the stitches stay. New crossings are still refused
        (the intersection check flags every crossing outside the exempt pairs). With
        ``contact.untangle_speed > 0`` a global intersection analysis (:class:`pscc.sim.untangle.Untangler`)
        then finds the side of each crossing that passed through, and the next frame's steps push it back
        (:attr:`pscc.sim.assembly.ImplicitSystem.untangle_velocity`); the push ends with the crossings.

        Sync point (reads the positions) while crossings remain; nothing once untangled.

        Returns:
            The crossings left (also :attr:`intersecting_pairs`).
        """
        if self._untangle_check is None:
            return 0
        positions = state.positions.numpy().astype(np.float32)
        crossings = self._untangle_check.find(positions)
        if crossings.shape[0] and self.scene.obstacles:
            cloth_faces = int(self.scene.faces.shape[0])
            owners = self._untangle_check.edge_owner_faces[crossings[:, 0]]
            crossings = crossings[(owners < cloth_faces) | (crossings[:, 1] < cloth_faces)]
        if self.scene.stitches is not None and crossings.shape[0]:
            joined = {(int(a), int(b)) for a, b in self._stitch_pairs()}
            edges = self._untangle_check.edge_vertices
            keep = [not any((int(e), int(v)) in joined for e in edges[edge] for v in self.collision_faces[face])
                    for edge, face in crossings[:, :2]]
            crossings = crossings[np.asarray(keep, dtype=bool)]
        self.intersecting_pairs = int(crossings.shape[0])
        if self.intersecting_pairs == 0:
            self._untangle_check = None
        self._join_crossings(crossings)
        self._push_apart(state.positions, crossings)
        return self.intersecting_pairs

    def _push_apart(self, positions: wp.array | np.ndarray, crossings: np.ndarray) -> None:
        """Set the integrator's untangle velocity from ``crossings`` (:class:`pscc.sim.untangle.Untangler`), or
        clear it (no crossings, or no untangler). The caller records graphs again (:meth:`_join_crossings`)."""
        system = self.integrator.system
        if self.untangler is None or crossings.shape[0] == 0:
            system.untangle_velocity = None
            if crossings.shape[0] == 0:
                self.untangler = None
            return
        if not isinstance(positions, wp.array):
            positions = wp.array(np.asarray(positions, np.float32), dtype=wp.vec3, device=self.device)
        pushed = self.untangler.analyse(positions, crossings)
        system.untangle_velocity = self.untangler.velocity if pushed else None

    def _stitch_pairs(self) -> np.ndarray:
        rows = np.asarray(self.scene.stitches, dtype=np.int64).reshape(-1, 4)[:, :3]
        pairs = np.concatenate([rows[:, [0, 1]], rows[:, [0, 2]]])
        return np.concatenate([pairs, pairs[:, ::-1]])

    def _join_crossings(self, crossings: np.ndarray) -> None:
        """Leave the vertex pairs of ``crossings`` (edge id, face id) out of collision handling, with the stitches."""
        rows = [] if self.scene.stitches is None else [np.asarray(self.scene.stitches, dtype=np.float64).reshape(-1, 4)]
        if crossings.shape[0]:
            edges = self.intersection_check.edge_vertices[crossings[:, 0]]
            faces = self.collision_faces[crossings[:, 1]]
            a = np.repeat(edges, 3, axis=1).reshape(-1)  # each end of the edge ...
            p = np.tile(faces, (1, 2)).reshape(-1)  # ... with each vertex of the face
            rows.append(np.stack([a, p, p, np.zeros_like(a)], axis=1).astype(np.float64))
        self.detector.set_joined(np.concatenate(rows) if rows else None)
        self.intersection_check.refresh_seams()
        self._frame_graph = None  # the graph bound the old arrays: record again
        self._frame_graph_warm = None

    def add_stitch_constraints(self, positions_t1: wp.array) -> None:
        """After :meth:`InelasticProjection.reset`: the seams as hard constraints of the step's response
        (:meth:`InelasticProjection.add_stitches_device`; each seam may close but not open by more than
        the integrator left it, or the CCD distance). Allocates: no. Capture-safe: yes."""
        model = self.model
        if model.stitch_count:
            self.projection.add_stitches_device(model.stitch_vertices, model.stitch_weights, positions_t1,
                                                self.separation, self.ccd_distance)

    def _ease_start_contacts(self, vertices: np.ndarray) -> int:
        """Find the pairs closer than the thickness h in the initial state and let the contact springs keep
        their start distance at first, opening it to h over ``SolverConfig.start_gap_relax_time``
        (:meth:`pscc.sim.assembly.ImplicitSystem.set_start_gaps`): a garment draped onto a body, or layers
        pressed together, are eased apart instead of popping off. Returns the number of cloth vertices
        that start that close."""
        h = self.thickness
        found = self.detector.detect(vertices, thickness=h)
        points = vertices.astype(np.float64)
        gaps = np.full(points.shape[0], h, dtype=np.float64)
        free = ~self._kinematic
        rows = [np.concatenate([found.vertex_face[:, :1], self.collision_faces[found.vertex_face[:, 1]]], axis=1),
                found.edge_edge]
        for ids, distance in ((rows[0], vertex_face_distance), (rows[1], edge_edge_distance)):
            if ids.shape[0] == 0:
                continue
            d = distance(points[ids], device=self.device)
            close = d < h
            for column in range(4):
                vertex = ids[close, column]
                keep = free[vertex]
                np.minimum.at(gaps, vertex[keep], d[close][keep])
        eased = int((gaps < h).sum())
        relax = float(self.scene.solver.start_gap_relax_time)
        self.integrator.system.set_start_gaps(gaps if eased else None, h / relax)
        self.integrator.system.set_clock(0.0)
        return eased

    # ------------------------------------------------------------------ public

    def initial_state(self) -> ClothState:
        """A new state at the scene's initial positions, at rest. Allocates: yes."""
        return ClothState.from_model(self.model)

    def obstacle_mesh(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        """All obstacle vertices at time ``t`` and their faces (ids into those vertices)."""
        obstacles = self.scene.obstacles
        if not obstacles:
            return np.zeros((0, 3), np.float32), np.zeros((0, 3), np.int32)
        base = self._obstacle_offsets - self.cloth_vertex_count
        vertices = np.concatenate([o.positions(t) for o in obstacles])
        faces = np.concatenate([o.faces + base[k] for k, o in enumerate(obstacles)])
        return vertices.astype(np.float32), faces.astype(np.int32)

    def device_bytes(self) -> dict[str, int]:
        """Device memory per structure, in bytes, and their ``total``.

        ``collision`` (the detector's own accounting: BVH, front, hash tables, pair buffers; the
        intersection check shares the hash tables and does not count them again),
        ``contact_springs`` (the springs and the tables that pick them), ``projection``
        (penetration-handling buffers), ``intersection_check``, ``integrator`` (block-sparse system, PCG
        vectors and the model's arrays) and ``device_step`` (the device step's report and loop flags,
        the frame's targets table and the frame-start copies a fallback restores; 0 before the first
        device frame). States are owned by the caller and not counted.
        """
        collision = self.detector.device_bytes() if self.detector.topology is not None else {"total": 0}
        # The detector's own accounting holds its hash, which the intersection check may share.
        seen: set[int] = {id(getattr(self.detector, "spatial_hash", None))}
        # ... and the mesh connectivity that the springs and the check share with it.
        topology = getattr(self.detector, "device_topology", None)
        seen.update(id(array) for array in (topology.arrays if topology is not None else ()))
        # ... and the springs' merge table where it lives in the BSR values (the integrator's).
        springs = self.proximity.springs
        seen.update(id(getattr(springs, name)) for name in springs.merge_table_lent)
        # ... and the intersection check's face boxes, the detector's.
        seen.update({id(self.detector.boxes.face_lower), id(self.detector.boxes.face_upper)})
        # ... and the stitch partners (the detector's, shared with the check).
        seen.update({id(self.detector.seams.args.offsets), id(self.detector.seams.args.partners)})
        parts = {
            "collision": int(collision["total"]),
            "contact_springs": warp_array_bytes(self.proximity, seen=seen),
            "projection": warp_array_bytes(self.projection, seen=seen),
            "intersection_check": warp_array_bytes(self.intersection_check, seen=seen),
            "integrator": warp_array_bytes(self.integrator, seen=seen) + warp_array_bytes(self.model, seen=seen),
            "device_step": self._device_step.device_bytes() if self._device_step is not None else 0,
        }
        parts["total"] = sum(parts.values())
        return parts

    def state_dict(self, state: ClothState) -> dict[str, np.ndarray]:
        """Everything a later step depends on, as host arrays (for checkpoints).

        That is the state (positions, velocities), the simulated time, the integrator's warm start,
        the contact springs of the last DCD, the contact clock (:meth:`_ease_start_contacts`) and the
        detector's normal cone test front. Restoring it
        with :meth:`load_state_dict` into a solver of the same scene continues bit for bit as the
        original would on the CPU.
        """
        springs = self.proximity.springs
        count = springs.host_count
        return {
            "time": np.array([self.time], dtype=np.float64),
            # Copies: on the CPU, .numpy() is a view that later steps would overwrite.
            "positions": state.positions.numpy().copy(),
            "velocities": state.velocities.numpy().copy(),
            "warm_start": self.integrator.dv.numpy().copy(),
            "spring_vertices": springs.vertices.numpy()[:count].copy(),
            "spring_weights": springs.weights.numpy()[:count].copy(),
            "spring_normals": springs.normals.numpy()[:count].copy(),
            "spring_multiplicity": springs.multiplicity.numpy()[:count].copy(),
            # The contact clock as the device holds it (accumulated in float32 by the device steps).
            "contact_clock": self.integrator.system.contact_clock.numpy().copy(),
            **{f"detector_{key}": value for key, value in self.detector.state_dict().items()},
        }

    def load_state_dict(self, data: dict[str, np.ndarray], state: ClothState) -> None:
        """Restore :meth:`state_dict` output into this solver and ``state``.

        Raises:
            InputError: arrays missing or of the wrong shape (a checkpoint of another scene).
        """
        n = self.model.vertex_count
        for key in ("time", "positions", "velocities", "warm_start", "spring_vertices", "spring_weights",
                    "spring_normals"):
            if key not in data:
                raise InputError("checkpoint", key, "is missing", "resume from a checkpoint written by pscc simulate")
        for key in ("positions", "velocities", "warm_start"):
            if np.shape(data[key]) != (n, 3):
                raise InputError("checkpoint", key, f"shape {np.shape(data[key])} is not ({n}, 3)",
                                 "resume with the scene and size the checkpoint was written for")
        count = int(np.shape(data["spring_vertices"])[0])
        # Checkpoints from before springs were merged hold one spring per row: multiplicity 1.
        factors = np.asarray(data.get("spring_multiplicity", np.ones(count, np.int32)))
        if factors.shape != (count,) or factors.dtype.kind not in "iu" or (count and factors.min() < 1):
            raise InputError("checkpoint", "spring_multiplicity",
                             f"shape {factors.shape} dtype {factors.dtype} is not ({count},) integers >= 1",
                             "resume from a checkpoint written by pscc simulate")
        state.positions.assign(np.asarray(data["positions"], np.float32))
        state.velocities.assign(np.asarray(data["velocities"], np.float32))
        self.integrator.dv.assign(np.asarray(data["warm_start"], np.float32))
        springs = self.proximity.springs
        springs.ensure(count)
        for name in ("vertices", "weights", "normals"):
            buffer = getattr(springs, name)
            width = {"vertices": 4, "weights": 4, "normals": 3}[name]
            rows = np.asarray(data[f"spring_{name}"]).reshape(count, width)
            padded = np.zeros((buffer.shape[0], width), dtype=np.int32 if name == "vertices" else np.float32)
            padded[:count] = rows
            buffer.assign(padded)
        multiplicity = np.ones(springs.capacity, np.int32)
        multiplicity[:count] = factors
        springs.multiplicity.assign(multiplicity)
        springs.set_count(count)
        self.detector.load_state_dict({key[len("detector_"):]: value for key, value in data.items()
                                       if key.startswith("detector_")})
        self.time = float(np.asarray(data["time"]).reshape(-1)[0])
        clock = np.asarray(data.get("contact_clock", [self.time]), dtype=np.float32).reshape(-1)
        if clock.shape != (1,) or not np.isfinite(clock[0]):
            raise InputError("checkpoint", "contact_clock", f"{clock.tolist()} is not one finite time",
                             "resume from a checkpoint written by pscc simulate")
        self.integrator.system.contact_clock.assign(clock)
        if self.intersecting_pairs:
            self.update_tangles(state)  # exempt the crossings of the checkpoint's state, as the run had
        self._frame_graph = None  # buffers may have been replaced: record again after an eager frame
        self._frame_graph_warm = None

    def step(self, state_in: ClothState, state_out: ClothState, dt: float) -> dict[str, Any]:
        """Advance ``state_in`` by ``dt`` [s] into ``state_out``; the result is intersection-free.

        Returns:
            Step stats: ``seconds`` per stage (integration, broad_phase, narrow_phase, penetration,
            proximity, intersection_check, total) and ``counts`` (cg_iterations, broad_phases,
            ccd_rounds, ccd_hits, projection_rounds, projection_iterations, zone_rounds, halvings, contacts, front_size,
            dcd_vertex_face, dcd_edge_edge).

        Raises:
            SimulationError: the step still fails after ``max_step_halvings`` halvings.

        Allocates: yes. Capture-safe: no.
        """
        started = time.perf_counter()
        stats = _new_stats()
        self._advance(state_in, state_out, self.time, float(dt), 0, stats)
        self.time += float(dt)
        stats["seconds"]["total"] = time.perf_counter() - started
        stats["counts"]["contacts"] = self.proximity.springs.host_count
        return stats

    def advance_frame(self, state: ClothState, scratch: ClothState, dt: float, steps: int, *,
                      graph: bool = True) -> dict[str, Any]:
        """Advance ``state`` in place by ``steps`` steps of ``dt`` [s] on the device path; the result is
        intersection-free.

        Every step runs on the device (:class:`pscc.sim.device_step.DeviceStep`); the frame reads one
        small report back at its end. With ``graph``, the frame is recorded into a graph after one
        eager frame of the same shape and replayed from then on (bit-identical to eager on the CPU).
        When the report shows that a step would need a smaller step, rigid impact zones, or a bigger
        buffer, the frame is restored and run again on the host path (:meth:`step`), which halves
        and grows as needed; ``counts.device_fallbacks`` counts those frames.

        Args:
            state: the state at the frame's start; holds the frame's end afterwards.
            scratch: a second state of the same solver (overwritten).
            dt: time step [s].
            steps: steps in the frame (>= 1).
            graph: record and replay the frame as a graph (``False``: eager launches only).

        Returns:
            Frame stats: ``steps``, ``seconds`` (``total``; per stage only for frames that fell back)
            and ``counts`` as :meth:`step` sums them, plus ``device_fallbacks``, ``graph_recordings`` (1 when
            this frame recorded the graph, then replayed it) and ``graph_replays`` (1 when it replayed a
            graph recorded earlier);
            a frame that fell back also has ``fallback_reason``.

        Raises:
            SimulationError: the host path could not make a step intersection-free.

        Allocates: on the first frame, when a buffer grows, and on recording. Capture-safe: no.
        """
        started = time.perf_counter()
        runner = self._device_runner()
        t0 = self.time
        times = [t0]
        for _ in range(steps):
            times.append(times[-1] + float(dt))
        if self.model.handle_count:
            runner.upload_targets(np.stack([self._kinematic_targets(t) for t in times[1:]]))
        runner.save(state)
        mode = self._run_device_frame(runner, state, scratch, float(dt), steps, graph)
        report = runner.read_report()
        failed = [name for flag, name in FLAG_NAMES.items() if report[flag]]
        if report[FLAG_OVERFLOW]:  # named by the first buffer that overflowed
            failed = [f"{FLAG_NAMES[FLAG_OVERFLOW]} ({runner.overflow_name(int(report[FLAG_OVERFLOW]))})",
                      *(name for name in failed if name != FLAG_NAMES[FLAG_OVERFLOW])]
        if report[CG_FAILED] and not failed:
            failed = ["the linear solve overflowed"]
        if not failed:
            # A frame that grows a buffer trims none and restarts every trim window: a buffer grown for this
            # frame's peak would otherwise be trimmed back at once, and grow again on the next (a graph
            # recorded after every such frame is never replayed).
            grew = runner.grow_near_full(report)
            if grew:
                self._restart_trim_windows()
            if grew or (self._trim_projection(int(report[PROJECTION_PEAK]), int(report[CONTACTS]))
                        | self._trim_hash([int(v) for v in report[HASH_PEAKS:HASH_PEAKS + 5]])
                        | self._trim_springs(int(report[CONTACTS]))
                        | self._trim_candidates([int(v) for v in report[CANDIDATE_PEAKS:CANDIDATE_PEAKS + 2]])):
                self._frame_graph = None  # record again, after an eager frame on the new buffers
                self._frame_graph_warm = None
            self.time = times[-1]
            counts = _new_stats()["counts"]
            counts.update(report_counts(report), device_fallbacks=0, graph_recordings=int(mode == "recorded"),
                          graph_replays=int(mode == "replayed"))
            return {"steps": steps, "seconds": {"total": time.perf_counter() - started}, "counts": counts}
        # Rare: restore the frame's start and run it on the host path (halvings, impact zones, growth).
        runner.restore()
        self._rebuild_springs(state)
        self._frame_graph = None  # the host path may grow buffers: record again after an eager frame
        self._frame_graph_warm = None
        self.time = t0
        record = self.advance_frame_host(state, scratch, dt, steps)
        # The host path sized what overflowed for this frame's need; contact that grew into an overflow
        # usually grows on, so the buffers the failed frame filled beyond 85 % get the headroom too.
        runner.grow_near_full(report)
        self._restart_trim_windows()
        record["counts"]["device_fallbacks"] = 1
        record["fallback_reason"] = "; ".join(failed)
        record["seconds"]["total"] = time.perf_counter() - started
        return record

    def advance_frame_host(self, state: ClothState, scratch: ClothState, dt: float, steps: int) -> dict[str, Any]:
        """Advance ``state`` in place by ``steps`` host-path steps (:meth:`step`) of ``dt`` [s].

        The host path reads results back after every stage, so its stats hold seconds per stage
        (``seconds``: sums over the steps, and ``total``; ``counts``: sums, maxima for the sizes). It is
        the fallback of :meth:`advance_frame` and the profiling mode of
        :class:`pscc.sim.simulation.Simulation` (``stage_timing=True``).

        Raises:
            SimulationError: a step could not be made intersection-free.

        Allocates: yes. Capture-safe: no.
        """
        started = time.perf_counter()
        current, other = state, scratch
        seconds: dict[str, float] = {}
        counts: dict[str, int] = {}
        for _ in range(steps):
            stats = self.step(current, other, dt)
            current, other = other, current
            for key, value in stats["seconds"].items():
                seconds[key] = seconds.get(key, 0.0) + float(value)
            for key, value in stats["counts"].items():
                counts[key] = max(counts.get(key, 0), int(value)) if key in ("front_size", "contacts") \
                    else counts.get(key, 0) + int(value)
        if current is not state:
            wp.copy(state.positions, current.positions)
            wp.copy(state.velocities, current.velocities)
        counts.update(device_fallbacks=0, graph_recordings=0, graph_replays=0)
        seconds["total"] = time.perf_counter() - started
        return {"steps": steps, "seconds": seconds, "counts": counts}

    def _trim_projection(self, peak: int, contacts: int) -> bool:
        """Shrink the projection's constraint buffers (to 4 x the recent peak, keeping room for ``contacts``
        proximity constraints, the frame's most springs) once the last :data:`TRIM_FRAMES` frames used less
        than a sixteenth of them: contact peaks at the start of a scene (layers landing) would otherwise hold
        their memory for the whole run. Returns whether the buffers changed."""
        self._projection_peaks = (self._projection_peaks + [peak])[-TRIM_FRAMES:]
        floor = self._projection_floor(contacts)
        target = max(4 * max(self._projection_peaks), floor)
        if len(self._projection_peaks) < TRIM_FRAMES or 16 * max(self._projection_peaks) > self.projection.capacity \
                or target >= self.projection.capacity:
            return False
        self.projection.trim(target)
        self._projection_peaks = []
        return True

    def _restart_trim_windows(self) -> None:
        """Forget the frames counted towards every trim (after buffers grew)."""
        self._projection_peaks, self._hash_peaks, self._spring_peaks, self._candidate_peaks = [], [], [], []

    def _projection_floor(self, springs: int) -> int:
        """Constraint slots the projection keeps at least: a quarter per cloth face for collisions, plus one per
        contact spring slot (``springs``) when the springs join the first round (``proximity_constraints``)."""
        return self.cloth_face_count // 4 + (int(springs) if self.contact.proximity_constraints else 0)

    def _rebuild_springs(self, state: ClothState) -> None:
        """The contact springs of ``state``: a DCD at its positions and :meth:`ProximityContacts.update_device`
        (the springs a frame starts from, after :meth:`DeviceStep.restore`). They are the contacts the
        previous step's end found at the same positions, bit for bit, except perhaps a pair at the edge of
        the thickness (that DCD tested the candidates of the step's swept boxes; measured: 1 of 4,894 on
        ``stack``). Allocates: when buffers grow. Capture-safe: no."""
        contacts = self.detector.detect(state.positions, None, self.thickness)
        self.proximity.update_device(contacts.args, state.positions)
        while not self.proximity.check_capacity():
            self.proximity.update_device(contacts.args, state.positions)

    def _trim_springs(self, peak: int) -> bool:
        """Shrink the contact springs (to 1.25 x the recent peak, keeping the stored ones) once the last
        :data:`TRIM_FRAMES` frames used less than two thirds of them, like :meth:`_trim_hash`. Returns
        whether the buffers changed."""
        springs = self.proximity.springs
        self._spring_peaks = (self._spring_peaks + [peak])[-TRIM_FRAMES:]
        peak = max(self._spring_peaks)
        if len(self._spring_peaks) < TRIM_FRAMES or springs.capacity <= 1.5 * peak + TRIM_SLACK:
            return False
        target = max(int(1.25 * peak) + TRIM_SLACK // 2, self.cloth_face_count // 4)
        if target >= springs.capacity:
            return False
        springs.trim(target)
        self.integrator.system.reserve_contacts(springs.capacity)
        self._spring_peaks = []
        return True

    def _trim_candidates(self, peaks: list[int]) -> bool:
        """Shrink the candidate pair buffers and the narrow phase's (to 1.25 x the recent peak, never below
        the sizes the detector made them with: room for contact before it happens) once the last
        :data:`TRIM_FRAMES` frames used less than two thirds of them, like :meth:`_trim_hash`. Returns
        whether the buffers changed."""
        candidates = self.detector.candidates
        self._candidate_peaks = (self._candidate_peaks + [peaks])[-TRIM_FRAMES:]
        if len(self._candidate_peaks) < TRIM_FRAMES:
            return False
        targets = []
        for k, capacity in enumerate((candidates.capacity_vf, candidates.capacity_ee)):
            peak = max(frame[k] for frame in self._candidate_peaks)
            target = max(int(1.25 * peak) + TRIM_SLACK // 2, candidates.initial_capacities[k])
            targets.append(target if capacity > 1.5 * peak + TRIM_SLACK and target < capacity else capacity)
        if targets == [candidates.capacity_vf, candidates.capacity_ee]:
            return False
        candidates.trim(*targets)
        self.detector.narrow.reserve(candidates)
        self.detector.refresh_loans()
        self._candidate_peaks = []
        return True

    def _trim_hash(self, peaks: list[int]) -> bool:
        """Shrink the hash tables (:func:`~pscc.collision.spatial_hash_settings.fitted_capacities`: to 1.25 x
        the recent peak) once the last :data:`TRIM_FRAMES` frames used less than two thirds of them: growth
        ahead of need while contact builds up leaves slack that the settled contact does not use. Returns
        whether the buffers changed."""
        spatial_hash = self.intersection_check.spatial_hash  # the detector's, when it hashes
        self._hash_peaks = (self._hash_peaks + [peaks])[-TRIM_FRAMES:]
        if len(self._hash_peaks) < TRIM_FRAMES:
            return False
        recent_peaks = {k: max(frame[k] for frame in self._hash_peaks) for k in range(5)}
        targets = fitted_capacities(spatial_hash.capacities(), recent_peaks)
        if not targets:
            return False
        spatial_hash.trim(targets)
        self._hash_peaks = []
        return True

    def _device_runner(self) -> DeviceStep:
        if self._device_step is None:
            self._device_step = DeviceStep(self)
        return self._device_step

    def _run_device_frame(self, runner: DeviceStep, state: ClothState, scratch: ClothState, dt: float, steps: int,
                          graph: bool) -> str:
        """Run the frame's steps on the device: replay the recorded graph when it fits, else launch
        eagerly (and record a graph once an eager frame of this shape has succeeded). Returns
        ``"replayed"``, ``"recorded"`` (recorded, then replayed) or ``"eager"``."""
        key = (state.positions.ptr, scratch.positions.ptr, dt, steps)
        if graph and self._frame_graph is not None and self._frame_graph[0] == key:
            wp.capture_launch(self._frame_graph[1])
            return "replayed"
        if graph and self._frame_graph_warm == key and self.graph_unavailable is None:
            # Tables in lent memory follow a lender that was resized since the warm frame: move them now,
            # not while recording (nothing may be allocated or recorded again inside the capture).
            self.detector.refresh_loans()
            try:
                with wp.ScopedCapture(device=self.device) as capture:
                    self._launch_frame(runner, state, scratch, dt, steps)
            except Exception as error:  # noqa: BLE001 - any refusal to record: the eager frame runs instead
                # E.g. a CUDA driver without conditional graph nodes (CUDA < 12.4): the frame is
                # recorded with device-side loops, which that driver cannot replay. Run eagerly.
                self.graph_unavailable = f"{type(error).__name__}: {error}"
                warnings.warn(f"{self.scene.name}: the frame could not be recorded into a graph on {self.device} "
                              f"({self.graph_unavailable}); the run goes on with eager launches (stats.json: "
                              "graph)", GraphUnavailableWarning, stacklevel=2)
                self._launch_frame(runner, state, scratch, dt, steps)
                return "eager"
            self._frame_graph = (key, capture.graph)
            wp.capture_launch(capture.graph)
            return "recorded"
        self._launch_frame(runner, state, scratch, dt, steps)
        self._frame_graph_warm = key
        return "eager"

    def _launch_frame(self, runner: DeviceStep, state: ClothState, scratch: ClothState, dt: float,
                      steps: int) -> None:
        """The launches of one frame (recorded as they are into a graph)."""
        runner.clear_report()
        current, other = state, scratch
        for index in range(steps):
            runner.step(current, other, dt, index)
            current, other = other, current
        if current is not state:
            wp.copy(state.positions, current.positions)
            wp.copy(state.velocities, current.velocities)

    # ------------------------------------------------------------------ internals

    def _advance(self, state_in: ClothState, state_out: ClothState, t: float, dt: float, depth: int,
                 stats: dict[str, Any]) -> None:
        try:
            self._attempt(state_in, state_out, t, dt, stats)
        except _StepRejected as why:
            if self.contact.proximity_constraints and not self._near_off:
                # The proximity constraints may leave no room for a response (a vertex pressed between a
                # collision and a layer it touches): the same step again without them, before any halving.
                self._near_off = True
                try:
                    self._advance(state_in, state_out, t, dt, depth, stats)
                finally:
                    self._near_off = False
                return
            if depth >= self.contact.max_step_halvings:
                if self.initial_crossings:
                    fix = (f"the initial state has {self.initial_crossings} edge-face crossings, let through by "
                           f"allow_initial_intersections = true ({self.intersecting_pairs} still crossing); their "
                           "pairs are exempt from collision handling until they come apart, and the side that "
                           "passed through is pushed back (untangle_speed under [contact]), but the features "
                           "around them may still collide like this. Fix: separate the surfaces in the input")
                else:
                    fix = ("Fix: use a smaller time step (more steps_per_frame), allow more max_step_halvings or "
                           "max_response_rounds under [contact], or check the scene for surfaces squeezed "
                           "between moving obstacles")
                raise SimulationError(f"{self.scene.name}: step at t={t:.6g} s: could not be made intersection-free "
                                      f"after {depth} halvings (dt={dt:.3g} s): {why}; {fix}") from None
            stats["counts"]["halvings"] += 1
            middle = self._scratch.get(depth)
            if middle is None:
                middle = self._scratch[depth] = self.initial_state()
            self._advance(state_in, middle, t, dt / 2.0, depth + 1, stats)
            self._advance(middle, state_out, t + dt / 2.0, dt / 2.0, depth + 1, stats)

    def _kinematic_targets(self, t: float) -> np.ndarray:
        """Positions of every handle and obstacle vertex at time t (rows of model.handle_ids order)."""
        positions = np.zeros((self.model.vertex_count, 3), dtype=np.float64)
        for handle in self.scene.handles:
            rotation, translation = handle.transform(t)
            positions[handle.vertices] = self._initial[handle.vertices] @ rotation.T + translation
        for k, obstacle in enumerate(self.scene.obstacles):
            positions[self._obstacle_offsets[k]:self._obstacle_offsets[k + 1]] = obstacle.positions(t)
        return positions[self.model.handle_ids_host].astype(np.float32)

    def _group_maps(self, t: float, dt: float) -> dict[int, tuple[np.ndarray, np.ndarray]]:
        """Step maps of the rigid kinematic groups; non-rigid ones (mesh sequences) are fitted per zone."""
        movers = list(self.scene.handles) + list(self.scene.obstacles)
        return {g: step_map(m.transform(t), m.transform(t + dt)) for g, m in enumerate(movers)
                if getattr(m, "rigid", True)}

    def _cloth_crossings(self, positions: np.ndarray) -> np.ndarray:
        """Edge-face crossings that involve the cloth (obstacles may touch or overlap each other,
        e.g. the limbs of a body at its joints)."""
        crossings = self.intersection_check.find(positions)
        if crossings.shape[0] == 0 or not self.scene.obstacles:
            return crossings
        cloth_faces = int(self.scene.faces.shape[0])
        owners = self.intersection_check.edge_owner_faces[crossings[:, 0]]
        return crossings[(owners < cloth_faces) | (crossings[:, 1] < cloth_faces)]

    def _attempt(self, state_in: ClothState, state_out: ClothState, t: float, dt: float,
                 stats: dict[str, Any]) -> None:
        seconds, counts = stats["seconds"], stats["counts"]
        mark = time.perf_counter()
        springs = self.proximity.springs
        targets = self._kinematic_targets(t + dt) if self.model.handle_count else None
        self.integrator.system.set_clock(t)  # a retried (halved) step starts from its own time
        integration = self.integrator.step(state_in, state_out, dt,
                                           contacts=springs if springs.host_count else None,
                                           handle_targets=targets)
        counts["cg_iterations"] += integration.cg_iterations
        seconds["integration"] += time.perf_counter() - mark
        x0 = state_in.positions.numpy()
        x1 = state_out.positions.numpy()
        if not _finite_in_range(x1):
            raise _StepRejected("the integrator produced NaN, Inf or coordinates beyond MAX_COORDINATE")

        mark = time.perf_counter()
        broad = self.detector.broad_phase(x0, x1, self.thickness)
        counts["broad_phases"] += 1
        counts["front_size"] = max(counts["front_size"], int(broad["front_size"]))
        seconds["broad_phase"] += time.perf_counter() - mark
        certified = True
        zones: ImpactZones | None = None
        faces = self.collision_faces
        positions_t0 = wp.array(x0, dtype=wp.vec3, device=self.device)
        positions_t1 = wp.array(x1, dtype=wp.vec3, device=self.device)
        rounds = 0
        self.projection.reset()
        self.add_stitch_constraints(positions_t1)
        tolerance = self.response_tolerance
        while True:
            mark = time.perf_counter()
            # After a response, only pairs with a vertex it moved are tested again (exact re-check).
            result = self.detector.narrow_phase(x0, x1, self.ccd_distance, recheck=True,
                                                inside_share=CCD_INSIDE_SHARE)
            seconds["narrow_phase"] += time.perf_counter() - mark
            counts["ccd_rounds"] += 1
            hits = result.vertex_face.shape[0] + result.edge_edge.shape[0]
            counts["ccd_hits"] += hits
            if hits == 0:
                if certified:
                    break
                mark = time.perf_counter()
                self.detector.broad_phase(x0, x1, self.thickness)
                counts["broad_phases"] += 1
                seconds["broad_phase"] += time.perf_counter() - mark
                certified = True
                continue
            if rounds >= self.contact.max_response_rounds:
                raise _StepRejected(f"{hits} collisions left after {rounds} response rounds")
            rounds += 1
            certified = False
            mark = time.perf_counter()
            vertex_face = np.concatenate([result.vertex_face[:, :1], faces[result.vertex_face[:, 1]]], axis=1)
            if rounds <= self.contact.projection_rounds:
                counts["projection_rounds"] += 1
                # positions_t1 holds x1 here: the integrator's end positions or the last projection.
                self.projection.add(vertex_face, result.vertex_face_toi, result.edge_edge, result.edge_edge_toi,
                                    positions_t0, positions_t1)
                if rounds == 1 and self.contact.proximity_constraints and not self._near_off:
                    # The pairs already in contact may not be pushed closer (the next round's collisions).
                    self.projection.add_near(springs, positions_t1, self.separation)
                solved = self.projection.solve(positions_t1, self.separation, tolerance)
                counts["projection_iterations"] += solved.iterations
                x1 = positions_t1.numpy()
            else:
                counts["zone_rounds"] += 1
                if zones is None:
                    zones = ImpactZones(self._masses, self.kinematic_group)
                zones.merge(vertex_face)
                zones.merge(result.edge_edge)
                try:
                    x1 = zones.apply(x0, x1, dt, self._group_maps(t, dt), self._scale)
                except ImpactZoneFailure as failure:
                    raise _StepRejected(str(failure)) from None
            seconds["penetration"] += time.perf_counter() - mark
            if not _finite_in_range(x1):
                raise _StepRejected("the penetration response produced NaN, Inf or coordinates beyond MAX_COORDINATE")

        # The DCD reads the candidate pairs before the intersection check hashes over their memory (lent
        # to the detector's hash); the springs change only once the check has passed.
        mark = time.perf_counter()
        proximity = self.detector.narrow_phase(x1, None, self.thickness)
        seconds["proximity"] += time.perf_counter() - mark
        if self.contact.check_intersections:
            mark = time.perf_counter()
            crossings = self._cloth_crossings(x1)
            seconds["intersection_check"] += time.perf_counter() - mark
            if crossings.shape[0]:
                raise _StepRejected(f"the intersection check found {crossings.shape[0]} edge-face crossings")

        mark = time.perf_counter()
        state_out.positions.assign(x1)
        wp.launch(_velocities_from_positions, dim=self.model.vertex_count,
                  inputs=[state_in.positions, state_out.positions, 1.0 / dt], outputs=[state_out.velocities],
                  device=self.device)
        counts["dcd_vertex_face"] = int(proximity.vertex_face.shape[0])
        counts["dcd_edge_edge"] = int(proximity.edge_edge.shape[0])
        self.proximity.update(proximity.vertex_face, proximity.edge_edge, state_out.positions)
        seconds["proximity"] += time.perf_counter() - mark
