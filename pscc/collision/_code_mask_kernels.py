"""Bit masks over the sorted entries' cell codes, so that the test pass finds the entries whose codes
overlap an entry's in a 64-entry word at a time (private: :class:`pscc.collision.spatial_hash.SpatialHash`
builds them, :func:`pscc.collision._hash_row_kernels._test_bounding_volumes` reads them).

The cell codes (:func:`pscc.collision._hash_row_kernels.entry_cell_code`) hold, per axis k, a box's
lower end ``lo_k`` in 0..15 (0: it starts in an earlier cell) and its upper end ``up_k`` in 1..15. Two
entries a and b of one cell pass the code test when, on every axis, ``lo_b <= up_a`` and
``up_b >= lo_a`` (their quantised intervals overlap) and ``lo_a != 0`` or ``lo_b != 0`` (the cell
holds the token). For every *block* of 64 consecutive sorted entries (block w holds entries
64 w .. 64 w + 63, whatever their cells), :func:`_write_code_masks` keeps 96 words:

===========================  =====================================================================
word ``96 w + 32 k + q``     bit j set when entry 64 w + j has ``lo_k <= q`` (q = 0..15)
word ``96 w + 32 k + 16 + q``  bit j set when entry 64 w + j has ``up_k >= q`` (q = 0..15)
===========================  =====================================================================

so the entries of block w that pass entry a's code test are the AND over the three axes of
``word[32 k + up_a]``, ``word[32 k + 16 + lo_a]`` and, where ``lo_a = 0``, the complement of
``word[32 k]`` (:func:`code_mask_query`): nine loads for 64 code tests. Bits of entries past the live
count are never set in the first two families, so they never pass. The test pass restricts the
word to the entry range of its row, whose entries all lie in one cell, so a block that spans two
cells needs nothing more. The set of entries found is exactly the set the code-by-code scan finds.
"""

from __future__ import annotations

import warp as wp

from pscc.collision._spatial_hash_kernels import _CELL_CODES, _LIVE_ENTRIES, _TEST_CHUNK

wp.set_module_options({"enable_backward": False})

ENTRIES_PER_BLOCK: int = 64
"""Sorted entries per mask block (bits of one word)."""

WORDS_PER_BLOCK: int = 96
"""Mask words per block: 3 axes x (16 lower-end prefixes + 16 upper-end suffixes)."""

_WORDS_PER_BLOCK = wp.constant(WORDS_PER_BLOCK)
ALL_BITS = wp.constant(wp.uint64(0xFFFFFFFFFFFFFFFF))
"""A 64-bit word with every bit set."""

_LOWEST_BIT_SNIPPET = """
#if defined(__CUDA_ARCH__)
    return __ffsll((long long)word) - 1;
#else
    return __builtin_ctzll(word);
#endif
"""


@wp.func_native(_LOWEST_BIT_SNIPPET)
def lowest_bit(word: wp.uint64) -> int:
    """Index of the lowest set bit of ``word`` (which must not be 0)."""
    ...


def block_count(entry_capacity: int) -> int:
    """Mask blocks for ``entry_capacity`` sorted entry slots."""
    return -(-int(entry_capacity) // ENTRIES_PER_BLOCK)


@wp.func
def _masks_unread(info: wp.array(dtype=wp.int64), first: int, mask_min_run: int) -> bool:
    """True when the test pass reads no mask word of the block starting at entry ``first``: the call reads
    no cell codes, the block lies past the live entries, or no test thread's chunk of BV tests is as long
    as ``mask_min_run`` (a run through the masks lies inside one chunk; a GPU running one BV test per
    thread never reads them)."""
    return (info[_CELL_CODES] == wp.int64(0) or wp.int64(first) >= info[_LIVE_ENTRIES]
            or info[_TEST_CHUNK] < wp.int64(mask_min_run))


@wp.kernel
def _write_code_masks(
    # in:
    entry_code: wp.array(dtype=wp.uint32),
    info: wp.array(dtype=wp.int64),
    mask_min_run: int,
    # out:
    code_masks: wp.array(dtype=wp.uint64),
):
    """One thread per block of 64 entry slots (nothing where the masks go unread: :func:`_masks_unread`):
    each entry sets its bit in the word of its lower end and of its upper end per axis, then prefix ORs
    turn them into the ``lo <= q`` and ``up >= q`` words (module docstring)."""
    block = wp.tid()
    live = info[_LIVE_ENTRIES]
    first = block * 64
    if _masks_unread(info, first, mask_min_run):
        return
    base = block * _WORDS_PER_BLOCK
    for w in range(_WORDS_PER_BLOCK):
        code_masks[base + w] = wp.uint64(0)
    last = int(wp.min(wp.int64(first + 64), live))
    for i in range(first, last):
        code = entry_code[i]
        bit = wp.uint64(1) << wp.uint64(i - first)
        for k in range(3):
            upper = int((code >> wp.uint32(5 * k)) & wp.uint32(15))
            lower = int((code >> wp.uint32(15 + 5 * k)) & wp.uint32(15))
            code_masks[base + 32 * k + lower] = code_masks[base + 32 * k + lower] | bit
            code_masks[base + 32 * k + 16 + upper] = code_masks[base + 32 * k + 16 + upper] | bit
    for k in range(3):
        low = base + 32 * k
        for q in range(1, 16):
            code_masks[low + q] = code_masks[low + q] | code_masks[low + q - 1]
        high = low + 16
        for r in range(15):
            q = 14 - r
            code_masks[high + q] = code_masks[high + q] | code_masks[high + q + 1]


@wp.kernel
def _write_code_mask_words(
    # in:
    entry_code: wp.array(dtype=wp.uint32),
    info: wp.array(dtype=wp.int64),
    mask_min_run: int,
    # out:
    code_masks: wp.array(dtype=wp.uint64),
):
    """One thread per mask word (96 per block of 64 entry slots): the same words as
    :func:`_write_code_masks`, each ORed from the block's codes in registers and written once. On a GPU
    that thread's loop reads codes that its block's other 95 threads read at the same time, where
    :func:`_write_code_masks` reads and writes global words one after another (0.14 ms on an H200 for a
    5K-face frame, where nothing read them; this form has not been timed on its own: a GPU call writes
    masks only past about 4M BV tests)."""
    word = wp.tid()
    block = word // _WORDS_PER_BLOCK
    slot = word - block * _WORDS_PER_BLOCK
    live = info[_LIVE_ENTRIES]
    first = block * 64
    if _masks_unread(info, first, mask_min_run):
        return
    k = slot // 32
    q = slot - 32 * k
    upper_word = q >= 16
    shift = wp.uint32(5 * k)
    if not upper_word:
        shift = wp.uint32(15 + 5 * k)
    else:
        q = q - 16
    last = int(wp.min(wp.int64(first + 64), live))
    bits = wp.uint64(0)
    for i in range(first, last):
        end = int((entry_code[i] >> shift) & wp.uint32(15))
        if (upper_word and end >= q) or (not upper_word and end <= q):
            bits = bits | (wp.uint64(1) << wp.uint64(i - first))
    code_masks[word] = bits


def write_code_masks(entry_code: wp.array, info: wp.array, code_masks: wp.array, entry_capacity: int,
                     mask_min_run: int, device: wp.Device, per_word: bool | None = None) -> None:
    """Launch the code masks of ``entry_capacity`` entry slots (module docstring), where the test pass
    will read them (runs of at least ``mask_min_run`` entries): one thread per mask word on a GPU
    (:func:`_write_code_mask_words`), one per block of 64 entries on the CPU, where Warp runs threads one
    after another and the per-word form would read every code 96 times. ``per_word`` forces one form
    (the tests compare them)."""
    blocks = block_count(entry_capacity)
    inputs = [entry_code, info, int(mask_min_run)]
    if device.is_cuda if per_word is None else per_word:
        wp.launch(_write_code_mask_words, dim=blocks * WORDS_PER_BLOCK, inputs=inputs, outputs=[code_masks],
                  device=device)
    else:
        wp.launch(_write_code_masks, dim=blocks, inputs=inputs, outputs=[code_masks], device=device)


@wp.func
def code_mask_query(code_masks: wp.array(dtype=wp.uint64), block: int, code_a: wp.uint32) -> wp.uint64:
    """The entries of ``block`` whose cell codes pass entry a's code test (overlap on every axis and
    hold the token with it), as bits; entries of other cells in the block must be masked off by the
    caller."""
    base = block * _WORDS_PER_BLOCK
    bits = ALL_BITS
    for k in range(3):
        upper = int((code_a >> wp.uint32(5 * k)) & wp.uint32(15))
        lower = int((code_a >> wp.uint32(15 + 5 * k)) & wp.uint32(15))
        bits = bits & code_masks[base + 32 * k + upper] & code_masks[base + 32 * k + 16 + lower]
        if lower == 0:
            bits = bits & ~code_masks[base + 32 * k]
    return bits
