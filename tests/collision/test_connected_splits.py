"""BVH nodes over CAD-like tessellations: cuts that keep both halves edge-connected, and reference faces for
the contour test of nodes without interior vertex (pscc.collision.connected_splits, reference_points)."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sparse
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.sparse import csgraph
from scipy.spatial import Delaunay

import pscc.collision.bvh as bvh_module
from pscc.collision.bvh import MaterialBvh
from pscc.collision.connected_splits import connected_cut, face_adjacency, face_links, split_pieces, union_roots
from pscc.collision.intrinsic import bvh_material
from pscc.collision.reference_points import reference_faces
from pscc.geometry import simple_contour
from pscc.mesh import MeshTopology
from tests.collision.test_bvh import check_contours, check_tree
from tests.collision.test_pscc import _assert_same_contacts, _check_dcd_contract, _detectors


def sliver_plate(points: int, seed: int, stretch: float = 20.0) -> tuple[np.ndarray, np.ndarray]:
    """A bent plate triangulated like an exporter's CAD face: the Delaunay triangles of random points in a
    1 x 1/stretch strip (long slivers whose centroids interleave), bent out of the plane."""
    rng = np.random.default_rng(seed)
    flat = rng.random((points, 2))
    flat[:, 1] /= stretch
    faces = Delaunay(flat).simplices.astype(np.int32)
    vertices = np.concatenate([flat, 0.1 * np.sin(3.0 * flat[:, :1])], axis=1)
    return vertices, faces


def components(faces: np.ndarray, members: np.ndarray) -> int:
    """Edge-connected pieces of the faces ``members`` (a plain search, the reference)."""
    edge_faces: dict[tuple[int, int], list[int]] = {}
    for f in members.tolist():
        tri = faces[f].tolist()
        for k in range(3):
            edge = (min(tri[k], tri[(k + 1) % 3]), max(tri[k], tri[(k + 1) % 3]))
            edge_faces.setdefault(edge, []).append(f)
    neighbours: dict[int, set[int]] = {f: set() for f in members.tolist()}
    for shared in edge_faces.values():
        for f in shared:
            neighbours[f].update(g for g in shared if g != f)
    seen: set[int] = set()
    pieces = 0
    for start in neighbours:
        if start in seen:
            continue
        pieces += 1
        stack = [start]
        seen.add(start)
        while stack:
            for g in neighbours[stack.pop()]:
                if g not in seen:
                    seen.add(g)
                    stack.append(g)
    return pieces


def test_union_roots_are_the_smallest_member_of_each_component() -> None:
    rng = np.random.default_rng(3)
    for _ in range(20):
        count = int(rng.integers(1, 60))
        links = rng.integers(0, count, size=(int(rng.integers(0, 80)), 2))
        roots = union_roots(count, links[:, 0], links[:, 1])
        graph = sparse.coo_matrix((np.ones(links.shape[0]), (links[:, 0], links[:, 1])), shape=(count, count))
        _, label = csgraph.connected_components(graph, directed=False)
        smallest = {lab: int(np.flatnonzero(label == lab).min()) for lab in np.unique(label)}
        assert roots.tolist() == [smallest[lab] for lab in label.tolist()]


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), nodes=st.integers(1, 6))
def test_split_pieces_flags_exactly_the_cuts_with_a_half_in_pieces(seed: int, nodes: int) -> None:
    """Random disjoint ranges of a random face order, cut at random: the flag is True exactly when a plain
    search finds a half of several edge-connected pieces."""
    vertices, faces = sliver_plate(60, seed % 1000)
    topology = MeshTopology.from_faces(faces, vertices.shape[0])
    rng = np.random.default_rng(seed)
    order = rng.permutation(faces.shape[0])
    bounds = np.sort(rng.choice(np.arange(1, faces.shape[0]), size=min(nodes, faces.shape[0] - 1), replace=False))
    begin = np.concatenate([[0], bounds])[:-1]
    end = bounds
    keep = end - begin >= 2
    begin, end = begin[keep], end[keep]
    if begin.size == 0:
        return
    left = np.array([rng.integers(1, e - b) for b, e in zip(begin, end, strict=True)])
    flags = split_pieces(order, begin, end, left, face_links(topology), faces.shape[0])
    for i, (b, e) in enumerate(zip(begin.tolist(), end.tolist(), strict=True)):
        halves = (order[b:b + left[i]], order[b + left[i]:e])
        assert bool(flags[i]) == any(components(faces, half) > 1 for half in halves), i


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), size=st.integers(2, 80))
def test_connected_cut_keeps_the_faces_and_connects_both_halves(seed: int, size: int) -> None:
    """On an edge-connected set of faces (grown from one face), a connected cut reorders the same faces so
    that its median halves are both edge-connected; it is deterministic; on a set in pieces it gives None."""
    vertices, faces = sliver_plate(120, seed % 1000)
    topology = MeshTopology.from_faces(faces, vertices.shape[0])
    adjacency = face_adjacency(topology, faces.shape[0])
    rng = np.random.default_rng(seed)
    grown = [int(rng.integers(faces.shape[0]))]
    while len(grown) < min(size, faces.shape[0]):
        frontier = sorted(set(adjacency[grown].indices.tolist()) - set(grown))
        if not frontier:
            break
        grown.append(int(rng.choice(frontier)))
    members = rng.permutation(np.array(grown))
    result = connected_cut(members, adjacency)
    if result is not None:
        assert sorted(result.tolist()) == sorted(members.tolist())
        cut = (members.size + 1) // 2
        assert components(faces, result[:cut]) == 1 and components(faces, result[cut:]) == 1
        assert np.array_equal(result, connected_cut(members, adjacency))
    far = np.array([0, int(np.argmax(np.linalg.norm(vertices[faces].mean(axis=1) - vertices[faces[0]].mean(axis=0),
                                                   axis=1)))])
    if components(faces, far) > 1:
        assert connected_cut(far, adjacency) is None


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_connected_cut_finds_a_cut_for_most_grown_patches(seed: int) -> None:
    """Of 40 edge-connected patches of 4-60 sliver faces grown at random (ragged, unlike a tree's nodes), the
    search finds a cut with both halves edge-connected for most (26-28 of 40 at seeds 0-2)."""
    vertices, faces = sliver_plate(120, seed)
    adjacency = face_adjacency(MeshTopology.from_faces(faces, vertices.shape[0]), faces.shape[0])
    rng = np.random.default_rng(seed)
    found = 0
    for _ in range(40):
        grown = [int(rng.integers(faces.shape[0]))]
        size = int(rng.integers(4, 60))
        while len(grown) < size:
            frontier = sorted(set(adjacency[grown].indices.tolist()) - set(grown))
            if not frontier:
                break
            grown.append(int(rng.choice(frontier)))
        found += connected_cut(rng.permutation(np.array(grown)), adjacency) is not None
    assert found >= 24, found


def _build(vertices: np.ndarray, faces: np.ndarray) -> tuple[MaterialBvh, np.ndarray]:
    """The detector's BVH of a mesh without rest coordinates: the intrinsic embedding, cut at its shape's
    feature edges."""
    topology = MeshTopology.from_faces(faces, vertices.shape[0])
    material = bvh_material(faces, None, vertices)
    bvh = MaterialBvh.build(faces, material, np.zeros(faces.shape[0], dtype=np.int32), topology,
                            feature_shape=vertices)
    return bvh, material


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_sliver_plates_get_far_fewer_untestable_nodes(seed: int, monkeypatch: pytest.MonkeyPatch) -> None:
    """On sliver plates many median cuts leave a half in pieces (never testable); cut again along the surface,
    well under half as many inner nodes stay untestable (160 -> 67, 198 -> 41, 169 -> 26 at seeds 0-2). The
    tree and its contours keep every invariant of tests/collision/test_bvh.py."""
    vertices, faces = sliver_plate(400, seed)
    bvh, material = _build(vertices, faces)
    topology = MeshTopology.from_faces(faces, vertices.shape[0])
    ids = np.zeros(faces.shape[0], dtype=np.int32)
    panels = bvh_module._face_panels(topology, ids, bvh_module._feature_edges(faces, vertices, topology))
    check_tree(bvh, faces, ids, panels=panels)
    check_contours(bvh, faces, material, panels_cut=True)
    with monkeypatch.context() as patch:
        patch.setattr(bvh_module, "_connect_halves", lambda *args: None)
        plain, _ = _build(vertices, faces)
    untestable = int(np.sum(~bvh.is_leaf & ~bvh.testable))
    before = int(np.sum(~plain.is_leaf & ~plain.testable))
    assert untestable < 0.5 * before, (untestable, before)


def _star_margin(points: np.ndarray, loop: np.ndarray, o: np.ndarray, axis: np.ndarray) -> float:
    """The smallest turn of the contour edges around o (positive: they all turn one way)."""
    a = points[loop] - o
    b = points[np.roll(loop, -1)] - o
    turns = np.cross(a, b) @ axis / (np.linalg.norm(a, axis=1) * np.linalg.norm(b, axis=1))
    return float(max(turns.min(), -turns.max()))


@pytest.mark.parametrize("seed", [0, 3])
def test_reference_faces_see_the_contour_turn_one_way(seed: int) -> None:
    """A reference face is chosen exactly for the testable inner nodes without interior vertex whose contour
    mean fails the star test in the shape; it is one of the node's faces, and the contour turns one way around
    its centroid."""
    vertices, faces = sliver_plate(400, seed)
    bvh, _ = _build(vertices, faces)
    chosen = np.flatnonzero(bvh.reference_face >= 0)
    assert chosen.size > 10
    normal = np.cross(vertices[faces[:, 1]] - vertices[faces[:, 0]], vertices[faces[:, 2]] - vertices[faces[:, 0]])
    for node in range(bvh.node_count):
        face = int(bvh.reference_face[node])
        if face < 0:
            continue
        assert bvh.testable[node] and not bvh.is_leaf[node] and bvh.reference_vertex[node] == -1
        members = bvh.faces_of(node)
        assert face in members.tolist()
        axis = normal[members].sum(axis=0)
        axis /= np.linalg.norm(axis)
        loop = bvh.contour(node)
        assert _star_margin(vertices, loop, vertices[loop].mean(axis=0), axis) <= 0.0
        assert _star_margin(vertices, loop, vertices[faces[face]].mean(axis=0), axis) > 0.0
    # A node with a reference vertex never gets a face.
    host = {name: getattr(bvh, name) for name in ("testable", "is_leaf", "reference_vertex", "contour_offsets",
                                                  "contour_vertices", "face_order", "face_begin", "face_end")}
    host["reference_vertex"] = np.where(bvh.testable & ~bvh.is_leaf, 0, -1)
    assert np.all(reference_faces(faces, vertices, host) == -1)


def test_reference_faces_shrink_the_front(monkeypatch: pytest.MonkeyPatch) -> None:
    """pscc's detector on a plate of thinner slivers without rest, the star test alone (no simple-contour
    fallback): with the faces' centroids as the contour test's points, its front has fewer nodes than with
    the contour means (284 against 343)."""
    vertices, faces = sliver_plate(400, 0, stretch=50.0)
    x = vertices.astype(np.float32)
    sizes = {}
    for label in ("faces", "means"):
        with monkeypatch.context() as patch:
            patch.setattr(simple_contour, "SIMPLE_CONTOUR_MAX_EDGES", 0)
            if label == "means":
                patch.setattr(bvh_module, "reference_faces",
                              lambda faces, shape, host: np.full(host["left"].shape[0], -1, dtype=np.int64))
            detector = _detectors(faces)["pscc"]
            detector.detect(x, thickness=0.002)
            sizes[label] = detector.detect(x, thickness=0.002).stats["front_size"]
    assert sizes["faces"] < sizes["means"], sizes


@settings(max_examples=6, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), motion=st.sampled_from([0.01, 0.05, 0.2]))
def test_sliver_plates_hide_no_contact(seed: int, motion: float) -> None:
    """CCD and touching DCD (thickness 0) of pscc equal brute force on crumpled sliver plates without rest
    (nodes certified with reference faces and connected cuts never hide a contact); DCD at a radius keeps
    pscc's contract (tests/collision/test_pscc.py)."""
    vertices, faces = sliver_plate(300, seed % 1000)
    assert_shaken_hides_no_contact(faces, vertices.astype(np.float32), seed, motion, "sliver plate")


def assert_shaken_hides_no_contact(faces: np.ndarray, x0: np.ndarray, seed: int, motion: float, label: str) -> None:
    """pscc's CCD from ``x0`` to ``x0`` plus Gaussian noise of deviation ``motion``, and its touching DCD at
    the end, equal brute force (no rest coordinates); its DCD at radius 0.01 keeps pscc's contract."""
    rng = np.random.default_rng(seed)
    x1 = (x0 + rng.normal(0.0, motion, x0.shape)).astype(np.float32)
    detectors = _detectors(faces)
    for positions, end in ((x0, x1), (x1, None)):
        reference = detectors["brute-force"].detect(positions, end)
        result = detectors["pscc"].detect(positions, end)
        _assert_same_contacts(result, reference, faces, positions, end, 0.0, label)
    _check_dcd_contract(faces, x0, 0.01, detectors)
