"""The solver's step on the device: no host read inside a step, so a whole frame records into a graph.

:class:`DeviceStep` runs the step of :class:`pscc.sim.ClothSolver` (``docs/simulator.md``) with
every decision on the device:

1. integration (PCG looped with ``wp.capture_while``), the handle targets of the step read from a
   per-frame device table;
2. a range check of the predicted positions (finite, within ``MAX_COORDINATE``);
3. the broad phase, then the CCD / response loop as a ``wp.capture_while`` whose body runs a
   narrow phase (re-checking only pairs with a moved vertex), a one-thread decision kernel, and two
   ``wp.capture_if`` branches: the certifying broad phase once the response stops finding
   collisions, and a round of the inelastic projection while it does;
4. velocities, the DCD on the last broad phase and the proximity springs;
5. the independent intersection check (a device count of crossings that involve the cloth), last:
   its hash tables live in the candidate pairs' memory.

Everything that would make the host path halve a step or fall back to rigid impact zones, and
every buffer that overflows, raises a flag in the :attr:`DeviceStep.report` array instead. The
frame reads that one array once (:meth:`DeviceStep.read_report`): when a flag is up, the solver
restores the frame's start (:meth:`DeviceStep.save` / :meth:`DeviceStep.restore`, device copies),
grows the buffers, and runs the frame again on the host path, which halves steps and uses impact
zones as before. The counters of the report give the frame's stats.

========================  =====================================================================
report slot               meaning (summed over the steps since :meth:`DeviceStep.clear_report`)
========================  =====================================================================
FLAG_RANGE                positions NaN/Inf or beyond MAX_COORDINATE (integrator or response)
FLAG_UNRESOLVED           CCD still found collisions after ``projection_rounds`` response rounds
FLAG_CROSSINGS            the intersection check found edge-face crossings involving the cloth
FLAG_OVERFLOW             a buffer was too small (the frame runs again after growing it)
CG_ITERATIONS ...         the step counters of :meth:`pscc.sim.ClothSolver.step`
========================  =====================================================================
"""

from __future__ import annotations

from typing import Any

import numpy as np
import warp as wp

from pscc.sim.contact_config import CCD_INSIDE_SHARE
from pscc.tolerances import MAX_COORDINATE

wp.set_module_options({"enable_backward": False})

FLAG_RANGE = 0
FLAG_UNRESOLVED = 1
FLAG_CROSSINGS = 2
FLAG_OVERFLOW = 3
CG_ITERATIONS = 4
BROAD_PHASES = 5
CCD_ROUNDS = 6
CCD_HITS = 7
PROJECTION_ROUNDS = 8
PROJECTION_ITERATIONS = 9
DCD_VERTEX_FACE = 10
DCD_EDGE_EDGE = 11
CG_FAILED = 12
CONTACTS = 13
FRONT_SIZE = 14
NEAR_FULL_SPRINGS = 15
NEAR_FULL_VERTEX_FACE = 16
NEAR_FULL_EDGE_EDGE = 17
NEAR_FULL_PROJECTION = 18
NEAR_FULL_BROAD_PHASE = 19
NEAR_FULL_INTERSECTION = 20
PROJECTION_PEAK = 21
HASH_PEAKS = 22  # 5 slots: the largest entries, groups, rows, pairs and slab-tested groups of the frame
CANDIDATE_PEAKS = 27  # 2 slots: the most vertex-face and edge-edge candidates of a broad phase in the frame
REPORT_SIZE = 29

NEAR_FULL_GROWTH = 1.5
"""Factor a nearly full buffer grows by (see :data:`NEAR_FULL_FRACTION`)."""

NEAR_FULL_FRACTION = 0.85
"""A growing buffer (contact springs, candidates, projection constraints, hash tables) that a frame
fills beyond this fraction is grown after the frame (to about :data:`NEAR_FULL_GROWTH` x its size),
before it overflows: contact builds up over frames, and an overflow costs a frame on the host path.
Above 1 / 1.25 = 0.8, so a buffer the host path just sized (1.25 x its need) is not grown at once."""

FLAG_NAMES: dict[int, str] = {
    FLAG_RANGE: "positions became NaN, Inf or left the coordinate range",
    FLAG_UNRESOLVED: "collisions were left after the projection rounds",
    FLAG_CROSSINGS: "the intersection check found edge-face crossings",
    FLAG_OVERFLOW: "a device buffer was too small",
}
"""What each flag of the report means (for the stats and the fallback's reason)."""

# Slots of the response loop's control array.
_ROUNDS = 0
_CERTIFIED = 1
_LOOP_SLOTS = 2


@wp.kernel
def _flag_out_of_range(
    # in:
    positions: wp.array(dtype=wp.vec3),
    limit: float,
    # out:
    report: wp.array(dtype=wp.int32),
):
    """One thread per vertex: raise FLAG_RANGE for a NaN/Inf coordinate or one beyond ``limit``."""
    v = wp.tid()
    p = positions[v]
    for k in range(3):
        c = p[k]
        if not (wp.abs(c) <= limit):  # also true for NaN
            report[FLAG_RANGE] = 1


@wp.kernel
def _begin_response(
    # out:
    control: wp.array(dtype=wp.int32),
    running: wp.array(dtype=wp.int32),
    need_broad_phase: wp.array(dtype=wp.int32),
    project: wp.array(dtype=wp.int32),
    report: wp.array(dtype=wp.int32),
):
    """One thread: start the CCD / response loop of a step (skipped when a flag is already up)."""
    control[_ROUNDS] = 0
    control[_CERTIFIED] = 1
    need_broad_phase[0] = 0
    project[0] = 0
    running[0] = 1
    if report[FLAG_RANGE] != 0 or report[FLAG_UNRESOLVED] != 0 or report[FLAG_CROSSINGS] != 0 \
            or report[FLAG_OVERFLOW] != 0:
        running[0] = 0
    report[BROAD_PHASES] = report[BROAD_PHASES] + 1


@wp.kernel
def _decide_round(
    # in:
    hit_counts: wp.array(dtype=wp.int32),
    projection_rounds: int,
    # out:
    control: wp.array(dtype=wp.int32),
    running: wp.array(dtype=wp.int32),
    need_broad_phase: wp.array(dtype=wp.int32),
    project: wp.array(dtype=wp.int32),
    report: wp.array(dtype=wp.int32),
):
    """One thread: after a CCD, stop, certify with a new broad phase, or run a response round."""
    hits = hit_counts[0] + hit_counts[1]
    report[CCD_ROUNDS] = report[CCD_ROUNDS] + 1
    report[CCD_HITS] = report[CCD_HITS] + hits
    need_broad_phase[0] = 0
    project[0] = 0
    if report[FLAG_RANGE] != 0 or report[FLAG_OVERFLOW] != 0:
        running[0] = 0
        return
    if hits == 0:
        if control[_CERTIFIED] == 1:
            running[0] = 0
        else:
            need_broad_phase[0] = 1
            control[_CERTIFIED] = 1
            report[BROAD_PHASES] = report[BROAD_PHASES] + 1
        return
    if control[_ROUNDS] >= projection_rounds:
        report[FLAG_UNRESOLVED] = 1
        running[0] = 0
        return
    control[_ROUNDS] = control[_ROUNDS] + 1
    control[_CERTIFIED] = 0
    project[0] = 1
    report[PROJECTION_ROUNDS] = report[PROJECTION_ROUNDS] + 1


@wp.kernel
def _add_counter(
    # in:
    source: wp.array(dtype=wp.int32),
    source_index: int,
    slot: int,
    # out:
    report: wp.array(dtype=wp.int32),
):
    """One thread: report[slot] += source[source_index]."""
    report[slot] = report[slot] + source[source_index]


@wp.func
def _max_into(value: wp.int64, slot: int, report: wp.array(dtype=wp.int32)):
    """report[slot] = max(report[slot], value) (clamped to int32)."""
    report[slot] = wp.max(report[slot], wp.int32(wp.min(value, wp.int64(2147483647))))


@wp.func
def _mark_into(value: wp.int64, limit: wp.int64, slot: int, mask: int, report: wp.array(dtype=wp.int32)):
    """Set the bits ``mask`` of report[slot] when ``value`` exceeds ``limit``."""
    if value > limit:
        report[slot] = report[slot] | mask


@wp.func
def _flag_into(value: wp.int64, capacity: wp.int64, code: int, report: wp.array(dtype=wp.int32)):
    """Set FLAG_OVERFLOW to ``code`` when ``value`` exceeds ``capacity`` or wrapped negative, unless an
    earlier overflow is already recorded (the first one is the cause)."""
    if (value > capacity or value < wp.int64(0)) and report[FLAG_OVERFLOW] == 0:
        report[FLAG_OVERFLOW] = code


# One kernel per counter type, not one generic kernel with overloads: Warp 1.19's CPU graphs replayed a
# launch of the int32 overload with the int64 one in some recorded frames (it read an int32 counter and the
# next one as a single int64 and raised a false overflow), so the recorded code picks the kernel itself.
@wp.kernel
def _max_counter_int32(source: wp.array(dtype=wp.int32), source_index: int, slot: int,
                       report: wp.array(dtype=wp.int32)):
    """One thread: report[slot] = max(report[slot], source[source_index])."""
    _max_into(wp.int64(source[source_index]), slot, report)


@wp.kernel
def _max_counter_int64(source: wp.array(dtype=wp.int64), source_index: int, slot: int,
                       report: wp.array(dtype=wp.int32)):
    """One thread: report[slot] = max(report[slot], source[source_index]) (clamped to int32)."""
    _max_into(source[source_index], slot, report)


@wp.kernel
def _mark_if_above_int32(count: wp.array(dtype=wp.int32), index: int, limit: wp.int64, slot: int, mask: int,
                         report: wp.array(dtype=wp.int32)):
    """One thread: set the bits ``mask`` of report[slot] when count[index] exceeds ``limit``."""
    _mark_into(wp.int64(count[index]), limit, slot, mask, report)


@wp.kernel
def _mark_if_above_int64(count: wp.array(dtype=wp.int64), index: int, limit: wp.int64, slot: int, mask: int,
                         report: wp.array(dtype=wp.int32)):
    """One thread: set the bits ``mask`` of report[slot] when count[index] exceeds ``limit``."""
    _mark_into(count[index], limit, slot, mask, report)


@wp.kernel
def _flag_if_above_int32(count: wp.array(dtype=wp.int32), index: int, capacity: wp.int64, code: int,
                         report: wp.array(dtype=wp.int32)):
    """One thread: :func:`_flag_into` on count[index]."""
    _flag_into(wp.int64(count[index]), capacity, code, report)


@wp.kernel
def _flag_if_above_int64(count: wp.array(dtype=wp.int64), index: int, capacity: wp.int64, code: int,
                         report: wp.array(dtype=wp.int32)):
    """One thread: :func:`_flag_into` on count[index]."""
    _flag_into(count[index], capacity, code, report)


_MAX_COUNTER = {wp.int32: _max_counter_int32, wp.int64: _max_counter_int64}
_MARK_IF_ABOVE = {wp.int32: _mark_if_above_int32, wp.int64: _mark_if_above_int64}
_FLAG_IF_ABOVE = {wp.int32: _flag_if_above_int32, wp.int64: _flag_if_above_int64}


def _max_counter(source: wp.array) -> wp.Kernel:
    """The report-max kernel for ``source``'s counter type (int32 or int64)."""
    return _MAX_COUNTER[source.dtype]


def _mark_if_above(count: wp.array) -> wp.Kernel:
    """The mark-if-above kernel for ``count``'s counter type (int32 or int64)."""
    return _MARK_IF_ABOVE[count.dtype]


@wp.kernel
def _velocities_from_positions(
    # in:
    positions_t0: wp.array(dtype=wp.vec3),
    positions_t1: wp.array(dtype=wp.vec3),
    inverse_dt: float,
    # out:
    velocities: wp.array(dtype=wp.vec3),
):
    """One thread per vertex: v = (x1 - x0) / dt."""
    v = wp.tid()
    velocities[v] = (positions_t1[v] - positions_t0[v]) * inverse_dt


def report_counts(report: np.ndarray) -> dict[str, int]:
    """The step counters of a host copy of the report, under the names of :meth:`ClothSolver.step`'s counts."""
    slots = {"cg_iterations": CG_ITERATIONS, "broad_phases": BROAD_PHASES, "ccd_rounds": CCD_ROUNDS,
             "ccd_hits": CCD_HITS, "projection_rounds": PROJECTION_ROUNDS,
             "projection_iterations": PROJECTION_ITERATIONS, "dcd_vertex_face": DCD_VERTEX_FACE,
             "dcd_edge_edge": DCD_EDGE_EDGE, "contacts": CONTACTS, "front_size": FRONT_SIZE}
    return {name: int(report[slot]) for name, slot in slots.items()}


def flag_overflow(count: wp.array, index: int, capacity: int, report: wp.array, code: int = 1) -> None:
    """Launch the overflow check of one device counter (int32 or int64) against its capacity; an
    overflow sets ``report[FLAG_OVERFLOW]`` to ``code`` (>= 1, names the buffer).

    Allocates: no. Capture-safe: yes.
    """
    wp.launch(_FLAG_IF_ABOVE[count.dtype], dim=1, inputs=[count, int(index), wp.int64(int(capacity)), int(code)],
              outputs=[report],
              device=report.device)


class DeviceStep:
    """The device path of :meth:`pscc.sim.ClothSolver.step` (module docstring).

    Args:
        solver: the solver whose integrator, detector, response and checks it drives.
    """

    def __init__(self, solver: Any) -> None:
        self.solver = solver
        dev = solver.device
        self.device = dev
        self.report = wp.zeros(REPORT_SIZE, dtype=wp.int32, device=dev)
        self._control = wp.zeros(_LOOP_SLOTS, dtype=wp.int32, device=dev)
        self._running = wp.zeros(1, dtype=wp.int32, device=dev)
        self._need_broad_phase = wp.zeros(1, dtype=wp.int32, device=dev)
        self._project = wp.zeros(1, dtype=wp.int32, device=dev)
        self._targets: wp.array | None = None
        self._staging: wp.array | None = None
        self._staging_view: np.ndarray | None = None
        self._saved: list[tuple[wp.array, wp.array]] = []
        self._overflow_names: list[str] = []

    # ------------------------------------------------------------------ frame-level (host) helpers

    def device_bytes(self) -> int:
        """Bytes of this object's device arrays: the report, the loop flags, the targets table and the
        frame-start copies of :meth:`save` (the host staging array is not device memory)."""
        arrays = [self.report, self._control, self._running, self._need_broad_phase, self._project, self._targets,
                  *(copy for _, copy in self._saved)]
        return sum(int(a.capacity) for a in arrays if a is not None)

    def upload_targets(self, targets: np.ndarray) -> None:
        """Copy the handle targets of a frame's steps, (steps, handle_count, 3), to the device table.

        The one upload of a frame (kinematic targets only): the values go into a host staging array
        (pinned memory when the device is a GPU) and from there to the device table in one copy. It
        happens outside a recorded graph, which reads the same table every replay.

        Allocates: when the table's shape changes. Capture-safe: no.
        """
        steps, count = int(targets.shape[0]), int(targets.shape[1])
        if count == 0:
            return
        if self._targets is None or self._targets.shape != (steps, count):
            self._targets = wp.empty((steps, count), dtype=wp.vec3, device=self.device)
            self._staging = wp.empty((steps, count), dtype=wp.vec3, device="cpu", pinned=self.device.is_cuda)
            self._staging_view = self._staging.numpy()  # a view of the staging memory, kept
        self._staging_view[...] = targets
        self._targets.assign(self._staging)

    def clear_report(self) -> None:
        """Zero the report (flags and counters). Allocates: no. Capture-safe: yes."""
        self.report.zero_()

    def read_report(self) -> np.ndarray:
        """The report as host int64 values (one read: the frame's sync point). Capture-safe: no."""
        return self.report.numpy().astype(np.int64)

    def _saved_arrays(self, state: Any) -> list[wp.array]:
        return [state.positions, state.velocities, self.solver.integrator.dv,
                self.solver.integrator.system.contact_clock]

    def save(self, state: Any) -> None:
        """Device copies of what the frame changes that a re-run needs and cannot recompute: positions,
        velocities, the CG warm start and the contact clock (the contact springs are a function of the positions:
        :meth:`pscc.sim.ClothSolver.advance_frame` rebuilds them after :meth:`restore`). Allocates: when
        a buffer's shape changed. Capture-safe: yes once allocated."""
        arrays = self._saved_arrays(state)
        if len(self._saved) != len(arrays) or any(copy.shape != a.shape or copy.dtype != a.dtype or src is not a
                                                  for (src, copy), a in zip(self._saved, arrays, strict=True)):
            self._saved = [(a, wp.empty_like(a)) for a in arrays]
        for source, copy in self._saved:
            wp.copy(copy, source)

    def restore(self) -> None:
        """Copy the saved arrays back (the frame's start). Allocates: no. Capture-safe: yes."""
        for source, copy in self._saved:
            wp.copy(source, copy)

    # ------------------------------------------------------------------ the step

    def step(self, state_in: Any, state_out: Any, dt: float, step_index: int) -> None:
        """One step from ``state_in`` into ``state_out`` on the device (module docstring).

        ``step_index`` selects the row of the handle targets table (:meth:`upload_targets`).
        Allocates: no. Capture-safe: yes.
        """
        solver = self.solver
        dev = self.device
        report = self.report
        springs = solver.proximity.springs
        targets = self._targets[step_index] if self._targets is not None else None
        solver.integrator.step_device(state_in, state_out, dt, contacts=springs, handle_targets=targets)
        pcg = solver.integrator._solver
        wp.launch(_add_counter, dim=1, inputs=[pcg.counters, 0, CG_ITERATIONS], outputs=[report], device=dev)
        wp.launch(_add_counter, dim=1, inputs=[pcg.counters, 1, CG_FAILED], outputs=[report], device=dev)
        x0 = state_in.positions
        x1 = state_out.positions
        vertex_count = x1.shape[0]
        wp.launch(_flag_out_of_range, dim=vertex_count, inputs=[x1, MAX_COORDINATE], outputs=[report], device=dev)

        detector = solver.detector
        detector.broad_phase_device(x0, x1, solver.thickness)
        self._flag_detector_overflow()
        solver.projection.reset()
        solver.add_stitch_constraints(x1)
        wp.launch(_begin_response, dim=1, outputs=[self._control, self._running, self._need_broad_phase,
                                                   self._project, report], device=dev)
        wp.capture_while(self._running, lambda: self._response_round(x0, x1))

        constraints = solver.projection.constraint_count
        wp.launch(_max_counter(constraints), dim=1, inputs=[constraints, 0, PROJECTION_PEAK], outputs=[report],
                  device=dev)

        wp.launch(_velocities_from_positions, dim=vertex_count, inputs=[x0, x1, 1.0 / dt],
                  outputs=[state_out.velocities], device=dev)
        # The DCD and the springs in one pass (each pair's closest points found once).
        contacts = detector.narrow_phase_device(x1, None, solver.thickness, defer_dcd=True)
        solver.proximity.test_and_update_device(contacts, x1, detector.narrow.proximity_test(solver.thickness))
        wp.launch(_add_counter, dim=1, inputs=[contacts.hit_counts, 0, DCD_VERTEX_FACE], outputs=[report], device=dev)
        wp.launch(_add_counter, dim=1, inputs=[contacts.hit_counts, 1, DCD_EDGE_EDGE], outputs=[report], device=dev)
        self._flag(springs.count, 0, springs.capacity, "contact springs")
        self._mark_near_full(springs.count, 0, springs.capacity, NEAR_FULL_SPRINGS)
        wp.launch(_max_counter(springs.count), dim=1, inputs=[springs.count, 0, CONTACTS], outputs=[report], device=dev)
        # The check hashes over the candidate pairs and times of impact (lent to the detector's hash), so
        # it runs once the springs are built from them.
        if solver.contact.check_intersections:
            check = solver.intersection_check
            check.count_device(x1, solver.cloth_face_count)
            self._flag_intersection_overflow()
            crossings = check.crossing_count
            wp.launch(_mark_if_above(crossings), dim=1, inputs=[crossings, 0, wp.int64(0), FLAG_CROSSINGS, 1],
                      outputs=[report], device=dev)
        front_count = detector.front_count()
        if front_count is not None:
            wp.launch(_max_counter(front_count), dim=1, inputs=[front_count, 0, FRONT_SIZE], outputs=[report],
                      device=dev)

    def _response_round(self, x0: wp.array, x1: wp.array) -> None:
        """The body of the CCD / response loop (recorded once, replayed per round)."""
        solver = self.solver
        dev = self.device
        contacts = solver.detector.narrow_phase_device(x0, x1, solver.ccd_distance, recheck=True,
                                                       inside_share=CCD_INSIDE_SHARE)
        wp.launch(_decide_round, dim=1, inputs=[contacts.hit_counts, solver.contact.projection_rounds],
                  outputs=[self._control, self._running, self._need_broad_phase, self._project, self.report],
                  device=dev)
        wp.capture_if(self._need_broad_phase, on_true=lambda: self._certify(x0, x1))
        wp.capture_if(self._project, on_true=lambda: self._project_round(contacts, x0, x1))

    def _certify(self, x0: wp.array, x1: wp.array) -> None:
        """A new broad phase over the responded trajectory (its candidates cover the final motion)."""
        self.solver.detector.broad_phase_device(x0, x1, self.solver.thickness)
        self._flag_detector_overflow()

    def _project_round(self, contacts: Any, x0: wp.array, x1: wp.array) -> None:
        """One round of the inelastic projection on the hits of the last CCD."""
        solver = self.solver
        projection = solver.projection
        projection.add_device(contacts.args, x0, x1)
        if solver.contact.proximity_constraints:
            # First round only (the round counter is 1): the contact springs as proximity constraints.
            projection.add_near_device(solver.proximity.springs, x1, solver.separation, gate=self._control)
        self._flag_projection_overflow()
        projection.solve_device(x1, solver.separation, solver.response_tolerance)
        wp.launch(_add_counter, dim=1, inputs=[projection.iteration_count, 0, PROJECTION_ITERATIONS],
                  outputs=[self.report], device=self.device)
        wp.launch(_flag_out_of_range, dim=x1.shape[0], inputs=[x1, MAX_COORDINATE], outputs=[self.report],
                  device=self.device)

    # ------------------------------------------------------------------ overflow checks

    def overflow_name(self, code: int) -> str:
        """The buffer an overflow code of the report names."""
        return self._overflow_names[code - 1] if 1 <= code <= len(self._overflow_names) else f"code {code}"

    def _track_hash_peak(self, count: wp.array, index: int, capacity: int, k: int) -> None:
        if k == 4 and capacity >= 2**30 - 1:  # not a slab-testing call: its groups are not slab groups
            return
        wp.launch(_max_counter(count), dim=1, inputs=[count, index, HASH_PEAKS + k], outputs=[self.report],
                  device=self.device)

    def _mark_near_full(self, count: wp.array, index: int, capacity: int, slot: int, bit: int = 0) -> None:
        """Set bit ``bit`` of report[slot] when the counter passes :data:`NEAR_FULL_FRACTION` of ``capacity``."""
        limit = wp.int64(int(NEAR_FULL_FRACTION * capacity))
        wp.launch(_mark_if_above(count), dim=1, inputs=[count, index, limit, slot, 1 << bit], outputs=[self.report],
                  device=self.device)

    def grow_near_full(self, report: np.ndarray) -> bool:
        """After a frame that fit: grow the buffers its report marks as nearly full.

        Returns whether anything grew (recorded graphs then hold stale buffers).
        Allocates: when growing. Capture-safe: no.
        """
        solver = self.solver
        grew = False
        if report[NEAR_FULL_SPRINGS]:
            springs = solver.proximity.springs
            before = springs.capacity
            springs.ensure(int(NEAR_FULL_GROWTH * springs.capacity))
            solver.integrator.system.reserve_contacts(springs.capacity)
            if solver.contact.proximity_constraints:  # the springs join the projection's first round
                solver.projection.reserve(solver.projection.capacity + springs.capacity - before)
            grew = True
        hashes: dict[int, tuple[Any, set[int]]] = {}  # the check may share the detector's hash: grow it once
        for slot, spatial_hash in ((NEAR_FULL_BROAD_PHASE, getattr(solver.detector, "spatial_hash", None)),
                                   (NEAR_FULL_INTERSECTION, solver.intersection_check.spatial_hash)):
            if report[slot] and spatial_hash is not None:
                bits = hashes.setdefault(id(spatial_hash), (spatial_hash, set()))[1]
                bits.update(bit for bit in range(5) if int(report[slot]) >> bit & 1)
        for spatial_hash, bits in hashes.values():
            spatial_hash.grow(bits, NEAR_FULL_GROWTH)
            grew = True
        if report[NEAR_FULL_PROJECTION]:
            solver.projection.reserve(int(NEAR_FULL_GROWTH * solver.projection.capacity))
            grew = True
        if report[NEAR_FULL_VERTEX_FACE] or report[NEAR_FULL_EDGE_EDGE]:
            candidates = solver.detector.candidates
            candidates.ensure(int(NEAR_FULL_GROWTH * candidates.capacity_vf) if report[NEAR_FULL_VERTEX_FACE] else 0,
                              int(NEAR_FULL_GROWTH * candidates.capacity_ee) if report[NEAR_FULL_EDGE_EDGE] else 0)
            solver.detector.narrow.reserve(candidates)
            solver.detector.refresh_loans()
            grew = True
        return grew

    def _flag(self, count: wp.array, index: int, capacity: int, name: str) -> None:
        if name not in self._overflow_names:
            self._overflow_names.append(name)
        flag_overflow(count, index, capacity, self.report, self._overflow_names.index(name) + 1)

    def _flag_detector_overflow(self) -> None:
        detector = self.solver.detector
        candidates = detector.candidates
        self._flag(candidates.counts, 0, candidates.capacity_vf, "vertex-face candidates")
        self._flag(candidates.counts, 1, candidates.capacity_ee, "edge-edge candidates")
        self._mark_near_full(candidates.counts, 0, candidates.capacity_vf, NEAR_FULL_VERTEX_FACE)
        self._mark_near_full(candidates.counts, 1, candidates.capacity_ee, NEAR_FULL_EDGE_EDGE)
        for k in range(2):
            wp.launch(_max_counter(candidates.counts), dim=1, inputs=[candidates.counts, k, CANDIDATE_PEAKS + k],
                      outputs=[self.report], device=self.device)
        for k, (count, index, capacity) in enumerate(detector.overflow_counters()):
            self._flag(count, index, capacity, f"broad phase counter {k}")
            if k < 5 and capacity > 0:  # the growing hash buffers: entries, groups, rows, pairs, slabs
                self._mark_near_full(count, index, capacity, NEAR_FULL_BROAD_PHASE, k)
                self._track_hash_peak(count, index, capacity, k)

    def _flag_projection_overflow(self) -> None:
        projection = self.solver.projection
        self._flag(projection.constraint_count, 0, projection.capacity, "projection constraints")
        self._mark_near_full(projection.constraint_count, 0, projection.capacity, NEAR_FULL_PROJECTION)

    def _flag_intersection_overflow(self) -> None:
        for k, (count, index, capacity) in enumerate(self.solver.intersection_check.overflow_counters()):
            self._flag(count, index, capacity, f"intersection check counter {k}")
            if k < 5 and capacity > 0:
                self._mark_near_full(count, index, capacity, NEAR_FULL_INTERSECTION, k)
                self._track_hash_peak(count, index, capacity, k)
