"""Prefix sums and inner products that allocate nothing, for loops recorded into CUDA graphs.

Warp 1.19's ``wp.utils.array_scan`` and ``wp.utils.array_inner`` run CUB on a GPU, and CUB asks for
temporary memory on every call. Inside a ``wp.capture_while`` body that request becomes a memory
allocation node, which CUDA refuses in a conditional graph ("Conditional body graph contains an
unsupported operation (memory allocation)"), and outside a graph it is an allocation per call in a hot
path. The classes here keep their scratch buffers, sized once, and on a GPU run their own kernels on
them:

* scan (int32 or int64): every thread sums a chunk of :data:`SCAN_CHUNK` consecutive elements; the
  chunk totals are scanned the same way, level by level, until one chunk is left, which one thread
  scans; going back down, every thread scans its chunk from its offset. An array of ``n`` elements
  takes ``2 ceil(log_32 n)`` launches of at most ``n / 32`` threads; Warp's tile scan would be faster
  but takes no int64, which the spatial hash's cell counts need;
* inner product (vec3): every block reduces one tile of :data:`DOT_TILE` element products to a partial sum;
  one block adds the partial sums in tile order, so the result does not depend on scheduling.

On the CPU, Warp's own scan and inner product are single sequential loops that allocate nothing and
are faster than these kernels there (Warp runs a tile's block threads one after another), so
:class:`PrefixSum` and :class:`InnerProduct` call them; ``own_kernels=True`` forces the kernels on any
device (the tests check both paths against numpy on the CPU).

float32 inner products are rounded in a different order from numpy's; the relative error stays below
about ``n * 6e-8`` of the sum of the absolute products, as for any float32 summation.
"""

from __future__ import annotations

from typing import Any

import warp as wp

__all__ = ["DOT_TILE", "SCAN_CHUNK", "InnerProduct", "PrefixSum"]

wp.set_module_options({"enable_backward": False})

SCAN_CHUNK = 32
"""Consecutive elements one thread of the scan handles (per level)."""
DOT_TILE = 1024
"""Element products one block reduces."""
DOT_THREADS = 256
"""Threads of a reducing block."""


@wp.kernel
def _chunk_totals(
    # in:
    values: wp.array(dtype=Any),
    count: int,
    # out:
    totals: wp.array(dtype=Any),
):
    """One thread per chunk of ``SCAN_CHUNK`` values (the last one may be shorter): their sum."""
    chunk = wp.tid()
    start = chunk * SCAN_CHUNK
    end = wp.min(start + SCAN_CHUNK, count)
    total = values[start]
    for i in range(start + 1, end):
        total = total + values[i]
    totals[chunk] = total


@wp.kernel
def _chunk_scan(
    # in:
    values: wp.array(dtype=Any),
    count: int,
    chunk_offsets: wp.array(dtype=Any),
    has_offsets: int,
    inclusive: int,
    # out:
    scanned: wp.array(dtype=Any),
):
    """One thread per chunk: its prefix sums, starting from ``chunk_offsets[chunk]`` (zero without
    offsets). ``scanned`` may be ``values`` itself: each element is read before it is written."""
    chunk = wp.tid()
    start = chunk * SCAN_CHUNK
    end = wp.min(start + SCAN_CHUNK, count)
    running = values[start] - values[start]
    if has_offsets != 0:
        running = chunk_offsets[chunk]
    for i in range(start, end):
        value = values[i]
        if inclusive != 0:
            running = running + value
            scanned[i] = running
        else:
            scanned[i] = running
            running = running + value


for _dtype in (wp.int32, wp.int64):
    wp.overload(_chunk_totals, {"values": wp.array(dtype=_dtype), "totals": wp.array(dtype=_dtype)})
    wp.overload(_chunk_scan, {"values": wp.array(dtype=_dtype), "chunk_offsets": wp.array(dtype=_dtype),
                              "scanned": wp.array(dtype=_dtype)})


@wp.kernel
def _dot_tiles(
    # in:
    a: wp.array(dtype=wp.vec3),
    b: wp.array(dtype=wp.vec3),
    # out:
    partials: wp.array(dtype=float),
):
    """One block per tile: the sum of the tile's ``dot(a[i], b[i])`` (elements past the end read 0)."""
    tile = wp.tid()
    start = tile * DOT_TILE
    products = wp.tile_map(wp.dot, wp.tile_load(a, shape=DOT_TILE, offset=start),
                           wp.tile_load(b, shape=DOT_TILE, offset=start))
    wp.tile_store(partials, wp.tile_sum(products), offset=tile)


@wp.kernel
def _sum_partials(
    # in:
    partials: wp.array(dtype=float),
    chunk_count: int,
    # out:
    result: wp.array(dtype=float),
):
    """One block: the partial sums added chunk by chunk in tile order, written to ``result[0]``."""
    _block = wp.tid()
    total = float(0.0)
    for chunk in range(chunk_count):
        total = total + wp.tile_extract(wp.tile_sum(wp.tile_load(partials, shape=DOT_TILE, offset=chunk * DOT_TILE)), 0)
    wp.tile_store(result, wp.tile_full(1, total, dtype=float))


def _chunks(count: int, chunk: int) -> int:
    return max(1, (int(count) + chunk - 1) // chunk)


def _use_own(device: wp.Device, own_kernels: bool | None) -> bool:
    return device.is_cuda if own_kernels is None else bool(own_kernels)


class PrefixSum:
    """Inclusive or exclusive prefix sums of whole int32 or int64 arrays, with no allocation per call.

    Args:
        device: the Warp device of the arrays.
        capacity: the longest array expected (the scratch grows, outside any graph capture, when a longer
            one comes).
        own_kernels: ``None`` for this module's kernels on a GPU and Warp's scan on the CPU; ``True`` or
            ``False`` to force one.

    Device buffers: per dtype used, one chunk-total array per level, ``ceil(capacity / 32)``,
    ``ceil(capacity / 32^2)``, ... elements (own kernels only).
    """

    def __init__(self, device: wp.Device | str, capacity: int = 1, own_kernels: bool | None = None) -> None:
        self.device = wp.get_device(device)
        self.own_kernels = _use_own(self.device, own_kernels)
        self.capacity = max(1, int(capacity))
        self._levels: dict[type, list[wp.array]] = {}

    def _level_arrays(self, dtype: type, count: int) -> list[wp.array]:
        """The chunk-total arrays for ``count`` elements of ``dtype`` (allocated when they grow)."""
        self.capacity = max(self.capacity, int(count))
        levels = self._levels.get(dtype)
        sizes = []
        length = self.capacity
        while length > SCAN_CHUNK:
            length = _chunks(length, SCAN_CHUNK)
            sizes.append(length)
        if levels is None or len(levels) < len(sizes) or any(levels[k].shape[0] < size for k, size in enumerate(sizes)):
            levels = [wp.zeros(n, dtype=dtype, device=self.device) for n in sizes]
            self._levels[dtype] = levels
        return levels

    def __call__(self, values: wp.array, scanned: wp.array, inclusive: bool = True) -> None:
        """Write the prefix sums of all of ``values`` into ``scanned`` (another array of the same length
        and dtype, int32 or int64).

        Allocates: no, after the first call at this length and dtype. Capture-safe: yes, also inside a
        ``wp.capture_while`` body on CUDA (after such a first call).
        """
        n = values.shape[0]
        if not self.own_kernels:
            wp.utils.array_scan(values, scanned, inclusive=inclusive)
            return
        if n == 0:
            return
        levels = self._level_arrays(values.dtype, n)
        dev = self.device
        counts = [n]
        while counts[-1] > SCAN_CHUNK:
            counts.append(_chunks(counts[-1], SCAN_CHUNK))
        sources = [values, *levels[: len(counts) - 1]]
        for level in range(len(counts) - 1):  # up: chunk totals, level by level
            wp.launch(_chunk_totals, dim=counts[level + 1], inputs=[sources[level], counts[level]],
                      outputs=[sources[level + 1]], device=dev)
        top = len(counts) - 1  # one chunk left: one thread scans it (exclusively, unless it is the input)
        wp.launch(_chunk_scan, dim=1, inputs=[sources[top], counts[top], scanned, 0, int(top == 0 and inclusive)],
                  outputs=[scanned if top == 0 else sources[top]], device=dev)
        for level in range(top - 1, -1, -1):  # down: every chunk from its offset
            last = level == 0
            wp.launch(_chunk_scan, dim=counts[level + 1],
                      inputs=[sources[level], counts[level], sources[level + 1], 1, int(last and inclusive)],
                      outputs=[scanned if last else sources[level]], device=dev)


class InnerProduct:
    """``sum_i dot(a[i], b[i])`` of two vec3 arrays into a one-element float array, with no allocation
    per call.

    Args:
        device: the Warp device of the arrays.
        capacity: the longest arrays expected (the scratch grows, outside any capture, when longer come).
        own_kernels: as for :class:`PrefixSum`.

    Device buffers: ``partials`` (``ceil(capacity / DOT_TILE)``,) float32 (own kernels only).
    """

    def __init__(self, device: wp.Device | str, capacity: int = 1, own_kernels: bool | None = None) -> None:
        self.device = wp.get_device(device)
        self.own_kernels = _use_own(self.device, own_kernels)
        self.partials: wp.array | None = None
        self._partial_views: dict[int, wp.array] = {}
        self.reserve(capacity)

    def reserve(self, capacity: int) -> None:
        """Make room for arrays of ``capacity`` elements (allocates when it grows; not in a capture)."""
        tiles = _chunks(capacity, DOT_TILE)
        if self.own_kernels and (self.partials is None or self.partials.shape[0] < tiles):
            self.partials = wp.zeros(tiles, dtype=float, device=self.device)
            self._partial_views = {}

    def __call__(self, a: wp.array, b: wp.array, result: wp.array) -> None:
        """Write ``sum_i dot(a[i], b[i])`` into ``result[0]`` (``result`` may be a one-element view).

        Allocates: no, once :meth:`reserve` covered ``len(a)``. Capture-safe: yes, also inside a
        ``wp.capture_while`` body on CUDA.
        """
        if not self.own_kernels:
            wp.utils.array_inner(a, b, out=result)
            return
        n = a.shape[0]
        self.reserve(n)
        tiles = _chunks(n, DOT_TILE)
        dev = self.device
        # The second pass reads exactly this call's partial sums: a view per length, made once.
        partials = self._partial_views.get(tiles)
        if partials is None:
            partials = self._partial_views[tiles] = self.partials[:tiles]
        wp.launch_tiled(_dot_tiles, dim=tiles, inputs=[a, b], outputs=[partials], block_dim=DOT_THREADS, device=dev)
        wp.launch_tiled(_sum_partials, dim=1, inputs=[partials, _chunks(tiles, DOT_TILE)], outputs=[result],
                        block_dim=DOT_THREADS, device=dev)
