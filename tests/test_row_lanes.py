"""Row kernels (:mod:`pscc._lanes`) give the same results whatever the launch shape.

On the CPU a row kernel runs as one thread over every row; on a GPU as one thread per row slot. The
tests here force the GPU's shape (and a stride of 7, several rows per thread) on the CPU and compare
with the CPU's own: the detector's pairs and times of impact, the intersection check's crossings and
the contact springs are the same sets, and a simulated frame the same up to float32 summation order
(atomic additions then come in another order)."""

from __future__ import annotations

from collections.abc import Callable, Iterator
from contextlib import contextmanager

import numpy as np
import pytest
import warp as wp

from pscc.collision import feature_pairs, intersection, narrow_phase
from pscc.collision.detector import CollisionDetector
from pscc.collision.intersection import IntersectionCheck
from pscc.mesh.generate import folded_sheet, grid_sheet
from pscc.scenes import build_scene
from pscc.sim import assembly, proximity
from pscc.sim.proximity import ProximityContacts
from pscc.sim.simulation import Simulation
from tests.sim.contact_rows import contact_args

USERS = (feature_pairs, intersection, narrow_phase, assembly, proximity)
"""Every module that launches row kernels."""

SHAPES: dict[str, Callable[[wp.Device, int], int]] = {
    "one per slot (a GPU's shape)": lambda device, capacity: max(int(capacity), 1),
    "stride 7": lambda device, capacity: min(max(int(capacity), 1), 7),
}


@contextmanager
def _lanes(shape: Callable[[wp.Device, int], int]) -> Iterator[None]:
    with pytest.MonkeyPatch.context() as patch:
        for module in USERS:
            patch.setattr(module, "row_lanes", shape)
        yield


def _detect(mesh, method: str) -> list[np.ndarray]:
    detector = CollisionDetector(mesh.faces, method=method, device="cpu")
    ccd = detector.detect(mesh.vertices, mesh.vertices_end)
    ccd_hits = detector.narrow.hit_counts.numpy().copy()
    dcd = detector.detect(mesh.vertices_end, thickness=0.02)
    dcd_hits = detector.narrow.hit_counts.numpy().copy()
    return [ccd.vertex_face, ccd.edge_edge, ccd.vertex_face_toi, ccd.edge_edge_toi, ccd_hits, dcd.vertex_face,
            dcd.edge_edge, dcd_hits]


@pytest.mark.parametrize("method", ["pscc", "brute-force"])
def test_detector_pairs_do_not_depend_on_the_launch_shape(method: str) -> None:
    mesh = folded_sheet(600, layers=3, seed=2)
    reference = _detect(mesh, method)
    assert len(reference[0]) + len(reference[1]) > 0 and len(reference[5]) + len(reference[6]) > 0
    np.testing.assert_array_equal(reference[4], [len(reference[0]), len(reference[1])])  # the device hit counts
    for name, shape in SHAPES.items():
        with _lanes(shape):
            for got, want in zip(_detect(mesh, method), reference, strict=True):
                np.testing.assert_array_equal(got, want, err_msg=name)


def test_intersection_check_does_not_depend_on_the_launch_shape() -> None:
    vertices, faces, _ = grid_sheet(12, 12)
    crossing = np.concatenate([vertices, vertices @ np.array([[1, 0, 0], [0, 0, 1], [0, 1, 0]], np.float32)
                               + np.array([0.0, 0.5, -0.5], np.float32)])
    both = np.concatenate([faces, faces + len(vertices)])
    reference = IntersectionCheck(both, len(crossing), "cpu").find(crossing)
    assert len(reference) > 0
    for name, shape in SHAPES.items():
        with _lanes(shape):
            found = IntersectionCheck(both, len(crossing), "cpu").find(crossing)
        np.testing.assert_array_equal(found, reference, err_msg=name)


def _springs(merge: bool, rows) -> tuple[np.ndarray, ...]:
    x, kinematic, faces, edges, contacts = rows
    springs = ProximityContacts(faces, kinematic, 0.01, "cpu", merge=merge)
    positions = wp.array(x, dtype=wp.vec3)
    built = springs.update_device(contacts, positions)
    while not springs.check_capacity():
        built = springs.update_device(contacts, positions)
    count = built.host_count
    arrays = (built.vertices.numpy()[:count], built.weights.numpy()[:count], built.normals.numpy()[:count],
              built.multiplicity.numpy()[:count])
    # Sorted by every field (one vertex tuple can come from a vertex-face and an edge-edge row).
    keys = np.concatenate([a.reshape(count, -1).view(np.int32) for a in arrays], axis=1)
    order = np.lexsort(keys.T[::-1])
    return tuple(a[order] for a in arrays)


def test_contact_springs_do_not_depend_on_the_launch_shape() -> None:
    # A layered sheet's DCD rows: vertex-face and edge-edge, at face corners and edges (merged) and inside.
    mesh = folded_sheet(400, layers=3, seed=5)
    detector = CollisionDetector(mesh.faces, device="cpu")
    result = detector.detect(mesh.vertices, thickness=0.5 * float(np.ptp(mesh.vertices[:, 2])))
    topology = detector.topology
    edge_ids = {tuple(e): k for k, e in enumerate(topology.edges.tolist())}
    edge_edge = np.array([[edge_ids[tuple(r[:2])], edge_ids[tuple(r[2:])]] for r in result.edge_edge.tolist()],
                         np.int32).reshape(-1, 2)
    contacts = contact_args("cpu", mesh.faces, topology.edges, result.vertex_face,
                            np.zeros(len(result.vertex_face)), edge_edge, np.zeros(len(edge_edge)))
    rows = (mesh.vertices, np.zeros(len(mesh.vertices), bool), mesh.faces, topology.edges, contacts)
    unmerged = _springs(False, rows)
    merged = _springs(True, rows)
    assert len(unmerged[0]) > len(merged[0]) > 0  # some rows were merged
    for name, shape in SHAPES.items():
        with _lanes(shape):
            for got, want in zip(_springs(False, rows), unmerged, strict=True):
                np.testing.assert_array_equal(got, want, err_msg=name)
            # Merged: which row of a contact gives its spring depends on the order; the contacts and the
            # rows they stand for do not.
            got = _springs(True, rows)
            assert len(got[0]) == len(merged[0]), name
            np.testing.assert_array_equal(np.sort(got[3]), np.sort(merged[3]), err_msg=name)


def _frames(frames: int) -> list[np.ndarray]:
    sim = Simulation(build_scene("stack", 300), device="cpu", graph=False)
    out = []
    for _ in range(frames):
        sim.step_frame()
        out.append(sim.state.positions.numpy().copy())
    assert sim.solver.intersection_check.find(out[-1]).shape == (0, 2)
    return out


def test_a_simulated_frame_does_not_depend_on_the_launch_shape() -> None:
    reference = _frames(3)
    with _lanes(SHAPES["one per slot (a GPU's shape)"]):
        frames = _frames(3)
    for got, want in zip(frames, reference, strict=True):
        np.testing.assert_allclose(got, want, rtol=0, atol=2e-5)
