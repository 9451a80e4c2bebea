"""Preconditioned conjugate gradients on a 3x3-block sparse matrix, with device-side scalars.

The algorithm is textbook PCG (the one ``warp.optim.linear.cg`` runs). It is written out here
because, on Warp 1.19's CPU device, that solver's tiled dot-product kernels take about 5 ms per
dot product for 15,000 unknowns (a 10K-triangle cloth spent 96 % of its step in them), while
``wp.utils.array_inner`` takes 0.08 ms; on a GPU both are fast. Scalars (alpha, beta and the dot
products) stay on the device, so an iteration has no host sync; the host reads the residual only
every ``check_every`` iterations.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import warp as wp
from warp.sparse import BsrMatrix, bsr_mv

wp.set_module_options({"enable_backward": False})

_RZ, _PAP, _RZ_NEW, _RR = 0, 1, 2, 3


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


class PreconditionedConjugateGradient:
    """Solves ``A x = b`` for a symmetric positive (semi-)definite operator on (n,) vec3 arrays.

    Args:
        matrix: the operator: a BSR matrix of (n x n) 3x3 blocks (its values may change between calls, not
            its size), or a callable ``f(x, y)`` writing ``y = A x``.
        rhs: (n,) vec3 right-hand side (read at every call).
        x: (n,) vec3 solution, used as the initial guess (warm start) and overwritten.
        tolerance: stop when ``|b - A x| <= tolerance * |b|``.
        max_iterations: hard cap.
        check_every: iterations between host reads of the residual (sync points).
        precondition: ``f(r, z)`` writing ``z = M^-1 r``; ``None`` for no preconditioner.
    """

    def __init__(self, matrix: BsrMatrix | Callable[[wp.array, wp.array], None], rhs: wp.array, x: wp.array,
                 tolerance: float, max_iterations: int,
                 check_every: int, precondition: Callable[[wp.array, wp.array], None] | None = None) -> None:
        self.matrix = matrix
        self._apply = matrix if callable(matrix) and not isinstance(matrix, BsrMatrix) else self._bsr_apply
        self.rhs = rhs
        self.x = x
        self.tolerance = float(tolerance)
        self.max_iterations = int(max_iterations)
        self.check_every = max(1, int(check_every))
        self.precondition = precondition
        n = rhs.shape[0]
        device = rhs.device
        self.device = device
        self.r = wp.zeros(n, dtype=wp.vec3, device=device)
        self.z = wp.zeros(n, dtype=wp.vec3, device=device) if precondition is not None else self.r
        self.p = wp.zeros(n, dtype=wp.vec3, device=device)
        self.ap = wp.zeros(n, dtype=wp.vec3, device=device)
        self.scalars = wp.zeros(4, dtype=float, device=device)
        self._bb = wp.zeros(1, dtype=float, device=device)
        self._scalar_views = [self.scalars[k : k + 1] for k in range(4)]  # slicing costs Python time per call
        # The loop's launches, packed once (Python argument packing costs as much as a small kernel).
        self._step_solution = wp.launch(_step_solution, dim=n, inputs=[self.scalars, self.p, self.ap],
                                        outputs=[self.x, self.r], device=device, record_cmd=True)
        self._step_direction = wp.launch(_step_direction, dim=n, inputs=[self.z, self.scalars], outputs=[self.p],
                                         device=device, record_cmd=True)
        self._shift_scalars = wp.launch(_shift_scalars, dim=1, inputs=[self.scalars], device=device,
                                        record_cmd=True)

    def _bsr_apply(self, x: wp.array, y: wp.array) -> None:
        bsr_mv(self.matrix, x, y, alpha=1.0, beta=0.0)

    def _dot(self, a: wp.array, b: wp.array, slot: int) -> None:
        wp.utils.array_inner(a, b, out=self._scalar_views[slot])

    def __call__(self) -> tuple[int, float, float]:
        """Run PCG from the current ``x``.

        Returns:
            ``(iterations, residual_norm, absolute_tolerance)`` with ``absolute_tolerance =
            tolerance * |b|`` (the same triple as ``warp.optim.linear.cg``).

        Allocates: no. Capture-safe: no (reads the residual every ``check_every`` iterations).
        """
        n = self.rhs.shape[0]
        dev = self.device
        wp.utils.array_inner(self.rhs, self.rhs, out=self._bb)
        self._apply(self.x, self.r)
        wp.launch(_initial_residual, dim=n, inputs=[self.rhs], outputs=[self.r], device=dev)
        absolute = self.tolerance * float(self._bb.numpy()[0]) ** 0.5
        self._dot(self.r, self.r, _RR)
        residual = float(self.scalars.numpy()[_RR]) ** 0.5
        if not (math.isfinite(absolute) and math.isfinite(residual)):
            # float32 overflow (e.g. an absurd force): inf <= inf must not read as convergence. The
            # solution becomes NaN, which the caller rejects like any other non-finite result.
            self.x.fill_(wp.vec3(math.nan, math.nan, math.nan))
            return 0, math.inf, absolute
        if residual <= absolute:
            return 0, residual, absolute
        if self.precondition is not None:
            self.precondition(self.r, self.z)
        wp.copy(self.p, self.z)
        self._dot(self.r, self.z, _RZ)
        iterations = 0
        while iterations < self.max_iterations:
            self._apply(self.p, self.ap)
            self._dot(self.p, self.ap, _PAP)
            self._step_solution.launch()
            if self.precondition is not None:
                self.precondition(self.r, self.z)
            self._dot(self.r, self.z, _RZ_NEW)
            self._step_direction.launch()
            self._shift_scalars.launch()
            iterations += 1
            if iterations % self.check_every == 0 or iterations == self.max_iterations:
                self._dot(self.r, self.r, _RR)
                residual = float(self.scalars.numpy()[_RR]) ** 0.5
                if residual <= absolute:
                    break
        return iterations, residual, absolute
