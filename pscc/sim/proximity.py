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

**One spring per contact.** A vertex over a face's interior, or two edges crossing between their ends,
is reported by one row. A contact at a face's edge or corner (closest barycentric weights 0) or at an
edge's end (parameter 0 or 1), both up to :data:`pscc.tolerances.CONTACT_FEATURE_WEIGHT`, is reported
by every face around that edge or corner and every edge around that end: on layered cloth most rows.
Such rows carry the key of their closest features (vertex-edge: vertex and edge id; vertex-vertex:
both vertex ids) into a hash table (:class:`ContactSprings` owns it, one slot per spring slot, linear
probing with ``atomic_cas``); the first row of a key appends the spring, the others only count, and a
last pass writes the count as the spring's ``multiplicity``, the factor on its stiffness. The forces
and the matrix are those of one spring per row, as before the merge (the duplicates of a contact
share its closest points), in a third to a quarter of the memory on layered cloth. A key that finds
no free slot within :data:`MERGE_PROBES` probes gets its own spring (multiplicity 1): never a lost
contact.

The normal is the direction between the closest points. A configuration whose closest points
coincide (distance below :data:`pscc.tolerances.CONTACT_NORMAL_MIN_OFFSET`, which the CCD minimum
distance keeps from happening) falls back to the face normal (vertex-face) or the edges' cross product
(edge-edge): :func:`pscc.geometry.contact_weights.contact_normal`, shared with the projection.
"""

from __future__ import annotations

import numpy as np
import warp as wp

from pscc import tolerances
from pscc._lanes import row_lanes
from pscc.collision.contacts import (
    ContactArgs,
    DeviceContacts,
    edge_edge_rows,
    edge_edge_vertices,
    vertex_face_rows,
    vertex_face_vertices,
)
from pscc.collision.device_topology import DeviceTopology
from pscc.collision.narrow_phase import (
    ProximityTest,
    edge_edge_proximity_toi,
    edges_certified_apart,
    vertex_face_proximity_toi,
)
from pscc.geometry.ccd import NO_HIT
from pscc.geometry.contact_weights import contact_normal, pair_plane_normal, pair_weights, weighted_sum
from pscc.geometry.distance import edge_edge_closest_point, vertex_face_closest_point
from pscc.mesh.topology import MeshTopology
from pscc.sim.contact_springs import ContactSprings, MergeTable

wp.set_module_options({"enable_backward": False})

MERGE_PROBES: int = 32
"""Slots a contact key probes in the merge table before it gives up merging (its row then gets a spring
of its own)."""

_FEATURE_WEIGHT = wp.constant(tolerances.CONTACT_FEATURE_WEIGHT)
_PROBES = wp.constant(MERGE_PROBES)
_ID_LIMIT = wp.constant(wp.int64(1 << 30))


@wp.func
def _pack_key(kind: int, a: int, b: int) -> wp.int64:
    """Key of a contact: ``kind`` (1 vertex-edge, 2 vertex-vertex) and two ids below 2^30; -1 (no
    merge) for larger ids."""
    if wp.int64(a) >= _ID_LIMIT or wp.int64(b) >= _ID_LIMIT:
        return wp.int64(-1)
    return (wp.int64(kind) << wp.int64(60)) | (wp.int64(a) << wp.int64(30)) | wp.int64(b)


@wp.func
def _vertex_vertex_key(a: int, b: int) -> wp.int64:
    return _pack_key(2, wp.min(a, b), wp.max(a, b))


@wp.func
def _vertex_face_key(face_edges: wp.array(dtype=wp.vec3i), ids: wp.vec4i, face: int, w: wp.vec4) -> wp.int64:
    """Key of a vertex-face row's contact (module docstring); -1 for a face-interior contact."""
    zeros = int(0)
    zero = int(0)
    corner = int(0)
    for k in range(3):
        if -w[k + 1] <= _FEATURE_WEIGHT:
            zeros += 1
            zero = k
        else:
            corner = k
    if zeros == 0:
        return wp.int64(-1)
    if zeros == 1:  # on the edge opposite corner `zero`: face_edges lists (f0 f1), (f1 f2), (f2 f0)
        return _pack_key(1, ids[0], face_edges[face][(zero + 1) % 3])
    return _vertex_vertex_key(ids[0], ids[1 + corner])


@wp.func
def _edge_edge_key(ids: wp.vec4i, edges: wp.vec2i, w: wp.vec4) -> wp.int64:
    """Key of an edge-edge row's contact (module docstring); -1 when both closest points are inside their
    edges. ``w`` is ``(1 - s, s, -(1 - t), -t)``; ``edges`` the two edge ids."""
    a = int(-1)
    if w[1] <= _FEATURE_WEIGHT:
        a = ids[0]
    elif w[0] <= _FEATURE_WEIGHT:
        a = ids[1]
    b = int(-1)
    if -w[3] <= _FEATURE_WEIGHT:
        b = ids[2]
    elif -w[2] <= _FEATURE_WEIGHT:
        b = ids[3]
    if a >= 0 and b >= 0:
        return _vertex_vertex_key(a, b)
    if a >= 0:
        return _pack_key(1, a, edges[1])
    if b >= 0:
        return _pack_key(1, b, edges[0])
    return wp.int64(-1)


@wp.func
def _merge_slot(table: MergeTable, key: wp.int64) -> wp.vec2i:
    """(slot, 1) when this call put ``key`` into the table, (slot, 0) when it was there, (-1, 0) when
    :data:`MERGE_PROBES` slots were taken by other keys."""
    size = table.keys.shape[0]
    start = int((wp.uint64(key) * wp.uint64(0x9E3779B97F4A7C15)) >> wp.uint64(33)) % size
    for probe in range(_PROBES):
        slot = (start + probe) % size
        old = wp.atomic_cas(table.keys, slot, wp.int64(-1), key)
        if old == wp.int64(-1):
            return wp.vec2i(slot, 1)
        if old == key:
            return wp.vec2i(slot, 0)
    return wp.vec2i(-1, 0)


@wp.struct
class SpringArrays:
    """The spring buffers a kernel appends to (:class:`ContactSprings`)."""

    vertices: wp.array(dtype=wp.vec4i)
    weights: wp.array(dtype=wp.vec4)
    normals: wp.array(dtype=wp.vec3)
    multiplicity: wp.array(dtype=wp.int32)
    count: wp.array(dtype=wp.int32)


@wp.func
def _append_hit(
    contacts: ContactArgs,
    kinematic: wp.array(dtype=wp.int32),
    face_edges: wp.array(dtype=wp.vec3i),
    merge: int,
    table: MergeTable,
    springs: SpringArrays,
    edge_edge: int,
    row: int,
    ids: wp.vec4i,
    x0: wp.vec3,
    x1: wp.vec3,
    x2: wp.vec3,
    x3: wp.vec3,
    w: wp.vec4,
):
    """A hit row (vertex ids ``ids`` at ``x0..x3``, closest-point weights ``w``): unless all four vertices
    are kinematic, append its spring at the next counter slot, or, when an earlier row of the same edge or
    corner contact did (module docstring), only count it in the merge table."""
    # Pairs made only of kinematic vertices: nothing can respond to them.
    if kinematic[ids[0]] != 0 and kinematic[ids[1]] != 0 and kinematic[ids[2]] != 0 and kinematic[ids[3]] != 0:
        return
    key = wp.int64(-1)  # no merge: a face-interior or edges-interior contact, or merge off
    if merge != 0:
        if edge_edge != 0:
            key = _edge_edge_key(ids, contacts.edge_edge[row], w)
        else:
            key = _vertex_face_key(face_edges, ids, contacts.vertex_face[row][1], w)
    merged = int(1)  # the multiplicity, or -(table slot + 2) until _write_multiplicity
    if key >= wp.int64(0):
        found = _merge_slot(table, key)
        if found[0] >= 0:
            wp.atomic_add(table.counts, found[0], 1)
            if found[1] == 0:
                return  # counted in the spring of the row that put the key there
            merged = -(found[0] + 2)
    slot = wp.atomic_add(springs.count, 0, 1)
    if slot >= springs.vertices.shape[0]:
        return  # overflow: the counter keeps the true number for check_capacity()
    springs.vertices[slot] = ids
    springs.weights[slot] = w
    springs.multiplicity[slot] = merged
    plane = pair_plane_normal(x0, x1, x2, x3, edge_edge)
    springs.normals[slot] = contact_normal(weighted_sum(w, x0, x1, x2, x3), plane, plane)


@wp.func
def _row_of(r: int, vertex_face_count: int) -> wp.vec2i:
    """(0, r) for the r-th vertex-face row, (1, r - count) for an edge-edge row (the rows of one pass)."""
    if r >= vertex_face_count:
        return wp.vec2i(1, r - vertex_face_count)
    return wp.vec2i(0, r)


@wp.func
def _row_vertices(contacts: ContactArgs, kind_row: wp.vec2i) -> wp.vec4i:
    """The four vertex ids of a row of :func:`_row_of`."""
    if kind_row[0] != 0:
        return edge_edge_vertices(contacts, kind_row[1])
    return vertex_face_vertices(contacts, kind_row[1])


@wp.kernel
def _append_contacts(
    # in:
    contacts: ContactArgs,
    kinematic: wp.array(dtype=wp.int32),
    positions: wp.array(dtype=wp.vec3),
    face_edges: wp.array(dtype=wp.vec3i),
    merge: int,
    lanes: int,
    # out:
    table: MergeTable,
    springs: SpringArrays,
):
    """Row kernel (:mod:`pscc._lanes`) over the valid vertex-face rows of ``contacts`` followed by its valid
    edge-edge rows (on the CPU, one thread takes them all in that order): every hit (toi <= 1) goes
    through :func:`_append_hit` with its closest-point weights."""
    vertex_face_count = vertex_face_rows(contacts)
    for r in range(wp.tid(), vertex_face_count + edge_edge_rows(contacts), lanes):
        kind_row = _row_of(r, vertex_face_count)
        edge_edge = kind_row[0]
        row = kind_row[1]
        toi = contacts.vertex_face_toi[row] if edge_edge == 0 else contacts.edge_edge_toi[row]
        if toi > 1.0:
            continue
        ids = _row_vertices(contacts, kind_row)
        x0 = positions[ids[0]]
        x1 = positions[ids[1]]
        x2 = positions[ids[2]]
        x3 = positions[ids[3]]
        _append_hit(contacts, kinematic, face_edges, merge, table, springs, edge_edge, row, ids, x0, x1, x2, x3,
                    pair_weights(x0, x1, x2, x3, edge_edge))


@wp.kernel
def _test_and_append(
    # in:
    contacts: ContactArgs,
    kinematic: wp.array(dtype=wp.int32),
    positions: wp.array(dtype=wp.vec3),
    face_edges: wp.array(dtype=wp.vec3i),
    test: ProximityTest,
    merge: int,
    lanes: int,
    # out:
    hit_counts: wp.array(dtype=wp.int32),
    table: MergeTable,
    springs: SpringArrays,
):
    """The DCD and :func:`_append_contacts` in one pass, each pair's closest points found once: row kernel
    over the valid vertex-face rows, then the edge-edge rows; each row gets the narrow phase's discrete
    test (:func:`pscc.collision.narrow_phase.vertex_face_proximity_toi` / ``edge_edge_proximity_toi``, the
    time of impact written and the hit counted as :meth:`NarrowPhase.run_device` does), and a hit its
    spring."""
    vertex_face_count = vertex_face_rows(contacts)
    for r in range(wp.tid(), vertex_face_count + edge_edge_rows(contacts), lanes):
        kind_row = _row_of(r, vertex_face_count)
        edge_edge = kind_row[0]
        row = kind_row[1]
        ids = _row_vertices(contacts, kind_row)
        x0 = positions[ids[0]]
        x1 = positions[ids[1]]
        x2 = positions[ids[2]]
        x3 = positions[ids[3]]
        toi = float(0.0)
        w = wp.vec4(0.0)
        if edge_edge != 0:
            toi = float(NO_HIT)  # certified apart: the narrow phase's own test, bit for bit
            if not edges_certified_apart(x0, x1, x2, x3, test.thickness, test.proximity):
                st = edge_edge_closest_point(x0, x1, x2, x3)
                toi = edge_edge_proximity_toi(x0, x1, x2, x3, st, test.thickness, test.proximity)
                w = wp.vec4(1.0 - st[0], st[0], -(1.0 - st[1]), -st[1])
            contacts.edge_edge_toi[row] = toi
        else:
            closest = vertex_face_closest_point(x0, x1, x2, x3)
            toi = vertex_face_proximity_toi(x0, x1, x2, x3, closest, test.thickness, test.params, test.proximity)
            contacts.vertex_face_toi[row] = toi
            w = wp.vec4(1.0, -closest[0], -closest[1], -closest[2])
        if toi <= 1.0:
            wp.atomic_add(hit_counts, edge_edge, 1)
            _append_hit(contacts, kinematic, face_edges, merge, table, springs, edge_edge, row, ids, x0, x1, x2, x3,
                        w)


@wp.kernel
def _write_multiplicity(
    # in:
    counts: wp.array(dtype=wp.int32),
    count: wp.array(dtype=wp.int32),
    lanes: int,
    # out:
    multiplicity: wp.array(dtype=wp.int32),
):
    """Row kernel (:mod:`pscc._lanes`) over the stored springs: a merged spring's table slot becomes the
    number of rows it stands for."""
    for c in range(wp.tid(), wp.min(count[0], multiplicity.shape[0]), lanes):
        m = multiplicity[c]
        if m < 0:
            multiplicity[c] = counts[-m - 2]


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
        topology: the faces' :class:`pscc.mesh.topology.MeshTopology`, whose edge ids the detector's
            edge-edge rows use (built here when not given).
        merge: one spring per contact (default) or, with False, one per row.
        device_topology: the faces' :class:`~pscc.collision.device_topology.DeviceTopology` (e.g. the
            detector's) to share instead of uploading the faces and face edges again; its host topology
            then stands for ``topology``.
    """

    def __init__(self, faces: np.ndarray, kinematic: np.ndarray, rest_gap: float, device: wp.DeviceLike,
                 topology: MeshTopology | None = None, merge: bool = True,
                 device_topology: DeviceTopology | None = None) -> None:
        self.device = wp.get_device(device)
        self.merge = bool(merge)
        """Whether the rows of one edge or corner contact become one spring (module docstring); False
        gives one spring per row, the reference the merged springs are tested against."""
        self.faces = np.asarray(faces, dtype=np.int32).reshape(-1, 3)
        self.kinematic = np.asarray(kinematic, dtype=bool)
        if device_topology is not None:
            topology = device_topology.topology
        elif topology is None:
            topology = MeshTopology.from_faces(self.faces, self.kinematic.shape[0])
        if device_topology is None:
            device_topology = DeviceTopology.upload(self.faces, topology, self.device)
        device_topology.check_same(self.faces, self.device, "contact springs")
        self._edges = np.asarray(topology.edges, dtype=np.int32).reshape(-1, 2)
        self.device_topology = device_topology
        """The collision mesh's faces, edges and face edges on the device (the caller's when it passed them)."""
        self.faces_device = device_topology.faces
        """(m,) vec3i the collision mesh's faces (for host rows in :meth:`update`)."""
        self.face_edges = device_topology.face_edges
        """(m,) vec3i edge ids of each face's (f0 f1), (f1 f2), (f2 f0): the edge of a vertex-edge key."""
        self.kinematic_flags = wp.array(self.kinematic.astype(np.int32), dtype=wp.int32, device=self.device)
        """(n,) int32 1 for kinematic vertices."""
        self.springs = ContactSprings(0, rest_gap=rest_gap, device=self.device)

    def update_device(self, contacts: ContactArgs, positions: wp.array) -> ContactSprings:
        """Replace the springs with the contacts of the hit rows of ``contacts`` (toi <= 1) at ``positions``.

        Vertex-face rows first, then edge-edge rows, each in row order on the CPU (in the order of the
        atomic appends on a GPU); pairs of kinematic vertices only are dropped, and the rows of one edge
        or corner contact become one spring with their count as its multiplicity (module docstring; on
        a GPU, which of the rows gives the spring varies). ``springs.count`` counts past the capacity;
        :meth:`check_capacity` (a sync point) grows and asks for a re-run (an overflowing run's count can
        exceed the need: its merge table, one slot per spring slot, may have been too small to merge).

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
        table = springs.merge_table()
        table.keys.fill_(-1)
        table.counts.zero_()
        lanes = row_lanes(self.device, contacts.vertex_face.shape[0] + contacts.edge_edge.shape[0])
        wp.launch(_append_contacts, dim=lanes,
                  inputs=[contacts, self.kinematic_flags, positions, self.face_edges, int(self.merge), lanes],
                  outputs=[table, self._spring_arrays()], device=self.device)
        self._finish(table)
        return springs

    def test_and_update_device(self, contacts: DeviceContacts, positions: wp.array,
                               test: ProximityTest) -> ContactSprings:
        """The DCD of ``contacts`` and :meth:`update_device` in one pass over the rows (each pair's closest
        points found once): ``contacts`` comes from a narrow phase that left its DCD to this call
        (``CollisionDetector.narrow_phase_device(..., defer_dcd=True)``), ``test`` is that narrow phase's
        :meth:`~pscc.collision.narrow_phase.NarrowPhase.proximity_test`. The times of impact, the hit
        counts and the springs are bit for bit those of the DCD followed by :meth:`update_device`.

        Allocates: no. Capture-safe: yes (as :meth:`update_device`).
        """
        springs = self.springs
        springs.count.zero_()
        table = springs.merge_table()
        table.keys.fill_(-1)
        table.counts.zero_()
        args = contacts.args
        lanes = row_lanes(self.device, args.vertex_face.shape[0] + args.edge_edge.shape[0])
        wp.launch(_test_and_append, dim=lanes,
                  inputs=[args, self.kinematic_flags, positions, self.face_edges, test, int(self.merge), lanes],
                  outputs=[contacts.hit_counts, table, self._spring_arrays()], device=self.device)
        self._finish(table)
        return springs

    def _spring_arrays(self) -> SpringArrays:
        springs = self.springs
        arrays = SpringArrays()
        arrays.vertices = springs.vertices
        arrays.weights = springs.weights
        arrays.normals = springs.normals
        arrays.multiplicity = springs.multiplicity
        arrays.count = springs.count
        return arrays

    def _finish(self, table: MergeTable) -> None:
        """Merged springs' table slots become their multiplicities."""
        springs = self.springs
        lanes = row_lanes(self.device, springs.capacity)
        wp.launch(_write_multiplicity, dim=lanes, inputs=[table.counts, springs.count, lanes],
                  outputs=[springs.multiplicity], device=self.device)

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
        # The rows as a ContactArgs: the mesh's faces and edges (edges of a row that the mesh lacks
        # appended), every row a hit.
        edges, edge_ids = self._edge_ids(ee.reshape(-1, 2))
        contacts = ContactArgs()
        contacts.faces = self.faces_device
        contacts.edges = wp.array(edges, dtype=wp.vec2i, device=dev)
        contacts.vertex_face = wp.array(vf, dtype=wp.vec2i, device=dev)
        contacts.edge_edge = wp.array(edge_ids.reshape(-1, 2), dtype=wp.vec2i, device=dev)
        contacts.vertex_face_toi = wp.zeros(k, dtype=float, device=dev)
        contacts.edge_edge_toi = wp.zeros(l, dtype=float, device=dev)
        contacts.counts = wp.array(np.array([k, l], dtype=np.int32), dtype=wp.int32, device=dev)
        while True:
            springs = self.update_device(contacts, positions)
            if self.check_capacity():
                return springs

    def _edge_ids(self, pairs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The mesh's edges with the vertex pairs it lacks appended, and the id of each pair in that list."""
        edges = self._edges
        if pairs.shape[0] == 0:
            return (edges if edges.shape[0] else np.zeros((1, 2), np.int32)), np.zeros(0, np.int32)
        ordered = pairs.astype(np.int64)  # as given: a row's vertex order is kept (mesh edges have a < b)
        count = int(max(int(ordered.max()), int(edges.max()) if edges.size else 0)) + 1
        codes = edges[:, 0].astype(np.int64) * count + edges[:, 1]  # sorted: edges are lexicographic
        wanted = ordered[:, 0] * count + ordered[:, 1]
        at = np.searchsorted(codes, wanted)
        found = (at < codes.shape[0]) & (codes[np.minimum(at, codes.shape[0] - 1)] == wanted)
        extra, inverse = np.unique(wanted[~found], return_inverse=True)
        ids = at.astype(np.int32)
        ids[~found] = edges.shape[0] + inverse.astype(np.int32)
        extra_edges = np.stack([extra // count, extra % count], axis=1).astype(np.int32)
        return np.concatenate([edges, extra_edges]), ids
