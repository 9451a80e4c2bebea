"""Bounding boxes of every vertex, edge and face over a time step, grown for proximity.

``PrimitiveBoxes`` owns one (lower, upper) pair of arrays per primitive kind:

======================  =====================  ===============================================
buffer                  shape, dtype           meaning
======================  =====================  ===============================================
vertex_lower/upper      (vertex_count,) vec3   box of the vertex's positions at t0 and t1
edge_lower/upper        (edge_count,) vec3     box of the edge's 4 positions
face_lower/upper        (face_count,) vec3     box of the face's 6 positions
face_diagonal_lower/    (face_count,) vec10    the face's slabs along the ten diagonal axes of
upper                   (0 when off)           :mod:`pscc.geometry.dop` (``face_diagonals=True``), in
                                               the call's local frame (origin: vertex 0 at t0)
======================  =====================  ===============================================

Every box is grown by half the proximity distance (so two primitives closer than the distance have
overlapping boxes) and by the relative pad of :data:`pscc.tolerances.BOX_RELATIVE_PAD`.
For discrete detection pass the same positions as t0 and t1.
"""

from __future__ import annotations

import warp as wp

from pscc import tolerances
from pscc.geometry.aabb import grow_box_lower, grow_box_upper
from pscc.geometry.dop import face_diagonal_slabs, vec10

wp.set_module_options({"enable_backward": False})


@wp.kernel
def _compute_vertex_boxes(
    # in:
    positions_t0: wp.array(dtype=wp.vec3),
    positions_t1: wp.array(dtype=wp.vec3),
    swept: int,
    half_distance: float,
    relative_pad: float,
    # out:
    lower_out: wp.array(dtype=wp.vec3),
    upper_out: wp.array(dtype=wp.vec3),
):
    """One thread per vertex (``swept`` = 0: positions_t1 is not read)."""
    i = wp.tid()
    lo = positions_t0[i]
    hi = lo
    if swept != 0:
        b = positions_t1[i]
        lo = wp.min(lo, b)
        hi = wp.max(hi, b)
    lower_out[i] = grow_box_lower(lo, hi, half_distance, relative_pad)
    upper_out[i] = grow_box_upper(lo, hi, half_distance, relative_pad)


@wp.kernel
def _compute_edge_boxes(
    # in:
    edges: wp.array(dtype=wp.vec2i),
    positions_t0: wp.array(dtype=wp.vec3),
    positions_t1: wp.array(dtype=wp.vec3),
    swept: int,
    half_distance: float,
    relative_pad: float,
    # out:
    lower_out: wp.array(dtype=wp.vec3),
    upper_out: wp.array(dtype=wp.vec3),
):
    """One thread per edge (``swept`` = 0: positions_t1 is not read)."""
    i = wp.tid()
    e = edges[i]
    a = positions_t0[e[0]]
    b = positions_t0[e[1]]
    lo = wp.min(a, b)
    hi = wp.max(a, b)
    if swept != 0:
        a = positions_t1[e[0]]
        b = positions_t1[e[1]]
        lo = wp.min(lo, wp.min(a, b))
        hi = wp.max(hi, wp.max(a, b))
    lower_out[i] = grow_box_lower(lo, hi, half_distance, relative_pad)
    upper_out[i] = grow_box_upper(lo, hi, half_distance, relative_pad)


@wp.kernel
def _compute_face_boxes(
    # in:
    faces: wp.array(dtype=wp.vec3i),
    positions_t0: wp.array(dtype=wp.vec3),
    positions_t1: wp.array(dtype=wp.vec3),
    swept: int,
    half_distance: float,
    relative_pad: float,
    diagonals: int,
    slab_pad: float,
    # out:
    lower_out: wp.array(dtype=wp.vec3),
    upper_out: wp.array(dtype=wp.vec3),
    diagonal_lower_out: wp.array(dtype=vec10),
    diagonal_upper_out: wp.array(dtype=vec10),
):
    """One thread per face (``swept`` = 0: positions_t1 is not read; ``diagonals`` = 0: the diagonal
    slabs, grown with ``slab_pad``, are not written)."""
    i = wp.tid()
    f = faces[i]
    a = positions_t0[f[0]]
    b = positions_t0[f[1]]
    c = positions_t0[f[2]]
    lo = wp.min(wp.min(a, b), c)
    hi = wp.max(wp.max(a, b), c)
    a1 = a
    b1 = b
    c1 = c
    if swept != 0:
        a1 = positions_t1[f[0]]
        b1 = positions_t1[f[1]]
        c1 = positions_t1[f[2]]
        lo = wp.min(lo, wp.min(wp.min(a1, b1), c1))
        hi = wp.max(hi, wp.max(wp.max(a1, b1), c1))
    lower_out[i] = grow_box_lower(lo, hi, half_distance, relative_pad)
    upper_out[i] = grow_box_upper(lo, hi, half_distance, relative_pad)
    if diagonals != 0:
        # In the call's local frame (pscc.geometry.dop): the rounding pads then scale with the scene's size,
        # not with its distance from the origin.
        origin = positions_t0[0]
        slab_lo, slab_hi = face_diagonal_slabs(a - origin, b - origin, c - origin, a1 - origin, b1 - origin,
                                               c1 - origin, swept, half_distance, slab_pad)
        diagonal_lower_out[i] = slab_lo
        diagonal_upper_out[i] = slab_hi


@wp.struct
class PrimitiveBoxArgs:
    """The six box arrays of :class:`PrimitiveBoxes`, bundled as one kernel argument."""

    vertex_lower: wp.array(dtype=wp.vec3)
    vertex_upper: wp.array(dtype=wp.vec3)
    edge_lower: wp.array(dtype=wp.vec3)
    edge_upper: wp.array(dtype=wp.vec3)
    face_lower: wp.array(dtype=wp.vec3)
    face_upper: wp.array(dtype=wp.vec3)


class PrimitiveBoxes:
    """Per-primitive swept, grown bounding boxes (layout in the module docstring).

    Args:
        faces: (face_count,) ``wp.vec3i`` device array.
        edges: (edge_count,) ``wp.vec2i`` device array.
        vertex_count: number of vertices.
        device: Warp device.
        face_diagonals: also keep each face's diagonal slabs (:mod:`pscc.geometry.dop`), which make
            its box a 26-DOP for the spatial hash's face test.
    """

    def __init__(self, faces: wp.array, edges: wp.array, vertex_count: int, device: wp.Device,
                 face_diagonals: bool = False) -> None:
        self.device = device
        self.faces = faces
        self.edges = edges
        self._face_diagonals = bool(face_diagonals)
        diagonal_count = faces.shape[0] if face_diagonals else 0
        self.face_diagonal_lower = wp.empty(diagonal_count, dtype=vec10, device=device)
        self.face_diagonal_upper = wp.empty(diagonal_count, dtype=vec10, device=device)
        self.vertex_lower = wp.empty(vertex_count, dtype=wp.vec3, device=device)
        self.vertex_upper = wp.empty(vertex_count, dtype=wp.vec3, device=device)
        self.edge_lower = wp.empty(edges.shape[0], dtype=wp.vec3, device=device)
        self.edge_upper = wp.empty(edges.shape[0], dtype=wp.vec3, device=device)
        self.face_lower = wp.empty(faces.shape[0], dtype=wp.vec3, device=device)
        self.face_upper = wp.empty(faces.shape[0], dtype=wp.vec3, device=device)

    def as_struct(self) -> PrimitiveBoxArgs:
        """The six box arrays as one :class:`PrimitiveBoxArgs` kernel argument."""
        boxes = PrimitiveBoxArgs()
        boxes.vertex_lower = self.vertex_lower
        boxes.vertex_upper = self.vertex_upper
        boxes.edge_lower = self.edge_lower
        boxes.edge_upper = self.edge_upper
        boxes.face_lower = self.face_lower
        boxes.face_upper = self.face_upper
        return boxes

    @property
    def device_bytes(self) -> int:
        """Bytes held on the device by the box arrays (and the diagonal slabs)."""
        arrays = (self.vertex_lower, self.vertex_upper, self.edge_lower, self.edge_upper,
                  self.face_lower, self.face_upper, self.face_diagonal_lower, self.face_diagonal_upper)
        return sum(a.capacity for a in arrays)

    def compute(self, positions_t0: wp.array, positions_t1: wp.array, distance: float) -> None:
        """Fill every box from positions at t0 and t1, grown so pairs closer than ``distance`` overlap.
        Passing the same array twice (discrete detection) reads the positions once.

        Allocates: no. Capture-safe: yes.
        """
        half = 0.5 * float(distance)
        pad = tolerances.BOX_RELATIVE_PAD
        swept = int(positions_t1 is not positions_t0)
        wp.launch(_compute_vertex_boxes, dim=self.vertex_lower.shape[0],
                  inputs=[positions_t0, positions_t1, swept, half, pad],
                  outputs=[self.vertex_lower, self.vertex_upper], device=self.device)
        wp.launch(_compute_edge_boxes, dim=self.edge_lower.shape[0],
                  inputs=[self.edges, positions_t0, positions_t1, swept, half, pad],
                  outputs=[self.edge_lower, self.edge_upper], device=self.device)
        wp.launch(_compute_face_boxes, dim=self.face_lower.shape[0],
                  inputs=[self.faces, positions_t0, positions_t1, swept, half, pad,
                          int(self.has_face_diagonals), tolerances.GROUP_SLAB_RELATIVE_PAD],
                  outputs=[self.face_lower, self.face_upper, self.face_diagonal_lower, self.face_diagonal_upper],
                  device=self.device)

    @property
    def has_face_diagonals(self) -> bool:
        """Whether :meth:`compute` also fills the faces' diagonal slabs."""
        return self._face_diagonals
