"""From candidate triangle pairs to vertex-face and edge-edge feature pairs, each emitted once.

Every vertex and every edge is *owned* by exactly one of its incident faces (the one with the lowest
id). For a candidate triangle pair (A, B) the features tested are: vertices owned by A against face
B, vertices owned by B against face A, and edges owned by A against edges owned by B; pairs that
share a vertex are skipped. Each feature pair then comes from exactly one triangle pair (its
owners), and none is lost: a feature lies inside its owner's box, so the owner's box overlaps
whatever the feature's box overlaps.

========================  ===================  ==============================================
buffer                    shape, dtype         meaning
========================  ===================  ==============================================
owned_vertex_bits         (face_count,) int32  bit k set: the face owns its vertex k
owned_edge_bits           (face_count,) int32  bit k set: the face owns its edge k (face_edges)
========================  ===================  ==============================================

Each triangle pair (a row of a row kernel, :mod:`pscc._lanes`) first meets the supporting-plane test
of :mod:`pscc.collision.pair_filter`, per vertex (discrete detection with at least two triangle pairs per
face: against the per-face plane slabs of :mod:`pscc.collision.face_planes`, computed once per call;
otherwise:
:func:`~pscc.collision.pair_filter.plane_sides`): the
pair is dropped when one face's plane separates the other face; otherwise a vertex certified beyond the
other face's plane, and an edge whose two ends are beyond it on one side, are left out of its feature
pairs (none of them can come within the thickness). Of the rest, the feature pairs whose own boxes
overlap are appended to the candidate buffers with one atomic add per kind. The pass is launched for
the capacity of the triangle-pair buffer and
reads the number of valid pairs from a device counter (:meth:`FeaturePairs.extract_device`), so it
reads nothing back and can be captured. A buffer that overflows keeps counting on the device;
:meth:`CandidatePairs.fits` grows it and the pass runs again (:meth:`FeaturePairs.extract` does both).
The order of the candidates follows the atomic appends (fixed on the CPU, where one thread takes the
pairs in order); the detector sorts its results, so they do not depend on it.

========================  ===================  ==============================================
pair_stats                (3,) int32           [kept pairs, kept within one object, all pairs
                                               within one object] of the last pass
========================  ===================  ==============================================
"""

from __future__ import annotations

import numpy as np
import warp as wp

from pscc import tolerances
from pscc._lanes import row_lanes
from pscc.collision.boxes import PrimitiveBoxArgs
from pscc.collision.candidates import CandidatePairs
from pscc.collision.device_topology import DeviceTopology
from pscc.collision.face_planes import FacePlane, FacePlanes, slab_sides
from pscc.collision.pair_filter import plane_sides, sides_agree
from pscc.collision.seams import SeamAdjacency, SeamArgs, stitched, stitched_to_face
from pscc.geometry.aabb import boxes_overlap
from pscc.geometry.ccd import CcdParameters, ccd_parameters
from pscc.mesh.topology import MeshTopology

wp.set_module_options({"enable_backward": False})


def ownership_bits(faces: np.ndarray, topology: MeshTopology) -> tuple[np.ndarray, np.ndarray]:
    """Per-face bit masks of owned vertices and owned edges (owner = lowest incident face id)."""
    face_count = faces.shape[0]
    vertex_owner = np.full(topology.vertex_count, -1, dtype=np.int64)
    starts = topology.vertex_face_offsets[:-1]
    has_faces = np.diff(topology.vertex_face_offsets) > 0
    vertex_owner[has_faces] = topology.vertex_face_indices[starts[has_faces]]
    edge_owner = topology.edge_face_indices[topology.edge_face_offsets[:-1]].astype(np.int64)
    ids = np.arange(face_count)[:, None]
    vertex_bits = ((vertex_owner[faces] == ids) * (1 << np.arange(3))).sum(axis=1)
    edge_bits = ((edge_owner[topology.face_edges] == ids) * (1 << np.arange(3))).sum(axis=1)
    return vertex_bits.astype(np.int32), edge_bits.astype(np.int32)


@wp.func
def _shares_vertex(f: wp.vec3i, v: int) -> bool:
    return f[0] == v or f[1] == v or f[2] == v


@wp.func
def _owned_vertex_mask(tri: wp.vec3i, target: wp.vec3i, candidates: int, other_lower: wp.vec3, other_upper: wp.vec3,
                       vertex_lower: wp.array(dtype=wp.vec3), vertex_upper: wp.array(dtype=wp.vec3),
                       seams: SeamArgs, has_seams: bool) -> int:
    """Bit k: bit k of ``candidates`` is set (the face owns its vertex k, and the vertex is not certified
    beyond the other face's plane), vertex k of face ``tri`` is not a vertex of face ``target`` nor
    stitched to one, and its box overlaps the other face's box [``other_lower``, ``other_upper``]."""
    mask = int(0)
    for k in range(3):
        if (candidates >> k) & 1:
            v = tri[k]
            # Nested ifs: Warp evaluates both operands of ``and``.
            if not _shares_vertex(target, v):
                keep = True
                if has_seams:
                    keep = not stitched_to_face(seams, v, target)
                if keep:
                    if boxes_overlap(vertex_lower[v], vertex_upper[v], other_lower, other_upper):
                        mask = mask | (1 << k)
    return mask


@wp.func
def _inside_bits(sides: wp.vec3) -> int:
    """Bit k: vertex k is not certified beyond the other face's plane (its side is 0)."""
    return int(sides[0] == 0.0) | (int(sides[1] == 0.0) << 1) | (int(sides[2] == 0.0) << 2)


@wp.func
def _beyond_edge_bits(sides: wp.vec3) -> int:
    """Bit k: both ends of the face's edge k, (v_k, v_k+1) (``MeshTopology.face_edges``), are beyond the
    other face's plane on one side."""
    b0 = int(sides[0] != 0.0 and sides[0] == sides[1])
    b1 = int(sides[1] != 0.0 and sides[1] == sides[2])
    b2 = int(sides[2] != 0.0 and sides[2] == sides[0])
    return b0 | (b1 << 1) | (b2 << 2)


@wp.func
def _bit_count3(mask: int) -> int:
    return (mask & 1) + ((mask >> 1) & 1) + ((mask >> 2) & 1)


@wp.struct
class PlaneTestArgs:
    """Inputs of the supporting-plane test run before counting (see :mod:`pscc.collision.pair_filter`)."""

    positions_t0: wp.array(dtype=wp.vec3)
    positions_t1: wp.array(dtype=wp.vec3)
    object_ids: wp.array(dtype=wp.int32)
    swept: wp.int32
    thickness: wp.float32
    factor: wp.float32
    params: CcdParameters
    face_planes: wp.array(dtype=FacePlane)
    use_face_planes: wp.int32
    min_plane_pairs: wp.int64


@wp.struct
class FeatureTopology:
    """The mesh arrays :func:`_extract_features` reads (shared topology and ownership bits)."""

    faces: wp.array(dtype=wp.vec3i)
    face_edges: wp.array(dtype=wp.vec3i)
    owned_vertex_bits: wp.array(dtype=wp.int32)
    owned_edge_bits: wp.array(dtype=wp.int32)
    seams: SeamArgs


@wp.kernel
def _extract_features(
    # in:
    topology: FeatureTopology,
    triangle_pairs: wp.array(dtype=wp.vec2i),
    pair_counts: wp.array(dtype=wp.int64),
    planes: PlaneTestArgs,
    boxes: PrimitiveBoxArgs,
    lanes: int,
    # out:
    counts: wp.array(dtype=wp.int32),
    vertex_face_out: wp.array(dtype=wp.vec2i),
    edge_edge_out: wp.array(dtype=wp.vec2i),
    pair_stats: wp.array(dtype=wp.int32),
):
    """Row kernel (:mod:`pscc._lanes`) over the valid triangle pairs, the first
    ``min(pair_counts[0], slots)``. For each: unless a supporting plane separates the triangles, find
    its feature pairs that no plane separates and whose boxes overlap (as bit masks, each box loaded
    once); if there are any, append them (written only below each buffer's capacity; the counters keep
    counting) and count the pair as kept.
    ``pair_stats`` = [kept, kept within one object, all pairs within one object]."""
    # Arrays out of the struct once: on the CPU every struct member access copies the array header.
    faces = topology.faces
    face_edges = topology.face_edges
    owned_vertex_bits = topology.owned_vertex_bits
    owned_edge_bits = topology.owned_edge_bits
    seams = topology.seams
    has_seams = seams.offsets.shape[0] > 1
    face_planes = planes.face_planes
    positions = planes.positions_t0
    use_face_planes = planes.use_face_planes
    # The slabs were written only when the pair counter reached min_plane_pairs (FacePlanes.compute).
    if pair_counts[0] < planes.min_plane_pairs:
        use_face_planes = 0
    object_ids = planes.object_ids
    vertex_lower = boxes.vertex_lower
    vertex_upper = boxes.vertex_upper
    edge_lower = boxes.edge_lower
    edge_upper = boxes.edge_upper
    face_lower = boxes.face_lower
    face_upper = boxes.face_upper
    rows = int(wp.min(pair_counts[0], wp.int64(triangle_pairs.shape[0])))
    for i in range(wp.tid(), rows, lanes):
        pair = triangle_pairs[i]
        a = pair[0]
        b = pair[1]
        same_object = object_ids[a] == object_ids[b]
        if same_object:
            wp.atomic_add(pair_stats, 2, 1)
        tri_a = faces[a]
        tri_b = faces[b]
        # The supporting-plane test (pscc.collision.pair_filter), per vertex: the sides of b's vertices
        # with respect to a's plane and of a's with respect to b's.
        sides_a = wp.vec3(0.0)
        sides_b = wp.vec3(0.0)
        if use_face_planes != 0:
            plane_a = face_planes[a]
            plane_b = face_planes[b]
            sides_b = slab_sides(plane_a, plane_b, positions[tri_b[0]], positions[tri_b[1]], positions[tri_b[2]])
            sides_a = slab_sides(plane_b, plane_a, positions[tri_a[0]], positions[tri_a[1]], positions[tri_a[2]])
        else:
            sides_b = plane_sides(tri_a, tri_b, planes.positions_t0, planes.positions_t1, planes.swept,
                                  planes.thickness, planes.factor, planes.params)
            sides_a = plane_sides(tri_b, tri_a, planes.positions_t0, planes.positions_t1, planes.swept,
                                  planes.thickness, planes.factor, planes.params)
        if sides_agree(sides_b) or sides_agree(sides_a):
            continue
        # A vertex certified beyond the other face's plane cannot come within the thickness of that face.
        mask_ab = _owned_vertex_mask(tri_a, tri_b, owned_vertex_bits[a] & _inside_bits(sides_a), face_lower[b],
                                     face_upper[b], vertex_lower, vertex_upper, seams, has_seams)
        mask_ba = _owned_vertex_mask(tri_b, tri_a, owned_vertex_bits[b] & _inside_bits(sides_b), face_lower[a],
                                     face_upper[a], vertex_lower, vertex_upper, seams, has_seams)
        vf = _bit_count3(mask_ab) + _bit_count3(mask_ba)
        # Owned edges of b: ids, end points and boxes, loaded once for the 3 x 3 tests. An edge whose
        # two ends are beyond the other face's plane on one side cannot come within the thickness of
        # that face's edges (they lie in the plane). Edge k of a face joins its vertices k and k + 1
        # (``MeshTopology.face_edges``), so the ends come from the face, not from the edge table.
        bits_a = owned_edge_bits[a] & ~_beyond_edge_bits(sides_a)
        bits_b = owned_edge_bits[b] & ~_beyond_edge_bits(sides_b)
        ids_a = face_edges[a]
        ids_b = face_edges[b]
        lower_b = wp.mat33(0.0)
        upper_b = wp.mat33(0.0)
        ends_b0 = wp.vec3i(-1, -1, -1)
        ends_b1 = wp.vec3i(-1, -1, -1)
        for k in range(3):
            if (bits_b >> k) & 1:
                eb = ids_b[k]
                ends_b0[k] = tri_b[k]
                ends_b1[k] = tri_b[(k + 1) % 3]
                lower_b[k] = edge_lower[eb]
                upper_b[k] = edge_upper[eb]
        edge_mask = int(0)
        for j in range(3):
            if (bits_a >> j) & 1:
                ea = ids_a[j]
                ends_a = wp.vec2i(tri_a[j], tri_a[(j + 1) % 3])
                lower_a = edge_lower[ea]
                upper_a = edge_upper[ea]
                for k in range(3):
                    if (bits_b >> k) & 1:
                        shared = (ends_a[0] == ends_b0[k] or ends_a[0] == ends_b1[k] or ends_a[1] == ends_b0[k]
                                  or ends_a[1] == ends_b1[k])
                        if not shared and has_seams:
                            shared = (stitched(seams, ends_a[0], ends_b0[k]) or stitched(seams, ends_a[0], ends_b1[k])
                                      or stitched(seams, ends_a[1], ends_b0[k])
                                      or stitched(seams, ends_a[1], ends_b1[k]))
                        if not shared and boxes_overlap(lower_a, upper_a, lower_b[k], upper_b[k]):
                            edge_mask = edge_mask | (1 << (3 * j + k))
        ee = int(0)
        for t in range(9):
            ee += (edge_mask >> t) & 1
        if vf + ee == 0:
            continue
        wp.atomic_add(pair_stats, 0, 1)
        if same_object:
            wp.atomic_add(pair_stats, 1, 1)
        # Every row below the capacity is written, also when the buffer overflows part-way through this
        # pair's rows: readers clamp the count to the capacity and read every row below it.
        if vf > 0:
            slot = wp.atomic_add(counts, 0, vf)
            capacity = vertex_face_out.shape[0]
            for k in range(3):
                if (mask_ab >> k) & 1:
                    if slot < capacity:
                        vertex_face_out[slot] = wp.vec2i(tri_a[k], b)
                    slot += 1
            for k in range(3):
                if (mask_ba >> k) & 1:
                    if slot < capacity:
                        vertex_face_out[slot] = wp.vec2i(tri_b[k], a)
                    slot += 1
        if ee > 0:
            slot = wp.atomic_add(counts, 1, ee)
            capacity = edge_edge_out.shape[0]
            for j in range(3):
                for k in range(3):
                    if (edge_mask >> (3 * j + k)) & 1:
                        if slot < capacity:
                            ea = ids_a[j]
                            eb = ids_b[k]
                            edge_edge_out[slot] = wp.vec2i(wp.min(ea, eb), wp.max(ea, eb))
                        slot += 1


class FeaturePairs:
    """Turns candidate triangle pairs into candidate feature pairs (layout in the module docstring).

    :meth:`extract_device` is the device path (no host read, capturable); :meth:`extract` is the host
    API built on it (device path, then :meth:`CandidatePairs.fits`, re-run while a buffer grew, then
    the stats read back).

    Args:
        faces: (face_count, 3) int32 host faces.
        device_topology: those faces' topology on the device (shared with the caller, not copied).
        device: Warp device.
        seams: the stitch partners of the vertices (:mod:`pscc.collision.seams`); None: no stitches.
    """

    def __init__(self, faces: np.ndarray, device_topology: DeviceTopology, device: wp.Device,
                 seams: SeamAdjacency | None = None) -> None:
        self.device = device
        device_topology.check_same(faces, wp.get_device(device), "feature pair extraction")
        vertex_bits, edge_bits = ownership_bits(faces, device_topology.topology)
        self.owned_vertex_bits = wp.array(vertex_bits, dtype=wp.int32, device=device)
        self.owned_edge_bits = wp.array(edge_bits, dtype=wp.int32, device=device)
        self.face_edges = device_topology.face_edges
        self.faces = device_topology.faces
        self.topology = FeatureTopology()
        """The faces, face edges and ownership bits as the kernel's struct."""
        self.topology.faces = self.faces
        self.topology.face_edges = self.face_edges
        self.topology.owned_vertex_bits = self.owned_vertex_bits
        self.topology.owned_edge_bits = self.owned_edge_bits
        self.seams = seams if seams is not None else SeamAdjacency(None, 0, device)
        """Stitch partners: the feature pairs a stitch joins are not candidates."""
        self.topology.seams = self.seams.args
        self.pair_stats = wp.zeros(3, dtype=wp.int32, device=device)
        # The host API's pair count, handed to the device path like a broad phase's counter.
        self._host_pair_count = wp.zeros(1, dtype=wp.int64, device=device)
        self.planes = PlaneTestArgs()
        self.planes.factor = tolerances.COPLANARITY_ROUNDING_FACTOR * tolerances.FLOAT32_UNIT_ROUNDOFF
        self.planes.params = ccd_parameters()
        self.face_planes = FacePlanes(self.faces, device)
        """Per-face plane slabs of the discrete plane test (:mod:`pscc.collision.face_planes`)."""
        self.use_face_planes = True
        """Discrete detection takes the plane test from :attr:`face_planes` when the call has enough
        triangle pairs (False: always from the six vertices, :func:`~pscc.collision.pair_filter.plane_sides`,
        as continuous detection does)."""
        self.planes.face_planes = self.face_planes.planes
        self.planes.min_plane_pairs = self.face_planes.min_pairs
        self.kept_pairs = 0
        self.kept_self_pairs = 0
        self.self_pairs = 0
        self.reruns = 0

    @property
    def device_bytes(self) -> int:
        """Bytes held on the device (ownership tables; the shared topology is the caller's)."""
        return (self.owned_vertex_bits.capacity + self.owned_edge_bits.capacity
                + self.pair_stats.capacity + self._host_pair_count.capacity + self.face_planes.device_bytes)

    def extract_device(
        self,
        triangle_pairs: wp.array,
        pair_counts: wp.array,
        candidates: CandidatePairs,
        positions_t0: wp.array,
        positions_t1: wp.array | None,
        thickness: float,
        object_ids: wp.array,
        boxes: PrimitiveBoxArgs,
    ) -> None:
        """Device path of :meth:`extract`: reset ``candidates`` and ``pair_stats``, then append the
        feature pairs of the valid triangle pairs, reading their number on the device.

        One launch of a row kernel (:mod:`pscc._lanes`) over ``triangle_pairs.shape[0]`` slots; the
        valid pairs are the first ``min(pair_counts[0], triangle_pairs.shape[0])``. Candidate buffers
        that are too small keep counting (``candidates.counts``); the owner calls
        :meth:`CandidatePairs.fits` (a sync point) and runs again when it returns False. ``pair_stats``
        holds the kept / self counters on the device.

        Args:
            triangle_pairs: (slots,) ``wp.vec2i`` candidate triangle pairs (face a, face b).
            pair_counts: int64 device array; element 0 is the number of pairs written (it may
                exceed ``slots``, e.g. a broad phase's overflowed counter).
            candidates: output buffers.
            positions_t0: (vertex_count,) ``wp.vec3`` positions (DCD) or start of the step (CCD).
            positions_t1: end of the step for CCD, else None.
            thickness: the distance the broad-phase boxes were grown by (length units).
            object_ids: (face_count,) int32 object of each face, for the self / inter pair counts.
            boxes: the primitive boxes of the same call; feature pairs whose boxes miss are skipped.

        Allocates: no. Capture-safe: yes.
        """
        planes = self.planes
        planes.positions_t0 = positions_t0
        planes.positions_t1 = positions_t1 if positions_t1 is not None else positions_t0
        planes.object_ids = object_ids
        planes.swept = 1 if positions_t1 is not None else 0
        planes.thickness = float(thickness)
        planes.use_face_planes = int(self.use_face_planes and positions_t1 is None)
        planes.min_plane_pairs = self.face_planes.min_pairs
        if planes.use_face_planes:
            self.face_planes.compute(positions_t0, thickness, pair_counts)
        candidates.reset()
        self.pair_stats.zero_()
        slots = triangle_pairs.shape[0]
        if slots == 0:
            return
        lanes = row_lanes(self.device, slots)
        wp.launch(_extract_features, dim=lanes, device=self.device,
                  inputs=[self.topology, triangle_pairs, pair_counts, planes, boxes, lanes],
                  outputs=[candidates.counts, candidates.vertex_face, candidates.edge_edge, self.pair_stats])

    def extract(
        self,
        triangle_pairs: wp.array,
        pair_count: int,
        candidates: CandidatePairs,
        positions_t0: wp.array,
        positions_t1: wp.array | None,
        thickness: float,
        object_ids: wp.array,
        boxes: PrimitiveBoxArgs,
    ) -> None:
        """Write the feature pairs of the first ``pair_count`` triangle pairs into ``candidates``,
        skipping feature pairs whose boxes miss and triangle pairs that a supporting plane separates
        (:mod:`pscc.collision.pair_filter`).

        Args:
            triangle_pairs: candidate triangle pairs from a broad phase.
            pair_count: number of valid pairs.
            candidates: output buffers (grown to the exact totals when they overflow).
            positions_t0: positions (DCD) or start of the step (CCD).
            positions_t1: end of the step for CCD, else None.
            thickness: the distance the broad-phase boxes were grown by.
            object_ids: (face_count,) object of each face, for the self / inter pair counts.
            boxes: the primitive boxes of the same call; feature pairs whose boxes miss are skipped.

        Runs :meth:`extract_device` until :meth:`CandidatePairs.fits` accepts it. Afterwards
        ``kept_pairs`` and ``kept_self_pairs`` hold the triangle pairs that gave at least one feature
        pair (boxes overlap, no separating supporting plane), all and within one object,
        ``self_pairs`` the given pairs within one object, and ``reruns`` the passes repeated after a
        buffer grew. Reads the totals to the host (a sync point).
        Allocates: only when ``candidates`` must grow. Capture-safe: no.
        """
        n = max(0, min(int(pair_count), triangle_pairs.shape[0]))
        self._host_pair_count.fill_(n)
        # Launch over the valid pairs only (the count guards the rest; Warp cannot slice to length 0).
        pairs = triangle_pairs[:n] if 0 < n < triangle_pairs.shape[0] else triangle_pairs
        self.reruns = 0
        while True:
            self.extract_device(pairs, self._host_pair_count, candidates, positions_t0, positions_t1, thickness,
                                object_ids, boxes)
            if candidates.fits():
                break
            self.reruns += 1
        stats = self.pair_stats.numpy()
        self.kept_pairs = int(stats[0])
        self.kept_self_pairs = int(stats[1])
        self.self_pairs = int(stats[2])
