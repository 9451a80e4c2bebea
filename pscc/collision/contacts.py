"""Device view of the pairs a narrow phase found: what the simulator's kernels read, on the device.

A :class:`CollisionDetector` keeps its candidate pairs and their narrow-phase results on the device.
:class:`DeviceContacts` names those buffers for the consumers that run in the same step (the
inelastic projection, the proximity springs), so nothing is copied to the host in between:

=========================  ===================  ==============================================================
field (``ContactArgs``)    shape, dtype         meaning
=========================  ===================  ==============================================================
faces                      (m,) vec3i           vertex ids of each face of the collision mesh
edges                      (E,) vec2i           vertex ids of each edge (lexicographic edge order)
vertex_face                (Cvf,) vec2i         candidate rows (vertex id, face id)
edge_edge                  (Cee,) vec2i         candidate rows (edge id a, edge id b), a < b
vertex_face_toi            (>= Cvf,) float32    time of impact of each row; the row is a hit iff toi <= 1
edge_edge_toi              (>= Cee,) float32    same for the edge-edge rows
counts                     (2,) int32           rows appended [vertex-face, edge-edge]; may exceed the
                                                buffers (an overflow), so readers clamp with
                                                :func:`vertex_face_rows` / :func:`edge_edge_rows`
=========================  ===================  ==============================================================

Rows are in the order the broad phase appended them: deterministic on the CPU, not on a GPU. The
detector's NumPy results (:class:`pscc.collision.detector.CollisionResult`) are these rows, filtered
to the hits and sorted, copied to the host.
"""

from __future__ import annotations

from dataclasses import dataclass

import warp as wp

wp.set_module_options({"enable_backward": False})


@wp.struct
class ContactArgs:
    """The pair buffers of one narrow phase, for kernels (layout in the module docstring)."""

    faces: wp.array(dtype=wp.vec3i)
    edges: wp.array(dtype=wp.vec2i)
    vertex_face: wp.array(dtype=wp.vec2i)
    edge_edge: wp.array(dtype=wp.vec2i)
    vertex_face_toi: wp.array(dtype=wp.float32)
    edge_edge_toi: wp.array(dtype=wp.float32)
    counts: wp.array(dtype=wp.int32)


@wp.func
def vertex_face_rows(contacts: ContactArgs) -> int:
    """Valid vertex-face rows: the appended count clamped to the buffers."""
    return wp.min(wp.min(contacts.counts[0], contacts.vertex_face.shape[0]), contacts.vertex_face_toi.shape[0])


@wp.func
def edge_edge_rows(contacts: ContactArgs) -> int:
    """Valid edge-edge rows: the appended count clamped to the buffers."""
    return wp.min(wp.min(contacts.counts[1], contacts.edge_edge.shape[0]), contacts.edge_edge_toi.shape[0])


@wp.func
def vertex_face_hit(contacts: ContactArgs, row: int) -> bool:
    """Whether vertex-face row ``row`` is valid and a hit (toi <= 1)."""
    if row >= vertex_face_rows(contacts):
        return False
    return contacts.vertex_face_toi[row] <= 1.0


@wp.func
def edge_edge_hit(contacts: ContactArgs, row: int) -> bool:
    """Whether edge-edge row ``row`` is valid and a hit (toi <= 1)."""
    if row >= edge_edge_rows(contacts):
        return False
    return contacts.edge_edge_toi[row] <= 1.0


@wp.func
def vertex_face_vertices(contacts: ContactArgs, row: int) -> wp.vec4i:
    """Vertex ids (vertex, face corner 0, 1, 2) of vertex-face row ``row``."""
    pair = contacts.vertex_face[row]
    f = contacts.faces[pair[1]]
    return wp.vec4i(pair[0], f[0], f[1], f[2])


@wp.func
def edge_edge_vertices(contacts: ContactArgs, row: int) -> wp.vec4i:
    """Vertex ids (a0, a1, b0, b1) of edge-edge row ``row``."""
    pair = contacts.edge_edge[row]
    a = contacts.edges[pair[0]]
    b = contacts.edges[pair[1]]
    return wp.vec4i(a[0], a[1], b[0], b[1])


@dataclass
class DeviceContacts:
    """The result of a device narrow phase: buffers that stay on the device.

    Attributes:
        args: the buffers as a :class:`ContactArgs` struct (pass it to kernels).
        hit_counts: (2,) int32 device array, [vertex-face hits, edge-edge hits] among the valid rows
            (0 and 0 means the step is collision-free; a device loop condition reads it).
        continuous: whether the narrow phase was a CCD (times of impact in [0, 1]) or a DCD
            (hits have toi 0).
        thickness: the distance the narrow phase tested.
    """

    args: ContactArgs
    hit_counts: wp.array
    continuous: bool
    thickness: float
