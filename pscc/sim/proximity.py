"""DCD proximity pairs -> contact springs for the next implicit step (paper section 5, I-Cloth 2.5).

The detector reports the vertex-face and edge-edge pairs closer than the thickness h at the end
of a step. For each pair this module computes, on the device, the closest points, the signed
weights and the unit normal of the contact (see :mod:`pscc.sim.contact_springs`) at those
positions, and stores them in a :class:`ContactSprings` that the next
:meth:`pscc.sim.ImplicitEuler.step` treats implicitly.

The normal is the direction between the closest points. A configuration whose closest points
coincide (distance below 1e-12 m, which the CCD minimum distance keeps from happening) falls back
to the face normal (vertex-face) or the edges' cross product (edge-edge).
"""

from __future__ import annotations

import numpy as np
import warp as wp

from pscc.geometry.contact_weights import pair_plane_normal, pair_weights, weighted_sum
from pscc.sim.contact_springs import ContactSprings

wp.set_module_options({"enable_backward": False})


@wp.func
def _unit_or(offset: wp.vec3, fallback: wp.vec3) -> wp.vec3:
    length = wp.length(offset)
    if length > 1.0e-12:
        return offset / length
    if wp.length(fallback) > 1.0e-20:
        return wp.normalize(fallback)
    return wp.vec3(0.0, 0.0, 1.0)


@wp.kernel
def _pair_contacts(
    # in:
    pairs: wp.array(dtype=wp.vec4i),
    positions: wp.array(dtype=wp.vec3),
    first: int,
    edge_edge: int,
    # out:
    vertices: wp.array(dtype=wp.vec4i),
    weights: wp.array(dtype=wp.vec4),
    normals: wp.array(dtype=wp.vec3),
):
    """One thread per pair (vertex-face (p, a, b, c), or edge-edge (a0, a1, b0, b1) when
    ``edge_edge`` is not 0): closest-point weights and unit normal, at slot first + i."""
    i = wp.tid()
    ids = pairs[i]
    x0 = positions[ids[0]]
    x1 = positions[ids[1]]
    x2 = positions[ids[2]]
    x3 = positions[ids[3]]
    w = pair_weights(x0, x1, x2, x3, edge_edge)
    vertices[first + i] = ids
    weights[first + i] = w
    normals[first + i] = _unit_or(weighted_sum(w, x0, x1, x2, x3), pair_plane_normal(x0, x1, x2, x3, edge_edge))


class ProximityContacts:
    """Builds the contact springs of a step from DCD pairs.

    Args:
        faces: (m, 3) int32 triangles of the collision mesh (to expand vertex-face rows).
        kinematic: (n,) bool, True for vertices whose motion is prescribed; pairs made only of
            such vertices are dropped (nothing can respond to them).
        rest_gap: the thickness h [m] the springs keep.
        device: Warp device.
    """

    def __init__(self, faces: np.ndarray, kinematic: np.ndarray, rest_gap: float, device: wp.Device) -> None:
        self.device = device
        self.faces = np.asarray(faces, dtype=np.int32)
        self.kinematic = np.asarray(kinematic, dtype=bool)
        self.springs = ContactSprings(0, rest_gap=rest_gap, device=device)

    def update(self, vertex_face: np.ndarray, edge_edge: np.ndarray, positions: wp.array) -> ContactSprings:
        """Replace the springs with the contacts of these pairs at ``positions``.

        Args:
            vertex_face: (k, 2) rows (vertex, face) from the detector.
            edge_edge: (l, 4) rows (a0, a1, b0, b1) from the detector.
            positions: (n,) vec3 device positions the pairs were found at.

        Returns:
            The updated :class:`ContactSprings` (owned by this object).

        Allocates: yes (uploads the pairs; grows the springs). Capture-safe: no.
        """
        vf = np.zeros((0, 4), np.int32)
        if vertex_face.shape[0]:
            vf = np.concatenate([vertex_face[:, :1], self.faces[vertex_face[:, 1]]], axis=1).astype(np.int32)
        ee = np.asarray(edge_edge, dtype=np.int32).reshape(-1, 4)
        vf = vf[~self.kinematic[vf].all(axis=1)]
        ee = ee[~self.kinematic[ee].all(axis=1)]
        springs = self.springs
        total = vf.shape[0] + ee.shape[0]
        springs.ensure(total)
        for kind, rows, first in ((0, vf, 0), (1, ee, vf.shape[0])):
            if rows.shape[0]:
                pairs = wp.array(rows, dtype=wp.vec4i, device=self.device)
                wp.launch(_pair_contacts, dim=rows.shape[0], inputs=[pairs, positions, first, kind],
                          outputs=[springs.vertices, springs.weights, springs.normals], device=self.device)
        springs.set_count(total)
        return springs
