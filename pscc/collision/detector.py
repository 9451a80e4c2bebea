"""``CollisionDetector``: the one interface every detection method of pscc shares.

A detector is built once per mesh topology and called once per step::

    det = pscc.CollisionDetector(faces, method="pscc", object_ids=None, device=None)
    res = det.detect(positions, positions_end=None, thickness=0.0)

Discrete detection (DCD, ``positions_end=None``) reports the pairs closer than ``thickness``.
Continuous detection (CCD) reports the pairs that come within ``thickness`` (0 = touching) at some
time of the step, with a time of impact that is never later than the true one. Pairs that share a
vertex are never reported, and isolated vertices (used by no face) take no part. Both are
conservative: a true pair is never missed; a reported pair may be a near miss within the
tolerance band documented in :mod:`pscc.tolerances` (``docs/ccd.md``).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import warp as wp

from pscc._checks import INT32_MAX, as_numpy, check_coordinate_range, check_object_ids, check_points, check_thickness
from pscc._memory import DETECTION_BYTES_PER_TRIANGLE, check_fits
from pscc.collision.boxes import PrimitiveBoxes
from pscc.collision.brute_force import BroadPhaseBruteForce
from pscc.collision.bvh import MaterialBvh
from pscc.collision.candidates import CandidatePairs
from pscc.collision.capacity_verdict import CapacityVerdict
from pscc.collision.contacts import DeviceContacts
from pscc.collision.device_topology import DeviceTopology
from pscc.collision.feature_pairs import FeaturePairs
from pscc.collision.front import NormalConeFront
from pscc.collision.intrinsic import bvh_material
from pscc.collision.narrow_phase import NarrowPhase
from pscc.collision.scratch import held_arrays
from pscc.collision.seams import SeamAdjacency
from pscc.collision.spatial_hash import DEFAULT_CELL_SIZE_FACTOR, SpatialHash
from pscc.collision.spatial_hash_settings import SLAB_PROBE_BACKOFF, fitted_capacities
from pscc.errors import InputError, StaleGraphError
from pscc.mesh.mesh_data import validate_mesh
from pscc.mesh.topology import MeshTopology

FITTED_TABLES: tuple[int, ...] = (0, 1, 4)
"""The spatial hash's tables that :meth:`CollisionDetector.fit_buffers` fits to a call (indices of
:meth:`~pscc.collision.spatial_hash.SpatialHash.capacities`: entries, groups, slab tables)."""

METHODS: tuple[str, ...] = ("pscc", "spatial-hash", "brute-force")
"""Detection methods of :class:`CollisionDetector`: ``pscc`` (normal-cone test front + paired-key
spatial hash, the default), ``spatial-hash`` (the same hash with cell-only keys: no normal-cone
culling) and ``brute-force`` (all feature pairs; the exact reference)."""


def resolve_device(device: str | None) -> wp.Device:
    """Return the Warp device for a name, or raise :class:`InputError` listing the devices."""
    try:
        return wp.get_device(device)
    except (RuntimeError, ValueError) as exc:
        names = ", ".join(d.alias for d in wp.get_devices())
        raise InputError("argument", "device", f"{device!r} is not available ({exc})",
                         f"use one of: {names}") from exc


@dataclass
class CollisionResult:
    """Pairs found by one :meth:`CollisionDetector.detect` call; rows sorted lexicographically.

    Attributes:
        vertex_face: (K, 2) int32 rows (vertex, face).
        edge_edge: (L, 4) int32 rows (a0, a1, b0, b1) with a0 < a1, b0 < b1, (a0, a1) < (b0, b1).
        vertex_face_toi: (K,) float32 time of impact in [0, 1] (CCD only, else None).
        edge_edge_toi: (L,) float32 time of impact (CCD only, else None).
        stats: counts, per-stage seconds and device bytes (see :meth:`CollisionDetector.detect`).
    """

    vertex_face: np.ndarray
    edge_edge: np.ndarray
    vertex_face_toi: np.ndarray | None = None
    edge_edge_toi: np.ndarray | None = None
    stats: dict[str, Any] = field(default_factory=dict)


class CollisionDetector:
    """Collision detection for a triangle mesh with fixed topology (one or several objects).

    The first :meth:`detect` (or :meth:`broad_phase`) call validates the faces against the
    positions and builds every structure; later calls reuse them (the ``pscc`` test front persists
    across calls: temporal coherence).

    Args:
        faces: (face_count, 3) integer vertex ids.
        method: one of :data:`METHODS` (default ``"pscc"``).
        object_ids: optional (face_count,) integer object id per face, in [0, 2**31 - 1] (default: one
            object). Ids need not be contiguous; memory grows with the number of distinct ids.
        device: Warp device name (default: Warp's default device).
        rest: optional (vertex_count, 2 or 3) material-space coordinates for the ``pscc`` BVH;
            when omitted, the BVH is built over an embedding of the first positions seen by distance
            along the surface (:func:`pscc.collision.intrinsic.intrinsic_coordinates`); a connected
            piece whose 3-D rest shape is not flat is embedded the same way from that rest shape
            (:func:`pscc.collision.intrinsic.bvh_material`).
        rigid_objects: object ids that are rigid obstacles: each is one front node, so its own
            faces are never tested against each other.
        shrink_interval: ``pscc`` shrinks its test front every this many calls.
        cell_size_factor: k of the grid-size heuristic, cell = k x mean box axis length.
        stitches: optional (s, 4) rows ``(i, j, k, r)`` (vertex i sewn to (1 - r) x_j + r x_k): the
            features a stitch joins are never reported (:mod:`pscc.collision.seams`).
        face_diagonals: test face pairs in the spatial hash with 26-DOPs (the box and ten diagonal
            slabs, :mod:`pscc.geometry.dop`) instead of boxes alone; ``None`` (default): on for
            ``pscc``, off for ``spatial-hash`` (the plain hashing baseline). The pairs found do not
            change, only the triangle pairs handed on. Ignored by ``brute-force``.

    Coordinate range: the kernels compute in float32, so every call that takes positions refuses
    arrays whose largest |coordinate| exceeds :data:`pscc.tolerances.MAX_COORDINATE` (1e9 length
    units: products of four lengths would overflow) or is positive but below
    :data:`pscc.tolerances.MIN_COORDINATE_SCALE` (1e-6: they would underflow), and a thickness
    above :data:`pscc.tolerances.MAX_THICKNESS` (1e9), with an :class:`InputError` naming the
    argument, the largest value and the limit. Inside the range the pairs do not depend on the
    unit (measured for every method, DCD and CCD, from 1e-6 to 1e9; ``docs/mesh-input.md``).
    Positions are rounded to float32 on entry, so a small object far from the origin loses detail
    (about |x| 2^-24): express positions relative to a nearby origin.

    Raises:
        InputError: bad faces, object ids, method or device.
    """

    def __init__(
        self,
        faces: Any,
        *,
        method: str = "pscc",
        object_ids: Any = None,
        device: str | None = None,
        rest: Any = None,
        rigid_objects: Any = (),
        shrink_interval: int = 5,
        cell_size_factor: float = DEFAULT_CELL_SIZE_FACTOR,
        stitches: Any = None,
        face_diagonals: bool | None = None,
    ) -> None:
        if method not in METHODS:
            raise InputError("argument", "method", f"unknown method {method!r}",
                             f"use one of {', '.join(METHODS)}")
        faces_np = as_numpy(faces)
        if faces_np.ndim != 2 or faces_np.shape[-1] != 3:
            raise InputError("argument", "faces", f"shape {faces_np.shape} is not (m, 3)",
                             "pass triangle faces as an (m, 3) integer array")
        if faces_np.size and faces_np.dtype.kind not in "iu":
            raise InputError("argument", "faces", f"dtype {faces_np.dtype} is not an integer type",
                             "pass vertex ids as integers")
        if faces_np.size and (int(faces_np.max()) > INT32_MAX or int(faces_np.min()) < 0):
            bad = int(faces_np.max()) if int(faces_np.max()) > INT32_MAX else int(faces_np.min())
            raise InputError("argument", "faces", f"vertex id {bad} is outside [0, {INT32_MAX}]",
                             "pass 0-based vertex ids that fit a 32-bit signed integer")
        if int(shrink_interval) < 1:
            raise InputError("argument", "shrink_interval", f"{shrink_interval!r} is below 1", "pass an integer >= 1")
        self.method = method
        self.device = resolve_device(device)
        check_fits(faces_np.shape[0] * DETECTION_BYTES_PER_TRIANGLE, what=f"detecting collisions among "
                   f"{faces_np.shape[0]:,} triangles", source="argument", field="faces",
                   fix="pass a coarser mesh or use a device with more memory", device=str(self.device))
        self._faces_np = np.ascontiguousarray(faces_np, dtype=np.int32)
        self._object_ids_np = None if object_ids is None else check_object_ids(object_ids, faces_np.shape[0])
        self._rest = None if rest is None else as_numpy(rest)
        self._stitches = None if stitches is None else as_numpy(stitches)
        try:
            self._rigid_objects = frozenset(int(o) for o in rigid_objects)
        except (TypeError, ValueError) as exc:
            raise InputError("argument", "rigid_objects", f"{rigid_objects!r} is not a collection of integer "
                             "object ids", "pass e.g. {1, 3}, or () for none") from exc
        self._shrink_interval = int(shrink_interval)
        self._cell_size_factor = float(cell_size_factor)
        if face_diagonals is not None and not isinstance(face_diagonals, bool | np.bool_):
            raise InputError("argument", "face_diagonals", f"{face_diagonals!r} is not a bool or None",
                             "pass True, False or None (on for pscc only)")
        self._face_diagonals = (method == "pscc") if face_diagonals is None else bool(face_diagonals)
        self._lent_scratch: wp.array | None = None
        self._retired: list[Any] = []  # buffers the last growth or trim replaced, kept for a stale replay
        self._lend_pair_buffers = False
        self._vertex_count: int | None = None
        self._broad_mode: str | None = None
        self._last_ccd_thickness: tuple[float, float] | None = None
        self.topology: MeshTopology | None = None
        self.front: NormalConeFront | None = None
        self.bvh: MaterialBvh | None = None

    def _setup(self, vertex_count: int, positions: np.ndarray) -> None:
        """Validate the topology against the first positions and allocate device buffers."""
        needed = int(self._faces_np.max()) + 1 if self._faces_np.size else 0
        if vertex_count < needed:
            # validate_mesh would blame the faces; the positions are what is short.
            raise InputError("argument", "positions",
                             f"shape {positions.shape} has {vertex_count} rows, but the faces use vertex ids up to "
                             f"{needed - 1}, so at least {needed} rows are needed, shape ({needed}, 3)",
                             "pass one (x, y, z) row per mesh vertex, in the vertex order the faces index")
        mesh = validate_mesh(positions, self._faces_np, object_ids=self._object_ids_np, rest=self._rest)
        self._vertex_count = vertex_count
        self.object_ids = mesh.object_ids
        self.topology = MeshTopology.from_faces(mesh.faces, vertex_count)
        # Edge end points as two flat arrays: 1-D gathers are what the output stage does most.
        self._edge_first = np.ascontiguousarray(self.topology.edges[:, 0], dtype=np.int32)
        self._edge_second = np.ascontiguousarray(self.topology.edges[:, 1], dtype=np.int32)
        device = self.device
        self.device_topology = DeviceTopology.upload(mesh.faces, self.topology, device)
        """The mesh's faces, edges and face edges on the device, shared with the intersection check and the
        contact springs of a simulator (:class:`~pscc.collision.device_topology.DeviceTopology`)."""
        self._faces = self.device_topology.faces
        self._edges = self.device_topology.edges
        self._object_ids = wp.array(mesh.object_ids, dtype=wp.int32, device=device)
        self._positions_t0 = wp.empty(vertex_count, dtype=wp.vec3, device=device)
        self._positions_t1 = wp.empty(vertex_count, dtype=wp.vec3, device=device)
        # Positions of the previous CCD (the re-check compares against them); NaN: test every pair.
        self._previous_t0 = wp.full(vertex_count, wp.vec3(math.nan, math.nan, math.nan), dtype=wp.vec3,
                                    device=device)
        self._previous_t1 = wp.empty(vertex_count, dtype=wp.vec3, device=device)
        self.seams = SeamAdjacency(self._stitches, vertex_count, device)
        """The stitch partners of each vertex (pairs a stitch joins are left out)."""
        self.boxes = PrimitiveBoxes(self._faces, self._edges, vertex_count, device,
                                    face_diagonals=self._face_diagonals and self.method != "brute-force")
        self._feature_boxes = self.boxes.as_struct()
        self.candidates = CandidatePairs(4 * mesh.face_count, 4 * self.topology.edge_count, device)
        self.narrow = NarrowPhase(self._faces, self._edges, device)
        self.verdict = CapacityVerdict(device)
        self.narrow.mark_moved(self._previous_t0, self._previous_t0, self._previous_t1, self._previous_t1)
        self.narrow.reserve(self.candidates)
        if self.method == "brute-force":
            used = (np.diff(self.topology.vertex_face_offsets) > 0).astype(np.int32)
            self._vertex_used = wp.array(used, dtype=wp.int32, device=device)
            self.brute_force = BroadPhaseBruteForce(self.boxes, self._vertex_used, device, self.seams)
            return
        # The detector sorts its final rows, so the hash's own pair sort is not needed.
        self.spatial_hash = SpatialHash(mesh.face_count, device, self._cell_size_factor, sort_pairs=False,
                                        faces=self._faces, group_slab_test=self.method == "pscc")
        if self._lent_scratch is not None or self._lend_pair_buffers:
            self.spatial_hash.lend_scratch(self._lent_scratch, self._scratch_source())
        self.feature_pairs = FeaturePairs(mesh.faces, self.device_topology, device, self.seams)
        if self.method == "pscc":
            # Without rest coordinates, or with a 3-D rest shape that is not flat, the BVH groups faces by
            # distance along the surface, not in a 3-D shape where folded layers would share nodes
            # (pscc.collision.intrinsic.bvh_material).
            material = bvh_material(mesh.faces, mesh.rest, mesh.vertices)
            # A 3-D shape (the first positions, or a 3-D rest shape) is cut into panels at its feature edges
            # too (bvh.FEATURE_EDGE_COSINE); 2-D rest coordinates keep the pattern's panels.
            shape = mesh.vertices if mesh.rest is None else (mesh.rest if mesh.rest.shape[1] == 3 else None)
            self.bvh = MaterialBvh.build(mesh.faces, material, mesh.object_ids, self.topology, device,
                                         self._rigid_objects, self._stitches, feature_shape=shape)
            self.front = NormalConeFront(self.bvh, self._faces, device, self._shrink_interval)
            self.front.lend_scratch(self._front_scratch_source())

    def _positions(self, value: Any, name: str) -> np.ndarray:
        points = check_points(value, name, shape_tail=(3,))
        check_coordinate_range(points, name)
        if self._vertex_count is not None and points.shape[0] != self._vertex_count:
            raise InputError("argument", name,
                             f"{points.shape[0]} vertices, but this detector was set up for "
                             f"{self._vertex_count}", "pass positions of the same mesh every call")
        return points

    def _inputs(self, positions: Any, positions_end: Any, thickness: float) -> tuple[np.ndarray, Any, float]:
        x0 = self._positions(positions, "positions")
        x1 = None if positions_end is None else self._positions(positions_end, "positions_end")
        if x1 is not None and x1.shape != x0.shape:
            raise InputError("argument", "positions_end", f"shape {x1.shape} differs from positions {x0.shape}",
                             "pass end positions of the same vertices")
        h = check_thickness(thickness, "thickness")
        if self.topology is None:
            self._setup(x0.shape[0], x0)
        return x0, x1, h

    def prepare(self, positions: Any) -> None:
        """Validate the faces against ``positions`` and build every structure now, instead of on the
        first call (nothing is detected; the ``pscc`` front stays at its roots).

        Raises:
            InputError: bad positions (including coordinates outside the supported range) or faces.
        """
        self._inputs(positions, None, 0.0)

    def state_dict(self) -> dict[str, np.ndarray]:
        """The state a detector carries between calls: the ``pscc`` test front and the spatial hash's
        group slab policy (empty for other methods).

        Restoring it (:meth:`load_state_dict`) into a detector over the same mesh makes later calls
        return exactly what this one's would (the slab policy decides which triangle pairs reach the
        narrow phase, and so the order of the contacts). Call :meth:`prepare` or a detection first.
        """
        if self.front is None:
            return {}
        state = {f"front_{key}": value for key, value in self.front.state_dict().items()}
        state["hash_slab_policy"] = self.spatial_hash.slab_policy.numpy().astype(np.int32)
        return state

    def load_state_dict(self, state: dict[str, np.ndarray]) -> None:
        """Restore :meth:`state_dict` output; the detector must be prepared (:meth:`prepare`).

        Raises:
            InputError: the detector is not prepared, or the state does not fit it.
        """
        front_state = {key[len("front_"):]: value for key, value in state.items() if key.startswith("front_")}
        if self.method == "pscc" and self.front is None:
            raise InputError("checkpoint", "detector", "the detector is not prepared",
                             "call prepare(positions) before load_state_dict()")
        if self.front is not None and front_state:
            self.front.load_state_dict(front_state)
        if self.front is not None and "hash_slab_policy" in state:  # absent from older checkpoints
            policy = np.asarray(state["hash_slab_policy"]).reshape(-1)
            if policy.shape != (2,) or not -SLAB_PROBE_BACKOFF <= policy[0] <= 1 or policy[1] < 0:
                raise InputError("checkpoint", "hash_slab_policy",
                                 f"{policy.tolist()} is not [-{SLAB_PROBE_BACKOFF} to 1, calls >= 0]",
                                 "restore a checkpoint written by this version of pscc")
            self.spatial_hash.slab_policy.assign(policy.astype(np.int32))

    def broad_phase(self, positions: Any, positions_end: Any = None,
                    thickness: float = 0.0) -> dict[str, Any] | None:
        """Find candidate feature pairs from boxes over [positions, positions_end] grown by ``thickness``.

        Positions may be host arrays (copied to the device) or ``wp.array`` s of ``wp.vec3`` on the
        detector's device (used in place: :meth:`broad_phase_device`, then, outside a graph capture,
        :meth:`check_capacity`, re-running until every buffer fits; nothing else is read back and
        ``None`` is returned instead of the stats, see :meth:`broad_phase_stats`).

        The candidates stay in the detector, so one broad phase can serve several narrow phases
        (the paper's Figure 8b): the CCD of a step (:meth:`narrow_phase` with both positions and
        thickness 0) and, once penetrations are resolved, the DCD proximity query at the step's end
        (:meth:`narrow_phase` with the end positions and the same ``thickness``). Every pair whose
        swept boxes come within ``thickness`` is a candidate, so both narrow phases see every
        pair they could report. For ``pscc`` the test front is updated over the whole step.

        Returns:
            Broad-phase stats: ``bv_tests``, ``triangle_pairs`` (the triangle pairs the broad phase
            outputs: all pairs for brute force, the hash's pairs otherwise), ``self_triangle_pairs``,
            ``inter_triangle_pairs``, ``kept_triangle_pairs`` (hashed methods: those that give a
            feature pair whose boxes overlap and that no supporting plane separates),
            ``front_size``, ``candidate_pairs`` and ``seconds``.

        Raises:
            InputError: bad positions or thickness, including coordinates or a thickness outside
                the supported range (see the class docstring).
        """
        if isinstance(positions, wp.array):
            self._prepare_from(positions)
            while True:
                self.broad_phase_device(positions, positions_end, thickness)
                if self.device.is_capturing or self.check_capacity():
                    break
            return None
        x0, x1, h = self._inputs(positions, positions_end, thickness)
        return self._broad(x0, x1, h)

    def _prepare_from(self, positions: wp.array) -> None:
        """Build the structures from the first device positions (one host copy, outside any capture)."""
        if self.topology is None:
            if self.device.is_capturing:
                raise InputError("argument", "detector", "is not prepared and a graph is being recorded",
                                 "call prepare(positions) or run one call before recording")
            self.prepare(positions.numpy())

    def _broad(self, x0: np.ndarray, x1: np.ndarray | None, h: float) -> dict[str, Any]:
        """Broad phase on validated float32 host positions: upload, the device path, then the
        capacity check (re-run while a buffer had to grow) and the stats (see :meth:`broad_phase`)."""
        self._positions_t0.assign(x0)
        positions_t1 = None
        if x1 is not None:
            self._positions_t1.assign(x1)
            positions_t1 = self._positions_t1
        while True:
            seconds: dict[str, float] = {}
            self._broad_device(self._positions_t0, positions_t1, h, seconds)
            mark = time.perf_counter()
            fits = self.check_capacity()
            seconds["capacity_check"] = time.perf_counter() - mark
            if fits:
                break
        stats = self.broad_phase_stats()
        stats["seconds"] = seconds
        self._broad_stats = stats
        self._last_ccd_thickness = None  # the candidates changed: no result to reuse
        return stats

    # ------------------------------------------------------------------ device path

    def _device_positions(self, value: Any, name: str) -> wp.array:
        """A device position array accepted as is (shape, dtype and device checked on the host only)."""
        if self.topology is None:
            raise InputError("argument", "detector", "is not prepared",
                             "call prepare(positions) once before the device-array methods")
        n = self._vertex_count
        if not isinstance(value, wp.array) or value.dtype != wp.vec3 or value.ndim != 1 or value.shape[0] != n:
            described = (f"a {value.shape} array of {wp.types.type_repr(value.dtype)}" if isinstance(value, wp.array)
                         else type(value).__name__)
            raise InputError("argument", name, f"got {described}", f"pass a ({n},) wp.array of vec3")
        if value.device != self.device:
            raise InputError("argument", name, f"array is on {value.device}, the detector on {self.device}",
                             f"copy it to {self.device} first")
        if not value.is_contiguous:
            raise InputError("argument", name, "array is not contiguous", "pass a contiguous array")
        return value

    def broad_phase_device(self, positions_t0: wp.array, positions_t1: wp.array | None = None,
                           thickness: float = 0.0) -> None:
        """The broad phase of :meth:`broad_phase` on device arrays; the candidates stay on the device.

        The detector must be prepared (:meth:`prepare`). Positions are not range-checked here (that
        would be a host read): the caller keeps them finite and within
        :data:`pscc.tolerances.MAX_COORDINATE`. Buffers that are too small keep counting on the
        device; :meth:`check_capacity` (a sync point) grows them and says whether to run again.

        Args:
            positions_t0: (vertex_count,) ``wp.vec3`` on the detector's device (start of the step).
            positions_t1: end of the step (CCD), or ``None`` (DCD).
            thickness: distance the boxes are grown by, in [0, MAX_THICKNESS].

        Raises:
            InputError: the detector is not prepared, or arrays of the wrong shape, dtype or device.

        Allocates: no. Capture-safe: yes (after a call that :meth:`check_capacity` accepted).
        """
        self._broad_device(positions_t0, positions_t1, thickness, None)

    def _broad_device(self, positions_t0: wp.array, positions_t1: wp.array | None, thickness: float,
                      seconds: dict[str, float] | None) -> None:
        """:meth:`broad_phase_device`; with a ``seconds`` dict, synchronizes after every stage and adds
        its time there (the host path's per-stage timing)."""
        x0 = self._device_positions(positions_t0, "positions_t0")
        x1 = None if positions_t1 is None else self._device_positions(positions_t1, "positions_t1")
        h = check_thickness(thickness, "thickness")
        mark = [time.perf_counter()]

        def lap(stage: str) -> None:
            if seconds is not None:
                wp.synchronize_device(self.device)
                now = time.perf_counter()
                seconds[stage] = seconds.get(stage, 0.0) + now - mark[0]
                mark[0] = now

        self.boxes.compute(x0, x1 if x1 is not None else x0, h)
        self.candidates.reset()
        lap("boxes")
        if self.method == "brute-force":
            self.brute_force.find_pairs(self.candidates)
            lap("broad_phase")
        else:
            node_id = None
            if self.method == "pscc":
                node_id = self.front.update(x0, x1)
                lap("front")
            self.spatial_hash.find_pairs_device(
                self.boxes.face_lower, self.boxes.face_upper, node_id,
                positions_t0=x0, positions_t1=x1, half_distance=0.5 * h,
                node_id_bound=self.bvh.node_count if node_id is not None else None,
                face_order=self.bvh.arrays.face_order if node_id is not None else None,
                # Front nodes are BVH nodes: each covers a contiguous range of the BVH's leaf order.
                order_is_node_contiguous=node_id is not None,
                face_diagonal_lower=self.boxes.face_diagonal_lower if self.boxes.has_face_diagonals else None,
                face_diagonal_upper=self.boxes.face_diagonal_upper if self.boxes.has_face_diagonals else None,
                certify_shared=node_id is not None)
            lap("spatial_hash")
            self.feature_pairs.extract_device(self.spatial_hash.pairs, self.spatial_hash.counts, self.candidates,
                                              x0, x1, h, self._object_ids, self._feature_boxes)
            lap("feature_pairs")
        self.verdict.judge(None if self.method == "brute-force" else self.spatial_hash, self.candidates)
        # New candidates: the next CCD re-check must test every pair (NaN differs from every position).
        self._previous_t0.fill_(wp.vec3(math.nan, math.nan, math.nan))
        self._broad_mode = "ccd" if x1 is not None else "dcd"
        self._broad_thickness = h
        self._last_ccd_thickness = None

    def check_capacity(self) -> bool:
        """Sync point: read the device counters of the last device call, grow what overflowed.

        Returns:
            True when every buffer held its data; False when one grew, and the broad phase (and the
            narrow phases after it) must run again; a graph recorded before then holds the released
            buffers and must be recorded again (:class:`pscc.collision.recorded.RecordedDetection`).

        Raises:
            InputError: a deferred input problem found on the device (boxes with NaN/Inf).
            CapacityError: more pairs than int32 buffers can hold.
            StaleGraphError: the last call was a graph recorded before a growth or a trim replaced the
                buffers it writes (its rows are not in this detector's buffers): record it again.

        Reads one device flag when the call fits (:mod:`pscc.collision.capacity_verdict`: the counters
        were compared on the device, and the stats read them only when asked); the counters otherwise.
        The buffers a growth or trim replaces are kept until a call on the new ones fits, so a stale graph
        replayed right after by mistake writes into them, not into released memory, before this check raises.

        Allocates: when a buffer grows. Capture-safe: no.
        """
        if self.verdict.fits():
            self._retired = []  # a call of this generation ran: the caller has moved to the new buffers
            if self.method != "brute-force":
                self.spatial_hash.accept_unread()
            self.candidates.accept_unread()
            self.narrow.reserve(self.candidates)
            return True
        if self.verdict.stale():
            raise StaleGraphError(
                f"replayed a graph recorded with buffers of generation {int(self.verdict.host_verdict.numpy()[1])}; "
                f"growths and trims have replaced them since (generation {self.verdict.generation}), so its rows are "
                "not in the detector's buffers; record the call again after every check_capacity() that returns "
                "False, or replay through pscc.collision.recorded.RecordedDetection, which does")
        held = self._held_buffers()
        fits = True
        if self.method != "brute-force" and not self.spatial_hash.check_capacity():
            fits = False
        if not self.candidates.fits():
            fits = False
        self.narrow.reserve(self.candidates)
        if not fits:
            self._retire(held)
        return fits

    def _held_buffers(self) -> list[Any]:
        """Every device array (and struct of arrays) the detector's growable parts hold now."""
        parts = [self.candidates, self.narrow] + ([] if self.method == "brute-force" else [self.spatial_hash])
        return held_arrays(parts)

    def _retire(self, held: list[Any]) -> None:
        """Buffers were replaced: keep the ones held before (``held``) alive until a call on the new ones fits,
        and start a new generation of the capacity verdict, which marks the graphs recorded before as stale."""
        self._retired = held
        self.verdict.advance()

    def fit_buffers(self) -> bool:
        """Shrink the spatial hash's entry, group and slab tables to what the last call used, with room to
        spare (:func:`~pscc.collision.spatial_hash_settings.fitted_capacities`), for a caller about to record
        the call into a graph: a replay sorts, pads and scans these tables whole, and a detector starts
        with 4 entry slots and 1 group slot per face whatever the mesh needs. The work rows and the pair
        buffer keep their size: their use swings from call to call with the same positions (a call that
        probes the group slab test doubles the rows of `cloth_rollers f3`). Call it after
        a call that :meth:`check_capacity` accepted; it reads that call's counters (a sync point).

        Returns:
            True when a table shrank: run the call again before recording it (it grows back, through
            :meth:`check_capacity`, if the next positions need more). A graph recorded before must be
            recorded again. :class:`pscc.collision.recorded.RecordedDetection` does both.

        Allocates: when a table shrinks. Capture-safe: no.
        """
        if self.method == "brute-force":
            return False
        counters = self.spatial_hash.overflow_counters()[:5]
        copies = {id(array): array.numpy() for array, _, _ in counters}  # two arrays: one read each
        used = {k: int(copies[id(array)][index]) for k, (array, index, _) in enumerate(counters)}
        capacities = {k: c for k, c in self.spatial_hash.capacities().items() if k in FITTED_TABLES}
        targets = fitted_capacities(capacities, used)
        if targets:
            held = self._held_buffers()
            self.spatial_hash.trim(targets)
            self._retire(held)
        return bool(targets)

    def front_count(self) -> wp.array | None:
        """The test front's size as a (1,) int32 device array (``pscc`` only, else ``None``)."""
        return self.front.front_count if self.front is not None else None

    def overflow_counters(self) -> list[tuple[wp.array, int, int]]:
        """``(device counter, index, capacity)`` triples of the broad phase's internal buffers: a
        counter above its capacity means the last device call overflowed (the candidate buffers are
        checked separately, through :attr:`candidates`). Capacities change only in
        :meth:`check_capacity`."""
        if self.method == "brute-force":
            return []
        return self.spatial_hash.overflow_counters()

    def broad_phase_stats(self) -> dict[str, Any]:
        """Stats of the last broad phase (keys of :meth:`broad_phase`'s result but ``seconds``).

        A sync point (reads device counters); valid after :meth:`check_capacity` accepted the call.
        Allocates: yes (host copies). Capture-safe: no.
        """
        stats: dict[str, Any] = {"front_size": 0}
        m = self._faces_np.shape[0]
        if self.method == "brute-force":
            # Faces per distinct object id (ids need not be contiguous: no table of max id + 1 rows).
            _, sizes = np.unique(self.object_ids, return_counts=True)
            sizes = sizes.astype(np.int64)
            self_pairs = int((sizes * (sizes - 1) // 2).sum())
            stats.update(bv_tests=self.brute_force.bounding_volume_tests(self._vertex_count, m,
                                                                         self.topology.edge_count),
                         triangle_pairs=m * (m - 1) // 2, self_triangle_pairs=self_pairs,
                         inter_triangle_pairs=m * (m - 1) // 2 - self_pairs)
        else:
            if self.method == "pscc":
                front_stats = dict(self.front.stats)
                stats["front_size"] = int(front_stats["front_size"])
                stats["front"] = front_stats
            hash_stats = self.spatial_hash.stats
            kept, _, self_pairs = (int(v) for v in self.feature_pairs.pair_stats.numpy()[:3])
            box_pairs = int(hash_stats.triangle_pairs)
            stats.update(bv_tests=int(hash_stats.bv_tests), triangle_pairs=box_pairs,
                         self_triangle_pairs=self_pairs, inter_triangle_pairs=box_pairs - self_pairs,
                         kept_triangle_pairs=kept,
                         grid={"cell_size": float(hash_stats.cell_size), "cells": int(hash_stats.cells),
                               "groups": int(hash_stats.groups), "entries": int(hash_stats.entries),
                               "face_tests": int(hash_stats.face_tests), "slab_tests": int(hash_stats.slab_tests),
                               "mean_cells_per_face": float(hash_stats.mean_cells_per_face),
                               "wide_faces": int(hash_stats.wide_faces), "wide_tests": int(hash_stats.wide_tests),
                               "long_faces": int(hash_stats.long_faces)})
        stats["candidate_pairs"] = self.candidates.vertex_face_count + self.candidates.edge_edge_count
        return stats

    def narrow_phase_device(self, positions_t0: wp.array, positions_t1: wp.array | None = None,
                            thickness: float = 0.0, *, recheck: bool = False,
                            defer_dcd: bool = False, inside_share: float = 0.0) -> DeviceContacts:
        """The narrow phase of :meth:`narrow_phase` on device arrays; the result stays on the device.

        Tests the candidates of the last broad phase (device or host path). With ``recheck`` (CCD),
        only candidates with a vertex whose start or end position changed since the previous CCD of
        this broad phase are tested again (the first CCD after a broad phase tests every pair). The
        caller keeps the thickness at most the broad phase's, and CCD after a CCD broad phase.

        With ``defer_dcd`` (DCD only), the test itself is left to the caller's kernel, which writes the
        times of impact and hit counts (:meth:`NarrowPhase.run_device`; the proximity springs do, to find
        each pair's closest points once).

        ``inside_share`` (CCD only): 0, or s in (0, 1): a pair found at t = 0 (within ``thickness``, or
        too near it for the rounding bound) is a contact only if it comes within s times the smaller
        of its start distance and ``thickness`` (:class:`pscc.collision.narrow_phase.CcdDistance`). A
        re-check keeps the same value.

        Returns:
            The :class:`DeviceContacts` view of the candidate rows, their times of impact and
            ``hit_counts`` (all on the device, valid until the next call).

        Raises:
            InputError: the detector is not prepared, no broad phase has run, or bad arrays.

        Allocates: no. Capture-safe: yes.
        """
        if self._broad_mode is None:
            raise InputError("argument", "narrow_phase_device", "no broad phase has run", "call broad_phase() first")
        x0 = self._device_positions(positions_t0, "positions_t0")
        x1 = None if positions_t1 is None else self._device_positions(positions_t1, "positions_t1")
        h = check_thickness(thickness, "thickness")
        if not 0.0 <= float(inside_share) < 1.0:
            raise InputError("argument", "inside_share", f"{inside_share!r} is not in [0, 1)",
                             "pass 0 (a pair inside the thickness is a contact at t = 0) or a share such as 0.5")
        if x1 is not None and self._broad_mode == "dcd":
            raise InputError("argument", "positions_t1", "the last broad phase was discrete (no end positions)",
                             "run a broad phase with end positions before a CCD narrow phase")
        if h > self._broad_thickness:
            raise InputError("argument", "thickness", f"{h:g} exceeds the broad phase's thickness "
                             f"{self._broad_thickness:g}", "run the broad phase with at least this thickness")
        moved = None
        if x1 is not None and recheck:
            moved = self.narrow.mark_moved(self._previous_t0, x0, self._previous_t1, x1)
        self.narrow.run_device(self.candidates, x0, x1 if x1 is not None else x0, h, moved=moved,
                               defer_dcd=defer_dcd and x1 is None, inside_share=inside_share if x1 is not None else 0.0)
        if x1 is not None:
            wp.copy(self._previous_t0, x0)
            wp.copy(self._previous_t1, x1)
        else:
            # The DCD replaced the times of impact: a later CCD re-check must test every pair.
            self._previous_t0.fill_(wp.vec3(math.nan, math.nan, math.nan))
        return self.narrow.contacts(self.candidates, continuous=x1 is not None, thickness=h)

    def narrow_phase(self, positions: Any, positions_end: Any = None, thickness: float = 0.0,
                     recheck: bool = False, inside_share: float = 0.0) -> CollisionResult | DeviceContacts:
        """Test the candidates of the last :meth:`broad_phase` (CCD when ``positions_end`` is given).

        With ``wp.array`` positions on the detector's device, this is :meth:`narrow_phase_device`: the
        result stays on the device (:class:`DeviceContacts`; :meth:`collect` copies it to the host).

        The caller is responsible for the candidates covering these positions: boxes of the
        broad phase must contain the motion tested here (the Figure 8b pipeline guarantees it: CCD
        over the same step, then DCD at its end positions).

        ``recheck`` (CCD only; the penetration-response loop, where a response changes a few end
        positions between CCD rounds): when the previous narrow phase was a CCD with this thickness
        on the same candidates, only the candidates with a vertex whose start or end position
        changed since (compared on the device, coordinate by coordinate) are tested again; the others keep their
        previous result, which is exact because their trajectories are unchanged. Otherwise
        everything is tested.

        ``inside_share`` (CCD only): 0, or s in (0, 1): a pair found at t = 0 is a contact only if it
        comes within s times its start distance (see :meth:`narrow_phase_device`).

        Raises:
            InputError: no broad phase has run, CCD after a discrete broad phase, a thickness
                larger than the broad phase's (its candidates would not cover the query), or
                positions or a thickness outside the supported range (see the class docstring).
        """
        if isinstance(positions, wp.array):
            return self.narrow_phase_device(positions, positions_end, thickness, recheck=recheck,
                                            inside_share=inside_share)
        if self._broad_mode is None:
            raise InputError("argument", "narrow_phase", "no broad phase has run", "call broad_phase() first")
        x0, x1, h = self._inputs(positions, positions_end, thickness)
        if x1 is not None and self._broad_mode == "dcd":
            raise InputError("argument", "positions_end", "the last broad phase was discrete (no end positions)",
                             "run broad_phase(positions, positions_end, thickness) before a CCD narrow phase")
        if h > self._broad_thickness:
            raise InputError("argument", "thickness",
                             f"{h:g} exceeds the broad phase's thickness {self._broad_thickness:g}",
                             "run broad_phase() with at least the thickness the narrow phase uses")
        return self._narrow(x0, x1, h, upload=True, recheck=recheck and x1 is not None
                            and self._last_ccd_thickness == (h, inside_share), inside_share=inside_share)

    def _narrow(self, x0: np.ndarray, x1: np.ndarray | None, h: float, *, upload: bool,
                recheck: bool = False, inside_share: float = 0.0) -> CollisionResult:
        """Narrow phase on the current candidates through the device path, then the host copy;
        ``upload=False`` reuses the positions already on the device; ``recheck``: see
        :meth:`narrow_phase`."""
        mark = time.perf_counter()
        if upload:
            self._positions_t0.assign(x0)
            if x1 is not None:
                self._positions_t1.assign(x1)
        self.narrow_phase_device(self._positions_t0, self._positions_t1 if x1 is not None else None, h,
                                 recheck=recheck, inside_share=inside_share)
        self._last_ccd_thickness = (h, inside_share) if x1 is not None else None
        wp.synchronize_device(self.device)
        narrow_seconds = time.perf_counter() - mark
        mark = time.perf_counter()
        result = self._collect(ccd=x1 is not None)
        result.stats = {"narrow_phase": narrow_seconds, "output": time.perf_counter() - mark}
        return result

    def detect(self, positions: Any, positions_end: Any = None,
               thickness: float = 0.0) -> CollisionResult | DeviceContacts:
        """Find the colliding vertex-face and edge-edge pairs of one step.

        Host arrays in, a :class:`CollisionResult` out. ``wp.array`` positions (``wp.vec3`` on the
        detector's device) are used in place and the result stays on the device: a
        :class:`DeviceContacts` whose rows are the candidates with a time of impact <= 1 (unsorted;
        :meth:`collect` gives the sorted host rows). Outside a graph capture the call then reads the
        buffer counters once (:meth:`check_capacity`) and runs again if a buffer had to grow, so no pair
        is dropped; inside a capture nothing is read, and an overflow is left in the counters for the
        caller's :meth:`check_capacity` after the replay. The first such call builds the structures
        from a host copy of the positions (or call :meth:`prepare` first).

        Args:
            positions: (vertex_count, 3) positions at the start of the step.
            positions_end: optional (vertex_count, 3) positions at the end of the step (CCD).
            thickness: proximity distance in [0, :data:`pscc.tolerances.MAX_THICKNESS`], in the units
                of the positions.

        Returns:
            A :class:`CollisionResult`. ``stats`` holds, for every method: ``bv_tests``,
            ``triangle_pairs``, ``self_triangle_pairs``, ``inter_triangle_pairs``, ``front_size``,
            ``candidate_pairs``, ``vertex_face_pairs``, ``edge_edge_pairs``, ``seconds`` (per stage
            and ``total``) and ``device_bytes`` (per structure and ``total``).

        Raises:
            InputError: bad positions or thickness, including coordinates or a thickness outside
                the supported range (see the class docstring).
        """
        if isinstance(positions, wp.array):
            self._prepare_from(positions)
            while True:
                self.broad_phase_device(positions, positions_end, thickness)
                contacts = self.narrow_phase_device(positions, positions_end, thickness)
                if self.device.is_capturing or self.check_capacity():
                    return contacts
        started = time.perf_counter()
        x0, x1, h = self._inputs(positions, positions_end, thickness)
        setup = time.perf_counter() - started
        broad = self._broad(x0, x1, h)
        result = self._narrow(x0, x1, h, upload=False)
        seconds = {"setup": setup, **broad["seconds"], "narrow_phase": result.stats["narrow_phase"],
                   "output": result.stats["output"]}
        seconds["total"] = time.perf_counter() - started
        result.stats = {
            "method": self.method,
            "mode": "ccd" if x1 is not None else "dcd",
            "thickness": h,
            "vertex_count": int(x0.shape[0]),
            "face_count": int(self._faces_np.shape[0]),
            "edge_count": self.topology.edge_count,
            **{k: v for k, v in broad.items() if k != "seconds"},
            "vertex_face_pairs": int(result.vertex_face.shape[0]),
            "edge_edge_pairs": int(result.edge_edge.shape[0]),
            "seconds": seconds,
            "device_bytes": self.device_bytes(),
        }
        return result

    def lend_scratch(self, buffer: wp.array | None, *, pair_buffers: bool = False) -> None:
        """Lend the spatial hash memory for its per-call tables (:meth:`SpatialHash.lend_scratch`, whose
        contract the lender keeps), and the normal cone front for its own
        (:meth:`~pscc.collision.front.NormalConeFront.lend_scratch`). Methods without them ignore it.

        Args:
            buffer: a buffer of the caller's, dead while this detector runs (``None``: none).
            pair_buffers: also lend the hash this detector's candidate pairs and times of impact. Only
                for a caller that reads the results of a narrow phase (:class:`DeviceContacts`) before
                the next call of this detector *or of anything sharing its hash*, e.g. an
                :class:`~pscc.collision.intersection.IntersectionCheck`: the hash writes over them.

        Allocates: the hash's and the front's tables again. Capture-safe: no.
        """
        self._lent_scratch = buffer
        self._lend_pair_buffers = bool(pair_buffers)
        if getattr(self, "spatial_hash", None) is not None:
            self.spatial_hash.lend_scratch(buffer, self._scratch_source())
        if getattr(self, "front", None) is not None:
            self.front.lend_scratch(self._front_scratch_source())

    def _front_scratch_source(self) -> Callable[[], list[wp.array]] | None:
        """Everything lent to this detector, for the normal cone front's per-call tables: the front is
        updated at the start of the broad phase, before the hash (NormalConeFront.lend_scratch)."""
        pair_buffers = self._scratch_source()
        if self._lent_scratch is None and pair_buffers is None:
            return None
        lent = [] if self._lent_scratch is None else [self._lent_scratch]
        return lambda: lent + (pair_buffers() if pair_buffers is not None else [])

    def _scratch_source(self) -> Callable[[], list[wp.array]] | None:
        """The candidate and time-of-impact buffers as they are now (they are replaced when they grow or
        shrink), for the hash to place tables in; ``None`` unless :meth:`lend_scratch` asked for it."""
        if not self._lend_pair_buffers:
            return None
        return lambda: [self.candidates.storage, self.narrow.toi_storage]

    def refresh_loans(self) -> None:
        """Place the hash's and the front's tables again after the candidate buffers were resized
        (:meth:`SpatialHash.refresh_loans`, :meth:`NormalConeFront.refresh_loans`), so that a graph
        recorded next allocates and records nothing. Allocates: only then. Capture-safe: no."""
        if getattr(self, "spatial_hash", None) is not None:
            self.spatial_hash.refresh_loans()
        if getattr(self, "front", None) is not None:
            self.front.refresh_loans()

    def set_joined(self, rows: np.ndarray | None) -> None:
        """Replace the vertex pairs left out of the broad phase (the stitches given at construction, and e.g.
        a simulator's crossing pairs while they come apart): ``rows`` as for ``stitches``. The detector
        must be prepared. Allocates: yes. Capture-safe: no (graphs that bound the old arrays must be
        recorded again)."""
        self.seams.rebuild(rows)
        if self.method != "brute-force":
            self.feature_pairs.topology.seams = self.seams.args

    def device_bytes(self) -> dict[str, int]:
        """Device memory per structure, in bytes, and their ``total``."""
        sizes = {
            "mesh": sum(a.capacity for a in self.device_topology.arrays) + self._object_ids.capacity
            + self._positions_t0.capacity + self._positions_t1.capacity + self.seams.device_bytes,
            "boxes": self.boxes.device_bytes,
            "candidates": self.candidates.device_bytes + self.verdict.device_bytes,
            "narrow_phase": self.narrow.device_bytes + self._previous_t0.capacity + self._previous_t1.capacity,
        }
        if self.method != "brute-force":
            sizes["spatial_hash"] = int(sum(self.spatial_hash.device_bytes.values()))
            sizes["feature_pairs"] = self.feature_pairs.device_bytes
        if self.method == "pscc":
            sizes["bvh"] = self.bvh.device_bytes
            sizes["front"] = self.front.device_bytes
        sizes["total"] = sum(sizes.values())
        return sizes

    def collect(self, contacts: DeviceContacts) -> CollisionResult:
        """Copy a device result (:meth:`detect` / :meth:`narrow_phase` on ``wp.array`` s) to the host as
        a :class:`CollisionResult` (hits only, rows sorted). Valid until the next call of this detector.

        A sync point (reads the counters and the rows). Allocates: yes (host arrays). Capture-safe: no.
        """
        return self._collect(ccd=contacts.continuous)

    def _collect(self, *, ccd: bool) -> CollisionResult:
        """Copy the reported pairs to the host as sorted rows (a sync point)."""
        counts = self.candidates.counts.numpy()
        vf_count = max(0, min(int(counts[0]), self.candidates.capacity_vf))
        ee_count = max(0, min(int(counts[1]), self.candidates.capacity_ee))
        vf_pairs = self.candidates.vertex_face[:vf_count].numpy().reshape(-1, 2)
        ee_pairs = self.candidates.edge_edge[:ee_count].numpy().reshape(-1, 2)
        vf_toi = self.narrow.vertex_face_toi[:vf_count].numpy()
        ee_toi = self.narrow.edge_edge_toi[:ee_count].numpy()
        # One int64 key per row gives the lexicographic order: (vertex, face), and (edge a, edge b)
        # with edges sorted lexicographically, so edge-id order is vertex-tuple order. Every feature
        # pair is a candidate once, so the keys are unique and any sort gives the same order.
        m = self._faces_np.shape[0]
        edge_count = self.topology.edge_count
        vf_keep = np.flatnonzero(vf_toi <= 1.0)
        ee_keep = np.flatnonzero(ee_toi <= 1.0)
        vf_key = vf_pairs[vf_keep, 0].astype(np.int64) * m + vf_pairs[vf_keep, 1]
        ee_key = ee_pairs[ee_keep, 0].astype(np.int64) * edge_count + ee_pairs[ee_keep, 1]
        if ccd:
            vf_order = np.argsort(vf_key)
            ee_order = np.argsort(ee_key)
            vf_key = vf_key[vf_order]
            ee_key = ee_key[ee_order]
            vf_toi = vf_toi[vf_keep[vf_order]]
            ee_toi = ee_toi[ee_keep[ee_order]]
        else:
            vf_key.sort()
            ee_key.sort()
        vertex_face = np.empty((vf_key.shape[0], 2), dtype=np.int32)
        vertex_face[:, 0] = vf_key // m
        vertex_face[:, 1] = vf_key % m
        edge_a = ee_key // edge_count
        edge_b = ee_key - edge_a * edge_count
        edge_edge = np.empty((ee_key.shape[0], 4), dtype=np.int32)
        edge_edge[:, 0] = self._edge_first[edge_a]
        edge_edge[:, 1] = self._edge_second[edge_a]
        edge_edge[:, 2] = self._edge_first[edge_b]
        edge_edge[:, 3] = self._edge_second[edge_b]
        return CollisionResult(
            vertex_face=vertex_face,
            edge_edge=edge_edge,
            vertex_face_toi=vf_toi.astype(np.float32) if ccd else None,
            edge_edge_toi=ee_toi.astype(np.float32) if ccd else None,
        )
