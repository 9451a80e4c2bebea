"""All-pairs broad phase: the exact reference every culling method is tested against.

Every vertex of the surface (isolated vertices, used by no face, take no part) is box-tested
against every face, and every edge against every other edge, skipping only pairs that share a
vertex. Work is split into launches of bounded size: thread (row, block) tests one vertex (or
edge) against a block of ``BLOCK`` faces (or edges). Nothing is culled, so its candidates are a
superset of every colliding pair; its cost is Θ(V F + E²).
"""

from __future__ import annotations

import warp as wp

from pscc.collision.boxes import PrimitiveBoxes
from pscc.collision.candidates import CandidatePairs
from pscc.collision.seams import SeamAdjacency, SeamArgs, stitched, stitched_to_face
from pscc.geometry.aabb import boxes_overlap

wp.set_module_options({"enable_backward": False})

BLOCK: int = 256
"""Faces (or edges) one thread tests its vertex (or edge) against."""

TESTS_PER_LAUNCH: int = 2**26
"""Upper bound of box tests in one launch, so a launch never runs for long on one device."""


@wp.kernel
def _vertex_face_pairs(
    # in:
    faces: wp.array(dtype=wp.vec3i),
    vertex_used: wp.array(dtype=wp.int32),
    vertex_lower: wp.array(dtype=wp.vec3),
    vertex_upper: wp.array(dtype=wp.vec3),
    face_lower: wp.array(dtype=wp.vec3),
    face_upper: wp.array(dtype=wp.vec3),
    seams: SeamArgs,
    first_vertex: int,
    # out:
    counts: wp.array(dtype=wp.int32),
    pairs: wp.array(dtype=wp.vec2i),
):
    """One thread per (vertex, block of BLOCK faces); pairs sharing or stitched to a vertex are skipped."""
    row, block = wp.tid()
    v = first_vertex + row
    if vertex_used[v] == 0:
        return  # a vertex of no face is not part of any surface
    lo = vertex_lower[v]
    hi = vertex_upper[v]
    face_count = faces.shape[0]
    begin = block * BLOCK
    end = wp.min(begin + BLOCK, face_count)
    for f in range(begin, end):
        tri = faces[f]
        if tri[0] == v or tri[1] == v or tri[2] == v:
            continue
        if stitched_to_face(seams, v, tri):
            continue
        if boxes_overlap(lo, hi, face_lower[f], face_upper[f]):
            slot = wp.atomic_add(counts, 0, 1)
            if slot < pairs.shape[0]:
                pairs[slot] = wp.vec2i(v, f)


@wp.kernel
def _edge_edge_pairs(
    # in:
    edges: wp.array(dtype=wp.vec2i),
    edge_lower: wp.array(dtype=wp.vec3),
    edge_upper: wp.array(dtype=wp.vec3),
    seams: SeamArgs,
    first_edge: int,
    # out:
    counts: wp.array(dtype=wp.int32),
    pairs: wp.array(dtype=wp.vec2i),
):
    """One thread per (edge a, block of BLOCK edges b), testing only b > a; pairs sharing or stitched to a
    vertex are skipped."""
    row, block = wp.tid()
    a = first_edge + row
    ea = edges[a]
    lo = edge_lower[a]
    hi = edge_upper[a]
    edge_count = edges.shape[0]
    begin = wp.max(block * BLOCK, a + 1)
    end = wp.min(block * BLOCK + BLOCK, edge_count)
    for b in range(begin, end):
        eb = edges[b]
        if ea[0] == eb[0] or ea[0] == eb[1] or ea[1] == eb[0] or ea[1] == eb[1]:
            continue
        if (stitched(seams, ea[0], eb[0]) or stitched(seams, ea[0], eb[1]) or stitched(seams, ea[1], eb[0])
                or stitched(seams, ea[1], eb[1])):
            continue
        if boxes_overlap(lo, hi, edge_lower[b], edge_upper[b]):
            slot = wp.atomic_add(counts, 1, 1)
            if slot < pairs.shape[0]:
                pairs[slot] = wp.vec2i(a, b)


class BroadPhaseBruteForce:
    """Exact all-pairs broad phase over feature pairs (vertex-face and edge-edge).

    Args:
        boxes: the primitive boxes it reads (filled by the caller each call).
        vertex_used: (vertex_count,) int32, 1 for vertices of at least one face.
        device: Warp device.
        seams: the stitch partners of the vertices (:mod:`pscc.collision.seams`); None: no stitches.
    """

    def __init__(self, boxes: PrimitiveBoxes, vertex_used: wp.array, device: wp.Device,
                 seams: SeamAdjacency | None = None) -> None:
        self.boxes = boxes
        self.vertex_used = vertex_used
        self.device = device
        self.seams = seams if seams is not None else SeamAdjacency(None, 0, device)

    def bounding_volume_tests(self, vertex_count: int, face_count: int, edge_count: int) -> int:
        """Box tests one call performs (all pairs; shared-vertex pairs are skipped before the test
        and counted here too, as an upper bound)."""
        return vertex_count * face_count + edge_count * (edge_count - 1) // 2

    def find_pairs(self, candidates: CandidatePairs) -> None:
        """Append every box-overlapping vertex-face and edge-edge pair to ``candidates``.

        The caller resets the counters first (:meth:`CandidatePairs.reset`) and checks
        :meth:`CandidatePairs.fits` after (the sync point). This is a device path: the launch sizes
        come from the array shapes (host metadata), the counts stay in ``candidates.counts`` and a
        full buffer keeps counting on the device, so a call reads nothing back and can be captured.
        Allocates: no. Capture-safe: yes.
        """
        boxes = self.boxes
        vertex_count = boxes.vertex_lower.shape[0]
        face_count = boxes.face_lower.shape[0]
        edge_count = boxes.edge_lower.shape[0]
        face_blocks = (face_count + BLOCK - 1) // BLOCK
        rows = max(1, TESTS_PER_LAUNCH // max(1, face_count))
        for first in range(0, vertex_count, rows):
            count = min(rows, vertex_count - first)
            wp.launch(_vertex_face_pairs, dim=(count, face_blocks),
                      inputs=[boxes.faces, self.vertex_used, boxes.vertex_lower, boxes.vertex_upper,
                              boxes.face_lower, boxes.face_upper, self.seams.args, first],
                      outputs=[candidates.counts, candidates.vertex_face], device=self.device)
        edge_blocks = (edge_count + BLOCK - 1) // BLOCK
        rows = max(1, TESTS_PER_LAUNCH // max(1, edge_count))
        for first in range(0, edge_count, rows):
            count = min(rows, edge_count - first)
            wp.launch(_edge_edge_pairs, dim=(count, edge_blocks),
                      inputs=[boxes.edges, boxes.edge_lower, boxes.edge_upper, self.seams.args, first],
                      outputs=[candidates.counts, candidates.edge_edge], device=self.device)
