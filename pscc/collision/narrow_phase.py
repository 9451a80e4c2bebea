"""Narrow phase: the conservative CCD / proximity test on every candidate feature pair.

One thread per candidate pair calls :func:`pscc.geometry.ccd.vertex_face_ccd_toi` or
:func:`pscc.geometry.ccd.edge_edge_ccd_toi`. Discrete detection (DCD) is the same test with the
end positions equal to the start positions: the pair is reported when it is provably within, or
possibly within (the documented tolerance band), the thickness.

======================  =====================  ===============================================
buffer                  shape, dtype           meaning
======================  =====================  ===============================================
vertex_face_toi         (capacity_vf,) f32     time of impact per vertex-face candidate; > 1 =
                                               no contact (``pscc.geometry.ccd.NO_HIT``)
edge_edge_toi           (capacity_ee,) f32     likewise per edge-edge candidate
======================  =====================  ===============================================
"""

from __future__ import annotations

import warp as wp

from pscc.collision.candidates import CandidatePairs
from pscc.geometry import distance_tolerances
from pscc.geometry.ccd import CcdParameters, ccd_parameters, edge_edge_ccd_toi, vertex_face_ccd_toi
from pscc.geometry.distance import edge_edge_distance_squared, vertex_face_distance_squared

wp.set_module_options({"enable_backward": False})


@wp.kernel
def _vertex_face_narrow(
    # in:
    faces: wp.array(dtype=wp.vec3i),
    pairs: wp.array(dtype=wp.vec2i),
    positions_t0: wp.array(dtype=wp.vec3),
    positions_t1: wp.array(dtype=wp.vec3),
    thickness: float,
    params: CcdParameters,
    moved: wp.array(dtype=wp.int32),
    only_moved: int,
    # out:
    toi_out: wp.array(dtype=wp.float32),
):
    """One thread per vertex-face candidate. With ``only_moved``, a pair none of whose vertices is
    marked in ``moved`` keeps its previous result (its trajectory has not changed)."""
    i = wp.tid()
    pair = pairs[i]
    v = pair[0]
    f = faces[pair[1]]
    if only_moved != 0:
        if moved[v] + moved[f[0]] + moved[f[1]] + moved[f[2]] == 0:
            return
    toi_out[i] = vertex_face_ccd_toi(
        positions_t0[v], positions_t0[f[0]], positions_t0[f[1]], positions_t0[f[2]],
        positions_t1[v], positions_t1[f[0]], positions_t1[f[1]], positions_t1[f[2]],
        thickness, 0.0, params,
    )


@wp.kernel
def _edge_edge_narrow(
    # in:
    edges: wp.array(dtype=wp.vec2i),
    pairs: wp.array(dtype=wp.vec2i),
    positions_t0: wp.array(dtype=wp.vec3),
    positions_t1: wp.array(dtype=wp.vec3),
    thickness: float,
    params: CcdParameters,
    moved: wp.array(dtype=wp.int32),
    only_moved: int,
    # out:
    toi_out: wp.array(dtype=wp.float32),
):
    """One thread per edge-edge candidate (``moved``, ``only_moved``: as for vertex-face)."""
    i = wp.tid()
    pair = pairs[i]
    a = edges[pair[0]]
    b = edges[pair[1]]
    if only_moved != 0:
        if moved[a[0]] + moved[a[1]] + moved[b[0]] + moved[b[1]] == 0:
            return
    toi_out[i] = edge_edge_ccd_toi(
        positions_t0[a[0]], positions_t0[a[1]], positions_t0[b[0]], positions_t0[b[1]],
        positions_t1[a[0]], positions_t1[a[1]], positions_t1[b[0]], positions_t1[b[1]],
        thickness, 0.0, params,
    )


@wp.kernel
def _mark_moved(
    # in:
    old_t0: wp.array(dtype=wp.vec3),
    new_t0: wp.array(dtype=wp.vec3),
    old_t1: wp.array(dtype=wp.vec3),
    new_t1: wp.array(dtype=wp.vec3),
    # out:
    moved: wp.array(dtype=wp.int32),
):
    """One thread per vertex: 1 when its start or end position differs from the last CCD run's
    (coordinate comparison: NaN counts as changed, -0 equals +0)."""
    v = wp.tid()
    a = old_t0[v]
    b = new_t0[v]
    c = old_t1[v]
    d = new_t1[v]
    changed = int(0)
    for k in range(3):
        if a[k] != b[k] or c[k] != d[k]:
            changed = 1
    moved[v] = changed


@wp.struct
class ProximityParameters:
    """Bounds of the closed-form distance fast path of discrete proximity (see :class:`NarrowPhase`)."""

    distance_error: wp.float32  # C x EPS32: |d_float32 - d_exact| <= distance_error x L (well-shaped)
    well_shaped_flatness: wp.float32  # smallest |ab x ac|^2 / max_edge^4 the bound covers


def proximity_parameters() -> ProximityParameters:
    """The fast-path bounds from :mod:`pscc.geometry.distance_tolerances`, with a safety factor of 2."""
    params = ProximityParameters()
    params.distance_error = 2.0 * distance_tolerances.DISTANCE_ERROR_CONST * 2.0**-23
    params.well_shaped_flatness = distance_tolerances.WELL_SHAPED_MIN_FLATNESS
    return params


@wp.func
def _local_scale(a: wp.vec3, b: wp.vec3, c: wp.vec3, d: wp.vec3) -> float:
    m = wp.max(wp.max(wp.abs(b - a), wp.abs(c - a)), wp.abs(d - a))
    return wp.max(m[0], wp.max(m[1], m[2]))


@wp.func
def _within(distance_sq: float, thickness: float, error: float) -> float:
    """0 (contact) when the computed distance may be within the thickness, else ``NO_HIT`` (2).

    With |d_float32 - d_exact| <= error / 2, a pair reported beyond is truly farther than the
    thickness, and a reported pair is closer than ``thickness + 1.5 error``.
    """
    if wp.sqrt(distance_sq) <= thickness + error:
        return 0.0
    return 2.0


@wp.kernel
def _vertex_face_proximity(
    # in:
    faces: wp.array(dtype=wp.vec3i),
    pairs: wp.array(dtype=wp.vec2i),
    positions: wp.array(dtype=wp.vec3),
    thickness: float,
    params: CcdParameters,
    proximity: ProximityParameters,
    # out:
    toi_out: wp.array(dtype=wp.float32),
):
    """One thread per vertex-face candidate: closed-form distance for well-shaped faces, else the search."""
    i = wp.tid()
    pair = pairs[i]
    f = faces[pair[1]]
    p = positions[pair[0]]
    a = positions[f[0]]
    b = positions[f[1]]
    c = positions[f[2]]
    ab = b - a
    ac = c - a
    n = wp.cross(ab, ac)
    longest = wp.max(wp.max(wp.dot(ab, ab), wp.dot(ac, ac)), wp.dot(c - b, c - b))
    area_sq = wp.dot(n, n)
    if area_sq == 0.0 or area_sq >= proximity.well_shaped_flatness * longest * longest:
        error = proximity.distance_error * _local_scale(a, b, c, p)
        toi_out[i] = _within(vertex_face_distance_squared(p, a, b, c), thickness, error)
    else:
        # Nearly flat triangle: the closed form may overestimate; the inclusion search is exact-safe.
        toi_out[i] = vertex_face_ccd_toi(p, a, b, c, p, a, b, c, thickness, 0.0, params)


@wp.kernel
def _edge_edge_proximity(
    # in:
    edges: wp.array(dtype=wp.vec2i),
    pairs: wp.array(dtype=wp.vec2i),
    positions: wp.array(dtype=wp.vec3),
    thickness: float,
    params: CcdParameters,
    proximity: ProximityParameters,
    # out:
    toi_out: wp.array(dtype=wp.float32),
):
    """One thread per edge-edge candidate: closed-form distance (its bound holds for every edge pair)."""
    i = wp.tid()
    pair = pairs[i]
    ea = edges[pair[0]]
    eb = edges[pair[1]]
    a0 = positions[ea[0]]
    a1 = positions[ea[1]]
    b0 = positions[eb[0]]
    b1 = positions[eb[1]]
    error = proximity.distance_error * _local_scale(a0, a1, b0, b1)
    toi_out[i] = _within(edge_edge_distance_squared(a0, a1, b0, b1), thickness, error)


class NarrowPhase:
    """Runs the conservative test on candidate pairs (layout in the module docstring).

    Args:
        faces: (face_count,) ``wp.vec3i``.
        edges: (edge_count,) ``wp.vec2i``.
        device: Warp device.
    """

    def __init__(self, faces: wp.array, edges: wp.array, device: wp.Device) -> None:
        self.device = device
        self.faces = faces
        self.edges = edges
        self.params = ccd_parameters()
        self.proximity = proximity_parameters()
        self.vertex_face_toi = wp.empty(1, dtype=wp.float32, device=device)
        self.edge_edge_toi = wp.empty(1, dtype=wp.float32, device=device)
        self._no_marks = wp.zeros(1, dtype=wp.int32, device=device)
        self.moved = wp.zeros(0, dtype=wp.int32, device=device)

    @property
    def device_bytes(self) -> int:
        """Bytes held on the device."""
        return self.vertex_face_toi.capacity + self.edge_edge_toi.capacity + self.moved.capacity

    def mark_moved(self, old_t0: wp.array, new_t0: wp.array, old_t1: wp.array, new_t1: wp.array) -> wp.array:
        """Per-vertex int32 marks (``self.moved``): 1 where the start or end position changed.

        Allocates: once per vertex count. Capture-safe: yes after the first call.
        """
        if self.moved.shape[0] != old_t0.shape[0]:
            self.moved = wp.zeros(old_t0.shape[0], dtype=wp.int32, device=self.device)
        wp.launch(_mark_moved, dim=old_t0.shape[0], inputs=[old_t0, new_t0, old_t1, new_t1], outputs=[self.moved],
                  device=self.device)
        return self.moved

    def run(
        self,
        candidates: CandidatePairs,
        positions_t0: wp.array,
        positions_t1: wp.array,
        thickness: float,
        moved: wp.array | None = None,
    ) -> None:
        """Test the first ``count`` candidates of each kind (counts read by ``candidates.fits()``).

        ``moved`` (CCD only): per-vertex int32 marks (:meth:`mark_moved`); when given, only pairs with
        a marked vertex are tested again and the others keep the time of impact of the previous run,
        which must have been a CCD run on the same candidates and thickness, with every vertex whose
        start or end position changed since marked.

        Allocates: only when the candidate buffers grew. Capture-safe: no (sizes come from the host).
        """
        vf = candidates.vertex_face_count
        ee = candidates.edge_edge_count
        if self.vertex_face_toi.shape[0] < candidates.capacity_vf:
            self.vertex_face_toi = wp.empty(candidates.capacity_vf, dtype=wp.float32, device=self.device)
        if self.edge_edge_toi.shape[0] < candidates.capacity_ee:
            self.edge_edge_toi = wp.empty(candidates.capacity_ee, dtype=wp.float32, device=self.device)
        if positions_t1 is positions_t0:
            self._proximity(candidates, positions_t0, thickness)
            return
        only_moved = int(moved is not None)
        marks = moved if moved is not None else self._no_marks
        if vf > 0:
            wp.launch(_vertex_face_narrow, dim=vf,
                      inputs=[self.faces, candidates.vertex_face, positions_t0, positions_t1,
                              float(thickness), self.params, marks, only_moved],
                      outputs=[self.vertex_face_toi], device=self.device)
        if ee > 0:
            wp.launch(_edge_edge_narrow, dim=ee,
                      inputs=[self.edges, candidates.edge_edge, positions_t0, positions_t1,
                              float(thickness), self.params, marks, only_moved],
                      outputs=[self.edge_edge_toi], device=self.device)

    def _proximity(self, candidates: CandidatePairs, positions: wp.array, thickness: float) -> None:
        vf = candidates.vertex_face_count
        ee = candidates.edge_edge_count
        if vf > 0:
            wp.launch(_vertex_face_proximity, dim=vf,
                      inputs=[self.faces, candidates.vertex_face, positions, float(thickness), self.params,
                              self.proximity],
                      outputs=[self.vertex_face_toi], device=self.device)
        if ee > 0:
            wp.launch(_edge_edge_proximity, dim=ee,
                      inputs=[self.edges, candidates.edge_edge, positions, float(thickness), self.params,
                              self.proximity],
                      outputs=[self.edge_edge_toi], device=self.device)
