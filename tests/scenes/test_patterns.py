"""Sewing patterns (``pscc.scenes.patterns``) and garment pieces (``pscc.scenes.garments``): flat panels
that wrap onto cones without strain and meet vertex for vertex at their seams."""

from __future__ import annotations

import math

import numpy as np
import pytest

from pscc.errors import InputError, PsccError
from pscc.scenes.garments import GarmentPiece, sew_pieces
from pscc.scenes.patterns import Panel, Wrap, mesh_panel, seam_stitches

WRAPS = [
    Wrap((0.0, 0.0, 1.0), (0.0, 0.0, 0.5), half_length=0.06, radius=0.12),  # cylinder
    Wrap((0.0, 0.0, 1.0), (0.0, 0.05, 0.45), half_length=0.06, radius=0.12, end_scale=1.8),  # flared skirt
    Wrap((0.3, 0.0, 1.3), (0.5, 0.0, 1.1), half_length=0.0, radius=0.06, end_scale=0.7,
         long_axis=(0.0, 1.0, 0.0)),  # tapering sleeve
]


@pytest.mark.parametrize("wrap", WRAPS)
def test_development_is_an_isometry_and_undevelop_inverts_it(wrap: Wrap) -> None:
    rng = np.random.default_rng(1)
    s = rng.uniform(0.0, wrap.perimeter, 400)
    f = rng.uniform(0.0, 1.0, 400)
    flat = wrap.develop(s, f)
    back_s, back_f = wrap.undevelop(flat, near_s=0.5 * wrap.perimeter)
    np.testing.assert_allclose(np.mod(back_s - s + 0.5 * wrap.perimeter, wrap.perimeter), 0.5 * wrap.perimeter,
                               atol=1e-6)
    np.testing.assert_allclose(back_f, f, atol=1e-6)
    # Short steps keep their length: distances in the pattern are distances on the surface.
    ds = 1e-4
    for step_s, step_f in ((ds, 0.0), (0.0, ds / 0.5), (ds, ds / 0.5)):
        surface = np.linalg.norm(wrap.position(s + step_s, f + step_f) - wrap.position(s, f), axis=1)
        pattern = np.linalg.norm(wrap.develop(s + step_s, f + step_f) - flat, axis=1)
        np.testing.assert_allclose(pattern, surface, rtol=2e-3)


@pytest.mark.parametrize("wrap", WRAPS)
def test_front_and_back_panels_meet_at_their_seams(wrap: Wrap) -> None:
    left, right = sorted([wrap.arc_toward((1.0, 0.0, 0.0)), wrap.arc_toward((-1.0, 0.0, 0.0))])
    cell = 0.02
    front = mesh_panel(Panel("front", wrap, left, right), cell)
    back = mesh_panel(Panel("back", wrap, right, left + wrap.perimeter), cell)
    for mesh in (front, back):
        edges = np.linalg.norm(mesh.vertices[mesh.faces[:, [1, 2, 0]]] - mesh.vertices[mesh.faces], axis=2)
        rest = np.linalg.norm(mesh.rest[mesh.faces[:, [1, 2, 0]]] - mesh.rest[mesh.faces], axis=2)
        # Unstrained up to the chord of a curved edge: 1 - chord / arc <= (length / radius)^2 / 24 (1.6 % for a
        # 2 cm edge on the sleeve's 4.2 cm end).
        radius = wrap.radius * min(1.0, wrap.end_scale)
        assert np.all(np.abs(edges / rest - 1.0) <= (rest / radius) ** 2 / 24.0 + 1e-4)
        assert edges.max() < 2.0 * cell and edges.min() > 0.2 * cell
        # One piece of cloth: a disc (Euler characteristic 1), every interior edge in two triangles.
        undirected, counts = np.unique(np.sort(np.concatenate(
            [mesh.faces[:, [0, 1]], mesh.faces[:, [1, 2]], mesh.faces[:, [2, 0]]]), axis=1), axis=0,
            return_counts=True)
        assert counts.max() == 2
        assert mesh.vertices.shape[0] - undirected.shape[0] + mesh.faces.shape[0] == 1
        # Outward: normals point away from the axis.
        start, _, _, ez, _ = wrap.frame()
        tri = mesh.vertices[mesh.faces].astype(np.float64)
        normal = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
        radial = tri.mean(axis=1) - start
        radial -= (radial @ ez)[:, None] * ez
        assert np.all(np.einsum("ij,ij->i", normal, radial) > 0.0)
    positions = np.concatenate([front.vertices, back.vertices]).astype(np.float64)
    offset = front.vertices.shape[0]
    rows = np.concatenate([seam_stitches(front.right_seam, back.left_seam + offset, positions),
                           seam_stitches(back.right_seam + offset, front.left_seam, positions)])
    assert rows.shape[0] == front.left_seam.shape[0] + front.right_seam.shape[0]
    assert np.all(rows[:, 3] == 0.0) and np.all(rows[:, 1] == rows[:, 2])
    with pytest.raises(PsccError):  # lines that do not coincide are not sewn
        seam_stitches(front.right_seam, front.left_seam, positions)


def test_a_sleeve_is_one_panel_sewn_to_itself_and_an_opening_is_not_sewn() -> None:
    wrap = WRAPS[2]
    sleeve = GarmentPiece("sleeve", wrap, ((0.0, 0.0, -1.0),))
    panels, sewn = sleeve.panels()
    assert len(panels) == 1 and sewn == [(0, 0)]
    assert panels[0].s_right - panels[0].s_left == pytest.approx(wrap.perimeter)
    vest = GarmentPiece("vest", WRAPS[0], ((1.0, 0.0, 0.0), (-1.0, 0.0, 0.0)), opening_toward=(0.0, 1.0, 0.0),
                        opening=0.08)
    panels, sewn = vest.panels()
    assert len(panels) == 3 and len(sewn) == 2  # back and two fronts; the fronts are not sewn to each other
    covered = sum(p.s_right - p.s_left for p in panels)
    assert covered == pytest.approx(WRAPS[0].perimeter - 0.08)
    mesh = sew_pieces([sleeve, vest], 0.02)
    assert mesh.panel_names == ["sleeve 0", "vest 0", "vest 1", "vest 2"]
    assert set(np.unique(mesh.object_ids)) == {0, 1}  # one cloth object per piece
    rows = mesh.stitches.astype(np.int64)
    np.testing.assert_allclose(mesh.vertices[rows[:, 0]], mesh.vertices[rows[:, 1]], atol=1e-6)
    # Pattern pieces are laid out side by side in the rest coordinates: no two overlap.
    boxes = [(mesh.rest[np.unique(mesh.faces[mesh.panel_ids == k])]) for k in range(4)]
    spans = sorted((b[:, 0].min(), b[:, 0].max()) for b in boxes)
    assert all(a[1] < b[0] for a, b in zip(spans, spans[1:], strict=False))
    with pytest.raises(InputError):
        GarmentPiece("tube", WRAPS[0], ()).panels()


def test_bad_panels_are_refused() -> None:
    wrap = WRAPS[0]
    with pytest.raises(InputError):
        mesh_panel(Panel("empty", wrap, 0.3, 0.3), 0.02)
    with pytest.raises(InputError):
        mesh_panel(Panel("tiny", wrap, 0.0, 0.01, 0.0, 0.02), 0.02)
    assert math.isclose(wrap.perimeter, 4 * 0.06 + 2 * math.pi * 0.12)
