"""Device paths of feature-pair extraction, the candidate buffers and the narrow phase (issue 12).

The device path (``FeaturePairs.extract_device`` then ``NarrowPhase.run_device``) reads its counts on
the device and launches at capacity. These tests check that it gives the rows and times of impact of
the host path, that a captured graph replays it bit for bit, that a steady-state call makes no host
read, sync, upload or allocation, and that an overflow is flagged, grown and re-run exactly.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pytest
import warp as wp

from pscc.bench.host_traffic import count_host_traffic
from pscc.collision.boxes import PrimitiveBoxes
from pscc.collision.brute_force import BroadPhaseBruteForce
from pscc.collision.candidates import CandidatePairs
from pscc.collision.contacts import ContactArgs, edge_edge_hit, vertex_face_hit
from pscc.collision.device_topology import DeviceTopology
from pscc.collision.feature_pairs import FeaturePairs
from pscc.collision.narrow_phase import NarrowPhase
from pscc.mesh import MeshTopology, folded_sheet, grid_sheet

PADDING = 37
"""Junk triangle-pair slots past the count: a kernel that ignored the count would extract them too."""


@wp.kernel
def _count_contact_hits(
    # in:
    contacts: ContactArgs,
    # out:
    hits: wp.array(dtype=wp.int32),
):
    """One thread per row slot (up to the longest buffer): count the rows the contacts helpers call hits."""
    row = wp.tid()
    if vertex_face_hit(contacts, row):
        wp.atomic_add(hits, 0, 1)
    if edge_edge_hit(contacts, row):
        wp.atomic_add(hits, 1, 1)


@dataclass
class Scene:
    """One mesh on the device, its boxes and host-computed candidate triangle pairs."""

    faces: np.ndarray
    topology: MeshTopology
    faces_device: wp.array
    edges_device: wp.array
    x0: wp.array
    x1: wp.array | None
    thickness: float
    object_ids: wp.array
    boxes: PrimitiveBoxes
    pairs: np.ndarray  # (n, 2) triangle pairs whose grown face boxes overlap
    device: wp.Device

    @property
    def x1_or_x0(self) -> wp.array:
        return self.x1 if self.x1 is not None else self.x0


def _face_box_pairs(faces: np.ndarray, x0: np.ndarray, x1: np.ndarray, thickness: float) -> np.ndarray:
    """All triangle pairs a < b whose swept face boxes, grown by the thickness, overlap (NumPy)."""
    corners = np.concatenate([x0[faces], x1[faces]], axis=1)
    lower = corners.min(axis=1) - thickness
    upper = corners.max(axis=1) + thickness
    a, b = np.triu_indices(faces.shape[0], k=1)
    keep = np.all((lower[a] <= upper[b]) & (lower[b] <= upper[a]), axis=1)
    return np.stack([a[keep], b[keep]], axis=1).astype(np.int32)


def _scene(device: str, kind: str, ccd: bool, seed: int = 0) -> Scene:
    """Small meshes with many contacts: folded sheets, crumpled grids with coincident vertices
    (zero-area faces, parallel edges) and two coincident sheets (coplanar everywhere)."""
    rng = np.random.default_rng(seed)
    if kind == "fold":
        mesh = folded_sheet(300, layers=3, seed=seed)  # seeds 1, 2, 3, 9 collide during the step
        faces = mesh.faces.astype(np.int32)
        x0 = mesh.vertices.astype(np.float32)
        x1 = mesh.vertices_end.astype(np.float32)
        object_ids = mesh.object_ids.astype(np.int32)
        thickness = 0.02 if ccd else 0.2  # DCD: within the thickness of neighbouring features
    elif kind == "crumpled":
        x0, faces, _ = grid_sheet(8, 6)
        x0 = x0.astype(np.float32)
        x0[:, 2] = rng.normal(0.0, 0.08, size=x0.shape[0]).astype(np.float32)
        # Coincident vertices: zero-area faces and parallel / overlapping edges.
        x0[5] = x0[6]
        x0[20] = x0[21] = x0[22]
        x1 = x0 + rng.normal(0.0, 0.05, size=x0.shape).astype(np.float32)
        object_ids = np.zeros(faces.shape[0], np.int32)
        thickness = 0.05
    elif kind == "coincident":
        sheet, sheet_faces, _ = grid_sheet(5, 4)
        x0 = np.concatenate([sheet, sheet]).astype(np.float32)
        faces = np.concatenate([sheet_faces, sheet_faces + sheet.shape[0]]).astype(np.int32)
        x1 = x0.copy()
        x1[: sheet.shape[0], 2] += 0.01
        x1[sheet.shape[0]:, 2] -= 0.01
        object_ids = np.repeat(np.array([0, 1], np.int32), sheet_faces.shape[0])
        thickness = 0.0
    else:
        raise ValueError(kind)
    faces = np.ascontiguousarray(faces, dtype=np.int32)
    dev = wp.get_device(device)
    topology = MeshTopology.from_faces(faces, x0.shape[0])
    faces_device = wp.array(faces, dtype=wp.vec3i, device=dev)
    edges_device = wp.array(topology.edges, dtype=wp.vec2i, device=dev)
    x0_device = wp.array(x0, dtype=wp.vec3, device=dev)
    x1_device = wp.array(x1, dtype=wp.vec3, device=dev) if ccd else None
    boxes = PrimitiveBoxes(faces_device, edges_device, x0.shape[0], dev)
    boxes.compute(x0_device, x1_device if ccd else x0_device, thickness)
    pairs = _face_box_pairs(faces, x0, x1 if ccd else x0, thickness)
    return Scene(faces, topology, faces_device, edges_device, x0_device, x1_device, thickness,
                 wp.array(object_ids, dtype=wp.int32, device=dev), boxes, pairs, dev)


def _padded_pairs(scene: Scene) -> tuple[wp.array, wp.array]:
    """The scene's triangle pairs in a buffer with ``PADDING`` junk slots past the count (valid face
    ids, so an unguarded kernel would extract them), and the count as an int64 device array."""
    last = scene.faces.shape[0] - 1
    junk = np.tile(np.array([[0, last]], np.int32), (PADDING, 1))
    rows = np.concatenate([scene.pairs, junk]).astype(np.int32)
    counts = np.array([scene.pairs.shape[0], 0], np.int64)
    return (wp.array(rows, dtype=wp.vec2i, device=scene.device),
            wp.array(counts, dtype=wp.int64, device=scene.device))


def _extractor(scene: Scene) -> FeaturePairs:
    return FeaturePairs(scene.faces, DeviceTopology.upload(scene.faces, scene.topology, scene.device), scene.device)


def _host_path(scene: Scene) -> dict[str, np.ndarray]:
    """The host API: ``extract`` (from 1-slot buffers, grown by its loop) then ``run``."""
    extractor = _extractor(scene)
    candidates = CandidatePairs(1, 1, scene.device)
    narrow = NarrowPhase(scene.faces_device, scene.edges_device, scene.device)
    n = scene.pairs.shape[0]
    pairs = wp.array(scene.pairs.reshape(-1, 2), dtype=wp.vec2i, device=scene.device)
    extractor.extract(pairs, n, candidates, scene.x0, scene.x1, scene.thickness, scene.object_ids,
                      scene.boxes.as_struct())
    narrow.run(candidates, scene.x0, scene.x1_or_x0, scene.thickness)
    vf = candidates.vertex_face_count
    ee = candidates.edge_edge_count
    return {
        "vertex_face": candidates.vertex_face.numpy()[:vf].reshape(-1, 2),
        "edge_edge": candidates.edge_edge.numpy()[:ee].reshape(-1, 2),
        "vertex_face_toi": narrow.vertex_face_toi.numpy()[:vf],
        "edge_edge_toi": narrow.edge_edge_toi.numpy()[:ee],
        "pair_stats": np.array([extractor.kept_pairs, extractor.kept_self_pairs, extractor.self_pairs]),
    }


class DevicePipeline:
    """Buffers sized once (from the host result), then the device path only."""

    def __init__(self, scene: Scene, capacity_vf: int, capacity_ee: int) -> None:
        self.scene = scene
        self.pairs, self.pair_counts = _padded_pairs(scene)
        self.extractor = _extractor(scene)
        self.candidates = CandidatePairs(capacity_vf, capacity_ee, scene.device)
        self.narrow = NarrowPhase(scene.faces_device, scene.edges_device, scene.device)
        self.narrow.reserve(self.candidates)
        self.box_args = scene.boxes.as_struct()

    def poison(self) -> None:
        """Fill every output with values a skipped write or an unguarded row would show."""
        self.candidates.vertex_face.fill_(wp.vec2i(-7, -7))
        self.candidates.edge_edge.fill_(wp.vec2i(-7, -7))
        self.candidates.counts.fill_(12345)
        self.narrow.vertex_face_toi.fill_(0.0)  # a hit, if a row past the count were read as valid
        self.narrow.edge_edge_toi.fill_(0.0)
        self.narrow.hit_counts.fill_(-3)
        self.extractor.pair_stats.fill_(-3)

    def run(self, moved: wp.array | None = None) -> None:
        """The device path: no host read, sync, upload or allocation."""
        s = self.scene
        self.extractor.extract_device(self.pairs, self.pair_counts, self.candidates, s.x0, s.x1, s.thickness,
                                      s.object_ids, self.box_args)
        self.narrow.run_device(self.candidates, s.x0, s.x1_or_x0, s.thickness, moved=moved)

    def snapshot(self) -> dict[str, np.ndarray]:
        """Every output, whole buffers included (for bit-identity)."""
        return {
            "counts": self.candidates.counts.numpy().copy(),
            "vertex_face_all": self.candidates.vertex_face.numpy().copy(),
            "edge_edge_all": self.candidates.edge_edge.numpy().copy(),
            "vertex_face_toi_all": self.narrow.vertex_face_toi.numpy().copy(),
            "edge_edge_toi_all": self.narrow.edge_edge_toi.numpy().copy(),
            "hit_counts": self.narrow.hit_counts.numpy().copy(),
            "pair_stats": self.extractor.pair_stats.numpy().copy(),
        }

    def rows(self) -> dict[str, np.ndarray]:
        vf, ee = (int(c) for c in self.candidates.counts.numpy())
        return {
            "vertex_face": self.candidates.vertex_face.numpy()[:vf].reshape(-1, 2),
            "edge_edge": self.candidates.edge_edge.numpy()[:ee].reshape(-1, 2),
            "vertex_face_toi": self.narrow.vertex_face_toi.numpy()[:vf],
            "edge_edge_toi": self.narrow.edge_edge_toi.numpy()[:ee],
            "pair_stats": self.extractor.pair_stats.numpy()[:3],
        }


def _sorted_rows(pairs: np.ndarray, toi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Rows and their toi bits in key order (GPU append order is not fixed)."""
    order = np.lexsort((pairs[:, 1], pairs[:, 0]))
    return pairs[order], toi[order].view(np.uint32)


def _assert_same_results(device: str, got: dict[str, np.ndarray], expected: dict[str, np.ndarray]) -> None:
    np.testing.assert_array_equal(got["pair_stats"], expected["pair_stats"])
    for kind in ("vertex_face", "edge_edge"):
        pairs, toi = got[kind], got[f"{kind}_toi"]
        want_pairs, want_toi = expected[kind], expected[f"{kind}_toi"]
        assert pairs.shape == want_pairs.shape
        if wp.get_device(device).is_cpu:
            # The CPU runs a launch's threads in order: the append order itself is fixed.
            np.testing.assert_array_equal(pairs, want_pairs)
            np.testing.assert_array_equal(toi.view(np.uint32), want_toi.view(np.uint32))
        else:
            for a, b in zip(_sorted_rows(pairs, toi), _sorted_rows(want_pairs, want_toi), strict=True):
                np.testing.assert_array_equal(a, b)


def _sized_pipeline(scene: Scene, expected: dict[str, np.ndarray]) -> DevicePipeline:
    return DevicePipeline(scene, expected["vertex_face"].shape[0] + 11, expected["edge_edge"].shape[0] + 13)


CASES = [("fold", True, 1), ("fold", False, 1), ("fold", True, 2), ("crumpled", True, 2), ("crumpled", False, 3),
         ("coincident", True, 0), ("coincident", False, 0)]


@pytest.mark.parametrize(("kind", "ccd", "seed"), CASES)
def test_device_path_equals_host_path(device: str, kind: str, ccd: bool, seed: int) -> None:
    scene = _scene(device, kind, ccd, seed)
    expected = _host_path(scene)
    assert expected["vertex_face"].shape[0] > 0 and expected["edge_edge"].shape[0] > 0
    pipeline = _sized_pipeline(scene, expected)
    pipeline.poison()
    pipeline.run()
    assert pipeline.candidates.fits()
    got = pipeline.rows()
    _assert_same_results(device, got, expected)
    hits = np.array([np.count_nonzero(expected["vertex_face_toi"] <= 1.0),
                     np.count_nonzero(expected["edge_edge_toi"] <= 1.0)])
    assert hits.sum() > 0, "the scene should have contacts"
    np.testing.assert_array_equal(pipeline.narrow.hit_counts.numpy(), hits)
    # The contacts view: rows past the count hold toi 0 (poisoned), yet are not hits.
    contacts = pipeline.narrow.contacts(pipeline.candidates)
    assert contacts.continuous == ccd and contacts.thickness == pytest.approx(scene.thickness)
    assert contacts.hit_counts is pipeline.narrow.hit_counts
    assert contacts.args.counts.ptr == pipeline.candidates.counts.ptr
    assert contacts.args.vertex_face_toi.ptr == pipeline.narrow.vertex_face_toi.ptr
    assert pipeline.narrow.vertex_face_toi.numpy()[-1] == 0.0  # a slot past the count, still poisoned
    seen = wp.zeros(2, dtype=wp.int32, device=scene.device)
    slots = max(pipeline.narrow.vertex_face_toi.shape[0], pipeline.narrow.edge_edge_toi.shape[0])
    wp.launch(_count_contact_hits, dim=slots, inputs=[contacts.args], outputs=[seen], device=scene.device)
    np.testing.assert_array_equal(seen.numpy(), hits)


@pytest.mark.parametrize("kind", ["fold", "crumpled"])
def test_moved_recheck_equals_full_run(device: str, kind: str) -> None:
    scene = _scene(device, kind, True, 9)
    expected = _host_path(scene)
    pipeline = _sized_pipeline(scene, expected)
    pipeline.run()
    # Move a few end positions (to the start positions: no contact) and re-check only what moved.
    x1_old = wp.clone(scene.x1)
    x1_new = scene.x1.numpy()
    x1_new[::5] = scene.x0.numpy()[::5]
    scene.x1.assign(x1_new)
    moved = pipeline.narrow.mark_moved(scene.x0, scene.x0, x1_old, scene.x1)
    assert 0 < int(moved.numpy().sum()) < x1_new.shape[0]
    pipeline.narrow.run_device(pipeline.candidates, scene.x0, scene.x1, scene.thickness, moved=moved)
    rechecked = pipeline.rows()
    recheck_hits = pipeline.narrow.hit_counts.numpy()
    pipeline.narrow.run_device(pipeline.candidates, scene.x0, scene.x1, scene.thickness)
    full = pipeline.rows()
    for kind_name in ("vertex_face_toi", "edge_edge_toi"):
        np.testing.assert_array_equal(rechecked[kind_name].view(np.uint32), full[kind_name].view(np.uint32))
    np.testing.assert_array_equal(recheck_hits, pipeline.narrow.hit_counts.numpy())
    # Kept rows count as hits too: the moved vertices lost their contacts, the others kept theirs.
    full_hits = [np.count_nonzero(full["vertex_face_toi"] <= 1.0), np.count_nonzero(full["edge_edge_toi"] <= 1.0)]
    np.testing.assert_array_equal(recheck_hits, full_hits)
    assert sum(full_hits) > 0


@pytest.mark.parametrize(("kind", "ccd"), [("fold", True), ("fold", False), ("crumpled", True)])
def test_capture_replay_is_bit_identical(device: str, kind: str, ccd: bool) -> None:
    scene = _scene(device, kind, ccd, 3)
    expected = _host_path(scene)
    pipeline = _sized_pipeline(scene, expected)
    pipeline.run()  # warm-up: modules loaded outside the capture
    # Record with the start positions, then move them: the replay must read the arrays, not a copy.
    with wp.ScopedCapture(device=scene.device) as capture:
        pipeline.run()
    x0_moved = scene.x0.numpy()
    x0_moved[::3] += np.float32(0.004)
    scene.x0.assign(x0_moved)
    if ccd:
        scene.boxes.compute(scene.x0, scene.x1, scene.thickness)
    else:
        scene.boxes.compute(scene.x0, scene.x0, scene.thickness)
    pipeline.poison()
    pipeline.run()
    wp.synchronize_device(scene.device)
    eager = pipeline.snapshot()
    pipeline.poison()
    wp.capture_launch(capture.graph)
    wp.synchronize_device(scene.device)
    replayed = pipeline.snapshot()
    assert eager["counts"].sum() > 0 and eager["hit_counts"].sum() > 0
    if wp.get_device(scene.device).is_cpu:
        for key, value in eager.items():
            np.testing.assert_array_equal(replayed[key].view(np.uint8), value.view(np.uint8), err_msg=key)
    else:  # rows are appended in no fixed order on a GPU: the same rows, the same bits, the same poison after
        for key in ("counts", "hit_counts", "pair_stats"):
            np.testing.assert_array_equal(replayed[key], eager[key], err_msg=key)
        for kind, count in (("vertex_face", eager["counts"][0]), ("edge_edge", eager["counts"][1])):
            pairs, toi = replayed[f"{kind}_all"], replayed[f"{kind}_toi_all"]
            want_pairs, want_toi = eager[f"{kind}_all"], eager[f"{kind}_toi_all"]
            got_rows, want_rows = _sorted_rows(pairs[:count], toi[:count]), _sorted_rows(want_pairs[:count],
                                                                                           want_toi[:count])
            for a, b in zip(got_rows, want_rows, strict=True):
                np.testing.assert_array_equal(a, b, err_msg=kind)
            np.testing.assert_array_equal(pairs[count:], want_pairs[count:], err_msg=kind)
            np.testing.assert_array_equal(toi[count:].view(np.uint32), want_toi[count:].view(np.uint32), err_msg=kind)
    # And a second replay (counters were reset by the graph, not accumulated).
    wp.capture_launch(capture.graph)
    wp.synchronize_device(scene.device)
    np.testing.assert_array_equal(pipeline.candidates.counts.numpy(), eager["counts"])
    np.testing.assert_array_equal(pipeline.narrow.hit_counts.numpy(), eager["hit_counts"])


def test_device_path_makes_no_host_traffic(device: str, monkeypatch: pytest.MonkeyPatch) -> None:
    scene = _scene(device, "fold", True, 1)
    expected = _host_path(scene)
    pipeline = _sized_pipeline(scene, expected)
    dcd = _sized_pipeline(_scene(device, "fold", False, 6), _host_path(_scene(device, "fold", False, 6)))
    brute = CandidatePairs(4 * scene.faces.shape[0] ** 2, scene.topology.edge_count ** 2, scene.device)
    used = wp.array(np.ones(scene.x0.shape[0], np.int32), dtype=wp.int32, device=scene.device)
    brute_force = BroadPhaseBruteForce(scene.boxes, used, scene.device)
    moved = pipeline.narrow.mark_moved(scene.x0, scene.x0, scene.x1, scene.x1)
    for _ in range(2):  # steady state: modules loaded, buffers sized
        pipeline.run()
        pipeline.run(moved=moved)
        dcd.run()
        brute.reset()
        brute_force.find_pairs(brute)
    assert pipeline.candidates.fits() and dcd.candidates.fits() and brute.fits()
    with count_host_traffic() as traffic:
        _steady_calls(pipeline, dcd, brute, brute_force, scene, moved)
    assert traffic == {"reads": 0, "syncs": 0, "uploads": 0, "allocations": 0}
    with count_host_traffic() as traffic:  # the counter works: the sync method is seen
        pipeline.candidates.fits()
    assert traffic["reads"] > 0
    np.testing.assert_array_equal(pipeline.rows()["vertex_face"].shape, expected["vertex_face"].shape)


def _steady_calls(pipeline, dcd, brute, brute_force, scene, moved) -> None:
    pipeline.run()
    pipeline.narrow.mark_moved(scene.x0, scene.x0, scene.x1, scene.x1)
    pipeline.run(moved=moved)
    pipeline.narrow.contacts(pipeline.candidates)
    dcd.run()
    dcd.narrow.contacts(dcd.candidates)
    brute.reset()
    brute_force.find_pairs(brute)


@pytest.mark.parametrize("ccd", [True, False])
def test_overflow_sets_counts_grows_and_reruns_exactly(device: str, ccd: bool) -> None:
    scene = _scene(device, "fold", ccd, 2)
    expected = _host_path(scene)
    true_counts = np.array([expected["vertex_face"].shape[0], expected["edge_edge"].shape[0]])
    pipeline = DevicePipeline(scene, 3, 2)
    pipeline.poison()
    pipeline.run()  # overflows: writes stay in bounds, the narrow phase clamps
    counts = pipeline.candidates.counts.numpy()
    np.testing.assert_array_equal(counts, true_counts)  # the device keeps the true totals
    assert np.all(pipeline.narrow.hit_counts.numpy() <= [3, 2])
    assert not pipeline.candidates.fits()
    assert pipeline.candidates.capacity_vf >= true_counts[0] and pipeline.candidates.capacity_ee >= true_counts[1]
    with pytest.raises(ValueError, match="reserve"):
        pipeline.narrow.run_device(pipeline.candidates, scene.x0, scene.x1_or_x0, scene.thickness)
    pipeline.narrow.reserve(pipeline.candidates)
    pipeline.run()
    assert pipeline.candidates.fits()
    _assert_same_results(device, pipeline.rows(), expected)
    hits = [np.count_nonzero(expected["vertex_face_toi"] <= 1.0), np.count_nonzero(expected["edge_edge_toi"] <= 1.0)]
    np.testing.assert_array_equal(pipeline.narrow.hit_counts.numpy(), hits)


def test_broad_phase_counter_past_the_buffer_is_clamped(device: str) -> None:
    """A triangle-pair counter larger than its buffer (an overflowed broad phase) reads only the buffer."""
    scene = _scene(device, "fold", True, 3)
    expected = _host_path(scene)
    pipeline = _sized_pipeline(scene, expected)
    pipeline.pairs = wp.array(scene.pairs, dtype=wp.vec2i, device=scene.device)
    pipeline.pair_counts = wp.array([scene.pairs.shape[0] + 1000, 0], dtype=wp.int64, device=scene.device)
    pipeline.run()
    assert pipeline.candidates.fits()
    _assert_same_results(device, pipeline.rows(), expected)
