"""Penetration handling after CCD: inelastic impulses, then rigid impact zones as the fail-safe.

Positions are in the collision index space of the simulator (cloth vertices first, then the
obstacle vertices). A step moves every vertex on the straight line from ``x0`` (start, free of
intersections) to ``x1`` (end); CCD reports the pairs that come closer than the minimum distance
on the way, with a time of impact ``toi``. Both responses change only ``x1``:

* **Impulses** (:class:`ImpulseResponse`, device kernels): for a pair with signed weights ``w``
  (vertex-face ``(1, -b_a, -b_b, -b_c)``, edge-edge ``(1 - s, s, -(1 - t), -t)``) and the contact
  normal ``n`` at ``toi``, the end gap ``g = n . sum_i w_i x1_i`` is raised to ``separation`` by
  moving each vertex along ``n`` in proportion to ``w_i / m_i`` (inelastic, momentum-preserving).
  Corrections of all pairs are averaged per vertex (Jacobi), so the result does not depend on the
  order of the pairs.
* **Rigid impact zones** (:class:`ImpactZones`, host, after a few impulse rounds do not clear
  every collision): vertices of colliding pairs are merged into zones (union-find), and each zone
  moves by one affine map ``x1 = A x0 + b``: the rigid velocity field (mean velocity plus angular
  velocity from the zone's angular momentum) of a free zone, or the step map of the kinematic
  group (pins, handle, obstacle) a zone touches. Every point of a zone then moves by the family
  ``(1 - s) I + s A``, which is invertible for every s in [0, 1], so nothing inside a zone can
  collide during the step. Zones grow until no collision is left; a zone that touches two
  kinematic groups with different motions cannot be made rigid, and the step must be retried
  with a smaller time step (:class:`ImpactZoneFailure`).
"""

from __future__ import annotations

import numpy as np
import warp as wp

from pscc.errors import PsccError
from pscc.geometry.distance import edge_edge_closest_point, vertex_face_closest_point

wp.set_module_options({"enable_backward": False})

ZONE_MOTION_TOLERANCE: float = 1e-9
"""Two kinematic step maps count as the same motion when their matrices differ by at most this
(relative, per entry) and their translations by this times the scene size."""


class ImpactZoneFailure(PsccError):
    """A zone touches kinematic vertices with different prescribed motions (retry with a smaller step)."""


@wp.func
def _normal_or_fallback(offset: wp.vec3, fallback: wp.vec3, start_offset: wp.vec3) -> wp.vec3:
    """Unit contact normal: the closest-point offset, else ``fallback`` oriented like the start."""
    length = wp.length(offset)
    if length > 1.0e-12:
        return offset / length
    n = fallback
    if wp.length(n) <= 1.0e-20:
        n = start_offset
    if wp.length(n) <= 1.0e-20:
        n = wp.vec3(0.0, 0.0, 1.0)
    n = wp.normalize(n)
    if wp.dot(n, start_offset) < 0.0:
        n = -n
    return n


@wp.func
def _push(vertices: wp.vec4i, weights: wp.vec4, n: wp.vec3, separation: float,
          positions_t1: wp.array(dtype=wp.vec3), inverse_mass: wp.array(dtype=float),
          displacement: wp.array(dtype=wp.vec3), touched: wp.array(dtype=wp.int32)):
    gap = float(0.0)
    denominator = float(0.0)
    for k in range(4):
        gap += weights[k] * wp.dot(n, positions_t1[vertices[k]])
        denominator += weights[k] * weights[k] * inverse_mass[vertices[k]]
    deficit = separation - gap
    if deficit <= 0.0 or denominator <= 0.0:
        return
    for k in range(4):
        v = vertices[k]
        scale = inverse_mass[v] * weights[k] * deficit / denominator
        if scale != 0.0:
            wp.atomic_add(displacement, v, scale * n)
            wp.atomic_add(touched, v, 1)


@wp.kernel
def _vertex_face_impulses(
    # in:
    pairs: wp.array(dtype=wp.vec4i),
    toi: wp.array(dtype=float),
    positions_t0: wp.array(dtype=wp.vec3),
    positions_t1: wp.array(dtype=wp.vec3),
    inverse_mass: wp.array(dtype=float),
    separation: float,
    # out:
    displacement: wp.array(dtype=wp.vec3),
    touched: wp.array(dtype=wp.int32),
):
    """One thread per colliding vertex-face pair (p, a, b, c)."""
    i = wp.tid()
    ids = pairs[i]
    s = toi[i]
    p = wp.lerp(positions_t0[ids[0]], positions_t1[ids[0]], s)
    a = wp.lerp(positions_t0[ids[1]], positions_t1[ids[1]], s)
    b = wp.lerp(positions_t0[ids[2]], positions_t1[ids[2]], s)
    c = wp.lerp(positions_t0[ids[3]], positions_t1[ids[3]], s)
    w = vertex_face_closest_point(p, a, b, c)
    q = w[0] * a + w[1] * b + w[2] * c
    p0 = positions_t0[ids[0]]
    q0 = w[0] * positions_t0[ids[1]] + w[1] * positions_t0[ids[2]] + w[2] * positions_t0[ids[3]]
    n = _normal_or_fallback(p - q, wp.cross(b - a, c - a), p0 - q0)
    _push(ids, wp.vec4(1.0, -w[0], -w[1], -w[2]), n, separation, positions_t1, inverse_mass, displacement, touched)


@wp.kernel
def _edge_edge_impulses(
    # in:
    pairs: wp.array(dtype=wp.vec4i),
    toi: wp.array(dtype=float),
    positions_t0: wp.array(dtype=wp.vec3),
    positions_t1: wp.array(dtype=wp.vec3),
    inverse_mass: wp.array(dtype=float),
    separation: float,
    # out:
    displacement: wp.array(dtype=wp.vec3),
    touched: wp.array(dtype=wp.int32),
):
    """One thread per colliding edge-edge pair (a0, a1, b0, b1)."""
    i = wp.tid()
    ids = pairs[i]
    s = toi[i]
    a0 = wp.lerp(positions_t0[ids[0]], positions_t1[ids[0]], s)
    a1 = wp.lerp(positions_t0[ids[1]], positions_t1[ids[1]], s)
    b0 = wp.lerp(positions_t0[ids[2]], positions_t1[ids[2]], s)
    b1 = wp.lerp(positions_t0[ids[3]], positions_t1[ids[3]], s)
    st = edge_edge_closest_point(a0, a1, b0, b1)
    pa = wp.lerp(a0, a1, st[0])
    pb = wp.lerp(b0, b1, st[1])
    start = (wp.lerp(positions_t0[ids[0]], positions_t0[ids[1]], st[0])
             - wp.lerp(positions_t0[ids[2]], positions_t0[ids[3]], st[1]))
    n = _normal_or_fallback(pa - pb, wp.cross(a1 - a0, b1 - b0), start)
    weights = wp.vec4(1.0 - st[0], st[0], -(1.0 - st[1]), -st[1])
    _push(ids, weights, n, separation, positions_t1, inverse_mass, displacement, touched)


@wp.kernel
def _apply_displacements(
    # in:
    displacement: wp.array(dtype=wp.vec3),
    touched: wp.array(dtype=wp.int32),
    # out:
    positions_t1: wp.array(dtype=wp.vec3),
):
    """One thread per vertex: move by the mean of the corrections it received."""
    v = wp.tid()
    count = touched[v]
    if count > 0:
        positions_t1[v] = positions_t1[v] + displacement[v] / float(count)


class ImpulseResponse:
    """Inelastic impulses on the end positions of colliding pairs (see the module docstring).

    Args:
        inverse_mass: (vertex_count,) 1 / mass [1/kg] in the collision index space; 0 for kinematic
            vertices (pins, handles, obstacles), which are never moved.
        device: Warp device.
    """

    def __init__(self, inverse_mass: np.ndarray, device: wp.Device) -> None:
        self.device = device
        self.vertex_count = int(inverse_mass.shape[0])
        self.inverse_mass = wp.array(np.asarray(inverse_mass, dtype=np.float32), dtype=float, device=device)
        self.displacement = wp.zeros(self.vertex_count, dtype=wp.vec3, device=device)
        self.touched = wp.zeros(self.vertex_count, dtype=wp.int32, device=device)

    def apply(self, vertex_face: np.ndarray, vertex_face_toi: np.ndarray, edge_edge: np.ndarray,
              edge_edge_toi: np.ndarray, positions_t0: wp.array, positions_t1: wp.array, separation: float) -> None:
        """Push every colliding pair's end gap up to ``separation`` [m]; updates ``positions_t1``.

        Args:
            vertex_face: (k, 4) int32 rows (vertex, face vertex a, b, c).
            vertex_face_toi: (k,) time of impact in [0, 1].
            edge_edge: (l, 4) int32 rows (a0, a1, b0, b1).
            edge_edge_toi: (l,) time of impact.
            positions_t0: start positions (device, vec3).
            positions_t1: end positions, updated in place.
            separation: end gap to reach along the contact normal [m].

        Allocates: yes (uploads the pairs). Capture-safe: no.
        """
        self.displacement.zero_()
        self.touched.zero_()
        dev = self.device
        for kernel, rows, toi in ((_vertex_face_impulses, vertex_face, vertex_face_toi),
                                  (_edge_edge_impulses, edge_edge, edge_edge_toi)):
            if rows.shape[0] == 0:
                continue
            pairs = wp.array(np.ascontiguousarray(rows, dtype=np.int32), dtype=wp.vec4i, device=dev)
            times = wp.array(np.ascontiguousarray(toi, dtype=np.float32), dtype=float, device=dev)
            wp.launch(kernel, dim=rows.shape[0],
                      inputs=[pairs, times, positions_t0, positions_t1, self.inverse_mass, float(separation)],
                      outputs=[self.displacement, self.touched], device=dev)
        wp.launch(_apply_displacements, dim=self.vertex_count, inputs=[self.displacement, self.touched],
                  outputs=[positions_t1], device=dev)


class ImpactZones:
    """Rigid impact zones over one step (host union-find; see the module docstring).

    Args:
        masses: (vertex_count,) vertex masses [kg] in the collision index space (any value for
            kinematic vertices).
        kinematic_group: (vertex_count,) int: -1 for free vertices, else the id of the kinematic
            group (pins, a handle, an obstacle) whose prescribed motion the vertex follows.
    """

    def __init__(self, masses: np.ndarray, kinematic_group: np.ndarray) -> None:
        self.masses = np.asarray(masses, dtype=np.float64)
        self.kinematic_group = np.asarray(kinematic_group, dtype=np.int64)
        self.parent = np.arange(self.masses.shape[0], dtype=np.int64)
        self.in_zone = np.zeros(self.masses.shape[0], dtype=bool)

    def _find(self, v: int) -> int:
        parent = self.parent
        root = v
        while parent[root] != root:
            root = parent[root]
        while parent[v] != root:
            parent[v], v = root, parent[v]
        return root

    def merge(self, rows: np.ndarray) -> None:
        """Put the 4 vertices of every colliding row in one zone.

        Kinematic vertices are members too: they tell the zone which prescribed motion to follow.
        Allocates: no (host only).
        """
        for row in np.asarray(rows, dtype=np.int64).reshape(-1, 4):
            self.in_zone[row] = True
            roots = [self._find(int(v)) for v in row]
            first = roots[0]
            for root in roots[1:]:
                if root != first:
                    self.parent[root] = first

    def zones(self) -> list[np.ndarray]:
        """Vertex ids of each zone (sorted; zones ordered by their smallest vertex)."""
        members = np.flatnonzero(self.in_zone)
        roots = np.array([self._find(int(v)) for v in members], dtype=np.int64)
        order = np.argsort(roots, kind="stable")
        members, roots = members[order], roots[order]
        splits = np.flatnonzero(np.diff(roots)) + 1
        groups = np.split(members, splits) if members.size else []
        return sorted(groups, key=lambda g: int(g[0]))

    def apply(self, positions_t0: np.ndarray, positions_t1: np.ndarray, dt: float,
              group_maps: dict[int, tuple[np.ndarray, np.ndarray]], scale: float) -> np.ndarray:
        """End positions with every zone moved by one affine map; kinematic vertices keep theirs.

        Args:
            positions_t0: (n, 3) start positions.
            positions_t1: (n, 3) current end positions.
            dt: step length [s] (the rigid velocity field is fitted to (x1 - x0) / dt).
            group_maps: step map ``(A, b)`` (x1 = A x0 + b) of every rigid kinematic group id. A group
                missing here moves non-rigidly (a mesh sequence): its map is the least-squares affine
                fit to its vertices in the zone (any misfit is caught by the next CCD round).
            scale: scene size [m], for the translation tolerance of :data:`ZONE_MOTION_TOLERANCE`.

        Returns:
            (n, 3) float32 new end positions.

        Raises:
            ImpactZoneFailure: a zone touches two kinematic groups with different motions.
        """
        x0 = np.asarray(positions_t0, dtype=np.float64)
        x1 = np.asarray(positions_t1, dtype=np.float64).copy()
        for zone in self.zones():
            groups = np.unique(self.kinematic_group[zone])
            groups = groups[groups >= 0]
            free = zone[self.kinematic_group[zone] < 0]
            if free.size == 0:
                continue
            if groups.size:
                maps = [group_maps[int(g)] if int(g) in group_maps
                        else _fitted_map(x0, x1, zone[self.kinematic_group[zone] == g]) for g in groups]
                matrix, offset = maps[0]
                for other_matrix, other_offset in maps[1:]:
                    if (np.abs(other_matrix - matrix).max() > ZONE_MOTION_TOLERANCE
                            or np.abs(other_offset - offset).max() > ZONE_MOTION_TOLERANCE * max(scale, 1.0)):
                        raise ImpactZoneFailure(
                            f"an impact zone of {zone.size} vertices touches kinematic groups {groups.tolist()} "
                            "with different motions; retry the step with a smaller time step")
                x1[free] = x0[free] @ matrix.T + offset
                continue
            mass = self.masses[zone][:, None]
            total = float(mass.sum())
            velocity = (x1[zone] - x0[zone]) / dt
            center = (mass * x0[zone]).sum(axis=0) / total
            mean_velocity = (mass * velocity).sum(axis=0) / total
            r = x0[zone] - center
            momentum = (mass * np.cross(r, velocity - mean_velocity)).sum(axis=0)
            inertia = (mass[:, 0, None, None] * (np.einsum("ij,ij->i", r, r)[:, None, None] * np.eye(3)
                                                  - r[:, :, None] * r[:, None, :])).sum(axis=0)
            omega = np.linalg.pinv(inertia, rcond=1e-12) @ momentum
            x1[zone] = x0[zone] + dt * (mean_velocity + np.cross(omega, r))
        return x1.astype(np.float32)


def _fitted_map(x0: np.ndarray, x1: np.ndarray, members: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Least-squares step map ``x1 ~ A x0 + b`` of kinematic vertices without a rigid motion
    (minimum-norm ``A - I``, so one or two vertices give a translation)."""
    centre = x0[members].mean(axis=0)
    motion = x1[members] - x0[members]
    mean = motion.mean(axis=0)
    linear = np.linalg.lstsq(x0[members] - centre, motion - mean, rcond=None)[0].T
    matrix = np.eye(3) + linear
    return matrix, centre + mean - matrix @ centre
