"""Growable device buffers of candidate feature pairs, filled by a broad phase.

======================  ======================  ==============================================
buffer                  shape, dtype            meaning
======================  ======================  ==============================================
vertex_face             (capacity_vf,) vec2i    (vertex id, face id)
edge_edge               (capacity_ee,) vec2i    (edge id a, edge id b), a < b
storage                 (both,) vec2i           the one allocation the two above are views of
counts                  (2,) int32              pairs appended: [vertex-face, edge-edge]; may
                                                exceed the capacities (an overflow)
======================  ======================  ==============================================

Broad-phase kernels append with an atomic counter and write only below capacity, so they never write
out of bounds; the counter keeps counting past the capacity, which tells the owner the exact size to
grow to before running again (see :meth:`CandidatePairs.fits`).

The counts stay on the device: consumers launch at the capacities and clamp with ``counts`` in their
kernels (``min(counts[k], capacity)`` valid rows, see :func:`valid_rows` and
:mod:`pscc.collision.contacts`, whose ``ContactArgs.counts`` is exactly :attr:`CandidatePairs.counts`).
Only :meth:`CandidatePairs.fits` reads them to the host (the sync point).
"""

from __future__ import annotations

import numpy as np
import warp as wp

from pscc.collision.scratch import view
from pscc.errors import CapacityError

wp.set_module_options({"enable_backward": False})

MAX_CAPACITY: int = 2**31 - 1
"""Largest number of pairs one buffer can hold (int32 indexing)."""

GROWTH: float = 1.25
"""Factor a buffer grows by past the count that overflowed it (plus a fixed margin of ``GROWTH_MARGIN``)."""

GROWTH_MARGIN: int = 1024
"""Slots added to a grown buffer on top of ``GROWTH`` x the count."""


@wp.func
def valid_rows(counts: wp.array(dtype=wp.int32), kind: int, capacity: int) -> int:
    """Rows of buffer ``kind`` (0: vertex-face, 1: edge-edge) that hold pairs: the appended count
    clamped to ``capacity`` (and to 0 when the int32 counter wrapped)."""
    return wp.max(0, wp.min(counts[kind], capacity))


class CandidatePairs:
    """Candidate vertex-face and edge-edge pairs (layout in the module docstring).

    Producers append on the device (:meth:`reset`, then their kernels); :meth:`fits` is the only sync
    point. The buffers are replaced only by :meth:`fits` and :meth:`ensure`, so a graph captured after a
    :meth:`fits` that returned True stays valid until the next one that returns False.

    Args:
        capacity_vf: initial number of vertex-face slots.
        capacity_ee: initial number of edge-edge slots.
        device: Warp device.
    """

    def __init__(self, capacity_vf: int, capacity_ee: int, device: wp.Device) -> None:
        self.device = device
        self._allocate(max(1, int(capacity_vf)), max(1, int(capacity_ee)))
        self.counts = wp.zeros(2, dtype=wp.int32, device=device)
        self._host_counts: np.ndarray | None = np.zeros(2, dtype=np.int64)  # None: accepted unread
        self.initial_capacities = (max(1, int(capacity_vf)), max(1, int(capacity_ee)))
        """The slots the buffers were made with: room for contact before it happens, which
        :meth:`trim` does not go below."""

    def _allocate(self, capacity_vf: int, capacity_ee: int) -> None:
        """One buffer for both kinds (contents not kept): :attr:`vertex_face` and :attr:`edge_edge` are
        views of its two parts, so the memory is one block a simulator can lend out between uses."""
        self.storage = wp.empty(capacity_vf + capacity_ee, dtype=wp.vec2i, device=self.device)
        """(capacity_vf + capacity_ee,) vec2i the memory of both kinds of pairs."""
        # Views made from the address (scratch.view), not slices: with slices of the storage, a CPU graph
        # recorded right after the storage was replaced held no operations (Warp 1.19).
        self.vertex_face = view(self.storage, 0, capacity_vf, wp.vec2i)
        self.edge_edge = view(self.storage, 8 * capacity_vf, capacity_ee, wp.vec2i)

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
        return self.storage.capacity + self.counts.capacity

    def reset(self) -> None:
        """Zero both counters. Allocates: no. Capture-safe: yes."""
        self.counts.zero_()

    def fits(self) -> bool:
        """Sync point: read the counters to the host and grow the buffers that overflowed.

        Afterwards :attr:`vertex_face_count` and :attr:`edge_edge_count` hold the counts read. A grown
        buffer is replaced by a new one (``GROWTH`` x the count, plus ``GROWTH_MARGIN``; both kinds share
        one allocation, so both are new); their contents are not kept.

        Returns:
            True when every pair found was stored; False when a buffer was grown, in which case
            the broad phase must run again.

        Raises:
            CapacityError: more pairs than one int32-indexed buffer can hold.

        Allocates: only when a buffer grows. Capture-safe: no.
        """
        counts = self.counts.numpy().astype(np.int64)
        vertex_face, edge_edge = int(counts[0]), int(counts[1])
        if vertex_face < 0 or edge_edge < 0:
            raise CapacityError("candidate counter overflowed int32; reduce the thickness or split the scene")
        self._host_counts = counts
        fits = vertex_face <= self.capacity_vf and edge_edge <= self.capacity_ee
        if not fits:
            self.ensure(vertex_face, edge_edge)
        return fits

    def ensure(self, capacity_vf: int, capacity_ee: int) -> None:
        """Grow the buffers (contents are not kept, of either kind) to hold at least the given numbers of
        pairs.

        Allocates: only when a buffer is too small. Capture-safe: no.
        """
        if capacity_vf > self.capacity_vf or capacity_ee > self.capacity_ee:
            vf = self._grown(capacity_vf, "vertex_face") if capacity_vf > self.capacity_vf else self.capacity_vf
            ee = self._grown(capacity_ee, "edge_edge") if capacity_ee > self.capacity_ee else self.capacity_ee
            self._allocate(vf, ee)

    def trim(self, capacity_vf: int, capacity_ee: int) -> None:
        """Shrink the buffers (contents are not kept) that are larger than the given numbers of pairs, but
        not below :attr:`initial_capacities`: between broad phases only; the narrow phase's buffers follow with
        :meth:`pscc.collision.narrow_phase.NarrowPhase.reserve`, and recorded graphs must be recorded again.

        Allocates: only when a buffer shrinks. Capture-safe: no.
        """
        capacity_vf = max(int(capacity_vf), self.initial_capacities[0])
        capacity_ee = max(int(capacity_ee), self.initial_capacities[1])
        if capacity_vf < self.capacity_vf or capacity_ee < self.capacity_ee:
            self._allocate(min(capacity_vf, self.capacity_vf), min(capacity_ee, self.capacity_ee))

    def accept_unread(self) -> None:
        """Accept the last run without reading its counters (a caller's device verdict,
        :mod:`pscc.collision.capacity_verdict`, found both within their capacities):
        :attr:`vertex_face_count` and :attr:`edge_edge_count` then read them when asked. Capture-safe: no."""
        self._host_counts = None

    def _read_counts(self) -> np.ndarray:
        if self._host_counts is None:
            self._host_counts = self.counts.numpy().astype(np.int64)
        return self._host_counts

    @property
    def vertex_face_count(self) -> int:
        """Vertex-face pairs found by the last run, as read by the last :meth:`fits` (host value; read
        now after :meth:`accept_unread`)."""
        return int(self._read_counts()[0])

    @property
    def edge_edge_count(self) -> int:
        """Edge-edge pairs found by the last run, as read by the last :meth:`fits` (host value; read
        now after :meth:`accept_unread`)."""
        return int(self._read_counts()[1])

    def _grown(self, needed: int, name: str) -> int:
        if needed > MAX_CAPACITY:
            raise CapacityError(
                f"{name} candidate buffer: {needed} pairs exceed {MAX_CAPACITY}; "
                "reduce the thickness or split the scene"
            )
        return min(MAX_CAPACITY, int(needed * GROWTH) + GROWTH_MARGIN)
