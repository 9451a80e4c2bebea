"""DCD proximity pairs -> contact springs for the next implicit step (paper section 5, I-Cloth 2.5).

The detector reports the vertex-face and edge-edge pairs closer than the thickness h at the end
of a step. For each pair this module computes, on the device, the closest points, the signed
weights and the unit normal of the contact (see :mod:`pscc.sim.contact_springs`) at those
positions, and stores them in a :class:`ContactSprings` that the next
:meth:`pscc.sim.ImplicitEuler.step` treats implicitly.

:meth:`ProximityContacts.update_device` reads the narrow phase's rows where they are
(:class:`pscc.collision.contacts.ContactArgs`; a row is a contact iff its toi <= 1) and appends the
springs with the device counter ``ContactSprings.count``: no host read, no upload, capturable. An
overflow keeps counting; :meth:`ProximityContacts.check_capacity` (a sync point) grows the springs
and asks for a re-run. :meth:`ProximityContacts.update` (host rows) is that device path on uploaded
rows.

The normal is the direction between the closest points. A configuration whose closest points
coincide (distance below :data:`pscc.tolerances.CONTACT_NORMAL_MIN_OFFSET`, which the CCD minimum
distance keeps from happening) falls back to the face normal (vertex-face) or the edges' cross product
(edge-edge): :func:`pscc.geometry.contact_weights.contact_normal`, shared with the projection.
"""

from __future__ import annotations

import numpy as np
import warp as wp

from pscc.collision.contacts import (
    ContactArgs,
    edge_edge_hit,
    edge_edge_vertices,
    vertex_face_hit,
    vertex_face_vertices,
)
from pscc.geometry.contact_weights import contact_normal, pair_plane_normal, pair_weights, weighted_sum
from pscc.sim.contact_springs import ContactSprings

wp.set_module_options({"enable_backward": False})


@wp.kernel
def _append_contacts(
    # in:
    contacts: ContactArgs,
    kinematic: wp.array(dtype=wp.int32),
    positions: wp.array(dtype=wp.vec3),
    edge_edge: int,
    # out:
    vertices: wp.array(dtype=wp.vec4i),
    weights: wp.array(dtype=wp.vec4),
    normals: wp.array(dtype=wp.vec3),
    count: wp.array(dtype=wp.int32),
):
    """One thread per vertex-face row of ``contacts`` (edge-edge row when ``edge_edge`` is not 0): a hit
    with a free vertex appends its spring (closest-point weights and unit normal) at the next counter
    slot."""
    row = wp.tid()
    ids = wp.vec4i(0, 0, 0, 0)
    if edge_edge != 0:
        if not edge_edge_hit(contacts, row):
            return
        ids = edge_edge_vertices(contacts, row)
    else:
        if not vertex_face_hit(contacts, row):
            return
        ids = vertex_face_vertices(contacts, row)
    # Pairs made only of kinematic vertices: nothing can respond to them.
    if kinematic[ids[0]] != 0 and kinematic[ids[1]] != 0 and kinematic[ids[2]] != 0 and kinematic[ids[3]] != 0:
        return
    slot = wp.atomic_add(count, 0, 1)
    if slot >= vertices.shape[0]:
        return  # overflow: the counter keeps the true number for check_capacity()
    x0 = positions[ids[0]]
    x1 = positions[ids[1]]
    x2 = positions[ids[2]]
    x3 = positions[ids[3]]
    w = pair_weights(x0, x1, x2, x3, edge_edge)
    vertices[slot] = ids
    weights[slot] = w
    plane = pair_plane_normal(x0, x1, x2, x3, edge_edge)
    normals[slot] = contact_normal(weighted_sum(w, x0, x1, x2, x3), plane, plane)


class ProximityContacts:
    """Builds the contact springs of a step from DCD pairs.

    Device buffers: ``springs`` (:class:`ContactSprings`, its ``count`` the device counter),
    ``kinematic_flags`` (n,) int32 and ``faces_device`` (m,) vec3i, uploaded once.

    Args:
        faces: (m, 3) int32 triangles of the collision mesh (to expand vertex-face rows).
        kinematic: (n,) bool, True for vertices whose motion is prescribed; pairs made only of
            such vertices are dropped (nothing can respond to them).
        rest_gap: the thickness h [m] the springs keep.
        device: Warp device.
    """

    def __init__(self, faces: np.ndarray, kinematic: np.ndarray, rest_gap: float, device: wp.DeviceLike) -> None:
        self.device = wp.get_device(device)
        self.faces = np.asarray(faces, dtype=np.int32).reshape(-1, 3)
        self.kinematic = np.asarray(kinematic, dtype=bool)
        self.faces_device = wp.array(self.faces, dtype=wp.vec3i, device=self.device)
        """(m,) vec3i the collision mesh's faces (for host rows in :meth:`update`)."""
        self.kinematic_flags = wp.array(self.kinematic.astype(np.int32), dtype=wp.int32, device=self.device)
        """(n,) int32 1 for kinematic vertices."""
        self.springs = ContactSprings(0, rest_gap=rest_gap, device=self.device)

    def update_device(self, contacts: ContactArgs, positions: wp.array) -> ContactSprings:
        """Replace the springs with the contacts of the hit rows of ``contacts`` (toi <= 1) at ``positions``.

        Vertex-face rows first, then edge-edge rows, each in row order on the CPU (in the order of the
        atomic appends on a GPU); pairs of kinematic vertices only are dropped. ``springs.count``
        counts past the capacity; :meth:`check_capacity` (a sync point) grows and asks for a re-run.

        Args:
            contacts: the DCD narrow phase's rows (:class:`pscc.collision.contacts.ContactArgs`).
            positions: (n,) vec3 device positions the pairs were found at [m].

        Returns:
            The updated :class:`ContactSprings` (owned by this object).

        Allocates: no. Capture-safe: yes (the graph binds the spring buffers: recapture after
        :meth:`check_capacity` grew them).
        """
        springs = self.springs
        springs.count.zero_()
        for edge_edge, rows in ((0, contacts.vertex_face), (1, contacts.edge_edge)):
            wp.launch(_append_contacts, dim=rows.shape[0],
                      inputs=[contacts, self.kinematic_flags, positions, edge_edge],
                      outputs=[springs.vertices, springs.weights, springs.normals, springs.count],
                      device=self.device)
        return springs

    def check_capacity(self) -> bool:
        """Whether the last :meth:`update_device` stored every spring; grows the springs when not.

        Sync point: reads the spring counter (:meth:`ContactSprings.fits`).

        Returns:
            True when every spring was stored; False when the buffers were grown (1.25 times the
            count), in which case the caller runs :meth:`update_device` again.

        Allocates: only when growing. Capture-safe: no.
        """
        return self.springs.fits()

    def update(self, vertex_face: np.ndarray, edge_edge: np.ndarray, positions: wp.array) -> ContactSprings:
        """Replace the springs with the contacts of these pairs at ``positions`` (:meth:`update_device`
        on uploaded rows, then :meth:`check_capacity`).

        Args:
            vertex_face: (k, 2) rows (vertex, face) from the detector.
            edge_edge: (l, 4) rows (a0, a1, b0, b1) from the detector.
            positions: (n,) vec3 device positions the pairs were found at.

        Returns:
            The updated :class:`ContactSprings` (owned by this object).

        Allocates: yes (uploads the pairs; grows the springs). Capture-safe: no.
        """
        vf = np.ascontiguousarray(vertex_face, dtype=np.int32).reshape(-1, 2)
        ee = np.ascontiguousarray(edge_edge, dtype=np.int32).reshape(-1, 4)
        k, l = int(vf.shape[0]), int(ee.shape[0])
        # Size the springs for the pairs kept, as the device path would after one overflow.
        kept = 0
        if k:
            corners = np.concatenate([vf[:, :1], self.faces[vf[:, 1]]], axis=1)
            kept += int((~self.kinematic[corners].all(axis=1)).sum())
        if l:
            kept += int((~self.kinematic[ee].all(axis=1)).sum())
        self.springs.ensure(kept)
        dev = self.device
        # The rows as a ContactArgs: the mesh's faces, two edges per edge-edge row, every row a hit.
        contacts = ContactArgs()
        contacts.faces = self.faces_device
        contacts.edges = wp.array(ee.reshape(-1, 2), dtype=wp.vec2i, device=dev)
        contacts.vertex_face = wp.array(vf, dtype=wp.vec2i, device=dev)
        contacts.edge_edge = wp.array(np.arange(2 * l, dtype=np.int32).reshape(-1, 2), dtype=wp.vec2i, device=dev)
        contacts.vertex_face_toi = wp.zeros(k, dtype=float, device=dev)
        contacts.edge_edge_toi = wp.zeros(l, dtype=float, device=dev)
        contacts.counts = wp.array(np.array([k, l], dtype=np.int32), dtype=wp.int32, device=dev)
        while True:
            springs = self.update_device(contacts, positions)
            if self.check_capacity():
                return springs
