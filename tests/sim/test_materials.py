"""Float32 material functions against float64 NumPy energies and their finite differences.

The reference energies below are written independently of the device code (directly from the
formulas in :mod:`pscc.sim.materials`). Gradients are checked against central differences of the
float64 energy; Hessians against central differences of the float64 gradient where the device
Hessian is exact (stretched membrane, hinge at its rest angle) and for positive semi-definiteness
everywhere.
"""

from __future__ import annotations

import numpy as np
import pytest
import warp as wp

from pscc.sim import materials as mat

STIFFNESS = np.array([1000.0, 800.0, 150.0, 300.0])  # k_uu, k_vv, k_uv, k_shear


# ------------------------------------------------------------------------------------------------
# Float64 references
# ------------------------------------------------------------------------------------------------


def membrane_energy_np(x: np.ndarray, inv_rest: np.ndarray, area: float, k: np.ndarray) -> float:
    ds = np.stack([x[1] - x[0], x[2] - x[0]], axis=1)  # 3x2
    f = ds @ inv_rest
    g = 0.5 * (f.T @ f - np.eye(2))
    return 0.5 * area * (k[0] * g[0, 0] ** 2 + k[1] * g[1, 1] ** 2 + 2 * k[2] * g[0, 0] * g[1, 1]
                         + k[3] * g[0, 1] ** 2)


def dihedral_np(x: np.ndarray) -> float:
    e = x[1] - x[0]
    n_a = np.cross(e, x[2] - x[0])
    n_b = np.cross(x[3] - x[1], e)
    cos = np.dot(n_a, n_b) / (np.linalg.norm(n_a) * np.linalg.norm(n_b))
    sin = np.dot(np.cross(n_a, n_b), e) / (np.linalg.norm(n_a) * np.linalg.norm(n_b) * np.linalg.norm(e))
    return float(np.arctan2(sin, cos))


def bending_energy_np(x: np.ndarray, rest_angle: float, k: float) -> float:
    delta = dihedral_np(x) - rest_angle
    delta = (delta + np.pi) % (2 * np.pi) - np.pi
    return 0.5 * k * delta**2


def fd_gradient(energy, x: np.ndarray, step: float) -> np.ndarray:
    grad = np.zeros_like(x)
    for index in np.ndindex(*x.shape):
        xp, xm = x.copy(), x.copy()
        xp[index] += step
        xm[index] -= step
        grad[index] = (energy(xp) - energy(xm)) / (2 * step)
    return grad


def fd_hessian(gradient, x: np.ndarray, step: float) -> np.ndarray:
    k = x.size
    hess = np.zeros((k, k))
    for col in range(k):
        xp, xm = x.copy().reshape(-1), x.copy().reshape(-1)
        xp[col] += step
        xm[col] -= step
        hess[:, col] = (gradient(xp.reshape(x.shape)) - gradient(xm.reshape(x.shape))).reshape(-1) / (2 * step)
    return hess


# ------------------------------------------------------------------------------------------------
# Device wrappers
# ------------------------------------------------------------------------------------------------


@wp.kernel
def _evaluate_membrane(
    # in:
    x: wp.array2d(dtype=wp.vec3),
    inv_rest: wp.array(dtype=wp.mat22),
    area: wp.array(dtype=float),
    stiffness: wp.vec4,
    # out:
    energy: wp.array(dtype=float),
    gradient: wp.array2d(dtype=wp.vec3),
    hessian: wp.array3d(dtype=wp.mat33),
):
    """One thread per triangle: energy, gradient and (clamped) Hessian blocks."""
    t = wp.tid()
    f0, f1 = mat.membrane_deformation(x[t, 0], x[t, 1], x[t, 2], inv_rest[t])
    stress = mat.membrane_stress(mat.green_strain(f0, f1), stiffness)
    clamped = mat.membrane_clamped_stress(stress)
    energy[t] = mat.membrane_energy(x[t, 0], x[t, 1], x[t, 2], inv_rest[t], area[t], stiffness)
    for a in range(3):
        shape_a = mat.membrane_shape_vector(inv_rest[t], a)
        gradient[t, a] = mat.membrane_gradient(f0, f1, shape_a, stress, area[t])
        for b in range(3):
            shape_b = mat.membrane_shape_vector(inv_rest[t], b)
            block = mat.membrane_gauss_newton_block(f0, f1, shape_a, shape_b, stiffness, area[t])
            geometric = mat.membrane_geometric_coefficient(shape_a, shape_b, clamped, area[t])
            hessian[t, a, b] = block + wp.identity(n=3, dtype=float) * geometric


@wp.kernel
def _evaluate_hinge(
    # in:
    x: wp.array2d(dtype=wp.vec3),
    rest_angle: wp.array(dtype=float),
    stiffness: float,
    # out:
    angle: wp.array(dtype=float),
    energy: wp.array(dtype=float),
    gradient: wp.array2d(dtype=wp.vec3),
):
    """One thread per hinge: dihedral angle, bending energy and its gradient."""
    h = wp.tid()
    theta = mat.dihedral_angle(x[h, 0], x[h, 1], x[h, 2], x[h, 3])
    angle[h] = theta
    energy[h] = mat.bending_energy(x[h, 0], x[h, 1], x[h, 2], x[h, 3], rest_angle[h], stiffness)
    g = mat.dihedral_angle_gradient(x[h, 0], x[h, 1], x[h, 2], x[h, 3])
    delta = mat.wrap_angle(theta - rest_angle[h])
    for a in range(4):
        gradient[h, a] = stiffness * delta * g[a]


def run_membrane(device: str, x: np.ndarray, inv_rest: np.ndarray, area: np.ndarray):
    k = x.shape[0]
    energy = wp.zeros(k, dtype=float, device=device)
    gradient = wp.zeros((k, 3), dtype=wp.vec3, device=device)
    hessian = wp.zeros((k, 3, 3), dtype=wp.mat33, device=device)
    wp.launch(_evaluate_membrane, dim=k, device=device,
              inputs=[wp.array(x.astype(np.float32), dtype=wp.vec3, device=device),
                      wp.array(inv_rest.astype(np.float32), dtype=wp.mat22, device=device),
                      wp.array(area.astype(np.float32), dtype=float, device=device),
                      wp.vec4(*STIFFNESS.astype(np.float32))],
              outputs=[energy, gradient, hessian])
    hess = hessian.numpy().transpose(0, 1, 3, 2, 4).reshape(k, 9, 9)
    return energy.numpy(), gradient.numpy(), hess


def random_triangles(rng: np.random.Generator, count: int, skinny: bool = False,
                     stretch_range: tuple[float, float] = (0.8, 1.3), max_shear: float = 0.2):
    """Rest triangles in 2-D plus deformed 3-D positions (rotated, stretched, sheared, noisy)."""
    rest = rng.normal(size=(count, 3, 2)) * 0.05
    if skinny:  # aspect ratio ~ 1 : 500
        rest = np.zeros((count, 3, 2))
        rest[:, 1, 0] = 0.05
        rest[:, 2, 0] = rng.uniform(0.01, 0.04, size=count)
        rest[:, 2, 1] = 1.0e-4 * rng.choice([-1.0, 1.0], size=count)
    dm = np.stack([rest[:, 1] - rest[:, 0], rest[:, 2] - rest[:, 0]], axis=2)
    inv_rest = np.linalg.inv(dm)
    area = 0.5 * np.abs(np.linalg.det(dm))
    x = np.zeros((count, 3, 3))
    for t in range(count):
        q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
        stretch = np.diag(rng.uniform(*stretch_range, size=2))
        shear = np.array([[1.0, rng.uniform(-max_shear, max_shear)], [0.0, 1.0]])
        planar = rest[t] @ (stretch @ shear).T
        x[t] = np.concatenate([planar, np.zeros((3, 1))], axis=1) @ q.T + rng.normal(size=3)
        x[t] += rng.normal(size=(3, 3)) * 0.002  # small out-of-plane noise
    return x, inv_rest, area


# ------------------------------------------------------------------------------------------------
# Membrane
# ------------------------------------------------------------------------------------------------


@pytest.mark.parametrize("skinny", [False, True], ids=["random", "skinny"])
def test_membrane_gradient_matches_finite_differences(device: str, skinny: bool) -> None:
    rng = np.random.default_rng(7 if skinny else 3)
    x, inv_rest, area = random_triangles(rng, 24, skinny=skinny)
    energy, gradient, _ = run_membrane(device, x, inv_rest, area)
    for t in range(x.shape[0]):
        def e(y, t=t):
            return membrane_energy_np(y, inv_rest[t], area[t], STIFFNESS)
        ref_energy = e(x[t])
        ref_grad = fd_gradient(e, x[t], 1e-7)
        assert energy[t] == pytest.approx(ref_energy, rel=2e-3, abs=1e-9)
        scale = np.abs(ref_grad).max()
        assert scale > 0.0
        assert np.abs(gradient[t] - ref_grad).max() <= 2e-3 * scale, f"triangle {t}"


def test_membrane_hessian_is_exact_under_tension_and_psd_otherwise(device: str) -> None:
    rng = np.random.default_rng(11)
    # First half stretched by 10-30 % along both material axes (both principal stresses > 0): the
    # Hessian is exact. Second half compressed to 60-90 %: the geometric term must be clamped.
    x_t, inv_t, area_t = random_triangles(rng, 12, stretch_range=(1.1, 1.3), max_shear=0.0)
    x_c, inv_c, area_c = random_triangles(rng, 12, stretch_range=(0.6, 0.9))
    x, inv_rest, area = np.concatenate([x_t, x_c]), np.concatenate([inv_t, inv_c]), np.concatenate([area_t, area_c])
    _, _, hessian = run_membrane(device, x, inv_rest, area)
    indefinite = 0
    for t in range(24):
        def grad(y, t=t):
            return fd_gradient(lambda z: membrane_energy_np(z, inv_rest[t], area[t], STIFFNESS), y, 1e-7)
        scale = np.abs(hessian[t]).max()
        assert np.abs(hessian[t] - hessian[t].T).max() <= 1e-5 * scale
        assert np.linalg.eigvalsh(hessian[t].astype(np.float64)).min() >= -1e-4 * scale, f"triangle {t} not PSD"
        ref = fd_hessian(grad, x[t], 1e-5)
        if t < 12:
            assert np.abs(hessian[t] - ref).max() <= 5e-3 * np.abs(ref).max(), f"triangle {t}"
        else:
            indefinite += int(np.linalg.eigvalsh(0.5 * (ref + ref.T)).min() < -1e-3 * np.abs(ref).max())
    # Under compression the exact Hessian is indefinite: the clamping is what makes the blocks PSD.
    assert indefinite >= 6


def test_membrane_energy_is_zero_at_rest_and_invariant_to_rotation(device: str) -> None:
    rng = np.random.default_rng(5)
    rest = rng.normal(size=(8, 3, 2)) * 0.1
    dm = np.stack([rest[:, 1] - rest[:, 0], rest[:, 2] - rest[:, 0]], axis=2)
    x = np.concatenate([rest, np.zeros((8, 3, 1))], axis=2)
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    rotated = x @ q.T + 1.0
    energy, gradient, _ = run_membrane(device, np.concatenate([x, rotated]), np.tile(np.linalg.inv(dm), (2, 1, 1)),
                                       np.tile(0.5 * np.abs(np.linalg.det(dm)), 2))
    assert np.abs(energy).max() < 1e-9
    assert np.abs(gradient).max() < 1e-3  # N, for k ~ 1e3 N/m and float32 rest strain ~1e-7


# ------------------------------------------------------------------------------------------------
# Bending
# ------------------------------------------------------------------------------------------------


def random_hinges(rng: np.random.Generator, count: int, angle_range: tuple[float, float]) -> np.ndarray:
    """Hinges with edge along a random axis and wings at a controlled dihedral angle."""
    hinges = np.zeros((count, 4, 3))
    for h in range(count):
        length = rng.uniform(0.02, 0.1)
        x0 = np.zeros(3)
        x1 = np.array([length, 0.0, 0.0])
        a_t, b_t = rng.uniform(-0.3, 1.3, size=2)
        wing_a = rng.uniform(0.3, 1.0) * length
        wing_b = rng.uniform(0.3, 1.0) * length
        theta = rng.uniform(*angle_range) * rng.choice([-1.0, 1.0])
        x2 = np.array([a_t * length, wing_a, 0.0])
        # Rotate the second wing about the edge so the dihedral angle is theta.
        direction = np.array([0.0, -np.cos(theta), -np.sin(theta)])
        x3 = np.array([b_t * length, 0.0, 0.0]) + wing_b * direction
        q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
        hinges[h] = np.stack([x0, x1, x2, x3]) @ q.T + rng.normal(size=3)
    return hinges


@pytest.mark.parametrize("angles", [(0.05, 2.5), (1e-4, 1e-3), (2.9, 3.1)], ids=["random", "nearly-flat", "folded"])
def test_bending_gradient_matches_finite_differences(device: str, angles: tuple[float, float]) -> None:
    rng = np.random.default_rng(int(angles[0] * 1e4) + 1)
    x = random_hinges(rng, 20, angles)
    rest = rng.uniform(-0.5, 0.5, size=20)
    stiffness = 2.0e-4
    k = x.shape[0]
    out_angle = wp.zeros(k, dtype=float, device=device)
    out_energy = wp.zeros(k, dtype=float, device=device)
    out_grad = wp.zeros((k, 4), dtype=wp.vec3, device=device)
    wp.launch(_evaluate_hinge, dim=k, device=device,
              inputs=[wp.array(x.astype(np.float32), dtype=wp.vec3, device=device),
                      wp.array(rest.astype(np.float32), dtype=float, device=device), stiffness],
              outputs=[out_angle, out_energy, out_grad])
    angle, energy, gradient = out_angle.numpy(), out_energy.numpy(), out_grad.numpy()
    for h in range(k):
        ref_angle = dihedral_np(x[h])
        assert abs(np.angle(np.exp(1j * (angle[h] - ref_angle)))) < 1e-4
        assert abs(abs(ref_angle) - np.mean(angles)) <= (angles[1] - angles[0]) / 2 + 1e-9  # the construction
        ref_energy = bending_energy_np(x[h], rest[h], stiffness)
        assert energy[h] == pytest.approx(ref_energy, rel=1e-3, abs=1e-12)
        ref_grad = fd_gradient(lambda y, h=h: bending_energy_np(y, rest[h], stiffness), x[h], 1e-7)
        scale = np.abs(ref_grad).max()
        assert np.abs(gradient[h] - ref_grad).max() <= 2e-3 * scale + 1e-9, f"hinge {h}"
        assert np.abs(gradient[h].sum(axis=0)).max() <= 1e-4 * scale + 1e-9  # translation invariance


def test_bending_gauss_newton_hessian_is_exact_at_rest_angle() -> None:
    rng = np.random.default_rng(2)
    x = random_hinges(rng, 5, (0.2, 1.5))
    stiffness = 1.0e-4
    for h in range(5):
        rest = dihedral_np(x[h])

        def grad(y, h=h, rest=rest):
            return fd_gradient(lambda z: bending_energy_np(z, rest, stiffness), y, 1e-6)

        ref = fd_hessian(grad, x[h], 1e-4)
        g = fd_gradient(dihedral_np, x[h], 1e-7).reshape(-1)
        gauss_newton = stiffness * np.outer(g, g)  # what the assembly uses, from the exact gradient
        assert np.abs(gauss_newton - ref).max() <= 1e-3 * np.abs(ref).max()
