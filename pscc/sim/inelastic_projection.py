"""Penetration handling after CCD: the inelastic projection of the step's end positions.

Positions are in the collision index space of the simulator (cloth vertices first, then the
obstacle vertices). A step moves every vertex on the straight line from ``x0`` (start, free of
intersections) to ``x1`` (end); CCD reports the pairs that come closer than the minimum distance on
the way, with a time of impact ``toi``. The response changes only ``x1``.

Every colliding pair becomes one linear **constraint** on the end positions, frozen at its time of
impact (the linearised gap of Harmon et al. 2008, "Robust treatment of simultaneous collisions"):
signed weights ``w`` (vertex-face ``(1, -b_a, -b_b, -b_c)``, edge-edge ``(1 - s, s, -(1 - t), -t)``
with the closest-point coordinates at ``toi``) and the unit contact normal ``n`` at ``toi`` give

    g_k(x) = n_k . sum_i w_ki x_i  >=  separation.

The projection moves the integrator's end positions ``x~`` as little as possible in the mass norm
while meeting every constraint found so far in the step (constraints accumulate over CCD rounds,
so a resolved pair cannot come back):

    minimise 1/2 (x - x~)^T M (x - x~)   subject to   g_k(x) >= separation for all k,

with kinematic vertices (pins, handles, obstacles; inverse mass 0) fixed. Unlike a rigid impact
zone, the colliding cloth keeps deforming and can slide along a kinematic object, so a contact
region that touches two differently moving objects (a spinning ball and a held corner) is solved
instead of failing.

**Solver.** The dual of this quadratic programme is solved by accelerated projected gradient
ascent (FISTA, Beck and Teboulle 2009, with the adaptive restart of O'Donoghue and Candes 2015), one
thread per constraint (Jacobi, so the result does not depend on the order of the pairs). With
``x(y) = x~ + M^-1 A^T y``, every iteration sets

    lambda_k' = max(0, y_k - (g_k(x(y)) - separation) / D_k),   y' = lambda' + beta (lambda' - lambda),

    D_k = sum_i |w_ki| m_i^-1 S_i,   S_i = sum_{j touching i} |w_ji|.

``D`` bounds every row sum of the dual Hessian ``H = A M^-1 A^T`` (``|H_kj| <= sum_{i in k and j}
|w_ki| |w_ji| / m_i``, unit normals), so the diagonal matrix ``D`` dominates ``H`` (Gershgorin) and
``1 / D_k`` is a safe step; ``beta`` follows the FISTA sequence and drops to 0 when the momentum points
uphill (checked every few iterations). Iterations stop at the KKT conditions within ``tolerance``:
no gap more than ``tolerance`` below ``separation`` and no constraint with a positive multiplier
more than ``tolerance`` above it (stationarity holds by construction), or after ``max_iterations``.
The solver then runs CCD again; constraints it cannot meet (a free vertex squeezed between two
kinematic objects) are left to the rigid impact zones
(:class:`pscc.sim.impact_response.ImpactZones`) and, at last, to a smaller step.

Momentum: every constraint's correction ``M^-1 w_k n_k lambda_k`` has zero total momentum when all
its vertices are free (the weights sum to zero), as for an inelastic impulse.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import warp as wp

from pscc.geometry.contact_weights import pair_plane_normal, pair_weights, weighted_sum

wp.set_module_options({"enable_backward": False})


@wp.func
def _normal_or_fallback(offset: wp.vec3, fallback: wp.vec3, start_offset: wp.vec3) -> wp.vec3:
    """Unit contact normal: the closest-point offset, else ``fallback`` oriented like the start."""
    length = wp.length(offset)
    if length > 1.0e-12:
        return offset / length
    n = fallback
    if wp.length(n) <= 1.0e-20:
        n = start_offset
    if wp.length(n) <= 1.0e-20:
        n = wp.vec3(0.0, 0.0, 1.0)
    n = wp.normalize(n)
    if wp.dot(n, start_offset) < 0.0:
        n = -n
    return n


@wp.kernel
def _pair_constraints(
    # in:
    pairs: wp.array(dtype=wp.vec4i),
    toi: wp.array(dtype=float),
    positions_t0: wp.array(dtype=wp.vec3),
    positions_t1: wp.array(dtype=wp.vec3),
    first: int,
    edge_edge: int,
    # out:
    vertices: wp.array(dtype=wp.vec4i),
    weights: wp.array(dtype=wp.vec4),
    normals: wp.array(dtype=wp.vec3),
):
    """One thread per colliding pair (vertex-face (p, a, b, c), or edge-edge (a0, a1, b0, b1) when
    ``edge_edge`` is not 0): its constraint, linearised at the time of impact, at slot first + i."""
    i = wp.tid()
    ids = pairs[i]
    s = toi[i]
    x0 = wp.lerp(positions_t0[ids[0]], positions_t1[ids[0]], s)
    x1 = wp.lerp(positions_t0[ids[1]], positions_t1[ids[1]], s)
    x2 = wp.lerp(positions_t0[ids[2]], positions_t1[ids[2]], s)
    x3 = wp.lerp(positions_t0[ids[3]], positions_t1[ids[3]], s)
    w = pair_weights(x0, x1, x2, x3, edge_edge)
    start = weighted_sum(w, positions_t0[ids[0]], positions_t0[ids[1]], positions_t0[ids[2]], positions_t0[ids[3]])
    vertices[first + i] = ids
    weights[first + i] = w
    normals[first + i] = _normal_or_fallback(weighted_sum(w, x0, x1, x2, x3),
                                             pair_plane_normal(x0, x1, x2, x3, edge_edge), start)


@wp.kernel
def _weight_sums(
    # in:
    vertices: wp.array(dtype=wp.vec4i),
    weights: wp.array(dtype=wp.vec4),
    # out:
    weight_sum: wp.array(dtype=float),
):
    """One thread per constraint: S_i += |w_ki| for its four vertices."""
    k = wp.tid()
    ids = vertices[k]
    w = weights[k]
    for j in range(4):
        wp.atomic_add(weight_sum, ids[j], wp.abs(w[j]))


@wp.kernel
def _dual_steps(
    # in:
    vertices: wp.array(dtype=wp.vec4i),
    weights: wp.array(dtype=wp.vec4),
    inverse_mass: wp.array(dtype=float),
    weight_sum: wp.array(dtype=float),
    # out:
    step: wp.array(dtype=float),
):
    """One thread per constraint: 1 / D_k (0 when every vertex is kinematic)."""
    k = wp.tid()
    ids = vertices[k]
    w = weights[k]
    bound = float(0.0)
    for j in range(4):
        bound += wp.abs(w[j]) * inverse_mass[ids[j]] * weight_sum[ids[j]]
    if bound > 0.0:
        step[k] = 1.0 / bound
    else:
        step[k] = 0.0


@wp.kernel
def _dual_update(
    # in:
    vertices: wp.array(dtype=wp.vec4i),
    weights: wp.array(dtype=wp.vec4),
    normals: wp.array(dtype=wp.vec3),
    step: wp.array(dtype=float),
    positions_t1: wp.array(dtype=wp.vec3),
    separation: float,
    momentum: float,
    measure: int,
    # in/out:
    multiplier: wp.array(dtype=float),
    extrapolated: wp.array(dtype=float),
    # out:
    change: wp.array(dtype=float),
    violation: wp.array(dtype=float),
    restart: wp.array(dtype=float),
):
    """One thread per constraint: one accelerated projected dual step.

    ``positions_t1`` are the positions of the extrapolated multipliers y. The new multiplier is
    lambda' = max(0, y + deficit / D_k), the new extrapolation y' = lambda' + momentum (lambda' - lambda);
    ``change`` = y' - y for the primal update. When ``measure`` is not 0 it also records the largest
    deficit (primal feasibility), the largest excess gap of a constraint with lambda' > 0
    (complementarity) and the restart indicator sum (y - lambda') (lambda' - lambda) (> 0: the momentum
    points uphill)."""
    k = wp.tid()
    if step[k] == 0.0:
        change[k] = 0.0
        return
    ids = vertices[k]
    w = weights[k]
    n = normals[k]
    gap = float(0.0)
    for j in range(4):
        gap += w[j] * wp.dot(n, positions_t1[ids[j]])
    deficit = separation - gap
    old = multiplier[k]
    y = extrapolated[k]
    new = wp.max(y + deficit * step[k], 0.0)
    if measure != 0:
        wp.atomic_max(violation, 0, deficit)
        if new > 0.0:
            wp.atomic_max(violation, 1, -deficit)
        wp.atomic_add(restart, 0, (y - new) * (new - old))
    y_new = new + momentum * (new - old)
    multiplier[k] = new
    extrapolated[k] = y_new
    change[k] = y_new - y


@wp.kernel
def _settle(
    # in:
    multiplier: wp.array(dtype=float),
    # in/out:
    extrapolated: wp.array(dtype=float),
    # out:
    change: wp.array(dtype=float),
):
    """One thread per constraint: drop the momentum (y = lambda); ``change`` = lambda - y."""
    k = wp.tid()
    change[k] = multiplier[k] - extrapolated[k]
    extrapolated[k] = multiplier[k]


@wp.kernel
def _primal_update(
    # in:
    vertices: wp.array(dtype=wp.vec4i),
    weights: wp.array(dtype=wp.vec4),
    normals: wp.array(dtype=wp.vec3),
    change: wp.array(dtype=float),
    inverse_mass: wp.array(dtype=float),
    # out:
    positions_t1: wp.array(dtype=wp.vec3),
):
    """One thread per constraint: x += M^-1 w_k n_k (change of lambda_k)."""
    k = wp.tid()
    delta = change[k]
    if delta == 0.0:
        return
    ids = vertices[k]
    w = weights[k]
    n = normals[k]
    for j in range(4):
        scale = inverse_mass[ids[j]] * w[j] * delta
        if scale != 0.0:
            wp.atomic_add(positions_t1, ids[j], scale * n)


@dataclass(frozen=True)
class ProjectionResult:
    """What one :meth:`InelasticProjection.solve` did."""

    iterations: int
    """Dual iterations run."""
    violation: float
    """At the last check [m]: the larger of the largest gap deficit ``separation - g_k`` and the
    largest excess ``g_k - separation`` of a constraint with a positive multiplier (<= tolerance:
    converged to the projection within tolerance)."""
    constraints: int
    """Constraints of the step so far."""


class InelasticProjection:
    """Inelastic projection of the end positions onto the step's collision constraints (see the
    module docstring).

    Use per step: :meth:`reset`, then per CCD round :meth:`add` the colliding pairs and
    :meth:`solve`.

    Args:
        inverse_mass: (vertex_count,) 1 / mass [1/kg] in the collision index space; 0 for kinematic
            vertices (pins, handles, obstacles), which are never moved.
        device: Warp device.
        max_iterations: dual iterations per :meth:`solve` at most.
        check_every: iterations between two convergence checks (each check reads three floats back).
    """

    def __init__(self, inverse_mass: np.ndarray, device: wp.Device, max_iterations: int = 512,
                 check_every: int = 16) -> None:
        self.device = device
        self.vertex_count = int(inverse_mass.shape[0])
        self.inverse_mass = wp.array(np.asarray(inverse_mass, dtype=np.float32), dtype=float, device=device)
        self.max_iterations = int(max_iterations)
        self.check_every = max(1, int(check_every))
        self.weight_sum = wp.zeros(self.vertex_count, dtype=float, device=device)
        self.violation = wp.zeros(2, dtype=float, device=device)
        self.restart = wp.zeros(1, dtype=float, device=device)
        self.count = 0
        self._allocate(64)

    def _allocate(self, capacity: int) -> None:
        dev = self.device
        self.capacity = int(capacity)
        self.vertices = wp.zeros(capacity, dtype=wp.vec4i, device=dev)
        self.weights = wp.zeros(capacity, dtype=wp.vec4, device=dev)
        self.normals = wp.zeros(capacity, dtype=wp.vec3, device=dev)
        self.multiplier = wp.zeros(capacity, dtype=float, device=dev)
        self.extrapolated = wp.zeros(capacity, dtype=float, device=dev)
        self.step = wp.zeros(capacity, dtype=float, device=dev)
        self.change = wp.zeros(capacity, dtype=float, device=dev)

    def _grow(self, needed: int) -> None:
        if needed <= self.capacity:
            return
        old = (self.vertices, self.weights, self.normals, self.multiplier, self.extrapolated)
        self._allocate(max(needed, 2 * self.capacity))
        new = (self.vertices, self.weights, self.normals, self.multiplier, self.extrapolated)
        for src, dst in zip(old, new, strict=True):
            if self.count:
                wp.copy(dst, src, count=self.count)

    def reset(self) -> None:
        """Forget the constraints (start of a step). Allocates: no."""
        self.count = 0

    def add(self, vertex_face: np.ndarray, vertex_face_toi: np.ndarray, edge_edge: np.ndarray,
            edge_edge_toi: np.ndarray, positions_t0: wp.array, positions_t1: wp.array) -> None:
        """Append one constraint per colliding pair, linearised at its time of impact on the current
        trajectory ``positions_t0 -> positions_t1``.

        Args:
            vertex_face: (k, 4) int rows (vertex, face vertex a, b, c).
            vertex_face_toi: (k,) time of impact in [0, 1].
            edge_edge: (l, 4) int rows (a0, a1, b0, b1).
            edge_edge_toi: (l,) time of impact.
            positions_t0: start positions (device, vec3).
            positions_t1: current end positions (device, vec3).

        Allocates: uploads the pairs; grows the constraint buffers (doubling) when full.
        """
        added = int(vertex_face.shape[0]) + int(edge_edge.shape[0])
        self._grow(self.count + added)
        dev = self.device
        for kind, rows, toi in ((0, vertex_face, vertex_face_toi), (1, edge_edge, edge_edge_toi)):
            if rows.shape[0] == 0:
                continue
            pairs = wp.array(np.ascontiguousarray(rows, dtype=np.int32), dtype=wp.vec4i, device=dev)
            times = wp.array(np.ascontiguousarray(toi, dtype=np.float32), dtype=float, device=dev)
            wp.launch(_pair_constraints, dim=rows.shape[0],
                      inputs=[pairs, times, positions_t0, positions_t1, self.count, kind],
                      outputs=[self.vertices, self.weights, self.normals], device=dev)
            self.multiplier[self.count:self.count + rows.shape[0]].zero_()
            self.extrapolated[self.count:self.count + rows.shape[0]].zero_()
            self.count += int(rows.shape[0])

    def solve(self, positions_t1: wp.array, separation: float, tolerance: float) -> ProjectionResult:
        """Project ``positions_t1`` (updated in place) onto every constraint added since :meth:`reset`.

        The multipliers of earlier constraints are kept (warm start), and ``positions_t1`` must be
        the previous :meth:`solve`'s output (or the integrator's end positions after :meth:`reset`),
        so the result is the projection of the integrator's end positions.

        Args:
            positions_t1: end positions (device, vec3), updated in place.
            separation: gap each constraint asks for along its normal [m].
            tolerance: stop when no gap is more than this below ``separation``, and no constraint with
                a positive multiplier has a gap more than this above it [m] (the KKT conditions:
                ``x = x~ + M^-1 A^T lambda`` holds by construction).

        Returns:
            Iterations run and the violation measured at the last check (before that iteration's
            update).

        Allocates: no. Capture-safe: no (reads the violation back every ``check_every`` iterations).
        """
        count = self.count
        if count == 0:
            return ProjectionResult(0, 0.0, 0)
        dev = self.device
        self.weight_sum.zero_()
        constraint = (self.vertices, self.weights)
        wp.launch(_weight_sums, dim=count, inputs=list(constraint), outputs=[self.weight_sum], device=dev)
        wp.launch(_dual_steps, dim=count, inputs=[*constraint, self.inverse_mass, self.weight_sum],
                  outputs=[self.step], device=dev)
        iterations = 0
        violation = float("inf")
        momentum_step = 1.0  # the FISTA sequence t_k; 1 = no momentum (start, restart)
        while iterations < self.max_iterations:
            check = (iterations % self.check_every == 0) or iterations + 1 == self.max_iterations
            if check:
                self.violation.fill_(-np.inf)
                self.restart.zero_()
            following = 0.5 * (1.0 + np.sqrt(1.0 + 4.0 * momentum_step * momentum_step))
            momentum = (momentum_step - 1.0) / following
            momentum_step = following
            wp.launch(_dual_update, dim=count,
                      inputs=[*constraint, self.normals, self.step, positions_t1, float(separation), float(momentum),
                              int(check)],
                      outputs=[self.multiplier, self.extrapolated, self.change, self.violation, self.restart],
                      device=dev)
            # The positions always follow the extrapolated multipliers.
            wp.launch(_primal_update, dim=count,
                      inputs=[*constraint, self.normals, self.change, self.inverse_mass],
                      outputs=[positions_t1], device=dev)
            iterations += 1
            if check:
                deficit, excess = (float(v) for v in self.violation.numpy())
                violation = max(deficit, excess)
                if violation <= tolerance:
                    break
                if self.restart.numpy()[0] > 0.0:
                    momentum_step = 1.0  # adaptive restart (O'Donoghue and Candes 2015)
        # Back to the positions of the multipliers themselves, so a later solve can warm-start.
        wp.launch(_settle, dim=count, inputs=[self.multiplier], outputs=[self.extrapolated, self.change], device=dev)
        wp.launch(_primal_update, dim=count, inputs=[*constraint, self.normals, self.change, self.inverse_mass],
                  outputs=[positions_t1], device=dev)
        return ProjectionResult(iterations, violation, count)
