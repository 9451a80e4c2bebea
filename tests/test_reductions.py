"""Allocation-free prefix sums and inner products (pscc._reductions) against numpy, on both paths."""

from __future__ import annotations

import numpy as np
import pytest
import warp as wp

from pscc._reductions import DOT_TILE, SCAN_CHUNK, InnerProduct, PrefixSum
from pscc.bench.host_traffic import device_path_traffic

SIZES = [1, 2, SCAN_CHUNK - 1, SCAN_CHUNK, SCAN_CHUNK + 1, SCAN_CHUNK**2, SCAN_CHUNK**2 + 1, DOT_TILE + 3,
         SCAN_CHUNK**3 + 5]


def _expected_scan(values: np.ndarray, inclusive: bool) -> np.ndarray:
    total = np.cumsum(values, dtype=values.dtype)
    return total if inclusive else np.concatenate([np.zeros(1, values.dtype), total[:-1]])


@pytest.mark.parametrize("own_kernels", [True, None])
@pytest.mark.parametrize("dtype", [np.int32, np.int64])
def test_prefix_sums_equal_numpy_at_every_chunk_boundary(device: str, own_kernels: bool | None,
                                                         dtype: type) -> None:
    rng = np.random.default_rng(3)
    scan = PrefixSum(device, 4, own_kernels=own_kernels)  # grows on the longer arrays
    for n in SIZES:
        values = rng.integers(-3, 9, n).astype(dtype)
        source = wp.array(values, device=device)
        out = wp.full(n, 77, dtype=source.dtype, device=device)
        for inclusive in (True, False):
            scan(source, out, inclusive=inclusive)
            np.testing.assert_array_equal(out.numpy(), _expected_scan(values, inclusive), err_msg=f"{n} {inclusive}")
        np.testing.assert_array_equal(source.numpy(), values)  # the input is left alone


def test_int64_sums_past_the_int32_range(device: str) -> None:
    values = np.full(SCAN_CHUNK**2 + 7, 2**31 - 1, np.int64)
    out = wp.zeros(values.shape[0], dtype=wp.int64, device=device)
    PrefixSum(device, own_kernels=True)(wp.array(values, device=device), out)
    assert out.numpy()[-1] == values.sum() > 2**40


@pytest.mark.parametrize("own_kernels", [True, None])
def test_inner_products_equal_numpy_within_float32_rounding(device: str, own_kernels: bool | None) -> None:
    rng = np.random.default_rng(4)
    inner = InnerProduct(device, 1, own_kernels=own_kernels)
    result = wp.full(3, 5.0, dtype=float, device=device)
    for n in [*SIZES, 3 * DOT_TILE * DOT_TILE + 11]:
        a, b = rng.standard_normal((2, n, 3)).astype(np.float32)
        inner(wp.array(a, dtype=wp.vec3, device=device), wp.array(b, dtype=wp.vec3, device=device), result[1:2])
        expected = float((a.astype(np.float64) * b).sum())
        bound = n * 6e-8 * 3 * float(np.abs(a.astype(np.float64) * b).sum()) + 1e-30
        got = result.numpy()
        assert abs(got[1] - expected) <= bound, (n, got[1], expected, bound)
        assert got[0] == got[2] == 5.0  # only the one element is written
    # A shorter array after a longer one reads only its own partial sums.
    a = np.ones((5, 3), np.float32)
    inner(wp.array(a, dtype=wp.vec3, device=device), wp.array(a, dtype=wp.vec3, device=device), result[1:2])
    assert result.numpy()[1] == 15.0


def test_own_kernels_run_in_a_graph_loop_with_no_traffic_and_no_allocation(device: str) -> None:
    """The case they exist for: inside a ``wp.capture_while`` body (on CUDA a conditional graph node)."""
    n = SCAN_CHUNK**2 + 9
    rng = np.random.default_rng(5)
    values = rng.integers(0, 4, n).astype(np.int32)
    source = wp.array(values, device=device)
    out = wp.zeros(n, dtype=wp.int32, device=device)
    vectors = wp.array(rng.standard_normal((n, 3)).astype(np.float32), dtype=wp.vec3, device=device)
    result = wp.zeros(1, dtype=float, device=device)
    rounds = wp.zeros(1, dtype=wp.int32, device=device)
    scan, inner = PrefixSum(device, n, own_kernels=True), InnerProduct(device, n, own_kernels=True)

    @wp.kernel
    def count_down(rounds: wp.array(dtype=wp.int32)):
        rounds[0] = rounds[0] - 1

    def body() -> None:
        scan(source, out)
        inner(vectors, vectors, result)
        wp.launch(count_down, dim=1, outputs=[rounds], device=device)

    def loop() -> None:
        rounds.fill_(3)
        wp.capture_while(rounds, body)

    loop()  # loads the modules
    out.zero_()
    traffic = device_path_traffic(device, loop, calls=2)
    assert traffic == {"reads": 0, "syncs": 0, "uploads": 0, "allocations": 0}
    np.testing.assert_array_equal(out.numpy(), np.cumsum(values))
    expected = float((vectors.numpy().astype(np.float64) ** 2).sum())
    assert abs(result.numpy()[0] - expected) <= 1e-5 * expected
    assert rounds.numpy()[0] == 0
