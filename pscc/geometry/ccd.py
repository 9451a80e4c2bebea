"""Conservative continuous collision detection (CCD) for vertex-face and edge-edge pairs.

Vertices move linearly over the step, x(t) = (1 - t) x_t0 + t x_t1 with t in [0, 1]. Both primitive
pairs reduce to the roots of one multilinear function of three parameters (the formulation of
Tight Inclusion, Wang et al. 2021):

- vertex-face (p; a, b, c):   F(t, u, v) = (p - a) + u (a - b) + v (a - c),  u, v >= 0, u + v <= 1
- edge-edge (a0 a1; b0 b1):   F(t, u, v) = (a0 - b0) + u (a1 - a0) + v (b0 - b1),  u, v in [0, 1]

with every point taken at time t. The pair comes within distance ``d_min`` at time t exactly when
|F(t, u, v)| <= d_min for some admissible (u, v). F is linear in each parameter separately, so over
a box of parameters its values lie in the bounding box of its 8 corner values.

**Swept-box filter.** First of all, a pair is excluded when the bounding boxes of its two features'
start and end positions are farther apart than ``d_min``. A vertex moving linearly stays in the box of
its start and end, so every point of a feature stays in its box over the whole step, and the distance
between the boxes bounds the distance of the features from below. The boxes are taken on the input
coordinates (minimum and maximum are exact), each axis gap is reduced by twice the input rounding
``extra_error`` and the comparison carries a relative margin far above float32 rounding, so a pair that
could come within ``d_min`` is never excluded. This is the common case of a step's candidates: the broad
phase pairs features whose boxes come within the thickness h, and the CCD tests the much smaller
``d_min``; the test costs a few comparisons where the distance below costs tens of operations.

**Motion-bound filter.** Next, a pair is excluded when its distance at t0, bounded
from below with the distance functions' documented float32 error, exceeds ``d_min`` plus the largest
motion of F over the step (|F(t)| >= |F(0)| - max |F(1) - F(0)|, the maximum taken at the corners of
the (u, v) domain). Resting and slowly moving pairs, the grazing queries that cost the search the most
boxes, end here.

**Plane filter** (minimum distance > 0). Then a pair is excluded when its first feature provably stays
farther than ``d_min`` from the moving plane of the second (:func:`plane_keeps_distance`, docs/ccd.md).

**Conservative advancement** (minimum distance > 0 with the distance tolerance
:data:`pscc.tolerances.CCD_DISTANCE_TOLERANCE` on, for a pair that starts clear of the tolerance's band).
For fixed (u, v), F is linear in t, so the pair's distance at time s is at least its distance at t minus
|s - t| times the largest |dF/dt| (a corner value). Starting at t = 0, every step bounds the distance
from below with the closest-point functions of :mod:`pscc.geometry.distance` (their documented error and
``err`` subtracted), excludes the time that distance minus ``d_min`` buys at that speed and jumps there.
It reports a contact at t once the bound is within half the tolerance of ``d_min``, ``NO_HIT`` once the
rest of the step is excluded, and hands the rest of the step to the search below after
:data:`pscc.tolerances.CCD_ADVANCE_STEPS` steps. A reported time is a lower bound of the first contact,
and the pair is then within ``d_min (1 + tolerance)`` of touching. On a late `twisting` frame this decides
the pairs that come within ``d_min`` in 3-5 µs each where the search took 50-150 µs.

**Search.** A depth-first search over (t, u, v) boxes with a fixed per-thread stack. A box is
*excluded* when the bounding box of its corner values, grown by the rounding bound ``err``, stays
farther than ``d_min`` from the origin (Euclidean). Boxes are split along the parameter whose
change moves F the most; the earlier half in t is searched first, and once a collision time
``toi`` is known every box starting at or after it is skipped. A box that is too small to split
(see :mod:`pscc.tolerances`) is reported as a collision at its start time. If the stack or the box
budget runs out, the search stops and reports the earliest start time among the boxes not yet
excluded. Hence:

- a pair that truly comes within ``d_min`` is never missed, and
- the reported time of impact is never later than the true first time of contact,

provided ``err`` bounds the float32 rounding of F. That bound is derived in
:data:`pscc.tolerances.CCD_ROUNDING_FACTOR`: per axis, ``err = 80 u M`` where u = 2^-24 and M is
the largest coordinate magnitude after translating the query to its first point. The host
wrappers add the rounding of float64 input to float32 when the input is not exactly float32, so
the answer is conservative for the input as given.

The stages live in their own modules: :mod:`pscc.geometry.ccd_filters` (swept box, motion bound, plane
tests), :mod:`pscc.geometry.ccd_advance` (start-band guard, conservative advancement),
:mod:`pscc.geometry.ccd_search` (box search) and :mod:`pscc.geometry.ccd_base` (parameters, margins).
This module holds the per-query set-up, the two device functions and the host API. Every function here
runs unchanged on CUDA and on the CPU.
"""

from __future__ import annotations

import numpy as np
import warp as wp

from pscc import tolerances
from pscc._checks import check_nonnegative, check_points
from pscc.errors import InputError
from pscc.geometry.ccd_advance import advance_to_contact, query_distance_tolerance
from pscc.geometry.ccd_base import MOTION_MARGIN, NO_HIT, CcdParameters, ccd_parameters
from pscc.geometry.ccd_filters import (
    coplanarity_sign,
    features_apart,
    motion_cannot_reach,
    never_coplanar,
    plane_keeps_distance,
    vertex_plane_side,
)
from pscc.geometry.ccd_search import ccd_search
from pscc.geometry.distance import edge_edge_distance_squared, vertex_face_distance_squared

__all__ = [
    "NO_HIT",
    "CcdParameters",
    "ccd_parameters",
    "coplanarity_sign",
    "edge_edge_ccd",
    "edge_edge_ccd_toi",
    "input_rounding_error",
    "plane_keeps_distance",
    "vertex_face_ccd",
    "vertex_face_ccd_toi",
    "vertex_plane_side",
]

wp.set_module_options({"enable_backward": False})


@wp.func
def _abs_max(m: wp.vec3, x: wp.vec3) -> wp.vec3:
    return wp.vec3(wp.max(m[0], wp.abs(x[0])), wp.max(m[1], wp.abs(x[1])), wp.max(m[2], wp.abs(x[2])))


@wp.func
def _query_error(scale_axes: wp.vec3, extra_error: float, params: CcdParameters) -> wp.vec3:
    """Per-axis bound on |F_float32 - F_exact| for a query of per-axis magnitude ``scale_axes``."""
    return params.rounding_factor * scale_axes + wp.vec3(extra_error, extra_error, extra_error)


@wp.func
def _ccd_from_differences(
    q0: wp.vec3,
    e10: wp.vec3,
    e20: wp.vec3,
    q1: wp.vec3,
    e11: wp.vec3,
    e21: wp.vec3,
    triangle_domain: int,
    magnitude: wp.vec3,
    extra_error: float,
    minimum_distance: float,
    distance_squared_t0: float,
    params: CcdParameters,
) -> float:
    """Shared tail of the two CCD functions: rounding bound, motion-bound and coplanarity filters,
    then the search.

    ``magnitude`` is the per-axis largest |translated coordinate| of the query (M in the bound);
    ``distance_squared_t0`` the float32 squared distance of the pair at t0 (translated points).
    """
    err = _query_error(magnitude, extra_error, params)
    scale = wp.max(magnitude[0], wp.max(magnitude[1], magnitude[2]))
    if motion_cannot_reach(distance_squared_t0, q0, e10, e20, q1, e11, e21, triangle_domain, err, scale,
                            minimum_distance):
        return 2.0
    if minimum_distance == 0.0 and extra_error == 0.0:
        if never_coplanar(q0, e10, e20, q1, e11, e21, params.coplanarity_factor):
            return 2.0
    elif params.plane_filter != 0:
        # F_exact differs from F evaluated on the float inputs by at most |err| (twice, as in the motion bound).
        if plane_keeps_distance(q0, e10, e20, q1, e11, e21,
                                minimum_distance * (1.0 + MOTION_MARGIN) + 2.0 * wp.length(err),
                                params.coplanarity_factor):
            return 2.0
    distance_tolerance = query_distance_tolerance(distance_squared_t0, err, scale, minimum_distance, params)
    t_start = float(0.0)
    if distance_tolerance > 0.0:
        t_start = advance_to_contact(q0, e10, e20, q1, e11, e21, triangle_domain, err, scale, minimum_distance,
                                      distance_tolerance)
        if t_start >= 0.0:
            return t_start  # a contact (or NO_HIT, 2.0) decided by the advancement
        t_start = -t_start - 1.0  # undecided: the box search goes on from there
    return ccd_search(q0, e10, e20, q1, e11, e21, triangle_domain, err, scale, minimum_distance,
                       distance_tolerance, t_start, params)


@wp.func
def vertex_face_ccd_toi(
    p_t0: wp.vec3,
    a_t0: wp.vec3,
    b_t0: wp.vec3,
    c_t0: wp.vec3,
    p_t1: wp.vec3,
    a_t1: wp.vec3,
    b_t1: wp.vec3,
    c_t1: wp.vec3,
    minimum_distance: float,
    extra_error: float,
    params: CcdParameters,
) -> float:
    """Conservative first time (in [0, 1]) at which vertex p comes within ``minimum_distance`` of
    triangle (a, b, c); returns ``NO_HIT`` (2.0) when it provably never does.

    ``extra_error`` is an absolute per-axis amount added to the rounding bound (e.g. for input
    that was rounded to float32). With p_t1 = p_t0 etc. this is a conservative static proximity
    test whose answer is 0 (hit) or ``NO_HIT``.
    """
    face_lo = wp.min(wp.min(wp.min(a_t0, b_t0), wp.min(c_t0, a_t1)), wp.min(b_t1, c_t1))
    face_hi = wp.max(wp.max(wp.max(a_t0, b_t0), wp.max(c_t0, a_t1)), wp.max(b_t1, c_t1))
    if features_apart(wp.min(p_t0, p_t1), wp.max(p_t0, p_t1), face_lo, face_hi, extra_error, minimum_distance):
        return 2.0
    r = p_t0
    yp0 = p_t0 - r
    ya0 = a_t0 - r
    yb0 = b_t0 - r
    yc0 = c_t0 - r
    yp1 = p_t1 - r
    ya1 = a_t1 - r
    yb1 = b_t1 - r
    yc1 = c_t1 - r
    m = wp.vec3(0.0, 0.0, 0.0)
    m = _abs_max(m, yp0)
    m = _abs_max(m, ya0)
    m = _abs_max(m, yb0)
    m = _abs_max(m, yc0)
    m = _abs_max(m, yp1)
    m = _abs_max(m, ya1)
    m = _abs_max(m, yb1)
    m = _abs_max(m, yc1)
    return _ccd_from_differences(yp0 - ya0, ya0 - yb0, ya0 - yc0, yp1 - ya1, ya1 - yb1, ya1 - yc1, 1, m,
                                 extra_error, minimum_distance, vertex_face_distance_squared(yp0, ya0, yb0, yc0),
                                 params)


@wp.func
def edge_edge_ccd_toi(
    a0_t0: wp.vec3,
    a1_t0: wp.vec3,
    b0_t0: wp.vec3,
    b1_t0: wp.vec3,
    a0_t1: wp.vec3,
    a1_t1: wp.vec3,
    b0_t1: wp.vec3,
    b1_t1: wp.vec3,
    minimum_distance: float,
    extra_error: float,
    params: CcdParameters,
) -> float:
    """Conservative first time (in [0, 1]) at which edge (a0, a1) comes within
    ``minimum_distance`` of edge (b0, b1); ``NO_HIT`` (2.0) when it provably never does.

    See :func:`vertex_face_ccd_toi` for ``extra_error`` and the static use.
    """
    if features_apart(wp.min(wp.min(a0_t0, a1_t0), wp.min(a0_t1, a1_t1)),
                       wp.max(wp.max(a0_t0, a1_t0), wp.max(a0_t1, a1_t1)),
                       wp.min(wp.min(b0_t0, b1_t0), wp.min(b0_t1, b1_t1)),
                       wp.max(wp.max(b0_t0, b1_t0), wp.max(b0_t1, b1_t1)), extra_error, minimum_distance):
        return 2.0
    r = a0_t0
    ya00 = a0_t0 - r
    ya10 = a1_t0 - r
    yb00 = b0_t0 - r
    yb10 = b1_t0 - r
    ya01 = a0_t1 - r
    ya11 = a1_t1 - r
    yb01 = b0_t1 - r
    yb11 = b1_t1 - r
    m = wp.vec3(0.0, 0.0, 0.0)
    m = _abs_max(m, ya00)
    m = _abs_max(m, ya10)
    m = _abs_max(m, yb00)
    m = _abs_max(m, yb10)
    m = _abs_max(m, ya01)
    m = _abs_max(m, ya11)
    m = _abs_max(m, yb01)
    m = _abs_max(m, yb11)
    return _ccd_from_differences(ya00 - yb00, ya10 - ya00, yb00 - yb10, ya01 - yb01, ya11 - ya01, yb01 - yb11, 0,
                                 m, extra_error, minimum_distance,
                                 edge_edge_distance_squared(ya00, ya10, yb00, yb10), params)


@wp.kernel
def _vertex_face_ccd_kernel(
    # in:
    points_t0: wp.array2d(dtype=wp.vec3),
    points_t1: wp.array2d(dtype=wp.vec3),
    extra_error: wp.array(dtype=wp.float32),
    minimum_distance: float,
    params: CcdParameters,
    # out:
    toi_out: wp.array(dtype=wp.float32),
):
    """One thread per vertex-face query."""
    i = wp.tid()
    toi_out[i] = vertex_face_ccd_toi(
        points_t0[i, 0], points_t0[i, 1], points_t0[i, 2], points_t0[i, 3],
        points_t1[i, 0], points_t1[i, 1], points_t1[i, 2], points_t1[i, 3],
        minimum_distance, extra_error[i], params,
    )


@wp.kernel
def _edge_edge_ccd_kernel(
    # in:
    points_t0: wp.array2d(dtype=wp.vec3),
    points_t1: wp.array2d(dtype=wp.vec3),
    extra_error: wp.array(dtype=wp.float32),
    minimum_distance: float,
    params: CcdParameters,
    # out:
    toi_out: wp.array(dtype=wp.float32),
):
    """One thread per edge-edge query."""
    i = wp.tid()
    toi_out[i] = edge_edge_ccd_toi(
        points_t0[i, 0], points_t0[i, 1], points_t0[i, 2], points_t0[i, 3],
        points_t1[i, 0], points_t1[i, 1], points_t1[i, 2], points_t1[i, 3],
        minimum_distance, extra_error[i], params,
    )


def input_rounding_error(points_t0: np.ndarray, points_t1: np.ndarray) -> np.ndarray:
    """Per-query bound on how much rounding the input to float32 can move F, per axis.

    Zero for queries whose coordinates are exactly float32. Otherwise 2 u max|x| (F is affine in
    the 8 points with coefficients whose absolute values sum to at most 2 per axis, and rounding
    moves each coordinate by at most u |x|), enlarged by 1 % for the float32 evaluation.

    Args:
        points_t0: (n, 4, 3) array of any real dtype, as the user gave it.
        points_t1: (n, 4, 3) array, likewise.

    Returns:
        (n,) float32 absolute error per query.
    """
    error = np.zeros(points_t0.shape[0], dtype=np.float32)
    for points in (points_t0, points_t1):
        as_given = np.asarray(points, dtype=np.float64)
        changed = (as_given != as_given.astype(np.float32).astype(np.float64)).reshape(len(as_given), -1)
        inexact = changed.any(axis=1)
        if inexact.any():
            magnitude = np.abs(as_given).reshape(len(as_given), -1).max(axis=1)
            bound = 2.02 * tolerances.FLOAT32_UNIT_ROUNDOFF * magnitude
            error = np.maximum(error, np.where(inexact, bound, 0.0).astype(np.float32))
    return error


def _run_ccd(kernel, points_t0, points_t1, minimum_distance, device,
             plane_filter: bool = True, distance_tolerance: float | None = None) -> tuple[np.ndarray, np.ndarray]:
    raw_t0 = np.asarray(points_t0.numpy() if isinstance(points_t0, wp.array) else points_t0)
    raw_t1 = np.asarray(points_t1.numpy() if isinstance(points_t1, wp.array) else points_t1)
    x0 = check_points(raw_t0, "points_t0", shape_tail=(4, 3))
    x1 = check_points(raw_t1, "points_t1", shape_tail=(4, 3))
    if x0.shape != x1.shape:
        raise InputError("argument", "points_t1", f"shape {x1.shape} differs from points_t0 {x0.shape}",
                         "pass start and end positions of the same queries")
    distance = check_nonnegative(minimum_distance, "minimum_distance")
    if distance_tolerance is not None:
        distance_tolerance = check_nonnegative(distance_tolerance, "distance_tolerance")
        if distance_tolerance >= 1.0:
            raise InputError("argument", "distance_tolerance",
                             f"{distance_tolerance!r} is not below 1 (contacts would be reported up to "
                             f"{1.0 + distance_tolerance:g} x minimum_distance apart)",
                             "pass a fraction of the minimum distance such as 0.1, or 0 for exact refinement")
    count = x0.shape[0]
    if count == 0:
        return np.zeros(0, dtype=bool), np.zeros(0, dtype=np.float32)
    extra = input_rounding_error(raw_t0, raw_t1)
    device = wp.get_device(device)
    toi = wp.empty(count, dtype=wp.float32, device=device)
    params = ccd_parameters()
    params.plane_filter = int(bool(plane_filter))
    if distance_tolerance is not None:
        params.distance_tolerance = float(distance_tolerance)
    wp.launch(
        kernel,
        dim=count,
        inputs=[
            wp.array(x0, dtype=wp.vec3, device=device),
            wp.array(x1, dtype=wp.vec3, device=device),
            wp.array(extra, dtype=wp.float32, device=device),
            float(distance),
            params,
        ],
        outputs=[toi],
        device=device,
    )
    toi_host = toi.numpy()
    hit = toi_host <= 1.0
    return hit, np.where(hit, toi_host, np.float32(np.inf)).astype(np.float32)


def vertex_face_ccd(
    points_t0: np.ndarray | wp.array,
    points_t1: np.ndarray | wp.array,
    minimum_distance: float = 0.0,
    *,
    device: str | None = None,
    plane_filter: bool = True,
    distance_tolerance: float | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Batched conservative vertex-face CCD.

    Args:
        points_t0: (n, 4, 3) positions at t = 0, ordered [vertex, f0, f1, f2].
        points_t1: (n, 4, 3) positions at t = 1, same order.
        minimum_distance: report the pair when the vertex comes within this Euclidean distance of
            the triangle (0 = touching), in the units of the points.
        device: Warp device to run on (default: Warp's default device).
        plane_filter: exclude pairs whose features provably stay farther than ``minimum_distance`` from
            each other's moving plane before the search (:func:`plane_keeps_distance`; False: the
            search decides every pair, for comparisons).
        distance_tolerance: :data:`pscc.tolerances.CCD_DISTANCE_TOLERANCE` for this call, in [0, 1) (``None``:
            the default; 0: every contact refined exactly).

    Returns:
        ``(hit, toi)``: (n,) bool and (n,) float32. ``toi`` is a lower bound of the first time of
        contact for hits and ``inf`` otherwise. Never misses a contact of the input as given.

    Raises:
        InputError: bad shapes, NaN/Inf, a negative ``minimum_distance``, or a ``distance_tolerance``
            outside [0, 1).
    """
    return _run_ccd(_vertex_face_ccd_kernel, points_t0, points_t1, minimum_distance, device, plane_filter,
                    distance_tolerance)


def edge_edge_ccd(
    points_t0: np.ndarray | wp.array,
    points_t1: np.ndarray | wp.array,
    minimum_distance: float = 0.0,
    *,
    device: str | None = None,
    plane_filter: bool = True,
    distance_tolerance: float | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Batched conservative edge-edge CCD.

    Args:
        points_t0: (n, 4, 3) positions at t = 0, ordered [a0, a1, b0, b1].
        points_t1: (n, 4, 3) positions at t = 1, same order.
        minimum_distance: Euclidean distance at which the edges count as colliding (0 = touching).
        device: Warp device to run on.
        plane_filter: as in :func:`vertex_face_ccd`.
        distance_tolerance: as in :func:`vertex_face_ccd`.

    Returns:
        ``(hit, toi)`` as in :func:`vertex_face_ccd`.

    Raises:
        InputError: bad shapes, NaN/Inf, a negative ``minimum_distance``, or a ``distance_tolerance``
            outside [0, 1).
    """
    return _run_ccd(_edge_edge_ccd_kernel, points_t0, points_t1, minimum_distance, device, plane_filter,
                    distance_tolerance)
