"""Proximity contacts as implicit springs: the interface between collision detection and the integrator.

A contact couples four vertices with signed weights w (VF = vertex-face, EE = edge-edge):

=============  ==============================  =======================================================
buffer         shape, dtype                    meaning
=============  ==============================  =======================================================
vertices       (capacity,) vec4i               VF: (p, a, b, c); EE: (a0, a1, b0, b1)
weights        (capacity,) vec4                VF: (1, -w_a, -w_b, -w_c) with barycentric w;
                                               EE: (1 - s, s, -(1 - t), -t) with edge parameters s, t
normals        (capacity,) vec3                unit normal n pointing from the second feature (face,
                                               edge b) to the first (vertex, edge a)
multiplicity   (capacity,) int32               pair rows the spring stands for: the factor on its
                                               stiffness (>= 1; see :mod:`pscc.sim.proximity`)
count          (1,) int32                      contacts stored; only rows [0, min(count, capacity))
                                               are read
merge keys     (capacity,) int64, int32        the producer's hash table of edge and corner contact
and counts                                     keys (:meth:`ContactSprings.merge_table`)
rest_gap       float (host)                    the thickness h [m] the springs keep the features apart
=============  ==============================  =======================================================

The gap is ``g = n . sum_i w_i x_i - h``. While ``g < 0`` the integrator applies
``f_i = -m k_c g w_i n`` implicitly, m the multiplicity (Jacobian blocks ``-m k_c w_i w_j n n^T``, normal
frozen), and Coulomb
friction as an implicit tangential damper (see :class:`pscc.sim.ImplicitEuler`).

Producers either upload pairs from the host (:meth:`ContactSprings.set`) or append on the device with
``wp.atomic_add(count, 0, 1)`` (e.g. :meth:`pscc.sim.proximity.ProximityContacts.update_device`),
writing only below capacity; the counter keeps counting past the capacity, and
:meth:`ContactSprings.fits` (a sync point) grows the buffers to 1.25 times the size needed before the
producer runs again. Nothing overflows silently. The count lives on the device only: consumers read
``count`` in their kernels (:mod:`pscc.sim.assembly` launches at capacity and clamps), and
:attr:`ContactSprings.host_count` is a sync read of it.
"""

from __future__ import annotations

import weakref
from typing import Any

import numpy as np
import warp as wp

from pscc._checks import as_numpy
from pscc.collision.scratch import Lender, TableSpec, check_lender, place_tables
from pscc.errors import CapacityError, InputError

MAX_CAPACITY: int = 2**31 - 1
"""Largest number of contacts one buffer can hold (int32 indexing)."""


@wp.struct
class MergeTable:
    """Open-addressing hash table a producer merges duplicate contact rows with (:mod:`pscc.sim.proximity`)."""

    keys: wp.array(dtype=wp.int64)
    """(capacity,) contact keys, -1 for a free slot."""
    counts: wp.array(dtype=wp.int32)
    """(capacity,) rows seen per key."""


class ContactSprings:
    """Growable device buffers of contact springs (layout in the module docstring).

    Args:
        capacity: Initial number of contact slots (>= 0; at least one slot is allocated).
        rest_gap: The thickness h [m] (>= 0) kept between the two features of every contact.
        device: Warp device.
    """

    def __init__(self, capacity: int = 0, *, rest_gap: float = 0.002, device: wp.DeviceLike = None) -> None:
        if isinstance(capacity, bool) or not isinstance(capacity, int | np.integer) or capacity < 0:
            raise InputError("argument", "capacity", f"{capacity!r} is not an integer >= 0",
                             "pass the expected number of contacts (0 is fine: the buffers grow)")
        gap = float(rest_gap)
        if not np.isfinite(gap) or gap < 0.0:
            raise InputError("argument", "rest_gap", f"{rest_gap!r} is negative or not finite",
                             "pass the cloth thickness in meters (>= 0)")
        self.device = wp.get_device(device)
        self.rest_gap: float = gap
        """The thickness h [m] the springs keep between the features."""
        self.vertices = wp.zeros(max(1, int(capacity)), dtype=wp.vec4i, device=self.device)
        """(capacity,) vec4i vertex ids of each contact."""
        self.weights = wp.zeros(max(1, int(capacity)), dtype=wp.vec4, device=self.device)
        """(capacity,) vec4 signed weights of each contact (dimensionless)."""
        self.normals = wp.zeros(max(1, int(capacity)), dtype=wp.vec3, device=self.device)
        """(capacity,) vec3 unit normals of each contact."""
        self.multiplicity = wp.ones(max(1, int(capacity)), dtype=wp.int32, device=self.device)
        """(capacity,) int32 pair rows each contact stands for (the factor on its stiffness)."""
        self._merge_lender: weakref.ref[wp.array] | None = None
        self._place_merge_table(max(1, int(capacity)))
        self.count = wp.zeros(1, dtype=wp.int32, device=self.device)
        """(1,) int32 number of contacts stored (may exceed capacity after an overflowing append)."""

    @property
    def capacity(self) -> int:
        """Number of contact slots."""
        return int(self.vertices.shape[0])

    def lend_merge_table(self, buffer: wp.array | None) -> None:
        """Let the merge table (:attr:`merge_keys`, :attr:`merge_counts`: 12 bytes per slot) live in
        ``buffer``'s memory when it fits there, for a lender whose buffer holds nothing it needs while a
        producer merges (the solver lends its BSR values, dead from the end of one integration to the start
        of the next, when the springs are built). ``None`` takes the loan back. The table then counts as
        the lender's memory (:attr:`merge_table_lent`). Allocates: the table again. Capture-safe: no."""
        if buffer is not None:
            check_lender(buffer, self.device, "buffer")
        # A weak reference: the lender owns (and counts) the buffer; the views placed in it keep it alive.
        self._merge_lender = weakref.ref(buffer) if buffer is not None else None
        self._place_merge_table(self.capacity)

    def _place_merge_table(self, size: int) -> None:
        """(Re)make the merge table for ``size`` slots: in the lent buffer when it fits, else its own.
        It holds nothing between producer runs (each run clears it first)."""
        tables = [TableSpec("merge_keys", size, wp.int64), TableSpec("merge_counts", size, wp.int32)]
        lender = self._merge_lender() if self._merge_lender is not None else None
        lenders = [Lender(lender)] if lender is not None else []
        placed, lent = place_tables(tables, lenders, self.device)
        self.merge_keys = placed["merge_keys"]
        """(capacity,) int64 the merge table's keys (:meth:`merge_table`)."""
        self.merge_counts = placed["merge_counts"]
        """(capacity,) int32 the merge table's counts."""
        self.merge_table_lent: set[str] = lent
        """Names of the merge table's arrays that live in lent memory (the lender's to count)."""

    def merge_table(self) -> MergeTable:
        """The hash table (one slot per contact slot) a producer merges the rows of one contact with.
        Allocates: no. Capture-safe: yes."""
        table = MergeTable()
        table.keys = self.merge_keys
        table.counts = self.merge_counts
        return table

    @property
    def host_count(self) -> int:
        """Contacts stored: the device counter clamped to the capacity.

        Sync point: reads one integer back (device code reads :attr:`count` instead).
        """
        return max(0, min(int(self.count.numpy()[0]), self.capacity))

    def set_count(self, count: int) -> None:
        """Record that a producer filled rows [0, count) of the buffers (writes the device counter).

        Allocates: no. Capture-safe: no (uploads the value).
        """
        if isinstance(count, bool) or not isinstance(count, int | np.integer) or not 0 <= count <= self.capacity:
            raise InputError("argument", "count", f"{count!r} is not an integer in [0, {self.capacity}]",
                             "call ensure(count) before filling the buffers")
        self.count.fill_(int(count))

    def reset(self) -> None:
        """Drop every contact (zero the counter). Allocates: no. Capture-safe: yes."""
        self.count.zero_()

    def fits(self) -> bool:
        """Read the counter (a sync point) and grow the buffers when a producer overflowed them.

        Returns:
            True when every contact was stored; False when the buffers were grown (contents kept
            below the old capacity), in which case the producer must run again.

        Raises:
            CapacityError: the counter overflowed int32.

        Allocates: only when growing. Capture-safe: no.
        """
        count = int(self.count.numpy()[0])
        if count < 0:
            raise CapacityError("contact counter overflowed int32; reduce the thickness or split the scene")
        if count <= self.capacity:
            return True
        self.ensure(count)
        return False

    def ensure(self, capacity: int) -> None:
        """Grow the buffers to at least ``capacity`` slots, keeping the stored contacts.

        Allocates: only when growing. Capture-safe: no.
        """
        if capacity <= self.capacity:
            return
        if capacity > MAX_CAPACITY:
            raise CapacityError(f"contact springs: {capacity} contacts exceed {MAX_CAPACITY}; "
                                "reduce the thickness or split the scene")
        size = min(MAX_CAPACITY, int(capacity * 1.25) + 256)
        self._resize_all(size)

    def trim(self, capacity: int) -> None:
        """Shrink the buffers to ``capacity`` slots (at least 256) when they are larger, keeping the
        contacts stored below it: call between steps with ``capacity`` at least the stored count, and
        record graphs again (the buffers are new arrays).

        Allocates: when shrinking. Capture-safe: no.
        """
        size = max(256, int(capacity))
        if size < self.capacity:
            self._resize_all(size)

    def set(self, vertices: Any, weights: Any, normals: Any, multiplicity: Any = None) -> None:
        """Replace the contacts with host data (grows the buffers as needed).

        Args:
            vertices: (k, 4) integer vertex ids, VF (p, a, b, c) or EE (a0, a1, b0, b1).
            weights: (k, 4) signed weights, VF (1, -w_a, -w_b, -w_c) or EE (1 - s, s, -(1 - t), -t).
            normals: (k, 3) unit normals from the second feature to the first (normalised here).
            multiplicity: (k,) integers >= 1, the factor on each contact's stiffness (default 1).

        Raises:
            InputError: wrong shapes, negative ids, non-finite values or a zero normal.

        Allocates: yes (host-to-device upload). Capture-safe: no.
        """
        ids = as_numpy(vertices)
        if ids.size == 0:
            ids = ids.reshape(0, 4)
        if ids.ndim != 2 or ids.shape[1] != 4 or ids.dtype.kind not in "iu":
            raise InputError("argument", "vertices", f"shape {ids.shape} dtype {ids.dtype} is not (k, 4) integer",
                             "pass four vertex ids per contact")
        k = int(ids.shape[0])
        if k and ids.min() < 0:
            raise InputError("argument", "vertices", "a vertex id is negative", "pass 0-based vertex ids")
        w = np.asarray(as_numpy(weights), dtype=np.float32).reshape(-1, 4) if k else np.zeros((0, 4), np.float32)
        n = np.asarray(as_numpy(normals), dtype=np.float64).reshape(-1, 3) if k else np.zeros((0, 3))
        if w.shape != (k, 4) or n.shape != (k, 3):
            raise InputError("argument", "weights/normals", f"shapes {w.shape} and {n.shape} do not match ({k}, 4) "
                             f"and ({k}, 3)", "pass one weight vec4 and one normal per contact")
        if not (np.all(np.isfinite(w)) and np.all(np.isfinite(n))):
            raise InputError("argument", "weights/normals", "holds NaN or Inf", "pass finite weights and normals")
        length = np.linalg.norm(n, axis=1)
        if k and length.min() <= 0.0:
            raise InputError("argument", "normals", f"contact {int(np.argmin(length))} has a zero normal",
                             "pass a non-zero normal per contact")
        self.ensure(k)
        if k:
            self.vertices.assign(np.concatenate([ids.astype(np.int32), np.zeros((self.capacity - k, 4), np.int32)]))
            self.weights.assign(np.concatenate([w, np.zeros((self.capacity - k, 4), np.float32)]))
            unit = (n / length[:, None]).astype(np.float32)
            self.normals.assign(np.concatenate([unit, np.zeros((self.capacity - k, 3), np.float32)]))
        self.multiplicity.fill_(1)
        if k and multiplicity is not None:
            factors = np.asarray(as_numpy(multiplicity)).reshape(-1)
            if factors.shape != (k,) or factors.dtype.kind not in "iu" or factors.min() < 1:
                raise InputError("argument", "multiplicity", f"shape {factors.shape} dtype {factors.dtype} is not "
                                 f"({k},) integers >= 1", "pass one stiffness factor >= 1 per contact")
            self.multiplicity.assign(np.concatenate([factors.astype(np.int32),
                                                     np.ones(self.capacity - k, np.int32)]))
        self.set_count(k)

    def _resize_all(self, size: int) -> None:
        self.vertices = self._resized(self.vertices, size)
        self.weights = self._resized(self.weights, size)
        self.normals = self._resized(self.normals, size)
        self.multiplicity = self._resized(self.multiplicity, size)
        # The merge table holds nothing between producer runs: placed anew.
        self._place_merge_table(size)

    def _resized(self, old: wp.array, size: int) -> wp.array:
        new = wp.zeros(size, dtype=old.dtype, device=self.device)
        wp.copy(new, old, count=min(size, old.shape[0]))
        return new
