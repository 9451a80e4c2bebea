"""The spatial hash's input checks and the kernel-argument structs built from its inputs.

:class:`pscc.collision.spatial_hash.SpatialHash` calls these on every :meth:`find_pairs_device` call:
each check raises an :class:`~pscc.errors.InputError` naming the argument and the fix, and each builder
returns the ``@wp.struct`` a kernel reads (with placeholder arrays where a feature is off, since a struct
member cannot be ``None``). Host only: nothing here launches a kernel or reads the device.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np
import warp as wp

from pscc import tolerances
from pscc.collision import _spatial_hash_kernels as kernels
from pscc.collision import shared_vertex
from pscc.errors import InputError
from pscc.geometry.dop import vec10

if TYPE_CHECKING:
    from pscc.collision.spatial_hash import SpatialHash

__all__ = ["check_face_array", "check_positions", "diagonal_args", "shared_args", "slab_args"]


def check_face_array(value: object, name: str, dtype: type, face_count: int, device: wp.Device) -> None:
    """``value`` is a contiguous (``face_count``,) ``wp.array`` of ``dtype`` on ``device``."""
    if not isinstance(value, wp.array):
        raise InputError("argument", name, f"got {type(value).__name__}, not a wp.array",
                         f"pass a ({face_count},) wp.array of {dtype.__name__}")
    if value.dtype != dtype or value.ndim != 1 or value.shape[0] != face_count:
        raise InputError("argument", name, f"got a {value.shape} array of {wp.types.type_repr(value.dtype)}",
                         f"pass a ({face_count},) wp.array of {dtype.__name__}")
    if value.device != device:
        raise InputError("argument", name, f"array is on {value.device}, the hash on {device}",
                         f"copy it to {device} first")
    if not value.is_contiguous:
        raise InputError("argument", name, "array is not contiguous", "pass a contiguous array")


def check_positions(positions_t0: wp.array | None, positions_t1: wp.array | None, user: str, when: str,
                    device: wp.Device, vertex_bound: int) -> None:
    """Vertex positions that ``user`` reads: vec3 arrays on ``device`` covering the faces' vertices (the
    first ``vertex_bound``); ``positions_t1``, when given, the same shape as ``positions_t0``."""
    for name, value in (("positions_t0", positions_t0), ("positions_t1", positions_t1)):
        if value is None:
            if name == "positions_t0":
                raise InputError("argument", name, f"{user} needs the vertex positions",
                                 f"pass positions_t0 (and positions_t1 for CCD) {when}")
            continue
        if not isinstance(value, wp.array) or value.dtype != wp.vec3 or value.ndim != 1:
            raise InputError("argument", name, f"got {type(value).__name__}, not a 1-D wp.array of vec3",
                             "pass the (vertex_count,) wp.vec3 positions the boxes were built from")
        if value.device != device:
            raise InputError("argument", name, f"array is on {value.device}, the hash on {device}",
                             f"copy it to {device} first")
    if positions_t0.shape[0] < vertex_bound:
        raise InputError("argument", "positions_t0", f"{positions_t0.shape[0]} positions, but the faces use "
                         f"{vertex_bound} vertices", "pass a position for every vertex the faces use")
    if positions_t1 is not None and positions_t1.shape != positions_t0.shape:
        raise InputError("argument", "positions_t1", f"shape {positions_t1.shape} != positions_t0's "
                         f"{positions_t0.shape}", "pass both ends of the step for the same vertices")


def diagonal_args(lower: wp.array | None, upper: wp.array | None, empty: wp.array, face_count: int,
                  device: wp.Device) -> kernels.DiagonalArgs:
    """The face test's diagonal slabs, checked (both arrays or neither; ``empty`` stands in when off)."""
    args = kernels.DiagonalArgs()
    if lower is None and upper is None:
        args.lower = empty
        args.upper = empty
        args.enabled = 0
        return args
    if lower is None or upper is None:
        raise InputError("argument", "face_diagonal_lower/face_diagonal_upper", "only one of the two was given",
                         "pass both (PrimitiveBoxes(face_diagonals=True) fills them) or neither")
    check_face_array(lower, "face_diagonal_lower", vec10, face_count, device)
    check_face_array(upper, "face_diagonal_upper", vec10, face_count, device)
    args.lower = lower
    args.upper = upper
    args.enabled = 1
    return args


def slab_args(hash_: SpatialHash, grouped: bool, positions_t0: wp.array | None, positions_t1: wp.array | None,
              half_distance: float) -> tuple[kernels.SlabArgs, float]:
    """The group slab test's launch arguments for ``hash_`` (disabled unless it is
    configured and the call has node ids) and the half distance as the float32 value the margin is
    computed from."""
    slab = kernels.SlabArgs()
    slab.enabled = 0
    slab.faces = hash_.faces
    slab.swept = 0
    slab.min_work = hash_.slab_min_work
    slab.exact_min_work = hash_.slab_exact_min_work
    slab.group_skip = hash_.group_skip
    slab.group_sphere = hash_.group_sphere
    slab.policy = hash_.slab_policy
    if not (hash_.group_slab_test and grouped):
        slab.positions_t0 = slab.positions_t1 = hash_.chunk_lower
        return slab, 0.0
    check_positions(positions_t0, positions_t1, "the group slab test", "with node_id", hash_.device,
                    hash_.vertex_bound)
    half = float(half_distance)
    if not math.isfinite(half) or half < 0.0:
        raise InputError("argument", "half_distance", f"{half_distance!r} is not a finite number >= 0",
                         "pass the half distance the boxes were grown by")
    slab.enabled = 1
    slab.positions_t0 = positions_t0
    slab.positions_t1 = positions_t0 if positions_t1 is None else positions_t1
    slab.swept = 0 if positions_t1 is None else 1
    return slab, float(np.float32(half))


def shared_args(hash_: SpatialHash, certify: bool, positions_t0: wp.array | None,
                positions_t1: wp.array | None) -> shared_vertex.SharedVertexArgs:
    """The face test's arguments for pairs that share a vertex (``skip_adjacent``, ``certify_shared``)."""
    args = shared_vertex.SharedVertexArgs()
    args.faces = hash_.faces
    args.mode = shared_vertex.SHARED_SKIP if hash_.skip_adjacent else shared_vertex.SHARED_KEEP
    args.swept = 0
    args.positions_t0 = args.positions_t1 = hash_.chunk_lower
    args.margin = tolerances.NORMAL_CONE_MARGIN
    if certify:
        if not hash_.faces_given or hash_.skip_adjacent:
            raise InputError("argument", "certify_shared", "this hash has no faces or skips every pair "
                             "that shares a vertex", "construct it with faces= and without skip_adjacent")
        check_positions(positions_t0, positions_t1, "certify_shared", "on every call", hash_.device,
                        hash_.vertex_bound)
        args.mode = shared_vertex.SHARED_CERTIFY
        args.positions_t0 = positions_t0
        args.positions_t1 = positions_t0 if positions_t1 is None else positions_t1
        args.swept = 0 if positions_t1 is None else 1
    return args
