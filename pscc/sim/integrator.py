"""Linearised backward Euler (Baraff & Witkin 1998) for cloth: assemble, precondition, CG, update.

One call of :meth:`ImplicitEuler.step` performs::

    (M + dt D + dt^2 H) dv = dt f(x_t) - (dt D + dt^2 H) v_t      (assembly: pscc.sim.assembly)
    v_{t+1} = v_t + dv,  x_{t+1} = x_t + dt v_{t+1}                 (the predicted state)

with H = -df/dx (PSD approximations: :mod:`pscc.sim.materials`) and D = -df/dv (Rayleigh damping,
air drag, contact friction). Scripted vertices are Dirichlet constraints: their new velocity is
``(target - x_t) / dt`` and their new position is exactly the target.

Contact springs (:class:`pscc.sim.ContactSprings`) are included implicitly with their gap evaluated
at x_t: for ``g = n . sum_i w_i x_i - h < 0`` the force is ``f_i = -k_c g w_i n`` with Jacobian blocks
``-k_c w_i w_j n n^T`` (normal frozen), and Coulomb friction becomes the tangential damper
``D_ij = -c w_i w_j (I - n n^T)``, ``c = mu |k_c g| / max(|v_t|, eps_v)`` (relative tangential
velocity v_t = (I - n n^T) sum_i w_i v_i). Because the damper is implicit it slows sliding by at
most the Coulomb impulse and never reverses it.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import Any

import numpy as np
import warp as wp

from pscc._checks import as_numpy
from pscc.errors import InputError
from pscc.sim.assembly import ImplicitSystem, StepParams
from pscc.sim.config import SIM_HINGE_DEGENERACY_RATIO, SolverConfig
from pscc.sim.contact_springs import ContactSprings
from pscc.sim.materials import bending_energy, membrane_energy
from pscc.sim.model import VERTEX_FREE, VERTEX_SCRIPTED, ClothModel, FaceArrays, HingeArrays, VertexArrays
from pscc.sim.pcg import PreconditionedConjugateGradient
from pscc.sim.state import ClothState

wp.set_module_options({"enable_backward": False})

_FREE = wp.constant(VERTEX_FREE)
_SCRIPTED = wp.constant(VERTEX_SCRIPTED)
_PRECONDITIONER_MODE = {"block_jacobi": 0, "diag": 1}


@dataclass
class StepStats:
    """Statistics of the last :meth:`ImplicitEuler.step`."""

    cg_iterations: int = 0
    """Conjugate-gradient iterations performed."""
    cg_residual: float = 0.0
    """Relative residual ``|b - A dv| / |b|`` at exit (CG's recursive estimate; 0 when b = 0)."""
    cg_converged: bool = True
    """Whether the residual reached ``SolverConfig.cg_tolerance``."""
    rhs_norm: float = 0.0
    """``|b|`` [kg m/s]."""
    seconds: float = 0.0
    """Wall-clock time of the step, device synchronised [s]."""


@wp.kernel
def _scatter_handle_targets(
    # in:
    handle_ids: wp.array(dtype=wp.int32),
    handle_targets: wp.array(dtype=wp.vec3),
    # out:
    targets: wp.array(dtype=wp.vec3),
):
    """One thread per handle: copy its target into the per-vertex target array."""
    k = wp.tid()
    targets[handle_ids[k]] = handle_targets[k]


@wp.kernel
def _invert_diagonal_blocks(
    # in:
    diagonal: wp.array(dtype=wp.mat33),
    scalar_only: int,
    # out:
    inverse: wp.array(dtype=wp.mat33),
):
    """One thread per vertex: inverse of its 3x3 diagonal block (or of its diagonal entries); in place is fine."""
    i = wp.tid()
    block = diagonal[i]
    if scalar_only != 0:
        inv = wp.mat33(0.0)
        for k in range(3):
            if block[k, k] != 0.0:
                inv[k, k] = 1.0 / block[k, k]
        inverse[i] = inv
        return
    if wp.determinant(block) != 0.0:
        inverse[i] = wp.inverse(block)
    else:
        inverse[i] = wp.identity(n=3, dtype=float)


@wp.kernel
def _apply_block_diagonal(
    # in:
    inverse: wp.array(dtype=wp.mat33),
    x: wp.array(dtype=wp.vec3),
    y: wp.array(dtype=wp.vec3),
    alpha: float,
    beta: float,
    # out:
    z: wp.array(dtype=wp.vec3),
):
    """One thread per vertex: ``z = alpha P^-1 x + beta y`` (y ignored when beta is 0)."""
    i = wp.tid()
    value = alpha * (inverse[i] * x[i])
    if beta != 0.0:
        value = value + beta * y[i]
    z[i] = value


@wp.kernel
def _advance(
    # in:
    kind: wp.array(dtype=wp.int32),
    targets: wp.array(dtype=wp.vec3),
    v_ref: wp.array(dtype=wp.vec3),
    positions: wp.array(dtype=wp.vec3),
    velocities: wp.array(dtype=wp.vec3),
    dv: wp.array(dtype=wp.vec3),
    dt: float,
    # out:
    positions_out: wp.array(dtype=wp.vec3),
    velocities_out: wp.array(dtype=wp.vec3),
):
    """One thread per vertex: v += dv, x += dt v; scripted vertices land exactly on their target."""
    i = wp.tid()
    k = kind[i]
    if k == _FREE:
        v = velocities[i] + dv[i]
        velocities_out[i] = v
        positions_out[i] = positions[i] + dt * v
    elif k == _SCRIPTED:
        velocities_out[i] = v_ref[i]
        positions_out[i] = targets[i]
    else:
        velocities_out[i] = v_ref[i]
        positions_out[i] = positions[i] + dt * v_ref[i]


@wp.kernel
def _sum_membrane_energy(
    # in:
    faces: FaceArrays,
    positions: wp.array(dtype=wp.vec3),
    # out:
    total: wp.array(dtype=wp.float64),
):
    """One thread per face: add its membrane energy [J]."""
    f = wp.tid()
    ids = faces.indices[f]
    energy = membrane_energy(positions[ids[0]], positions[ids[1]], positions[ids[2]], faces.inv_rest[f],
                             faces.rest_area[f], faces.stiffness[f])
    wp.atomic_add(total, 0, wp.float64(energy))


@wp.kernel
def _sum_bending_energy(
    # in:
    hinges: HingeArrays,
    positions: wp.array(dtype=wp.vec3),
    # out:
    total: wp.array(dtype=wp.float64),
):
    """One thread per hinge: add its bending energy [J]."""
    h = wp.tid()
    ids = hinges.indices[h]
    energy = bending_energy(positions[ids[0]], positions[ids[1]], positions[ids[2]], positions[ids[3]],
                            hinges.rest_angle[h], hinges.stiffness[h])
    wp.atomic_add(total, 1, wp.float64(energy))


@wp.kernel
def _sum_vertex_energy(
    # in:
    vertices: VertexArrays,
    positions: wp.array(dtype=wp.vec3),
    velocities: wp.array(dtype=wp.vec3),
    gravity: wp.vec3,
    # out:
    total: wp.array(dtype=wp.float64),
):
    """One thread per vertex: add its kinetic and gravitational potential energy [J]."""
    i = wp.tid()
    mass = vertices.mass[i]
    v = velocities[i]
    wp.atomic_add(total, 2, wp.float64(0.5 * mass * wp.dot(v, v)))
    wp.atomic_add(total, 3, wp.float64(-mass * wp.dot(gravity, positions[i])))


class ImplicitEuler:
    """One linearised backward-Euler step of a cloth, with implicit contact springs and friction.

    Args:
        model: The cloth.
        config: Solver options (validated); default ``SolverConfig()``.
        device: Must be the model's device when given (the integrator always runs there).

    Attributes:
        stats: :class:`StepStats` of the last step.
        targets: (n,) vec3 positions scripted vertices reach at the end of the next step [m]
            (pinned: their initial positions; handles: the last targets given, initially their
            initial positions).
        dv: (n,) vec3 velocity change of the last step [m/s].

    Raises:
        InputError: invalid config, or ``device`` differs from the model's.
    """

    def __init__(self, model: ClothModel, config: SolverConfig | None = None, device: wp.DeviceLike = None) -> None:
        if not isinstance(model, ClothModel):
            raise InputError("argument", "model", f"{type(model).__name__} is not a ClothModel",
                             "build a pscc.sim.ClothModel first")
        self.config = (config if config is not None else SolverConfig()).validate()
        if device is not None and wp.get_device(device) != model.device:
            raise InputError("argument", "device", f"{wp.get_device(device)} differs from the model's {model.device}",
                             "build the model on the device you integrate on")
        self.model = model
        self.device = model.device
        n = model.vertex_count
        self.system = ImplicitSystem(model)
        self.dv = wp.zeros(n, dtype=wp.vec3, device=self.device)
        self.targets = wp.clone(model.initial_positions)
        self.stats = StepStats()
        # The diagonal blocks of A, inverted in place each step (the preconditioner).
        self._inverse_diagonal = wp.zeros(n, dtype=wp.mat33, device=self.device)
        self._energies = wp.zeros(4, dtype=wp.float64, device=self.device)
        self._precondition_launches: dict[tuple[int, int], Any] = {}
        precondition = self._precondition if self.config.preconditioner != "none" else None
        self._solver = PreconditionedConjugateGradient(
            self.system.apply, self.system.rhs, self.dv, self.config.cg_tolerance, self.config.cg_max_iterations,
            self.config.cg_check_every, precondition)

    def step(self, state_in: ClothState, state_out: ClothState, dt: float, contacts: ContactSprings | None = None,
             handle_targets: Any = None) -> StepStats:
        """Advance ``state_in`` by ``dt`` into ``state_out`` (predicted positions and velocities).

        Args:
            state_in: x_t and v_t (not modified unless it is ``state_out``; in place is allowed).
            state_out: Receives x_{t+1} and v_{t+1}.
            dt: Time step [s] (> 0).
            contacts: Optional contact springs, evaluated at x_t. The integrator reads the first
                ``min(count, capacity)`` contacts; a producer that overflowed must call
                :meth:`ContactSprings.fits` first.
            handle_targets: Optional (handle_count, 3) positions [m] the handles (``model.handle_ids``
                order) must reach at the end of this step; they stay in effect for later steps.

        Returns:
            The step statistics (also in :attr:`stats`).

        Raises:
            InputError: a state of the wrong size or device, a bad ``dt``, contacts on another device
                or handle targets of the wrong shape.

        Allocates: only when the contact capacity grows.
        Capture-safe: no (it reads the CG result back for the stats; the solve itself,
        :meth:`pscc.sim.pcg.PreconditionedConjugateGradient.launch`, is).
        """
        started = time.perf_counter()
        self._check_state(state_in, "state_in")
        self._check_state(state_out, "state_out")
        step = float(dt) if isinstance(dt, int | float | np.floating | np.integer) else float("nan")
        if not math.isfinite(step) or step <= 0.0:
            raise InputError("argument", "dt", f"{dt!r} is not a finite time step > 0",
                             "pass dt in seconds, e.g. 1/200")
        if contacts is not None and (not isinstance(contacts, ContactSprings) or contacts.device != self.device):
            raise InputError("argument", "contacts", "is not a ContactSprings on the integrator's device",
                             f"allocate ContactSprings(device={self.device})")
        if handle_targets is not None:
            self.set_handle_targets(handle_targets)

        self._launch_step(state_in, state_out, step, contacts)
        iterations, residual, absolute_tolerance = self._solver.result()
        wp.synchronize_device(self.device)

        rhs_norm = float(absolute_tolerance) / self.config.cg_tolerance
        residual = float(residual)
        relative = residual / rhs_norm if rhs_norm > 0.0 else 0.0
        self.stats = StepStats(cg_iterations=int(iterations), cg_residual=relative,
                               cg_converged=residual <= float(absolute_tolerance), rhs_norm=rhs_norm,
                               seconds=time.perf_counter() - started)
        return self.stats

    def step_device(self, state_in: ClothState, state_out: ClothState, dt: float,
                    contacts: ContactSprings | None = None, handle_targets: wp.array | None = None) -> None:
        """:meth:`step` without reading anything back: the device path of a simulation step.

        The arguments are as for :meth:`step`, except that ``handle_targets`` must be a
        ``(handle_count,)`` vec3 ``wp.array`` on the integrator's device (or ``None``) and nothing is
        validated but their types. The CG result stays on the device
        (:meth:`pscc.sim.pcg.PreconditionedConjugateGradient.result` reads it). Pass the same
        ``contacts`` every step (with a device count of 0 when there are none), so a recorded graph
        holds the contact terms.

        Allocates: only when the contact capacity grows. Capture-safe: yes (with the same arrays).
        """
        if handle_targets is not None:
            self.set_handle_targets(handle_targets)
        self._launch_step(state_in, state_out, float(dt), contacts)

    def solve_result(self) -> tuple[int, float, float]:
        """``(iterations, residual_norm, absolute_tolerance)`` of the last step's CG solve. A sync point."""
        return self._solver.result()

    def _launch_step(self, state_in: ClothState, state_out: ClothState, step: float,
                     contacts: ContactSprings | None) -> None:
        """Assemble, precondition, solve and advance: launches only."""
        params = self._step_params(step)
        self.system.assemble(state_in.positions, state_in.velocities, self.targets, params, contacts, self.dv,
                             warm_start=self.config.cg_warm_start)
        if self.config.preconditioner != "none":
            self.system.diagonal(self._inverse_diagonal)
            wp.launch(_invert_diagonal_blocks, dim=self.model.vertex_count, device=self.device,
                      inputs=[self._inverse_diagonal, _PRECONDITIONER_MODE[self.config.preconditioner]],
                      outputs=[self._inverse_diagonal])
        self._solver.launch()
        wp.launch(_advance, dim=self.model.vertex_count, device=self.device,
                  inputs=[self.model.vertices.kind, self.targets, self.system.reference_velocities,
                          state_in.positions, state_in.velocities, self.dv, step],
                  outputs=[state_out.positions, state_out.velocities])
        self.system.tick(step)

    def set_handle_targets(self, handle_targets: Any) -> None:
        """Set the positions [m] the handles reach at the end of the next step (and keep them after).

        Args:
            handle_targets: (handle_count, 3) array-like, or a (handle_count,) vec3 ``wp.array`` on the
                integrator's device (then nothing is allocated), in ``model.handle_ids`` order.

        Raises:
            InputError: wrong shape, non-finite values, or a Warp array on another device.

        Allocates: only for host input. Capture-safe: only for a device ``wp.array``.
        """
        count = self.model.handle_count
        if isinstance(handle_targets, wp.array) and handle_targets.dtype == wp.vec3:
            if handle_targets.shape != (count,) or handle_targets.device != self.device:
                raise InputError("argument", "handle_targets", f"shape {handle_targets.shape} on "
                                 f"{handle_targets.device}", f"pass ({count},) vec3 on {self.device}")
            source = handle_targets
        else:
            host = np.asarray(as_numpy(handle_targets), dtype=np.float64)
            if host.shape != (count, 3) or not np.all(np.isfinite(host)):
                raise InputError("argument", "handle_targets", f"shape {host.shape} is not ({count}, 3) finite",
                                 "pass one finite target position per handle, in model.handle_ids order")
            source = wp.array(host.astype(np.float32), dtype=wp.vec3, device=self.device)
        if count:
            wp.launch(_scatter_handle_targets, dim=count, device=self.device,
                      inputs=[self.model.handle_ids, source], outputs=[self.targets])

    def energies(self, state: ClothState) -> dict[str, float]:
        """Energies of a state [J]: ``membrane``, ``bending``, ``kinetic``, ``gravity`` and ``total``.

        The gravitational energy is ``-sum_i m_i g . x_i`` (zero at the origin). A sync point.

        Allocates: no. Capture-safe: no.
        """
        self._check_state(state, "state")
        self._energies.zero_()
        model = self.model
        wp.launch(_sum_membrane_energy, dim=model.face_count, device=self.device,
                  inputs=[model.faces, state.positions], outputs=[self._energies])
        if model.hinge_count:
            wp.launch(_sum_bending_energy, dim=model.hinge_count, device=self.device,
                      inputs=[model.hinges, state.positions], outputs=[self._energies])
        wp.launch(_sum_vertex_energy, dim=model.vertex_count, device=self.device,
                  inputs=[model.vertices, state.positions, state.velocities, wp.vec3(*self.config.gravity)],
                  outputs=[self._energies])
        values = self._energies.numpy()
        result = {"membrane": float(values[0]), "bending": float(values[1]), "kinetic": float(values[2]),
                  "gravity": float(values[3])}
        result["total"] = float(values.sum())
        return result

    def _step_params(self, dt: float) -> StepParams:
        config = self.config
        params = StepParams()
        params.dt = dt
        params.gravity = wp.vec3(*config.gravity)
        params.wind = wp.vec3(*config.wind)
        params.air_drag = config.air_drag
        params.contact_stiffness = config.contact_stiffness if config.contact_stiffness is not None else 0.0
        params.contact_stiffness_scale = config.contact_stiffness_scale
        params.stitch_stiffness_scale = config.stitch_stiffness_scale
        params.sewing_step = config.sewing_speed * dt
        params.friction_epsilon = config.friction_velocity_epsilon
        params.hinge_degeneracy_ratio = SIM_HINGE_DEGENERACY_RATIO
        return params

    def _precondition(self, r: wp.array, z: wp.array) -> None:
        """z = P^-1 r with the inverted diagonal blocks (or scalar diagonal); launches packed once per pair."""
        key = (r.ptr, z.ptr)
        command = self._precondition_launches.get(key)
        if command is None:
            command = wp.launch(_apply_block_diagonal, dim=self.model.vertex_count, device=self.device,
                                inputs=[self._inverse_diagonal, r, r, 1.0, 0.0], outputs=[z], record_cmd=True)
            self._precondition_launches[key] = command
        command.launch()

    def _check_state(self, state: ClothState, name: str) -> None:
        if not isinstance(state, ClothState):
            raise InputError("argument", name, f"{type(state).__name__} is not a ClothState",
                             "create one with ClothState.from_model(model)")
        if state.vertex_count != self.model.vertex_count or state.device != self.device:
            raise InputError("argument", name, f"{state.vertex_count} vertices on {state.device}",
                             f"pass a state of {self.model.vertex_count} vertices on {self.device}")
