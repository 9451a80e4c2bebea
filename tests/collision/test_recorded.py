"""RecordedDetection: a detector call recorded once and replayed; a replay whose buffers overflowed records
the call again (never replays a graph whose buffers were released) and returns the rows of a fresh call."""

from __future__ import annotations

import numpy as np
import pytest
import warp as wp

from pscc.collision.detector import CollisionDetector
from pscc.collision.recorded import RecordedDetection
from pscc.errors import InputError
from pscc.mesh import folded_sheet

DEVICE = "cpu"


def _rows(result) -> tuple[np.ndarray, np.ndarray]:
    return np.asarray(result.vertex_face), np.asarray(result.edge_edge)


@pytest.mark.parametrize("method", ["pscc", "spatial-hash"])
def test_replays_give_the_rows_of_a_fresh_call(method: str) -> None:
    mesh = folded_sheet(600, layers=3, seed=4)
    detector = CollisionDetector(mesh.faces, method=method, rest=mesh.rest, device=DEVICE)
    positions = wp.array(mesh.vertices_end, dtype=wp.vec3, device=DEVICE)
    recorded = RecordedDetection(detector, positions, thickness=0.01)
    for _ in range(3):
        rows = _rows(detector.collect(recorded.replay()))
    expected = _rows(CollisionDetector(mesh.faces, method=method, rest=mesh.rest, device=DEVICE)
                     .detect(mesh.vertices_end, thickness=0.01))
    assert rows[0].shape[0] + rows[1].shape[0] > 0
    np.testing.assert_array_equal(rows[0], expected[0])
    np.testing.assert_array_equal(rows[1], expected[1])
    assert recorded.recordings == 1


def test_a_replay_that_overflows_records_the_call_again() -> None:
    mesh = folded_sheet(600, layers=3, seed=4)
    spread = mesh.vertices_end.astype(np.float64)
    spread[:, 2] *= 50.0  # the layers far apart: few pairs, small buffers
    detector = CollisionDetector(mesh.faces, rest=mesh.rest, device=DEVICE)
    positions = wp.array(spread.astype(np.float32), dtype=wp.vec3, device=DEVICE)
    recorded = RecordedDetection(detector, positions, thickness=0.02)
    first = recorded.contacts
    # The sheet crumpled into a small ball, written in place: the recorded buffers overflow.
    crumpled = np.random.default_rng(2).random(spread.shape).astype(np.float32) * 0.1
    positions.assign(wp.array(crumpled, dtype=wp.vec3, device=DEVICE))
    rows = _rows(detector.collect(recorded.replay()))
    assert recorded.recordings == 2 and recorded.contacts is not first
    expected = _rows(CollisionDetector(mesh.faces, rest=mesh.rest, device=DEVICE).detect(crumpled, thickness=0.02))
    assert expected[0].shape[0] + expected[1].shape[0] > 0
    np.testing.assert_array_equal(rows[0], expected[0])
    np.testing.assert_array_equal(rows[1], expected[1])
    # And the new graph replays as it is.
    rows = _rows(detector.collect(recorded.replay()))
    np.testing.assert_array_equal(rows[1], expected[1])
    assert recorded.recordings == 2


def test_host_positions_are_refused() -> None:
    mesh = folded_sheet(200, layers=2, seed=1)
    detector = CollisionDetector(mesh.faces, device=DEVICE)
    with pytest.raises(InputError, match="positions.*ndarray"):
        RecordedDetection(detector, mesh.vertices_end, thickness=0.01)
    x = wp.array(mesh.vertices_end, dtype=wp.vec3, device=DEVICE)
    with pytest.raises(InputError, match="positions_end"):
        RecordedDetection(detector, x, mesh.vertices_end, thickness=0.01)
