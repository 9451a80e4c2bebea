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


# An edge pair of the 96-triangle `twist` strip at t = 5.14 s (float32 positions of its four vertices at the
# step's start and end), resting at 1.003 times the CCD distance 0.2 mm: too near it for the rounding bound,
# so the CCD reports it at t = 0, and the run used to stop there.
TWIST_T0 = [[-0.1414732187986374, 0.007496476173400879, -0.09766870737075806],
            [-0.23109640181064606, 0.025673028081655502, -0.04309796541929245],
            [-0.21721383929252625, -0.059681911021471024, -0.0051807318814098835],
            [-0.18463318049907684, 0.016562651842832565, -0.07183809578418732]]
TWIST_T1 = [[-0.14162281155586243, 0.007573517970740795, -0.0977981761097908],
            [-0.2312677502632141, 0.025762086734175682, -0.04326716065406799],
            [-0.21730206906795502, -0.05950815603137016, -0.005189700052142143],
            [-0.18479353189468384, 0.016644641757011414, -0.07198727875947952]]


def test_a_pair_resting_just_outside_the_distance_is_not_held_at_t_zero() -> None:
    def mesh(points: list[list[float]]) -> np.ndarray:
        a0, a1, b0, b1 = np.asarray(points, np.float32)
        return np.array([a0, a1, a0 + [0.0, 0.0, -0.5], b0, b1, b0 + [0.0, 0.0, 0.5]], np.float32)

    faces = np.array([[0, 1, 2], [3, 4, 5]], np.int32)
    x0, x1 = mesh(TWIST_T0), mesh(TWIST_T1)
    results = []
    for share in (0.0, 0.5):
        detector = CollisionDetector(faces, method="brute-force", device="cpu")
        detector.broad_phase(x0, x1, 0.0002)
        results.append(detector.narrow_phase(x0, x1, 0.0002, inside_share=share))
    assert results[0].edge_edge.tolist() == [[0, 1, 3, 4]] and results[0].edge_edge_toi.tolist() == [0.0]
    assert results[1].edge_edge.shape[0] == 0 and results[1].vertex_face.shape[0] == 0
