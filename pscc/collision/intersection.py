"""Discrete intersection check of a triangle soup: which mesh edges cross which triangles.

An *intersection* is a mesh edge meeting a triangle it shares no vertex with (touching counts),
the definition of ipctk's ``has_intersections``. The cloth simulator calls
:class:`IntersectionCheck` on every output frame as a safety net, so the test is conservative:
every intersecting (edge, face) pair is reported, and a reported pair that does not intersect
lies within a certified float32 distance bound of the face (:mod:`pscc.geometry.segment_triangle`).

Pipeline of :meth:`IntersectionCheck.find`:

1. exact per-face boxes (min / max of the float32 corners: no rounding, so an intersecting
   pair always has overlapping closed boxes);
2. :class:`~pscc.collision.spatial_hash.SpatialHash` over the boxes, every face its own node (plain
   spatial hashing; pairs sharing a vertex are kept, since their other edges can still cross);
3. per face pair ``(g, f)`` (a row kernel, :mod:`pscc._lanes`): the 3 + 3 edges of one face against the other face,
   skipping edges that share a vertex with that face. Edge ``e`` is tested only from its owner,
   the lowest-id face containing it (``edge_owner``), so each (edge, face) pair is tested and
   reported once (an edge inside a face's box makes every face of that edge overlap the box);
4. hits are appended with an atomic counter that keeps counting past the buffer (no silent loss),
   and the hits that involve the cloth are counted on the device (``crossing_count``); the host
   API grows the buffer to the exact count and runs again when it overflowed, then sorts the hits.

:meth:`IntersectionCheck.count_device` is that pipeline with no host read, synchronization,
allocation or upload (the test pass runs at the hash's pair capacity and stops at its device
count), so it can be recorded into a graph; :meth:`IntersectionCheck.check_capacity` is its sync
point. :meth:`~IntersectionCheck.find` and :meth:`~IntersectionCheck.has_intersections` are both,
repeated until the buffers fit.

Device buffers of :class:`IntersectionCheck` (m faces, n vertices, E edges, H hit slots):

=======================  ====================  =================================================
buffer                   shape, dtype          meaning
=======================  ====================  =================================================
faces                    (m,) vec3i            vertex ids of each face
face_edges               (m,) vec3i            edge ids of (v0, v1), (v1, v2), (v2, v0)
edges                    (E,) vec2i            edge vertex ids ``[a, b]``, ``a < b``, sorted
edge_owner               (E,) int32            lowest face id containing the edge
face_lower / face_upper  (m,) vec3             exact face boxes
hits                     (H,) vec2i            reported (edge id, face id), unsorted
hit_kind / hit_bound     (H,) int32 / float32  1 certain crossing, 2 near; distance bound Delta
hit_count                (1,) int64            hits found (may exceed H: then H grows)
crossing_count           (1,) int32            hits that involve the cloth (``count_device``)
=======================  ====================  =================================================

Sync points of :meth:`IntersectionCheck.find` (host reads of device data): one per run in
:meth:`IntersectionCheck.check_capacity` (the hash's counters and the hit count), then the copy of
the hits to the host.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import warp as wp

from pscc._checks import check_object_ids, check_points
from pscc._lanes import row_lanes
from pscc.collision.device_topology import DeviceTopology
from pscc.collision.seams import SeamAdjacency, SeamArgs, stitched_to_face
from pscc.collision.spatial_hash import DEFAULT_CELL_SIZE_FACTOR, SpatialHash
from pscc.errors import CapacityError, InputError
from pscc.geometry.segment_triangle import segment_triangle_classify
from pscc.mesh.topology import MeshTopology

wp.set_module_options({"enable_backward": False})

MAX_HITS: int = 2**31 - 1
"""Most (edge, face) hits one call can report (int32 slot indices)."""

_GROWTH: float = 1.25
"""A grown hit buffer gets this factor over the exact count."""


@dataclass
class IntersectionStats:
    """Counters of the last :meth:`IntersectionCheck.find` call.

    Attributes:
        face_pairs: face pairs from the broad phase (closed boxes overlap).
        hits: reported (edge, face) pairs.
        crossings: hits that are certain proper crossings.
        near: hits reported because float32 could not exclude them (within their bound).
        max_near_bound: largest certified distance bound among the near hits (length units).
        reruns: times the test pass ran again after the hit buffer grew.
    """

    face_pairs: int = 0
    hits: int = 0
    crossings: int = 0
    near: int = 0
    max_near_bound: float = 0.0
    reruns: int = 0


@wp.kernel
def _compute_exact_face_boxes(
    # in:
    faces: wp.array(dtype=wp.vec3i),
    positions: wp.array(dtype=wp.vec3),
    # out:
    lower_out: wp.array(dtype=wp.vec3),
    upper_out: wp.array(dtype=wp.vec3),
):
    """One thread per face: componentwise min / max of its three corners (exact)."""
    i = wp.tid()
    f = faces[i]
    a = positions[f[0]]
    b = positions[f[1]]
    c = positions[f[2]]
    lower_out[i] = wp.min(wp.min(a, b), c)
    upper_out[i] = wp.max(wp.max(a, b), c)


@wp.struct
class EdgeTopologyArgs:
    """The faces and edges the test pass reads (layout in the module docstring)."""

    faces: wp.array(dtype=wp.vec3i)
    face_edges: wp.array(dtype=wp.vec3i)
    edges: wp.array(dtype=wp.vec2i)
    edge_owner: wp.array(dtype=wp.int32)
    seams: SeamArgs


@wp.kernel
def _reset_hit_counts(
    # out:
    hit_count: wp.array(dtype=wp.int64),
    crossing_count: wp.array(dtype=wp.int32),
):
    """A single thread: zeroes the counters of a call (a kernel, so a graph replays it)."""
    hit_count[0] = wp.int64(0)
    crossing_count[0] = 0


@wp.kernel
def _test_face_pairs(
    # in:
    topology: EdgeTopologyArgs,
    positions: wp.array(dtype=wp.vec3),
    face_pairs: wp.array(dtype=wp.vec2i),
    pair_counts: wp.array(dtype=wp.int64),
    cloth_face_count: int,
    capacity: int,
    lanes: int,
    # out:
    hit_count: wp.array(dtype=wp.int64),
    crossing_count: wp.array(dtype=wp.int32),
    hits: wp.array(dtype=wp.vec2i),
    hit_kind: wp.array(dtype=wp.int32),
    hit_bound: wp.array(dtype=float),
):
    """Row kernel (:mod:`pscc._lanes`) over the live face pairs, the first min(pair_counts[0], slots):
    owned edges of each face against the other face. Every hit is counted (past ``capacity`` too); a hit
    whose edge owner or face is below ``cloth_face_count`` also counts as a cloth crossing."""
    # Arrays out of the struct once: on the CPU every struct member access copies the array header.
    faces = topology.faces
    face_edges = topology.face_edges
    edge_owner = topology.edge_owner
    edges = topology.edges
    seams = topology.seams
    has_seams = seams.offsets.shape[0] > 1
    rows = int(wp.min(pair_counts[0], wp.int64(face_pairs.shape[0])))
    for i in range(wp.tid(), rows, lanes):
        pair = face_pairs[i]
        for side in range(2):
            g = pair[side]
            f = pair[1 - side]
            fv = faces[f]
            fe = face_edges[g]
            for k in range(3):
                e = fe[k]
                if edge_owner[e] != g:
                    continue
                ev = edges[e]
                if (ev[0] == fv[0] or ev[0] == fv[1] or ev[0] == fv[2] or ev[1] == fv[0] or ev[1] == fv[1]
                        or ev[1] == fv[2]):
                    continue
                if has_seams:
                    if stitched_to_face(seams, ev[0], fv) or stitched_to_face(seams, ev[1], fv):
                        continue
                r = segment_triangle_classify(positions[ev[0]], positions[ev[1]],
                                              positions[fv[0]], positions[fv[1]], positions[fv[2]])
                if r[0] > 0.5:
                    if g < cloth_face_count or f < cloth_face_count:
                        wp.atomic_add(crossing_count, 0, 1)
                    slot = wp.atomic_add(hit_count, 0, wp.int64(1))
                    if slot < wp.int64(capacity):
                        s = int(slot)
                        hits[s] = wp.vec2i(e, f)
                        hit_kind[s] = int(r[0] + 0.5)
                        hit_bound[s] = r[1]

class IntersectionCheck:
    """Conservative discrete intersection check of one triangle soup (cloth and obstacles together).

    Callers concatenate their meshes into one index space (offset the faces of each mesh by the
    vertices before it) and may tag each face with an object id to learn which objects are
    involved (:meth:`object_pairs`). Buffer layout and pipeline in the module docstring.

    Args:
        faces: (face_count, 3) integer vertex ids; the three ids of a face must differ.
        vertex_count: number of vertices n (positions passed later have n rows).
        device: Warp device (``None``: the default device).
        object_ids: (face_count,) integer object id per face, or ``None`` (all 0).
        cell_size_factor: spatial hash cell size over the mean face box size.
        hit_capacity: initial hit slots (default 64); grown to the exact need.
        spatial_hash: a :class:`SpatialHash` over the same faces to use (and grow) instead of a new one,
            e.g. a :class:`pscc.collision.detector.CollisionDetector`'s: its buffers are scratch between
            calls, so a simulator that checks after its broad phase's pairs were consumed saves a
            second set of hash tables. Its own pair sort and slab test are not used (no node ids).
        device_topology: the faces' :class:`~pscc.collision.device_topology.DeviceTopology` to use instead
            of uploading them again (e.g. the detector's), or ``None``.
        face_boxes: two (face_count,) ``wp.vec3`` buffers for the face boxes, lent by a caller that needs
            nothing in them while the check runs and never reads what it leaves (e.g. the detector's
            face boxes, which its next broad phase computes anew), or ``None`` (buffers of its own).
        seams: the stitch partners of the vertices (:mod:`pscc.collision.seams`): an edge with an end
            stitched to a vertex of a face is not tested against it (a closed seam touches there); None:
            no stitches.

    Raises:
        InputError: invalid faces, vertex count, object ids or options.

    Allocates: yes (every buffer at its initial capacity). Capture-safe: no.
    """

    def __init__(
        self,
        faces: np.ndarray,
        vertex_count: int,
        device: wp.Device | str | None = None,
        *,
        object_ids: np.ndarray | None = None,
        cell_size_factor: float = DEFAULT_CELL_SIZE_FACTOR,
        hit_capacity: int = 64,
        spatial_hash: SpatialHash | None = None,
        device_topology: DeviceTopology | None = None,
        face_boxes: tuple[wp.array, wp.array] | None = None,
        seams: SeamAdjacency | None = None,
    ) -> None:
        if isinstance(vertex_count, bool) or not isinstance(vertex_count, int | np.integer) or vertex_count < 0:
            raise InputError("argument", "vertex_count", f"{vertex_count!r} is not an integer >= 0",
                             "pass the number of vertices")
        if isinstance(hit_capacity, bool) or not isinstance(hit_capacity, int | np.integer) or hit_capacity < 1:
            raise InputError("argument", "hit_capacity", f"{hit_capacity!r} is not an integer >= 1",
                             "pass a positive integer such as 64")
        topology = (device_topology.topology if device_topology is not None
                    else MeshTopology.from_faces(faces, int(vertex_count)))
        tris = np.asarray(faces).reshape(-1, 3).astype(np.int32)
        m = tris.shape[0]
        if object_ids is None:
            objects = np.zeros(m, dtype=np.int32)
        else:
            objects = check_object_ids(object_ids, m)
        self.device = wp.get_device(device)
        self.vertex_count = int(vertex_count)
        self.face_count = m
        self.topology = topology
        self.object_ids = objects
        edge_count = topology.edge_count
        owner = topology.edge_face_indices[topology.edge_face_offsets[:-1]] if edge_count else np.zeros(0, np.int32)
        self._edge_owner_np = owner.astype(np.int32)

        dev = self.device
        if device_topology is None:
            device_topology = DeviceTopology.upload(tris, topology, dev)
        device_topology.check_same(tris, dev, "intersection check")
        self.device_topology = device_topology
        """The faces, edges and face edges on the device (the caller's when it passed them)."""
        self.faces = device_topology.faces
        self.face_edges = device_topology.face_edges
        self.edges = device_topology.edges
        self.edge_owner = wp.array(self._edge_owner_np, dtype=wp.int32, device=dev)
        if face_boxes is None:
            face_boxes = (wp.empty(m, dtype=wp.vec3, device=dev), wp.empty(m, dtype=wp.vec3, device=dev))
        if not isinstance(face_boxes, tuple | list) or len(face_boxes) != 2:
            raise InputError("argument", "face_boxes", f"got {type(face_boxes).__name__}, not two arrays",
                             "pass (lower, upper) face box buffers, or None")
        for k, box in enumerate(face_boxes):
            if not isinstance(box, wp.array) or box.dtype != wp.vec3 or box.shape != (m,) or box.device != dev:
                raise InputError("argument", f"face_boxes[{k}]", "is not a (face_count,) wp.vec3 array on the check's "
                                 "device", "lend two face box buffers of the same mesh, or None")
        self.face_lower, self.face_upper = face_boxes
        self.hit_count = wp.zeros(1, dtype=wp.int64, device=dev)
        self.crossing_count = wp.zeros(1, dtype=wp.int32, device=dev)
        self._topology = EdgeTopologyArgs()
        self._topology.faces = self.faces
        self._topology.face_edges = self.face_edges
        self._topology.edges = self.edges
        self._topology.edge_owner = self.edge_owner
        self.seams = seams if seams is not None else SeamAdjacency(None, 0, dev)
        self._topology.seams = self.seams.args
        self._allocate_hits(int(hit_capacity))
        self._hit_total = 0
        self._hit_reruns = 0
        if spatial_hash is not None and (not isinstance(spatial_hash, SpatialHash) or spatial_hash.face_count != m
                                         or spatial_hash.device != dev or spatial_hash.skip_adjacent):
            raise InputError("argument", "spatial_hash", "is not a SpatialHash over these faces on this device "
                             "(without skip_adjacent)", "pass the detector's hash over the same faces, or None")
        self.spatial_hash = spatial_hash if spatial_hash is not None else SpatialHash(m, dev, cell_size_factor,
                                                                                      sort_pairs=False)
        self.stats = IntersectionStats()
        self._kinds = np.zeros(0, dtype=np.int32)
        self._bounds = np.zeros(0, dtype=np.float32)

    def refresh_seams(self) -> None:
        """Take the current arrays of :attr:`seams` (after :meth:`SeamAdjacency.rebuild`). Capture-safe: no."""
        self._topology.seams = self.seams.args

    def _allocate_hits(self, capacity: int) -> None:
        self.hit_capacity = capacity
        self.hits = wp.empty(capacity, dtype=wp.vec2i, device=self.device)
        self.hit_kind = wp.empty(capacity, dtype=wp.int32, device=self.device)
        self.hit_bound = wp.empty(capacity, dtype=float, device=self.device)

    @property
    def edge_vertices(self) -> np.ndarray:
        """(edge_count, 2) int32 vertex ids of each edge (the edge ids that :meth:`find` reports)."""
        return self.topology.edges

    @property
    def edge_owner_faces(self) -> np.ndarray:
        """(edge_count,) int32 lowest face id containing each edge (its object is the edge's object)."""
        return self._edge_owner_np

    def _upload(self, positions: object) -> wp.array:
        """Validated device positions: a matching ``wp.array`` as is, anything else copied."""
        if isinstance(positions, wp.array):
            return self._device_positions(positions)
        n = self.vertex_count
        host = check_points(positions, "positions", shape_tail=(3,))
        if host.shape[0] != n:
            raise InputError("argument", "positions", f"{host.shape[0]} rows for {n} vertices",
                             f"pass ({n}, 3) positions")
        # A copy for this call only (the host API allocates anyway; device callers pass their own array).
        return wp.array(host.reshape(-1, 3), dtype=wp.vec3, device=self.device)

    def overflow_counters(self) -> list[tuple[wp.array, int, int]]:
        """``(device counter, index, capacity)`` triples of the last :meth:`count_device`: a counter
        above its capacity means :meth:`check_capacity` must grow a buffer (see
        :meth:`SpatialHash.overflow_counters`)."""
        return [*self.spatial_hash.overflow_counters(), (self.hit_count, 0, self.hit_capacity)]

    def count_device(self, positions: wp.array, cloth_face_count: int | None = None) -> None:
        """Boxes, the hash's device path and the test pass, with nothing read back: leaves in
        ``crossing_count[0]`` (int32) the number of reported (edge, face) pairs, and the hits in
        ``hits`` / ``hit_kind`` / ``hit_bound`` (the first min(hit_count[0], hit_capacity) rows).

        Buffers that are too small keep counting on the device; :meth:`check_capacity` (a sync point)
        grows them and says whether to run again. The positions are not checked for NaN/Inf here (a
        host read): boxes holding them are reported by :meth:`check_capacity`.

        Args:
            positions: (vertex_count,) ``wp.vec3`` on the check's device.
            cloth_face_count: count only the pairs that involve the cloth, the faces below this id
                (the edge's owner face or the face is a cloth face; obstacle-obstacle contact is
                ignored). ``None``: count every pair.

        Raises:
            InputError: positions of the wrong type, shape, dtype or device; a bad cloth face count.

        Allocates: no. Capture-safe: yes (with the arrays of the recorded call; after
        :meth:`check_capacity` grows a buffer, record again).
        """
        points = self._device_positions(positions)
        m = self.face_count
        if cloth_face_count is None:
            cloth = m
        elif isinstance(cloth_face_count, bool) or not isinstance(cloth_face_count, int | np.integer) \
                or not 0 <= cloth_face_count <= m:
            raise InputError("argument", "cloth_face_count", f"{cloth_face_count!r} is not an integer in [0, {m}]",
                             "pass the number of cloth faces (they come first), or None")
        else:
            cloth = int(cloth_face_count)
        dev = self.device
        wp.launch(_reset_hit_counts, dim=1, outputs=[self.hit_count, self.crossing_count], device=dev)
        if m < 2:
            return
        wp.launch(_compute_exact_face_boxes, dim=m, inputs=[self.faces, points],
                  outputs=[self.face_lower, self.face_upper], device=dev)
        hash_ = self.spatial_hash
        hash_.find_pairs_device(self.face_lower, self.face_upper)
        lanes = row_lanes(dev, hash_.pair_capacity)
        wp.launch(_test_face_pairs, dim=lanes,
                  inputs=[self._topology, points, hash_.pairs, hash_.counts, cloth, self.hit_capacity, lanes],
                  outputs=[self.hit_count, self.crossing_count, self.hits, self.hit_kind, self.hit_bound],
                  device=dev)

    def check_capacity(self) -> bool:
        """Sync point after :meth:`count_device`: raise the hash's deferred input errors, grow the hash
        and the hit buffer where they overflowed (1.25 x the exact need).

        Returns:
            True when everything fit (``crossing_count`` and the hits are valid); False when a buffer
            grew: run :meth:`count_device` again (and record it again).

        Raises:
            InputError: NaN or Inf positions (found as non-finite boxes).
            CapacityError: more hits or pairs than int32 slots.

        Allocates: when a buffer grows. Capture-safe: no.
        """
        if self.face_count < 2:
            self._hit_total = 0
            return True
        if not self.spatial_hash.check_capacity():
            return False  # the hits of a partial pair set only bound the need from below: size them next run
        fits = True
        found = int(self.hit_count.numpy()[0])
        if found > MAX_HITS:
            raise CapacityError(f"intersection hit buffer: {found} hits exceed {MAX_HITS}; "
                                "the mesh is massively self-intersecting")
        if found > self.hit_capacity:
            self._allocate_hits(min(MAX_HITS, int(found * _GROWTH) + 1))
            self._hit_reruns += 1
            fits = False
        self._hit_total = found
        return fits

    def _device_positions(self, positions: object) -> wp.array:
        """A position array used in place: type, shape, dtype, device and layout checked on the host."""
        n = self.vertex_count
        if not isinstance(positions, wp.array):
            raise InputError("argument", "positions", f"got {type(positions).__name__}, not a wp.array",
                             f"pass a ({n},) wp.array of vec3 on {self.device}")
        if positions.dtype != wp.vec3 or positions.ndim != 1 or positions.shape[0] != n:
            raise InputError("argument", "positions", f"got a {positions.shape} array of "
                             f"{wp.types.type_repr(positions.dtype)}", f"pass a ({n},) wp.array of vec3")
        if positions.device != self.device:
            raise InputError("argument", "positions", f"array is on {positions.device}, the check on "
                             f"{self.device}", f"copy it to {self.device} first")
        if not positions.is_contiguous:
            raise InputError("argument", "positions", "array is not contiguous", "pass a contiguous array")
        return positions

    def _run(self, positions: object) -> int:
        """The device path and its sync point until the buffers fit; returns the exact hit count."""
        self.stats = IntersectionStats()
        points = self._upload(positions)
        if self.face_count < 2:
            return 0
        self._hit_reruns = 0
        while True:
            self.count_device(points)
            if self.check_capacity():
                break
        self.stats.face_pairs = self.spatial_hash.stats.triangle_pairs
        self.stats.reruns = self._hit_reruns
        return self._hit_total

    def find(self, positions: object) -> np.ndarray:
        """All reported (edge id, face id) pairs: the edge meets the face or is within its bound of it.

        Every intersecting pair is reported (no false negatives); a reported pair that does not
        intersect is within the certified distance bound of :mod:`pscc.geometry.segment_triangle`
        (see :meth:`details`). Edge ids index :attr:`edge_vertices`.

        Sync points: :meth:`check_capacity` after each run of :meth:`count_device` (until the buffers
        fit), then the copy of the hits.

        Args:
            positions: (vertex_count, 3) float positions (NumPy or nested lists, converted to float32
                and copied to the device) or a (vertex_count,) ``wp.vec3`` array on the check's device
                (used in place; must be finite).

        Returns:
            (k, 2) int32 array of (edge id, face id) rows, each pair once, sorted lexicographically.

        Raises:
            InputError: wrong shape, dtype or device, NaN or Inf.
            CapacityError: more hits than int32 slots.

        Allocates: when the hit buffer or the spatial hash grows, the host result, and a device copy of
        host positions. Capture-safe: no.
        """
        count = self._run(positions)
        if count == 0:
            self._kinds = np.zeros(0, dtype=np.int32)
            self._bounds = np.zeros(0, dtype=np.float32)
            return np.zeros((0, 2), dtype=np.int32)
        hits = self.hits[:count].numpy().reshape(-1, 2).astype(np.int32)
        kinds = self.hit_kind[:count].numpy()
        bounds = self.hit_bound[:count].numpy()
        order = np.lexsort((hits[:, 1], hits[:, 0]))
        hits, self._kinds, self._bounds = hits[order], kinds[order], bounds[order]
        near = self._kinds == 2
        self.stats.hits = count
        self.stats.near = int(near.sum())
        self.stats.crossings = count - self.stats.near
        self.stats.max_near_bound = float(self._bounds[near].max()) if self.stats.near else 0.0
        return hits

    def details(self) -> tuple[np.ndarray, np.ndarray]:
        """Kind and distance bound of each row of the last :meth:`find` result.

        Returns:
            ``(kinds, bounds)``: (k,) int32 :class:`~pscc.geometry.segment_triangle.SegmentTriangleKind`
            values (1 certain crossing, 2 near) and (k,) float32 certified bounds on the
            edge-face distance (0 for crossings, length units).

        Allocates: no. Capture-safe: no (host data).
        """
        return self._kinds, self._bounds

    def has_intersections(self, positions: object) -> bool:
        """Whether any edge meets (or is within its bound of) a face it shares no vertex with.

        Sync points: those of :meth:`find`, except the copy of the hits (only their count is read).

        Args:
            positions: as for :meth:`find`.

        Returns:
            True when at least one pair is reported.

        Raises:
            InputError: invalid positions.
            CapacityError: more hits than int32 slots.

        Allocates: when the hit buffer or the spatial hash grows, and a device copy of host positions.
        Capture-safe: no.
        """
        count = self._run(positions)
        self._kinds = np.zeros(0, dtype=np.int32)
        self._bounds = np.zeros(0, dtype=np.float32)
        self.stats.hits = count
        return count > 0

    def object_pairs(self, pairs: np.ndarray) -> np.ndarray:
        """Objects involved in (edge id, face id) pairs, e.g. the result of :meth:`find`.

        The object of an edge is that of its owner face (:attr:`edge_owner_faces`).

        Args:
            pairs: (k, 2) integer (edge id, face id) rows.

        Returns:
            (j, 2) int32 unique rows ``(min, max)`` of the two objects, sorted; ``(i, i)`` is a
            self-intersection of object i.

        Allocates: yes (host arrays). Capture-safe: no.
        """
        rows = np.asarray(pairs, dtype=np.int64).reshape(-1, 2)
        if rows.shape[0] == 0:
            return np.zeros((0, 2), dtype=np.int32)
        edge_objects = self.object_ids[self._edge_owner_np[rows[:, 0]]]
        face_objects = self.object_ids[rows[:, 1]]
        both = np.stack([np.minimum(edge_objects, face_objects), np.maximum(edge_objects, face_objects)], axis=1)
        return np.unique(both, axis=0).astype(np.int32)
