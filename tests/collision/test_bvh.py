"""MaterialBvh: tree invariants and per-node contours against a plain-Python reference."""

from __future__ import annotations

import contextlib
import os
from collections.abc import Iterator

import numpy as np
import pytest
import warp as wp
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from pscc.collision.bvh import MaterialBvh, _chain_loops
from pscc.errors import InputError
from pscc.mesh import MeshTopology, folded_sheet, grid_sheet, twisted_sheet

# --- references --------------------------------------------------------------------------------


def reference_panels(faces: np.ndarray, object_ids: np.ndarray) -> list[int]:
    """Panel label per face: edge-connected components among faces of the same object (BFS)."""
    edge_faces: dict[tuple[int, int], list[int]] = {}
    for f, face in enumerate(faces.tolist()):
        for k in range(3):
            a, b = face[k], face[(k + 1) % 3]
            edge_faces.setdefault((min(a, b), max(a, b)), []).append(f)
    label = [-1] * len(faces)
    for seed in range(len(faces)):
        if label[seed] >= 0:
            continue
        label[seed] = seed
        stack = [seed]
        while stack:
            f = stack.pop()
            face = faces[f].tolist()
            for k in range(3):
                a, b = face[k], face[(k + 1) % 3]
                for g in edge_faces[(min(a, b), max(a, b))]:
                    if label[g] < 0 and object_ids[g] == object_ids[f]:
                        label[g] = seed
                        stack.append(g)
    return label


def reference_node(faces: np.ndarray, material: np.ndarray, node_faces: list[int],
                   global_count: dict[tuple[int, int], int]) -> tuple[bool, list[int], set[int], np.ndarray]:
    """Testability, loop (from the smallest vertex), interior vertices and centroid of a multi-face node."""
    incidence: dict[tuple[int, int], list[tuple[int, int, int]]] = {}
    for f in node_faces:
        face = faces[f].tolist()
        for k in range(3):
            a, b = face[k], face[(k + 1) % 3]
            incidence.setdefault((min(a, b), max(a, b)), []).append((a, b, f))
    contour = [(a, b) for uses in incidence.values() if len(uses) == 1 for a, b, _ in uses]
    non_manifold = any(global_count[key] >= 3 for key in incidence)

    # Edge-connectivity of the node's faces.
    neighbours: dict[int, set[int]] = {f: set() for f in node_faces}
    for uses in incidence.values():
        for _, _, f in uses:
            neighbours[f].update(g for _, _, g in uses if g != f)
    seen = {node_faces[0]}
    stack = [node_faces[0]]
    while stack:
        for g in neighbours[stack.pop()]:
            if g not in seen:
                seen.add(g)
                stack.append(g)
    connected = len(seen) == len(node_faces)

    out_edges: dict[int, list[int]] = {}
    in_degree: dict[int, int] = {}
    for a, b in contour:
        out_edges.setdefault(a, []).append(b)
        in_degree[b] = in_degree.get(b, 0) + 1
    degrees_ok = (set(out_edges) == set(in_degree) and all(len(v) == 1 for v in out_edges.values())
                  and all(v == 1 for v in in_degree.values()))
    loop: list[int] = []
    if degrees_ok and contour:
        start = min(out_edges)
        v = start
        while True:
            loop.append(v)
            v = out_edges[v][0]
            if v == start:
                break
    testable = connected and not non_manifold and degrees_ok and bool(contour) and len(loop) == len(contour)
    vertices = {int(v) for f in node_faces for v in faces[f]}
    corners = material[faces[node_faces]]
    centroids = corners.mean(axis=1)
    e1, e2 = corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]
    if material.shape[1] == 2:
        area = 0.5 * np.abs(e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0])
    else:
        area = 0.5 * np.linalg.norm(np.cross(e1, e2), axis=1)
    center = (area @ centroids) / area.sum() if area.sum() > 0 else centroids.mean(axis=0)
    return testable, (loop if testable else []), vertices - set(loop), center


def check_contours(bvh: MaterialBvh, faces: np.ndarray, material: np.ndarray, panels_cut: bool = False) -> None:
    """Every node's testability, loop and reference vertex against :func:`reference_node`. With
    ``panels_cut`` (a build with a feature shape, whose panels the reference does not know), nodes above
    the panels must be untestable and are not compared."""
    material = np.asarray(material, dtype=np.float64)
    global_count: dict[tuple[int, int], int] = {}
    for face in faces.tolist():
        for k in range(3):
            a, b = face[k], face[(k + 1) % 3]
            global_count[(min(a, b), max(a, b))] = global_count.get((min(a, b), max(a, b)), 0) + 1
    assert bvh.contour_offsets.shape == (bvh.node_count + 1,) and bvh.contour_offsets[0] == 0
    assert np.all(np.diff(bvh.contour_offsets) >= 0)
    assert bvh.contour_offsets[-1] == bvh.contour_vertices.shape[0]
    for node in range(bvh.node_count):
        node_faces = bvh.faces_of(node).tolist()
        loop = bvh.contour(node).tolist()
        if bvh.is_rigid[node]:
            assert not bvh.testable[node] and loop == [] and bvh.reference_vertex[node] == -1
            continue
        if bvh.is_leaf[node]:
            assert bvh.testable[node] and loop == faces[node_faces[0]].tolist()
            assert bvh.reference_vertex[node] == -1
            continue
        if panels_cut and bvh.panel[node] < 0:
            assert not bvh.testable[node] and loop == [], node
            continue
        testable, expected, interior, center = reference_node(faces, material, node_faces, global_count)
        assert bool(bvh.testable[node]) == testable, node
        assert loop == expected, node
        ref = int(bvh.reference_vertex[node])
        if not testable or not interior:
            assert ref == -1, node
            continue
        distances = {v: float(np.sum((material[v] - center) ** 2)) for v in interior}
        assert ref in interior, node
        assert distances[ref] <= min(distances.values()) * (1 + 1e-9) + 1e-12, node


def check_tree(bvh: MaterialBvh, faces: np.ndarray, object_ids: np.ndarray, rigid: set[int] = frozenset(),
               panels: np.ndarray | None = None) -> None:
    """Structural invariants of the hierarchy (see the class docstring); ``panels``: the expected panel of
    each face (default :func:`reference_panels`, for a build without a feature shape)."""
    m = faces.shape[0]
    n_nodes = bvh.node_count
    assert bvh.face_count == m
    int_arrays = ("left", "right", "parent", "depth", "face_begin", "face_end", "object_id", "panel",
                  "reference_vertex", "contour_offsets", "contour_vertices", "face_order", "face_leaf",
                  "face_panel", "level_offsets", "level_nodes", "roots", "object_values")
    for name in int_arrays:
        assert getattr(bvh, name).dtype == np.int32, name
    for name in ("is_leaf", "is_rigid", "testable"):
        assert getattr(bvh, name).dtype == np.bool_ and getattr(bvh, name).shape == (n_nodes,), name
    assert np.array_equal(np.sort(bvh.face_order), np.arange(m))

    objects = sorted(set(object_ids.tolist()))
    expected_count = sum(1 if o in rigid else 2 * int(np.sum(object_ids == o)) - 1 for o in objects)
    assert n_nodes == expected_count

    # Roots: one per object, in object order; object_values and root_of map ids to them.
    root_nodes = np.flatnonzero(bvh.parent == -1)
    assert bvh.roots.tolist() == root_nodes.tolist()
    assert bvh.object_id[bvh.roots].tolist() == objects == bvh.object_values.tolist()
    for o in sorted({0, *objects, *(o + 1 for o in objects)}):  # every id and the one after it
        assert bvh.root_of(o) == (bvh.roots[objects.index(o)] if o in objects else -1)
    for root in bvh.roots:
        assert bvh.depth[root] == 0
        covered = bvh.faces_of(int(root))
        assert np.all(object_ids[covered] == bvh.object_id[root])
        assert covered.shape[0] == np.sum(object_ids == bvh.object_id[root])

    for node in range(n_nodes):
        begin, end = int(bvh.face_begin[node]), int(bvh.face_end[node])
        assert 0 <= begin < end <= m
        covered = bvh.faces_of(node)
        assert np.all(object_ids[covered] == bvh.object_id[node])  # objects never mixed
        left, right = int(bvh.left[node]), int(bvh.right[node])
        assert (left < 0) == (right < 0) == bool(bvh.is_leaf[node])
        if bvh.is_rigid[node]:
            assert bvh.is_leaf[node] and bvh.parent[node] == -1 and int(bvh.object_id[node]) in rigid
            assert np.all(bvh.face_leaf[covered] == node)
        elif bvh.is_leaf[node]:
            assert end - begin == 1 and bvh.face_leaf[covered[0]] == node
        else:
            assert bvh.face_begin[left] == begin and bvh.face_end[left] == bvh.face_begin[right]
            assert bvh.face_end[right] == end
            assert bvh.parent[left] == node and bvh.parent[right] == node
            assert bvh.depth[left] == bvh.depth[node] + 1 and bvh.depth[right] == bvh.depth[node] + 1
        parent = int(bvh.parent[node])
        if parent >= 0:
            assert node in (bvh.left[parent], bvh.right[parent])
    for o in objects:
        if o in rigid:
            assert bvh.is_rigid[bvh.root_of(o)]
        else:
            assert not np.any(bvh.is_rigid[bvh.object_id == o])

    # Levels: every node once, grouped by depth, deepest last.
    assert bvh.level_offsets[0] == 0 and bvh.level_offsets[-1] == n_nodes
    assert np.array_equal(np.sort(bvh.level_nodes), np.arange(n_nodes))
    for d, level in enumerate(bvh.levels):
        assert level.size > 0 and np.all(bvh.depth[level] == d)
    assert bvh.level_count == int(bvh.depth.max()) + 1

    # Panels: the reference partition; a node holds one panel or whole panels only.
    panels = np.array(reference_panels(faces, object_ids)) if panels is None else panels
    _, reference_index = np.unique(panels, return_inverse=True)
    _, our_index = np.unique(bvh.face_panel, return_inverse=True)
    pairs = set(zip(reference_index.tolist(), our_index.tolist(), strict=True))
    assert len(pairs) == len(set(reference_index.tolist())) == len(set(our_index.tolist()))
    for node in range(n_nodes):
        covered = bvh.faces_of(node)
        touched = np.unique(bvh.face_panel[covered])
        if touched.size == 1:
            assert bvh.panel[node] == touched[0]
        else:
            assert bvh.panel[node] == -1
            assert np.sum(np.isin(bvh.face_panel, touched)) == covered.size  # whole panels only


def build(faces: np.ndarray, material: np.ndarray, object_ids: np.ndarray | None = None,
          rigid: set[int] = frozenset(), device: str = "cpu") -> MaterialBvh:
    faces = np.asarray(faces, dtype=np.int32)
    if object_ids is None:
        object_ids = np.zeros(faces.shape[0], dtype=np.int32)
    topology = MeshTopology.from_faces(faces, material.shape[0])
    return MaterialBvh.build(faces, material, object_ids, topology, device, rigid_objects=rigid)


def full_check(faces: np.ndarray, material: np.ndarray, object_ids: np.ndarray | None = None,
               rigid: set[int] = frozenset()) -> MaterialBvh:
    faces = np.asarray(faces, dtype=np.int32)
    ids = np.zeros(faces.shape[0], dtype=np.int32) if object_ids is None else np.asarray(object_ids, np.int32)
    bvh = build(faces, material, ids, rigid)
    check_tree(bvh, faces, ids, set(rigid))
    check_contours(bvh, faces, material)
    return bvh


# --- hand-made patches on a regular vertex grid ------------------------------------------------


def cell_grid(cells_x: int, cells_y: int, keep: set[tuple[int, int, int]] | None = None) -> tuple[np.ndarray, ...]:
    """Triangles (i, j, t) of a cells_x x cells_y grid, t = 0: (a, b, c), t = 1: (a, c, d) (CCW)."""
    xs, ys = np.meshgrid(np.arange(cells_x + 1), np.arange(cells_y + 1))
    material = np.stack([xs.reshape(-1), ys.reshape(-1)], axis=1).astype(np.float32)
    faces = []
    for j in range(cells_y):
        for i in range(cells_x):
            a, b = j * (cells_x + 1) + i, j * (cells_x + 1) + i + 1
            d, c = a + cells_x + 1, b + cells_x + 1
            for t, tri in enumerate(([a, b, c], [a, c, d])):
                if keep is None or (i, j, t) in keep:
                    faces.append(tri)
    return np.array(faces, dtype=np.int32), material


def test_grid_sheet_tree_and_contours() -> None:
    _, faces, rest = grid_sheet(8, 8)
    bvh = full_check(faces, rest)
    assert np.all(bvh.testable)
    root = int(bvh.roots[0])
    expected = (list(range(0, 8)) + [8 + 9 * j for j in range(8)] + [80 - i for i in range(8)]
                + [72 - 9 * j for j in range(8)])
    assert bvh.contour(root).tolist() == expected  # counter-clockwise boundary, 2 (nx + ny) vertices
    assert bvh.reference_vertex[root] == 40  # the centre vertex (4, 4)


@pytest.mark.parametrize("nx, ny", [(1, 1), (3, 1), (7, 5), (13, 4), (20, 3)])
def test_grid_sheet_shapes(nx: int, ny: int) -> None:
    _, faces, rest = grid_sheet(nx, ny)
    bvh = full_check(faces, rest)
    assert bvh.contour(int(bvh.roots[0])).shape[0] == 2 * (nx + ny)
    assert np.all(bvh.testable)


def test_folded_and_twisted_sheets() -> None:
    for mesh in (folded_sheet(400, layers=3), twisted_sheet(300), folded_sheet(200, layers=2, seed=3)):
        bvh = full_check(mesh.faces, mesh.rest, mesh.object_ids)
        assert np.all(bvh.testable)
    # Without rest coordinates the caller passes the first positions (3-D material space).
    mesh = folded_sheet(300)
    full_check(mesh.faces, mesh.vertices)
    assert MaterialBvh.from_mesh(mesh, MeshTopology.from_faces(mesh.faces, mesh.vertex_count)).node_count == 599


def test_larger_sheets_tree_only() -> None:
    mesh = folded_sheet(6000, layers=4)
    bvh = build(mesh.faces, mesh.rest)
    check_tree(bvh, mesh.faces, mesh.object_ids)
    assert bvh.testable.mean() > 0.99
    lengths = np.diff(bvh.contour_offsets)
    assert np.all(lengths[bvh.testable] >= 3) and np.all(lengths[~bvh.testable] == 0)


def test_annulus_is_not_testable() -> None:
    keep = {(i, j, t) for i in range(3) for j in range(3) for t in range(2) if (i, j) != (1, 1)}
    faces, material = cell_grid(3, 3, keep)
    bvh = full_check(faces, material)
    assert not bvh.testable[bvh.roots[0]]  # outer loop and hole loop


def test_pinch_vertex_is_not_testable() -> None:
    # Ring of cells around a hole, one triangle cut so the ring touches itself only at vertex (1, 0).
    keep = {(i, j, t) for i in range(3) for j in range(3) for t in range(2) if (i, j) != (1, 1)} - {(1, 0, 1)}
    faces, material = cell_grid(3, 3, keep)
    bvh = full_check(faces, material)
    root = int(bvh.roots[0])
    assert bvh.panel[root] >= 0 and not bvh.testable[root]  # one panel, one walk, but a pinch


def test_two_faces_touching_at_a_vertex() -> None:
    faces = np.array([[0, 1, 2], [2, 3, 4]], dtype=np.int32)
    material = np.array([[0, 0], [1, 0], [1, 1], [2, 1], [2, 2]], dtype=np.float32)
    bvh = full_check(faces, material)
    root = int(bvh.roots[0])
    assert not bvh.testable[root] and bvh.panel[root] == -1 and bvh.contour(root).size == 0


def test_non_manifold_edge_is_not_testable() -> None:
    faces, material = cell_grid(2, 2)
    material = np.vstack([material, [[0.3, 0.8]]]).astype(np.float32)
    fin = [0, 4, material.shape[0] - 1]  # third face on the diagonal (0, 4) of cell (0, 0)
    faces = np.vstack([faces, [fin]]).astype(np.int32)
    bvh = full_check(faces, material)
    assert not bvh.testable[bvh.roots[0]]
    for node in np.flatnonzero(~bvh.is_leaf):
        if any({0, 4} <= set(faces[f].tolist()) for f in bvh.faces_of(node)):
            assert not bvh.testable[node]


def test_objects_panels_and_rigid() -> None:
    a, ma = cell_grid(4, 3)
    b, mb = cell_grid(2, 2)
    c, mc = cell_grid(3, 1)
    faces = np.vstack([a, b + ma.shape[0], c + ma.shape[0] + mb.shape[0], b + ma.shape[0]])
    faces[-b.shape[0]:] = faces[-b.shape[0]:, ::-1]  # repeat of panel b, flipped: a separate object
    material = np.vstack([ma, mb, mc]).astype(np.float32)  # overlapping charts, as in garments
    ids = np.concatenate([np.full(a.shape[0], 2), np.full(b.shape[0], 2), np.full(c.shape[0], 5),
                          np.full(b.shape[0], 7)]).astype(np.int32)
    bvh = full_check(faces, material, ids, rigid={5})
    assert bvh.roots.shape == (3,) and [bvh.root_of(o) for o in range(3)] == [-1, -1, int(bvh.roots[0])]
    assert bvh.is_rigid[bvh.root_of(5)] and bvh.node_count == (2 * 32 - 1) + 1 + (2 * 8 - 1)
    top = bvh.root_of(2)
    assert bvh.panel[top] == -1 and not bvh.testable[top]
    assert bvh.panel[bvh.left[top]] >= 0 and bvh.panel[bvh.right[top]] >= 0  # two panels: one top node
    assert np.all(bvh.face_leaf[ids == 5] == bvh.root_of(5))


# --- random meshes -----------------------------------------------------------------------------


@st.composite
def patch_meshes(draw: st.DrawFn) -> tuple[np.ndarray, np.ndarray, np.ndarray, set[int]]:
    """Several grid patches (holes, flips, glued vertices, extra faces), objects and rigid ids."""
    faces_list, material_list, ids_list = [], [], []
    offset = 0
    for _ in range(draw(st.integers(1, 4))):
        nx, ny = draw(st.integers(1, 6)), draw(st.integers(1, 5))
        cells = [(i, j, t) for i in range(nx) for j in range(ny) for t in range(2)]
        mask = draw(st.lists(st.integers(0, 9), min_size=len(cells), max_size=len(cells)))  # holes: 1 in 5
        keep = {cell for cell, kept in zip(cells, mask, strict=True) if kept >= 2} or {cells[0]}
        faces, material = cell_grid(nx, ny, keep)
        flips = np.array(draw(st.lists(st.integers(0, 19), min_size=faces.shape[0], max_size=faces.shape[0])))
        faces[flips == 0] = faces[flips == 0][:, ::-1]  # a few faces against the patch orientation
        if draw(st.booleans()):
            faces = faces[:, ::-1].copy()  # whole patch clockwise
        shift = draw(st.tuples(st.floats(-2, 2), st.floats(-2, 2)))
        faces_list.append(faces + offset)
        material_list.append(material + np.array(shift, dtype=np.float32))
        ids_list.append(np.full(faces.shape[0], draw(st.integers(0, 3)), dtype=np.int32))
        offset += material.shape[0]
    faces = np.vstack(faces_list)
    material = np.vstack(material_list)
    ids = np.concatenate(ids_list)
    # Glue a few vertex pairs (pinches, shared edges across patches) and add a few stray faces.
    for _ in range(draw(st.integers(0, 3))):
        u, v = draw(st.integers(0, offset - 1)), draw(st.integers(0, offset - 1))
        faces[faces == max(u, v)] = min(u, v)
    extra = draw(st.lists(st.lists(st.integers(0, offset - 1), min_size=3, max_size=3, unique=True), max_size=3))
    if extra:
        faces = np.vstack([faces, np.array(extra, dtype=np.int32)])
        ids = np.concatenate([ids, np.full(len(extra), ids[0], dtype=np.int32)])
    good = (faces[:, 0] != faces[:, 1]) & (faces[:, 1] != faces[:, 2]) & (faces[:, 0] != faces[:, 2])
    faces, ids = faces[good], ids[good]
    _, unique_rows = np.unique(np.sort(faces, axis=1), axis=0, return_index=True)
    unique_rows = np.sort(unique_rows)
    faces, ids = faces[unique_rows], ids[unique_rows]
    rigid = set(draw(st.lists(st.integers(0, 3), max_size=2)))
    if draw(st.booleans()):
        material = np.hstack([material, draw(st.floats(-1, 1)) * material[:, :1]]).astype(np.float32)
    return faces, material.astype(np.float32), ids, rigid


@settings(max_examples=120, deadline=None)
@given(patch_meshes())
def test_random_patch_meshes(case: tuple[np.ndarray, np.ndarray, np.ndarray, set[int]]) -> None:
    faces, material, ids, rigid = case
    assume(faces.shape[0] > 0)
    full_check(faces, material, ids, rigid)


@settings(max_examples=80, deadline=None)
@given(st.data())
def test_random_triangle_soups(data: st.DataObject) -> None:
    n = data.draw(st.integers(3, 14))
    triple = st.lists(st.integers(0, n - 1), min_size=3, max_size=3, unique=True)
    faces = data.draw(st.lists(triple, min_size=1, max_size=30, unique_by=lambda f: tuple(sorted(f))))
    coords = data.draw(st.lists(st.tuples(st.integers(-5, 5), st.integers(-5, 5)), min_size=n, max_size=n))
    ids = data.draw(st.lists(st.integers(0, 2), min_size=len(faces), max_size=len(faces)))
    full_check(np.array(faces, dtype=np.int32), np.array(coords, dtype=np.float32), np.array(ids, dtype=np.int32))


def test_chain_loops_cases() -> None:
    """The loop chaining on hand-made directed edge lists (node, tail, head)."""
    edges = [
        (0, 5, 7), (0, 7, 9), (0, 9, 5),  # node 0: one loop 5 -> 7 -> 9
        (1, 1, 2), (1, 2, 3), (1, 3, 1), (1, 4, 5), (1, 5, 6), (1, 6, 4),  # node 1: two loops
        (2, 1, 2), (2, 3, 2), (2, 2, 1),  # node 2: vertex 2 entered twice, 3 never entered
        (3, 1, 2), (3, 2, 3),  # node 3: open chain
        (4, 3, 1), (4, 1, 2), (4, 2, 3), (4, 3, 4), (4, 4, 0), (4, 0, 3),  # node 4: pinch at vertex 3
        (5, 8, 6), (5, 6, 4), (5, 4, 8),  # node 5: one loop, starts at vertex 4
    ]
    node, tail, head = (np.array(column, dtype=np.int64) for column in zip(*edges, strict=True))
    loop_node, rank, vertex = _chain_loops(node, tail, head, 10, 6)
    loops: dict[int, list[int]] = {}
    for k in np.argsort(loop_node * 100 + rank, kind="stable"):
        loops.setdefault(int(loop_node[k]), []).append(int(vertex[k]))
    assert loops == {0: [5, 7, 9], 5: [4, 8, 6]}
    # An open chain alone in its node.
    node, tail, head = np.array([0, 0, 1, 1, 1]), np.array([1, 2, 4, 5, 6]), np.array([2, 3, 5, 6, 4])
    loop_node, rank, vertex = _chain_loops(node, tail, head, 10, 2)
    assert loop_node.tolist() == [1, 1, 1] and vertex[np.argsort(rank)].tolist() == [4, 5, 6]


def test_zero_area_material_uses_the_mean_centroid() -> None:
    faces, material = cell_grid(4, 4)
    material[:, 1] = 0.0  # every face degenerate in material space
    bvh = full_check(faces, material)
    assert bvh.reference_vertex[bvh.roots[0]] == 7  # (2, 1): the first interior vertex at x = 2


# --- device copies, errors, timing -------------------------------------------------------------


def test_device_arrays(device: str) -> None:
    mesh = twisted_sheet(200)
    bvh = build(mesh.faces, mesh.rest, device=device)
    assert str(bvh.device) == device
    total = 0
    for name in ("left", "right", "parent", "depth", "face_begin", "face_end", "is_leaf", "is_rigid", "object_id",
                 "testable", "reference_vertex", "reference_face", "contour_offsets", "contour_vertices", "face_order",
                 "face_leaf", "level_offsets", "level_nodes", "seam_offsets"):
        array = getattr(bvh.arrays, name)
        assert array.device == bvh.device and array.dtype == wp.int32
        assert np.array_equal(array.numpy(), getattr(bvh, name).astype(np.int32)), name
        total += array.capacity
    assert bvh.seam_vertices.size == 0 and bvh.arrays.seam_vertices.shape == (1,)  # no stitches: one unused entry
    total += bvh.arrays.seam_vertices.capacity
    assert bvh.device_bytes == total > 0


def test_invalid_input() -> None:
    _, faces, rest = grid_sheet(2, 2)
    topology = MeshTopology.from_faces(faces, rest.shape[0])
    ids = np.zeros(faces.shape[0], dtype=np.int32)
    with pytest.raises(InputError, match="faces"):
        MaterialBvh.build(faces.astype(np.float32), rest, ids, topology)
    with pytest.raises(InputError, match="faces"):
        MaterialBvh.build(faces + 100, rest, ids, topology)
    with pytest.raises(InputError, match="material"):
        MaterialBvh.build(faces, rest[:, :1], ids, topology)
    with pytest.raises(InputError, match="material"):
        MaterialBvh.build(faces, np.full_like(rest, np.nan), ids, topology)
    with pytest.raises(InputError, match="object_ids"):
        MaterialBvh.build(faces, rest, ids - 1, topology)
    with pytest.raises(InputError, match="topology"):
        MaterialBvh.build(faces[:4], rest, ids[:4], topology)
    with pytest.raises(InputError, match="rigid_objects"):
        MaterialBvh.build(faces, rest, ids, topology, rigid_objects=["x"])


def test_large_folded_sheet() -> None:
    """A 50K-triangle folded sheet builds a full binary tree whose internal nodes are all testable
    (build times are measured in docs/bvh.md, not here)."""
    mesh = folded_sheet(50_000)
    topology = MeshTopology.from_faces(mesh.faces, mesh.vertex_count)
    bvh = MaterialBvh.from_mesh(mesh, topology)
    assert bvh.node_count == 2 * mesh.face_count - 1
    internal = ~bvh.is_leaf.astype(bool)
    assert bvh.testable[internal].all()


@contextlib.contextmanager
def _address_space_limit(extra_bytes: int) -> Iterator[None]:
    """Let the process map at most ``extra_bytes`` more, so a runaway allocation fails fast as a MemoryError."""
    resource = pytest.importorskip("resource")
    with open("/proc/self/statm") as statm:
        used = int(statm.read().split()[0]) * os.sysconf("SC_PAGE_SIZE")
    soft, hard = resource.getrlimit(resource.RLIMIT_AS)
    limit = used + extra_bytes
    if hard != resource.RLIM_INFINITY:
        limit = min(limit, hard)
    resource.setrlimit(resource.RLIMIT_AS, (limit, hard))
    try:
        yield
    finally:
        resource.setrlimit(resource.RLIMIT_AS, (soft, hard))


def test_sparse_object_ids_build_the_same_tree_in_small_memory() -> None:
    """Ids {5, 7, 2**31 - 1} give the tree of {0, 1, 2}; no table has max id + 1 rows (that took 16 GiB)."""
    a, ma = cell_grid(4, 3)
    b, mb = cell_grid(2, 2)
    c, mc = cell_grid(3, 1)
    faces = np.vstack([a, b + ma.shape[0], c + ma.shape[0] + mb.shape[0]])
    material = np.vstack([ma, mb, mc]).astype(np.float32)
    sizes = (a.shape[0], b.shape[0], c.shape[0])
    small = np.repeat(np.array([0, 1, 2], dtype=np.int64), sizes)
    big = 2**31 - 1
    sparse = np.repeat(np.array([5, 7, big], dtype=np.int64), sizes)
    reference = build(faces, material, small, rigid={2})
    with _address_space_limit(1 << 30):
        bvh = build(faces, material, sparse, rigid={big, 2**70})  # an id no face has is ignored, however large
    check_tree(bvh, faces, sparse.astype(np.int32), {big})
    assert bvh.object_values.tolist() == [5, 7, big]
    assert bvh.root_of(big) == int(bvh.roots[2]) and bvh.root_of(0) == bvh.root_of(big - 1) == -1
    assert bvh.is_rigid[bvh.root_of(big)]
    rename = {0: 5, 1: 7, 2: big}
    for name in ("left", "right", "parent", "depth", "face_begin", "face_end", "is_leaf", "is_rigid", "panel",
                 "testable", "reference_vertex", "reference_face", "contour_offsets", "contour_vertices", "face_order",
                 "face_leaf"):
        np.testing.assert_array_equal(getattr(bvh, name), getattr(reference, name), err_msg=name)
    assert [rename[o] for o in reference.object_id.tolist()] == bvh.object_id.tolist()
    assert bvh.roots.tolist() == reference.roots.tolist()
    def host_sizes(tree: MaterialBvh) -> dict[str, int]:
        return {name: value.size for name, value in vars(tree).items() if isinstance(value, np.ndarray)}

    assert host_sizes(bvh) == host_sizes(reference)  # every table as small as with ids 0, 1, 2
    assert bvh.device_bytes == reference.device_bytes


@pytest.mark.parametrize("bad", [-1, 2**31, 2**40])
def test_object_ids_outside_int32_are_refused(bad: int) -> None:
    _, faces, rest = grid_sheet(2, 2)
    topology = MeshTopology.from_faces(faces, rest.shape[0])
    ids = np.zeros(faces.shape[0], dtype=np.int64)
    ids[3] = bad
    with pytest.raises(InputError) as caught:
        MaterialBvh.build(faces, rest, ids, topology)
    assert (caught.value.source, caught.value.field) == ("argument", "object_ids")
    assert f"has object id {bad}, outside [0, 2147483647]" in caught.value.problem


def _capped_cylinder(sections: int = 64) -> tuple[np.ndarray, np.ndarray]:
    """A closed cylinder whose flat caps are fans of slivers around their centres (as exporters write them)."""
    import trimesh

    mesh = trimesh.creation.cylinder(radius=1.0, height=0.2, sections=sections)
    return np.asarray(mesh.vertices, dtype=np.float64), np.asarray(mesh.faces, dtype=np.int32)


def test_feature_edges_cut_panels_of_an_embedded_shape() -> None:
    """With ``feature_shape``, a cylinder's two caps and its wall are three panels (the rim edges are 90
    degrees sharp), each cap a subtree whose root covers the whole cap; without it, one panel. Its 2-D
    rest coordinates would keep the pattern's panels: nothing is cut when no shape is given."""
    from pscc.collision.intrinsic import bvh_material

    vertices, faces = _capped_cylinder()
    topology = MeshTopology.from_faces(faces, vertices.shape[0])
    material = bvh_material(faces, None, vertices)
    objects = np.zeros(faces.shape[0], dtype=np.int64)
    plain = MaterialBvh.build(faces, material, objects, topology)
    cut = MaterialBvh.build(faces, material, objects, topology, feature_shape=vertices)
    assert np.unique(plain.face_panel).size == 1
    assert np.unique(cut.face_panel).size == 3
    normal = np.cross(vertices[faces[:, 1]] - vertices[faces[:, 0]], vertices[faces[:, 2]] - vertices[faces[:, 0]])
    cap = np.abs(normal[:, 2]) > 0.5 * np.linalg.norm(normal, axis=1)
    # Every panel is all cap (of one side) or all wall, and each cap is the range of one testable node.
    for panel in np.unique(cut.face_panel):
        members = np.flatnonzero(cut.face_panel == panel)
        assert cap[members].all() or not cap[members].any()
        if cap[members].all():
            covering = [node for node in range(cut.node_count)
                        if set(cut.faces_of(node).tolist()) == set(members.tolist())]
            assert covering and cut.testable[covering[0]]
    with pytest.raises(InputError, match="feature_shape"):
        MaterialBvh.build(faces, material, objects, topology, feature_shape=vertices[:-1])


def test_feature_edges_shrink_the_front_and_keep_the_dcd_contract() -> None:
    """pscc's detector on the cylinder without rest coordinates: its front covers each cap with one node
    (6 nodes at 64 sections, 147 without the cut), and its contacts are brute force's less only pairs inside one
    front node or of neighbouring faces certified apart (the contract of tests/collision/test_pscc.py)."""
    from tests.collision.test_pscc import _check_dcd_contract, _detectors

    vertices, faces = _capped_cylinder()
    x = vertices.astype(np.float32)
    detectors = _detectors(faces)
    thickness = 0.02
    _check_dcd_contract(faces, x, thickness, detectors)
    front = detectors["pscc"].broad_phase_stats()["front_size"]
    assert front <= 16, front
