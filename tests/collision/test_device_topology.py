"""One copy of the collision mesh's connectivity on the device (pscc.collision.device_topology)."""

from __future__ import annotations

import numpy as np
import pytest
import warp as wp

from pscc.collision.device_topology import DeviceTopology
from pscc.collision.intersection import IntersectionCheck
from pscc.errors import InputError
from pscc.mesh.topology import MeshTopology
from pscc.scenes import build_scene
from pscc.sim.memory import warp_array_bytes
from pscc.sim.proximity import ProximityContacts
from pscc.sim.solver import ClothSolver


def test_the_solver_uploads_the_collision_mesh_once_and_counts_it_once_and_shares_the_face_boxes() -> None:
    scene = build_scene("drape", 400)
    solver = ClothSolver(scene, device="cpu")
    shared = solver.detector.device_topology
    assert solver.intersection_check.device_topology is shared and solver.proximity.device_topology is shared
    assert solver.intersection_check.faces is shared.faces and solver.intersection_check.edges is shared.edges
    assert solver.proximity.faces_device is shared.faces and solver.proximity.face_edges is shared.face_edges
    assert solver.detector.feature_pairs.face_edges is shared.face_edges
    assert solver.detector.spatial_hash.faces is shared.faces
    # The check computes its face boxes in the detector's (dead after each broad phase).
    assert solver.intersection_check.face_lower is solver.detector.boxes.face_lower
    assert solver.intersection_check.face_upper is solver.detector.boxes.face_upper
    np.testing.assert_array_equal(shared.faces.numpy(), solver.collision_faces)
    np.testing.assert_array_equal(shared.edges.numpy(), shared.topology.edges)
    # The detector counts the three arrays; nobody else does.
    topology_bytes = sum(a.capacity for a in shared.arrays)
    check = solver.intersection_check
    box_bytes = check.face_lower.capacity + check.face_upper.capacity
    # ... and the stitch partners (none here), the detector's too.
    assert check.seams is solver.detector.seams
    seam_bytes = solver.detector.seams.device_bytes
    with_topology = warp_array_bytes(check, seen={id(check.spatial_hash)})
    assert solver.device_bytes()["intersection_check"] == with_topology - topology_bytes - box_bytes - seam_bytes
    assert solver.detector.spatial_hash.device_bytes["faces"] == 0


def test_a_topology_of_other_faces_or_another_device_is_refused() -> None:
    faces = np.array([[0, 1, 2], [1, 3, 2]], np.int32)
    other = np.array([[0, 1, 2], [2, 1, 3]], np.int32)
    topology = DeviceTopology.upload(faces, MeshTopology.from_faces(faces, 4), "cpu")
    with pytest.raises(InputError, match="device_topology: holds other faces"):
        IntersectionCheck(other, 4, "cpu", device_topology=topology)
    with pytest.raises(InputError, match="face_boxes: got array, not two arrays"):
        IntersectionCheck(faces, 4, "cpu", face_boxes=wp.empty(2, dtype=wp.vec3))
    with pytest.raises(InputError, match=r"face_boxes\[1\]"):
        IntersectionCheck(faces, 4, "cpu", face_boxes=(wp.empty(2, dtype=wp.vec3), wp.empty(3, dtype=wp.vec3)))
    with pytest.raises(InputError, match="device_topology: holds other faces"):
        ProximityContacts(other[:1], np.zeros(4, bool), 0.01, "cpu", device_topology=topology)
    check = IntersectionCheck(faces, 4, "cpu", device_topology=topology)
    assert check.faces is topology.faces
    x = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]], np.float32)
    assert check.find(wp.array(x, dtype=wp.vec3)).shape[0] == 0
