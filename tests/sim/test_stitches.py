"""Stitches (seams): two panels sewn along an edge close an open seam, hold a hanging panel, and their
seam is never a contact or an intersection (issue 13)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from pscc.bench.oracle import crossings as ipctk_crossings
from pscc.collision.detector import CollisionDetector
from pscc.collision.intersection import IntersectionCheck
from pscc.collision.seams import SeamAdjacency
from pscc.mesh.generate import grid_sheet
from pscc.scenes.scene_file import load_scene_file
from pscc.sim.simulation import Simulation

NX = 8
THICKNESS = 0.002


def _panels(shift: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two 0.2 m panels (8 x 8 cells) in the z = 0 plane, the second moved by ``shift``."""
    first, faces, _ = grid_sheet(NX, NX, 0.2, 0.2)
    second = first + np.asarray(shift, np.float32)
    return np.concatenate([first, second]), np.concatenate([faces, faces + len(first)])


def _write_obj(path: Path, vertices: np.ndarray, faces: np.ndarray,
               stitches: list[tuple[int, int, int, float]]) -> Path:
    lines = [f"v {x!r} {y!r} {z!r}" for x, y, z in vertices.astype(np.float64).tolist()]
    lines += [f"f {a + 1} {b + 1} {c + 1}" for a, b, c in faces]
    lines += [f"stitch {i} {j} {k} {r}" for i, j, k, r in stitches]
    path.write_text("\n".join(lines) + "\n")
    return path


def _seam_gaps(x: np.ndarray, stitches: np.ndarray) -> np.ndarray:
    i, j, k = (stitches[:, c].astype(int) for c in range(3))
    r = stitches[:, 3:4]
    return np.linalg.norm(x[i] - ((1.0 - r) * x[j] + r * x[k]), axis=1)


def test_an_open_seam_closes_without_contacts_or_crossings(tmp_path: Path) -> None:
    cell = 0.2 / NX
    vertices, faces = _panels([0.22, 0.5 * cell, 0.0])  # a 2 cm gap, and half a cell up
    n = (NX + 1) ** 2
    # The second panel's left column sewn to the midpoints of the first panel's right edges (r = 0.5).
    stitches = [(n + row * (NX + 1), row * (NX + 1) + NX, (row + 1) * (NX + 1) + NX, 0.5) for row in range(NX)]
    _write_obj(tmp_path / "panels.obj", vertices, faces, stitches)
    (tmp_path / "scene.toml").write_text('[solver]\ngravity = [0.0, 0.0, 0.0]\n[[cloth]]\nmesh = "panels.obj"\n')
    scene, contact, _ = load_scene_file(tmp_path / "scene.toml")
    assert scene.stitches.shape == (NX, 4)
    sim = Simulation(scene, device="cpu", contact=contact)
    gaps = []
    for _ in range(4):
        record = sim.step_frame()
        assert record["counts"]["halvings"] == 0 and record["counts"]["contacts"] == 0
        x = sim.state.positions.numpy()
        assert sim.solver.intersection_check.find(x).shape == (0, 2)
        gaps.append(_seam_gaps(x, scene.stitches).max())
    # Sewing at 0.5 m/s: 2 cm closes within two frames (1/30 s each) and stays closed.
    assert gaps[0] < 0.02 and gaps[1] < 2 * THICKNESS and gaps[-1] < 0.5 * THICKNESS, gaps


def test_a_seam_holds_a_hanging_panel(tmp_path: Path) -> None:
    vertices, faces = _panels([0.0, -0.21, 0.0])  # the second panel 1 cm below the first
    n = (NX + 1) ** 2
    stitches = [(n + NX * (NX + 1) + c, c, c + 1 if c < NX else c - 1, 0.0) for c in range(NX + 1)]
    _write_obj(tmp_path / "hang.obj", vertices, faces, stitches)
    top = ", ".join(str(NX * (NX + 1) + c) for c in range(NX + 1))
    (tmp_path / "scene.toml").write_text(f'[[cloth]]\nmesh = "hang.obj"\nrotate = [90.0, 0.0, 0.0]\npins = [{top}]\n')
    scene, contact, _ = load_scene_file(tmp_path / "scene.toml")
    sim = Simulation(scene, device="cpu", contact=contact)
    for _ in range(8):
        record = sim.step_frame()
        assert record["counts"]["halvings"] == 0
    x = sim.state.positions.numpy()
    assert _seam_gaps(x, scene.stitches).max() < 0.5 * THICKNESS  # closed, and holding the weight below
    assert x[:, 2].min() < -0.2  # the sewn panel hangs below the pinned one
    assert sim.solver.intersection_check.find(x).shape == (0, 2)


@pytest.mark.parametrize("method", ["pscc", "spatial-hash", "brute-force"])
def test_detector_leaves_out_exactly_the_stitched_pairs(method: str) -> None:
    # A closed seam: the second panel's left column on the first panel's right column (coincident vertices).
    vertices, faces = _panels([0.2, 0.0, 0.001])
    n = (NX + 1) ** 2
    stitches = np.array([[n + row * (NX + 1), row * (NX + 1) + NX, (row + 1) * (NX + 1) + NX if row < NX else
                          (row - 1) * (NX + 1) + NX, 0.0] for row in range(NX + 1)])
    plain = CollisionDetector(faces, method=method, device="cpu").detect(vertices, thickness=0.005)
    sewn = CollisionDetector(faces, method=method, device="cpu", stitches=stitches).detect(vertices, thickness=0.005)
    partners = {}
    for i, j, k, _ in stitches.astype(int):
        partners.setdefault(i, set()).update((j, k))
        partners.setdefault(j, set()).add(i)
        partners.setdefault(k, set()).add(i)

    def joined(a: int, others: list[int]) -> bool:
        return any(o in partners.get(a, ()) for o in others)

    expected_vf = [row for row in plain.vertex_face.tolist() if not joined(row[0], faces[row[1]].tolist())]
    expected_ee = [row for row in plain.edge_edge.tolist()
                   if not (joined(row[0], row[2:]) or joined(row[1], row[2:]))]
    assert len(expected_vf) < len(plain.vertex_face) and len(expected_ee) < len(plain.edge_edge)
    assert sewn.vertex_face.tolist() == expected_vf
    assert sewn.edge_edge.tolist() == expected_ee


def test_intersection_check_leaves_out_a_closed_seam_only() -> None:
    # The second panel folds back under the first from a seam along the first panel's right edge: the only
    # place the two touch is the seam, which the check without stitches reports and the one with does not.
    first, faces, _ = grid_sheet(NX, NX, 0.2, 0.2)
    second = first.astype(np.float64)
    second[:, 2] = -0.3 * second[:, 0]
    second[:, 0] = 0.2 - 0.5 * second[:, 0]
    vertices = np.concatenate([first, second.astype(np.float32)])
    both = np.concatenate([faces, faces + len(first)])
    n = (NX + 1) ** 2
    stitches = np.array([[n + row * (NX + 1), row * (NX + 1) + NX, (row + 1) * (NX + 1) + NX if row < NX else
                          (row - 1) * (NX + 1) + NX, 0.0] for row in range(NX + 1)])
    assert IntersectionCheck(both, len(vertices), "cpu").find(vertices).shape[0] > 0
    seams = SeamAdjacency(stitches, len(vertices), "cpu")
    assert seams.pair_count == 2 * (NX + 1)  # each of the seam's vertices with both ends of its edge
    assert IntersectionCheck(both, len(vertices), "cpu", seams=seams).find(vertices).shape == (0, 2)
    # A real crossing away from the seam is still found: push the middle of the second panel up through the first.
    crossing = vertices.copy()
    middle = n + (NX // 2) * (NX + 1) + NX // 2
    crossing[middle, 2] = 0.05
    assert IntersectionCheck(both, len(vertices), "cpu", seams=seams).find(crossing).shape[0] > 0
    # The ipctk oracle agrees: the seam is its only "crossing", and the pushed vertex a real one.
    assert ipctk_crossings(vertices, both).shape[0] > 0
    assert ipctk_crossings(vertices, both, stitches).shape == (0, 3)
    found = ipctk_crossings(crossing, both, stitches)
    assert found.shape[0] > 0 and np.any(found[:, :2] == middle)
