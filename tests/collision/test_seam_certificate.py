"""Normal-cone certificates across sewn seams (issue 13, item 2): no missed contact, and more culling."""

from __future__ import annotations

import time
from pathlib import Path

import ipctk
import numpy as np
import pytest

import pscc.collision.detector as detector_module
from pscc import tolerances
from pscc.collision.bvh import MaterialBvh
from pscc.collision.detector import CollisionDetector
from pscc.mesh import MeshTopology
from pscc.mesh.io import load_mesh

SKIRT = Path(__file__).resolve().parents[2] / "examples" / "garment" / "skirt.obj"


def _gore_skirt(gores: int, cells: tuple[int, int] = (6, 10), width: float = 0.3,
                height: float = 0.5) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """A tube of ``gores`` grid panels laid side by side in the pattern (u, v), each sewn to the next
    (the last to the first) by vertex stitches; positions on a cylinder with closed seams."""
    nu, nv = cells
    radius = gores * width / (2.0 * np.pi)
    uu, vv = np.meshgrid(np.linspace(0.0, width, nu + 1), np.linspace(0.0, height, nv + 1))
    quads = np.array([j * (nu + 1) + i for j in range(nv) for i in range(nu)])
    cell_faces = np.concatenate([np.stack([quads, quads + 1, quads + nu + 2], 1),
                                 np.stack([quads, quads + nu + 2, quads + nu + 1], 1)])
    size = (nu + 1) * (nv + 1)
    positions, pattern, faces, stitches = [], [], [], []
    for g in range(gores):
        angle = (uu.ravel() + g * width) / radius
        positions.append(np.stack([radius * np.cos(angle), radius * np.sin(angle), vv.ravel()], 1))
        pattern.append(np.stack([uu.ravel() + g * (width + 0.05), vv.ravel()], 1))
        faces.append(cell_faces + g * size)
        right = g * size + np.arange(nv + 1) * (nu + 1) + nu
        left = ((g + 1) % gores) * size + np.arange(nv + 1) * (nu + 1)
        nxt = np.append(left[1:], left[-2])
        stitches.append(np.stack([right, left, nxt, np.zeros(nv + 1)], 1))
    return (np.concatenate(positions), np.concatenate(faces).astype(np.int32), np.concatenate(pattern),
            np.concatenate(stitches).astype(np.float64))


def _deform(x: np.ndarray, rng: np.random.Generator, stitches: np.ndarray, gap: float) -> np.ndarray:
    """Random radial folds, a random squash towards flat (front and back layers meet), noise, and the
    stitched vertices i pulled off their partners j by up to ``gap`` (relative to the cell size)."""
    angle = np.arctan2(x[:, 1], x[:, 0])
    z = x[:, 2] / x[:, 2].max()
    r = np.linalg.norm(x[:, :2], axis=1)
    r = r * (1.0 + rng.uniform(0.0, 0.4) * np.sin(rng.integers(2, 6) * angle + rng.uniform(0, 6)) * (1.0 - z))
    y = np.stack([r * np.cos(angle), r * np.sin(angle) * rng.uniform(0.02, 1.0), x[:, 2]], 1)
    y += rng.normal(0.0, rng.choice([1e-4, 3e-3, 1e-2]), y.shape)
    i, j = stitches[:, 0].astype(int), stitches[:, 1].astype(int)
    y[i] = y[j] + rng.normal(0.0, gap * 0.05, (len(i), 3))
    return y.astype(np.float32)


def _touches(kind: str, row: tuple, faces: np.ndarray, x0: np.ndarray, x1, thickness: float) -> bool:
    """Float64 ipctk: does the reported row really come within the thickness (CCD when x1 is given)?"""
    ids = [row[0], *faces[row[1]]] if kind == "vf" else list(row)
    p0 = [np.float64(x0[i]) for i in ids]
    if x1 is None:
        d2 = ipctk.point_triangle_distance(*p0) if kind == "vf" else ipctk.edge_edge_distance(*p0)
        return d2 <= thickness * thickness
    p1 = [np.float64(x1[i]) for i in ids]
    ccd = ipctk.TightInclusionCCD(tolerance=1e-9, max_iterations=1_000_000, conservative_rescaling=1.0)
    fn = ccd.point_triangle_ccd if kind == "vf" else ccd.edge_edge_ccd
    return fn(*p0, *p1, min_distance=thickness)[0]


def _assert_no_missed_contact(pscc, brute, faces, x0, x1, label: str) -> None:
    """pscc reports a subset of brute force (which leaves the stitched pairs out) and every pair it lacks
    is a near miss, never a true contact (float64 ipctk)."""
    got = pscc.detect(x0, x1)
    ref = brute.detect(x0, x1)
    for kind, a, b in (("vf", got.vertex_face, ref.vertex_face), ("ee", got.edge_edge, ref.edge_edge)):
        mine, theirs = {tuple(int(v) for v in r) for r in a}, {tuple(int(v) for v in r) for r in b}
        assert mine <= theirs, f"{label}: {kind} pairs outside the reference"
        for row in theirs - mine:
            assert not _touches(kind, row, faces, x0, x1, 0.0), f"{label}: missed {kind} contact {row}"


@pytest.mark.parametrize("gores", [2, 4])
def test_sewn_tubes_never_hide_a_contact(gores: int) -> None:
    """Sewn tubes folded, squashed flat and shaken at random, with closed, slightly open and wide open
    seams: touching DCD and CCD of pscc equal brute force (up to float64-checked near misses)."""
    x, faces, rest, stitches = _gore_skirt(gores, cells=(5, 8))
    kwargs = {"rest": rest, "stitches": stitches, "device": "cpu"}
    pscc = CollisionDetector(faces, method="pscc", **kwargs)
    brute = CollisionDetector(faces, method="brute-force", **kwargs)
    rng = np.random.default_rng(gores)
    certified_across = 0
    for trial in range(12):
        gap = [0.0, 0.2, 1.0, 40.0][trial % 4] * tolerances.SEAM_GAP_RATIO
        x0 = _deform(x, rng, stitches, gap)
        x1 = (x0 + rng.normal(0.0, rng.choice([0.0, 0.005, 0.03]), x0.shape)).astype(np.float32)
        _assert_no_missed_contact(pscc, brute, faces, x0, x1, f"trial {trial} ccd")
        _assert_no_missed_contact(pscc, brute, faces, x1, None, f"trial {trial} dcd")
        front = pscc.front.front.numpy()[:pscc.front.front_size]
        certified_across += int((~pscc.bvh.is_leaf[front] & (pscc.bvh.panel[front] < 0)).sum())
    for _ in range(2 * 5):  # a few shrinks (every 5 calls) lift the front back up
        _assert_no_missed_contact(pscc, brute, faces, x.astype(np.float32), None, "cylinder")
    front = pscc.front.front.numpy()[:pscc.front.front_size]
    certified_across += int((~pscc.bvh.is_leaf[front] & (pscc.bvh.panel[front] < 0)).sum())
    if gores > 2:  # certificates do cross seams here (a 2-panel tube never can: each node is a panel or annulus)
        assert certified_across > 0


def test_degenerate_seams() -> None:
    """Exactly closed seams, a tube squashed to a double layer, a seam pulled wide open, and all
    stitched vertices collapsed onto one point: never a missed contact."""
    x, faces, rest, stitches = _gore_skirt(3, cells=(4, 6))
    kwargs = {"rest": rest, "stitches": stitches, "device": "cpu"}
    pscc = CollisionDetector(faces, method="pscc", **kwargs)
    brute = CollisionDetector(faces, method="brute-force", **kwargs)
    flat = x * np.float32([1.0, 1e-3, 1.0])
    wide = x.copy()
    wide[stitches[:, 0].astype(int)] *= np.float32([1.5, 1.5, 1.0])
    collapsed = x.copy()
    collapsed[stitches[:, 0].astype(int)] = collapsed[stitches[:, 1].astype(int)] = x[0]
    for label, x0 in (("closed", x), ("flat", flat), ("wide", wide), ("collapsed", collapsed)):
        x0 = x0.astype(np.float32)
        _assert_no_missed_contact(pscc, brute, faces, x0, None, label)
        _assert_no_missed_contact(pscc, brute, faces, x0, flat.astype(np.float32), label + " to flat")


def test_open_seams_are_not_certified() -> None:
    """A node across a seam is certified only while the seam is closed (SEAM_GAP_RATIO)."""
    x, faces, rest, stitches = _gore_skirt(4, cells=(6, 10))
    topology = MeshTopology.from_faces(faces, len(x))
    bvh = MaterialBvh.build(faces, rest, np.zeros(len(faces), np.int32), topology, "cpu", stitches=stitches)
    sewn = np.flatnonzero(bvh.testable & (bvh.panel < 0))
    assert sewn.size and all(bvh.seam_offsets[n + 1] > bvh.seam_offsets[n] for n in sewn)
    pscc = CollisionDetector(faces, method="pscc", rest=rest, stitches=stitches, device="cpu")
    opened = x.copy()
    i = stitches[:, 0].astype(int)
    opened[i] += np.float32([0.0, 0.0, 2.0 * tolerances.SEAM_GAP_RATIO * 0.05])  # 2x the bound (0.05 cells)
    for positions, crosses in ((x, True), (opened, False)):
        pscc.detect(positions.astype(np.float32))
        front = pscc.front.front.numpy()[:pscc.front.front_size]
        assert bool((~pscc.bvh.is_leaf[front] & (pscc.bvh.panel[front] < 0)).any()) == crosses


def _culling(faces, rest, stitches, states, seams_in_bvh: bool, monkeypatch) -> np.ndarray:
    """(front size, candidate pairs) per state; without ``seams_in_bvh`` the BVH is built as before
    this change (no stitches), while filtering still leaves the stitched pairs out."""
    build = MaterialBvh.build.__func__
    if not seams_in_bvh:
        monkeypatch.setattr(detector_module.MaterialBvh, "build",
                            classmethod(lambda cls, *args, **kw: build(cls, *args[:6])))
    # Boxes only: the 26-DOP face test culls many of the same pairs either way, and this measures the
    # seam certificates' own share.
    det = CollisionDetector(faces, method="pscc", rest=rest, stitches=stitches, device="cpu", face_diagonals=False)
    det.detect(states[0], thickness=0.002)  # builds the BVH
    monkeypatch.undo()
    rows = []
    for x in states:
        for _ in range(3):  # let the front settle (shrinking every few calls)
            result = det.detect(x, thickness=0.002)
        rows.append((result.stats["front_size"], result.stats["candidate_pairs"]))
    return np.array(rows)


def test_sewn_gores_cull_more_and_the_skirt_no_less(monkeypatch) -> None:
    """An 8-gore skirt: fewer front nodes and candidate pairs than with per-panel certificates; the
    two-panel example skirt (whose panels already are the best cover of a tube) culls no less."""
    started = time.perf_counter()
    x, faces, rest, stitches = _gore_skirt(8)
    rng = np.random.default_rng(5)
    states = [x.astype(np.float32)] + [_deform(x, rng, stitches, 0.0) for _ in range(3)]
    before = _culling(faces, rest, stitches, states, False, monkeypatch)
    after = _culling(faces, rest, stitches, states, True, monkeypatch)
    assert (after[:, 0] <= before[:, 0]).all() and after[:, 0].sum() < before[:, 0].sum()
    assert after[:, 1].sum() < 0.8 * before[:, 1].sum()

    skirt = load_mesh(str(SKIRT))
    closed = skirt.vertices.copy()
    closed[skirt.stitches[:, 0].astype(int)] = closed[skirt.stitches[:, 1].astype(int)]
    states = [skirt.vertices, closed.astype(np.float32)]
    before = _culling(skirt.faces, skirt.uv, skirt.stitches, states, False, monkeypatch)
    after = _culling(skirt.faces, skirt.uv, skirt.stitches, states, True, monkeypatch)
    assert (after <= before).all()
    assert time.perf_counter() - started < 60.0
