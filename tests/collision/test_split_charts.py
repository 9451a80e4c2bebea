"""Meshes exported in charts: vertices duplicated along chart borders, as a UV-split export writes them.

Frames from other systems often come this way: every vertex on a border between two UV charts is
written once per chart, at the same position. Two faces on either side of such a border then share no
vertex id, while their border vertices and edges lie exactly on each other: distance-0 vertex-face and
edge-edge pairs, collinear overlapping edges, and faces that the shared-vertex certificate cannot see as
neighbours. pscc must keep its DCD contract (every pair it leaves out lies inside one front node or is
certified) and its CCD must equal brute force on them.
"""

from __future__ import annotations

from collections import deque

import numpy as np
import pytest
import warp as wp
from hypothesis import given, settings
from hypothesis import strategies as st

from pscc.collision.detector import CollisionDetector
from pscc.collision.recorded import RecordedDetection
from pscc.mesh import folded_sheet, twisted_sheet
from tests.collision.test_pscc import _assert_same_contacts, _check_dcd_contract, _detectors, _rows


def split_into_charts(faces: np.ndarray, charts: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """Faces grown into ``charts`` regions from random seed faces (across shared edges), and every vertex
    written once per region that uses it.

    Returns:
        ``(split_faces, source)``: the faces on the new vertex ids, and for each new vertex the vertex it
        copies (index the old per-vertex arrays with it).
    """
    rng = np.random.default_rng(seed)
    by_edge: dict[tuple[int, int], list[int]] = {}
    for f, tri in enumerate(faces.tolist()):
        for k in range(3):
            by_edge.setdefault(tuple(sorted((tri[k], tri[(k + 1) % 3]))), []).append(f)
    neighbours: list[list[int]] = [[] for _ in range(len(faces))]
    for sharing in by_edge.values():
        for a in sharing:
            neighbours[a].extend(b for b in sharing if b != a)
    chart = np.full(len(faces), -1)
    queue: deque[int] = deque()
    for label, start in enumerate(rng.choice(len(faces), size=charts, replace=False)):
        chart[start] = label
        queue.append(int(start))
    while queue:
        f = queue.popleft()
        for g in neighbours[f]:
            if chart[g] < 0:
                chart[g] = chart[f]
                queue.append(g)
    chart[chart < 0] = 0
    new_id: dict[tuple[int, int], int] = {}
    split = np.empty_like(faces)
    for f, tri in enumerate(faces.tolist()):
        for k, v in enumerate(tri):
            split[f, k] = new_id.setdefault((v, int(chart[f])), len(new_id))
    source = np.empty(len(new_id), dtype=np.int64)
    for (v, _), i in new_id.items():
        source[i] = v
    return split.astype(np.int32), source


def _border_copies(source: np.ndarray) -> int:
    """How many vertices were written more than once."""
    return int((np.bincount(source) > 1).sum())


@settings(max_examples=6, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), charts=st.integers(2, 9), thickness=st.sampled_from([0.0, 0.01]),
       with_rest=st.booleans())
def test_dcd_contract_on_split_folds(seed: int, charts: int, thickness: float, with_rest: bool) -> None:
    mesh = folded_sheet(600, layers=3, seed=seed % 1000)
    faces, source = split_into_charts(mesh.faces, charts, seed)
    assert _border_copies(source) > 0
    rng = np.random.default_rng(seed)
    # The noise is per original vertex: the copies of a border vertex stay on each other.
    x = (mesh.vertices_end + rng.normal(0.0, 0.01, mesh.vertices.shape)).astype(np.float32)[source]
    _check_dcd_contract(faces, x, thickness, _detectors(faces, mesh.rest[source] if with_rest else None))


@pytest.mark.parametrize("with_rest", [True, False])
def test_chart_borders_are_contacts_that_pscc_keeps_or_certifies(with_rest: bool) -> None:
    """At thickness 0 the copies along a border touch: brute force reports them, and pscc's DCD keeps
    every one whose faces lie in two front nodes (the contract of the test above, on a twisted strip)."""
    mesh = twisted_sheet(1500, turns=1.5, seed=2)
    faces, source = split_into_charts(mesh.faces, 6, seed=5)
    x = mesh.vertices[source]
    detectors = _detectors(faces, mesh.rest[source] if with_rest else None)
    reference_vf, reference_ee = _rows(detectors["brute-force"].detect(x, thickness=0.0))
    # Pairs across a border: their features are copies of one original vertex or edge, at distance 0.
    across_vf = {(v, f) for v, f in reference_vf if source[v] in source[faces[f]]}
    assert len(across_vf) >= _border_copies(source)
    _check_dcd_contract(faces, x, 0.0, detectors)


@pytest.mark.parametrize("maker", ["folded", "twisted"])
def test_ccd_on_split_meshes_equals_brute_force(maker: str) -> None:
    mesh = folded_sheet(900, layers=3, seed=4) if maker == "folded" else twisted_sheet(900, turns=1.5, seed=4)
    faces, source = split_into_charts(mesh.faces, 7, seed=11)
    x0 = mesh.vertices[source]
    end = mesh.vertices_end
    if maker == "twisted":  # shake it so that parts of the strip pass through others within the step
        end = end + np.random.default_rng(3).normal(0.0, 0.03 * np.abs(mesh.vertices).max(), end.shape)
    x1 = end.astype(np.float32)[source]
    detectors = _detectors(faces, mesh.rest[source])
    reference = detectors["brute-force"].detect(x0, x1)
    assert len(reference.vertex_face) + len(reference.edge_edge) > 0
    for method in ("spatial-hash", "pscc"):
        _assert_same_contacts(detectors[method].detect(x0, x1), reference, faces, x0, x1, 0.0, method)


def test_split_mesh_replay_matches_its_call() -> None:
    """The device path on a split mesh: a recorded graph gives the rows of the host call."""
    mesh = twisted_sheet(900, turns=1.5, seed=6)
    faces, source = split_into_charts(mesh.faces, 5, seed=8)
    x = mesh.vertices[source]
    detector = CollisionDetector(faces, method="pscc", rest=mesh.rest[source])
    expected = _rows(detector.detect(x, thickness=0.01))
    recorded = RecordedDetection(detector, wp.array(x, dtype=wp.vec3, device=detector.device), thickness=0.01)
    assert _rows(detector.collect(recorded.replay())) == expected
