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

**Proximity constraints.** Pairs that already touch (the contact springs of the step's start, closer than
the thickness) join the first round of a step as constraints of the same form with the spring's weights and
normal, their floor lowered to the gap ``g~`` they have at the integrator's end positions:
``g_k(x) >= min(separation, g~_k)`` (:meth:`InelasticProjection.add_near`). The integrator's positions meet
them, so they change nothing unless a response pushes a vertex out of one collision towards a surface it
touches on its other side (tangled layers, cloth on a body): then the neighbour is moved along instead of
being run into, which the next CCD round would have found.

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

**Device path.** :meth:`InelasticProjection.add_device` appends the hits of a narrow phase's rows
(:class:`pscc.collision.contacts.ContactArgs`) with a device counter, and
:meth:`InelasticProjection.solve_device` runs the iteration as a ``wp.capture_while`` loop whose
convergence and restart checks run on the device (one thread, every ``check_every`` iterations);
the FISTA sequence is kept in float64 on the device, so the iterates are the same bits as those of
a host-driven loop. Kernels launch at the buffers' capacity and stop at the counter. Nothing is read
back: the result (iterations, violation, converged) stays in ``loop_state`` / ``scalars`` until
:meth:`InelasticProjection.result` reads it, and an overflow of the constraint buffers keeps
counting until :meth:`InelasticProjection.check_capacity` grows them (both sync points). The host
methods :meth:`~InelasticProjection.add` and :meth:`~InelasticProjection.solve` are the device path
followed by those sync methods.

Momentum: every constraint's correction ``M^-1 w_k n_k lambda_k`` has zero total momentum when all
its vertices are free (the weights sum to zero), as for an inelastic impulse.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import warp as wp

from pscc.collision.contacts import ContactArgs
from pscc.errors import CapacityError
from pscc.sim._projection_kernels import (
    _ACTIVE,
    _ALWAYS,
    _CONVERGED,
    _GROWTH,
    _INITIAL_CAPACITY,
    _ITERATIONS,
    _LOOP_SLOTS,
    _VIOLATION,
    ConstraintArgs,
    _append_constraints,
    _append_near_constraints,
    _append_stitch_constraints,
    _begin_iteration,
    _close_block,
    _dual_steps,
    _dual_update,
    _primal_update,
    _settle,
    _start_solve,
    _weight_sums,
)
from pscc.sim.contact_springs import ContactSprings

wp.set_module_options({"enable_backward": False})

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
    converged: bool = False
    """Whether the last check met the tolerance (True when there was nothing to project)."""


class _SolveLaunches:
    """The solve's launches, packed once per (positions, separation, tolerance) (no ``__dict__``, so
    memory accounting does not walk into them)."""

    __slots__ = ("key", "positions_t1", "weight_sums", "dual_steps", "start", "begin", "dual", "primal", "close",
                 "settle", "settle_primal")


class InelasticProjection:
    """Inelastic projection of the end positions onto the step's collision constraints (see the
    module docstring).

    Use per step: :meth:`reset`, then per CCD round :meth:`add` (or :meth:`add_device`) the colliding
    pairs and :meth:`solve` (or :meth:`solve_device`).

    Device buffers (capacity ``C`` constraint slots, grown only by :meth:`check_capacity`):

    ==================  ===============  ===========================================================
    buffer              shape, dtype     meaning
    ==================  ===============  ===========================================================
    vertices            (C,) vec4i       the four vertex ids of each constraint
    weights             (C,) vec4        signed weights w_k
    normals             (C,) vec3        unit contact normal n_k at the time of impact
    offset              (C,) float32     the constraint's floor is separation + offset_k (0 for a
                                         collision; a seam's six constraints allow its opening)
    multiplier          (C,) float32     lambda_k (kept across solves of a step: warm start)
    extrapolated        (C,) float32     y_k, the extrapolated multipliers
    step, change        (C,) float32     1 / D_k; the last change of y_k
    constraint_count    (1,) int32       constraints appended since :meth:`reset`; may exceed ``C``
                                         (an overflow, caught by :meth:`check_capacity`)
    loop_state          (7,) int32       [iterations, active, measure, measured, stopped, converged, 1]
                                         (``iteration_count`` is a view of slot 0)
    scalars             (2,) float32     [momentum, violation at the last check]
    running             (1,) int32       the ``wp.capture_while`` condition
    ==================  ===============  ===========================================================

    Sync points: :meth:`check_capacity`, :meth:`result`, :attr:`count`, and the host methods
    :meth:`add` / :meth:`solve` that call them.

    Args:
        inverse_mass: (vertex_count,) 1 / mass [1/kg] in the collision index space; 0 for kinematic
            vertices (pins, handles, obstacles), which are never moved.
        device: Warp device.
        max_iterations: dual iterations per :meth:`solve` at most.
        check_every: iterations between two convergence checks (on the device; run eagerly, the loop
            reads its one-integer condition once per ``check_every`` iterations). The momentum's restart
            test runs with them: on ``twisting`` at 5K, 8 instead of 16 cut the projection iterations of
            the animation by 15 % and its CCD rounds by 5 % at the old tolerance, by 23 % and 9 % at the
            new one (``pscc.sim.solver.RESPONSE_TOLERANCE_SHARE``).
    """

    def __init__(self, inverse_mass: np.ndarray, device: wp.DeviceLike, max_iterations: int = 512,
                 check_every: int = 8) -> None:
        self.device = wp.get_device(device)
        dev = self.device
        self.vertex_count = int(inverse_mass.shape[0])
        self.inverse_mass = wp.array(np.asarray(inverse_mass, dtype=np.float32), dtype=float, device=dev)
        self.max_iterations = int(max_iterations)
        self.check_every = max(1, int(check_every))
        self.weight_sum = wp.zeros(self.vertex_count, dtype=float, device=dev)
        self.violation = wp.zeros(2, dtype=float, device=dev)
        """(2,) float32 [largest deficit, largest excess] of the measuring iteration."""
        self.restart = wp.zeros(1, dtype=float, device=dev)
        """(1,) float32 restart indicator of the measuring iteration."""
        self.constraint_count = wp.zeros(1, dtype=wp.int32, device=dev)
        """(1,) int32 constraints appended since :meth:`reset` (may exceed :attr:`capacity`)."""
        self.loop_state = wp.zeros(_LOOP_SLOTS, dtype=wp.int32, device=dev)
        """(7,) int32 loop state of the last solve (slots in the class docstring)."""
        self.iteration_count = self.loop_state[_ITERATIONS:_ITERATIONS + 1]
        """(1,) int32 view of ``loop_state``: dual iterations of the last :meth:`solve_device`."""
        self.fista = wp.zeros(1, dtype=wp.float64, device=dev)
        """(1,) float64 the FISTA sequence t_k."""
        self.scalars = wp.zeros(2, dtype=float, device=dev)
        """(2,) float32 [momentum, violation at the last check]."""
        self.running = wp.zeros(1, dtype=wp.int32, device=dev)
        """(1,) int32 loop condition of :meth:`solve_device`."""
        self._open_gate = wp.ones(1, dtype=wp.int32, device=dev)
        self._launches: _SolveLaunches | None = None
        self._allocate(_INITIAL_CAPACITY)

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
        self.offset = wp.zeros(capacity, dtype=float, device=dev)
        args = ConstraintArgs()
        args.vertices = self.vertices
        args.weights = self.weights
        args.normals = self.normals
        args.step = self.step
        args.count = self.constraint_count
        args.offset = self.offset
        self.constraints = args
        """The constraint buffers as a :class:`ConstraintArgs` (rebuilt when they grow)."""
        self._launches = None

    def _grow(self, needed: int) -> None:
        """Grow to ``1.25 * needed`` slots, keeping every stored constraint and multiplier."""
        if needed <= self.capacity:
            return
        size = int(needed * _GROWTH) + _INITIAL_CAPACITY
        if size > 2**31 - 1:
            raise CapacityError(f"inelastic projection: {needed} constraints exceed the int32 index range; "
                                "reduce the time step or split the scene")
        old = (self.vertices, self.weights, self.normals, self.multiplier, self.extrapolated, self.offset)
        kept = self.capacity
        self._allocate(size)
        new = (self.vertices, self.weights, self.normals, self.multiplier, self.extrapolated, self.offset)
        for src, dst in zip(old, new, strict=True):
            wp.copy(dst, src, count=kept)

    @property
    def count(self) -> int:
        """Constraints stored since :meth:`reset` (the device counter clamped to the capacity).

        Sync point: reads one integer back.
        """
        return max(0, min(int(self.constraint_count.numpy()[0]), self.capacity))

    def trim(self, capacity: int) -> None:
        """Shrink the buffers to ``capacity`` constraints (at least the initial 64) when they are larger,
        dropping the stored constraints: call between steps only (after :meth:`reset`), and record
        graphs again (the buffers are new arrays).

        Allocates: when shrinking. Capture-safe: no.
        """
        capacity = max(_INITIAL_CAPACITY, int(capacity))
        if capacity < self.capacity:
            self._allocate(capacity)

    def reserve(self, capacity: int) -> None:
        """Grow the buffers to at least ``capacity`` constraints (1.25 x), keeping the stored ones.

        Allocates: when growing. Capture-safe: no.
        """
        self._grow(int(capacity))

    def reset(self) -> None:
        """Forget the constraints (start of a step). Allocates: no. Capture-safe: yes."""
        self.constraint_count.zero_()

    def check_capacity(self) -> bool:
        """Read the constraint counter and grow the buffers when :meth:`add_device` overflowed them.

        Sync point: reads one integer back.

        Returns:
            True when every constraint was stored; False when the buffers were grown (to 1.25 times
            the count, contents kept), in which case the constraints past the old capacity were lost:
            the caller re-runs the step (:meth:`reset`, then every round's :meth:`add_device`).

        Raises:
            CapacityError: the counter overflowed int32.

        Allocates: only when growing. Capture-safe: no.
        """
        count = int(self.constraint_count.numpy()[0])
        if count < 0:
            raise CapacityError("inelastic projection: the constraint counter overflowed int32; reduce the time "
                                "step or split the scene")
        if count <= self.capacity:
            return True
        self._grow(count)
        return False

    def overflow_counters(self) -> list[tuple[wp.array, int, int]]:
        """``(counter, index, capacity)`` of each device counter that can overflow (for a device-side
        overflow flag): ``constraint_count[0]`` against :attr:`capacity`. Allocates: no."""
        return [(self.constraint_count, 0, self.capacity)]

    def add_device(self, contacts: ContactArgs, positions_t0: wp.array, positions_t1: wp.array) -> None:
        """Append one constraint per hit row of ``contacts`` (toi <= 1), linearised at its time of
        impact on the current trajectory ``positions_t0 -> positions_t1``.

        Vertex-face rows come first, then edge-edge rows, each in row order on the CPU (in the order
        of the device's atomic appends on a GPU). The counter :attr:`constraint_count` counts past
        the capacity; :meth:`check_capacity` (a sync point) reports and grows.

        Args:
            contacts: the narrow phase's rows (:class:`pscc.collision.contacts.ContactArgs`; vertex
                ids index ``positions_*``).
            positions_t0: (vertex_count,) vec3 start positions [m].
            positions_t1: (vertex_count,) vec3 current end positions [m].

        Allocates: no. Capture-safe: yes.
        """
        dev = self.device
        for edge_edge, rows in ((0, contacts.vertex_face), (1, contacts.edge_edge)):
            wp.launch(_append_constraints, dim=rows.shape[0],
                      inputs=[contacts, positions_t0, positions_t1, edge_edge],
                      outputs=[self.constraints, self.multiplier, self.extrapolated], device=dev)

    def add_stitches_device(self, stitch_vertices: wp.array, stitch_weights: wp.array, positions_t1: wp.array,
                            separation: float, slack: float) -> None:
        """Append six constraints per stitch that keep the response from opening a seam: each axis
        component of the stitch's offset ``d = sum_a w_a x_a`` stays within ``max(|d_c|, slack)`` of 0, its
        value at ``positions_t1`` (the integrator's end positions). Call right after :meth:`reset`, with the
        ``separation`` the solve will get.

        Args:
            stitch_vertices: (s,) vec4i ``(i, j, k, j)`` (:attr:`pscc.sim.model.ClothModel.stitch_vertices`).
            stitch_weights: (s,) vec4 ``(1, -(1 - r), -r, 0)``.
            positions_t1: (vertex_count,) vec3 end positions [m].
            separation: the solve's separation [m].
            slack: the opening always allowed [m].

        Allocates: no. Capture-safe: yes.
        """
        if stitch_vertices.shape[0] == 0:
            return
        wp.launch(_append_stitch_constraints, dim=stitch_vertices.shape[0], device=self.device,
                  inputs=[stitch_vertices, stitch_weights, positions_t1, float(separation), float(slack)],
                  outputs=[self.constraints, self.multiplier, self.extrapolated])

    def add_near_device(self, springs: ContactSprings, positions_t1: wp.array, separation: float,
                        gate: wp.array | None = None) -> None:
        """Append one proximity constraint per contact spring with a free vertex: ``n . sum_a w_a x_a >=
        min(separation, g)`` with the spring's weights and normal (its closest points at the step's start)
        and ``g`` its gap at ``positions_t1`` (the end positions before any response).

        The constraint holds where the positions are, so it changes nothing by itself; it keeps a response
        that pushes one vertex out of a collision from pushing it into the surface it already touches
        (which the next CCD round would find). The constraints count against the capacity like the
        collisions' (:meth:`check_capacity`).

        Args:
            springs: the contact springs of the step's start (:class:`pscc.sim.contact_springs.ContactSprings`,
                the last DCD's).
            positions_t1: (vertex_count,) vec3 end positions [m].
            separation: the solve's separation [m].
            gate: (1,) int32: append only while ``gate[0]`` is 1 (the device step passes its round
                counter: the first round only); ``None``: always.

        Allocates: no. Capture-safe: yes.
        """
        wp.launch(_append_near_constraints, dim=springs.capacity, device=self.device,
                  inputs=[springs.vertices, springs.weights, springs.normals, springs.count, self.inverse_mass,
                          positions_t1, float(separation), self._open_gate if gate is None else gate],
                  outputs=[self.constraints, self.multiplier, self.extrapolated])

    def add_near(self, springs: ContactSprings, positions_t1: wp.array, separation: float) -> None:
        """:meth:`add_near_device`, growing the buffers when they overflow (the host path).

        Allocates: when growing. Capture-safe: no (a sync point: reads the constraint counter).
        """
        before = self.count
        self._grow(before + springs.host_count)
        while True:
            self.add_near_device(springs, positions_t1, separation)
            if self.check_capacity():
                return
            self.constraint_count.fill_(before)  # rewind: the stored constraints below are kept

    def add(self, vertex_face: np.ndarray, vertex_face_toi: np.ndarray, edge_edge: np.ndarray,
            edge_edge_toi: np.ndarray, positions_t0: wp.array, positions_t1: wp.array) -> None:
        """Append one constraint per colliding pair, linearised at its time of impact on the current
        trajectory ``positions_t0 -> positions_t1`` (:meth:`add_device` on uploaded rows).

        Args:
            vertex_face: (k, 4) int rows (vertex, face vertex a, b, c).
            vertex_face_toi: (k,) time of impact in [0, 1].
            edge_edge: (l, 4) int rows (a0, a1, b0, b1).
            edge_edge_toi: (l,) time of impact.
            positions_t0: start positions (device, vec3).
            positions_t1: current end positions (device, vec3).

        Allocates: uploads the pairs; grows the constraint buffers when full. Capture-safe: no (a sync
        point: reads the constraint counter).
        """
        vf = np.ascontiguousarray(vertex_face, dtype=np.int32).reshape(-1, 4)
        ee = np.ascontiguousarray(edge_edge, dtype=np.int32).reshape(-1, 4)
        k, l = int(vf.shape[0]), int(ee.shape[0])
        if k + l == 0:
            return
        dev = self.device
        # The rows as a ContactArgs: one face per vertex-face row, two edges per edge-edge row.
        contacts = ContactArgs()
        contacts.faces = wp.array(vf[:, 1:].copy(), dtype=wp.vec3i, device=dev)
        contacts.edges = wp.array(ee.reshape(-1, 2), dtype=wp.vec2i, device=dev)
        contacts.vertex_face = wp.array(np.stack([vf[:, 0], np.arange(k, dtype=np.int32)], axis=1), dtype=wp.vec2i,
                                        device=dev)
        pairs = np.arange(2 * l, dtype=np.int32).reshape(-1, 2)
        contacts.edge_edge = wp.array(pairs, dtype=wp.vec2i, device=dev)
        # Times of impact clamped to [0, 1] only by the caller's contract; a row is a hit iff toi <= 1.
        contacts.vertex_face_toi = wp.array(np.asarray(vertex_face_toi, dtype=np.float32).reshape(-1), dtype=float,
                                            device=dev)
        contacts.edge_edge_toi = wp.array(np.asarray(edge_edge_toi, dtype=np.float32).reshape(-1), dtype=float,
                                          device=dev)
        contacts.counts = wp.array(np.array([k, l], dtype=np.int32), dtype=wp.int32, device=dev)
        before = self.count
        self._grow(before + k + l)
        while True:
            self.add_device(contacts, positions_t0, positions_t1)
            if self.check_capacity():
                return
            self.constraint_count.fill_(before)  # rewind: the stored constraints below are kept

    def _solve_launches(self, positions_t1: wp.array, separation: float, tolerance: float) -> _SolveLaunches:
        key = (positions_t1.ptr, positions_t1.shape, float(separation), float(tolerance))
        cached = self._launches
        if cached is not None and cached.key == key and cached.positions_t1 is positions_t1:
            return cached
        dev = self.device
        cap = self.capacity
        constraints = self.constraints
        tol = wp.float64(float(tolerance))
        launches = _SolveLaunches()
        launches.key = key
        launches.positions_t1 = positions_t1  # kept alive, so its address cannot be reused meanwhile
        launches.weight_sums = wp.launch(_weight_sums, dim=cap, inputs=[constraints], outputs=[self.weight_sum],
                                         device=dev, record_cmd=True)
        launches.dual_steps = wp.launch(_dual_steps, dim=cap, inputs=[self.inverse_mass, self.weight_sum],
                                        outputs=[constraints], device=dev, record_cmd=True)
        launches.start = wp.launch(_start_solve, dim=1, inputs=[constraints, self.max_iterations],
                                   outputs=[self.loop_state, self.fista, self.scalars, self.running], device=dev,
                                   record_cmd=True)
        launches.begin = wp.launch(_begin_iteration, dim=1, inputs=[tol, self.max_iterations, self.check_every],
                                   outputs=[self.loop_state, self.fista, self.scalars, self.violation, self.restart],
                                   device=dev, record_cmd=True)
        launches.dual = wp.launch(_dual_update, dim=cap,
                                  inputs=[constraints, positions_t1, float(separation), self.loop_state, self.scalars],
                                  outputs=[self.multiplier, self.extrapolated, self.change, self.violation,
                                           self.restart], device=dev, record_cmd=True)
        launches.primal = wp.launch(_primal_update, dim=cap,
                                    inputs=[constraints, self.change, self.inverse_mass, self.loop_state, _ACTIVE],
                                    outputs=[positions_t1], device=dev, record_cmd=True)
        launches.close = wp.launch(_close_block, dim=1, inputs=[tol, self.max_iterations],
                                   outputs=[self.loop_state, self.fista, self.scalars, self.violation, self.restart,
                                            self.running], device=dev, record_cmd=True)
        launches.settle = wp.launch(_settle, dim=cap, inputs=[constraints, self.multiplier],
                                    outputs=[self.extrapolated, self.change], device=dev, record_cmd=True)
        launches.settle_primal = wp.launch(_primal_update, dim=cap,
                                           inputs=[constraints, self.change, self.inverse_mass, self.loop_state,
                                                   _ALWAYS],
                                           outputs=[positions_t1], device=dev, record_cmd=True)
        self._launches = launches
        return launches

    def solve_device(self, positions_t1: wp.array, separation: float, tolerance: float) -> None:
        """Project ``positions_t1`` (updated in place) onto every constraint added since :meth:`reset`,
        entirely on the device (see :meth:`solve` for the arguments and the warm start).

        The loop is a ``wp.capture_while`` on :attr:`running`: blocks of ``check_every`` iterations,
        the first of each (and the last iteration) measuring the KKT violation; a one-thread kernel
        stops the loop at ``tolerance`` or restarts the momentum. Kernels launch at the capacity and
        stop at :attr:`constraint_count`. The outcome stays on the device (:meth:`result` reads it).

        Allocates: no. Capture-safe: yes (the graph binds ``positions_t1`` and the constraint buffers;
        recapture after :meth:`check_capacity` grew them).
        """
        launches = self._solve_launches(positions_t1, separation, tolerance)
        self.weight_sum.zero_()
        launches.weight_sums.launch()
        launches.dual_steps.launch()
        launches.start.launch()

        def block() -> None:
            for _ in range(self.check_every):
                launches.begin.launch()
                launches.dual.launch()
                # The positions always follow the extrapolated multipliers.
                launches.primal.launch()
            launches.close.launch()

        wp.capture_while(self.running, block)
        # Back to the positions of the multipliers themselves, so a later solve can warm-start.
        launches.settle.launch()
        launches.settle_primal.launch()

    def result(self) -> ProjectionResult:
        """The outcome of the last :meth:`solve_device`. Sync point: reads 12 numbers back.

        Allocates: no. Capture-safe: no.
        """
        state = self.loop_state.numpy()
        violation = float(self.scalars.numpy()[_VIOLATION])
        return ProjectionResult(int(state[_ITERATIONS]), violation, self.count, bool(state[_CONVERGED]))

    def solve(self, positions_t1: wp.array, separation: float, tolerance: float) -> ProjectionResult:
        """Project ``positions_t1`` (updated in place) onto every constraint added since :meth:`reset`
        (:meth:`solve_device`, then :meth:`result`).

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

        Allocates: no. Capture-safe: no (reads the result back once).
        """
        self.solve_device(positions_t1, separation, tolerance)
        return self.result()
