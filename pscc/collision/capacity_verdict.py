"""One device flag that says whether a detector call needs its host check (its capacity verdict).

:meth:`pscc.collision.detector.CollisionDetector.check_capacity` is the sync point after every device
call: it reads the spatial hash's counters and the candidate counters, raises the input errors the
hash counted and grows every buffer that overflowed. Most calls fit. For those, reading the counters
and comparing them on the host was most of the check's cost: on this project's 2-core CPU, right after
a `twisting f48` graph replay, the two reads and the Python around them took about 270 us (3 % of the
call; the replay had evicted everything the host code touches), and 61 us with the verdict.

:class:`CapacityVerdict` moves the comparisons to the device. At the end of every broad phase one
thread compares each counter with the capacity it was launched with and writes ``verdict[0]`` (0: every
buffer held its data and no input error was counted). The call copies it to host memory (page-locked on a
GPU), so the host check waits for the device once and reads that int32; only when it is not 0 does it
read and compare the counters themselves, which decide everything as before.
The device test is a superset of the host's: each counter it flags is one the host check acts on, or
one it could act on (the hash's node-id and same-node counters, which the host reads only for calls
that give node ids or an order). So a 0 always means the host check would have found nothing to do.

The capacities are launch arguments, so a recorded graph holds the capacities of its recording; like
every buffer of the call, they change only in the host check, after which a graph is recorded again.
The verdict's *generation* is a launch argument too: ``verdict[1]`` says which buffers the judged call
wrote. The owner advances the generation whenever it replaces them (:meth:`CapacityVerdict.advance`), so a
graph recorded before and replayed after says so (:meth:`CapacityVerdict.stale`) instead of passing.
A simulator's device step (:mod:`pscc.sim.device_step`) gathers the same counters into its own report
and never reads the verdict: there the verdict is one one-thread launch and one 4-byte asynchronous copy
per broad phase, read by nobody.

========================  ===================  ==============================================
buffer                    shape, dtype         meaning
========================  ===================  ==============================================
verdict                   (2,) int32           [0: the last broad phase fits, else a bit per
                                               kind of counter that needs the host check;
                                               the generation the call was launched with]
host_verdict              (2,) int32, host     its copy, made by the call
========================  ===================  ==============================================
"""

from __future__ import annotations

from typing import Any

import warp as wp

from pscc.collision import _spatial_hash_kernels as hash_kernels

wp.set_module_options({"enable_backward": False})

__all__ = ["ENTRIES_BIT", "ERROR_BIT", "GROUPS_BIT", "PAIRS_BIT", "ROWS_BIT", "CANDIDATES_BIT", "CapacityVerdict",
           "HashLimits"]

ENTRIES_BIT: int = 1
"""Verdict bit: the hash's entries (or the cell bits its grid wanted) overflowed."""
GROUPS_BIT: int = 2
"""Verdict bit: its groups, or the slab tables of a call that slab-tested, overflowed."""
ROWS_BIT: int = 4
"""Verdict bit: its work rows overflowed."""
PAIRS_BIT: int = 8
"""Verdict bit: its triangle pairs overflowed."""
ERROR_BIT: int = 16
"""Verdict bit: it counted an input error (bad boxes, node ids, face order, a node split by the order)."""
CANDIDATES_BIT: int = 32
"""Verdict bit: the vertex-face or edge-edge candidates overflowed (or their counter wrapped)."""


@wp.struct
class HashLimits:
    """The spatial hash's capacities at launch (its :meth:`~pscc.collision.spatial_hash.SpatialHash.overflow_counters`
    0-4): ``enabled`` 0 for a detector without a hash (brute force), ``slab_groups`` the slab tables' capacity when
    the call slab-tested (else the hash's entry limit, which the groups never exceed)."""

    enabled: wp.int32
    entries: wp.int64
    groups: wp.int64
    rows: wp.int64
    pairs: wp.int64
    slab_groups: wp.int64


_ENTRIES = wp.constant(hash_kernels.INFO_ENTRIES)
_GROUPS = wp.constant(hash_kernels.INFO_GROUPS)
_ROWS = wp.constant(hash_kernels.INFO_ROWS)
_WANTED_CELLS = wp.constant(hash_kernels.INFO_WANTED_CELLS)
_SAME_NODE = wp.constant(hash_kernels.INFO_SAME_NODE)
_BAD_BOXES = wp.constant(hash_kernels.INFO_BAD_BOXES)
_BAD_NODES = wp.constant(hash_kernels.INFO_BAD_NODES)
_BAD_ORDER = wp.constant(hash_kernels.INFO_BAD_ORDER)


@wp.kernel
def _judge_capacity(
    # in:
    info: wp.array(dtype=wp.int64),
    pair_counts: wp.array(dtype=wp.int64),
    limits: HashLimits,
    candidate_counts: wp.array(dtype=wp.int32),
    capacity_vertex_face: wp.int64,
    capacity_edge_edge: wp.int64,
    generation: wp.int32,
    # out:
    verdict: wp.array(dtype=wp.int32),
):
    """One thread: the verdict bits of the last broad phase and the generation of its buffers (module
    docstring)."""
    bits = int(0)
    if limits.enabled != 0:
        if info[_ENTRIES] > limits.entries or info[_WANTED_CELLS] > wp.int64(0):
            bits = bits | ENTRIES_BIT
        if info[_GROUPS] > limits.groups or info[_GROUPS] > limits.slab_groups:
            bits = bits | GROUPS_BIT
        if info[_ROWS] > limits.rows:
            bits = bits | ROWS_BIT
        if pair_counts[0] > limits.pairs or pair_counts[0] < wp.int64(0):
            bits = bits | PAIRS_BIT
        errors = info[_BAD_BOXES] + info[_BAD_NODES] + info[_BAD_ORDER] + info[_SAME_NODE]
        if errors != wp.int64(0):
            bits = bits | ERROR_BIT
    vertex_face = wp.int64(candidate_counts[0])
    edge_edge = wp.int64(candidate_counts[1])
    if (vertex_face > capacity_vertex_face or edge_edge > capacity_edge_edge or vertex_face < wp.int64(0)
            or edge_edge < wp.int64(0)):
        bits = bits | CANDIDATES_BIT
    verdict[0] = bits
    verdict[1] = generation


class CapacityVerdict:
    """The device verdict of a detector's calls (module docstring).

    Args:
        device: Warp device.
    """

    def __init__(self, device: Any) -> None:
        self.device = device
        self.verdict = wp.ones(2, dtype=wp.int32, device=device)
        """(2,) int32: [0 when the last judged call fits (1 until a call is judged), its generation]."""
        # The call copies its verdict to host memory (page-locked on a GPU); the check waits for the
        # device and reads it there through a view made once.
        self.host_verdict = wp.ones(2, dtype=wp.int32, device="cpu", pinned=wp.get_device(device).is_cuda)
        """(2,) int32 host copy of :attr:`verdict`, written by the call (capturable)."""
        self._host_view = self.host_verdict.numpy()
        # Stands in for the hash's counters when there is no hash (never read then).
        self._no_counters = wp.zeros(1, dtype=wp.int64, device=device)
        self._judged = False
        self.generation = 0
        """The generation of the owner's buffers: a call judged now writes it into ``verdict[1]``."""

    @property
    def device_bytes(self) -> int:
        """Bytes held on the device."""
        return self.verdict.capacity + self._no_counters.capacity  # the host copy is host memory

    def judge(self, spatial_hash: Any, candidates: Any) -> None:
        """Launch the verdict of the call that just ran (after its feature pairs): the counters of
        ``spatial_hash`` (a :class:`~pscc.collision.spatial_hash.SpatialHash`, or ``None``) against its
        :meth:`~pscc.collision.spatial_hash.SpatialHash.overflow_counters` capacities and those of
        ``candidates`` (:class:`~pscc.collision.candidates.CandidatePairs`), as they are now.

        Allocates: no. Capture-safe: yes.
        """
        limits = HashLimits()
        limits.enabled = 0
        info = pair_counts = self._no_counters
        if spatial_hash is not None:
            # Entries, groups, rows, pairs, and the groups against the slab tables of a slab-testing call.
            counters = spatial_hash.overflow_counters()
            limits.enabled = 1
            limits.entries, limits.groups, limits.rows, limits.pairs, limits.slab_groups = (
                wp.int64(counters[k][2]) for k in range(5))
            info, pair_counts = spatial_hash.info, spatial_hash.counts
        wp.launch(_judge_capacity, dim=1,
                  inputs=[info, pair_counts, limits, candidates.counts, wp.int64(candidates.capacity_vf),
                          wp.int64(candidates.capacity_ee), self.generation],
                  outputs=[self.verdict], device=self.device)
        wp.copy(self.host_verdict, self.verdict)
        self._judged = True

    def fits(self) -> bool:
        """Sync point: whether the last judged call fits. Waits for the device (one synchronize; the
        call's own copy brought the flag to the host) and reads the host copy. False before any call
        was judged, so the caller's full check runs (and says what is missing).

        Allocates: no. Capture-safe: no.
        """
        if not self._judged:
            return False
        wp.synchronize_device(self.device)
        return int(self._host_view[0]) == 0 and int(self._host_view[1]) == self.generation

    def stale(self) -> bool:
        """After :meth:`fits`: whether the last judged call was launched with buffers that the owner has
        replaced since (a graph recorded before an :meth:`advance`, replayed after it).

        Allocates: no. Capture-safe: no.
        """
        return self._judged and int(self._host_view[1]) != self.generation

    def advance(self) -> None:
        """Start a new generation: the owner is replacing buffers that calls judged so far wrote.

        Allocates: no. Capture-safe: no (a host counter, read by the next :meth:`judge`).
        """
        self.generation += 1
