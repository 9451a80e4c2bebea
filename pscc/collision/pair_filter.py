"""Supporting-plane test of candidate triangle pairs, after the box test of the spatial hash.

Two triangles A and B whose boxes overlap cannot touch (or come within the thickness h) when all
three vertices of B lie strictly on one side of A's plane, farther than h (or the same with A and
B swapped): B is the convex hull of its vertices, and A lies in its plane. Tilted layers of cloth
have large, overlapping boxes; this test removes most such pairs before feature extraction.

- DCD: signed distances n_A . (b_i - a_0) against h |n_A|, each trusted beyond a rounding bound of
  ``16 u`` times its magnitude companion (the same products with absolute values).
- CCD with thickness 0: the vertex stays strictly on one side of the moving plane during the whole
  step (:func:`pscc.geometry.ccd.vertex_plane_side`, a Bernstein sign test of the coplanarity
  cubic), for the three vertices with the same side.
- CCD with thickness > 0: no pair is removed.

Triangle pairs that share a vertex are never removed (the shared vertex lies on the plane).
Compaction is count -> exclusive scan -> scatter, so the order of the pairs is kept.
"""

from __future__ import annotations

import warp as wp

from pscc import tolerances
from pscc.geometry.ccd import CcdParameters, ccd_parameters, vertex_plane_side

wp.set_module_options({"enable_backward": False})


@wp.func
def _plane_separates_static(a: wp.vec3, b: wp.vec3, c: wp.vec3, p0: wp.vec3, p1: wp.vec3, p2: wp.vec3,
                            thickness: float, factor: float) -> bool:
    """All of p0, p1, p2 farther than ``thickness`` from the plane of (a, b, c), on one side."""
    e1 = b - a
    e2 = c - a
    n = wp.cross(e1, e2)
    mn = wp.vec3(wp.abs(e1[1] * e2[2]) + wp.abs(e1[2] * e2[1]), wp.abs(e1[2] * e2[0]) + wp.abs(e1[0] * e2[2]),
                 wp.abs(e1[0] * e2[1]) + wp.abs(e1[1] * e2[0]))
    limit = thickness * wp.length(n) * (1.0 + factor)
    side = float(0.0)
    for k in range(3):
        p = p0
        if k == 1:
            p = p1
        elif k == 2:
            p = p2
        d = p - a
        s = wp.dot(n, d)
        bound = factor * (wp.abs(mn[0] * d[0]) + wp.abs(mn[1] * d[1]) + wp.abs(mn[2] * d[2]))
        current = float(0.0)
        if s > limit + bound:
            current = 1.0
        elif s < -(limit + bound):
            current = -1.0
        if current == 0.0:
            return False
        if k > 0 and current != side:
            return False
        side = current
    return True


@wp.func
def _plane_separates_swept(fa: wp.vec3i, fb: wp.vec3i, positions_t0: wp.array(dtype=wp.vec3),
                           positions_t1: wp.array(dtype=wp.vec3), params: CcdParameters) -> bool:
    """All vertices of face ``fb`` stay strictly on one side of the moving plane of face ``fa``."""
    a0 = positions_t0[fa[0]]
    b0 = positions_t0[fa[1]]
    c0 = positions_t0[fa[2]]
    a1 = positions_t1[fa[0]]
    b1 = positions_t1[fa[1]]
    c1 = positions_t1[fa[2]]
    side = float(0.0)
    for k in range(3):
        v = fb[k]
        current = vertex_plane_side(positions_t0[v], a0, b0, c0, positions_t1[v], a1, b1, c1, params)
        if current == 0.0:
            return False
        if k > 0 and current != side:
            return False
        side = current
    return True


@wp.kernel
def _mark_pairs(
    # in:
    faces: wp.array(dtype=wp.vec3i),
    pairs: wp.array(dtype=wp.vec2i),
    positions_t0: wp.array(dtype=wp.vec3),
    positions_t1: wp.array(dtype=wp.vec3),
    swept: int,
    thickness: float,
    factor: float,
    params: CcdParameters,
    # out:
    keep_out: wp.array(dtype=wp.int32),
):
    """One thread per triangle pair: 1 to keep it, 0 when a supporting plane separates it."""
    i = wp.tid()
    pair = pairs[i]
    fa = faces[pair[0]]
    fb = faces[pair[1]]
    separated = False
    if swept == 0:
        a0 = positions_t0[fa[0]]
        a1 = positions_t0[fa[1]]
        a2 = positions_t0[fa[2]]
        b0 = positions_t0[fb[0]]
        b1 = positions_t0[fb[1]]
        b2 = positions_t0[fb[2]]
        separated = _plane_separates_static(a0, a1, a2, b0, b1, b2, thickness, factor)
        if not separated:
            separated = _plane_separates_static(b0, b1, b2, a0, a1, a2, thickness, factor)
    elif thickness == 0.0:
        separated = _plane_separates_swept(fa, fb, positions_t0, positions_t1, params)
        if not separated:
            separated = _plane_separates_swept(fb, fa, positions_t0, positions_t1, params)
    keep_out[i] = wp.where(separated, 0, 1)


@wp.kernel
def _scatter_kept(
    # in:
    pairs: wp.array(dtype=wp.vec2i),
    keep: wp.array(dtype=wp.int32),
    offsets: wp.array(dtype=wp.int32),
    # out:
    pairs_out: wp.array(dtype=wp.vec2i),
):
    """One thread per triangle pair: copy kept pairs to their scanned slot."""
    i = wp.tid()
    if keep[i] == 1:
        pairs_out[offsets[i]] = pairs[i]


class TrianglePairFilter:
    """Removes triangle pairs separated by a supporting plane (see the module docstring).

    Args:
        faces: (face_count,) ``wp.vec3i`` device faces.
        device: Warp device.
    """

    def __init__(self, faces: wp.array, device: wp.Device) -> None:
        self.faces = faces
        self.device = device
        self.params = ccd_parameters()
        self.factor = tolerances.COPLANARITY_ROUNDING_FACTOR * tolerances.FLOAT32_UNIT_ROUNDOFF
        self._keep = wp.zeros(1, dtype=wp.int32, device=device)
        self._offsets = wp.zeros(1, dtype=wp.int32, device=device)
        self.pairs = wp.zeros(1, dtype=wp.vec2i, device=device)

    @property
    def device_bytes(self) -> int:
        """Bytes held on the device."""
        return self._keep.capacity + self._offsets.capacity + self.pairs.capacity

    def _reserve(self, count: int) -> None:
        if self._keep.shape[0] < count + 1:
            size = int(1.25 * count) + 1024
            self._keep = wp.zeros(size, dtype=wp.int32, device=self.device)
            self._offsets = wp.zeros(size, dtype=wp.int32, device=self.device)
            self.pairs = wp.zeros(size, dtype=wp.vec2i, device=self.device)

    def filter(self, pairs: wp.array, count: int, positions_t0: wp.array, positions_t1: wp.array | None,
               thickness: float) -> tuple[wp.array, int]:
        """Keep the first ``count`` pairs that no supporting plane separates.

        Args:
            pairs: triangle pairs (a, b).
            count: number of valid pairs.
            positions_t0: positions (DCD) or start of the step (CCD).
            positions_t1: end of the step for CCD, else None.
            thickness: the proximity distance the boxes were grown by.

        Returns:
            ``(kept_pairs, kept_count)``: a view of the filter's buffer, in the input order.
        Reads one count to the host (a sync point). Allocates: when the buffer grows.
        """
        self._reserve(count)
        if count == 0:
            return self.pairs[:0], 0
        swept = 1 if positions_t1 is not None else 0
        end = positions_t1 if positions_t1 is not None else positions_t0
        wp.launch(_mark_pairs, dim=count, device=self.device,
                  inputs=[self.faces, pairs, positions_t0, end, swept, float(thickness), self.factor, self.params],
                  outputs=[self._keep])
        self._keep[count : count + 1].zero_()
        wp.utils.array_scan(self._keep[: count + 1], self._offsets[: count + 1], inclusive=False)
        kept = int(self._offsets[count : count + 1].numpy()[0])
        wp.launch(_scatter_kept, dim=count, inputs=[pairs, self._keep, self._offsets], outputs=[self.pairs],
                  device=self.device)
        return self.pairs[:kept], kept
