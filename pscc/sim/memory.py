"""Device-memory accounting: the bytes of every Warp array an object holds."""

from __future__ import annotations

from typing import Any

import numpy as np
import warp as wp


def warp_array_bytes(root: Any, depth: int = 4, seen: set[int] | None = None) -> int:
    """Allocated bytes of every ``wp.array`` reachable from ``root`` through attributes, dicts, lists and
    tuples, at most ``depth`` levels deep; an array reached twice is counted once (pass the same
    ``seen`` set to several calls to count shared arrays once across them)."""
    seen = set() if seen is None else seen
    if id(root) in seen:
        return 0
    seen.add(id(root))
    if isinstance(root, wp.array):
        return int(root.capacity)
    if depth == 0 or isinstance(root, str | bytes | int | float | np.ndarray | wp.Device):
        return 0
    if isinstance(root, dict):
        children = list(root.values())
    elif isinstance(root, list | tuple):
        children = list(root)
    elif hasattr(root, "__dict__"):
        children = list(vars(root).values())
    else:
        return 0
    return sum(warp_array_bytes(child, depth - 1, seen) for child in children)
