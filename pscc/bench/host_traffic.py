"""Count host <-> device traffic from outside, as ``../shared/tools/host_traffic.py`` does.

Reads are ``wp.array.numpy`` / ``wp.array.list``; syncs ``wp.synchronize`` / ``wp.synchronize_device`` /
``wp.synchronize_stream``;
uploads ``wp.array.assign``, ``wp.from_numpy`` and ``wp.array(...)`` built from host data. On the CPU
they cost little; on a GPU every read stalls the device and every upload crosses the bus. The tests
also count allocations: arrays built without data and without a pointer (``wp.empty``, ``wp.zeros``,
``wp.full``, ``wp.clone``, ... all come through there; views do not).
"""

from __future__ import annotations

import contextlib
from collections.abc import Callable, Iterator
from typing import Any

import warp as wp


@contextlib.contextmanager
def count_host_traffic() -> Iterator[dict[str, int]]:
    """Count ``reads``, ``syncs``, ``uploads`` and ``allocations`` made inside the ``with`` block (the dict
    fills as they happen).

    Not thread-safe: it patches Warp's functions for the duration of the block.
    """
    counts = {"reads": 0, "syncs": 0, "uploads": 0, "allocations": 0}
    patches: list[tuple[Any, str, Any]] = []

    def wrap(owner: Any, name: str, kind: str) -> None:
        original = getattr(owner, name)

        def counted(*args: Any, **kwargs: Any) -> Any:
            counts[kind] += 1
            return original(*args, **kwargs)

        patches.append((owner, name, original))
        setattr(owner, name, counted)

    wrap(wp.array, "numpy", "reads")
    wrap(wp.array, "list", "reads")
    wrap(wp, "synchronize", "syncs")
    wrap(wp, "synchronize_device", "syncs")
    wrap(wp, "synchronize_stream", "syncs")
    wrap(wp.array, "assign", "uploads")
    wrap(wp, "from_numpy", "uploads")
    original_init: Callable[..., None] = wp.array.__init__

    def init(self: wp.array, data: Any = None, *args: Any, **kwargs: Any) -> None:
        if data is not None and not isinstance(data, wp.array | int | float):
            counts["uploads"] += 1
        elif data is None and kwargs.get("ptr") is None:
            counts["allocations"] += 1
        original_init(self, data, *args, **kwargs)

    wp.array.__init__ = init
    try:
        yield counts
    finally:
        wp.array.__init__ = original_init
        for owner, name, original in reversed(patches):
            setattr(owner, name, original)


def device_path_traffic(device: wp.Device | str, run: Callable[[], Any], calls: int = 1) -> dict[str, int]:
    """Host traffic of ``calls`` runs of ``run`` the way the device path runs it.

    On the CPU ``run`` is called directly: Warp's ``capture_while`` reads its condition from memory
    there. On CUDA an eager ``capture_while`` synchronizes once per iteration to read its condition,
    so the device path is a graph: ``run`` is recorded once (outside the count) and the graph is
    replayed ``calls`` times inside it. Call ``run`` once before, so that modules are loaded and
    buffers sized outside the capture.
    """
    if wp.get_device(device).is_cpu:
        with count_host_traffic() as counts:
            for _ in range(calls):
                run()
        return counts
    with wp.ScopedCapture(device=device) as capture:
        run()
    with count_host_traffic() as counts:
        for _ in range(calls):
            wp.capture_launch(capture.graph)
    wp.synchronize_device(device)
    return counts
