"""The spatial hash's code masks (pscc.collision._code_mask_kernels): per block of 64 sorted entries, the
words that let the test pass find the entries passing a code test 64 at a time. The words give exactly
the entries that the code-by-code test (overlap and token) passes, for any codes and blocks that span
cells; the hash and the detector give the same pairs with the masks on every run and never."""

from __future__ import annotations

import numpy as np
import pytest
import warp as wp
from hypothesis import given, settings
from hypothesis import strategies as st

from pscc.collision._code_mask_kernels import (
    ENTRIES_PER_BLOCK,
    WORDS_PER_BLOCK,
    block_count,
    code_mask_query,
    lowest_bit,
    write_code_masks,
)
from pscc.collision._hash_row_kernels import cell_codes_overlap, code_minuend, code_subtrahend, codes_hold_token
from pscc.collision._spatial_hash_kernels import INFO_CELL_CODES, INFO_LIVE_ENTRIES, INFO_SIZE, INFO_TEST_CHUNK
from pscc.collision.detector import CollisionDetector
from pscc.collision.spatial_hash import SpatialHash
from pscc.errors import InputError
from pscc.mesh import folded_sheet
from tests.collision.test_group_slab import _twist
from tests.collision.test_spatial_hash import _reference

DEVICE = "cpu"


@wp.kernel
def _compare_queries(
    codes: wp.array(dtype=wp.uint32),
    masks: wp.array(dtype=wp.uint64),
    live: int,
    out: wp.array(dtype=wp.int32),
):
    """Thread a: for every live entry b, bit 0 of out[a * live + b] = the masks' answer, bit 1 = the
    code-by-code answer."""
    a = wp.tid()
    code_a = codes[a]
    for b in range(live):
        word = code_mask_query(masks, b / 64, code_a)
        by_mask = int((word >> wp.uint64(b % 64)) & wp.uint64(1))
        code_b = codes[b]
        by_code = int(cell_codes_overlap(code_minuend(code_a), code_subtrahend(code_a), code_b)
                      and codes_hold_token(code_a, code_b))
        out[a * live + b] = by_mask + 2 * by_code


@wp.kernel
def _lowest_bits(words: wp.array(dtype=wp.uint64), out: wp.array(dtype=wp.int32)):
    i = wp.tid()
    out[i] = lowest_bit(words[i])


def _random_codes(rng: np.random.Generator, n: int) -> np.ndarray:
    """Codes as ``entry_cell_code`` packs them (upper ends 1-15 in bits 0-14, lower ends 0-15 in bits
    15-29), with many lower ends 0 (boxes that start in an earlier cell) and ends at 1 and 15."""
    upper = rng.integers(1, 16, size=(n, 3))
    lower = np.where(rng.random((n, 3)) < 0.3, 0, rng.integers(0, 16, size=(n, 3)))
    lower = np.minimum(lower, upper)
    edge = rng.random((n, 3)) < 0.1
    upper = np.where(edge, 15, upper)
    code = np.zeros(n, dtype=np.int64)
    for k in range(3):
        code |= upper[:, k].astype(np.int64) << (5 * k)
        code |= lower[:, k].astype(np.int64) << (15 + 5 * k)
    return code.astype(np.uint32)


@pytest.mark.parametrize("per_word", [False, True], ids=["per-block", "per-word"])
@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), live=st.integers(1, 300))
def test_masks_give_exactly_the_code_test(per_word: bool, seed: int, live: int) -> None:
    """Random codes in several blocks (the last one part full, and a slot capacity past the live
    entries): for every entry pair the masks' bit is the code test's answer, and the masks never set a
    bit of a slot past the live entries; the GPU's per-word form (forced here on the CPU) writes the
    CPU's per-block words, bit for bit."""
    rng = np.random.default_rng(seed)
    capacity = live + 70
    codes = np.zeros(capacity, dtype=np.uint32)
    codes[:live] = _random_codes(rng, live)
    codes[live:] = _random_codes(rng, capacity - live)  # stale codes past the live count: never set bits
    info = np.zeros(INFO_SIZE, dtype=np.int64)
    info[INFO_LIVE_ENTRIES] = live
    info[INFO_CELL_CODES] = 1
    info[INFO_TEST_CHUNK] = 64  # the CPU's tests per thread: runs through the masks
    blocks = block_count(capacity)
    masks = wp.full(blocks * WORDS_PER_BLOCK, value=wp.uint64(0xDEADBEEF), dtype=wp.uint64, device=DEVICE)
    codes_wp = wp.array(codes, dtype=wp.uint32, device=DEVICE)
    info_wp = wp.array(info, dtype=wp.int64, device=DEVICE)
    write_code_masks(codes_wp, info_wp, masks, capacity, 4, wp.get_device(DEVICE), per_word=per_word)
    other = wp.full(blocks * WORDS_PER_BLOCK, value=wp.uint64(0xDEADBEEF), dtype=wp.uint64, device=DEVICE)
    write_code_masks(codes_wp, info_wp, other, capacity, 4, wp.get_device(DEVICE), per_word=not per_word)
    np.testing.assert_array_equal(masks.numpy(), other.numpy())
    out = wp.zeros(live * live, dtype=wp.int32, device=DEVICE)
    wp.launch(_compare_queries, dim=live, inputs=[codes_wp, masks, live], outputs=[out], device=DEVICE)
    got = out.numpy().reshape(live, live)
    np.testing.assert_array_equal(got & 1, got >> 1)
    if live > 20:
        assert 0 < (got & 1).sum() < live * live
    # Slots past the live entries (in the last written block) never pass.
    words = masks.numpy().reshape(blocks, WORDS_PER_BLOCK)
    last_block = (live - 1) // ENTRIES_PER_BLOCK
    used = live - last_block * ENTRIES_PER_BLOCK
    if used < 64:
        stale = ~np.uint64((1 << used) - 1)
        assert not np.any(words[last_block] & stale)


@pytest.mark.parametrize("per_word", [False, True], ids=["per-block", "per-word"])
@pytest.mark.parametrize("unread", ["no codes", "short chunks"])
def test_masks_are_not_written_where_nothing_reads_them(per_word: bool, unread: str) -> None:
    """A call that reads no cell codes, or whose test threads run chunks shorter than the minimum run
    through the masks (a GPU's one BV test per thread), leaves the masks alone; with codes and long
    chunks the same call writes them."""
    info = np.zeros(INFO_SIZE, dtype=np.int64)
    info[INFO_LIVE_ENTRIES] = 10
    info[INFO_CELL_CODES] = 0 if unread == "no codes" else 1
    info[INFO_TEST_CHUNK] = 64 if unread == "no codes" else 3
    codes = wp.array(_random_codes(np.random.default_rng(1), 10), dtype=wp.uint32, device=DEVICE)
    masks = wp.full(WORDS_PER_BLOCK, value=wp.uint64(7), dtype=wp.uint64, device=DEVICE)
    write_code_masks(codes, wp.array(info, dtype=wp.int64, device=DEVICE), masks, 10, 4, wp.get_device(DEVICE),
                     per_word=per_word)
    assert np.all(masks.numpy() == 7)
    info[INFO_CELL_CODES], info[INFO_TEST_CHUNK] = 1, 4
    write_code_masks(codes, wp.array(info, dtype=wp.int64, device=DEVICE), masks, 10, 4, wp.get_device(DEVICE),
                     per_word=per_word)
    assert not np.all(masks.numpy() == 7)


def test_lowest_bit() -> None:
    words = np.array([1, 2, 8, 1 << 40, (1 << 63) | (1 << 5), 12, 1 << 63], dtype=np.uint64)
    out = wp.zeros(words.shape[0], dtype=wp.int32, device=DEVICE)
    wp.launch(_lowest_bits, dim=words.shape[0], inputs=[wp.array(words, dtype=wp.uint64, device=DEVICE)],
              outputs=[out], device=DEVICE)
    np.testing.assert_array_equal(out.numpy(), [0, 1, 3, 40, 5, 2, 63])


def _pairs(lower, upper, node, cell_size, min_run: int, test_threads: int | None = None) -> tuple[np.ndarray, int]:
    hash_ = SpatialHash(lower.shape[0], DEVICE, cell_code_min_tests=0, code_mask_min_run=min_run,
                        test_threads=test_threads, tests_per_thread=None if test_threads is None else 1)
    hash_.find_pairs(wp.array(lower, dtype=wp.vec3, device=DEVICE), wp.array(upper, dtype=wp.vec3, device=DEVICE),
                     wp.array(node, dtype=wp.int32, device=DEVICE), cell_size)
    if test_threads is not None:  # the GPU's shape: one BV test per thread, so runs of one entry
        assert int(hash_.info.numpy()[INFO_TEST_CHUNK]) == 1
    return hash_.pairs_numpy(), int(hash_.info.numpy()[INFO_CELL_CODES])


@pytest.mark.parametrize("layout", ["crowded", "lattice", "points"])
def test_hash_pairs_are_the_same_with_and_without_masks(layout: str) -> None:
    """Cells of hundreds of entries (blocks that span cells and cells that span blocks), boxes touching on
    cell faces, points on cell corners: brute force's box pairs with the masks on every run (1), on runs of
    at least 8, and never; and with a GPU's one BV test per thread, masks skipped or read entry by entry."""
    rng = np.random.default_rng(3)
    m = 900
    if layout == "crowded":
        lower = rng.uniform(0.0, 3.0, size=(m, 3)).astype(np.float32)
        upper = lower + rng.uniform(0.0, 0.5, size=(m, 3)).astype(np.float32)
        cell_size = 1.5
    elif layout == "lattice":
        lower = rng.integers(0, 6, size=(m, 3)).astype(np.float32) * np.float32(0.5)
        upper = lower + rng.integers(0, 3, size=(m, 3)).astype(np.float32) * np.float32(0.5)
        cell_size = 1.0
    else:
        lower = rng.integers(0, 4, size=(m, 3)).astype(np.float32)
        upper = lower.copy()
        cell_size = 1.0
    node = rng.integers(0, m // 4, size=m).astype(np.int32)
    expected = _reference(lower, upper, node)
    assert expected.shape[0] > 1000
    # Last two: a GPU's launch shape (a thread per BV test), where a minimum run of 4 leaves the masks
    # unwritten and unread, and a minimum run of 1 writes them and reads them one entry at a time.
    for min_run, threads in ((1, None), (8, None), (2**31 - 1, None), (4, 2**20), (1, 2**20)):
        pairs, used = _pairs(lower, upper, node, cell_size, min_run, threads)
        assert used == 1
        np.testing.assert_array_equal(pairs, expected)


@pytest.mark.parametrize("continuous", [False, True])
def test_detector_pairs_do_not_change(continuous: bool) -> None:
    """Twisted layers with pscc's front and group slab test (rows split into runs): the same triangle
    pairs and VF / EE rows with the masks on every run and never."""
    mesh = folded_sheet(1500, layers=3, seed=11)
    x0 = _twist(mesh.vertices, 0.5)
    x1 = _twist(mesh.vertices_end, 0.52)
    h = 0.3 * float(np.linalg.norm(x0[mesh.faces[:, 0]] - x0[mesh.faces[:, 1]], axis=1).mean())
    results = []
    for min_run in (1, 2**31 - 1):
        det = CollisionDetector(mesh.faces, method="pscc", rest=mesh.rest, device=DEVICE)
        det.detect(x0, x1 if continuous else None, thickness=h)
        det.spatial_hash.code_mask_min_run = min_run
        det.spatial_hash.cell_code_min_tests = 0
        result = det.detect(x0, x1 if continuous else None, thickness=h)
        pairs = det.spatial_hash.pairs_numpy()
        results.append((result, pairs[np.lexsort((pairs[:, 1], pairs[:, 0]))]))
    (on, pairs_on), (off, pairs_off) = results
    assert on.vertex_face.shape[0] + on.edge_edge.shape[0] > 0
    np.testing.assert_array_equal(pairs_on, pairs_off)
    np.testing.assert_array_equal(on.vertex_face, off.vertex_face)
    np.testing.assert_array_equal(on.edge_edge, off.edge_edge)


@pytest.mark.parametrize("bad", [0, -1, 2**31, 1.5, True, "4"])
def test_bad_min_run(bad: object) -> None:
    with pytest.raises(InputError, match="code_mask_min_run"):
        SpatialHash(10, DEVICE, code_mask_min_run=bad)
