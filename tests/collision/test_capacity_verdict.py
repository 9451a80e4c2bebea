"""The detector's device capacity verdict (``pscc.collision.capacity_verdict``): a call it passes is one
the full host check finds nothing to do for, a call that overflows or counts an input error is never
passed, and the stats and counts read lazily after a passed call equal those the full check reads."""

from __future__ import annotations

import numpy as np
import pytest
import warp as wp

from pscc.collision import capacity_verdict as cv
from pscc.collision.detector import METHODS, CollisionDetector
from pscc.errors import InputError, StaleGraphError
from pscc.mesh import folded_sheet


def _capacities(detector: CollisionDetector) -> tuple:
    hash_capacities = () if detector.method == "brute-force" else (
        tuple(detector.spatial_hash.capacities().values()), detector.spatial_hash.cell_bits)
    return hash_capacities, detector.candidates.capacity_vf, detector.candidates.capacity_ee


def _full_check(detector: CollisionDetector) -> bool:
    """The host check without the verdict (both parts run, as in check_capacity)."""
    fits = detector.method == "brute-force" or detector.spatial_hash.check_capacity()
    return detector.candidates.fits() and fits


@pytest.mark.parametrize("method", METHODS)
def test_the_verdict_passes_exactly_the_calls_the_full_check_finds_nothing_to_do_for(method: str) -> None:
    mesh = folded_sheet(600, layers=3, seed=1)
    detector = CollisionDetector(mesh.faces, method=method, device="cpu")
    detector.prepare(mesh.vertices)
    x = wp.array(mesh.vertices_end, dtype=wp.vec3, device="cpu")
    seen = set()
    # Thicknesses that grow the contact from call to call: every few calls a buffer overflows.
    for thickness in (0.0, 0.0, 0.01, 0.01, 0.03, 0.03, 0.08, 0.08, 0.15, 0.15, 0.3, 0.3):
        detector.broad_phase_device(x, None, thickness)
        verdict = int(detector.verdict.verdict.numpy()[0])
        seen.add(verdict)
        passed = detector.verdict.fits()
        before = _capacities(detector)
        full = _full_check(detector)
        assert passed == full, (thickness, verdict)
        assert passed == (before == _capacities(detector))  # a passed call grows nothing; a failed one grows
    assert 0 in seen and any(v & cv.CANDIDATES_BIT for v in seen), seen
    if method != "brute-force":
        assert any(v & (cv.PAIRS_BIT | cv.ENTRIES_BIT | cv.GROUPS_BIT | cv.ROWS_BIT) for v in seen), seen


@pytest.mark.parametrize("counter", ["INFO_BAD_BOXES", "INFO_BAD_NODES", "INFO_BAD_ORDER", "INFO_SAME_NODE"])
def test_an_input_error_counted_on_the_device_is_never_passed(counter: str) -> None:
    from pscc.collision import _spatial_hash_kernels as hash_kernels

    mesh = folded_sheet(300, layers=2, seed=0)
    detector = CollisionDetector(mesh.faces, device="cpu")
    x = wp.array(mesh.vertices_end, dtype=wp.vec3, device="cpu")
    detector.detect(x, None, 0.01)  # sizes the buffers: the next call fits
    detector.broad_phase_device(x, None, 0.01)
    assert detector.verdict.fits()
    # The hash counted one input error (as its kernels do for NaN boxes, node ids out of range, an order
    # that is no permutation or splits a node): the verdict of the same counters fails, the check raises.
    slot = getattr(hash_kernels, counter)
    detector.spatial_hash.info.numpy()[slot] = 1
    detector.spatial_hash.summary.numpy()[slot] = 1.0  # the counters' copy the full check reads
    detector.verdict.judge(detector.spatial_hash, detector.candidates)
    assert int(detector.verdict.verdict.numpy()[0]) == cv.ERROR_BIT
    assert not detector.verdict.fits()
    with pytest.raises(InputError):
        detector.check_capacity()


def test_before_any_call_the_verdict_sends_the_check_to_the_counters() -> None:
    mesh = folded_sheet(200, layers=2, seed=0)
    detector = CollisionDetector(mesh.faces, device="cpu")
    detector.prepare(mesh.vertices)
    assert not detector.verdict.fits()
    with pytest.raises(InputError, match="no device call has run"):
        detector.check_capacity()


@pytest.mark.parametrize("method", ["pscc", "spatial-hash"])
def test_stats_read_after_a_passed_call_equal_those_of_the_full_check(method: str,
                                                                       monkeypatch: pytest.MonkeyPatch) -> None:
    mesh = folded_sheet(600, layers=3, seed=2)
    detectors = [CollisionDetector(mesh.faces, method=method, device="cpu") for _ in range(2)]
    for detector in detectors:
        detector.prepare(mesh.vertices)
    monkeypatch.setattr(detectors[1].verdict, "fits", lambda: False)  # always the full check
    results = []
    for detector in detectors:
        detector.detect(mesh.vertices_end, None, 0.03)  # grows the buffers
        result = detector.detect(mesh.vertices_end, None, 0.03)
        results.append(({k: v for k, v in result.stats.items() if k not in ("seconds",)}, result))
    assert results[0][0] == results[1][0]
    np.testing.assert_array_equal(results[0][1].edge_edge, results[1][1].edge_edge)
    np.testing.assert_array_equal(results[0][1].vertex_face, results[1][1].vertex_face)
    # The passed call's triangle pairs are read when asked, as the full check reads them.
    for detector in detectors:
        detector.detect(mesh.vertices_end, None, 0.03)
    np.testing.assert_array_equal(detectors[0].spatial_hash.pairs_numpy(), detectors[1].spatial_hash.pairs_numpy())
    assert detectors[0].spatial_hash.pairs_numpy().shape[0] > 0


def test_a_replayed_call_that_outgrows_its_recording_is_caught() -> None:
    mesh = folded_sheet(600, layers=3, seed=3)
    detector = CollisionDetector(mesh.faces, device="cpu")
    x = wp.array(mesh.vertices, dtype=wp.vec3, device="cpu")  # the open start: little contact
    detector.detect(x, None, 0.02)
    with wp.ScopedCapture(device="cpu") as capture:
        detector.detect(x, None, 0.02)
    wp.capture_launch(capture.graph)
    assert detector.check_capacity()
    # Layers squashed onto each other: far more pairs than the recorded buffers hold.
    squashed = (mesh.vertices_end * np.array([1.0, 1.0, 0.02], np.float32)).astype(np.float32)
    x.assign(squashed)
    wp.capture_launch(capture.graph)
    assert int(detector.verdict.verdict.numpy()[0]) != 0
    assert not detector.check_capacity()
    result = detector.collect(detector.detect(x, None, 0.02))
    expected = CollisionDetector(mesh.faces, device="cpu").detect(squashed, None, 0.02)
    np.testing.assert_array_equal(result.edge_edge, expected.edge_edge)
    np.testing.assert_array_equal(result.vertex_face, expected.vertex_face)


def _recorded(detector, x, thickness):
    with wp.ScopedCapture(device="cpu") as capture:
        contacts = detector.detect(x, None, thickness)
    return capture.graph, contacts


def test_a_graph_replayed_after_its_buffers_grew_is_refused_not_passed() -> None:
    mesh = folded_sheet(600, layers=3, seed=3)
    detector = CollisionDetector(mesh.faces, device="cpu")
    x = wp.array(mesh.vertices, dtype=wp.vec3, device="cpu")
    detector.detect(x, None, 0.02)
    graph, _ = _recorded(detector, x, 0.02)
    x.assign((mesh.vertices_end * np.array([1.0, 1.0, 0.02], np.float32)).astype(np.float32))
    wp.capture_launch(graph)
    generation = detector.verdict.generation
    assert not detector.check_capacity()  # grew: a new generation, the old buffers kept
    assert detector.verdict.generation == generation + 1 and detector._retired
    # Replayed again as it is (the caller ignored the False): it writes into the kept buffers, and the check
    # says so instead of accepting rows that are not in the detector's buffers.
    wp.capture_launch(graph)
    with pytest.raises(StaleGraphError, match="record the call again"):
        detector.check_capacity()
    # A call on the new buffers fits (and releases the old ones); a graph recorded now replays and passes.
    rows = detector.collect(detector.detect(x, None, 0.02))
    assert not detector._retired
    fresh, contacts = _recorded(detector, x, 0.02)
    wp.capture_launch(fresh)
    assert detector.check_capacity()
    again = detector.collect(contacts)
    assert rows.edge_edge.shape[0] > 0
    np.testing.assert_array_equal(again.edge_edge, rows.edge_edge)
    np.testing.assert_array_equal(again.vertex_face, rows.vertex_face)


def test_a_graph_recorded_before_a_trim_is_refused() -> None:
    mesh = folded_sheet(6000, layers=3, seed=4)
    detector = CollisionDetector(mesh.faces, method="pscc", rest=mesh.rest, device="cpu")
    x = wp.array(mesh.vertices_end, dtype=wp.vec3, device="cpu")
    detector.detect(x, None, 0.01)
    graph, _ = _recorded(detector, x, 0.01)
    wp.capture_launch(graph)
    assert detector.check_capacity()
    assert detector.fit_buffers()  # 4 entry slots per face shrink to what the call uses
    wp.capture_launch(graph)
    with pytest.raises(StaleGraphError):
        detector.check_capacity()
