"""PreconditionedConjugateGradient against a dense float64 solve."""

from __future__ import annotations

import numpy as np
import warp as wp
from warp.sparse import bsr_from_triplets

from pscc.sim.pcg import PreconditionedConjugateGradient


def _system(device: str, n: int = 40, seed: int = 0):
    rng = np.random.default_rng(seed)
    dense = rng.normal(size=(3 * n, 3 * n))
    dense = dense @ dense.T / (3 * n) + np.eye(3 * n)  # SPD, condition ~ 5
    rows, cols = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
    blocks = dense.reshape(n, 3, n, 3).transpose(0, 2, 1, 3).reshape(n * n, 3, 3)
    matrix = bsr_from_triplets(n, n, wp.array(rows.ravel(), dtype=int, device=device),
                               wp.array(cols.ravel(), dtype=int, device=device),
                               wp.array(blocks.astype(np.float32), dtype=wp.mat33, device=device))
    b = rng.normal(size=(n, 3))
    return dense, matrix, b


def test_pcg_matches_dense_solve(device: str) -> None:
    dense, matrix, b = _system(device)
    n = b.shape[0]
    rhs = wp.array(b.astype(np.float32), dtype=wp.vec3, device=device)
    x = wp.zeros(n, dtype=wp.vec3, device=device)
    inverse_diagonal = np.diag(1.0 / np.diag(dense)).astype(np.float32)

    def jacobi(r: wp.array, z: wp.array) -> None:
        z.assign((r.numpy().reshape(-1) @ inverse_diagonal).reshape(-1, 3))

    for precondition in (None, jacobi):
        x.zero_()
        solver = PreconditionedConjugateGradient(matrix, rhs, x, 1e-5, 200, 1, precondition)
        iterations, residual, absolute = solver()
        assert 0 < iterations < 60 and residual <= absolute
        expected = np.linalg.solve(dense, b.reshape(-1)).reshape(-1, 3)
        np.testing.assert_allclose(x.numpy(), expected, atol=1e-4 * np.abs(expected).max())


def test_pcg_warm_start_at_solution_does_no_iteration(device: str) -> None:
    dense, matrix, b = _system(device, n=10, seed=1)
    rhs = wp.array(b.astype(np.float32), dtype=wp.vec3, device=device)
    x = wp.zeros(10, dtype=wp.vec3, device=device)
    solver = PreconditionedConjugateGradient(matrix, rhs, x, 1e-4, 100, 5)
    solver()
    iterations, residual, absolute = solver()  # x already solves the system
    assert iterations == 0 and residual <= absolute
    rhs.zero_()
    x.zero_()
    assert solver()[0] == 0  # zero right-hand side: nothing to do


def _diagonal_preconditioner(dense: np.ndarray, device: str):
    inverse = wp.array((1.0 / np.diag(dense)).reshape(-1, 3).astype(np.float32), dtype=wp.vec3, device=device)

    @wp.kernel
    def scale(inverse: wp.array(dtype=wp.vec3), r: wp.array(dtype=wp.vec3), z: wp.array(dtype=wp.vec3)):
        i = wp.tid()
        z[i] = wp.cw_mul(inverse[i], r[i])

    def precondition(r: wp.array, z: wp.array) -> None:
        wp.launch(scale, dim=r.shape[0], inputs=[inverse, r, z], device=device)

    return precondition


def test_pcg_replayed_from_a_graph_is_bit_identical_and_reads_nothing(device: str, monkeypatch) -> None:
    """The whole solve, convergence loop included, captures into a graph; replays read nothing back."""
    dense, matrix, b = _system(device, n=30, seed=2)
    rhs = wp.array(b.astype(np.float32), dtype=wp.vec3, device=device)
    x = wp.zeros(30, dtype=wp.vec3, device=device)
    solver = PreconditionedConjugateGradient(matrix, rhs, x, 1e-5, 200, 4, _diagonal_preconditioner(dense, device))
    eager_iterations = solver()[0]
    eager = x.numpy().copy()
    assert 0 < eager_iterations < 200

    x.zero_()
    with wp.ScopedCapture(device=device) as capture:
        solver.launch()
    reads = {"n": 0}
    real_numpy = wp.array.numpy

    def counting_numpy(self: wp.array) -> np.ndarray:
        reads["n"] += 1
        return real_numpy(self)

    for _ in range(2):  # replays start from the same x
        x.zero_()
        monkeypatch.setattr(wp.array, "numpy", counting_numpy)
        wp.capture_launch(capture.graph)
        wp.synchronize_device(device)
        monkeypatch.setattr(wp.array, "numpy", real_numpy)
        assert reads["n"] == 0
        assert np.array_equal(x.numpy().view(np.uint32), eager.view(np.uint32))
        assert solver.result()[0] == eager_iterations


def test_pcg_overflow_is_a_failure_not_convergence(device: str) -> None:
    """|b| overflowing float32 used to read as converged (inf <= inf) and left x unchanged."""
    dense, matrix, b = _system(device, n=8, seed=3)
    rhs = wp.array((b * 1e30).astype(np.float32), dtype=wp.vec3, device=device)
    x = wp.zeros(8, dtype=wp.vec3, device=device)
    iterations, residual, _ = PreconditionedConjugateGradient(matrix, rhs, x, 1e-4, 100, 5)()
    assert iterations == 0 and residual == np.inf
    assert np.isnan(x.numpy()).all()
