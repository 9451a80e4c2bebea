"""Assembly of the linearised backward-Euler system as a 3x3-block sparse matrix (BSR).

One step solves ``A dv = b`` with (Baraff & Witkin 1998)

    A = M + dt D + dt^2 H,        b = dt f(x_t) - (dt D + dt^2 H) v_t,

where H = -df/dx is the PSD Hessian approximation of every element, D = -df/dv its damping and f the
conservative + external forces at ``x_t``. Element by element, ``A_e = dt D_e + dt^2 H_e`` and the
right-hand side gets ``dt f_e - A_e v``; damping and friction forces therefore enter only through
their blocks (they are linear in v).

Memory layout (nothing is stored per element block; two scalars per contact slot):

==========================  ====================  ==========================================================
buffer                      size                  contents
==========================  ====================  ==========================================================
``matrix`` (BSR)            nnz blocks            element blocks: mass (or the Dirichlet scale) on the
                                                  diagonal, plus every (a, b) pair of a face or hinge
``contact_coefficients``    contact capacity      vec2 ``(alpha, beta)`` of each contact's block K
``rhs``, ``v_ref``          n vec3                right-hand side and reference velocities
==========================  ====================  ==========================================================

The element blocks (vertex, face and hinge) have a sparsity pattern fixed by the mesh: the BSR matrix
is allocated once with every (a, b) pair of a face or hinge and every diagonal block. Each step
rewrites every block row (zero blocks and the mass block, one thread per vertex), then every face and
hinge adds its blocks straight into their slots: a binary search in the row's sorted columns (rows
hold about 10 blocks) finds the slot, so neither a triplet buffer (9 blocks per face and 16 per hinge,
about 1.4 KB per triangle) nor a per-block slot table (about 130 B per triangle) is needed.
Contacts change their pattern every step and have rank structure: the 16 blocks of a contact with
vertex weights w are ``w_a w_b K`` with ``K = alpha n n^T + beta (I - n n^T)``, ``alpha = dt^2 k_c``
and ``beta = dt c``. The normal n is the spring's, so each contact stores only ``(alpha, beta)`` (8 B
instead of a 36 B mat33). Recomputing them in every product instead (from x_t, v_ref, the masses and
the friction) would drop even those, but doubles the frame time of a contact-heavy scene (CG applies
A hundreds of times per frame). Contacts are applied matrix-free,
``A x = A_elements x + sum_c w (K sum_b w_b x_b)`` (:meth:`ImplicitSystem.apply`: 4 gathers and 4
scatters per contact instead of 16 block products), with ``w_a^2 K`` added to the preconditioner's
diagonal (:meth:`ImplicitSystem.diagonal`).

Dirichlet rows (scripted and massless vertices): the row and column of vertex i are replaced by
``s_i I`` (s_i its mass, or 1) with ``b_i = s_i dv_i`` for the prescribed ``dv_i``. Element blocks
touching such a vertex add nothing to the matrix, and free rows move the
known part to the right-hand side: ``b_k -= A_kj v_ref_j`` with ``v_ref_j`` the prescribed new
velocity of j, which is the same as ``-A_kj (v_j + dv_j)``. Free vertices use ``v_ref = v_t``.

Accumulation into ``b`` and into the matrix blocks uses float atomics: bitwise reproducible on the
CPU; on CUDA set ``wp.config.deterministic`` before import for run-to-run reproducibility.
"""

from __future__ import annotations

import numpy as np
import warp as wp
from warp.sparse import bsr_get_diag, bsr_set_from_triplets, bsr_zeros

from pscc._lanes import row_lanes
from pscc.sim.contact_springs import ContactSprings
from pscc.sim.materials import (
    dihedral_angle,
    dihedral_angle_gradient,
    green_strain,
    hinge_is_degenerate,
    membrane_clamped_stress,
    membrane_deformation,
    membrane_gauss_newton_block,
    membrane_geometric_coefficient,
    membrane_gradient,
    membrane_shape_vector,
    membrane_stress,
    wrap_angle,
)
from pscc.sim.model import VERTEX_FREE, VERTEX_SCRIPTED, ClothModel, FaceArrays, HingeArrays, VertexArrays

wp.set_module_options({"enable_backward": False})

_FREE = wp.constant(VERTEX_FREE)
_SCRIPTED = wp.constant(VERTEX_SCRIPTED)

@wp.struct
class StepParams:
    """Per-step scalars of the assembly kernels."""

    dt: float  # time step [s]
    gravity: wp.vec3  # [m/s^2]
    wind: wp.vec3  # [m/s]
    air_drag: float  # [kg/(m^2 s)]
    contact_stiffness: float  # [N/m]; <= 0 selects the automatic per-contact stiffness
    contact_stiffness_scale: float  # dimensionless
    stitch_stiffness_scale: float  # dimensionless
    sewing_step: float  # [m]: the largest stitch offset a step's force sees (sewing_speed x dt)
    friction_epsilon: float  # eps_v [m/s]
    hinge_degeneracy_ratio: float  # dimensionless


@wp.struct
class BlockMatrix:
    """Device view of the fixed-pattern BSR element matrix, and the count of blocks not in its pattern."""

    offsets: wp.array(dtype=wp.int32)
    columns: wp.array(dtype=wp.int32)
    values: wp.array(dtype=wp.mat33)
    missing: wp.array(dtype=wp.int32)


@wp.struct
class ContactArrays:
    """Device view of a :class:`pscc.sim.ContactSprings` (rebuilt when its buffers grow)."""

    vertices: wp.array(dtype=wp.vec4i)
    weights: wp.array(dtype=wp.vec4)
    normals: wp.array(dtype=wp.vec3)
    multiplicity: wp.array(dtype=wp.int32)
    count: wp.array(dtype=wp.int32)
    rest_gap: float
    start_gap: wp.array(dtype=float)  # per vertex: how close it started to something else; empty: none
    clock: wp.array(dtype=float)  # [1]: seconds since the start
    gap_rate: float  # [m/s]: how fast a start gap opens up to the rest gap


@wp.func
def _block_index(offsets: wp.array(dtype=wp.int32), columns: wp.array(dtype=wp.int32), row: int, col: int) -> int:
    """Position of block (row, col) in a BSR matrix with sorted columns per row; -1 when absent."""
    lo = offsets[row]
    end = offsets[row + 1]
    hi = end
    while lo < hi:
        mid = (lo + hi) // 2
        if columns[mid] < col:
            lo = mid + 1
        else:
            hi = mid
    if lo < end:
        if columns[lo] == col:
            return lo
    return -1


@wp.func
def _add_block(matrix: BlockMatrix, i: int, j: int, block: wp.mat33, kind: wp.array(dtype=wp.int32),
               v_ref: wp.array(dtype=wp.vec3), rhs: wp.array(dtype=wp.vec3)):
    """Add block (i, j) of an element into the matrix (both rows free); move ``A_ij v_ref_j`` to the
    right-hand side of a free row i. Rows and columns of Dirichlet vertices get nothing."""
    if kind[i] != _FREE:
        return
    wp.atomic_sub(rhs, i, block * v_ref[j])
    if kind[j] == _FREE:
        index = _block_index(matrix.offsets, matrix.columns, i, j)
        if index >= 0:
            wp.atomic_add(matrix.values, index, block)
        else:
            wp.atomic_add(matrix.missing, 0, 1)


@wp.func
def _emit_force(i: int, force: wp.vec3, dt: float, kind: wp.array(dtype=wp.int32), rhs: wp.array(dtype=wp.vec3)):
    """Add ``dt * force`` to the right-hand side of a free row i."""
    if kind[i] == _FREE:
        wp.atomic_add(rhs, i, dt * force)


@wp.kernel
def _prepare_vertices(
    # in:
    vertices: VertexArrays,
    targets: wp.array(dtype=wp.vec3),
    positions: wp.array(dtype=wp.vec3),
    velocities: wp.array(dtype=wp.vec3),
    params: StepParams,
    warm_start: int,
    # out:
    v_ref: wp.array(dtype=wp.vec3),
    matrix: BlockMatrix,
    rhs: wp.array(dtype=wp.vec3),
    dv: wp.array(dtype=wp.vec3),
):
    """One thread per vertex: its block row (zeros and the mass block), gravity, Dirichlet rows and the
    initial guess of dv."""
    i = wp.tid()
    mass = vertices.mass[i]
    kind = vertices.kind[i]
    v = velocities[i]
    dt = params.dt
    scale = mass
    if kind == _FREE:
        v_ref[i] = v
        rhs[i] = (dt * mass) * params.gravity
        if warm_start == 0:
            dv[i] = wp.vec3(0.0)
    else:
        target_velocity = v + dt * params.gravity  # massless: ballistic
        if kind == _SCRIPTED:
            target_velocity = (targets[i] - positions[i]) / dt
        scale = wp.where(mass > 0.0, mass, 1.0)
        v_ref[i] = target_velocity
        rhs[i] = scale * (target_velocity - v)
        dv[i] = target_velocity - v
    for k in range(matrix.offsets[i], matrix.offsets[i + 1]):
        if matrix.columns[k] == i:
            matrix.values[k] = wp.identity(n=3, dtype=float) * scale
        else:
            matrix.values[k] = wp.mat33(0.0)


@wp.kernel
def _assemble_faces(
    # in:
    faces: FaceArrays,
    kind: wp.array(dtype=wp.int32),
    positions: wp.array(dtype=wp.vec3),
    v_ref: wp.array(dtype=wp.vec3),
    params: StepParams,
    # out:
    matrix: BlockMatrix,
    rhs: wp.array(dtype=wp.vec3),
):
    """One thread per face: membrane force, its 9 Hessian/damping blocks, and air drag."""
    f = wp.tid()
    ids = faces.indices[f]
    x0 = positions[ids[0]]
    x1 = positions[ids[1]]
    x2 = positions[ids[2]]
    inv_rest = faces.inv_rest[f]
    area = faces.rest_area[f]
    stiffness = faces.stiffness[f]
    dt = params.dt
    f0, f1 = membrane_deformation(x0, x1, x2, inv_rest)
    stress = membrane_stress(green_strain(f0, f1), stiffness)
    clamped = membrane_clamped_stress(stress)
    gauss_newton_scale = dt * dt + dt * faces.damping[f]

    # Air drag on the normal relative velocity: constant wind push plus an implicit damper.
    normal = wp.cross(x1 - x0, x2 - x0)
    double_area = wp.length(normal)
    drag = float(0.0)
    if double_area > 0.0:
        normal = normal / double_area
        drag = params.air_drag * double_area / 6.0
    wind_force = (drag * wp.dot(params.wind, normal)) * normal
    drag_block = (dt * drag) * wp.outer(normal, normal)

    for a in range(3):
        shape_a = membrane_shape_vector(inv_rest, a)
        force = wind_force - membrane_gradient(f0, f1, shape_a, stress, area)
        _emit_force(ids[a], force, dt, kind, rhs)
        for b in range(3):
            shape_b = membrane_shape_vector(inv_rest, b)
            block = gauss_newton_scale * membrane_gauss_newton_block(f0, f1, shape_a, shape_b, stiffness, area)
            geometric = dt * dt * membrane_geometric_coefficient(shape_a, shape_b, clamped, area)
            block = block + wp.identity(n=3, dtype=float) * geometric
            if a == b:
                block = block + drag_block
            _add_block(matrix, ids[a], ids[b], block, kind, v_ref, rhs)


@wp.kernel
def _assemble_hinges(
    # in:
    hinges: HingeArrays,
    kind: wp.array(dtype=wp.int32),
    positions: wp.array(dtype=wp.vec3),
    v_ref: wp.array(dtype=wp.vec3),
    params: StepParams,
    # out:
    matrix: BlockMatrix,
    rhs: wp.array(dtype=wp.vec3),
):
    """One thread per hinge: bending force and its 16 Gauss-Newton blocks (nothing when degenerate)."""
    h = wp.tid()
    ids = hinges.indices[h]
    x0 = positions[ids[0]]
    x1 = positions[ids[1]]
    x2 = positions[ids[2]]
    x3 = positions[ids[3]]
    if hinge_is_degenerate(x0, x1, x2, x3, hinges.rest_length[h], params.hinge_degeneracy_ratio):
        return
    dt = params.dt
    stiffness = hinges.stiffness[h]
    delta = wrap_angle(dihedral_angle(x0, x1, x2, x3) - hinges.rest_angle[h])
    gradient = dihedral_angle_gradient(x0, x1, x2, x3)
    block_scale = (dt * dt + dt * hinges.damping[h]) * stiffness
    for a in range(4):
        _emit_force(ids[a], (-stiffness * delta) * gradient[a], dt, kind, rhs)
        for b in range(4):
            block = block_scale * wp.outer(gradient[a], gradient[b])
            _add_block(matrix, ids[a], ids[b], block, kind, v_ref, rhs)


@wp.func
def _contact_rows(contacts: ContactArrays) -> int:
    """Contact slots in use: the spring counter clamped to the buffers."""
    return wp.min(contacts.count[0], contacts.vertices.shape[0])


@wp.func
def _names_vertices(ids: wp.vec4i, vertex_count: int) -> bool:
    """Whether a contact's four vertex ids all name existing vertices."""
    for a in range(4):
        if ids[a] < 0 or ids[a] >= vertex_count:
            return False
    return True


@wp.func
def _contact_block(coefficients: wp.vec2, n: wp.vec3) -> wp.mat33:
    """The contact block ``K = alpha n n^T + beta (I - n n^T)`` from its two coefficients (alpha, beta)."""
    nn = wp.outer(n, n)
    return coefficients[0] * nn + coefficients[1] * (wp.identity(n=3, dtype=float) - nn)


@wp.func
def _weighted(ids: wp.vec4i, w: wp.vec4, values: wp.array(dtype=wp.vec3)) -> wp.vec3:
    """``sum_a w_a values[ids[a]]`` (a pair's offset from its positions, its relative velocity from velocities)."""
    return w[0] * values[ids[0]] + w[1] * values[ids[1]] + w[2] * values[ids[2]] + w[3] * values[ids[3]]


@wp.func
def _inverse_effective_mass(ids: wp.vec4i, w: wp.vec4, vertices: VertexArrays) -> float:
    """``sum_a w_a^2 / m_a`` over the free vertices with mass (scripted vertices count as infinitely heavy)."""
    total = float(0.0)
    for a in range(4):
        mass = vertices.mass[ids[a]]
        if vertices.kind[ids[a]] == _FREE and mass > 0.0:
            total = total + w[a] * w[a] / mass
    return total


@wp.func
def _emit_pair(ids: wp.vec4i, w: wp.vec4, force: wp.vec3, known: wp.vec3, dt: float, kind: wp.array(dtype=wp.int32),
               rhs: wp.array(dtype=wp.vec3)):
    """A pair's right-hand side on its free rows: ``dt w_a force`` and the moved-over known part ``-w_a known``
    (``known = K sum_b w_b v_ref_b``)."""
    for a in range(4):
        _emit_force(ids[a], w[a] * force, dt, kind, rhs)
        if kind[ids[a]] == _FREE:
            wp.atomic_sub(rhs, ids[a], w[a] * known)


@wp.func
def _assemble_contact(
    contacts: ContactArrays,
    vertices: VertexArrays,
    positions: wp.array(dtype=wp.vec3),
    v_ref: wp.array(dtype=wp.vec3),
    params: StepParams,
    c: int,
    coefficients: wp.array(dtype=wp.vec2),
    rhs: wp.array(dtype=wp.vec3),
):
    """Contact slot ``c`` of :func:`_assemble_contacts` (its coefficients stay zero when it names a missing
    vertex or is inactive)."""
    if not _names_vertices(contacts.vertices[c], positions.shape[0]):
        return
    ids = contacts.vertices[c]
    w = contacts.weights[c]
    n = contacts.normals[c]
    point = _weighted(ids, w, positions)
    relative_velocity = _weighted(ids, w, v_ref)
    inverse_mass = _inverse_effective_mass(ids, w, vertices)
    friction = float(0.0)
    for a in range(4):
        friction = friction + 0.5 * wp.abs(w[a]) * vertices.friction[ids[a]]
    rest = contacts.rest_gap
    if contacts.start_gap.shape[0] > 0:
        # Surfaces that started closer than the thickness keep that distance at first and are eased apart
        # (ImplicitSystem.set_start_gaps): the spring's rest gap opens at gap_rate up to the thickness.
        start = wp.min(wp.min(contacts.start_gap[ids[0]], contacts.start_gap[ids[1]]),
                       wp.min(contacts.start_gap[ids[2]], contacts.start_gap[ids[3]]))
        rest = wp.min(rest, start + contacts.gap_rate * contacts.clock[0])
    gap = wp.dot(n, point) - rest
    dt = params.dt
    stiffness = params.contact_stiffness
    if stiffness <= 0.0 and inverse_mass > 0.0:
        stiffness = params.contact_stiffness_scale / (inverse_mass * dt * dt)
    stiffness = stiffness * float(contacts.multiplicity[c])  # the pair rows this spring stands for
    if gap >= 0.0 or stiffness <= 0.0:
        return

    normal_force = -stiffness * gap  # > 0
    tangential = relative_velocity - wp.dot(relative_velocity, n) * n
    damping = friction * normal_force / wp.max(wp.length(tangential), params.friction_epsilon)
    coefficient = wp.vec2(dt * dt * stiffness, dt * damping)
    coefficients[c] = coefficient
    # Free rows: dt f_a and the moved-over known part -sum_b A_ab v_ref_b = -w_a K (sum_b w_b v_ref_b).
    _emit_pair(ids, w, normal_force * n, _contact_block(coefficient, n) * relative_velocity, dt, vertices.kind, rhs)


@wp.kernel
def _assemble_contacts(
    # in:
    contacts: ContactArrays,
    vertices: VertexArrays,
    positions: wp.array(dtype=wp.vec3),
    v_ref: wp.array(dtype=wp.vec3),
    params: StepParams,
    lanes: int,
    # out:
    coefficients: wp.array(dtype=wp.vec2),
    rhs: wp.array(dtype=wp.vec3),
):
    """Row kernel (:mod:`pscc._lanes`) over the contact slots in use (``coefficients`` zeroed before):
    spring force and friction damper, and the coefficients of its block K.

    The contact's 16 blocks are ``A_ab = w_a w_b K`` (a, b free) with ``K = dt^2 k_c n n^T + dt c (I - n n^T)``,
    ``k_c`` times the spring's multiplicity;
    only ``(dt^2 k_c, dt c)`` is stored (zero for an inactive slot): the normal n is the spring's.
    """
    for c in range(wp.tid(), _contact_rows(contacts), lanes):
        _assemble_contact(contacts, vertices, positions, v_ref, params, c, coefficients, rhs)


@wp.kernel
def _assemble_stitches(
    # in:
    stitches: ContactArrays,
    vertices: VertexArrays,
    positions: wp.array(dtype=wp.vec3),
    v_ref: wp.array(dtype=wp.vec3),
    params: StepParams,
    lanes: int,
    # out:
    coefficients: wp.array(dtype=wp.vec2),
    rhs: wp.array(dtype=wp.vec3),
):
    """Row kernel (:mod:`pscc._lanes`) over the stitches: zero-length springs between vertex i and its seam
    point, ``E = k/2 |d|^2`` with ``d = sum_a w_a x_a``, isotropic (K = dt^2 k I, stored as alpha = beta) and
    ``k = stitch_stiffness_scale m_eff / dt^2``. The force sees ``d`` clamped to ``sewing_step`` in length
    (an open seam closes at most that much per step)."""
    for c in range(wp.tid(), _contact_rows(stitches), lanes):
        ids = stitches.vertices[c]
        w = stitches.weights[c]
        offset = _weighted(ids, w, positions)
        inverse_mass = _inverse_effective_mass(ids, w, vertices)
        if inverse_mass <= 0.0:
            coefficients[c] = wp.vec2(0.0)
            continue
        dt = params.dt
        stiffness = params.stitch_stiffness_scale / (inverse_mass * dt * dt)
        length = wp.length(offset)
        if length > params.sewing_step:
            offset = offset * (params.sewing_step / length)
        coefficient = wp.vec2(dt * dt * stiffness, dt * dt * stiffness)
        coefficients[c] = coefficient
        _emit_pair(ids, w, -stiffness * offset, coefficient[0] * _weighted(ids, w, v_ref), dt, vertices.kind, rhs)


@wp.kernel
def _add_untangle_push(
    # in:
    vertices: VertexArrays,
    velocities: wp.array(dtype=wp.vec3),
    untangle: wp.array(dtype=wp.vec3),
    params: StepParams,
    # out:
    rhs: wp.array(dtype=wp.vec3),
):
    """One thread per vertex: the momentum that brings a free vertex's velocity along its untangle velocity
    u, with this step's gravity, up to |u| (a change of at most |u| + dt |g| along u, never braking;
    :mod:`pscc.sim.untangle`). The cloth's own forces still resist it: a bounded push, not a prescription."""
    i = wp.tid()
    if vertices.kind[i] != _FREE:
        return
    target = untangle[i]
    speed = wp.length(target)
    if speed == 0.0:
        return
    direction = target / speed
    fall = params.dt * params.gravity
    deficit = wp.min(speed - wp.dot(direction, velocities[i] + fall), speed + wp.length(fall))
    if deficit > 0.0:
        wp.atomic_add(rhs, i, (vertices.mass[i] * deficit) * direction)


@wp.kernel
def _tick(dt: float, clock: wp.array(dtype=float)):
    """One thread: clock += dt."""
    clock[0] = clock[0] + dt


@wp.kernel
def _element_matrix_times(
    # in:
    offsets: wp.array(dtype=wp.int32),
    columns: wp.array(dtype=wp.int32),
    values: wp.array(dtype=wp.mat33),
    x: wp.array(dtype=wp.vec3),
    # out:
    y: wp.array(dtype=wp.vec3),
):
    """One thread per block row: ``y_i = sum_k values[k] x[columns[k]]`` (the element matrix times x).

    Written out rather than ``warp.sparse.bsr_mv`` (which handles any block type, alpha and beta): on
    Warp 1.19's CPU device this is about 5 times faster for 3x3 blocks, and it is the inner loop of CG.
    """
    i = wp.tid()
    total = wp.vec3(0.0)
    for k in range(offsets[i], offsets[i + 1]):
        total += values[k] * x[columns[k]]
    y[i] = total


@wp.kernel
def _add_contact_products(
    # in:
    contacts: ContactArrays,
    kind: wp.array(dtype=wp.int32),
    coefficients: wp.array(dtype=wp.vec2),
    x: wp.array(dtype=wp.vec3),
    lanes: int,
    # out:
    y: wp.array(dtype=wp.vec3),
):
    """Row kernel (:mod:`pscc._lanes`) over the contact slots in use: ``y_a += w_a K sum_b w_b x_b`` over
    each active contact's free vertices a and b."""
    # Arrays out of the struct once: on the CPU every struct member access copies the array header.
    contact_vertices = contacts.vertices
    contact_weights = contacts.weights
    contact_normals = contacts.normals
    for c in range(wp.tid(), _contact_rows(contacts), lanes):
        coefficient = coefficients[c]
        if coefficient[0] == 0.0 and coefficient[1] == 0.0:
            continue  # inactive: K = 0
        ids = contact_vertices[c]
        if not _names_vertices(ids, x.shape[0]):
            continue
        w = contact_weights[c]
        combined = wp.vec3(0.0)
        for b in range(4):
            if kind[ids[b]] == _FREE:
                combined = combined + w[b] * x[ids[b]]
        # K combined in rank-one form: beta combined + (alpha - beta) (n . combined) n.
        n = contact_normals[c]
        product = coefficient[1] * combined + ((coefficient[0] - coefficient[1]) * wp.dot(n, combined)) * n
        for a in range(4):
            if kind[ids[a]] == _FREE:
                wp.atomic_add(y, ids[a], w[a] * product)


@wp.kernel
def _add_contact_diagonal(
    # in:
    contacts: ContactArrays,
    kind: wp.array(dtype=wp.int32),
    coefficients: wp.array(dtype=wp.vec2),
    vertex_count: int,
    lanes: int,
    # out:
    diagonal: wp.array(dtype=wp.mat33),
):
    """Row kernel (:mod:`pscc._lanes`) over the contact slots in use: add ``w_a^2 K`` to the diagonal block
    of each free vertex a."""
    for c in range(wp.tid(), _contact_rows(contacts), lanes):
        coefficient = coefficients[c]
        if coefficient[0] == 0.0 and coefficient[1] == 0.0:
            continue
        ids = contacts.vertices[c]
        if not _names_vertices(ids, vertex_count):
            continue
        w = contacts.weights[c]
        block = _contact_block(coefficient, contacts.normals[c])
        for a in range(4):
            if kind[ids[a]] == _FREE:
                wp.atomic_add(diagonal, ids[a], (w[a] * w[a]) * block)


@wp.kernel
def _write_contact_blocks(
    # in:
    contacts: ContactArrays,
    coefficients: wp.array(dtype=wp.vec2),
    # out:
    blocks: wp.array(dtype=wp.mat33),
):
    """One thread per contact slot: its block K (zero when inactive), for host inspection."""
    c = wp.tid()
    blocks[c] = _contact_block(coefficients[c], contacts.normals[c])


class ImplicitSystem:
    """Owns the element matrix, the contact coefficients, the right-hand side and the reference
    velocities of one step.

    The system matrix is ``A = matrix + stitch blocks + contact blocks``: apply it with :meth:`apply`, get its diagonal
    blocks with :meth:`diagonal` and the whole of it on the host with :meth:`dense`. Buffers::

        matrix                BSR, (n x n blocks of 3x3), nnz = n + distinct face/hinge pairs
          offsets (n + 1,)    columns (nnz,) sorted per row      values (nnz,) mat33
        contact_coefficients  (contact capacity,) vec2 (alpha, beta) of each contact's K
        rhs                   (n,) vec3
        reference_velocities  (n,) vec3

    Nothing is stored per element block: faces and hinges add into ``matrix.values`` directly.

    Args:
        model: The cloth.

    Attributes:
        matrix: (n x n blocks of 3x3) BSR matrix of the element blocks (mass, faces, hinges) [kg], with
            the fixed pattern of the mesh; its values are rewritten by every :meth:`assemble`.
        contact_coefficients: (contact capacity,) vec2 ``(alpha, beta) = (dt^2 k_c, dt c)`` of each
            contact of the last :meth:`assemble` [kg]: its block is ``K = alpha n n^T + beta (I - n n^T)``
            with n the spring's normal, and its 16 blocks are ``w_a w_b K`` (zero for an inactive slot).
        rhs: (n,) vec3 right-hand side b [kg m/s].
        reference_velocities: (n,) vec3 ``v_ref``: v_t for free vertices, the prescribed new velocity
            for Dirichlet vertices [m/s].
    """

    def __init__(self, model: ClothModel) -> None:
        self.model = model
        self.device = model.device
        n = model.vertex_count
        self._contacts: ContactArrays | None = None
        self._product_launches: dict[tuple[int, int], list] = {}
        self.contact_coefficients = wp.zeros(1, dtype=wp.vec2, device=self.device)
        self.matrix = bsr_zeros(n, n, wp.mat33, device=self.device)
        self._build_pattern()
        self._missing = wp.zeros(1, dtype=wp.int32, device=self.device)
        self._matrix_view = BlockMatrix()
        self._matrix_view.offsets = self.matrix.offsets
        self._matrix_view.columns = self.matrix.columns
        self._matrix_view.values = self.matrix.values
        self._matrix_view.missing = self._missing
        self.rhs = wp.zeros(n, dtype=wp.vec3, device=self.device)
        self.contact_start_gap = wp.zeros(0, dtype=float, device=self.device)
        """(n,) float32 per vertex: the distance it started at from something it touched, or empty (none)."""
        self.contact_clock = wp.zeros(1, dtype=float, device=self.device)
        """[1] float32 seconds since the start (advanced by :meth:`tick`, set by :meth:`set_clock`)."""
        self.contact_gap_rate = 0.0
        """[m/s] how fast a start gap opens (:meth:`set_start_gaps`)."""
        self._stitches: ContactArrays | None = None
        """The model's stitches in the contact kernels' layout (alpha = beta: the normal is unused)."""
        self.stitch_coefficients = wp.zeros(model.stitch_count, dtype=wp.vec2, device=self.device)
        if model.stitch_count:
            view = ContactArrays()
            view.vertices = model.stitch_vertices
            view.weights = model.stitch_weights
            view.normals = wp.zeros(model.stitch_count, dtype=wp.vec3, device=self.device)
            view.multiplicity = wp.ones(model.stitch_count, dtype=wp.int32, device=self.device)
            view.count = wp.array([model.stitch_count], dtype=wp.int32, device=self.device)
            view.rest_gap = 0.0
            view.start_gap = wp.zeros(0, dtype=float, device=self.device)
            view.clock = self.contact_clock
            view.gap_rate = 0.0
            self._stitches = view
        self.reference_velocities = wp.zeros(n, dtype=wp.vec3, device=self.device)
        self.untangle_velocity: wp.array | None = None
        """(n,) vec3 per-vertex untangle velocity [m/s] (:mod:`pscc.sim.untangle`), or None (no push, no
        launch). :meth:`assemble` adds the momentum that brings each free vertex's velocity along it up to
        its length. Setting or clearing it changes the launches: record graphs again."""

    def set_start_gaps(self, gaps: np.ndarray | None, rate: float) -> None:
        """Ease apart surfaces that start closer than the thickness: a contact spring's rest gap is
        ``min(h, min_a gaps[a] + rate t)`` (t: :attr:`contact_clock`) instead of h, so it keeps their start
        distance and opens it at ``rate`` instead of pushing the whole deficit out in one step.

        Args:
            gaps: (n,) per-vertex start distance [m] (the thickness or more where nothing was near), or
                None to switch the easing off.
            rate: [m/s] how fast the gaps open.

        Allocates: yes. Capture-safe: no.
        """
        if gaps is None:
            self.contact_start_gap = wp.zeros(0, dtype=float, device=self.device)
        else:
            self.contact_start_gap = wp.array(np.asarray(gaps, np.float32), dtype=float, device=self.device)
        self.contact_gap_rate = float(rate)

    def set_clock(self, t: float) -> None:
        """Set :attr:`contact_clock` to ``t`` [s] (a host upload: the host path, a resume).
        Allocates: no. Capture-safe: no."""
        self.contact_clock.fill_(float(t))

    def tick(self, dt: float) -> None:
        """Advance :attr:`contact_clock` by ``dt`` on the device (every step). Allocates: no. Capture-safe: yes."""
        wp.launch(_tick, dim=1, inputs=[float(dt)], outputs=[self.contact_clock], device=self.device)

    def reserve_contacts(self, capacity: int) -> None:
        """Size the contact coefficients for ``capacity`` contacts (the springs' capacity, which grows and
        shrinks). Allocates: only when the capacity changes. Capture-safe: no."""
        if capacity != self.contact_coefficients.shape[0]:
            self.contact_coefficients = wp.zeros(int(capacity), dtype=wp.vec2, device=self.device)

    def assemble(self, positions: wp.array, velocities: wp.array, targets: wp.array, params: StepParams,
                 contacts: ContactSprings | None, dv: wp.array, *, warm_start: bool = False) -> None:
        """Fill :attr:`matrix`, :attr:`contact_coefficients` and :attr:`rhs` for the state (x_t, v_t);
        write the initial guess into ``dv``.

        Args:
            positions: (n,) vec3 x_t [m].
            velocities: (n,) vec3 v_t [m/s].
            targets: (n,) vec3 positions the scripted vertices must reach at the end of the step [m].
            params: Per-step scalars.
            contacts: Optional contact springs (gaps evaluated at x_t); :meth:`apply` reads them until
                the next assemble.
            dv: (n,) vec3 initial guess, written here: the prescribed dv of Dirichlet vertices, and for
                free vertices 0 or, with ``warm_start``, the value ``dv`` already holds (the last step's).
            warm_start: Keep ``dv`` of free vertices as the initial guess.

        Allocates: only when the contact capacity grows. Capture-safe: yes once :meth:`reserve_contacts`
        covers the contacts' capacity.
        """
        model = self.model
        n = model.vertex_count
        wp.launch(_prepare_vertices, dim=n, device=self.device,
                  inputs=[model.vertices, targets, positions, velocities, params, int(warm_start)],
                  outputs=[self.reference_velocities, self._matrix_view, self.rhs, dv])
        if model.face_count:
            wp.launch(_assemble_faces, dim=model.face_count, device=self.device,
                      inputs=[model.faces, model.vertices.kind, positions, self.reference_velocities, params],
                      outputs=[self._matrix_view, self.rhs])
        if model.hinge_count:
            wp.launch(_assemble_hinges, dim=model.hinge_count, device=self.device,
                      inputs=[model.hinges, model.vertices.kind, positions, self.reference_velocities, params],
                      outputs=[self._matrix_view, self.rhs])
        if self.untangle_velocity is not None:
            wp.launch(_add_untangle_push, dim=n, device=self.device,
                      inputs=[model.vertices, velocities, self.untangle_velocity, params], outputs=[self.rhs])
        if self._stitches is not None:
            lanes = row_lanes(self.device, self.model.stitch_count)
            wp.launch(_assemble_stitches, dim=lanes, device=self.device,
                      inputs=[self._stitches, model.vertices, positions, self.reference_velocities, params, lanes],
                      outputs=[self.stitch_coefficients, self.rhs])
        self._contacts = None
        self._product_launches = {}
        if contacts is not None and contacts.capacity > 0:
            self.reserve_contacts(contacts.capacity)
            view = ContactArrays()
            view.vertices = contacts.vertices
            view.weights = contacts.weights
            view.normals = contacts.normals
            view.multiplicity = contacts.multiplicity
            view.count = contacts.count
            view.rest_gap = contacts.rest_gap
            view.start_gap = self.contact_start_gap
            view.clock = self.contact_clock
            view.gap_rate = self.contact_gap_rate
            self.contact_coefficients.zero_()
            lanes = row_lanes(self.device, contacts.capacity)
            wp.launch(_assemble_contacts, dim=lanes, device=self.device,
                      inputs=[view, model.vertices, positions, self.reference_velocities, params, lanes],
                      outputs=[self.contact_coefficients, self.rhs])
            self._contacts = view

    def apply(self, x: wp.array, y: wp.array) -> None:
        """``y = A x`` with the last assembled system (element matrix plus contact blocks).

        Allocates: no. Capture-safe: yes.
        """
        key = (x.ptr, y.ptr)
        commands = self._product_launches.get(key)
        if commands is None:
            # Packed once per (x, y) pair and step: CG calls this with the same arrays every iteration.
            matrix = self.matrix
            commands = [wp.launch(_element_matrix_times, dim=self.model.vertex_count, device=self.device,
                                  inputs=[matrix.offsets, matrix.columns, matrix.values, x], outputs=[y],
                                  record_cmd=True)]
            if self._stitches is not None:
                lanes = row_lanes(self.device, self.model.stitch_count)
                commands.append(wp.launch(_add_contact_products, dim=lanes, device=self.device,
                                          inputs=[self._stitches, self.model.vertices.kind,
                                                  self.stitch_coefficients, x, lanes],
                                          outputs=[y], record_cmd=True))
            if self._contacts is not None:
                lanes = row_lanes(self.device, self._contacts.vertices.shape[0])
                commands.append(wp.launch(_add_contact_products, dim=lanes, device=self.device,
                                          inputs=[self._contacts, self.model.vertices.kind,
                                                  self.contact_coefficients, x, lanes],
                                          outputs=[y], record_cmd=True))
            self._product_launches[key] = commands
        for command in commands:
            command.launch()

    def diagonal(self, out: wp.array) -> None:
        """Write the (n,) mat33 diagonal blocks of A into ``out``. Allocates: no. Capture-safe: yes."""
        bsr_get_diag(self.matrix, out=out)
        if self._stitches is not None:
            lanes = row_lanes(self.device, self.model.stitch_count)
            wp.launch(_add_contact_diagonal, dim=lanes, device=self.device,
                      inputs=[self._stitches, self.model.vertices.kind, self.stitch_coefficients,
                              self.model.vertex_count, lanes], outputs=[out])
        if self._contacts is not None:
            lanes = row_lanes(self.device, self._contacts.vertices.shape[0])
            wp.launch(_add_contact_diagonal, dim=lanes, device=self.device,
                      inputs=[self._contacts, self.model.vertices.kind, self.contact_coefficients,
                              self.model.vertex_count, lanes], outputs=[out])

    def contact_blocks(self) -> np.ndarray:
        """(contact capacity, 3, 3) float32 block K of every contact slot of the last :meth:`assemble`
        (its 16 blocks are ``w_a w_b K``; zero for an unused or separated slot) [kg]; (0, 3, 3) without
        contacts. For tests and debugging; a sync point.

        Allocates: yes. Capture-safe: no.
        """
        if self._contacts is None:
            return np.zeros((0, 3, 3), np.float32)
        blocks = wp.zeros(self._contacts.vertices.shape[0], dtype=wp.mat33, device=self.device)
        wp.launch(_write_contact_blocks, dim=blocks.shape[0], device=self.device,
                  inputs=[self._contacts, self.contact_coefficients], outputs=[blocks])
        return blocks.numpy()

    def dense(self) -> np.ndarray:
        """The whole system matrix A on the host, (3n, 3n) float64 (for tests and debugging). A sync point.

        Allocates: yes. Capture-safe: no.
        """
        n = self.model.vertex_count
        matrix = self.matrix
        nnz = matrix.nnz_sync()
        offsets = matrix.offsets.numpy()
        rows = np.repeat(np.arange(n), np.diff(offsets[: n + 1]))
        dense = np.zeros((n, 3, n, 3))
        np.add.at(dense, (rows, slice(None), matrix.columns.numpy()[:nnz]),
                  matrix.values.numpy()[:nnz].astype(np.float64))
        free = self.model.vertices.kind.numpy() == VERTEX_FREE
        if self._stitches is not None:
            ids = self.model.stitch_vertices.numpy()
            weights = self.model.stitch_weights.numpy().astype(np.float64)
            alpha = self.stitch_coefficients.numpy()[:, 0].astype(np.float64)
            for c in range(self.model.stitch_count):
                for a in range(4):
                    for b in range(4):
                        if free[ids[c, a]] and free[ids[c, b]]:
                            dense[ids[c, a], :, ids[c, b], :] += weights[c, a] * weights[c, b] * alpha[c] * np.eye(3)
        if self._contacts is not None:
            contacts = self._contacts
            used = min(int(contacts.count.numpy()[0]), contacts.vertices.shape[0])
            ids = contacts.vertices.numpy()[:used]
            weights = contacts.weights.numpy()[:used].astype(np.float64)
            blocks = self.contact_blocks()[:used].astype(np.float64)
            for c in range(used):
                if np.any(ids[c] < 0) or np.any(ids[c] >= n):
                    continue
                for a in range(4):
                    for b in range(4):
                        if free[ids[c, a]] and free[ids[c, b]]:
                            dense[ids[c, a], :, ids[c, b], :] += weights[c, a] * weights[c, b] * blocks[c]
        return dense.reshape(3 * n, 3 * n)

    def missing_blocks(self) -> int:
        """Element blocks that found no slot of the fixed pattern since the start (always 0 unless a
        kernel writes outside its element). A sync point.

        Allocates: no. Capture-safe: no.
        """
        return int(self._missing.numpy()[0])

    def _build_pattern(self) -> None:
        """Allocate :attr:`matrix` with every diagonal block and every (a, b) pair of a face or hinge."""
        n = self.model.vertex_count
        pairs = [np.stack([np.arange(n), np.arange(n)], axis=1)]
        for elements in (self.model.faces.indices, self.model.hinges.indices):
            if elements is None or elements.shape[0] == 0:
                continue
            ids = elements.numpy().astype(np.int64)
            k = ids.shape[1]
            pairs.append(np.stack([np.repeat(ids, k, axis=1).ravel(), np.tile(ids, (1, k)).ravel()], axis=1))
        keys = np.unique(np.concatenate(pairs)[:, 0] * n + np.concatenate(pairs)[:, 1])
        rows = wp.array((keys // n).astype(np.int32), dtype=wp.int32, device=self.device)
        cols = wp.array((keys % n).astype(np.int32), dtype=wp.int32, device=self.device)
        ones = wp.array(np.tile(np.eye(3, dtype=np.float32), (keys.size, 1, 1)), dtype=wp.mat33, device=self.device)
        bsr_set_from_triplets(self.matrix, rows, cols, ones, prune_numerical_zeros=False)
        nnz = self.matrix.nnz_sync()
        offsets = self.matrix.offsets.numpy()
        columns = self.matrix.columns.numpy()[:nnz]
        built = np.repeat(np.arange(n, dtype=np.int64), np.diff(offsets[: n + 1])) * n + columns
        if nnz != keys.size or not np.array_equal(built, keys):
            raise RuntimeError("the BSR build did not keep the element pattern sorted by (row, column)")
