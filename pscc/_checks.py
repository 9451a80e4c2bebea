"""Validation at the public boundary: turn bad arrays into :class:`pscc.InputError`.

Validation happens once, where user data enters (loaders, public functions, detector calls);
kernels never re-check.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import warp as wp

from pscc import tolerances
from pscc.errors import InputError


def as_numpy(value: Any) -> np.ndarray:
    """Return ``value`` as a NumPy array (Warp arrays are copied to the host)."""
    if isinstance(value, wp.array):
        return value.numpy()
    return np.asarray(value)


def check_points(
    value: Any, name: str, *, shape_tail: tuple[int, ...], source: str = "argument"
) -> np.ndarray:
    """Validate a float point array and return it as contiguous float32.

    Args:
        value: Array-like of real numbers.
        name: The argument or field name used in error messages.
        shape_tail: Required trailing shape, e.g. ``(4, 3)`` for (n, 4, 3) query batches.
        source: File path or ``"argument"``, for the error message.

    Raises:
        InputError: wrong rank/shape, non-real dtype, NaN or Inf.
    """
    array = as_numpy(value)
    expected = "(n, " + ", ".join(str(s) for s in shape_tail) + ")"
    if array.dtype.kind not in "fiu":
        raise InputError(source, name, f"dtype {array.dtype} is not a real number type",
                         f"pass a float array of shape {expected}")
    if array.ndim != len(shape_tail) + 1 or tuple(array.shape[1:]) != shape_tail:
        raise InputError(source, name, f"shape {array.shape} does not match {expected}",
                         f"reshape it to {expected}")
    array = np.ascontiguousarray(array, dtype=np.float32)
    if not np.all(np.isfinite(array)):
        bad = int(np.argwhere(~np.isfinite(array).reshape(array.shape[0], -1).all(axis=1))[0][0])
        raise InputError(source, name, f"row {bad} holds NaN or Inf (after conversion to float32)",
                         "remove or repair non-finite coordinates")
    return array


def check_nonnegative(value: float, name: str) -> float:
    """Validate a finite, non-negative scalar (a thickness or a distance)."""
    try:
        number = float(value)
    except (TypeError, ValueError) as exc:
        raise InputError("argument", name, f"{value!r} is not a number", "pass a float >= 0") from exc
    if not np.isfinite(number) or number < 0.0:
        raise InputError("argument", name, f"{value!r} is negative or not finite", "pass a float >= 0")
    return number


INT32_MAX = int(np.iinfo(np.int32).max)
"""Largest id pscc stores on the device (ids are int32 there)."""


def _default_row(row: int) -> str:
    return f"row {row}"


def check_object_ids(
    value: Any,
    face_count: int,
    *,
    source: str = "argument",
    name: str = "object_ids",
    row_label: Callable[[int], str] | None = None,
) -> np.ndarray:
    """Validate per-face object ids and return an owned (face_count,) int32 copy.

    Ids need not be contiguous: any value in [0, 2**31 - 1] is accepted. Code that keeps a table per
    object must compact them first (``np.unique(ids, return_inverse=True)``), never allocate
    ``max(id) + 1`` entries.

    Args:
        value: Array-like of integers, one per face.
        face_count: The number of faces m.
        source: File path or ``"argument"``, for the error message.
        name: The argument or field name used in error messages.
        row_label: Names a face row in messages (loaders point at the file line); default ``row i``.

    Raises:
        InputError: not a rectangular integer (m,) array, or an id below 0 or above 2**31 - 1.
    """
    label = row_label if row_label is not None else _default_row
    try:
        array = as_numpy(value)
    except (TypeError, ValueError) as exc:
        raise InputError(source, name, f"cannot be read as an integer array ({exc})",
                         f"pass one integer object id >= 0 per face, shape ({face_count},)") from exc
    if array.dtype.kind not in "iu":
        raise InputError(source, name, f"dtype {array.dtype} is not an integer type",
                         "pass integer object ids >= 0, one per face")
    if array.shape != (face_count,):
        raise InputError(source, name, f"shape {array.shape} does not match ({face_count},) (one id per face)",
                         "pass a 1-D array with one object id per face")
    bad = (array > INT32_MAX) if array.dtype.kind == "u" else (array < 0) | (array > INT32_MAX)
    rows = np.flatnonzero(bad)
    if rows.size:
        row = int(rows[0])
        raise InputError(source, name, f"face {label(row)} has object id {int(array[row])}, outside [0, {INT32_MAX}]",
                         "use non-negative object ids that fit a 32-bit signed integer (they need not be "
                         "contiguous)")
    return np.array(array, dtype=np.int32, order="C", copy=True)


def unused_object_ids(taken: np.ndarray, count: int) -> np.ndarray:
    """``count`` int32 object ids that are not in ``taken`` (ids already checked by :func:`check_object_ids`).

    They follow the largest taken id when that fits in int32, else they are the smallest free ids, so an
    id of ``2**31 - 1`` never overflows.
    """
    taken = np.asarray(taken, dtype=np.int64)
    start = int(taken.max()) + 1 if taken.size else 0
    if start + count - 1 <= INT32_MAX:
        return np.arange(start, start + count, dtype=np.int32)
    used = np.unique(taken)
    free: list[int] = []
    candidate = 0
    for value in used.tolist():  # sorted: the gaps below the taken ids, in order
        while candidate < value and len(free) < count:
            free.append(candidate)
            candidate += 1
        candidate = value + 1
        if len(free) == count:
            break
    while len(free) < count:
        free.append(candidate)
        candidate += 1
    return np.asarray(free, dtype=np.int32)


def check_coordinate_range(points: np.ndarray, name: str, *, source: str = "argument") -> None:
    """Refuse float32 positions outside the range the collision kernels handle exactly.

    The largest |coordinate| must be at most :data:`pscc.tolerances.MAX_COORDINATE` and, unless
    every coordinate is 0, at least :data:`pscc.tolerances.MIN_COORDINATE_SCALE` (see there for
    the float32 overflow and underflow they prevent). Costs two reductions over the host array.

    Args:
        points: Host float array of positions (already checked by :func:`check_points`).
        name: The argument or field name used in error messages.
        source: File path or ``"argument"``, for the error message.

    Raises:
        InputError: naming the field, the row and value of the largest magnitude, the limit and the fix.
    """
    if points.size == 0:
        return
    largest = max(float(points.max()), -float(points.min()))
    if tolerances.MIN_COORDINATE_SCALE <= largest <= tolerances.MAX_COORDINATE or largest == 0.0:
        return
    row = int(np.argmax(np.abs(points).reshape(points.shape[0], -1).max(axis=1)))
    if largest > tolerances.MAX_COORDINATE:
        raise InputError(source, name,
                         f"largest |coordinate| {largest:.4g} (row {row}) exceeds the supported limit "
                         f"{tolerances.MAX_COORDINATE:g} (float32 products of lengths would overflow)",
                         f"express the coordinates in a unit or frame where |x| <= {tolerances.MAX_COORDINATE:g}")
    raise InputError(source, name,
                     f"largest |coordinate| {largest:.4g} (row {row}) is below the supported minimum "
                     f"{tolerances.MIN_COORDINATE_SCALE:g} (float32 products of lengths would underflow)",
                     f"express the coordinates in a smaller unit, so that the largest |x| is >= "
                     f"{tolerances.MIN_COORDINATE_SCALE:g}")


def check_thickness(value: float, name: str) -> float:
    """Validate a thickness (proximity distance): finite, >= 0 and at most
    :data:`pscc.tolerances.MAX_THICKNESS` (its float32 square must not overflow)."""
    number = check_nonnegative(value, name)
    if number > tolerances.MAX_THICKNESS:
        raise InputError("argument", name, f"{number:.4g} exceeds the supported limit {tolerances.MAX_THICKNESS:g} "
                         "(its float32 square would overflow)",
                         f"express lengths in a unit where the thickness is <= {tolerances.MAX_THICKNESS:g}")
    return number


def shorten(text: str, limit: int = 40) -> str:
    """``text`` cut to ``limit`` characters (with its length) so that a huge token keeps messages short."""
    return text if len(text) <= limit else f"{text[:limit - 3]}... ({len(text)} characters)"


def read_input_bytes(path: Path) -> bytes:
    """The bytes of an input file, or an :class:`InputError` naming it when it cannot be read."""
    try:
        return Path(path).read_bytes()
    except OSError as exc:
        raise InputError(str(path), "file", f"cannot be read ({exc.strerror or exc})",
                         "check the file permissions and that the file is not locked") from exc
