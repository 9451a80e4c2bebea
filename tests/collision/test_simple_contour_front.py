"""The simple-contour fallback of the node test (pscc.geometry.simple_contour) inside pscc's detector:
U-shaped and comb-shaped panels, whose contours no point sees turn one way, are certified whole when
they are flat enough, and never when they are folded onto themselves (checked against brute force)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pscc.geometry import simple_contour
from tests.collision.test_connected_splits import assert_shaken_hides_no_contact
from tests.collision.test_pscc import _assert_same_contacts, _check_dcd_contract, _detectors


def cut_grid(size: int, notches: list[tuple[int, int, int, int]]) -> tuple[np.ndarray, np.ndarray]:
    """A size x size grid of unit squares (two triangles each) in z = 0, less the squares of each notch
    (x0, x1, y0, y1: the squares x0 <= i < x1, y0 <= j < y1)."""
    keep = np.ones((size, size), bool)
    for x0, x1, y0, y1 in notches:
        keep[x0:x1, y0:y1] = False
    index = -np.ones((size + 1, size + 1), np.int64)
    faces = []
    for i, j in zip(*np.nonzero(keep), strict=True):
        corners = [(i, j), (i + 1, j), (i + 1, j + 1), (i, j + 1)]
        for c in corners:
            if index[c] < 0:
                index[c] = index.max() + 1
        a, b, c, d = (index[c] for c in corners)
        faces += [(a, b, c), (a, c, d)]
    vertices = np.zeros((index.max() + 1, 3))
    for (i, j), k in np.ndenumerate(index):
        if k >= 0:
            vertices[k] = (i, j, 0.0)
    return vertices / size, np.asarray(faces, np.int32)


def u_panel(size: int = 12) -> tuple[np.ndarray, np.ndarray]:
    """A U: the grid less a notch from the middle of the top edge down to a third of the height."""
    return cut_grid(size, [(size // 3, size - size // 3, size // 3, size)])


def comb_panel(size: int = 15) -> tuple[np.ndarray, np.ndarray]:
    """A comb of four teeth on a base a fifth of the height."""
    gaps = [(k, k + size // 7, size // 5, size) for k in range(size // 7, size - size // 7, 2 * (size // 7))]
    return cut_grid(size, gaps[:3])


def bent(vertices: np.ndarray, amplitude: float) -> np.ndarray:
    """The panel bent gently out of its plane (its normals stay within a cone)."""
    x = vertices.copy()
    x[:, 2] = amplitude * np.sin(2.0 * x[:, 0]) * np.cos(1.5 * x[:, 1])
    return x.astype(np.float32)


def spiral_ramp(twist: float, turns: float = 1.2, rings: int = 2, steps: int = 24) -> tuple[np.ndarray, np.ndarray]:
    """An annulus strip (radii 1 to 1.5) wound ``turns`` times around the z axis, its height
    ``twist`` x angle x (r - 1.25): nearly flat everywhere (its normals fit in a narrow cone around z),
    but its last part lies over its first, and the two cross along r = 1.25 when ``twist`` > 0."""
    theta = np.linspace(0.0, 2.0 * np.pi * turns, steps + 1)
    radius = np.linspace(1.0, 1.5, rings + 1)
    t, r = np.meshgrid(theta, radius, indexing="ij")
    vertices = np.stack([r * np.cos(t), r * np.sin(t), twist * t * (r - 1.25)], axis=-1).reshape(-1, 3)
    index = np.arange(len(vertices)).reshape(steps + 1, rings + 1)
    faces = []
    for i in range(steps):
        for j in range(rings):
            a, b, c, d = index[i, j], index[i, j + 1], index[i + 1, j + 1], index[i + 1, j]
            faces += [(a, d, c), (a, c, b)]
    return vertices.astype(np.float32), np.asarray(faces, np.int32)


@pytest.mark.parametrize("maker", [u_panel, comb_panel], ids=["U", "comb"])
def test_non_star_panels_get_a_smaller_front(maker, monkeypatch: pytest.MonkeyPatch) -> None:
    """Without rest coordinates (the BVH over the panel's own shape), the front over a gently bent U or comb
    is smaller with the fallback than with the star test alone, and the DCD contract holds."""
    vertices, faces = maker()
    x = bent(vertices, 0.05)
    sizes = {}
    for limit in (0, simple_contour.SIMPLE_CONTOUR_MAX_EDGES):
        with monkeypatch.context() as patch:
            patch.setattr(simple_contour, "SIMPLE_CONTOUR_MAX_EDGES", limit)
            detectors = _detectors(faces)
            detectors["pscc"].detect(x, thickness=0.01)
            sizes[limit] = detectors["pscc"].detect(x, thickness=0.01).stats["front_size"]
            _check_dcd_contract(faces, x, 0.01, detectors)
    assert sizes[simple_contour.SIMPLE_CONTOUR_MAX_EDGES] < sizes[0], sizes


def test_a_spiral_that_crosses_itself_is_not_certified() -> None:
    """A strip wound past a full turn, whose last part passes through its first: its normals fit in a cone,
    so only the contour test can refuse it. Every intersection brute force finds (touching DCD), and every
    contact of the winding as a step (CCD, from the strip wound less than a turn), pscc finds too. Its
    contour (52 edges) is short enough for the simple-contour test. (1.25 turns, not 1.2: at 1.2 a vertex of the
    end lands 3e-16 from one of the start at t = 1, a gap in the float32 positions that ipctk's conservative
    CCD, the test's oracle, calls a contact.)"""
    wound, faces = spiral_ramp(0.05, turns=1.25)
    start, _ = spiral_ramp(0.05, turns=0.9)
    detectors = _detectors(faces)
    reference = detectors["brute-force"].detect(wound)
    assert len(reference.vertex_face) + len(reference.edge_edge) > 0, "the strip must pass through itself"
    _assert_same_contacts(detectors["pscc"].detect(wound), reference, faces, wound, None, 0.0, "wound strip")
    swept = detectors["brute-force"].detect(start, wound)
    assert len(swept.vertex_face) + len(swept.edge_edge) > 0
    _assert_same_contacts(detectors["pscc"].detect(start, wound), swept, faces, start, wound, 0.0, "winding strip")


@settings(max_examples=6, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), motion=st.sampled_from([0.01, 0.05, 0.2]))
def test_shaken_combs_hide_no_contact(seed: int, motion: float) -> None:
    """CCD and touching DCD of pscc equal brute force on combs shaken at random (no rest): teeth pushed
    through each other are found; DCD at a radius keeps pscc's contract."""
    vertices, faces = comb_panel()
    assert_shaken_hides_no_contact(faces, bent(vertices, 0.05), seed, motion, "comb")
