"""Memory estimates checked before allocation: a size that cannot fit is refused with the estimate.

The per-triangle figures are upper bounds from measurements (``BENCHMARKS.md`` and the numbers
below), with a margin: a run that passes the check may still be tight, but one that fails it would
certainly not fit. They cover the device buffers plus the host copies kept beside them; on the CPU
both live in host memory, so a CPU run is checked against host memory once with their sum.
"""

from __future__ import annotations

import os

from pscc.errors import InputError

__all__ = [
    "DETECTION_BYTES_PER_TRIANGLE",
    "SIMULATION_BYTES_PER_TRIANGLE",
    "available_bytes",
    "check_fits",
    "format_bytes",
]

SIMULATION_BYTES_PER_TRIANGLE = 8 * 1024
"""Simulator memory per triangle (cloth and obstacle) [bytes]: measured 4.2 KB of peak resident memory
per cloth triangle on the CPU (``drape``, 2K -> 20K triangles) and 3.4-4.9 KB of device buffers in
``BENCHMARKS.md``; twice the lower figure as margin for contact-heavy scenes."""

DETECTION_BYTES_PER_TRIANGLE = 4 * 1024
"""Collision detector memory per triangle [bytes]: 0.8-0.9 KB of device buffers in ``BENCHMARKS.md``
plus the host-side topology and the input arrays, with margin."""


def available_bytes(device: str | None = None) -> int | None:
    """Memory an allocation on ``device`` can use now [bytes]; ``None`` when it cannot be told.

    CUDA devices: the device's free memory. The CPU (and ``None``): ``MemAvailable`` of
    ``/proc/meminfo``, else the free physical pages.
    """
    if device is not None and str(device).startswith("cuda"):
        import warp as wp

        try:
            return int(wp.get_device(device).free_memory)
        except (RuntimeError, ValueError, AttributeError):
            return None
    try:
        with open("/proc/meminfo", encoding="ascii") as stream:
            for line in stream:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    try:
        return int(os.sysconf("SC_AVPHYS_PAGES")) * int(os.sysconf("SC_PAGE_SIZE"))
    except (ValueError, OSError, AttributeError):
        return None


def format_bytes(count: float) -> str:
    """``count`` bytes as a short human-readable size (``1.5 GiB``)."""
    value = float(count)
    for unit in ("B", "KiB", "MiB", "GiB", "TiB", "PiB"):
        if abs(value) < 1024.0 or unit == "PiB":
            return f"{value:.0f} {unit}" if unit == "B" else f"{value:.1f} {unit}"
        value /= 1024.0
    raise AssertionError("unreachable")


def check_fits(needed: float, *, what: str, source: str, field: str, fix: str, device: str | None = None) -> None:
    """Refuse ``needed`` bytes when they exceed the memory ``device`` has available.

    Args:
        needed: estimated bytes.
        what: what needs them, for the message (``"a simulation of 2,000,000 triangles"``).
        source: file or ``argument`` the size came from.
        field: the key or option that set the size.
        fix: what to do instead.
        device: Warp device the memory is for (``None``: host memory).

    Raises:
        InputError: ``needed`` exceeds the available memory (the message gives both).
    """
    available = available_bytes(device)
    if available is not None and needed > available:
        where = f"{device} has" if device is not None and str(device).startswith("cuda") else "this machine has"
        raise InputError(source, field, f"{what} needs about {format_bytes(needed)} of memory, {where} "
                         f"{format_bytes(available)} available", fix)
