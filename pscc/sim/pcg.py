"""Preconditioned conjugate gradients on a 3x3-block sparse matrix, with device-side scalars.

The algorithm is textbook PCG (the one ``warp.optim.linear.cg`` runs). It is written out here
because, on Warp 1.19's CPU device, that solver's tiled dot-product kernels take about 5 ms per
dot product for 15,000 unknowns (a 10K-triangle cloth spent 96 % of its step in them), while
``wp.utils.array_inner`` takes 0.08 ms. On a GPU ``wp.utils.array_inner`` asks CUB for temporary memory
at every call, which CUDA refuses inside the loop's conditional graph, so the dot products go through
:class:`pscc._reductions.InnerProduct` (Warp's on the CPU, allocation-free tiled kernels on a GPU).

Everything stays on the device: the scalars (alpha, beta, the dot products), the iteration count and
the convergence test, which runs every ``check_every`` iterations and sets the condition of a
``wp.capture_while`` loop. :meth:`PreconditionedConjugateGradient.launch` therefore reads nothing back
and can be captured in a graph (on CUDA and, with Warp 1.19, on the CPU); run eagerly, the loop reads
its one-integer condition once per ``check_every`` iterations. ``__call__`` launches and then reads the
result once.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import warp as wp
from warp.sparse import BsrMatrix, bsr_mv

from pscc._reductions import InnerProduct

wp.set_module_options({"enable_backward": False})

_RZ, _PAP, _RZ_NEW, _RR, _BB = 0, 1, 2, 3, 4
"""Slots of the device scalars: r.z, p.Ap, the new r.z, r.r and b.b."""

_ITERATIONS, _FAILED = 0, 1
"""Slots of the device counters: iterations done, and 1 when |b| or |r| overflowed."""


@wp.kernel
def _initial_residual(
    # in:
    b: wp.array(dtype=wp.vec3),
    # out:
    r: wp.array(dtype=wp.vec3),
):
    """One thread per block row: r = b - r (r holds A x on entry)."""
    i = wp.tid()
    r[i] = b[i] - r[i]


@wp.kernel
def _step_solution(
    # in:
    scalars: wp.array(dtype=float),
    p: wp.array(dtype=wp.vec3),
    ap: wp.array(dtype=wp.vec3),
    # out:
    x: wp.array(dtype=wp.vec3),
    r: wp.array(dtype=wp.vec3),
):
    """One thread per block row: alpha = rz / pAp; x += alpha p; r -= alpha Ap."""
    i = wp.tid()
    curvature = scalars[_PAP]
    alpha = float(0.0)
    if curvature > 0.0:
        alpha = scalars[_RZ] / curvature
    x[i] = x[i] + alpha * p[i]
    r[i] = r[i] - alpha * ap[i]


@wp.kernel
def _step_direction(
    # in:
    z: wp.array(dtype=wp.vec3),
    scalars: wp.array(dtype=float),
    # out:
    p: wp.array(dtype=wp.vec3),
):
    """One thread per block row: beta = rz_new / rz; p = z + beta p."""
    i = wp.tid()
    previous = scalars[_RZ]
    beta = float(0.0)
    if previous > 0.0:
        beta = scalars[_RZ_NEW] / previous
    p[i] = z[i] + beta * p[i]


@wp.kernel
def _shift_scalars(scalars: wp.array(dtype=float)):
    """A single thread: rz <- rz_new for the next iteration."""
    scalars[_RZ] = scalars[_RZ_NEW]


@wp.kernel
def _start_loop(
    # in:
    scalars: wp.array(dtype=float),
    tolerance_squared: float,
    # out:
    counters: wp.array(dtype=wp.int32),
    running: wp.array(dtype=wp.int32),
):
    """A single thread: no iteration yet; run while |r|^2 > tol^2 |b|^2; an overflow stops at once."""
    rr = scalars[_RR]
    bb = scalars[_BB]
    counters[_ITERATIONS] = 0
    counters[_FAILED] = 0
    # inf <= inf must not read as convergence: a non-finite |b| or |r| is a failure.
    if not (wp.isfinite(rr) and wp.isfinite(bb)):
        counters[_FAILED] = 1
        running[0] = 0
    elif rr > tolerance_squared * bb:
        running[0] = 1
    else:
        running[0] = 0


@wp.kernel
def _check_convergence(
    # in:
    scalars: wp.array(dtype=float),
    tolerance_squared: float,
    block: int,
    max_iterations: int,
    # out:
    counters: wp.array(dtype=wp.int32),
    running: wp.array(dtype=wp.int32),
):
    """A single thread, after a block of iterations: count them; go on while not converged and below the cap."""
    done = counters[_ITERATIONS] + block
    counters[_ITERATIONS] = done
    running[0] = 0
    if scalars[_RR] > tolerance_squared * scalars[_BB] and done < max_iterations:
        running[0] = 1


@wp.kernel
def _poison_on_failure(
    # in:
    counters: wp.array(dtype=wp.int32),
    # out:
    x: wp.array(dtype=wp.vec3),
):
    """One thread per block row: x = NaN when the solve overflowed (callers reject non-finite results)."""
    i = wp.tid()
    if counters[_FAILED] != 0:
        nan = wp.nan
        x[i] = wp.vec3(nan, nan, nan)


class PreconditionedConjugateGradient:
    """Solves ``A x = b`` for a symmetric positive (semi-)definite operator on (n,) vec3 arrays.

    Args:
        matrix: the operator: a BSR matrix of (n x n) 3x3 blocks (its values may change between calls, not
            its size), or a callable ``f(x, y)`` writing ``y = A x``.
        rhs: (n,) vec3 right-hand side (read at every call).
        x: (n,) vec3 solution, used as the initial guess (warm start) and overwritten.
        tolerance: stop when ``|b - A x| <= tolerance * |b|``.
        max_iterations: hard cap, rounded up to a multiple of ``check_every``.
        check_every: iterations between convergence tests (each a read of one integer when run eagerly).
        precondition: ``f(r, z)`` writing ``z = M^-1 r``; ``None`` for no preconditioner.

    Device buffers: ``r``, ``z``, ``p``, ``ap`` (n,) vec3; ``scalars`` (5,) float32 = [r.z, p.Ap, new r.z,
    r.r, b.b]; ``counters`` (2,) int32 = [iterations, overflowed]; ``running`` (1,) int32, the loop
    condition.
    """

    def __init__(self, matrix: BsrMatrix | Callable[[wp.array, wp.array], None], rhs: wp.array, x: wp.array,
                 tolerance: float, max_iterations: int,
                 check_every: int, precondition: Callable[[wp.array, wp.array], None] | None = None) -> None:
        self.matrix = matrix
        self._apply = matrix if callable(matrix) and not isinstance(matrix, BsrMatrix) else self._bsr_apply
        self.rhs = rhs
        self.x = x
        self.tolerance = float(tolerance)
        self.check_every = max(1, int(check_every))
        self.max_iterations = int(max_iterations)
        self.precondition = precondition
        n = rhs.shape[0]
        device = rhs.device
        self.device = device
        self.r = wp.zeros(n, dtype=wp.vec3, device=device)
        self.z = wp.zeros(n, dtype=wp.vec3, device=device) if precondition is not None else self.r
        self.p = wp.zeros(n, dtype=wp.vec3, device=device)
        self.ap = wp.zeros(n, dtype=wp.vec3, device=device)
        self.scalars = wp.zeros(5, dtype=float, device=device)
        self._inner = InnerProduct(device, n)  # allocation-free inside the loop on CUDA
        self.counters = wp.zeros(2, dtype=wp.int32, device=device)
        self.running = wp.zeros(1, dtype=wp.int32, device=device)
        self._scalar_views = [self.scalars[k : k + 1] for k in range(5)]  # slicing costs Python time per call
        tolerance_squared = self.tolerance * self.tolerance
        # The loop's launches, packed once (Python argument packing costs as much as a small kernel).
        self._step_solution = wp.launch(_step_solution, dim=n, inputs=[self.scalars, self.p, self.ap],
                                        outputs=[self.x, self.r], device=device, record_cmd=True)
        self._step_direction = wp.launch(_step_direction, dim=n, inputs=[self.z, self.scalars], outputs=[self.p],
                                         device=device, record_cmd=True)
        self._shift_scalars = wp.launch(_shift_scalars, dim=1, inputs=[self.scalars], device=device,
                                        record_cmd=True)
        self._check = wp.launch(_check_convergence, dim=1,
                                inputs=[self.scalars, tolerance_squared, self.check_every, self.max_iterations],
                                outputs=[self.counters, self.running], device=device, record_cmd=True)
        self._start = wp.launch(_start_loop, dim=1, inputs=[self.scalars, tolerance_squared],
                                outputs=[self.counters, self.running], device=device, record_cmd=True)

    def _bsr_apply(self, x: wp.array, y: wp.array) -> None:
        bsr_mv(self.matrix, x, y, alpha=1.0, beta=0.0)

    def _dot(self, a: wp.array, b: wp.array, slot: int) -> None:
        self._inner(a, b, self._scalar_views[slot])

    def _iterate(self) -> None:
        """``check_every`` iterations, then the convergence test that sets the loop condition."""
        for _ in range(self.check_every):
            self._apply(self.p, self.ap)
            self._dot(self.p, self.ap, _PAP)
            self._step_solution.launch()
            if self.precondition is not None:
                self.precondition(self.r, self.z)
            self._dot(self.r, self.z, _RZ_NEW)
            self._step_direction.launch()
            self._shift_scalars.launch()
        self._dot(self.r, self.r, _RR)
        self._check.launch()

    def launch(self) -> None:
        """Run PCG from the current ``x``, entirely on the device.

        When ``|b|`` or the residual overflows float32, ``x`` becomes NaN (an overflow must not read
        as convergence). The result stays in ``counters`` and ``scalars`` (see :meth:`result`).

        Allocates: no. Capture-safe: yes (the loop is a ``wp.capture_while`` on ``running``).
        """
        n = self.rhs.shape[0]
        dev = self.device
        self._dot(self.rhs, self.rhs, _BB)
        self._apply(self.x, self.r)
        wp.launch(_initial_residual, dim=n, inputs=[self.rhs], outputs=[self.r], device=dev)
        self._dot(self.r, self.r, _RR)
        if self.precondition is not None:
            self.precondition(self.r, self.z)
        wp.copy(self.p, self.z)
        self._dot(self.r, self.z, _RZ)
        self._start.launch()
        wp.capture_while(self.running, self._iterate)
        wp.launch(_poison_on_failure, dim=n, inputs=[self.counters], outputs=[self.x], device=dev)

    def result(self) -> tuple[int, float, float]:
        """``(iterations, residual_norm, absolute_tolerance)`` of the last solve (``residual_norm`` is inf
        after an overflow). Sync point: reads 7 numbers back."""
        scalars = self.scalars.numpy()
        iterations, failed = (int(v) for v in self.counters.numpy())
        absolute = self.tolerance * math.sqrt(max(float(scalars[_BB]), 0.0))
        if failed:
            return iterations, math.inf, absolute
        return iterations, math.sqrt(max(float(scalars[_RR]), 0.0)), absolute

    def __call__(self) -> tuple[int, float, float]:
        """Run PCG from the current ``x`` (:meth:`launch`) and return :meth:`result`.

        Returns:
            ``(iterations, residual_norm, absolute_tolerance)`` with ``absolute_tolerance =
            tolerance * |b|`` (the same triple as ``warp.optim.linear.cg``).

        Allocates: no. Capture-safe: no (reads the result back).
        """
        self.launch()
        return self.result()
