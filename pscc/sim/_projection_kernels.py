"""Kernels and constraint layout of :class:`pscc.sim.inelastic_projection.InelasticProjection` (its only user).

See that module's docstring for the constraints, the dual solver and the loop slots.
"""

from __future__ import annotations

import warp as wp

from pscc.collision.contacts import (
    ContactArgs,
    edge_edge_hit,
    edge_edge_vertices,
    vertex_face_hit,
    vertex_face_vertices,
)
from pscc.geometry.contact_weights import contact_normal, pair_plane_normal, pair_weights, weighted_sum

wp.set_module_options({"enable_backward": False})

_ITERATIONS, _ACTIVE, _MEASURE, _MEASURED, _STOPPED, _CONVERGED, _ALWAYS = range(7)
"""Slots of ``loop_state`` (int32): iterations run, whether the current iteration runs, whether it
measures the KKT violation, whether a measurement awaits its check, stopped, converged, constant 1."""

_MOMENTUM, _VIOLATION = 0, 1
"""Slots of ``scalars`` (float32): the current iteration's momentum, the violation at the last check."""

_LOOP_SLOTS = 7
_INITIAL_CAPACITY = 64
_GROWTH = 1.25


@wp.struct
class ConstraintArgs:
    """The step's constraints, for kernels: rows ``[0, min(count[0], capacity))`` are valid."""

    vertices: wp.array(dtype=wp.vec4i)
    weights: wp.array(dtype=wp.vec4)
    normals: wp.array(dtype=wp.vec3)
    step: wp.array(dtype=float)
    count: wp.array(dtype=wp.int32)
    offset: wp.array(dtype=float)  # per constraint: its floor is separation + offset (0 for a collision)


@wp.func
def _stored(constraints: ConstraintArgs) -> int:
    """Valid constraints: the counter clamped to the capacity."""
    return wp.min(constraints.count[0], constraints.vertices.shape[0])


@wp.kernel
def _append_constraints(
    # in:
    contacts: ContactArgs,
    positions_t0: wp.array(dtype=wp.vec3),
    positions_t1: wp.array(dtype=wp.vec3),
    edge_edge: int,
    # out:
    constraints: ConstraintArgs,
    multiplier: wp.array(dtype=float),
    extrapolated: wp.array(dtype=float),
):
    """One thread per vertex-face row of ``contacts`` (edge-edge row when ``edge_edge`` is not 0): a hit
    appends its constraint, linearised at its time of impact, at the next counter slot."""
    row = wp.tid()
    ids = wp.vec4i(0, 0, 0, 0)
    s = float(0.0)
    if edge_edge != 0:
        if not edge_edge_hit(contacts, row):
            return
        ids = edge_edge_vertices(contacts, row)
        s = contacts.edge_edge_toi[row]
    else:
        if not vertex_face_hit(contacts, row):
            return
        ids = vertex_face_vertices(contacts, row)
        s = contacts.vertex_face_toi[row]
    slot = wp.atomic_add(constraints.count, 0, 1)
    if slot >= constraints.vertices.shape[0]:
        return  # overflow: the counter keeps the true number for check_capacity()
    x0 = wp.lerp(positions_t0[ids[0]], positions_t1[ids[0]], s)
    x1 = wp.lerp(positions_t0[ids[1]], positions_t1[ids[1]], s)
    x2 = wp.lerp(positions_t0[ids[2]], positions_t1[ids[2]], s)
    x3 = wp.lerp(positions_t0[ids[3]], positions_t1[ids[3]], s)
    w = pair_weights(x0, x1, x2, x3, edge_edge)
    start = weighted_sum(w, positions_t0[ids[0]], positions_t0[ids[1]], positions_t0[ids[2]], positions_t0[ids[3]])
    constraints.vertices[slot] = ids
    constraints.weights[slot] = w
    constraints.normals[slot] = contact_normal(weighted_sum(w, x0, x1, x2, x3),
                                                    pair_plane_normal(x0, x1, x2, x3, edge_edge), start)
    constraints.offset[slot] = 0.0
    multiplier[slot] = 0.0
    extrapolated[slot] = 0.0


@wp.kernel
def _append_stitch_constraints(
    # in:
    stitch_vertices: wp.array(dtype=wp.vec4i),
    stitch_weights: wp.array(dtype=wp.vec4),
    positions_t1: wp.array(dtype=wp.vec3),
    separation: float,
    slack: float,
    # out:
    constraints: ConstraintArgs,
    multiplier: wp.array(dtype=float),
    extrapolated: wp.array(dtype=float),
):
    """One thread per stitch: six constraints ``+-e_c . d >= -a_c`` on its offset ``d = sum_a w_a x_a``, with
    ``a_c = max(|d_c|, slack)`` at ``positions_t1``: the response may close the seam but not open it further
    than the integrator left it (or than ``slack``)."""
    s = wp.tid()
    ids = stitch_vertices[s]
    w = stitch_weights[s]
    d = w[0] * positions_t1[ids[0]] + w[1] * positions_t1[ids[1]] + w[2] * positions_t1[ids[2]]
    for c in range(3):
        allowed = wp.max(wp.abs(d[c]), slack)
        for side in range(2):
            slot = wp.atomic_add(constraints.count, 0, 1)
            if slot < constraints.vertices.shape[0]:
                n = wp.vec3(0.0)
                n[c] = 1.0 - 2.0 * float(side)
                constraints.vertices[slot] = ids
                constraints.weights[slot] = w
                constraints.normals[slot] = n
                constraints.offset[slot] = -allowed - separation
                multiplier[slot] = 0.0
                extrapolated[slot] = 0.0


@wp.kernel
def _append_near_constraints(
    # in:
    spring_vertices: wp.array(dtype=wp.vec4i),
    spring_weights: wp.array(dtype=wp.vec4),
    spring_normals: wp.array(dtype=wp.vec3),
    spring_count: wp.array(dtype=wp.int32),
    inverse_mass: wp.array(dtype=float),
    positions_t1: wp.array(dtype=wp.vec3),
    separation: float,
    gate: wp.array(dtype=wp.int32),
    # out:
    constraints: ConstraintArgs,
    multiplier: wp.array(dtype=float),
    extrapolated: wp.array(dtype=float),
):
    """One thread per contact spring slot (when ``gate[0]`` is 1): a spring with a free vertex appends a
    proximity constraint ``n . sum_a w_a x_a >= min(separation, g)``, ``g`` its gap at ``positions_t1``
    (offset ``min(0, g - separation)``): met where the positions are, so the response may not push the pair
    closer than it is (or than ``separation``)."""
    k = wp.tid()
    if gate[0] != 1:
        return
    if k >= wp.min(spring_count[0], spring_vertices.shape[0]):
        return
    ids = spring_vertices[k]
    free = float(0.0)
    for j in range(4):
        free += inverse_mass[ids[j]]
    if free == 0.0:
        return  # nothing the response can move
    w = spring_weights[k]
    n = spring_normals[k]
    gap = wp.dot(n, weighted_sum(w, positions_t1[ids[0]], positions_t1[ids[1]], positions_t1[ids[2]],
                                 positions_t1[ids[3]]))
    slot = wp.atomic_add(constraints.count, 0, 1)
    if slot >= constraints.vertices.shape[0]:
        return  # overflow: the counter keeps the true number for check_capacity()
    constraints.vertices[slot] = ids
    constraints.weights[slot] = w
    constraints.normals[slot] = n
    constraints.offset[slot] = wp.min(gap - separation, 0.0)
    multiplier[slot] = 0.0
    extrapolated[slot] = 0.0


@wp.kernel
def _weight_sums(
    # in:
    constraints: ConstraintArgs,
    # out:
    weight_sum: wp.array(dtype=float),
):
    """One thread per constraint slot: S_i += |w_ki| for its four vertices."""
    k = wp.tid()
    if k >= _stored(constraints):
        return
    ids = constraints.vertices[k]
    w = constraints.weights[k]
    for j in range(4):
        wp.atomic_add(weight_sum, ids[j], wp.abs(w[j]))


@wp.kernel
def _dual_steps(
    # in:
    inverse_mass: wp.array(dtype=float),
    weight_sum: wp.array(dtype=float),
    # in/out (writes constraints.step):
    constraints: ConstraintArgs,
):
    """One thread per constraint slot: 1 / D_k (0 when every vertex is kinematic)."""
    k = wp.tid()
    if k >= _stored(constraints):
        return
    ids = constraints.vertices[k]
    w = constraints.weights[k]
    bound = float(0.0)
    for j in range(4):
        bound += wp.abs(w[j]) * inverse_mass[ids[j]] * weight_sum[ids[j]]
    if bound > 0.0:
        constraints.step[k] = 1.0 / bound
    else:
        constraints.step[k] = 0.0


@wp.kernel
def _start_solve(
    # in:
    constraints: ConstraintArgs,
    max_iterations: int,
    # out:
    loop_state: wp.array(dtype=wp.int32),
    fista: wp.array(dtype=wp.float64),
    scalars: wp.array(dtype=float),
    running: wp.array(dtype=wp.int32),
):
    """A single thread: no iteration yet, no momentum; run unless there is nothing to project."""
    for slot in range(_LOOP_SLOTS):
        loop_state[slot] = 0
    loop_state[_ALWAYS] = 1
    fista[0] = wp.float64(1.0)
    scalars[_MOMENTUM] = 0.0
    running[0] = 0
    if _stored(constraints) <= 0:
        scalars[_VIOLATION] = 0.0
        loop_state[_STOPPED] = 1
        loop_state[_CONVERGED] = 1
    else:
        scalars[_VIOLATION] = wp.inf
        if max_iterations > 0:
            running[0] = 1


@wp.func
def _close_check(
    tolerance: wp.float64,
    loop_state: wp.array(dtype=wp.int32),
    fista: wp.array(dtype=wp.float64),
    scalars: wp.array(dtype=float),
    violation: wp.array(dtype=float),
    restart: wp.array(dtype=float),
):
    """After an iteration that measured: stop at the tolerance, else restart the momentum when it
    points uphill (O'Donoghue and Candes 2015)."""
    if loop_state[_MEASURED] != 0:
        loop_state[_MEASURED] = 0
        value = wp.max(violation[0], violation[1])
        scalars[_VIOLATION] = value
        if wp.float64(value) <= tolerance:
            loop_state[_STOPPED] = 1
            loop_state[_CONVERGED] = 1
        elif restart[0] > 0.0:
            fista[0] = wp.float64(1.0)


@wp.kernel
def _begin_iteration(
    # in:
    tolerance: wp.float64,
    max_iterations: int,
    check_every: int,
    # in/out:
    loop_state: wp.array(dtype=wp.int32),
    fista: wp.array(dtype=wp.float64),
    # out:
    scalars: wp.array(dtype=float),
    violation: wp.array(dtype=float),
    restart: wp.array(dtype=float),
):
    """A single thread: close the previous iteration's check, then decide whether this iteration runs,
    whether it measures, and its FISTA momentum (float64, as ``t' = (1 + sqrt(1 + 4 t^2)) / 2``)."""
    _close_check(tolerance, loop_state, fista, scalars, violation, restart)
    i = loop_state[_ITERATIONS]
    loop_state[_ACTIVE] = 0
    loop_state[_MEASURE] = 0
    if loop_state[_STOPPED] != 0 or i >= max_iterations:
        return
    loop_state[_ACTIVE] = 1
    if i % check_every == 0 or i + 1 == max_iterations:
        loop_state[_MEASURE] = 1
        loop_state[_MEASURED] = 1
        violation[0] = -wp.inf
        violation[1] = -wp.inf
        restart[0] = 0.0
    t = fista[0]
    following = wp.float64(0.5) * (wp.float64(1.0) + wp.sqrt(wp.float64(1.0) + wp.float64(4.0) * t * t))
    scalars[_MOMENTUM] = wp.float32((t - wp.float64(1.0)) / following)
    fista[0] = following
    loop_state[_ITERATIONS] = i + 1


@wp.kernel
def _close_block(
    # in:
    tolerance: wp.float64,
    max_iterations: int,
    # in/out:
    loop_state: wp.array(dtype=wp.int32),
    fista: wp.array(dtype=wp.float64),
    scalars: wp.array(dtype=float),
    violation: wp.array(dtype=float),
    restart: wp.array(dtype=float),
    # out:
    running: wp.array(dtype=wp.int32),
):
    """A single thread, after a block of iterations: close the last check; go on while not stopped
    and below the iteration cap."""
    _close_check(tolerance, loop_state, fista, scalars, violation, restart)
    running[0] = 0
    if loop_state[_STOPPED] == 0 and loop_state[_ITERATIONS] < max_iterations:
        running[0] = 1


@wp.kernel
def _dual_update(
    # in:
    constraints: ConstraintArgs,
    positions_t1: wp.array(dtype=wp.vec3),
    separation: float,
    loop_state: wp.array(dtype=wp.int32),
    scalars: wp.array(dtype=float),
    # in/out:
    multiplier: wp.array(dtype=float),
    extrapolated: wp.array(dtype=float),
    # out:
    change: wp.array(dtype=float),
    violation: wp.array(dtype=float),
    restart: wp.array(dtype=float),
):
    """One thread per constraint slot: one accelerated projected dual step (when the iteration runs).

    ``positions_t1`` are the positions of the extrapolated multipliers y. The new multiplier is
    lambda' = max(0, y + deficit / D_k), the new extrapolation y' = lambda' + momentum (lambda' - lambda);
    ``change`` = y' - y for the primal update. When the iteration measures it also records the largest
    deficit (primal feasibility), the largest excess gap of a constraint with lambda' > 0
    (complementarity) and the restart indicator sum (y - lambda') (lambda' - lambda) (> 0: the momentum
    points uphill)."""
    k = wp.tid()
    if loop_state[_ACTIVE] == 0:
        return
    if k >= _stored(constraints):
        return
    step = constraints.step[k]
    if step == 0.0:
        change[k] = 0.0
        return
    ids = constraints.vertices[k]
    w = constraints.weights[k]
    n = constraints.normals[k]
    gap = float(0.0)
    for j in range(4):
        gap += w[j] * wp.dot(n, positions_t1[ids[j]])
    deficit = separation + constraints.offset[k] - gap
    old = multiplier[k]
    y = extrapolated[k]
    new = wp.max(y + deficit * step, 0.0)
    if loop_state[_MEASURE] != 0:
        wp.atomic_max(violation, 0, deficit)
        if new > 0.0:
            wp.atomic_max(violation, 1, -deficit)
        wp.atomic_add(restart, 0, (y - new) * (new - old))
    y_new = new + scalars[_MOMENTUM] * (new - old)
    multiplier[k] = new
    extrapolated[k] = y_new
    change[k] = y_new - y


@wp.kernel
def _settle(
    # in:
    constraints: ConstraintArgs,
    multiplier: wp.array(dtype=float),
    # in/out:
    extrapolated: wp.array(dtype=float),
    # out:
    change: wp.array(dtype=float),
):
    """One thread per constraint slot: drop the momentum (y = lambda); ``change`` = lambda - y."""
    k = wp.tid()
    if k >= _stored(constraints):
        return
    change[k] = multiplier[k] - extrapolated[k]
    extrapolated[k] = multiplier[k]


@wp.kernel
def _primal_update(
    # in:
    constraints: ConstraintArgs,
    change: wp.array(dtype=float),
    inverse_mass: wp.array(dtype=float),
    loop_state: wp.array(dtype=wp.int32),
    gate: int,
    # out:
    positions_t1: wp.array(dtype=wp.vec3),
):
    """One thread per constraint slot: x += M^-1 w_k n_k (change of lambda_k), when ``loop_state[gate]``
    is not 0."""
    k = wp.tid()
    if loop_state[gate] == 0:
        return
    if k >= _stored(constraints):
        return
    delta = change[k]
    if delta == 0.0:
        return
    ids = constraints.vertices[k]
    w = constraints.weights[k]
    n = constraints.normals[k]
    for j in range(4):
        scale = inverse_mass[ids[j]] * w[j] * delta
        if scale != 0.0:
            wp.atomic_add(positions_t1, ids[j], scale * n)
