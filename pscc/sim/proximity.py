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

from pscc.geometry.distance import edge_edge_closest_point, vertex_face_closest_point
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
def _vertex_face_contacts(
    # in:
    pairs: wp.array(dtype=wp.vec4i),
    positions: wp.array(dtype=wp.vec3),
    first: int,
    # out:
    vertices: wp.array(dtype=wp.vec4i),
    weights: wp.array(dtype=wp.vec4),
    normals: wp.array(dtype=wp.vec3),
):
    """One thread per vertex-face pair (p, a, b, c): closest point, weights and normal."""
    i = wp.tid()
    ids = pairs[i]
    p = positions[ids[0]]
    a = positions[ids[1]]
    b = positions[ids[2]]
    c = positions[ids[3]]
    w = vertex_face_closest_point(p, a, b, c)
    q = w[0] * a + w[1] * b + w[2] * c
    vertices[first + i] = ids
    weights[first + i] = wp.vec4(1.0, -w[0], -w[1], -w[2])
    normals[first + i] = _unit_or(p - q, wp.cross(b - a, c - a))


@wp.kernel
def _edge_edge_contacts(
    # in:
    pairs: wp.array(dtype=wp.vec4i),
    positions: wp.array(dtype=wp.vec3),
    first: int,
    # out:
    vertices: wp.array(dtype=wp.vec4i),
    weights: wp.array(dtype=wp.vec4),
    normals: wp.array(dtype=wp.vec3),
):
    """One thread per edge-edge pair (a0, a1, b0, b1): closest points, weights and normal."""
    i = wp.tid()
    ids = pairs[i]
    a0 = positions[ids[0]]
    a1 = positions[ids[1]]
    b0 = positions[ids[2]]
    b1 = positions[ids[3]]
    st = edge_edge_closest_point(a0, a1, b0, b1)
    vertices[first + i] = ids
    weights[first + i] = wp.vec4(1.0 - st[0], st[0], -(1.0 - st[1]), -st[1])
    normals[first + i] = _unit_or(wp.lerp(a0, a1, st[0]) - wp.lerp(b0, b1, st[1]), wp.cross(a1 - a0, b1 - b0))


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
        for kernel, rows, first in ((_vertex_face_contacts, vf, 0), (_edge_edge_contacts, ee, vf.shape[0])):
            if rows.shape[0]:
                pairs = wp.array(rows, dtype=wp.vec4i, device=self.device)
                wp.launch(kernel, dim=rows.shape[0], inputs=[pairs, positions, first],
                          outputs=[springs.vertices, springs.weights, springs.normals], device=self.device)
        springs.set_count(total)
        return springs
