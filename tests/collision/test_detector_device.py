"""``CollisionDetector`` with device arrays in and out: the same pairs as the NumPy API, recordable into
a graph, nothing read back inside a capture, and overflows grown instead of dropped."""

from __future__ import annotations

import numpy as np
import pytest
import warp as wp

from pscc.bench.host_traffic import count_host_traffic
from pscc.collision.contacts import DeviceContacts
from pscc.collision.detector import METHODS, CollisionDetector
from pscc.mesh import folded_sheet


def _same(a, b) -> None:
    np.testing.assert_array_equal(a.vertex_face, b.vertex_face)
    np.testing.assert_array_equal(a.edge_edge, b.edge_edge)
    if a.vertex_face_toi is not None:
        np.testing.assert_array_equal(a.vertex_face_toi, b.vertex_face_toi)
        np.testing.assert_array_equal(a.edge_edge_toi, b.edge_edge_toi)


@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize("mode", ["ccd", "dcd"])
def test_device_arrays_give_the_pairs_of_the_numpy_api(method: str, mode: str, device: str) -> None:
    mesh = folded_sheet(600, layers=3, seed=3)
    start = mesh.vertices if mode == "ccd" else mesh.vertices_end  # DCD at the pressed end state
    end = mesh.vertices_end if mode == "ccd" else None
    thickness = 0.0 if mode == "ccd" else 0.03
    reference = CollisionDetector(mesh.faces, method=method, device=device).detect(start, end, thickness)
    detector = CollisionDetector(mesh.faces, method=method, device=device)
    x0 = wp.array(start, dtype=wp.vec3, device=device)
    x1 = None if end is None else wp.array(end, dtype=wp.vec3, device=device)
    contacts = detector.detect(x0, x1, thickness)
    assert isinstance(contacts, DeviceContacts) and contacts.continuous == (mode == "ccd")
    hits = contacts.hit_counts.numpy()
    result = detector.collect(contacts)
    assert int(hits.sum()) == result.vertex_face.shape[0] + result.edge_edge.shape[0]
    assert result.vertex_face.shape[0] + result.edge_edge.shape[0] > 0
    if device == "cpu":
        _same(result, reference)
    else:  # float atomics and append order differ on a GPU; the pair sets may not
        assert {tuple(r) for r in result.vertex_face} == {tuple(r) for r in reference.vertex_face}


def test_a_recorded_detection_replays_on_new_positions_without_reading_anything(device: str) -> None:
    first, second = folded_sheet(600, layers=3, seed=1), folded_sheet(600, layers=3, seed=1)
    detector = CollisionDetector(first.faces, device=device)
    x0 = wp.array(first.vertices, dtype=wp.vec3, device=device)
    x1 = wp.array(first.vertices_end, dtype=wp.vec3, device=device)
    detector.detect(x0, x1)  # sizes every buffer
    with count_host_traffic() as counts, wp.ScopedCapture(device=device) as capture:
        contacts = detector.detect(x0, x1)
    assert counts == {"reads": 0, "syncs": 0, "uploads": 0, "allocations": 0}
    # New positions in the same arrays (a later step): the replay must find that step's pairs.
    moved = second.vertices_end + np.float32(0.002) * np.sin(second.vertices * 40.0).astype(np.float32)
    x1.assign(moved)
    wp.capture_launch(capture.graph)
    assert detector.check_capacity()
    replayed = detector.collect(contacts)
    eager = CollisionDetector(first.faces, device=device).detect(first.vertices, moved)
    if device == "cpu":
        _same(replayed, eager)
    else:
        assert {tuple(r) for r in replayed.edge_edge} == {tuple(r) for r in eager.edge_edge}


def test_an_overflow_outside_a_capture_is_grown_and_the_call_repeated() -> None:
    mesh = folded_sheet(600, layers=3, seed=2)
    detector = CollisionDetector(mesh.faces, device="cpu")
    detector.prepare(mesh.vertices)
    detector.candidates.vertex_face = wp.empty(3, dtype=wp.vec2i, device="cpu")
    detector.candidates.edge_edge = wp.empty(3, dtype=wp.vec2i, device="cpu")
    x0 = wp.array(mesh.vertices, dtype=wp.vec3, device="cpu")
    x1 = wp.array(mesh.vertices_end, dtype=wp.vec3, device="cpu")
    result = detector.collect(detector.detect(x0, x1))
    assert detector.candidates.capacity_vf > 3 and detector.candidates.capacity_ee > 3
    _same(result, CollisionDetector(mesh.faces, device="cpu").detect(mesh.vertices, mesh.vertices_end))


def test_wrong_device_arrays_are_refused_by_name() -> None:
    mesh = folded_sheet(200, layers=2, seed=0)
    detector = CollisionDetector(mesh.faces, device="cpu")
    detector.prepare(mesh.vertices)
    with pytest.raises(Exception, match="positions_t0"):
        detector.detect(wp.array(mesh.vertices[:-1], dtype=wp.vec3, device="cpu"))


def test_a_shared_hash_serves_the_detector_and_the_intersection_check() -> None:
    from pscc.collision.intersection import IntersectionCheck

    mesh = folded_sheet(800, layers=3, seed=4)
    n = mesh.vertices.shape[0]
    # One BVH for both detectors (the rest layout): pscc's DCD may leave pairs inside a certified node
    # unreported, so detectors with different trees may differ (tests/collision/test_pscc.py's contract).
    detector = CollisionDetector(mesh.faces, device="cpu", rest=mesh.rest)
    detector.prepare(mesh.vertices)
    shared = IntersectionCheck(mesh.faces, n, "cpu", spatial_hash=detector.spatial_hash)
    own = IntersectionCheck(mesh.faces, n, "cpu")
    squashed = mesh.vertices_end * np.array([1.0, 1.0, 0.2], np.float32)  # layers pushed through each other
    crossings = 0
    for x in (mesh.vertices, mesh.vertices_end, squashed, mesh.vertices_end):
        expected = CollisionDetector(mesh.faces, device="cpu", rest=mesh.rest).detect(x, None, 0.03)
        _same(detector.detect(x, None, 0.03), expected)
        found = shared.find(x)
        np.testing.assert_array_equal(found, own.find(x))
        crossings += found.shape[0]
    assert crossings > 0
    # The check hashes one group per face; the slab tables stay sized by the detector's groups.
    assert detector.spatial_hash.slab_capacity < detector.spatial_hash.group_capacity


def test_trimmed_hash_tables_still_give_every_pair() -> None:
    mesh = folded_sheet(800, layers=3, seed=5)
    detector = CollisionDetector(mesh.faces, device="cpu")
    expected = CollisionDetector(mesh.faces, device="cpu").detect(mesh.vertices, mesh.vertices_end)
    _same(detector.detect(mesh.vertices, mesh.vertices_end), expected)
    spatial_hash = detector.spatial_hash
    before = spatial_hash.capacities()
    spatial_hash.trim({k: 8 for k in range(5)})  # far below the need: the next call must grow them again
    assert all(capacity <= 8 for capacity in spatial_hash.capacities().values())
    _same(detector.detect(mesh.vertices, mesh.vertices_end), expected)
    assert spatial_hash.capacities()[0] >= min(before[0], spatial_hash.stats.entries)


def test_hash_tables_in_a_lent_buffer_give_the_same_pairs_and_count_as_the_lenders() -> None:
    # The solver lends its BSR values: whatever the lender writes there between calls is overwritten
    # by the next call before it is read.
    mesh = folded_sheet(800, layers=3, seed=7)
    expected = CollisionDetector(mesh.faces, device="cpu").detect(mesh.vertices, mesh.vertices_end)
    detector = CollisionDetector(mesh.faces, device="cpu")
    own = CollisionDetector(mesh.faces, device="cpu")
    own.detect(mesh.vertices, mesh.vertices_end)
    lent = wp.zeros(1 << 20, dtype=wp.float32, device="cpu")
    detector.lend_scratch(lent)
    for _ in range(2):
        _same(detector.detect(mesh.vertices, mesh.vertices_end), expected)
        lent.fill_(-3.0)  # the lender's own use of its buffer between calls
    spatial_hash = detector.spatial_hash
    assert {"entry_key", "pairs"} <= spatial_hash._lent_names
    assert spatial_hash.pairs.ptr == lent.ptr  # the output first
    assert detector.device_bytes()["spatial_hash"] < own.device_bytes()["spatial_hash"]
    # A buffer too small for any table: every table is the hash's own again.
    detector.lend_scratch(wp.zeros(1, dtype=wp.float32, device="cpu"))  # 4 bytes: smaller than any table
    assert not spatial_hash._lent_names
    _same(detector.detect(mesh.vertices, mesh.vertices_end), expected)
    detector.lend_scratch(None)
    assert detector.device_bytes()["spatial_hash"] == own.device_bytes()["spatial_hash"]


def test_hash_tables_in_the_detectors_pair_buffers_give_the_same_pairs_after_they_are_resized() -> None:
    # With pair_buffers the hash also places its tables in the candidate pairs and times of impact, which
    # the broad phase rewrites after the hash (the pairs themselves never go there).
    mesh = folded_sheet(800, layers=3, seed=11)
    reference = CollisionDetector(mesh.faces, device="cpu")
    detector = CollisionDetector(mesh.faces, device="cpu")
    detector.prepare(mesh.vertices)
    detector.lend_scratch(None, pair_buffers=True)
    spatial_hash = detector.spatial_hash
    pair_buffers = lambda: [detector.candidates.storage, detector.narrow.toi_storage]  # noqa: E731

    def inside(name: str) -> bool:
        table = getattr(spatial_hash, name)
        return any(b.ptr <= table.ptr and table.ptr + table.capacity <= b.ptr + b.capacity for b in pair_buffers())

    for positions, end in ((mesh.vertices, mesh.vertices_end), (mesh.vertices_end, None), (mesh.vertices, None)):
        _same(detector.detect(positions, end, 0.01), reference.detect(positions, end, 0.01))
        assert spatial_hash._lent_names and all(inside(name) for name in spatial_hash._lent_names)
        assert "pairs" not in spatial_hash._lent_names  # no buffer that may hold the output was lent
    # The candidates grow (a new buffer): the next call places the tables in the new buffers.
    old = detector.candidates.storage
    detector.candidates.ensure(0, 3 * detector.candidates.capacity_ee)
    detector.narrow.reserve(detector.candidates)
    assert detector.candidates.storage.ptr != old.ptr
    _same(detector.detect(mesh.vertices, mesh.vertices_end), reference.detect(mesh.vertices, mesh.vertices_end))
    assert all(inside(name) for name in spatial_hash._lent_names)
    assert spatial_hash.entry_key.ptr == detector.candidates.storage.ptr  # the largest table, the largest lender
    assert not spatial_hash.refresh_loans()  # nothing changed since
    # Counted once: as candidates, not again as hash tables.
    assert detector.device_bytes()["spatial_hash"] < reference.device_bytes()["spatial_hash"]
