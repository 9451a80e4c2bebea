"""Per-face plane slabs for the discrete supporting-plane test of candidate triangle pairs.

The supporting-plane test (:mod:`pscc.collision.pair_filter`) asks, for a triangle pair (A, B), which
vertices of B are certified farther than the thickness h from A's plane. Computed from the six vertices
it costs two cross products, two square roots and a rounding bound per vertex on every pair. This
module moves the per-face part to one pass over the faces per discrete detection, so a pair only
projects the other face's three vertices.

For face A = (a, b, c) it stores a direction ``normal`` ((b - a) x (c - a) as float32 computes it; the
test is valid for any direction), a point ``center`` (its vertex a) and the slab [``lower``, ``upper``] of
``normal . (x - center)`` that holds every point x of A, grown by h |normal| and by the rounding bounds
of its own computation. A vertex p of B whose computed projection ``s = normal . (p - center)`` is
above ``upper`` by more than ``e``, the rounding bound of s, is then farther than h from every point
of A (it is past a plane parallel to A's slab, farther than h from it); likewise below ``lower``.

Rounding (float32, unit roundoff u = 2^-24, with or without fused multiply-adds): the projection of
d = p - center, computed as fl(n . fl(p - center)), is within (u + gamma_3 (1 + u)) sum |n_i| |d_i|
< 4.01 u |n|_1 |d|_inf of the exact n . (p - center). The stored ``error_scale`` is 8 u |n|_1 (twice that
factor, so the few roundings of the bound itself are absorbed), ``reach`` bounds |x - center|_inf over
A's vertices from above, and a pair bounds |d|_inf by |center_B - center_A|_inf + reach_B. A tiny
absolute term covers products in the subnormal range. NaN anywhere makes every comparison false: the
vertex is then not certified (a side of 0), which never drops a pair. A face whose normal is zero
(a degenerate face) gets the zero direction and certifies nothing.

The pass over the faces costs about as much as the plane test saves on 1.5 triangle pairs per face, so
:class:`FacePlanes` runs it only when the broad phase found at least ``min_pairs_per_face`` pairs per face
(decided on the device, from the pair counter; the feature pass reads the same counter and takes the
six-vertex test otherwise).

========================  ======================  ==============================================
buffer                    shape, dtype            meaning
========================  ======================  ==============================================
planes                    (face_count,)           :class:`FacePlane` per face, for the positions
                          ``FacePlane``           and thickness of the last :meth:`FacePlanes.compute`
                                                  (unwritten when it found too few pairs)
========================  ======================  ==============================================
"""

from __future__ import annotations

import warp as wp

wp.set_module_options({"enable_backward": False})

UNIT_ROUNDOFF = 2.0**-24
# 8 u: twice the 4.01 u of a projection's rounding bound (module docstring).
PROJECTION_ERROR_FACTOR = wp.constant(8.0 * UNIT_ROUNDOFF)
# Grows a bound computed in float32 (a few roundings, each at most a factor 1 - u) past the exact value.
ROUND_UP_FACTOR = wp.constant(1.0 + 8.0 * UNIT_ROUNDOFF)
# An absolute term for products that fall into the subnormal range (their error is absolute there).
TINY_ERROR = wp.constant(1.0e-35)


@wp.struct
class FacePlane:
    """One face's plane slab (module docstring): every point x of the face has
    ``lower <= normal . (x - center) <= upper`` with the thickness folded in (``lower`` and ``upper`` are
    grown by h |normal|), ``reach`` >= |x - center|_inf over the face's vertices and ``error_scale`` =
    8 u |normal|_1."""

    normal: wp.vec3
    center: wp.vec3
    lower: wp.float32
    upper: wp.float32
    reach: wp.float32
    error_scale: wp.float32


@wp.func
def _inf_norm(v: wp.vec3) -> float:
    return wp.max(wp.max(wp.abs(v[0]), wp.abs(v[1])), wp.abs(v[2]))


@wp.func
def face_plane(a: wp.vec3, b: wp.vec3, c: wp.vec3, thickness: float) -> FacePlane:
    """The plane slab of triangle (a, b, c) grown by ``thickness`` (module docstring)."""
    db = b - a
    dc = c - a
    normal = wp.cross(db, dc)
    length = wp.length(normal)
    # Zero, tiny or non-finite normals give the zero direction: the face then certifies nothing.
    if not (length > 1.0e-30 and length < 1.0e30):
        normal = wp.vec3(0.0, 0.0, 0.0)
        length = 0.0
    reach = wp.max(_inf_norm(db), _inf_norm(dc)) * ROUND_UP_FACTOR
    error_scale = PROJECTION_ERROR_FACTOR * (wp.abs(normal[0]) + wp.abs(normal[1]) + wp.abs(normal[2]))
    vertex_error = error_scale * reach + TINY_ERROR
    grow = thickness * length * ROUND_UP_FACTOR + vertex_error
    # The centre's own projection is exactly 0; b's and c's are 0 but for rounding.
    pb = wp.dot(normal, db)
    pc = wp.dot(normal, dc)
    top = wp.max(wp.max(0.0, pb), pc)
    bottom = wp.min(wp.min(0.0, pb), pc)
    # The two sums below round by at most 2 u of their terms' magnitudes; 8 u of them (plus the tiny
    # term) covers that and the rounding of the final addition.
    plane = FacePlane()
    plane.normal = normal
    plane.center = a
    plane.upper = (top + grow) + ((wp.abs(top) + grow) * PROJECTION_ERROR_FACTOR + TINY_ERROR)
    plane.lower = (bottom - grow) - ((wp.abs(bottom) + grow) * PROJECTION_ERROR_FACTOR + TINY_ERROR)
    plane.reach = reach
    plane.error_scale = error_scale
    return plane


@wp.func
def slab_side(plane: FacePlane, p: wp.vec3, error: float) -> float:
    """+1 when point p is certified above the plane's grown slab, -1 below, 0 otherwise (``error``: the
    rounding bound of p's projection, :func:`projection_error`). Branch-free: in IEEE arithmetic,
    fl(s - e) > upper implies s - e > upper (rounding is monotone and ``upper`` is a float)."""
    s = wp.dot(plane.normal, p - plane.center)
    return wp.where(s - error > plane.upper, 1.0, wp.where(s + error < plane.lower, -1.0, 0.0))


@wp.func
def projection_error(plane: FacePlane, center: wp.vec3, reach: float) -> float:
    """Bound on the rounding error of :func:`slab_side`'s projection onto ``plane`` of any vertex of a
    face with this ``center`` and ``reach``."""
    return plane.error_scale * (_inf_norm(center - plane.center) + reach) + TINY_ERROR


@wp.func
def slab_sides(plane: FacePlane, other: FacePlane, p0: wp.vec3, p1: wp.vec3, p2: wp.vec3) -> wp.vec3:
    """The sides (:func:`slab_side`) of the vertices p0, p1, p2 of the face whose plane slab is
    ``other`` with respect to the slab ``plane``: +1 or -1 where a vertex is certified farther than the
    thickness from every point of the face of ``plane``, on that side; 0 where it may be within."""
    error = projection_error(plane, other.center, other.reach)
    return wp.vec3(slab_side(plane, p0, error), slab_side(plane, p1, error), slab_side(plane, p2, error))


@wp.kernel
def _compute_face_planes(
    # in:
    faces: wp.array(dtype=wp.vec3i),
    positions: wp.array(dtype=wp.vec3),
    thickness: float,
    pair_counts: wp.array(dtype=wp.int64),
    min_pairs: wp.int64,
    # out:
    planes: wp.array(dtype=FacePlane),
):
    """One thread per face: its plane slab at ``positions`` grown by ``thickness``, when the broad phase
    found at least ``min_pairs`` triangle pairs (``pair_counts[0]``); else nothing."""
    if pair_counts[0] < min_pairs:
        return
    i = wp.tid()
    f = faces[i]
    planes[i] = face_plane(positions[f[0]], positions[f[1]], positions[f[2]], thickness)


class FacePlanes:
    """The plane slab of every face, computed when a call has enough triangle pairs (module docstring).

    Args:
        faces: (face_count,) ``wp.vec3i`` device array.
        device: Warp device.
        min_pairs_per_face: triangle pairs per face from which :meth:`compute` writes the slabs.
    """

    def __init__(self, faces: wp.array, device: wp.Device, min_pairs_per_face: float = 2.0) -> None:
        self.device = device
        self.faces = faces
        self.planes = wp.empty(faces.shape[0], dtype=FacePlane, device=device)
        self.min_pairs = int(round(float(min_pairs_per_face) * faces.shape[0]))
        """Triangle pairs from which the slabs are written (and used)."""

    @property
    def device_bytes(self) -> int:
        """Bytes held on the device."""
        return self.planes.capacity

    def compute(self, positions: wp.array, thickness: float, pair_counts: wp.array) -> None:
        """Every face's plane slab at ``positions``, grown by ``thickness`` (length units), if
        ``pair_counts[0]`` (int64, on the device) is at least :attr:`min_pairs`.

        Allocates: no. Capture-safe: yes.
        """
        wp.launch(_compute_face_planes, dim=self.faces.shape[0],
                  inputs=[self.faces, positions, float(thickness), pair_counts, wp.int64(self.min_pairs)],
                  outputs=[self.planes], device=self.device)
