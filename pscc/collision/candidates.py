"""Growable device buffers of candidate feature pairs, filled by a broad phase.

======================  ======================  ==============================================
buffer                  shape, dtype            meaning
======================  ======================  ==============================================
vertex_face             (capacity_vf,) vec2i    (vertex id, face id)
edge_edge               (capacity_ee,) vec2i    (edge id a, edge id b), a < b
counts                  (2,) int32              pairs found: [vertex-face, edge-edge]
======================  ======================  ==============================================

Broad-phase kernels append with an atomic counter and write only below capacity, so they never write
out of bounds; the counter keeps counting past the capacity, which tells the owner the exact size to
grow to before running again (see :meth:`CandidatePairs.fits`).
"""

from __future__ import annotations

import numpy as np
import warp as wp

from pscc.errors import CapacityError

wp.set_module_options({"enable_backward": False})

MAX_CAPACITY: int = 2**31 - 1
"""Largest number of pairs one buffer can hold (int32 indexing)."""


class CandidatePairs:
    """Candidate vertex-face and edge-edge pairs (layout in the module docstring).

    Args:
        capacity_vf: initial number of vertex-face slots.
        capacity_ee: initial number of edge-edge slots.
        device: Warp device.
    """

    def __init__(self, capacity_vf: int, capacity_ee: int, device: wp.Device) -> None:
        self.device = device
        self.vertex_face = wp.empty(max(1, capacity_vf), dtype=wp.vec2i, device=device)
        self.edge_edge = wp.empty(max(1, capacity_ee), dtype=wp.vec2i, device=device)
        self.counts = wp.zeros(2, dtype=wp.int32, device=device)
        self._host_counts = np.zeros(2, dtype=np.int64)

    @property
    def capacity_vf(self) -> int:
        """Vertex-face slots."""
        return self.vertex_face.shape[0]

    @property
    def capacity_ee(self) -> int:
        """Edge-edge slots."""
        return self.edge_edge.shape[0]

    @property
    def device_bytes(self) -> int:
        """Bytes held on the device."""
        return self.vertex_face.capacity + self.edge_edge.capacity + self.counts.capacity

    def reset(self) -> None:
        """Zero both counters. Allocates: no. Capture-safe: yes."""
        self.counts.zero_()

    def fits(self) -> bool:
        """Read the counters (a sync point) and grow the buffers when they overflowed.

        Returns:
            True when every pair found was stored; False when a buffer was grown, in which case
            the broad phase must run again.

        Raises:
            CapacityError: more pairs than one int32-indexed buffer can hold.
        """
        counts = self.counts.numpy().astype(np.int64)
        if np.any(counts < 0):
            raise CapacityError("candidate counter overflowed int32; reduce the thickness or split the scene")
        self._host_counts = counts
        fits = True
        if counts[0] > self.capacity_vf:
            self.vertex_face = self._grown(counts[0], "vertex_face")
            fits = False
        if counts[1] > self.capacity_ee:
            self.edge_edge = self._grown(counts[1], "edge_edge")
            fits = False
        return fits

    def ensure(self, capacity_vf: int, capacity_ee: int) -> None:
        """Grow the buffers (contents are not kept) to hold at least the given numbers of pairs.

        Allocates: only when a buffer is too small. Capture-safe: no.
        """
        if capacity_vf > self.capacity_vf:
            self.vertex_face = self._grown(capacity_vf, "vertex_face")
        if capacity_ee > self.capacity_ee:
            self.edge_edge = self._grown(capacity_ee, "edge_edge")

    def set_counts(self, vertex_face_count: int, edge_edge_count: int) -> None:
        """Record pair counts known on the host (for producers that size their output exactly)."""
        self._host_counts = np.array([vertex_face_count, edge_edge_count], dtype=np.int64)
        self.counts.assign(np.array([vertex_face_count, edge_edge_count], dtype=np.int32))

    @property
    def vertex_face_count(self) -> int:
        """Vertex-face pairs found by the last run (valid after :meth:`fits`)."""
        return int(self._host_counts[0])

    @property
    def edge_edge_count(self) -> int:
        """Edge-edge pairs found by the last run (valid after :meth:`fits`)."""
        return int(self._host_counts[1])

    def _grown(self, needed: int, name: str) -> wp.array:
        if needed > MAX_CAPACITY:
            raise CapacityError(
                f"{name} candidate buffer: {needed} pairs exceed {MAX_CAPACITY}; "
                "reduce the thickness or split the scene"
            )
        size = min(MAX_CAPACITY, int(needed * 1.25) + 1024)
        return wp.empty(size, dtype=wp.vec2i, device=self.device)
