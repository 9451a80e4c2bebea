"""Settings, limits and per-call statistics of :class:`pscc.collision.spatial_hash.SpatialHash`: the
defaults of its constructor, the capacity limits of its buffers and the counters that its sync point
reads back (:class:`SpatialHashStats`). ``docs/spatial-hash.md`` has the measurements behind the
defaults."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from pscc.collision import _spatial_hash_kernels as kernels
from pscc.errors import InputError

__all__ = [
    "CELL_CODE_MIN_TESTS",
    "CODE_MASK_MIN_RUN",
    "DEFAULT_CELL_SIZE_FACTOR",
    "DEFAULT_MAX_MEAN_CELLS_PER_FACE",
    "DEFAULT_MAX_WIDE_FACES",
    "DEFAULT_SLAB_EXACT_MIN_WORK",
    "SLAB_GROUP_COST",
    "SLAB_PROBE_BACKOFF",
    "SLAB_PROBE_INTERVAL",
    "SLAB_TEST_COST",
    "DEFAULT_SLAB_MIN_WORK",
    "DEFAULT_TEST_THREADS",
    "FIT_MARGIN",
    "FIT_SLACK",
    "GROWTH",
    "MAX_ENTRIES",
    "MAX_GRID_CELLS",
    "MAX_PAIRS",
    "MIN_CELL_BITS",
    "SCENE_CHUNKS",
    "TESTS_PER_LAUNCH",
    "WIDE_FACE_MIN_CELLS",
    "WIDE_FACE_SHARE",
    "SpatialHashStats",
    "check_integer",
    "check_positive",
    "fitted_capacities",
    "raise_counted_input_errors",
]

DEFAULT_CELL_SIZE_FACTOR: float = 3.0
"""k in Size_cell = k x BoxAxisLen_aver (the paper does not give its value; ``docs/spatial-hash.md``
section 6 has the measurements behind 3)."""

TESTS_PER_LAUNCH: int = 2**24
"""Default bound on the BV tests of one test launch: the launch has at most
ceil(tests_per_launch / tests_per_thread) threads (and at most ``DEFAULT_TEST_THREADS``)."""

DEFAULT_TEST_THREADS: dict[str, int] = {"cuda": 2**20, "cpu": 1}
"""Threads of the test launch per device kind; each runs a contiguous chunk of the device-known
BV tests (at least ``tests_per_thread``), so the launch size does not depend on device data. One on
the CPU, whose kernel threads run one after the other: each thread there first copied the launch's
argument block and searched its first row (1,024 threads cost 1-3 % of a corpus detection)."""

MAX_GRID_CELLS: int = kernels.MAX_GRID_CELLS
"""Most cells of the grid: a CellId must fit in the high 31 bits of a non-negative int64 key."""

MIN_CELL_BITS: int = 12
"""Initial cell bits of the entry sort (2^12 cells; as many bits as the face count has when that is
more). The sort range must not depend on device data, so the grid guard also coarsens grids with more
cells than 2^cell_bits; :meth:`SpatialHash.check_capacity` then widens the bits and asks for a re-run.
On the CPU the sort's one pass over up to 16 bits clears and scans 2^bits counters: 16 bits for a 5K-face
mesh whose grid has about 700 cells cost 65 us of the sort's 255 (`twisting f48`)."""

MAX_ENTRIES: int = 2**30 - 1
"""Most face-cell entries: entries are int32-indexed and the radix sort needs 2 E slots."""

MAX_PAIRS: int = 2**30 - 1
"""Most emitted face pairs: the pair buffer is int32-indexed and the radix sort needs 2 P slots."""

DEFAULT_SLAB_MIN_WORK: int = 16
"""Two groups are slab-tested only when they would need at least this many face tests (n_g n_h):
a slab test projects the smaller group's vertices, so tiny groups are cheaper to test face by face
(16 since the cell codes made a face test cheaper; ``docs/spatial-hash.md`` section 3a)."""

DEFAULT_SLAB_EXACT_MIN_WORK: int = 64
"""A slab test whose O(1) bound of the smaller group meets the larger group's slab projects the
smaller group's vertices one by one (the exact interval) only when the two groups would need at least
this many face tests (``docs/spatial-hash.md`` section 3a)."""

SLAB_TEST_COST: int = 24
"""What one group slab test costs, in face tests (BV tests), for the slab policy: a call keeps the slab
test for the next call when the face tests it saved exceed this many per slab test plus
:data:`SLAB_GROUP_COST` per group. Fitted to the corpus frames on this 2-core CPU (graph replays with
the test on and off: `twisting`, `cloth_twist`, `unisex_shirt`, `cloth_rollers`): about 57 ns per slab
test (its bound, the exact projection of larger pairs, the row walk) and 54 ns per group, against about
2.5 ns per face test."""

SLAB_GROUP_COST: int = 20
"""What computing one group's slab and sphere and walking its rows costs, in face tests (see
:data:`SLAB_TEST_COST`)."""

SLAB_PROBE_INTERVAL: int = 8
"""After this many calls without the group slab test (the policy found it did not pay), the next call
runs it again and measures anew; twice as many after each probe that found it still does not pay, up to
:data:`SLAB_PROBE_BACKOFF` doublings."""

SLAB_PROBE_BACKOFF: int = 3
"""Most doublings of the probe interval (8, 16, 32, 64 calls). A probe costs its call 13-16 % on
`twisting f48` and `cloth_rollers f3`, where the test does not pay: 1.5 % of every call at one probe in
nine, 0.2 % at one in 65."""

DEFAULT_MAX_MEAN_CELLS_PER_FACE: float = 64.0
"""Grid guard: when the entries exceed this many per face, the cell size is doubled and the
faces are counted again (pairs are unchanged, only culling gets coarser)."""

DEFAULT_MAX_WIDE_FACES: int = 64
"""Most wide faces a call leaves out of the grid (each is box-tested against every face); a call that
finds more inserts every face as usual. 0 turns wide faces off."""

WIDE_FACE_MIN_CELLS: int = 64
WIDE_FACE_SHARE: int = 8
"""A face is wide when its box covers more than max(``WIDE_FACE_MIN_CELLS``, face_count /
``WIDE_FACE_SHARE``) cells of the call's first cell size (from every face's box length): comparing it
with every face then costs fewer box tests than its entries would cost (each entry costs a fill, a sort
slot and the tests of its cell). Wide faces are used only when they are at most face_count /
``WIDE_FACE_SHARE`` (and ``max_wide_faces``)."""

SCENE_CHUNKS: int = 1024
"""Most threads of the scene-bounds reduction (each folds a chunk of faces). A call uses about
sqrt(face_count) chunks of about as many faces, at most this many: the chunk pass and the single thread
that then folds the chunks (scene bounds, long and wide faces) loop about equally long. On an H200 the
single thread's loop over 999 chunks of a 5K-face frame took 0.16 ms of a 0.86 ms replayed detection."""

CODE_MASK_MIN_RUN: int = 4
"""Entries of a row segment (entry a against consecutive entries of later groups of its cell) from which
the test pass finds the entries that pass a's code test through the code masks (nine words per 64
entries, :mod:`pscc.collision._code_mask_kernels`) rather than code by code. The pairs are the same."""

CELL_CODE_MIN_TESTS: int = 4
"""BV tests per entry from which a call's test pass first compares the entries' cell codes (4 bytes,
read in entry order) and loads the boxes only of pairs whose codes overlap; below it, writing the codes
costs more than they save (measured on the corpus frames: about 8 ns per code, 1.2 ns saved per test)."""

GROWTH: float = 1.25
"""Grown buffers get this factor over the exact count, so small increases do not re-grow."""


@dataclass
class SpatialHashStats:
    """Counters of the last call that :meth:`SpatialHash.check_capacity` read (every
    :meth:`SpatialHash.find_pairs` call ends with one).

    Attributes:
        cell_size: cell edge used (float32 value; larger than requested after coarsening).
        grid_dims: (N_x, N_y, N_z) cells per axis.
        entries: face-cell insertions E.
        groups: distinct {cell, node} keys (triangleHashTable rows).
        cells: non-empty cells (workLoadHashTable rows).
        bv_tests: bounding-volume tests run: ``face_tests + slab_tests + wide_tests``.
        face_tests: face box tests run: sum over cells of sum_{i<j} n_i n_j over the group pairs
            that are not culled by a slab test (all of them when the slab test is off).
        slab_tests: group slab tests run (0 when the slab test is off).
        rows: work rows (a group against a run of later groups of its cell).
        triangle_pairs: face pairs emitted (unique, a < b).
        mean_cells_per_face: E / face_count.
        coarsenings: times the cell size was doubled by the grid guard.
        reruns: times the call ran again because the pair buffer grew (re-runs for the other
            buffers, which overflow before any pair is tested, are not counted).
        same_node_tests: face pairs of one node that met in a cell in two groups (never tested; 0
            unless a ``face_order`` splits a node; checked by the tests).
        wide_faces: faces left out of the grid because their boxes were too large for it (each
            box-tested against every other face instead).
        wide_tests: face box tests against the wide faces (in ``bv_tests``, not in ``face_tests``).
        wide_cell_size: the cell edge c0 of the wide test (0 when no face was wide): a face is wide
            when prod_k (e_k / c0 + 1) > max(64, face_count / 8), e its box extent.
        long_faces: grid faces whose mean box axis length exceeds 3 times the grid faces' mean, left out
            of the mean that sets the cell size (0 with an explicit ``cell_size``).
        device_bytes: bytes held on the device, per buffer.
    """

    cell_size: float = 0.0
    grid_dims: tuple[int, int, int] = (0, 0, 0)
    entries: int = 0
    groups: int = 0
    cells: int = 0
    bv_tests: int = 0
    face_tests: int = 0
    slab_tests: int = 0
    rows: int = 0
    triangle_pairs: int = 0
    mean_cells_per_face: float = 0.0
    coarsenings: int = 0
    reruns: int = 0
    same_node_tests: int = 0
    wide_faces: int = 0
    wide_tests: int = 0
    wide_cell_size: float = 0.0
    long_faces: int = 0
    device_bytes: dict[str, int] = field(default_factory=dict)

    @classmethod
    def from_summary(cls, summary: np.ndarray, face_count: int, reruns: int,
                     device_bytes: dict[str, int]) -> SpatialHashStats:
        """The stats of a call from the hash's summary array read back at its sync point (the ``info``
        counters first, then the grid dims, cell size, pair count and wide cell)."""
        stats = cls(reruns=reruns)
        if face_count == 1:
            stats.entries = stats.groups = stats.cells = 1
            stats.mean_cells_per_face = 1.0
        elif face_count >= 2:
            stats.cell_size = float(summary[kernels.SUMMARY_CELL_SIZE])
            stats.grid_dims = tuple(int(v) for v in summary[kernels.SUMMARY_DIMS: kernels.SUMMARY_DIMS + 3])
            stats.entries = int(summary[kernels.INFO_ENTRIES])
            stats.groups = int(summary[kernels.INFO_GROUPS])
            stats.cells = int(summary[kernels.INFO_CELLS])
            stats.rows = int(summary[kernels.INFO_ROWS])
            stats.face_tests = int(summary[kernels.INFO_FACE_TESTS])
            stats.slab_tests = int(summary[kernels.INFO_SLAB_TESTS])
            stats.same_node_tests = int(summary[kernels.INFO_SAME_NODE])
            stats.wide_faces = int(summary[kernels.INFO_WIDE_FACES])
            stats.wide_tests = int(summary[kernels.INFO_WIDE_TESTS])
            stats.wide_cell_size = float(summary[kernels.SUMMARY_WIDE_CELL])
            stats.long_faces = int(summary[kernels.INFO_LONG_FACES])
            stats.bv_tests = stats.face_tests + stats.slab_tests + stats.wide_tests
            stats.triangle_pairs = int(summary[kernels.SUMMARY_PAIRS])
            stats.coarsenings = int(summary[kernels.INFO_COARSENINGS])
            stats.mean_cells_per_face = stats.entries / face_count
        stats.device_bytes = device_bytes
        return stats


def check_integer(value: object, name: str, low: int, high: int | None, fix: str) -> int:
    """``value`` as an int, or an InputError naming the argument ``name`` (with ``fix``) when it is not an
    integer in [low, high] (``high`` None: no upper end). Booleans are refused."""
    if (isinstance(value, bool) or not isinstance(value, int | np.integer) or value < low
            or (high is not None and value > high)):
        bounds = f">= {low}" if high is None else f"in [{low}, {high}]"
        raise InputError("argument", name, f"{value!r} is not an integer {bounds}", fix)
    return int(value)


def check_positive(value: float, name: str) -> float:
    """``value`` as a float, or an InputError naming the argument ``name`` when it is not a finite number > 0."""
    try:
        number = float(value)
    except (TypeError, ValueError) as exc:
        raise InputError("argument", name, f"{value!r} is not a number", "pass a finite float > 0") from exc
    if not math.isfinite(number) or number <= 0.0:
        raise InputError("argument", name, f"{value!r} is not a finite number > 0", "pass a finite float > 0")
    return number


def raise_counted_input_errors(info: list[int], ordered: bool, node_limit: int) -> None:
    """Raise the input errors that a spatial hash call counted on the device (``info``: its counters as
    Python ints), in the order the checks run."""
    if info[kernels.INFO_BAD_ORDER] > 0:
        raise InputError("argument", "face_order", "is not a permutation of the faces",
                         "pass each face id exactly once")
    if info[kernels.INFO_BAD_BOXES] > 0:
        raise InputError("argument", "face_lower/face_upper",
                         f"{int(info[kernels.INFO_BAD_BOXES])} boxes hold NaN/Inf or have lower > upper on "
                         "some axis", "pass finite boxes with lower <= upper")
    if node_limit > 0 and info[kernels.INFO_BAD_NODES] > 0:
        raise InputError("argument", "node_id",
                         f"{int(info[kernels.INFO_BAD_NODES])} node ids lie outside [0, {node_limit})",
                         "pass node ids below node_id_bound, or node_id_bound=None")
    if ordered and info[kernels.INFO_SAME_NODE] > 0:
        raise InputError("argument", "face_order", "faces of one node are not contiguous in it",
                         "pass an order in which equal node ids are adjacent, or None")


FIT_MARGIN: float = 1.25
"""A table fitted to its use (:func:`fitted_capacities`) keeps this many slots per slot used, plus half of
:data:`FIT_SLACK`."""

FIT_SLACK: int = 1024
"""Slots a table keeps beyond 1.5 x its use before :func:`fitted_capacities` shrinks it (small tables are
never shrunk)."""


def fitted_capacities(capacities: dict[int, int], used: dict[int, int]) -> dict[int, int]:
    """The capacities to shrink the hash's tables to (:meth:`SpatialHash.trim` indices 0-4: entries, groups,
    rows, pairs, slab tables) given the slots a call (or the peak of several) used: FIT_MARGIN x the use plus
    half of FIT_SLACK, for every table that holds more than 1.5 x its use plus FIT_SLACK. Tables nearer
    their use are left out (a growth leaves 1.5 x, so a fit right after one changes nothing); an empty
    result means nothing to shrink.

    The recorded graph sorts, pads and scans the whole entry capacity: a 5K-face frame that uses 11.9K of
    the 20K entry slots its detector starts with pays for the other 8K on every replay."""
    targets = {}
    for k, capacity in capacities.items():
        use = int(used.get(k, capacity))
        if capacity > 1.5 * use + FIT_SLACK:
            targets[k] = int(FIT_MARGIN * use) + FIT_SLACK // 2
    return targets
