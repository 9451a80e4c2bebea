"""A mesh's connectivity on the device, uploaded once and shared by everything that reads it.

The detector, its feature-pair extraction, the intersection check and the contact springs all index
the same collision mesh; one :class:`DeviceTopology` holds its faces, edges and face edges for all of
them instead of a copy each (12 + 8 + 12 bytes per face and edge, several times over).

=============  ==========  ===========================================================
array          dtype       meaning
=============  ==========  ===========================================================
faces          vec3i (m,)  vertex ids of each face
edges          vec2i (e,)  vertex ids of each edge (``MeshTopology.edges``)
face_edges     vec3i (m,)  edge ids of each face's (f0 f1), (f1 f2), (f2 f0)
=============  ==========  ===========================================================
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import warp as wp

from pscc.errors import InputError
from pscc.mesh.topology import MeshTopology


@dataclass(frozen=True, eq=False)
class DeviceTopology:
    """Faces, edges and face edges of one mesh on one device (module docstring).

    Attributes:
        host_faces: (m, 3) int32 the faces uploaded (for checking that a user indexes the same mesh).
        topology: the faces' host :class:`~pscc.mesh.topology.MeshTopology`.
        faces: (m,) vec3i device faces.
        edges: (e,) vec2i device edges.
        face_edges: (m,) vec3i device edge ids per face.
    """

    host_faces: np.ndarray
    topology: MeshTopology
    faces: wp.array
    edges: wp.array
    face_edges: wp.array

    @staticmethod
    def upload(faces: np.ndarray, topology: MeshTopology, device: wp.DeviceLike) -> DeviceTopology:
        """Upload ``faces`` and ``topology`` (built from those faces) to ``device``. Allocates: yes."""
        device = wp.get_device(device)
        host_faces = np.ascontiguousarray(np.asarray(faces, dtype=np.int32).reshape(-1, 3))
        return DeviceTopology(
            host_faces=host_faces,
            topology=topology,
            faces=wp.array(host_faces, dtype=wp.vec3i, device=device),
            edges=wp.array(np.asarray(topology.edges, np.int32).reshape(-1, 2), dtype=wp.vec2i, device=device),
            face_edges=wp.array(np.asarray(topology.face_edges, np.int32).reshape(-1, 3), dtype=wp.vec3i,
                                device=device),
        )

    @property
    def arrays(self) -> tuple[wp.array, wp.array, wp.array]:
        """The three device arrays (faces, edges, face_edges), e.g. to count them once."""
        return self.faces, self.edges, self.face_edges

    def check_same(self, faces: np.ndarray, device: wp.Device, owner: str) -> None:
        """Raise :class:`InputError` unless these are ``faces`` on ``device`` (``owner`` names the
        class that was handed them)."""
        faces = np.asarray(faces).reshape(-1, 3)
        if self.faces.device != device:
            raise InputError("argument", "device_topology", f"is on {self.faces.device}, the {owner} on {device}",
                             "pass the topology uploaded to the same device")
        if faces.shape != self.host_faces.shape or not np.array_equal(faces, self.host_faces):
            raise InputError("argument", "device_topology", f"holds other faces than the {owner}'s",
                             "pass the DeviceTopology of the same collision mesh (or None)")
