"""Simulator benchmarks: pscc's cloth solver side by side with Newton's VBD, and pscc's per-stage cost.

Two sections of ``BENCHMARKS.md`` (``python -m pscc.bench``):

1. :func:`run_comparison`: the ``drape`` and ``twist`` scenes (``pscc.scenes``) simulated by pscc's
   :class:`~pscc.sim.simulation.Simulation` and by Newton's ``SolverVBD`` (the ``newton`` package, a
   benchmark-only extra) on the same mesh, at the same frame rate and for the same frames, on the same
   Warp device. Newton runs twice: with its default self-contact filter and with
   ``particle_topological_contact_filter_threshold=1``. After **every** frame the whole state is
   checked with ``ipctk.has_intersections``; the section reports seconds per frame and the frames
   that intersect.
2. :func:`run_breakdown`: pscc alone on ``drape``, ``stack`` and ``twist`` at larger sizes: seconds
   per frame per pipeline stage (the paper's Figure 11) and device memory per structure (Figure 12).

Newton's parameters are chosen to give the same cloth as pscc's :class:`~pscc.sim.config.ClothMaterial`
(derivations in :func:`newton_material`) and the time stepping of Newton's own ``cloth_twist``
example; every choice is listed in :data:`NEWTON_SETTINGS` and printed in the report.
"""

from __future__ import annotations

import statistics
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np
import warp as wp

from pscc.scenes import build_scene
from pscc.sim.memory import warp_array_bytes
from pscc.sim.scene import Scene
from pscc.sim.simulation import Simulation

STAGES: tuple[str, ...] = ("integration", "broad_phase", "narrow_phase", "penetration", "proximity",
                           "intersection_check")
"""pscc's per-step stages, in pipeline order (``ClothSolver.step`` stats)."""

STAGE_LABELS: dict[str, str] = {
    "integration": "integration", "broad_phase": "broad phase", "narrow_phase": "narrow phase (CCD + DCD)",
    "penetration": "penetration handling", "proximity": "proximity springs", "intersection_check": "intersection check",
    "other": "other (copies, velocities, bookkeeping)",
}

EXPLOSION_EXTENT: float = 10.0
"""A Newton or pscc state with a coordinate beyond this many metres (or NaN/Inf) counts as exploded [m]."""


@dataclass(frozen=True)
class NewtonSettings:
    """Newton VBD time stepping and contact settings (documented in the report).

    The defaults follow Newton 1.8's ``cloth_twist`` example (``newton/examples/cloth``): 10 substeps
    and 4 VBD iterations per 1/60 s frame, i.e. dt = 1/600 s; at pscc's 30 fps the same dt is 20
    substeps per frame. Self-contact margin and gap are the example's (2 mm and 1.5 mm); the margin is
    also pscc's cloth thickness h = 2 mm. Contact stiffness and damping are the example's; friction is
    pscc's material friction.
    """

    substeps: int = 20
    """Substeps per 1/30 s frame (dt = 1/600 s, as the example's 10 per 1/60 s)."""
    iterations: int = 4
    """VBD iterations per substep (the example's)."""
    self_contact_margin: float = 0.002
    """``particle_self_contact_margin`` [m]: interaction distance (= pscc's thickness h; the example's)."""
    self_contact_gap: float = 0.0015
    """``particle_self_contact_gap`` [m]: extra detection distance (the example's)."""
    vertex_contact_buffer: int = 64
    """``particle_vertex_contact_buffer_size`` (the example's, raised for tight twisting)."""
    edge_contact_buffer: int = 128
    """``particle_edge_contact_buffer_size`` (the example's)."""
    contact_ke: float = 1.0e3
    """``model.soft_contact_ke`` and the sphere's ``ke`` [N/m] (the example's)."""
    contact_kd: float = 1.0e-1
    """``model.soft_contact_kd`` and the sphere's ``kd`` (the example's)."""
    particle_radius: float = 0.002
    """Cloth particle radius [m]: cloth-sphere contact distance (= pscc's thickness h)."""
    color_bending: bool = True
    """Colour the particle graph with the bending stencils (``builder.color(include_bending=True)``),
    as Newton's ``cloth_bending`` example does for cloth with real bending stiffness."""
    rebuild_bvh_every_frame: bool = True
    """Rebuild the self-contact BVHs at the start of every frame (the example does)."""


NEWTON_SETTINGS = NewtonSettings()


# ---------------------------------------------------------------------------------------------- checks


def intersection_free(vertices: np.ndarray, faces: np.ndarray) -> bool | None:
    """``not ipctk.has_intersections`` of the mesh; None when ipctk is missing."""
    try:
        import ipctk
    except ImportError:
        return None
    v = np.ascontiguousarray(vertices, dtype=np.float64)
    f = np.ascontiguousarray(faces, dtype=np.int32)
    mesh = ipctk.CollisionMesh(v, ipctk.edges(f), f)
    return not ipctk.has_intersections(mesh, v)


def _exploded(vertices: np.ndarray) -> bool:
    return not np.all(np.isfinite(vertices)) or float(np.abs(vertices).max(initial=0.0)) > EXPLOSION_EXTENT


def _stretch(vertices: np.ndarray, edges: np.ndarray, rest_lengths: np.ndarray) -> float:
    """Largest relative edge elongation (a sanity check that the cloth is comparable)."""
    lengths = np.linalg.norm(vertices[edges[:, 0]] - vertices[edges[:, 1]], axis=1)
    return float((lengths / rest_lengths - 1.0).max(initial=0.0))


def _unique_edges(faces: np.ndarray) -> np.ndarray:
    edges = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    return np.unique(np.sort(edges, axis=1), axis=0)


# ---------------------------------------------------------------------------------------------- Newton


def newton_material(scene: Scene) -> dict[str, float]:
    """Newton triangle (StVK/stable Neo-Hookean Lamé) parameters matching pscc's membrane.

    pscc's membrane energy per area is ``1/2 (k_uu G00^2 + k_vv G11^2 + 2 k_uv G00 G11 + k_shear G01^2)``
    (Green strain G). Newton's VBD membrane (stable Neo-Hookean with Lamé ``mu = tri_ke``,
    ``lambda = tri_ka``) linearises to ``mu |G|_F^2 + lambda/2 tr(G)^2``, i.e. ``k_uu = k_vv = 2 mu + lambda``,
    ``k_uv = lambda`` and ``k_shear = 4 mu``. An isotropic material cannot match all four: we match the
    two stretch stiffnesses (their mean) and the coupling exactly, so Newton's shear is stiffer
    (``4 mu`` against pscc's ``k_shear``; reported). Membrane damping: pscc's Rayleigh term
    ``-stretch_damping * H * v`` equals Newton's metric-rate damping ``tri_kd`` for uniaxial stretch when
    ``tri_kd = stretch_damping * k_uu / 4``.
    """
    material = scene.material
    stretch = 0.5 * (material.stretch_u + material.stretch_v)
    lam = float(material.stretch_uv)
    mu = 0.5 * (stretch - lam)
    return {
        "density": float(material.density),
        "tri_ke": mu,
        "tri_ka": lam,
        "tri_kd": float(material.stretch_damping) * stretch / 4.0,
        "newton_shear_equivalent": 4.0 * mu,
        "pscc_shear": float(material.shear),
        "friction": float(material.friction),
    }


def _bending_per_edge(rest: np.ndarray, edge_indices: np.ndarray, bending: float) -> np.ndarray:
    """Newton's per-edge ``edge_ke`` giving pscc's discrete-shell bending energy.

    pscc: ``E = bending/2 * 3 |e|^2 / (A1 + A2) * (theta - theta0)^2``; Newton:
    ``E = edge_ke * |e| / 2 * (theta - theta0)^2``; so ``edge_ke = 3 bending |e| / (A1 + A2)``.
    Boundary edges (an opposite vertex is -1) get 0, as in both solvers.
    """
    o0, o1, v0, v1 = (edge_indices[:, k] for k in range(4))
    interior = (o0 >= 0) & (o1 >= 0)
    ke = np.zeros(edge_indices.shape[0])
    a, b = rest[v0[interior]], rest[v1[interior]]
    c0, c1 = rest[o0[interior]], rest[o1[interior]]
    e = b - a
    area0 = 0.5 * np.linalg.norm(np.cross(e, c0 - a), axis=1)
    area1 = 0.5 * np.linalg.norm(np.cross(e, c1 - a), axis=1)
    ke[interior] = 3.0 * bending * np.linalg.norm(e, axis=1) / (area0 + area1)
    return ke


@wp.kernel
def _set_points(ids: wp.array(dtype=wp.int32), targets: wp.array(dtype=wp.vec3),
                velocity_scale: float, positions: wp.array(dtype=wp.vec3), velocities: wp.array(dtype=wp.vec3)):
    """One thread per prescribed particle: velocity = (target - position) * velocity_scale, then position = target."""
    i = wp.tid()
    p = ids[i]
    velocities[p] = (targets[i] - positions[p]) * velocity_scale
    positions[p] = targets[i]


class NewtonCloth:
    """The scene's cloth in Newton's ``SolverVBD``: static sphere obstacles and kinematic handles.

    Args:
        scene: a pscc scene (its cloth mesh, material, gravity, handles and obstacles are used).
        device: Warp device.
        filter_threshold: ``particle_topological_contact_filter_threshold`` (None: Newton's default).
        settings: time stepping and contact settings.
    """

    def __init__(self, scene: Scene, device: str, filter_threshold: int | None = None,
                 settings: NewtonSettings = NEWTON_SETTINGS) -> None:
        import newton

        self.scene = scene
        self.settings = settings
        self.device = device
        self.frame_dt = scene.frame_time
        self.dt = scene.frame_time / settings.substeps
        self.time = 0.0
        material = newton_material(scene)
        builder = newton.ModelBuilder(gravity=tuple(float(g) for g in scene.solver.gravity))
        if any(abs(g) > 0.0 for g in scene.solver.gravity[:2]):
            raise ValueError("the Newton comparison supports gravity along z only")
        vertices = np.asarray(scene.vertices, dtype=np.float64)
        builder.add_cloth_mesh(
            pos=wp.vec3(0.0, 0.0, 0.0), rot=wp.quat_identity(), scale=1.0, vel=wp.vec3(0.0, 0.0, 0.0),
            vertices=[wp.vec3(*v) for v in vertices.tolist()], indices=np.asarray(scene.faces).reshape(-1).tolist(),
            density=material["density"], tri_ke=material["tri_ke"], tri_ka=material["tri_ka"],
            tri_kd=material["tri_kd"], edge_ke=1.0, edge_kd=0.0, particle_radius=settings.particle_radius,
        )
        shape_cfg = newton.ModelBuilder.ShapeConfig(ke=settings.contact_ke, kd=settings.contact_kd,
                                                    mu=material["friction"])
        for obstacle in scene.obstacles:
            # pscc's icosphere becomes an analytic static sphere through its vertices (the mesh lies inside it).
            if obstacle.name != "sphere" or any(not np.allclose(obstacle.positions(t), obstacle.vertices)
                                                for t in (0.0, 0.5, 1.0)):
                raise ValueError(f"the Newton comparison supports static spheres only, not {obstacle.name!r}")
            center = obstacle.vertices.mean(axis=0)
            radius = float(np.linalg.norm(obstacle.vertices - center, axis=1).max())
            builder.add_shape_sphere(body=-1, xform=wp.transform(wp.vec3(*center.tolist()), wp.quat_identity()),
                                     radius=radius, cfg=shape_cfg)
        builder.color(include_bending=settings.color_bending)
        model = builder.finalize(device=device)
        model.soft_contact_ke = settings.contact_ke
        model.soft_contact_kd = settings.contact_kd
        model.soft_contact_mu = material["friction"]

        # Bending: pscc's discrete-shell stiffness per edge, and its Rayleigh damping.
        edges = model.edge_indices.numpy()
        edge_ke = _bending_per_edge(vertices, edges, float(scene.material.bending))
        properties = model.edge_bending_properties.numpy()
        properties[:, 0] = edge_ke
        properties[:, 1] = float(scene.material.bending_damping) * edge_ke
        model.edge_bending_properties.assign(properties)

        # Handles: kinematic particles (ACTIVE cleared), positions written before every substep.
        self.handles = list(scene.handles)
        flags = model.particle_flags.numpy()
        for handle in self.handles:
            flags[handle.vertices] &= ~int(newton.ParticleFlags.ACTIVE)
        model.particle_flags.assign(flags)
        self._handle_ids = (wp.array(np.concatenate([h.vertices for h in self.handles]).astype(np.int32),
                                     dtype=wp.int32, device=device) if self.handles else None)
        self._handle_targets = (wp.zeros(self._handle_ids.shape[0], dtype=wp.vec3, device=device)
                                if self.handles else None)
        self._initial = vertices

        kwargs: dict[str, Any] = {}
        if filter_threshold is not None:
            kwargs["particle_topological_contact_filter_threshold"] = int(filter_threshold)
        self.pipeline = newton.CollisionPipeline(model)
        self.solver = newton.solvers.SolverVBD(
            model, iterations=settings.iterations, particle_enable_self_contact=True,
            particle_self_contact_margin=settings.self_contact_margin,
            particle_self_contact_gap=settings.self_contact_gap,
            particle_vertex_contact_buffer_size=settings.vertex_contact_buffer,
            particle_edge_contact_buffer_size=settings.edge_contact_buffer,
            collision_pipeline=self.pipeline, **kwargs,
        )
        self.filter_threshold = self.solver.particle_topological_contact_filter_threshold \
            if hasattr(self.solver, "particle_topological_contact_filter_threshold") else filter_threshold
        self.model = model
        self.state_0 = model.state()
        self.state_1 = model.state()
        self.control = model.control()
        self.vertex_count = int(vertices.shape[0])

    def _handle_positions(self, t: float) -> np.ndarray:
        rows = []
        for handle in self.handles:
            rotation, translation = handle.transform(t)
            rows.append(self._initial[handle.vertices] @ rotation.T + translation)
        return np.concatenate(rows).astype(np.float32)

    def step_frame(self) -> float:
        """Advance one frame; return its wall-clock seconds."""
        started = time.perf_counter()
        if self.settings.rebuild_bvh_every_frame:
            self.solver.rebuild_bvh(self.state_0)
        for _ in range(self.settings.substeps):
            if self.handles:
                # Prescribed positions at the end of the substep (what pscc's handles reach at t + dt).
                self._handle_targets.assign(self._handle_positions(self.time + self.dt))
                wp.launch(_set_points, dim=self._handle_ids.shape[0],
                          inputs=[self._handle_ids, self._handle_targets, 1.0 / self.dt],
                          outputs=[self.state_0.particle_q, self.state_0.particle_qd], device=self.device)
            self.state_0.clear_forces()
            self.solver.step(self.state_0, self.state_1, self.control, None, self.dt)
            self.state_0, self.state_1 = self.state_1, self.state_0
            self.time += self.dt
        wp.synchronize_device(self.device)
        return time.perf_counter() - started

    def positions(self) -> np.ndarray:
        """(n, 3) cloth positions."""
        return self.state_0.particle_q.numpy()[:self.vertex_count].astype(np.float64)


# ---------------------------------------------------------------------------------------------- comparison


def _check_mesh(scene: Scene, cloth: np.ndarray, t: float) -> tuple[np.ndarray, np.ndarray]:
    """Cloth positions plus every obstacle's pscc mesh at time t (vertices, faces) for ipctk."""
    vertices, faces = [cloth], [np.asarray(scene.faces, np.int32)]
    offset = cloth.shape[0]
    for obstacle in scene.obstacles:
        vertices.append(obstacle.positions(t).astype(np.float64))
        faces.append(obstacle.faces + offset)
        offset += obstacle.vertices.shape[0]
    return np.concatenate(vertices), np.concatenate(faces)


def _run_method(name: str, scene: Scene, frames: int, make: Callable[[], Any], progress: Callable[[str], None],
                time_limit: float) -> dict[str, Any]:
    """Step one method frame by frame, checking the state after every frame."""
    started = time.perf_counter()
    row: dict[str, Any] = {"method": name, "frames_requested": frames, "frame_seconds": [], "intersecting": [],
                           "error": None, "exploded_at": None, "check_seconds": 0.0}
    edges = _unique_edges(np.asarray(scene.faces))
    rest = np.asarray(scene.vertices, np.float64)
    rest_lengths = np.linalg.norm(rest[edges[:, 0]] - rest[edges[:, 1]], axis=1)
    try:
        runner = make()
    except Exception as exc:  # a failure to set up is a result, not a crash of the benchmark
        row["error"] = f"setup: {type(exc).__name__}: {exc}"
        return row
    row["setup_seconds"] = time.perf_counter() - started
    max_stretch = max_speed = 0.0
    previous = rest
    for frame in range(1, frames + 1):
        try:
            if isinstance(runner, Simulation):
                seconds = runner.step_frame()["seconds_total"]
                cloth = runner.state.positions.numpy()[:scene.vertices.shape[0]].astype(np.float64)
                t = runner.time
            else:
                seconds = runner.step_frame()
                cloth = runner.positions()
                t = runner.time
        except Exception as exc:  # pscc's SimulationError or a Newton failure: reported, not raised
            row["error"] = f"frame {frame}: {type(exc).__name__}: {exc}"
            break
        row["frame_seconds"].append(seconds)
        if _exploded(cloth):
            row["exploded_at"] = frame
            break
        max_stretch = max(max_stretch, _stretch(cloth, edges, rest_lengths))
        max_speed = max(max_speed, float(np.linalg.norm(cloth - previous, axis=1).max()) / scene.frame_time)
        previous = cloth
        row["final_centroid_z"] = float(cloth[:, 2].mean())
        mark = time.perf_counter()
        free = intersection_free(*_check_mesh(scene, cloth, t))
        row["check_seconds"] += time.perf_counter() - mark
        if free is False:
            row["intersecting"].append(frame)
        progress(f"{scene.name} {name} frame {frame}/{frames}: {seconds:.3f} s"
                 + ("" if free is not False else " INTERSECTING"))
        if time.perf_counter() - started > time_limit:
            row["error"] = f"stopped after frame {frame}: over the {time_limit:.0f} s limit of this run"
            break
    row["frames_done"] = len(row["frame_seconds"])
    row["max_stretch"] = max_stretch
    row["max_speed"] = max_speed
    timed = row["frame_seconds"][1:]  # the first frame compiles/loads kernels
    row["median_seconds"] = statistics.median(timed) if timed else None
    row["mean_seconds"] = statistics.fmean(timed) if timed else None
    row["wall_seconds"] = time.perf_counter() - started
    if isinstance(runner, Simulation):
        counts = [f["counts"] for f in runner.frame_stats]
        row["pscc_counts"] = {k: int(sum(c.get(k, 0) for c in counts))
                              for k in ("halvings", "ccd_hits", "projection_rounds", "zone_rounds", "cg_iterations")}
    return row


def compare_scene(scene_name: str, triangles: int, frames: int, device: str,
                  progress: Callable[[str], None] = lambda _: None, with_newton: bool = True,
                  time_limit: float = 600.0) -> list[dict[str, Any]]:
    """pscc, Newton (default filter) and Newton (filter threshold 1) on one scene; one row each."""
    scene = build_scene(scene_name, triangles)
    methods: list[tuple[str, Callable[[], Any]]] = [("pscc", lambda: Simulation(scene, device=device))]
    if with_newton:
        methods += [
            ("newton-default", lambda: NewtonCloth(scene, device, None)),
            ("newton-filter1", lambda: NewtonCloth(scene, device, 1)),
        ]
    rows = []
    for name, make in methods:
        row = _run_method(name, scene, frames, make, progress, time_limit)
        row.update(scene=scene_name, triangles=int(scene.faces.shape[0]), vertices=int(scene.vertices.shape[0]),
                   simulated_seconds=frames * scene.frame_time)
        rows.append(row)
    return rows


def newton_available() -> bool:
    """Whether ``newton`` imports."""
    try:
        import newton  # noqa: F401
    except ImportError:
        return False
    return True


def run_comparison(cases: list[tuple[str, int, int]], device: str, progress: Callable[[str], None] = lambda _: None,
                   with_newton: bool = True) -> dict[str, Any]:
    """Every (scene, triangles, frames) case; returns rows plus the settings used."""
    with_newton = with_newton and newton_available()
    started = time.perf_counter()
    rows = []
    for scene_name, triangles, frames in cases:
        rows += compare_scene(scene_name, triangles, frames, device, progress, with_newton)
    scene = build_scene("drape", 200)
    filter_default = relaxation = None
    if with_newton:
        import inspect

        import newton

        parameters = inspect.signature(newton.solvers.SolverVBD.__init__).parameters
        filter_default = parameters["particle_topological_contact_filter_threshold"].default
        relaxation = parameters["dat_conservative_bound_relaxation"].default
    return {"rows": rows, "newton_settings": asdict(NEWTON_SETTINGS), "newton_material": newton_material(scene),
            "newton_version": _newton_version(), "newton_filter_default": filter_default,
            "newton_dat_relaxation": relaxation,
            "frame_time": scene.frame_time, "steps_per_frame": scene.steps_per_frame,
            "seconds": time.perf_counter() - started}


def _newton_version() -> str | None:
    try:
        import newton
    except ImportError:
        return None
    return str(getattr(newton, "__version__", "?"))


# ---------------------------------------------------------------------------------------------- breakdown


def solver_memory(sim: Simulation) -> dict[str, int]:
    """Device bytes of a simulation's structures: ``collision.*`` (the detector's own accounting, with
    ``collision.total``), ``contact_springs``, ``intersection_check``, ``integrator`` (with the model) and
    ``states``."""
    detector = sim.solver.detector.device_bytes()
    memory = {f"collision.{k}": int(v) for k, v in detector.items() if k != "total"}
    memory["collision.total"] = int(detector["total"])
    solver = sim.solver.device_bytes()
    for key in ("contact_springs", "projection", "intersection_check", "integrator"):
        memory[key] = solver[key]
    memory["states"] = warp_array_bytes(sim.state) + warp_array_bytes(sim._next)
    return memory


def breakdown_scene(scene_name: str, triangles: int, warmup: int, frames: int, device: str,
                    progress: Callable[[str], None] = lambda _: None) -> dict[str, Any]:
    """pscc alone: ``warmup`` frames, then ``frames`` measured frames; per-stage seconds and memory."""
    scene = build_scene(scene_name, triangles)
    started = time.perf_counter()
    sim = Simulation(scene, device=device, stage_timing=True)  # the host path: it times every stage
    row: dict[str, Any] = {"scene": scene_name, "triangles": int(scene.faces.shape[0]),
                           "collision_triangles": int(sim.solver.collision_faces.shape[0]),
                           "warmup_frames": warmup, "frames": frames, "error": None}
    records = []
    try:
        for frame in range(1, warmup + frames + 1):
            record = sim.step_frame()
            progress(f"breakdown {scene_name} {triangles}: frame {frame}/{warmup + frames} "
                     f"{record['seconds_total']:.2f} s")
            if frame > warmup:
                records.append(record)
    except Exception as exc:  # SimulationError: reported
        row["error"] = f"{type(exc).__name__}: {exc}"
    row["measured_frames"] = len(records)
    row["first_measured_time"] = (warmup + 1) * scene.frame_time
    seconds = {k: statistics.fmean(r["seconds"].get(k, 0.0) for r in records) if records else 0.0 for k in STAGES}
    total = statistics.fmean(r["seconds_total"] for r in records) if records else 0.0
    seconds["other"] = max(0.0, total - sum(seconds.values()))
    row["stage_seconds"] = seconds
    row["frame_seconds"] = total
    row["counts"] = {k: statistics.fmean(r["counts"].get(k, 0) for r in records) if records else 0.0
                     for k in ("contacts", "ccd_hits", "broad_phases", "cg_iterations", "halvings", "zone_rounds")}
    row["device_bytes"] = solver_memory(sim)
    row["wall_seconds"] = time.perf_counter() - started
    return row


def run_breakdown(scenes: list[str], sizes: list[int], warmup: dict[str, int], frames: int, device: str,
                  progress: Callable[[str], None] = lambda _: None) -> dict[str, Any]:
    """Every scene at every size."""
    started = time.perf_counter()
    rows = [breakdown_scene(scene, size, warmup.get(scene, 1), frames, device, progress)
            for size in sizes for scene in scenes]
    return {"rows": rows, "seconds": time.perf_counter() - started}


# ---------------------------------------------------------------------------------------------- report


def _fmt(value: float | None, digits: int = 3) -> str:
    return "" if value is None else f"{value:.{digits}f}"


def _frames_text(row: dict[str, Any]) -> str:
    if row["error"] and row.get("frames_done", 0) == 0:
        return "failed"
    text = f"{len(row['intersecting'])} / {row['frames_done']}"
    return text


def report_comparison(results: dict[str, Any]) -> list[str]:
    """Markdown lines for the pscc / Newton VBD section."""
    settings = results["newton_settings"]
    material = results["newton_material"]
    rows = results["rows"]
    substep_dt = results["frame_time"] / settings["substeps"]
    lines = [
        "## Cloth simulation: pscc against Newton VBD",
        "",
        "The `drape` and `twist` scenes (`pscc/scenes/builtin.py`) simulated by pscc and by Newton "
        f"{results['newton_version']}'s `SolverVBD` on the same mesh (the scene's cloth vertices and faces), "
        f"from the same start, at {1 / results['frame_time']:.0f} frames per second for the same frames, on the "
        "same Warp device, one after the other in one process. After **every** frame the whole state is "
        "checked with `ipctk.has_intersections(CollisionMesh(V, edges(F), F), V)`: pscc's cloth plus its "
        "obstacle mesh; Newton's cloth plus pscc's icosphere mesh of the sphere (Newton collides with an "
        "analytic sphere of the icosphere's vertex radius, so the icosphere lies inside it: a cloth vertex "
        "that crosses the mesh is also inside the analytic sphere).",
        "",
        f"- **pscc**: `Simulation(scene)` with the default `ContactConfig`: {results['steps_per_frame']} implicit "
        f"steps per frame (dt = {results['frame_time'] / results['steps_per_frame'] * 1e3:.2f} ms), steps halved "
        "on demand, every step certified intersection-free.",
        f"- **Newton VBD**: {settings['substeps']} substeps per frame (dt = {substep_dt * 1e3:.2f} ms) and "
        f"{settings['iterations']} iterations, the time step of Newton's `cloth_twist` example (10 substeps, "
        "4 iterations at 60 fps); self-contact on with "
        f"`particle_self_contact_margin={settings['self_contact_margin']}` (pscc's thickness h = 2 mm) and "
        f"`particle_self_contact_gap={settings['self_contact_gap']}` (the example's margin and gap), contact "
        f"buffers {settings['vertex_contact_buffer']}/{settings['edge_contact_buffer']} (the example's), "
        f"`soft_contact_ke={settings['contact_ke']:g}`, `soft_contact_kd={settings['contact_kd']:g}` (the "
        f"example's; the sphere's shape material the same), friction {material['friction']:g} (pscc's), cloth "
        f"particle radius {settings['particle_radius']} m (cloth-sphere distance = h). The solver owns a "
        "`CollisionPipeline(model)` (cloth-sphere contacts each substep); the self-contact BVHs are rebuilt "
        "every frame, as in the example; particles are coloured with the bending stencils "
        "(`color(include_bending=True)`).",
        f"- **Same cloth**: density {material['density']} kg/m² (pscc's); Newton's isotropic membrane "
        f"`tri_ke` (Lamé mu) = {material['tri_ke']:g}, `tri_ka` (lambda) = {material['tri_ka']:g} N/m give pscc's "
        f"stretch stiffness 2 mu + lambda = {2 * material['tri_ke'] + material['tri_ka']:g} N/m and coupling "
        f"lambda = {material['tri_ka']:g} N/m exactly, but a shear stiffness 4 mu = "
        f"{material['newton_shear_equivalent']:g} N/m where pscc's is {material['pscc_shear']:g} N/m (an "
        "isotropic model cannot match all three; shear is the one left stiffer). Membrane damping "
        f"`tri_kd` = {material['tri_kd']:g} matches pscc's Rayleigh membrane damping in uniaxial stretch. "
        "Bending: per-edge `edge_ke = 3 k_b |e| / (A1 + A2)` and `edge_kd = 0.01 s * edge_ke`, which is pscc's "
        "discrete-shell bending energy and Rayleigh bending damping term for term. Handle vertices "
        "(twist) are kinematic (`ParticleFlags.ACTIVE` cleared) and are written before every substep at "
        "exactly `handle.transform(t + dt)`, the positions pscc's handles reach at the end of the same step.",
        "- **Newton twice**: with its default self-contact filter "
        f"(`particle_topological_contact_filter_threshold={results['newton_filter_default']}`) and with "
        "`particle_topological_contact_filter_threshold=1` (`newton-filter1`).",
        "- **Time**: wall-clock seconds per frame, median over the frames after the first (the first compiles "
        "and loads kernels), not counting the ipctk check. pscc's time includes its own per-step "
        "intersection check and step halvings. `pscc / this` < 1 means pscc is faster.",
        "- **Same motion?** `max speed` is the largest vertex displacement between two frames divided by the "
        "frame time; `centroid z` is the cloth's mean height after the last frame; `max stretch` is the "
        "largest relative edge elongation over the run.",
        "",
    ]
    if results.get("newton_dat_relaxation") is not None:
        reach = settings["self_contact_margin"] + settings["self_contact_gap"]
        budget = 0.5 * results["newton_dat_relaxation"] * reach
        lines += [
            f"Newton's penetration-free truncation bounds every particle's displacement per substep by 0.5 x "
            f"{results['newton_dat_relaxation']:g} x (margin + gap) = {budget * 1e3:.2f} mm, i.e. "
            f"**{budget / substep_dt:.2f} m/s** at this dt. pscc's draping sheet reaches about 1.4 m/s before it "
            "touches the sphere and its free corners whip at several m/s; the twist strip sags at about 1.5 m/s "
            "in its first frames. Newton's cloth therefore moves more slowly (the `max speed` column) and "
            "the frames compare different motions. A larger gap raises the bound (a 10 mm gap made Newton's "
            "sheet fall like pscc's before contact when we chose the parameters) but is five times the "
            "thickness and more than Newton's documentation advises (0.5 to 1 x the margin); we keep the "
            "example's values. With 4 iterations VBD is also far from converged at these resolutions: its "
            "cloth stretches much more than pscc's (`max stretch`), most visibly in `twist`, where the strip "
            "held by its two ends sags under gravity (Newton's `cloth_twist` example runs without gravity). "
            "When we checked, 10 iterations roughly halved the 2K twist's largest stretch and 16 iterations "
            "halved the 10K one; Newton's membrane damping (`tri_kd`) and bending made little difference.",
            "",
        ]
    if not any(r["method"] != "pscc" for r in rows):
        lines += ["Newton was not run (`--no-newton`, or the `newton` package is missing): pscc only.", ""]
    lines += [
        "| scene | triangles | frames | method | s/frame (median) | s/frame (mean) | pscc / this | "
        "frames intersecting | first intersecting frame | max speed m/s | centroid z m | max stretch | notes |",
        "|---|---:|---:|---|---:|---:|---:|---:|---:|---:|---:|---:|---|",
    ]
    index = {(r["scene"], r["triangles"], r["method"]): r for r in rows}
    for r in rows:
        pscc = index.get((r["scene"], r["triangles"], "pscc"))
        ratio = ""
        if pscc and pscc.get("median_seconds") and r.get("median_seconds") and r["method"] != "pscc":
            ratio = f"{pscc['median_seconds'] / r['median_seconds']:.2f}"
        notes = []
        if r.get("exploded_at"):
            notes.append(f"exploded at frame {r['exploded_at']}")
        if r.get("error"):
            notes.append(r["error"].replace("|", "/")[:160])
        if r.get("pscc_counts"):
            c = r["pscc_counts"]
            notes.append(f"{c['halvings']} halvings, {c['zone_rounds']} zone rounds")
        first = r["intersecting"][0] if r["intersecting"] else ""
        lines.append(f"| {r['scene']} | {r['triangles']:,} | {r.get('frames_done', 0)}/{r['frames_requested']} | "
                     f"{r['method']} | {_fmt(r.get('median_seconds'))} | {_fmt(r.get('mean_seconds'))} | {ratio} | "
                     f"{_frames_text(r)} | {first} | {r.get('max_speed', 0.0):.2f} | "
                     f"{_fmt(r.get('final_centroid_z'))} | {r.get('max_stretch', 0.0):.1%} | {'; '.join(notes)} |")
    lines += ["", f"Runtime of this section: {results['seconds']:.0f} s (including the checks and the "
              "first-frame compilation).", ""]
    return lines


def pyplot() -> Any | None:
    """``matplotlib.pyplot`` with the headless Agg backend, or None when matplotlib is missing."""
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        return None
    return plt


def stage_bars(ax: Any, labels: list[str], rows: list[dict[str, Any]]) -> None:
    """Stacked bars of seconds per frame per stage (``stage_seconds``) and ``other`` on ``ax``."""
    bottom = np.zeros(len(rows))
    for stage in STAGES:
        values = np.array([r["stage_seconds"][stage] for r in rows])
        ax.bar(labels, values, bottom=bottom, label=STAGE_LABELS[stage])
        bottom += values
    other = np.array([max(0.0, r["frame_seconds"] - sum(r["stage_seconds"][k] for k in STAGES)) for r in rows])
    ax.bar(labels, other, bottom=bottom, label=STAGE_LABELS["other"], color="0.8")


def plot_breakdown(results: dict[str, Any], path: Path) -> bool:
    """Stacked bars of seconds per frame per stage (one bar per scene and size); False without matplotlib."""
    plt = pyplot()
    if plt is None:
        return False
    rows = [r for r in results["rows"] if r["measured_frames"]]
    if not rows:
        return False
    labels = [f"{r['scene']}\n{r['triangles'] / 1000:.0f}K" for r in rows]
    fig, (seconds_ax, share_ax, memory_ax) = plt.subplots(1, 3, figsize=(max(10.0, 1.2 * len(rows) + 5.0), 4.4),
                                                          dpi=120)
    totals = np.array([sum(r["stage_seconds"].values()) for r in rows])
    bottom = np.zeros(len(rows))
    share_bottom = np.zeros(len(rows))
    for stage in (*STAGES, "other"):
        values = np.array([r["stage_seconds"][stage] for r in rows])
        seconds_ax.bar(labels, values, bottom=bottom, label=STAGE_LABELS[stage])
        share = 100.0 * values / np.maximum(totals, 1e-12)
        share_ax.bar(labels, share, bottom=share_bottom)
        bottom += values
        share_bottom += share
    seconds_ax.set_ylabel("seconds per frame (8 steps)")
    seconds_ax.set_title("time per frame")
    share_ax.set_ylabel("% of the frame")
    share_ax.set_title("share per stage")
    share_ax.set_ylim(0.0, 100.0)
    structures = sorted({k for r in rows for k in r["device_bytes"] if k.startswith("collision.")
                         and k != "collision.total"})
    bottom = np.zeros(len(rows))
    hatches = ("", "//", "..", "xx", "\\\\", "--", "++", "oo")
    for k, structure in enumerate(structures):
        values = np.array([r["device_bytes"].get(structure, 0) / r["triangles"] for r in rows])
        memory_ax.bar(labels, values, bottom=bottom, label=structure.removeprefix("collision."), color="white",
                      edgecolor=f"C{k % 10}", hatch=hatches[k % len(hatches)])
        bottom += values
    memory_ax.set_ylabel("bytes per cloth triangle")
    memory_ax.set_title("collision structures")
    memory_ax.legend(fontsize=6, loc="upper right")
    for ax in (seconds_ax, share_ax, memory_ax):
        ax.grid(True, axis="y", alpha=0.3)
        ax.tick_params(axis="x", labelsize=8)
    fig.suptitle("pscc cloth solver: time per stage and collision memory (CPU)")
    handles, names = seconds_ax.get_legend_handles_labels()
    fig.legend(handles, names, loc="lower center", ncol=4, fontsize=7, frameon=False)
    fig.tight_layout(rect=(0.0, 0.12, 1.0, 1.0))
    fig.savefig(path)
    plt.close(fig)
    return True


def report_breakdown(results: dict[str, Any], plot: str | None) -> list[str]:
    """Markdown lines for the per-stage time and memory section."""
    rows = results["rows"]
    lines = [
        "## Cloth simulation: time per stage and memory (pscc)",
        "",
        "pscc's solver on the three built-in scenes (like the paper's Figures 11 and 12). Each scene is run "
        "from its start; the first frames are a warm-up (they also compile and load the kernels), then the "
        "following frames are measured: average seconds per frame (8 steps) per stage of `ClothSolver.step`, "
        "the host path (`Simulation(stage_timing=True)`), which synchronizes after every stage to time it; "
        "the default device path and its graph replay are in the device-path section. "
        "The warm-up is chosen so that the measured frames have contact where that is affordable on the CPU: "
        "the `drape` sheet reaches the sphere at about frame 5, the `stack` layers lie on the ground from the "
        "start, and the `twist` strip only comes into self-contact after about 0.75 s (frame 23 at 2K), which is "
        "too many frames at these sizes on the CPU, so its frames measure the twisting strip before "
        "self-contact (integration-bound). "
        "`other` is the frame time not inside a stage (host copies, velocities, the stats).",
        "",
        "| scene | triangles | measured frames (from t) | s/frame | " + " | ".join(STAGE_LABELS[s] for s in STAGES)
        + " | other | contacts | CCD hits | halvings |",
        "|---|---:|---|---:|" + "---:|" * (len(STAGES) + 4),
    ]
    for r in rows:
        stages = " | ".join(f"{r['stage_seconds'][s]:.3f}" for s in (*STAGES, "other"))
        note = f" ({r['error'][:80]})" if r["error"] else ""
        lines.append(f"| {r['scene']} | {r['triangles']:,} | {r['measured_frames']} (t = "
                     f"{r['first_measured_time']:.2f} s){note} | {r['frame_seconds']:.3f} | {stages} | "
                     f"{r['counts']['contacts']:.0f} | {r['counts']['ccd_hits']:.0f} | {r['counts']['halvings']:.1f} |")
    if plot:
        lines += ["", f"![pscc time per stage]({plot})"]
    structures = sorted({k for r in rows for k in r["device_bytes"] if k.startswith("collision.")
                         and k != "collision.total"})
    lines += [
        "",
        "Device memory after the measured frames, in bytes per cloth triangle (collision structures count "
        "the whole collision mesh: cloth plus obstacles). `collision.*` are `CollisionDetector.device_bytes()`; "
        "`intersection check`, `integrator` (model, BSR system, PCG vectors) and `states` are the Warp arrays "
        "those objects hold.",
        "",
        "| scene | triangles | " + " | ".join(s.removeprefix("collision.") for s in structures)
        + " | collision total | contact springs | projection | intersection check | integrator | states | total MiB |",
        "|---|---:|" + "---:|" * (len(structures) + 7),
    ]
    for r in rows:
        memory = r["device_bytes"]
        per = r["triangles"]
        cells = " | ".join(f"{memory.get(s, 0) / per:.0f}" for s in structures)
        total = sum(v for k, v in memory.items() if k != "collision.total")
        lines.append(f"| {r['scene']} | {r['triangles']:,} | {cells} | **{memory['collision.total'] / per:.0f}** | "
                     f"{memory['contact_springs'] / per:.0f} | {memory.get('projection', 0) / per:.0f} | "
                     f"{memory['intersection_check'] / per:.0f} | "
                     f"{memory['integrator'] / per:.0f} | {memory['states'] / per:.0f} | {total / 2**20:.1f} |")
    lines += ["", f"Runtime of this section: {results['seconds']:.0f} s.", ""]
    return lines


# ---------------------------------------------------------------------------------------------- defaults

COMPARISON_CASES: list[tuple[str, int, int]] = [("drape", 2000, 15), ("twist", 2000, 45),
                                                 ("drape", 10000, 12), ("twist", 10000, 30)]
"""Default (scene, cloth triangles, frames) of the comparison."""

QUICK_COMPARISON_CASES: list[tuple[str, int, int]] = [("drape", 2000, 8), ("twist", 2000, 8)]
"""``--quick`` variant: contact in drape only."""

BREAKDOWN_SIZES: list[int] = [10000, 50000]
BREAKDOWN_WARMUP: dict[str, int] = {"drape": 6, "stack": 2, "twist": 2}
BREAKDOWN_FRAMES: int = 3
QUICK_BREAKDOWN_SIZES: list[int] = [2000]
QUICK_BREAKDOWN_FRAMES: int = 2


def parse_cases(values: list[str]) -> list[tuple[str, int, int]]:
    """``SCENE:TRIANGLES:FRAMES`` strings -> cases."""
    cases = []
    for value in values:
        parts = value.split(":")
        if len(parts) != 3:
            raise ValueError(f"{value!r} is not SCENE:TRIANGLES:FRAMES")
        cases.append((parts[0], int(parts[1]), int(parts[2])))
    return cases
