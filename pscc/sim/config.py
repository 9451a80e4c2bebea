"""Configuration of the cloth simulator: material parameters and solver options.

Both classes are frozen dataclasses; :meth:`ClothMaterial.validate` and :meth:`SolverConfig.validate`
raise :class:`pscc.InputError` naming the field and the fix. Every field documents its unit.

The module also holds the simulator's numerical tolerances (``SIM_*`` constants). They are passed to
kernels as arguments; no kernel holds a literal epsilon.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields
from typing import Any

from pscc.errors import InputError
from pscc.tolerances import MAX_THICKNESS

SIM_HINGE_DEGENERACY_RATIO: float = 1.0e-6
"""A bending hinge whose current triangle height is below this fraction of its edge length (or whose
edge is shorter than this fraction of its rest length) gets no bending force in that step: the
dihedral angle and its gradient are undefined there. Dimensionless."""

SIM_MIN_REST_AREA_RATIO: float = 1.0e-8
"""A rest triangle with ``2 * area <= ratio * (longest rest edge)^2`` is rejected as degenerate
(its inverse material matrix would not exist). Dimensionless."""


MAX_PARAMETER = 1.0e12
"""Largest magnitude of a material or solver parameter: beyond it float32 products overflow."""

MAX_ACCELERATION = 1.0e5
"""Largest gravity component [m/s^2] (10,000 g; 9810 is gravity in millimetres per second squared)."""


def _number(owner: str, name: str, value: Any, limit: float = MAX_PARAMETER) -> float:
    try:
        number = float(value)
    except (TypeError, ValueError) as exc:
        raise InputError(owner, name, f"{value!r} is not a number", f"set {name} to a finite float") from exc
    if not math.isfinite(number):
        raise InputError(owner, name, f"{value!r} is not finite", f"set {name} to a finite float")
    if abs(number) > limit:
        raise InputError(owner, name, f"{value!r} is beyond +-{limit:g}, where float32 arithmetic overflows",
                         f"set {name} to a value of magnitude <= {limit:g}")
    return number


def _non_negative(owner: str, name: str, value: Any) -> float:
    number = _number(owner, name, value)
    if number < 0.0:
        raise InputError(owner, name, f"{value!r} is negative", f"set {name} to a value >= 0")
    return number


def _positive(owner: str, name: str, value: Any) -> float:
    number = _number(owner, name, value)
    if number <= 0.0:
        raise InputError(owner, name, f"{value!r} is not > 0", f"set {name} to a value > 0")
    return number


def _vector3(owner: str, name: str, value: Any, limit: float = MAX_PARAMETER) -> tuple[float, float, float]:
    try:
        items = tuple(value)
    except TypeError as exc:
        raise InputError(owner, name, f"{value!r} is not a 3-tuple", f"set {name} to (x, y, z)") from exc
    if len(items) != 3:
        raise InputError(owner, name, f"{value!r} has {len(items)} components", f"set {name} to (x, y, z)")
    return tuple(_number(owner, f"{name}[{i}]", item, limit)  # type: ignore[return-value]
                 for i, item in enumerate(items))


@dataclass(frozen=True)
class ClothMaterial:
    """Physical parameters of one cloth object.

    Membrane: the anisotropic Green-strain energy of the ARCSim / Wang et al. 2011 model with constant
    coefficients, per triangle of rest area A and Green strain G (2x2, material axes u and v),

        E = A / 2 (k_uu G00^2 + k_vv G11^2 + 2 k_uv G00 G11 + k_shear G01^2),

    which is convex in G when ``stretch_uv^2 <= stretch_u * stretch_v``. Bending: the dihedral-angle
    energy E = bending / 2 * 3 |e|^2 / (A1 + A2) * (theta - theta_rest)^2 per interior edge e.

    The defaults are cotton-like: a 1 m x 1 m sheet pinned at two corners stretches by a few percent
    at most under gravity.
    """

    density: float = 0.187
    """Areal mass density [kg/m^2] (ARCSim's gray-interlock cotton/polyester)."""
    stretch_u: float = 1000.0
    """k_uu: stiffness of the strain along the material u axis [N/m]."""
    stretch_v: float = 1000.0
    """k_vv: stiffness of the strain along the material v axis [N/m]."""
    stretch_uv: float = 100.0
    """k_uv: coupling of the u and v strains (a Poisson-like effect) [N/m]; |k_uv| <= sqrt(k_uu k_vv)."""
    shear: float = 300.0
    """k_shear: stiffness of the in-plane shear strain G01 [N/m]."""
    bending: float = 5.0e-5
    """Dihedral-angle bending stiffness [N m] (energy per squared radian, before the edge weight)."""
    stretch_damping: float = 1.0e-3
    """Stiffness-proportional (Rayleigh) damping of the membrane [s]: the damping force is
    ``-stretch_damping * H_membrane * v`` with the Gauss-Newton part of the membrane Hessian, so it
    damps strain rates only (rigid motion is not damped)."""
    bending_damping: float = 1.0e-2
    """Stiffness-proportional (Rayleigh) damping of bending [s]: damping force
    ``-bending_damping * H_bending * v`` (damps the dihedral angle rate only)."""
    thickness: float = 0.002
    """Cloth thickness [m]: the proximity distance h that contacts keep between surfaces."""
    friction: float = 0.3
    """Coulomb friction coefficient (dimensionless) of this material's surface."""

    def validate(self) -> ClothMaterial:
        """Check every field; return ``self`` so calls can be chained.

        Raises:
            InputError: a field is not a finite number in its range, or the membrane energy is not
                convex (``stretch_uv^2 > stretch_u * stretch_v``).
        """
        owner = "ClothMaterial"
        _positive(owner, "density", self.density)
        for name in ("stretch_u", "stretch_v", "shear", "bending", "stretch_damping", "bending_damping",
                     "thickness", "friction"):
            _non_negative(owner, name, getattr(self, name))
        if self.thickness > MAX_THICKNESS:
            raise InputError(owner, "thickness", f"{self.thickness!r} exceeds {MAX_THICKNESS:g}",
                             "give the cloth thickness in the units of the positions, e.g. 0.002 (metres)")
        coupling = _number(owner, "stretch_uv", self.stretch_uv)
        if coupling * coupling > self.stretch_u * self.stretch_v:
            raise InputError(owner, "stretch_uv",
                             f"|{coupling}| exceeds sqrt(stretch_u * stretch_v) = "
                             f"{math.sqrt(self.stretch_u * self.stretch_v):.6g}, so the membrane energy is not convex",
                             "reduce |stretch_uv| or raise stretch_u / stretch_v")
        return self


PRECONDITIONERS: tuple[str, ...] = ("block_jacobi", "diag", "none")
"""Accepted values of :attr:`SolverConfig.preconditioner`."""


@dataclass(frozen=True)
class SolverConfig:
    """Options of the implicit integrator (:class:`pscc.sim.ImplicitEuler`)."""

    gravity: tuple[float, float, float] = (0.0, 0.0, -9.81)
    """Gravitational acceleration [m/s^2]."""
    wind: tuple[float, float, float] = (0.0, 0.0, 0.0)
    """Velocity of the air [m/s] (used by the air drag)."""
    air_drag: float = 0.0
    """Normal air drag [kg/(m^2 s)]: each face of current area a and unit normal n applies
    ``f = -air_drag * a / 3 * ((v_i - wind) . n) n`` to each of its vertices i. Only the normal
    component of the relative velocity is resisted (a sheet sliding in its own plane feels no drag).
    The velocity dependence is integrated implicitly; the dependence on n and a is not."""
    cg_tolerance: float = 1.0e-3
    """Relative residual at which conjugate gradients stop: ``|b - A dv| <= cg_tolerance * |b|``."""
    cg_max_iterations: int = 500
    """Hard cap on conjugate-gradient iterations per step (rounded up to a multiple of cg_check_every)."""
    cg_check_every: int = 10
    """Iterations between convergence tests, which run on the device (run eagerly, each reads one integer
    back: a device sync on CUDA); the reported iteration count is a multiple of it unless the solve
    converged at the start."""
    cg_warm_start: bool = True
    """Start CG from the previous step's dv (free vertices) instead of 0; saves iterations in smooth motion."""
    preconditioner: str = "block_jacobi"
    """``"block_jacobi"`` (inverse of each 3x3 diagonal block), ``"diag"`` (scalar Jacobi) or ``"none"``."""
    contact_stiffness: float | None = None
    """Contact spring stiffness k_c [N/m]. ``None`` chooses it per contact and per step as
    ``contact_stiffness_scale * m_eff / dt^2``, where ``m_eff = 1 / sum_i(w_i^2 / m_i)`` is the
    effective mass of the contact (scripted vertices count as infinitely heavy). With the scale 1 an
    isolated contact closes half of its penetration in one implicit step, independently of the mesh
    resolution and the time step."""
    contact_stiffness_scale: float = 1.0
    """Multiplier of the automatic contact stiffness (dimensionless); ignored when
    ``contact_stiffness`` is set."""
    start_gap_relax_time: float = 0.3
    """Surfaces that start closer than the thickness (a garment draped onto a body, layers pressed together)
    are eased apart over this time [s]: their contact springs keep the start distance at first and open it
    to the thickness at ``thickness / start_gap_relax_time``, instead of pushing the whole deficit out in
    a step or two (which made the outer of two pressed layers fly off by about 2 thicknesses)."""
    stitch_stiffness_scale: float = 1000.0
    """Stiffness of the stitch springs (seams), a multiple of ``m_eff / dt^2`` like the automatic contact
    stiffness (dimensionless). A seam carries what hangs from it and what pulls on it, and on a fine mesh a
    stitch's own vertices are light: at 10, the example skirt at 20K triangles left its hem corners' seams
    open by up to 4.9 thicknesses; at 100 the trouser leg of ``kungfu`` (5K) opened its inseam by 5.5
    thicknesses when the knee bent 85 degrees; at 1000 it stays within 0.25, for 12 % more CG iterations."""
    sewing_speed: float = 0.5
    """Fastest a stitch pulls its seam closed [m/s]: the offset a stitch's force sees is clamped to
    ``sewing_speed x dt``, so seams that start open (pieces laid out around a body) close over a few
    frames instead of snapping shut in one step."""
    friction_velocity_epsilon: float = 1.0e-3
    """eps_v [m/s]: below this tangential speed, Coulomb friction (coefficient
    ``mu |f_n| / max(|v_t|, eps_v)``) turns into a stiff viscous damper that approximates sticking.
    Smaller values stick harder; at 1e-3 m/s and dt = 5 ms, stuck vertices creep < 5 um per step."""

    def validate(self) -> SolverConfig:
        """Check every field; return ``self`` so calls can be chained.

        Raises:
            InputError: a field is out of range or of the wrong kind.
        """
        owner = "SolverConfig"
        _vector3(owner, "gravity", self.gravity, MAX_ACCELERATION)
        _vector3(owner, "wind", self.wind, MAX_ACCELERATION)
        _non_negative(owner, "air_drag", self.air_drag)
        tolerance = _positive(owner, "cg_tolerance", self.cg_tolerance)
        if tolerance >= 1.0:
            raise InputError(owner, "cg_tolerance", f"{tolerance!r} is not < 1",
                             "set cg_tolerance to a relative residual such as 1e-3")
        for name in ("cg_max_iterations", "cg_check_every"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                raise InputError(owner, name, f"{value!r} is not an integer >= 1", f"set {name} to an integer >= 1")
        if not isinstance(self.cg_warm_start, bool):
            raise InputError(owner, "cg_warm_start", f"{self.cg_warm_start!r} is not a bool", "set True or False")
        if self.preconditioner not in PRECONDITIONERS:
            raise InputError(owner, "preconditioner", f"{self.preconditioner!r} is not one of {PRECONDITIONERS}",
                             "use 'block_jacobi' (the default)")
        if self.contact_stiffness is not None:
            _positive(owner, "contact_stiffness", self.contact_stiffness)
        _positive(owner, "contact_stiffness_scale", self.contact_stiffness_scale)
        _positive(owner, "friction_velocity_epsilon", self.friction_velocity_epsilon)
        _positive(owner, "start_gap_relax_time", self.start_gap_relax_time)
        _positive(owner, "stitch_stiffness_scale", self.stitch_stiffness_scale)
        _positive(owner, "sewing_speed", self.sewing_speed)
        return self


def describe(config: ClothMaterial | SolverConfig) -> dict[str, Any]:
    """The fields of a configuration as a plain dict (for logs and benchmark reports)."""
    return {field.name: getattr(config, field.name) for field in fields(config)}
