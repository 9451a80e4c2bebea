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

Before counting, each triangle pair meets the supporting-plane test of
:mod:`pscc.collision.pair_filter` and is dropped when a plane separates its triangles.
Extraction is count -> exclusive scan -> fill, so the output order depends only on the order of
the triangle pairs.
"""

from __future__ import annotations

import numpy as np
import warp as wp

from pscc import tolerances
from pscc.collision.boxes import PrimitiveBoxArgs
from pscc.collision.candidates import CandidatePairs
from pscc.collision.pair_filter import triangle_pair_separated
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
def _edges_share_vertex(a: wp.vec2i, b: wp.vec2i) -> bool:
    return a[0] == b[0] or a[0] == b[1] or a[1] == b[0] or a[1] == b[1]


@wp.func
def _vertex_face_near(boxes: PrimitiveBoxArgs, v: int, f: int) -> bool:
    return boxes_overlap(boxes.vertex_lower[v], boxes.vertex_upper[v], boxes.face_lower[f], boxes.face_upper[f])


@wp.func
def _edge_edge_near(boxes: PrimitiveBoxArgs, a: int, b: int) -> bool:
    return boxes_overlap(boxes.edge_lower[a], boxes.edge_upper[a], boxes.edge_lower[b], boxes.edge_upper[b])


@wp.func
def _vertex_face_count(faces: wp.array(dtype=wp.vec3i), owned_vertex_bits: wp.array(dtype=wp.int32),
                       boxes: PrimitiveBoxArgs, owner: int, other: int) -> int:
    """Vertices owned by face ``owner`` that do not belong to face ``other``."""
    tri = faces[owner]
    target = faces[other]
    bits = owned_vertex_bits[owner]
    count = int(0)
    for k in range(3):
        if (bits >> k) & 1:
            if not _shares_vertex(target, tri[k]) and _vertex_face_near(boxes, tri[k], other):
                count += 1
    return count


@wp.func
def _vertex_face_fill(faces: wp.array(dtype=wp.vec3i), owned_vertex_bits: wp.array(dtype=wp.int32),
                      boxes: PrimitiveBoxArgs, owner: int, other: int, slot: int, out: wp.array(dtype=wp.vec2i)) -> int:
    """Write (vertex, other) for the vertices counted by :func:`_vertex_face_count`; return the count."""
    tri = faces[owner]
    target = faces[other]
    bits = owned_vertex_bits[owner]
    count = int(0)
    for k in range(3):
        if (bits >> k) & 1:
            if not _shares_vertex(target, tri[k]) and _vertex_face_near(boxes, tri[k], other):
                out[slot + count] = wp.vec2i(tri[k], other)
                count += 1
    return count


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


@wp.kernel
def _count_features(
    # in:
    faces: wp.array(dtype=wp.vec3i),
    face_edges: wp.array(dtype=wp.vec3i),
    edges: wp.array(dtype=wp.vec2i),
    owned_vertex_bits: wp.array(dtype=wp.int32),
    owned_edge_bits: wp.array(dtype=wp.int32),
    triangle_pairs: wp.array(dtype=wp.vec2i),
    planes: PlaneTestArgs,
    boxes: PrimitiveBoxArgs,
    # out:
    vertex_face_counts: wp.array(dtype=wp.int32),
    edge_edge_counts: wp.array(dtype=wp.int32),
    pair_stats: wp.array(dtype=wp.int32),
):
    """One thread per triangle pair: drop it when a supporting plane separates it, else count the
    feature pairs it emits (and the kept pairs, all and within one object, in ``pair_stats``)."""
    i = wp.tid()
    pair = triangle_pairs[i]
    a = pair[0]
    b = pair[1]
    if triangle_pair_separated(faces[a], faces[b], planes.positions_t0, planes.positions_t1, planes.swept,
                               planes.thickness, planes.factor, planes.params):
        vertex_face_counts[i] = 0
        edge_edge_counts[i] = 0
        return
    wp.atomic_add(pair_stats, 0, 1)
    if planes.object_ids[a] == planes.object_ids[b]:
        wp.atomic_add(pair_stats, 1, 1)
    vf = _vertex_face_count(faces, owned_vertex_bits, boxes, a, b)
    vf += _vertex_face_count(faces, owned_vertex_bits, boxes, b, a)
    ee = int(0)
    bits_a = owned_edge_bits[a]
    bits_b = owned_edge_bits[b]
    for j in range(3):
        if (bits_a >> j) & 1:
            for k in range(3):
                if (bits_b >> k) & 1:
                    ea = face_edges[a][j]
                    eb = face_edges[b][k]
                    if not _edges_share_vertex(edges[ea], edges[eb]) and _edge_edge_near(boxes, ea, eb):
                        ee += 1
    vertex_face_counts[i] = vf
    edge_edge_counts[i] = ee


@wp.kernel
def _fill_features(
    # in:
    faces: wp.array(dtype=wp.vec3i),
    face_edges: wp.array(dtype=wp.vec3i),
    edges: wp.array(dtype=wp.vec2i),
    owned_vertex_bits: wp.array(dtype=wp.int32),
    owned_edge_bits: wp.array(dtype=wp.int32),
    triangle_pairs: wp.array(dtype=wp.vec2i),
    boxes: PrimitiveBoxArgs,
    vertex_face_offsets: wp.array(dtype=wp.int32),
    edge_edge_offsets: wp.array(dtype=wp.int32),
    # out:
    vertex_face_out: wp.array(dtype=wp.vec2i),
    edge_edge_out: wp.array(dtype=wp.vec2i),
):
    """One thread per triangle pair: write its feature pairs at its scanned offsets.

    A pair that emits nothing (no feature pair, or separated by a supporting plane) is skipped."""
    i = wp.tid()
    if vertex_face_offsets[i + 1] == vertex_face_offsets[i] and edge_edge_offsets[i + 1] == edge_edge_offsets[i]:
        return
    pair = triangle_pairs[i]
    a = pair[0]
    b = pair[1]
    slot = vertex_face_offsets[i]
    slot += _vertex_face_fill(faces, owned_vertex_bits, boxes, a, b, slot, vertex_face_out)
    _vertex_face_fill(faces, owned_vertex_bits, boxes, b, a, slot, vertex_face_out)
    slot = edge_edge_offsets[i]
    bits_a = owned_edge_bits[a]
    bits_b = owned_edge_bits[b]
    for j in range(3):
        if (bits_a >> j) & 1:
            for k in range(3):
                if (bits_b >> k) & 1:
                    ea = face_edges[a][j]
                    eb = face_edges[b][k]
                    if not _edges_share_vertex(edges[ea], edges[eb]) and _edge_edge_near(boxes, ea, eb):
                        edge_edge_out[slot] = wp.vec2i(wp.min(ea, eb), wp.max(ea, eb))
                        slot += 1


class FeaturePairs:
    """Turns candidate triangle pairs into candidate feature pairs (layout in the module docstring).

    Args:
        faces: (face_count, 3) int32 host faces.
        topology: the mesh's topology tables.
        faces_device: (face_count,) ``wp.vec3i`` device faces.
        edges_device: (edge_count,) ``wp.vec2i`` device edges.
        device: Warp device.
    """

    def __init__(
        self, faces: np.ndarray, topology: MeshTopology, faces_device: wp.array, edges_device: wp.array,
        device: wp.Device,
    ) -> None:
        self.device = device
        vertex_bits, edge_bits = ownership_bits(faces, topology)
        self.owned_vertex_bits = wp.array(vertex_bits, dtype=wp.int32, device=device)
        self.owned_edge_bits = wp.array(edge_bits, dtype=wp.int32, device=device)
        self.face_edges = wp.array(topology.face_edges, dtype=wp.vec3i, device=device)
        self.faces = faces_device
        self.edges = edges_device
        self._counts = [wp.empty(1, dtype=wp.int32, device=device) for _ in range(4)]
        self.pair_stats = wp.zeros(2, dtype=wp.int32, device=device)
        self.planes = PlaneTestArgs()
        self.planes.factor = tolerances.COPLANARITY_ROUNDING_FACTOR * tolerances.FLOAT32_UNIT_ROUNDOFF
        self.planes.params = ccd_parameters()
        self.kept_pairs = 0
        self.kept_self_pairs = 0

    @property
    def device_bytes(self) -> int:
        """Bytes held on the device (ownership tables and scratch)."""
        return (self.owned_vertex_bits.capacity + self.owned_edge_bits.capacity + self.face_edges.capacity
                + sum(a.capacity for a in self._counts))

    def _scratch(self, index: int, size: int) -> wp.array:
        if self._counts[index].shape[0] < size:
            self._counts[index] = wp.empty(int(1.25 * size) + 1024, dtype=wp.int32, device=self.device)
        return self._counts[index]

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
        skipping pairs that a supporting plane separates (:mod:`pscc.collision.pair_filter`).

        Args:
            triangle_pairs: candidate triangle pairs from a broad phase.
            pair_count: number of valid pairs.
            candidates: output buffers (grown to the exact totals).
            positions_t0: positions (DCD) or start of the step (CCD).
            positions_t1: end of the step for CCD, else None.
            thickness: the distance the broad-phase boxes were grown by.
            object_ids: (face_count,) object of each face, for the self / inter pair counts.
            boxes: the primitive boxes of the same call; feature pairs whose boxes miss are skipped.

        Afterwards ``kept_pairs`` and ``kept_self_pairs`` hold the triangle pairs that passed.
        Reads the totals to the host (a sync point) to size the output exactly.
        Allocates: only when ``candidates`` or the scratch arrays must grow. Capture-safe: no.
        """
        n = int(pair_count)
        vf_counts = self._scratch(0, n + 1)
        ee_counts = self._scratch(1, n + 1)
        vf_offsets = self._scratch(2, n + 1)
        ee_offsets = self._scratch(3, n + 1)
        vf_counts.zero_()
        ee_counts.zero_()
        self.pair_stats.zero_()
        planes = self.planes
        planes.positions_t0 = positions_t0
        planes.positions_t1 = positions_t1 if positions_t1 is not None else positions_t0
        planes.object_ids = object_ids
        planes.swept = 1 if positions_t1 is not None else 0
        planes.thickness = float(thickness)
        if n > 0:
            wp.launch(_count_features, dim=n, device=self.device,
                      inputs=[self.faces, self.face_edges, self.edges, self.owned_vertex_bits,
                              self.owned_edge_bits, triangle_pairs, planes, boxes],
                      outputs=[vf_counts, ee_counts, self.pair_stats])
        # Exclusive scan over n + 1 entries: the last offset is the total.
        wp.utils.array_scan(vf_counts[: n + 1], vf_offsets[: n + 1], inclusive=False)
        wp.utils.array_scan(ee_counts[: n + 1], ee_offsets[: n + 1], inclusive=False)
        total_vf = int(vf_offsets[n : n + 1].numpy()[0])
        total_ee = int(ee_offsets[n : n + 1].numpy()[0])
        stats = self.pair_stats.numpy()
        self.kept_pairs = int(stats[0])
        self.kept_self_pairs = int(stats[1])
        candidates.ensure(total_vf, total_ee)
        if n > 0:
            wp.launch(_fill_features, dim=n, device=self.device,
                      inputs=[self.faces, self.face_edges, self.edges, self.owned_vertex_bits,
                              self.owned_edge_bits, triangle_pairs, boxes, vf_offsets, ee_offsets],
                      outputs=[candidates.vertex_face, candidates.edge_edge])
        candidates.set_counts(total_vf, total_ee)
