"""Narrow phase: the conservative CCD / proximity test on every candidate feature pair.

Every candidate pair goes through :func:`pscc.geometry.ccd.vertex_face_ccd_toi` or
:func:`pscc.geometry.ccd.edge_edge_ccd_toi`. Discrete detection (DCD) is the same test with the
end positions equal to the start positions: the pair is reported when it is provably within, or
possibly within (the documented tolerance band), the thickness.

======================  =====================  ===============================================
buffer                  shape, dtype           meaning
======================  =====================  ===============================================
vertex_face_toi         (capacity_vf,) f32     time of impact per vertex-face candidate; > 1 =
                                               no contact (``pscc.geometry.ccd.NO_HIT``)
edge_edge_toi           (capacity_ee,) f32     likewise per edge-edge candidate
toi_storage             (both,) f32            the one allocation the two above are views of
hit_counts              (2,) int32             valid rows with toi <= 1 after the last run:
                                               [vertex-face, edge-edge]
moved                   (vertex_count,) int32  per-vertex marks of the CCD re-check
======================  =====================  ===============================================

Every kernel is a row kernel (:mod:`pscc._lanes`: one thread per slot of its candidate buffer on a GPU,
one thread over all rows on the CPU) and reads the number of valid rows from ``candidates.counts`` on the
device (clamped to the buffers), so :meth:`NarrowPhase.run_device`
reads nothing back and can be captured into a graph. The time-of-impact buffers are at least as long
as the candidate buffers (:meth:`NarrowPhase.reserve`, called by the owner after
:meth:`CandidatePairs.fits` grew them), and :meth:`NarrowPhase.contacts` hands the rows to the
consumers of :mod:`pscc.collision.contacts`. Rows past the count are neither written nor counted.
"""

from __future__ import annotations

import warp as wp

from pscc._lanes import row_lanes
from pscc.collision.candidates import CandidatePairs, valid_rows
from pscc.collision.contacts import ContactArgs, DeviceContacts
from pscc.collision.pair_filter import segments_separated
from pscc.collision.scratch import view
from pscc.geometry import distance_tolerances
from pscc.geometry.ccd import NO_HIT, CcdParameters, ccd_parameters, edge_edge_ccd_toi, vertex_face_ccd_toi
from pscc.geometry.distance import (
    edge_edge_closest_point,
    edge_edge_distance_squared,
    edge_edge_distance_squared_at,
    projection_outside_triangle,
    vertex_face_closest_point,
    vertex_face_distance_squared,
    vertex_face_distance_squared_at,
)
from pscc.geometry.distance_tolerances import EPS32 as _EPS32_VALUE

wp.set_module_options({"enable_backward": False})

EPS32 = wp.constant(wp.float32(_EPS32_VALUE))


@wp.struct
class CcdDistance:
    """The distance a CCD run tests, and what it asks of pairs that start closer than it.

    ``inside_share`` = 0: a pair that starts within ``distance`` is a contact at t = 0, as the CCD
    defines it. ``inside_share`` = s > 0: a pair the CCD finds at t = 0 (inside the distance, or so
    near it that the rounding bound cannot tell) is tested again at s times the smaller of its start
    distance and ``distance``, so it is a contact only if it comes that much closer within the step.
    End positions cannot undo a contact at t = 0; with s > 0 a response can still keep the pair from
    closing in, and the pair still never crosses.
    """

    distance: float
    inside_share: float


@wp.kernel
def _vertex_face_narrow(
    # in:
    faces: wp.array(dtype=wp.vec3i),
    pairs: wp.array(dtype=wp.vec2i),
    positions_t0: wp.array(dtype=wp.vec3),
    positions_t1: wp.array(dtype=wp.vec3),
    distance: CcdDistance,
    params: CcdParameters,
    moved: wp.array(dtype=wp.int32),
    only_moved: int,
    counts: wp.array(dtype=wp.int32),
    lanes: int,
    # out:
    toi_out: wp.array(dtype=wp.float32),
    hit_counts: wp.array(dtype=wp.int32),
):
    """Row kernel (:mod:`pscc._lanes`) over the valid vertex-face rows (``counts[0]``, clamped).
    With ``only_moved``, a pair none of whose vertices is marked in ``moved`` keeps its previous
    result (its trajectory has not changed). A pair found at t = 0 is tested again at ``inside_share`` of
    its start distance (at most the distance; :class:`CcdDistance`). Every valid row with toi <= 1 adds 1
    to ``hit_counts[0]``."""
    for i in range(wp.tid(), valid_rows(counts, 0, wp.min(pairs.shape[0], toi_out.shape[0])), lanes):
        pair = pairs[i]
        v = pair[0]
        f = faces[pair[1]]
        # Nested ifs: Warp evaluates both operands of ``and`` (``moved`` may be a 1-element dummy).
        retest = int(1)
        if only_moved != 0:
            if moved[v] + moved[f[0]] + moved[f[1]] + moved[f[2]] == 0:
                retest = 0
        toi = float(0.0)
        if retest == 0:
            toi = toi_out[i]
        else:
            toi = vertex_face_ccd_toi(
                positions_t0[v], positions_t0[f[0]], positions_t0[f[1]], positions_t0[f[2]],
                positions_t1[v], positions_t1[f[0]], positions_t1[f[1]], positions_t1[f[2]],
                distance.distance, 0.0, params,
            )
            if toi <= 0.0 and distance.inside_share > 0.0:
                start = wp.sqrt(vertex_face_distance_squared(positions_t0[v], positions_t0[f[0]],
                                                             positions_t0[f[1]], positions_t0[f[2]]))
                toi = vertex_face_ccd_toi(
                    positions_t0[v], positions_t0[f[0]], positions_t0[f[1]], positions_t0[f[2]],
                    positions_t1[v], positions_t1[f[0]], positions_t1[f[1]], positions_t1[f[2]],
                    distance.inside_share * wp.min(start, distance.distance), 0.0, params,
                )
            toi_out[i] = toi
        if toi <= 1.0:
            wp.atomic_add(hit_counts, 0, 1)


@wp.kernel
def _edge_edge_narrow(
    # in:
    edges: wp.array(dtype=wp.vec2i),
    pairs: wp.array(dtype=wp.vec2i),
    positions_t0: wp.array(dtype=wp.vec3),
    positions_t1: wp.array(dtype=wp.vec3),
    distance: CcdDistance,
    params: CcdParameters,
    moved: wp.array(dtype=wp.int32),
    only_moved: int,
    counts: wp.array(dtype=wp.int32),
    lanes: int,
    # out:
    toi_out: wp.array(dtype=wp.float32),
    hit_counts: wp.array(dtype=wp.int32),
):
    """Row kernel (:mod:`pscc._lanes`) over the valid edge-edge rows (``counts[1]``, clamped;
    ``moved``, ``only_moved``, ``distance``, ``hit_counts[1]``: as for vertex-face)."""
    for i in range(wp.tid(), valid_rows(counts, 1, wp.min(pairs.shape[0], toi_out.shape[0])), lanes):
        pair = pairs[i]
        a = edges[pair[0]]
        b = edges[pair[1]]
        # Nested ifs: Warp evaluates both operands of ``and`` (``moved`` may be a 1-element dummy).
        retest = int(1)
        if only_moved != 0:
            if moved[a[0]] + moved[a[1]] + moved[b[0]] + moved[b[1]] == 0:
                retest = 0
        toi = float(0.0)
        if retest == 0:
            toi = toi_out[i]
        else:
            toi = edge_edge_ccd_toi(
                positions_t0[a[0]], positions_t0[a[1]], positions_t0[b[0]], positions_t0[b[1]],
                positions_t1[a[0]], positions_t1[a[1]], positions_t1[b[0]], positions_t1[b[1]],
                distance.distance, 0.0, params,
            )
            if toi <= 0.0 and distance.inside_share > 0.0:
                start = wp.sqrt(edge_edge_distance_squared(positions_t0[a[0]], positions_t0[a[1]],
                                                           positions_t0[b[0]], positions_t0[b[1]]))
                toi = edge_edge_ccd_toi(
                    positions_t0[a[0]], positions_t0[a[1]], positions_t0[b[0]], positions_t0[b[1]],
                    positions_t1[a[0]], positions_t1[a[1]], positions_t1[b[0]], positions_t1[b[1]],
                    distance.inside_share * wp.min(start, distance.distance), 0.0, params,
                )
            toi_out[i] = toi
        if toi <= 1.0:
            wp.atomic_add(hit_counts, 1, 1)


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
    thin_overestimate: wp.float32  # bound / L on how much the closed form overestimates on a thin face
    edge_separation: wp.int32  # 1: edge pairs certified apart by their common normal skip the closed form


def proximity_parameters() -> ProximityParameters:
    """The fast-path bounds from :mod:`pscc.geometry.distance_tolerances`, with a safety factor of 2."""
    params = ProximityParameters()
    params.distance_error = 2.0 * distance_tolerances.DISTANCE_ERROR_CONST * 2.0**-23
    params.well_shaped_flatness = distance_tolerances.WELL_SHAPED_MIN_FLATNESS
    params.thin_overestimate = 2.0 * distance_tolerances.ILL_CONDITIONED_REL_ERROR
    params.edge_separation = 1
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


@wp.func
def vertex_face_proximity_toi(
    p: wp.vec3, a: wp.vec3, b: wp.vec3, c: wp.vec3, w: wp.vec3, thickness: float, params: CcdParameters,
    proximity: ProximityParameters,
) -> float:
    """0 when vertex p may be within ``thickness`` of triangle (a, b, c), else ``NO_HIT``: closed-form
    distance (``w``: the closest point's barycentric weights,
    :func:`pscc.geometry.distance.vertex_face_closest_point`) for well-shaped faces; for nearly flat
    ones too, except in a narrow band past the thickness, where the search decides.

    On a nearly flat face the closed form is still never below the exact distance by more than the
    rounding bound (its weights are a convex combination), so a pair it puts within the thickness
    is a contact as on a well-shaped face; it may overestimate by at most
    ``thin_overestimate x L`` (``ILL_CONDITIONED_REL_ERROR``, doubled), so a pair beyond the
    thickness by more than that is not.

    A pair in between whose projection is certified outside the face
    (:func:`pscc.geometry.distance.projection_outside_triangle`) has its closest point on an edge, so the
    smallest of the three point-edge distances decides it, each within the edge-edge bound (``error / 2``
    at the edge's own local scale, at most twice the face's) and 7 ``EPS32 L`` more for the rounded points
    of the certificate: within ``thickness + error / 2`` it is a contact (truly within ``thickness + 1.5
    error``, as every reported pair), beyond ``thickness + 1.75 error`` it is not (truly beyond ``thickness
    + error / 2``, as every rejected pair). Only the rest run the exact-safe inclusion search."""
    ab = b - a
    ac = c - a
    n = wp.cross(ab, ac)
    longest = wp.max(wp.max(wp.dot(ab, ab), wp.dot(ac, ac)), wp.dot(c - b, c - b))
    area_sq = wp.dot(n, n)
    scale = _local_scale(a, b, c, p)
    error = proximity.distance_error * scale
    distance_sq = vertex_face_distance_squared_at(p, a, b, c, w)
    if area_sq == 0.0 or area_sq >= proximity.well_shaped_flatness * longest * longest:
        return _within(distance_sq, thickness, error)
    # Nearly flat triangle: the closed form may overestimate, by at most thin_overestimate x L.
    distance = wp.sqrt(distance_sq)
    if distance <= thickness + error:
        return 0.0
    if distance > thickness + error + proximity.thin_overestimate * scale:
        return 2.0
    if projection_outside_triangle(p, a, b, c):
        edge_sq = wp.min(wp.min(edge_edge_distance_squared(a, b, p, p), edge_edge_distance_squared(b, c, p, p)),
                         edge_edge_distance_squared(c, a, p, p))
        edge_distance = wp.sqrt(edge_sq)
        if edge_distance <= thickness + 0.5 * error:
            return 0.0
        if edge_distance > thickness + 1.75 * error:
            return 2.0
    return vertex_face_ccd_toi(p, a, b, c, p, a, b, c, thickness, 0.0, params)


@wp.func
def edge_edge_proximity_toi(
    a0: wp.vec3, a1: wp.vec3, b0: wp.vec3, b1: wp.vec3, st: wp.vec2, thickness: float,
    proximity: ProximityParameters,
) -> float:
    """0 when the segments may be within ``thickness``, else ``NO_HIT``: the closed-form distance at the
    closest points' parameters ``st`` (:func:`pscc.geometry.distance.edge_edge_closest_point`; its bound
    holds for every edge pair)."""
    error = proximity.distance_error * _local_scale(a0, a1, b0, b1)
    return _within(edge_edge_distance_squared_at(a0, a1, b0, b1, st), thickness, error)


@wp.func
def edges_certified_apart(a0: wp.vec3, a1: wp.vec3, b0: wp.vec3, b1: wp.vec3, thickness: float,
                          proximity: ProximityParameters) -> bool:
    """Whether the discrete test may skip the closed form: the segments are certified farther apart than
    ``thickness`` by the plane normal to both (:func:`pscc.collision.pair_filter.segments_separated`, with
    its own rounding bound). Such a pair gets ``NO_HIT``. Its distance may still be within the closed
    form's tolerance band past the thickness, where :func:`edge_edge_proximity_toi` would report it: a
    separated pair is farther than the thickness, so it is not a contact by either test's definition."""
    if proximity.edge_separation == 0:
        return False
    return segments_separated(a0, a1, b0, b1, thickness)


@wp.func
def certain_contact_sq(thickness: float) -> float:
    """The squared length below which two points are certified within ``thickness`` of each other by
    :func:`points_within`: ``thickness^2`` shrunk by ``8 EPS32``, more than the rounding of both squares
    (the computed ``|p - q|^2`` is at least ``(1 - 7u) |p - q|^2`` and this bound at most ``(1 - 14u)
    thickness^2``, ``u = 2**-24``), so a certified pair is truly closer than ``thickness`` (for a
    thickness whose square is a normal float32, above about ``1e-19``)."""
    return thickness * thickness * (1.0 - 8.0 * EPS32)


@wp.func
def points_within(p: wp.vec3, q: wp.vec3, certain_sq: float) -> bool:
    """Whether ``p`` and ``q`` are certified closer than the thickness whose :func:`certain_contact_sq` is
    ``certain_sq``. A feature pair with such a pair of points (a vertex and a corner of the face, an end
    of each edge) is a contact without its closest points: dense contact, where most rows hold one, skips
    the closed form for them."""
    d = p - q
    return wp.dot(d, d) < certain_sq


@wp.func
def corner_within(p: wp.vec3, a: wp.vec3, b: wp.vec3, c: wp.vec3, certain_sq: float) -> bool:
    """Whether vertex ``p`` is certified within the thickness of a corner of face ``(a, b, c)``
    (:func:`points_within`)."""
    return points_within(p, a, certain_sq) or points_within(p, b, certain_sq) or points_within(p, c, certain_sq)


@wp.func
def ends_within(a0: wp.vec3, a1: wp.vec3, b0: wp.vec3, b1: wp.vec3, certain_sq: float) -> bool:
    """Whether an end of edge ``(a0, a1)`` is certified within the thickness of an end of edge ``(b0, b1)``
    (:func:`points_within`)."""
    return (points_within(a0, b0, certain_sq) or points_within(a0, b1, certain_sq)
            or points_within(a1, b0, certain_sq) or points_within(a1, b1, certain_sq))


@wp.struct
class ProximityTest:
    """The discrete proximity test of a narrow phase, for a kernel that runs it itself
    (:meth:`NarrowPhase.proximity_test`)."""

    thickness: wp.float32
    params: CcdParameters
    proximity: ProximityParameters


@wp.kernel
def _vertex_face_proximity(
    # in:
    faces: wp.array(dtype=wp.vec3i),
    pairs: wp.array(dtype=wp.vec2i),
    positions: wp.array(dtype=wp.vec3),
    thickness: float,
    params: CcdParameters,
    proximity: ProximityParameters,
    counts: wp.array(dtype=wp.int32),
    lanes: int,
    # out:
    toi_out: wp.array(dtype=wp.float32),
    hit_counts: wp.array(dtype=wp.int32),
):
    """Row kernel (:mod:`pscc._lanes`) over the valid vertex-face rows (``counts[0]``, clamped):
    a vertex certified within the thickness of a face corner (:func:`corner_within`) is a contact, the
    others go through :func:`vertex_face_proximity_toi`; hits add 1 to ``hit_counts[0]``."""
    certain_sq = certain_contact_sq(thickness)
    for i in range(wp.tid(), valid_rows(counts, 0, wp.min(pairs.shape[0], toi_out.shape[0])), lanes):
        pair = pairs[i]
        f = faces[pair[1]]
        p = positions[pair[0]]
        a = positions[f[0]]
        b = positions[f[1]]
        c = positions[f[2]]
        toi = float(0.0)
        if not corner_within(p, a, b, c, certain_sq):
            toi = vertex_face_proximity_toi(p, a, b, c, vertex_face_closest_point(p, a, b, c), thickness, params,
                                            proximity)
        toi_out[i] = toi
        if toi <= 1.0:
            wp.atomic_add(hit_counts, 0, 1)


@wp.kernel
def _edge_edge_proximity(
    # in:
    edges: wp.array(dtype=wp.vec2i),
    pairs: wp.array(dtype=wp.vec2i),
    positions: wp.array(dtype=wp.vec3),
    thickness: float,
    proximity: ProximityParameters,
    counts: wp.array(dtype=wp.int32),
    lanes: int,
    # out:
    toi_out: wp.array(dtype=wp.float32),
    hit_counts: wp.array(dtype=wp.int32),
):
    """Row kernel (:mod:`pscc._lanes`) over the valid edge-edge rows (``counts[1]``, clamped):
    a pair with ends certified within the thickness (:func:`ends_within`) is a contact, the others go
    through the separation certificate and the closed-form distance (its bound holds for every edge pair);
    hits add 1 to ``hit_counts[1]``."""
    certain_sq = certain_contact_sq(thickness)
    for i in range(wp.tid(), valid_rows(counts, 1, wp.min(pairs.shape[0], toi_out.shape[0])), lanes):
        pair = pairs[i]
        ea = edges[pair[0]]
        eb = edges[pair[1]]
        a0 = positions[ea[0]]
        a1 = positions[ea[1]]
        b0 = positions[eb[0]]
        b1 = positions[eb[1]]
        toi = float(0.0)
        if not ends_within(a0, a1, b0, b1, certain_sq):
            toi = float(NO_HIT)
            if not edges_certified_apart(a0, a1, b0, b1, thickness, proximity):
                toi = edge_edge_proximity_toi(a0, a1, b0, b1, edge_edge_closest_point(a0, a1, b0, b1), thickness,
                                              proximity)
        toi_out[i] = toi
        if toi <= 1.0:
            wp.atomic_add(hit_counts, 1, 1)


class NarrowPhase:
    """Runs the conservative test on candidate pairs (layout in the module docstring).

    :meth:`run_device` is the device path (launches at the candidate capacities, no host read,
    capturable); :meth:`run` is the host API on top of it. The owner keeps the time-of-impact buffers
    as long as the candidate buffers with :meth:`reserve` after every :meth:`CandidatePairs.fits`
    (the only place the candidate buffers grow).

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
        self._allocate_toi(1, 1)
        self.hit_counts = wp.zeros(2, dtype=wp.int32, device=device)
        self._no_marks = wp.zeros(1, dtype=wp.int32, device=device)
        self.moved = wp.zeros(0, dtype=wp.int32, device=device)
        self._continuous = False
        self._thickness = 0.0

    @property
    def device_bytes(self) -> int:
        """Bytes held on the device."""
        return (self.toi_storage.capacity + self.moved.capacity
                + self.hit_counts.capacity)

    def reserve(self, candidates: CandidatePairs) -> None:
        """Size the time-of-impact buffers to the candidates' capacities (contents not kept).

        Reads nothing from the device; call it after :meth:`CandidatePairs.fits` or
        :meth:`CandidatePairs.trim` (which may resize the candidates) and before :meth:`run_device`.
        Allocates: only when the candidate buffers were resized. Capture-safe: no.
        """
        if (self.vertex_face_toi.shape[0], self.edge_edge_toi.shape[0]) != (candidates.capacity_vf,
                                                                             candidates.capacity_ee):
            self._allocate_toi(candidates.capacity_vf, candidates.capacity_ee)

    def _allocate_toi(self, capacity_vf: int, capacity_ee: int) -> None:
        """One buffer for both kinds of times of impact (contents not kept; a block a simulator can lend
        out between uses): :attr:`vertex_face_toi` and :attr:`edge_edge_toi` are views of its parts."""
        self.toi_storage = wp.empty(capacity_vf + capacity_ee, dtype=wp.float32, device=self.device)
        # Views made from the address (scratch.view), not slices: with slices of the storage, a CPU graph
        # recorded right after the storage was replaced held no operations (Warp 1.19).
        self.vertex_face_toi = view(self.toi_storage, 0, capacity_vf, wp.float32)
        self.edge_edge_toi = view(self.toi_storage, 4 * capacity_vf, capacity_ee, wp.float32)

    def mark_moved(self, old_t0: wp.array, new_t0: wp.array, old_t1: wp.array, new_t1: wp.array) -> wp.array:
        """Per-vertex int32 marks (``self.moved``): 1 where the start or end position changed.

        Allocates: once per vertex count. Capture-safe: yes after the first call.
        """
        if self.moved.shape[0] != old_t0.shape[0]:
            self.moved = wp.zeros(old_t0.shape[0], dtype=wp.int32, device=self.device)
        wp.launch(_mark_moved, dim=old_t0.shape[0], inputs=[old_t0, new_t0, old_t1, new_t1], outputs=[self.moved],
                  device=self.device)
        return self.moved

    def run_device(
        self,
        candidates: CandidatePairs,
        positions_t0: wp.array,
        positions_t1: wp.array,
        thickness: float,
        moved: wp.array | None = None,
        defer_dcd: bool = False,
        inside_share: float = 0.0,
    ) -> None:
        """Test the valid candidates of each kind, reading their numbers from ``candidates.counts``
        on the device (clamped to the buffers), and fill :attr:`hit_counts`.

        DCD when ``positions_t1`` is ``positions_t0`` (hits get toi 0, misses 2), CCD otherwise.
        ``moved`` (CCD only): per-vertex int32 marks (:meth:`mark_moved`); when given, only pairs with
        a marked vertex are tested again and the others keep the time of impact of the previous run,
        which must have been a CCD run on the same candidates and thickness, with every vertex whose
        start or end position changed since marked. ``hit_counts`` counts the valid rows with
        toi <= 1, kept rows included.

        Args:
            candidates: the candidate pairs (their buffers at most as long as the toi buffers).
            positions_t0: (vertex_count,) ``wp.vec3`` start positions (DCD: the positions).
            positions_t1: (vertex_count,) ``wp.vec3`` end positions, or ``positions_t0`` itself (DCD).
            thickness: the distance tested (length units).
            moved: optional (vertex_count,) int32 marks of the CCD re-check.
            defer_dcd: DCD only: zero :attr:`hit_counts` but launch nothing; a consumer that runs the
                same test in its own kernel (:meth:`proximity_test`, e.g.
                :meth:`pscc.sim.proximity.ProximityContacts.test_and_update_device`) writes the times of
                impact and the hit counts, bit for bit as this method would.
            inside_share: CCD only: 0 (a pair that starts within ``thickness`` is a contact at t = 0),
                or s in (0, 1): a pair found at t = 0 is a contact only if it comes within s times the
                smaller of its start distance and ``thickness`` (:class:`CcdDistance`; the simulator's
                response loop, which cannot undo a contact at t = 0).

        Raises:
            ValueError: the toi buffers are shorter than the candidate buffers (call :meth:`reserve`).

        Allocates: no. Capture-safe: yes.
        """
        if (self.vertex_face_toi.shape[0] < candidates.capacity_vf
                or self.edge_edge_toi.shape[0] < candidates.capacity_ee):
            raise ValueError(
                f"time-of-impact buffers ({self.vertex_face_toi.shape[0]}, {self.edge_edge_toi.shape[0]}) are "
                f"shorter than the candidate buffers ({candidates.capacity_vf}, {candidates.capacity_ee}); "
                "call NarrowPhase.reserve(candidates) after CandidatePairs.fits()")
        self.hit_counts.zero_()
        self._continuous = positions_t1 is not positions_t0
        self._thickness = float(thickness)
        lanes_vf = row_lanes(self.device, candidates.capacity_vf)
        lanes_ee = row_lanes(self.device, candidates.capacity_ee)
        if positions_t1 is positions_t0 and defer_dcd:
            return
        if positions_t1 is positions_t0:
            wp.launch(_vertex_face_proximity, dim=lanes_vf,
                      inputs=[self.faces, candidates.vertex_face, positions_t0, float(thickness), self.params,
                              self.proximity, candidates.counts, lanes_vf],
                      outputs=[self.vertex_face_toi, self.hit_counts], device=self.device)
            wp.launch(_edge_edge_proximity, dim=lanes_ee,
                      inputs=[self.edges, candidates.edge_edge, positions_t0, float(thickness), self.proximity,
                              candidates.counts, lanes_ee],
                      outputs=[self.edge_edge_toi, self.hit_counts], device=self.device)
            return
        only_moved = int(moved is not None)
        marks = moved if moved is not None else self._no_marks
        if not 0.0 <= float(inside_share) < 1.0:
            raise ValueError(f"inside_share {inside_share!r} is not in [0, 1)")
        distance = CcdDistance()
        distance.distance = float(thickness)
        distance.inside_share = float(inside_share)
        wp.launch(_vertex_face_narrow, dim=lanes_vf,
                  inputs=[self.faces, candidates.vertex_face, positions_t0, positions_t1, distance,
                          self.params, marks, only_moved, candidates.counts, lanes_vf],
                  outputs=[self.vertex_face_toi, self.hit_counts], device=self.device)
        wp.launch(_edge_edge_narrow, dim=lanes_ee,
                  inputs=[self.edges, candidates.edge_edge, positions_t0, positions_t1, distance,
                          self.params, marks, only_moved, candidates.counts, lanes_ee],
                  outputs=[self.edge_edge_toi, self.hit_counts], device=self.device)

    def proximity_test(self, thickness: float) -> ProximityTest:
        """The discrete test of :meth:`run_device` (DCD at ``thickness``) for a kernel that runs it itself
        (:func:`vertex_face_proximity_toi`, :func:`edge_edge_proximity_toi`). Allocates: no (a host
        struct). Capture-safe: yes."""
        test = ProximityTest()
        test.thickness = float(thickness)
        test.params = self.params
        test.proximity = self.proximity
        return test

    def run(
        self,
        candidates: CandidatePairs,
        positions_t0: wp.array,
        positions_t1: wp.array,
        thickness: float,
        moved: wp.array | None = None,
    ) -> None:
        """Test the valid candidates (host API): :meth:`reserve`, then :meth:`run_device`.

        Arguments as for :meth:`run_device`; the candidates' counts are read on the device, so the
        rows tested are those of the last broad phase (after :meth:`CandidatePairs.fits` accepted it).

        Allocates: only when the candidate buffers grew. Capture-safe: no.
        """
        self.reserve(candidates)
        self.run_device(candidates, positions_t0, positions_t1, thickness, moved=moved)

    def contacts(self, candidates: CandidatePairs, *, continuous: bool | None = None,
                 thickness: float | None = None) -> DeviceContacts:
        """The device view of the last run's results (:mod:`pscc.collision.contacts`).

        Args:
            candidates: the candidates the last :meth:`run_device` tested.
            continuous: whether that run was a CCD (default: as recorded by the last run).
            thickness: the distance it tested (default: as recorded by the last run).

        Returns:
            A :class:`DeviceContacts` whose ``args`` name the faces, edges, candidate rows, toi
            buffers and ``candidates.counts``, and whose ``hit_counts`` is :attr:`hit_counts`; all
            stay valid until the buffers grow (:meth:`CandidatePairs.fits` / :meth:`reserve`).

        Allocates: no (a host struct only). Capture-safe: yes.
        """
        args = ContactArgs()
        args.faces = self.faces
        args.edges = self.edges
        args.vertex_face = candidates.vertex_face
        args.edge_edge = candidates.edge_edge
        args.vertex_face_toi = self.vertex_face_toi
        args.edge_edge_toi = self.edge_edge_toi
        args.counts = candidates.counts
        return DeviceContacts(
            args=args,
            hit_counts=self.hit_counts,
            continuous=self._continuous if continuous is None else bool(continuous),
            thickness=self._thickness if thickness is None else float(thickness),
        )
