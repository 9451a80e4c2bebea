"""Device functions of the cloth material model: membrane (Green strain) and dihedral-angle bending.

Membrane, per triangle (x0, x1, x2) with inverse material matrix ``Dm^-1`` (2x2) and rest area A:

* deformation gradient ``F = [x1 - x0, x2 - x0] Dm^-1 = sum_i x_i d_i^T`` (3x2, columns f0 and f1),
  where the shape vectors are ``d1 = row 0 of Dm^-1``, ``d2 = row 1`` and ``d0 = -(d1 + d2)``;
* Green strain ``g = (G00, G11, G01) = (|f0|^2 - 1, |f1|^2 - 1, f0 . f1) / 2``;
* energy ``E = A / 2 g^T C g`` with ``C = [[k_uu, k_uv, 0], [k_uv, k_vv, 0], [0, 0, k_shear]]``
  (``stiffness`` is the vec4 ``(k_uu, k_vv, k_uv, k_shear)``);
* stress ``sigma = C g`` and the 2x2 second Piola-Kirchhoff-like tensor
  ``P = [[sigma0, sigma2 / 2], [sigma2 / 2, sigma1]]``; gradient ``dE/dx_i = A F P d_i``;
* exact Hessian ``d2E/dx_i dx_j = A B_i^T C B_j + A (d_i^T P d_j) I3``, where the rows of the 3x3
  strain Jacobian ``B_i = dg/dx_i`` are ``d_i.x f0``, ``d_i.y f1`` and ``(d_i.x f1 + d_i.y f0) / 2``.
  The first (Gauss-Newton) term is PSD whenever C is. The second (geometric, "stress") term is made
  PSD by clamping the negative eigenvalue(s) of P to zero (:func:`membrane_clamped_stress`): the
  approximation is exact under tension and drops the destabilising part under compression.

Bending, per interior edge (hinge) with edge vertices x0, x1 and opposite vertices x2 (in the face
that lists x0 -> x1 counter-clockwise) and x3 (in the other face):

* normals ``nA = e x (x2 - x0)``, ``nB = (x3 - x1) x e`` with ``e = x1 - x0``; the signed dihedral
  angle ``theta = atan2((nA^ x nB^) . e^, nA^ . nB^)`` is 0 for a flat hinge;
* energy ``E = k / 2 (theta - theta_rest)^2`` with ``k = bending * 3 |e_rest|^2 / (A1 + A2)``;
* gradient (Bridson et al. 2003): ``dtheta/dx2 = -|e| nA / |nA|^2``, ``dtheta/dx3 = -|e| nB / |nB|^2``,
  ``dtheta/dx0 = (t2 - 1) dtheta/dx2 + (t3 - 1) dtheta/dx3``, ``dtheta/dx1 = -t2 dtheta/dx2 - t3 dtheta/dx3``
  with ``t_k = (x_k - x0) . e / |e|^2``;
* Hessian: Gauss-Newton ``k grad(theta) grad(theta)^T`` (PSD; the curvature term
  ``k (theta - theta_rest) d2theta`` is dropped).

All functions are float32; the tests compare them against float64 NumPy finite differences.
"""

from __future__ import annotations

import warp as wp

wp.set_module_options({"enable_backward": False})

mat43 = wp.types.matrix(shape=(4, 3), dtype=wp.float32)
"""4x3 float32 matrix type: one vec3 row per hinge vertex (gradients of the dihedral angle)."""


# --------------------------------------------------------------------------------------------------
# Membrane
# --------------------------------------------------------------------------------------------------


@wp.func
def membrane_shape_vector(inv_rest: wp.mat22, corner: int) -> wp.vec2:
    """Shape vector d_corner of a triangle: ``F = sum_i x_i d_i^T`` (corner 0, 1 or 2)."""
    d1 = wp.vec2(inv_rest[0, 0], inv_rest[0, 1])
    d2 = wp.vec2(inv_rest[1, 0], inv_rest[1, 1])
    if corner == 1:
        return d1
    if corner == 2:
        return d2
    return -(d1 + d2)


@wp.func
def membrane_deformation(x0: wp.vec3, x1: wp.vec3, x2: wp.vec3, inv_rest: wp.mat22) -> tuple[wp.vec3, wp.vec3]:
    """Columns (f0, f1) of the deformation gradient ``F = [x1 - x0, x2 - x0] Dm^-1``."""
    e1 = x1 - x0
    e2 = x2 - x0
    f0 = e1 * inv_rest[0, 0] + e2 * inv_rest[1, 0]
    f1 = e1 * inv_rest[0, 1] + e2 * inv_rest[1, 1]
    return f0, f1


@wp.func
def green_strain(f0: wp.vec3, f1: wp.vec3) -> wp.vec3:
    """Green strain components (G00, G11, G01) of ``F = [f0 f1]``."""
    return wp.vec3(0.5 * (wp.dot(f0, f0) - 1.0), 0.5 * (wp.dot(f1, f1) - 1.0), 0.5 * wp.dot(f0, f1))


@wp.func
def membrane_stress(strain: wp.vec3, stiffness: wp.vec4) -> wp.vec3:
    """``sigma = C g`` for stiffness ``(k_uu, k_vv, k_uv, k_shear)`` [N/m]."""
    return wp.vec3(
        stiffness[0] * strain[0] + stiffness[2] * strain[1],
        stiffness[2] * strain[0] + stiffness[1] * strain[1],
        stiffness[3] * strain[2],
    )


@wp.func
def membrane_energy(x0: wp.vec3, x1: wp.vec3, x2: wp.vec3, inv_rest: wp.mat22, area: float,
                    stiffness: wp.vec4) -> float:
    """Membrane energy ``A / 2 g^T C g`` of one triangle [J]."""
    f0, f1 = membrane_deformation(x0, x1, x2, inv_rest)
    strain = green_strain(f0, f1)
    return 0.5 * area * wp.dot(strain, membrane_stress(strain, stiffness))


@wp.func
def membrane_stress_tensor(stress: wp.vec3) -> wp.mat22:
    """The symmetric 2x2 tensor P with ``dE/dx_i = A F P d_i``."""
    return wp.mat22(stress[0], 0.5 * stress[2], 0.5 * stress[2], stress[1])


@wp.func
def membrane_clamped_stress(stress: wp.vec3) -> wp.mat22:
    """P with its negative eigenvalues set to zero (the PSD part used in the geometric stiffness)."""
    p = membrane_stress_tensor(stress)
    mean = 0.5 * (p[0, 0] + p[1, 1])
    half_gap = 0.5 * (p[0, 0] - p[1, 1])
    radius = wp.sqrt(half_gap * half_gap + p[0, 1] * p[0, 1])
    high = mean + radius
    low = mean - radius
    if low >= 0.0:
        return p
    if high <= 0.0:
        return wp.mat22(0.0, 0.0, 0.0, 0.0)
    # One positive eigenvalue: P - low I = (high - low) v v^T, so high v v^T = (P - low I) high / (high - low).
    shifted = p - wp.mat22(low, 0.0, 0.0, low)
    return shifted * (high / (high - low))


@wp.func
def membrane_gradient(f0: wp.vec3, f1: wp.vec3, shape: wp.vec2, stress: wp.vec3, area: float) -> wp.vec3:
    """``dE/dx_i = A F P d_i`` for the corner with shape vector ``shape`` [N]."""
    p = membrane_stress_tensor(stress)
    pd = p * shape
    return area * (f0 * pd[0] + f1 * pd[1])


@wp.func
def membrane_strain_jacobian(f0: wp.vec3, f1: wp.vec3, shape: wp.vec2) -> wp.mat33:
    """``B_i = dg/dx_i``: row k is the gradient of strain component k with respect to x_i."""
    return wp.matrix_from_rows(shape[0] * f0, shape[1] * f1, 0.5 * (shape[0] * f1 + shape[1] * f0))


@wp.func
def membrane_gauss_newton_block(f0: wp.vec3, f1: wp.vec3, shape_i: wp.vec2, shape_j: wp.vec2,
                                stiffness: wp.vec4, area: float) -> wp.mat33:
    """Gauss-Newton Hessian block ``A B_i^T C B_j`` [N/m] (PSD when C is)."""
    c = wp.mat33(stiffness[0], stiffness[2], 0.0, stiffness[2], stiffness[1], 0.0, 0.0, 0.0, stiffness[3])
    b_i = membrane_strain_jacobian(f0, f1, shape_i)
    b_j = membrane_strain_jacobian(f0, f1, shape_j)
    return area * (wp.transpose(b_i) * (c * b_j))


@wp.func
def membrane_geometric_coefficient(shape_i: wp.vec2, shape_j: wp.vec2, clamped_stress: wp.mat22,
                                   area: float) -> float:
    """Geometric stiffness ``A d_i^T P+ d_j`` [N/m] (times the 3x3 identity)."""
    return area * wp.dot(shape_i, clamped_stress * shape_j)


# --------------------------------------------------------------------------------------------------
# Bending
# --------------------------------------------------------------------------------------------------


@wp.func
def dihedral_angle(x0: wp.vec3, x1: wp.vec3, x2: wp.vec3, x3: wp.vec3) -> float:
    """Signed dihedral angle of the hinge [rad], 0 when flat, in (-pi, pi]."""
    e = x1 - x0
    n_a = wp.cross(e, x2 - x0)
    n_b = wp.cross(x3 - x1, e)
    # atan2 is invariant to a common positive scale: both terms carry |nA| |nB| |e|.
    return wp.atan2(wp.dot(wp.cross(n_a, n_b), e), wp.dot(n_a, n_b) * wp.length(e))


@wp.func
def wrap_angle(angle: float) -> float:
    """``angle`` wrapped into [-pi, pi] (for differences of dihedral angles)."""
    two_pi = 2.0 * wp.pi
    return angle - two_pi * wp.round(angle / two_pi)


@wp.func
def bending_energy(x0: wp.vec3, x1: wp.vec3, x2: wp.vec3, x3: wp.vec3, rest_angle: float, stiffness: float) -> float:
    """Bending energy ``k / 2 (theta - theta_rest)^2`` [J] of one hinge (k includes the edge weight)."""
    delta = wrap_angle(dihedral_angle(x0, x1, x2, x3) - rest_angle)
    return 0.5 * stiffness * delta * delta


@wp.func
def hinge_is_degenerate(x0: wp.vec3, x1: wp.vec3, x2: wp.vec3, x3: wp.vec3, rest_length: float,
                        degeneracy_ratio: float) -> bool:
    """True when the edge is collapsed or a wing triangle is flat enough that theta is ill-defined."""
    e = x1 - x0
    length = wp.length(e)
    if length <= degeneracy_ratio * rest_length:
        return True
    limit = degeneracy_ratio * length * length
    return wp.length(wp.cross(e, x2 - x0)) <= limit or wp.length(wp.cross(x3 - x1, e)) <= limit


@wp.func
def dihedral_angle_gradient(x0: wp.vec3, x1: wp.vec3, x2: wp.vec3, x3: wp.vec3) -> mat43:
    """``dtheta/dx_k`` for k = 0..3 as the rows of a 4x3 matrix [1/m] (hinge must not be degenerate)."""
    e = x1 - x0
    length_sq = wp.dot(e, e)
    length = wp.sqrt(length_sq)
    n_a = wp.cross(e, x2 - x0)
    n_b = wp.cross(x3 - x1, e)
    g2 = n_a * (-length / wp.dot(n_a, n_a))
    g3 = n_b * (-length / wp.dot(n_b, n_b))
    t2 = wp.dot(x2 - x0, e) / length_sq
    t3 = wp.dot(x3 - x0, e) / length_sq
    g0 = (t2 - 1.0) * g2 + (t3 - 1.0) * g3
    g1 = -t2 * g2 - t3 * g3
    return wp.matrix_from_rows(g0, g1, g2, g3)
