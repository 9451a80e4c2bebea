"""Launch shape of row kernels: one thread per row slot on a GPU, one thread over all rows on the CPU.

Several hot kernels work on buffers launched at their capacity and read the number of valid rows on
the device (so that nothing is read back and the launch can be recorded into a graph). On a GPU each
row gets a thread. On the CPU, Warp 1.19 runs a launch's threads one after another and, for every
thread, first copies the kernel's whole argument block (its contiguous-array specialisation) before
the body runs: 1 to 5 ns per thread for kernels with struct arguments, paid again by every thread past
the valid rows. On ``stack`` at 2K triangles the contact springs' kernel spent 0.9 of its 2.9 ms per
step there.

A row kernel therefore loops ``for row in range(wp.tid(), rows, lanes)`` and is launched with
``dim = lanes = row_lanes(device, capacity)``: one thread per slot on a GPU (the loop runs at most
once), a single thread that walks every valid row in order on the CPU. The rows, their order on the
CPU and hence every result are the same as with one thread per row.
"""

from __future__ import annotations

import warp as wp

__all__ = ["row_lanes"]


def row_lanes(device: wp.Device, capacity: int) -> int:
    """Threads to launch (and the loop stride to pass) for a row kernel over ``capacity`` row slots.

    Args:
        device: the Warp device the kernel runs on.
        capacity: the number of row slots the buffers hold (the valid rows are read on the device).

    Returns:
        1 on the CPU; ``capacity`` (at least 1) on a GPU.
    """
    return 1 if device.is_cpu else max(int(capacity), 1)
