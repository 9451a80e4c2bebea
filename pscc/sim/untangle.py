"""Pushing tangled cloth apart: a global intersection analysis of the crossings left from a tangled start.

With ``allow_initial_intersections`` (:class:`pscc.sim.contact_config.ContactConfig`), surfaces may start crossing each
other. :meth:`pscc.sim.solver.ClothSolver.update_tangles` finds the crossings after every frame (edge e of one
surface through face f of another) and exempts their vertex pairs from collision handling; this module
decides, once per frame, which side of each crossing passed through and how to move it back, in the
spirit of Baraff, Witkin and Kass (2003), "Untangling cloth":

1. **Cut.** Every edge that crosses a face is cut. The intersection contour separates a surface wherever it
   is closed, or runs from border to border: the vertices on either side are then connected only through
   cut edges.
2. **Flood fill.** Connected components of the vertex graph over the uncut edges (min-label propagation
   with pointer jumping, a few launches per round until nothing changes). A surface the contour does not
   separate (an open contour that ends inside it) stays one component and is not pushed.
3. **Which side passed through.** For a cut edge (p, q) whose ends lie in different components, the
   component of smaller mass (lumped area) is the one that passed through (BWK's smaller-area rule); a
   component holding a pinned, scripted or obstacle vertex never is. Its push direction gains
   ``sign(n_f . (x_q - x_p)) n_f``: across the crossed face f, towards the side the larger component is on.
4. **Push.** Every free vertex of a component that passed through gets the unit sum of its component's
   directions times ``speed`` as an *untangle velocity* (:attr:`Untangler.velocity`);
   :class:`pscc.sim.assembly.ImplicitSystem` adds, in each step, the momentum that brings the vertex's
   velocity along that direction up to it (at most ``speed`` per step, never braking). The cloth's own
   forces, contact springs and the CCD response act as always: the push is a bounded external force.

The crossing vertex pairs are exempt from collision handling (each end of a crossing edge with each vertex of
the crossed face, and edges and faces around them), so the region near the contour can pass back through;
vertices further inside meet the CCD response until the contour reaches them, a frame or so later, when
their pairs are exempt in turn. So a passed-through region comes back about one ring of vertices a frame,
and no new crossing appears (the collision pipeline still refuses any crossing outside the exempt pairs).

Limits: a contour that separates neither surface (two sheets slotted into each other from their borders)
gives no push; two sides of equal mass (sheets crossing at right angles through their middles) push the
one that is a little lighter through, which may not be resolvable at all when both are held by pins;
self-intersections of one piece are treated as any other crossing (the smaller side is pushed across the
same piece's face).

Host part: the crossings arrive as a host array (:meth:`pscc.sim.solver.ClothSolver.update_tangles` filters them
on the host) and are uploaded once per frame; the flood fill reads one flag per round. Everything per
edge, per crossing and per vertex runs in the kernels below. Nothing runs while the cloth is untangled.
"""

from __future__ import annotations

import numpy as np
import warp as wp

wp.set_module_options({"enable_backward": False})

__all__ = ["MAX_FILL_ROUNDS", "Untangler"]

MAX_FILL_ROUNDS: int = 10_000
"""Flood-fill rounds at most (each halves the label chains at least; a mesh needs about log2 of its
diameter plus the diameter of its longest label chain, far below this)."""


@wp.kernel
def _mark_cut_edges(
    # in:
    crossings: wp.array(dtype=wp.vec2i),
    # out:
    cut: wp.array(dtype=wp.int32),
):
    """One thread per crossing (edge id, face id): cut its edge."""
    k = wp.tid()
    cut[crossings[k][0]] = 1


@wp.kernel
def _init_labels(
    # out:
    labels: wp.array(dtype=wp.int32),
):
    """One thread per vertex: its own label."""
    v = wp.tid()
    labels[v] = v


@wp.kernel
def _hook_labels(
    # in:
    edges: wp.array(dtype=wp.vec2i),
    cut: wp.array(dtype=wp.int32),
    # out:
    labels: wp.array(dtype=wp.int32),
    changed: wp.array(dtype=wp.int32),
):
    """One thread per uncut edge whose ends carry different labels: the larger label's root and both ends
    take the smaller (labels only decrease and always name a vertex of the same component)."""
    e = wp.tid()
    if cut[e] != 0:
        return
    a = edges[e][0]
    b = edges[e][1]
    la = labels[a]
    lb = labels[b]
    if la == lb:
        return
    lo = wp.min(la, lb)
    hi = wp.max(la, lb)
    wp.atomic_min(labels, hi, lo)
    wp.atomic_min(labels, a, lo)
    wp.atomic_min(labels, b, lo)
    changed[0] = 1


@wp.kernel
def _jump_labels(
    # out:
    labels: wp.array(dtype=wp.int32),
):
    """One thread per vertex: pointer jumping, ``label = label[label]`` (races only shorten chains)."""
    v = wp.tid()
    labels[v] = labels[labels[v]]


@wp.kernel
def _sum_components(
    # in:
    labels: wp.array(dtype=wp.int32),
    masses: wp.array(dtype=float),
    movable: wp.array(dtype=wp.int32),
    # out:
    component_mass: wp.array(dtype=float),
    component_held: wp.array(dtype=wp.int32),
):
    """One thread per vertex: add its mass to its component's, and flag a component holding a vertex that
    cannot move (pinned, scripted, obstacle)."""
    v = wp.tid()
    label = labels[v]
    wp.atomic_add(component_mass, label, masses[v])
    if movable[v] == 0:
        component_held[label] = 1


@wp.func
def _passes_through(mass_p: float, held_p: int, label_p: int, mass_q: float, held_q: int, label_q: int) -> bool:
    """Whether component p (not q) is the side of a cut edge that passed through: the lighter one (ties: the
    larger label), never one that is held."""
    if held_p != 0:
        return False
    if held_q != 0:
        return True
    if mass_p != mass_q:
        return mass_p < mass_q
    return label_p > label_q


@wp.kernel
def _accumulate_directions(
    # in:
    crossings: wp.array(dtype=wp.vec2i),
    edges: wp.array(dtype=wp.vec2i),
    faces: wp.array(dtype=wp.vec3i),
    positions: wp.array(dtype=wp.vec3),
    labels: wp.array(dtype=wp.int32),
    component_mass: wp.array(dtype=float),
    component_held: wp.array(dtype=wp.int32),
    # out:
    directions: wp.array(dtype=wp.vec3),
):
    """One thread per crossing whose edge joins two components: the side that passed through gains the
    crossed face's unit normal, signed towards the other side."""
    k = wp.tid()
    edge = edges[crossings[k][0]]
    face = faces[crossings[k][1]]
    a = edge[0]
    b = edge[1]
    la = labels[a]
    lb = labels[b]
    if la == lb:
        return
    p = a
    q = b
    if not _passes_through(component_mass[la], component_held[la], la, component_mass[lb], component_held[lb], lb):
        if not _passes_through(component_mass[lb], component_held[lb], lb, component_mass[la],
                               component_held[la], la):
            return
        p = b
        q = a
    x0 = positions[face[0]]
    normal = wp.cross(positions[face[1]] - x0, positions[face[2]] - x0)
    length = wp.length(normal)
    if length == 0.0:
        return
    normal = normal / length
    side = wp.dot(normal, positions[q] - positions[p])
    if side == 0.0:
        return
    wp.atomic_add(directions, labels[p], wp.sign(side) * normal)


@wp.kernel
def _vertex_velocities(
    # in:
    labels: wp.array(dtype=wp.int32),
    directions: wp.array(dtype=wp.vec3),
    movable: wp.array(dtype=wp.int32),
    speed: float,
    # out:
    velocity: wp.array(dtype=wp.vec3),
    pushed: wp.array(dtype=wp.int32),
):
    """One thread per vertex: ``speed`` along its component's unit direction (0 when it has none or the
    vertex cannot move); count the vertices pushed."""
    v = wp.tid()
    d = directions[labels[v]]
    length = wp.length(d)
    if movable[v] == 0 or length == 0.0:
        velocity[v] = wp.vec3(0.0)
        return
    velocity[v] = (speed / length) * d
    wp.atomic_add(pushed, 0, 1)


class Untangler:
    """Which side of each crossing passed through, and the velocity that moves it back (module docstring).

    Device buffers (n vertices, E edges, C components <= n):

    =================  ============  ======================================================
    buffer             shape, dtype  meaning
    =================  ============  ======================================================
    ``velocity``       (n,) vec3     untangle velocity of each vertex [m/s] (the output)
    ``labels``         (n,) int32    component of each vertex (its lowest vertex id)
    ``cut``            (E,) int32    1 for an edge that crosses a face
    ``mass``           (n,) float32  component masses, indexed by label [kg]
    ``held``           (n,) int32    1 for a component holding a vertex that cannot move
    ``directions``     (n,) vec3     summed push directions, indexed by label
    =================  ============  ======================================================

    Args:
        edges: (E,) ``wp.vec2i`` vertex ids of every edge of the collision mesh (the ids that crossings name).
        faces: (m,) ``wp.vec3i`` vertex ids of every face.
        masses: (n,) lumped vertex masses [kg].
        movable: (n,) bool, whether each vertex is free to move (not pinned, scripted or an obstacle's).
        speed: push speed [m/s] (> 0).
        device: Warp device of the arrays.

    Allocates: yes (every buffer). Capture-safe: no.
    """

    def __init__(self, edges: wp.array, faces: wp.array, masses: np.ndarray, movable: np.ndarray, speed: float,
                 device: wp.DeviceLike) -> None:
        self.device = wp.get_device(device)
        self.edges = edges
        self.faces = faces
        n = int(np.asarray(masses).shape[0])
        self.vertex_count = n
        self.speed = float(speed)
        dev = self.device
        self.masses = wp.array(np.asarray(masses, np.float32), dtype=float, device=dev)
        self.movable = wp.array(np.asarray(movable, bool).astype(np.int32), dtype=wp.int32, device=dev)
        self.velocity = wp.zeros(n, dtype=wp.vec3, device=dev)
        """(n,) untangle velocity of each vertex [m/s]: the output of :meth:`analyse`."""
        self.labels = wp.zeros(n, dtype=wp.int32, device=dev)
        self.cut = wp.zeros(edges.shape[0], dtype=wp.int32, device=dev)
        self.mass = wp.zeros(n, dtype=float, device=dev)
        self.held = wp.zeros(n, dtype=wp.int32, device=dev)
        self.directions = wp.zeros(n, dtype=wp.vec3, device=dev)
        self._flags = wp.zeros(2, dtype=wp.int32, device=dev)  # [changed, pushed]
        self.fill_rounds = 0
        """Flood-fill rounds of the last :meth:`analyse`."""
        self.pushed = 0
        """Vertices given an untangle velocity by the last :meth:`analyse`."""

    def analyse(self, positions: wp.array, crossings: np.ndarray) -> int:
        """Set :attr:`velocity` for the state ``positions`` with the given crossings.

        Args:
            positions: (n,) vec3 positions on the device.
            crossings: (k, 2) (edge id, face id) rows: the crossings to take apart (k = 0: no push).

        Returns:
            The vertices pushed (also :attr:`pushed`).

        Sync points: one flag read per flood-fill round and the count at the end. Allocates: the device copy of
        the crossings. Capture-safe: no.
        """
        dev = self.device
        n = self.vertex_count
        rows = np.ascontiguousarray(np.asarray(crossings, np.int32).reshape(-1, 2))
        self.velocity.zero_()
        self.fill_rounds = 0
        self.pushed = 0
        if rows.shape[0] == 0 or n == 0:
            return 0
        hits = wp.array(rows, dtype=wp.vec2i, device=dev)
        self.cut.zero_()
        wp.launch(_mark_cut_edges, dim=rows.shape[0], inputs=[hits], outputs=[self.cut], device=dev)
        wp.launch(_init_labels, dim=n, outputs=[self.labels], device=dev)
        changed = self._flags[:1]
        while self.fill_rounds < MAX_FILL_ROUNDS:
            self.fill_rounds += 1
            changed.zero_()
            wp.launch(_hook_labels, dim=self.edges.shape[0], inputs=[self.edges, self.cut],
                      outputs=[self.labels, changed], device=dev)
            for _ in range(2):
                wp.launch(_jump_labels, dim=n, outputs=[self.labels], device=dev)
            if int(changed.numpy()[0]) == 0:
                break
        self.mass.zero_()
        self.held.zero_()
        self.directions.zero_()
        wp.launch(_sum_components, dim=n, inputs=[self.labels, self.masses, self.movable],
                  outputs=[self.mass, self.held], device=dev)
        wp.launch(_accumulate_directions, dim=rows.shape[0],
                  inputs=[hits, self.edges, self.faces, positions, self.labels, self.mass, self.held],
                  outputs=[self.directions], device=dev)
        self._flags.zero_()
        wp.launch(_vertex_velocities, dim=n, inputs=[self.labels, self.directions, self.movable, self.speed],
                  outputs=[self.velocity, self._flags[1:]], device=dev)
        self.pushed = int(self._flags.numpy()[1])
        return self.pushed

    def labels_host(self) -> np.ndarray:
        """(n,) int32 component label of every vertex after :meth:`analyse` (its component's lowest vertex id).

        A sync point. Allocates: yes (host copy). Capture-safe: no."""
        return self.labels.numpy().copy()
