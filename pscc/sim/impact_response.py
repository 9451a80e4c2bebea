"""Rigid impact zones: the fail-safe of the penetration handling after CCD.

Positions are in the collision index space of the simulator (cloth vertices first, then the
obstacle vertices). A step moves every vertex on the straight line from ``x0`` (start, free of
intersections) to ``x1`` (end); CCD reports the pairs that come closer than the minimum distance
on the way. The solver first answers them with the inelastic projection
(:mod:`pscc.sim.inelastic_projection`); when that has not cleared every collision after
``ContactConfig.projection_rounds`` CCD rounds, it switches to the zones, which change only ``x1``:

* **Rigid impact zones** (:class:`ImpactZones`, host): vertices of colliding pairs are merged into
  zones (union-find), and each zone moves by one affine map ``x1 = A x0 + b``: the rigid velocity
  field (mean velocity plus angular velocity from the zone's angular momentum) of a free zone, or
  the step map of the kinematic group (pins, handle, obstacle) a zone touches. Every point of a
  zone then moves by the family ``(1 - s) I + s A``, which is invertible for every s in [0, 1], so
  nothing inside a zone can collide during the step. Zones grow until no collision is left; a zone
  that touches two kinematic groups with different motions cannot be made rigid, and the step must
  be retried with a smaller time step (:class:`ImpactZoneFailure`).
"""

from __future__ import annotations

import numpy as np

from pscc.errors import PsccError

ZONE_MOTION_TOLERANCE: float = 1e-9
"""Two kinematic step maps count as the same motion when their matrices differ by at most this
(relative, per entry) and their translations by this times the scene size."""


class ImpactZoneFailure(PsccError):
    """A zone touches kinematic vertices with different prescribed motions (retry with a smaller step)."""


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
