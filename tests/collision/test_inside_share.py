"""CCD on pairs that start closer than the CCD distance (``inside_share``, pscc.collision.narrow_phase)."""

from __future__ import annotations

import numpy as np
import pytest

from pscc.collision.detector import CollisionDetector
from pscc.errors import InputError

D = 0.01  # the CCD distance of these tests


def _vertex_face(start_gap: float, end_gap: float, slide: float = 0.0) -> tuple[np.ndarray, ...]:
    """One triangle at z = 0 (face 0) and a small far-away triangle whose vertex 3 hangs over it."""
    triangle = np.array([[-1.0, -1.0, 0.0], [1.0, -1.0, 0.0], [0.0, 1.0, 0.0]])
    above = np.array([[0.0, 0.0, 1.0], [5.0, 5.0, 5.0], [5.0, 5.2, 5.0]])
    x0 = np.concatenate([triangle, above])
    x1 = x0.copy()
    x0[3, 2] = start_gap
    x1[3] = [slide, 0.0, end_gap]
    faces = np.array([[0, 1, 2], [3, 4, 5]], dtype=np.int32)
    return faces, x0.astype(np.float32), x1.astype(np.float32)


def _edge_edge(start_gap: float, end_gap: float) -> tuple[np.ndarray, ...]:
    """Two triangles whose edges (0, 1) and (3, 4) cross at right angles, ``gap`` apart in z."""
    first = np.array([[-1.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, -1.0, -1.0]])
    second = np.array([[0.0, -1.0, 1.0], [0.0, 1.0, 1.0], [0.0, 0.0, 2.0]])
    x0 = np.concatenate([first, second])
    x1 = x0.copy()
    x0[3:, 2] += start_gap - 1.0
    x1[3:, 2] += end_gap - 1.0
    faces = np.array([[0, 1, 2], [3, 4, 5]], dtype=np.int32)
    return faces, x0.astype(np.float32), x1.astype(np.float32)


def _hits(case: tuple[np.ndarray, ...], share: float, kind: str) -> np.ndarray:
    faces, x0, x1 = case
    detector = CollisionDetector(faces, method="brute-force", device="cpu")
    detector.broad_phase(x0, x1, D)
    result = detector.narrow_phase(x0, x1, D, inside_share=share)
    if kind == "vf":
        return result.vertex_face_toi[(result.vertex_face == [3, 0]).all(axis=1)]
    rows = (result.edge_edge == [0, 1, 3, 4]).all(axis=1)
    return result.edge_edge_toi[rows]


@pytest.mark.parametrize("kind, make", [("vf", _vertex_face), ("ee", _edge_edge)])
def test_a_pair_starting_inside_the_distance_is_a_contact_only_if_it_closes_in(kind: str, make: object) -> None:
    start = 0.6 * D
    # Without the share, any pair that starts inside is a contact at t = 0, however it moves.
    for end in (0.9 * D, 0.5 * D, 2.0 * D):
        toi = _hits(make(start, end), 0.0, kind)
        assert toi.shape == (1,) and toi[0] == 0.0
    # With share 0.5: moving away or closing in by less than half is no contact.
    for end in (2.0 * D, 0.9 * D, 0.4 * D):
        assert _hits(make(start, end), 0.5, kind).shape == (0,), end
    # Closing in past half its start distance is a contact, reported near where it gets there.
    toi = _hits(make(start, 0.1 * D), 0.5, kind)
    assert toi.shape == (1,) and 0.0 < toi[0] <= 1.0
    crossing_point = (start - 0.5 * start) / (start - 0.1 * D)  # linear motion: gap 0.3 D at this time
    assert abs(toi[0] - crossing_point) < 0.15
    # Crossing through is a contact (before the crossing), and so is a pair that starts touching.
    toi = _hits(make(start, -start), 0.5, kind)
    assert toi.shape == (1,) and 0.0 < toi[0] < 0.5
    assert _hits(make(0.0, 0.5 * D), 0.5, kind).shape == (1,)


def test_a_pair_starting_outside_the_distance_is_tested_as_before() -> None:
    for end in (1.5 * D, 0.8 * D, 0.2 * D, -D):
        case = _vertex_face(3.0 * D, end)
        plain, shared = _hits(case, 0.0, "vf"), _hits(case, 0.5, "vf")
        np.testing.assert_array_equal(plain, shared)
        assert plain.shape == ((1,) if end < D else (0,))


def test_the_share_must_be_below_one() -> None:
    faces, x0, x1 = _vertex_face(0.6 * D, 0.5 * D)
    detector = CollisionDetector(faces, method="brute-force", device="cpu")
    detector.broad_phase(x0, x1, D)
    with pytest.raises(InputError, match="inside_share"):
        detector.narrow_phase(x0, x1, D, inside_share=1.0)
