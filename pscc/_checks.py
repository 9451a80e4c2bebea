"""Validation at the public boundary: turn bad arrays into :class:`pscc.InputError`.

Validation happens once, where user data enters (loaders, public functions, detector calls);
kernels never re-check.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import warp as wp

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
