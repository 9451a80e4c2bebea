"""``[[cloth.stitches]]``: two boundaries of pieces, chosen by selections, sewn by resampling one along the
other (issue 13): boundary ordering, orientation, loops, gathered seams, round trip and bad tables."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

from pscc.errors import InputError
from pscc.mesh.generate import grid_sheet
from pscc.scenes.scene_file import load_scene_file, read_scene_file
from pscc.scenes.seam_builder import boundary_path, sew
from pscc.sim.simulation import Simulation
from tests.scenes.test_scene_file import _round_trip, _write

TWO_PANELS = """
[solver]
gravity = [0.0, 0.0, 0.0]
[[cloth]]
name = "front"
[cloth.sheet]
size = [0.2, 0.2]
cells = [4, 4]
[[cloth.stitches]]
vertices = { side = "right" }
to = { side = "left" }
to_piece = "back"
[[cloth]]
name = "back"
translate = [0.22, 0.0, 0.0]
[cloth.sheet]
size = [0.2, 0.2]
cells = [4, 8]
"""


def test_two_pieces_sewn_side_to_side(tmp_path: Path) -> None:
    loaded = read_scene_file(_write(tmp_path, TWO_PANELS))
    scene = loaded.scene
    front = 25  # 5 x 5 vertices, then the back's 5 x 9
    rows = scene.stitches
    assert rows.shape == (5, 4)
    # Every right-column vertex of the front, each sewn to the back's left column at the same height:
    # the back has twice the rows, so each lands on one of its vertices (r = 0 or 1).
    x = scene.vertices.astype(np.float64)
    i, j, k = (rows[:, c].astype(int) for c in range(3))
    assert np.all(i < front) and np.all(j >= front) and np.all(k >= front)
    seam_points = (1.0 - rows[:, 3:4]) * x[j] + rows[:, 3:4] * x[k]
    np.testing.assert_allclose(seam_points[:, 1], x[i, 1], atol=1e-6)
    np.testing.assert_allclose(seam_points[:, 0] - x[i, 0], 0.02, atol=1e-6)
    spec = loaded.spec["cloth"][0]["stitches"][0]
    assert spec["to_piece"] == "back" and spec["reverse"] is False and len(spec["vertices"]) == 5
    _round_trip(tmp_path / "scene.toml", tmp_path)
    # It simulates: the 2 cm gap closes.
    sim = Simulation(scene, device="cpu")
    for _ in range(3):
        sim.step_frame()
    y = sim.state.positions.numpy().astype(np.float64)
    gaps = np.linalg.norm(y[i] - ((1.0 - rows[:, 3:4]) * y[j] + rows[:, 3:4] * y[k]), axis=1)
    assert gaps.max() < 0.002


def test_orientation_follows_the_positions_and_can_be_reversed(tmp_path: Path) -> None:
    flipped = TWO_PANELS.replace('translate = [0.22, 0.0, 0.0]',
                                 'translate = [0.22, 0.0, 0.0]\nrotate = [180.0, 0.0, 0.0]')
    # The back is upside down: its left column runs the other way, and the seam follows it.
    scene = load_scene_file(_write(tmp_path, flipped))[0]
    rows = scene.stitches
    x = scene.vertices.astype(np.float64)
    i, j, k = (rows[:, c].astype(int) for c in range(3))
    seam_points = (1.0 - rows[:, 3:4]) * x[j] + rows[:, 3:4] * x[k]
    np.testing.assert_allclose(seam_points[:, 1], x[i, 1], atol=1e-6)
    twisted = load_scene_file(_write(tmp_path, flipped.replace('to_piece = "back"',
                                                                'to_piece = "back"\nreverse = false')))[0]
    seam_points = ((1.0 - twisted.stitches[:, 3:4]) * x[twisted.stitches[:, 1].astype(int)]
                   + twisted.stitches[:, 3:4] * x[twisted.stitches[:, 2].astype(int)])
    assert np.abs(seam_points[:, 1] - x[i, 1]).max() > 0.1  # sewn crosswise, as asked


def test_boundary_paths_loops_and_gathered_seams() -> None:
    _, faces, rest = grid_sheet(4, 2, 0.4, 0.2)
    right = np.array([14, 9, 4])  # any order
    path, closed = boundary_path(faces, right)
    assert path.tolist() == [4, 9, 14] and not closed
    ring = np.array([0, 1, 2, 3, 4, 9, 14, 13, 12, 11, 10, 5])
    loop, closed = boundary_path(faces, ring)
    assert closed and sorted(loop.tolist()) == sorted(ring.tolist())
    with pytest.raises(ValueError, match="not joined"):
        boundary_path(faces, [4, 9, 7])  # 7 is an interior vertex
    with pytest.raises(ValueError, match="separate pieces"):
        boundary_path(faces, [0, 1, 3, 4])
    # Gathered: the left column of one piece (3 vertices, 0.2 m) sewn along the bottom row of another
    # (5 vertices, 0.4 m), proportionally; the bottom row runs backwards because its far end is nearer.
    positions = np.concatenate([rest, np.zeros((len(rest), 1))], axis=1)
    source, _ = boundary_path(faces, [0, 5, 10])
    target, _ = boundary_path(faces, [0, 1, 2, 3, 4])
    other = positions.copy()
    other[:, 0] = 0.4 - other[:, 0]  # the second piece mirrored: its vertex 4 lies at the source's start
    rows, reversed_ = sew(source, False, rest, target, False, rest, positions, other)
    assert reversed_
    assert rows[:, :3].astype(int).tolist() == [[0, 4, 3], [5, 2, 1], [10, 1, 0]]
    np.testing.assert_allclose(rows[:, 3], [0.0, 0.0, 1.0])


@pytest.mark.parametrize(("extra", "key", "pattern"), [
    ('[[cloth.stitches]]\nvertices = { side = "left" }\n', "stitches[1].to", "is missing"),
    ('[[cloth.stitches]]\nvertices = { side = "left" }\nto = { side = "right" }\nto_piece = "sleeve"\n',
     "stitches[1].to_piece", "no cloth piece is named 'sleeve'"),
    ('[[cloth.stitches]]\nvertices = [0, 6]\nto = { side = "right" }\n', "stitches[1].vertices", "not joined"),
    ('[[cloth.stitches]]\nvertices = { side = "right" }\nto = { side = "right" }\n', "stitches[1].to",
     "shares vertices"),
    ('[[cloth.stitches]]\nvertices = { side = "left" }\nto = { side = "right" }\nreverse = 1\n',
     "stitches[1].reverse", "expected true or false"),
])
def test_bad_seam_tables_name_the_key(tmp_path: Path, extra: str, key: str, pattern: str) -> None:
    text = TWO_PANELS.replace('[[cloth]]\nname = "back"', extra + '[[cloth]]\nname = "back"')
    path = _write(tmp_path, text)
    with pytest.raises(InputError) as info:
        load_scene_file(path)
    assert str(info.value).startswith(f"{path}: cloth[0].{key}: "), str(info.value)
    assert re.search(pattern, str(info.value)), str(info.value)


def test_a_loop_is_sewn_to_a_loop_from_the_nearest_vertex() -> None:
    # The boundary loops of two squares, the second one scaled about its centre by 1.02 and cut twice as
    # fine: every vertex of the first is sewn to the point of the second at the same fraction of the loop,
    # starting at the second's vertex nearest the first's start and running the same way round.
    first, faces_a, rest_a = grid_sheet(2, 2, 1.0, 1.0)
    second, faces_b, rest_b = grid_sheet(4, 4, 1.0, 1.0)
    second = (second - 0.5) * 1.02 + 0.5
    ring_a = [v for v in range(9) if v != 4]
    ring_b = [v for v in range(25) if v not in (6, 7, 8, 11, 12, 13, 16, 17, 18)]
    source, closed_a = boundary_path(faces_a, ring_a)
    target, closed_b = boundary_path(faces_b, ring_b)
    assert closed_a and closed_b and len(source) == 8 and len(target) == 16
    rows, _ = sew(source, True, rest_a, target, True, rest_b, first.astype(np.float64), second.astype(np.float64))
    points = (1.0 - rows[:, 3:4]) * second[rows[:, 1].astype(int)] + rows[:, 3:4] * second[rows[:, 2].astype(int)]
    # Each seam point lies next to its vertex (the loops match up to the 2 % scale), never across the square.
    assert np.abs(points - first[rows[:, 0].astype(int)]).max() < 0.02 + 1e-6
