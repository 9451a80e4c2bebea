"""The PSCC broad phase against the brute-force oracle: the correctness contract of issue 3."""

from __future__ import annotations

import ipctk
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pscc.collision.detector import CollisionDetector
from pscc.collision.feature_pairs import ownership_bits
from pscc.errors import InputError
from pscc.mesh import MeshTopology, folded_sheet, grid_sheet, twisted_sheet
from tests.collision.shared_oracle import meet_only_in_shared, shared_vertex_ids


def _rows(result):
    return {tuple(int(x) for x in r) for r in result.vertex_face}, {tuple(int(x) for x in r) for r in result.edge_edge}


_CCD_ORACLE = ipctk.TightInclusionCCD(tolerance=1e-9, max_iterations=1_000_000, conservative_rescaling=1.0)


def _truly_touches(kind: str, row: tuple, faces: np.ndarray, x0: np.ndarray, x1, thickness: float) -> bool:
    """Float64 ipctk decision for one reported row: does the pair really come within the thickness?"""
    ids = [row[0], *faces[row[1]]] if kind == "vf" else list(row)
    p0 = [np.float64(x0[i]) for i in ids]
    if x1 is None:
        d2 = ipctk.point_triangle_distance(*p0) if kind == "vf" else ipctk.edge_edge_distance(*p0)
        return d2 <= thickness * thickness
    p1 = [np.float64(x1[i]) for i in ids]
    fn = _CCD_ORACLE.point_triangle_ccd if kind == "vf" else _CCD_ORACLE.edge_edge_ccd
    return fn(*p0, *p1, min_distance=thickness)[0]


def _assert_same_contacts(result, reference, faces, x0, x1=None, thickness: float = 0.0, label: str = "") -> None:
    """``result`` is a subset of the conservative ``reference``, and every pair it lacks is a near
    miss of the reference's tolerance band (float64 ipctk finds no contact), never a true contact.
    (The hashed methods' box and plane tests are exact, so they drop near misses that the
    reference's narrow phase reports.)"""
    got_vf, got_ee = _rows(result)
    ref_vf, ref_ee = _rows(reference)
    assert got_vf <= ref_vf and got_ee <= ref_ee, f"{label}: pairs outside the reference"
    for row in ref_vf - got_vf:
        assert not _truly_touches("vf", row, faces, x0, x1, thickness), f"{label}: missed contact {row}"
    for row in ref_ee - got_ee:
        assert not _truly_touches("ee", row, faces, x0, x1, thickness), f"{label}: missed contact {row}"


def _owners(faces: np.ndarray, vertex_count: int):
    topology = MeshTopology.from_faces(faces, vertex_count)
    vertex_owner = topology.vertex_face_indices[topology.vertex_face_offsets[:-1].clip(max=len(
        topology.vertex_face_indices) - 1)]
    edge_owner = topology.edge_face_indices[topology.edge_face_offsets[:-1]]
    edge_index = {tuple(e): i for i, e in enumerate(topology.edges.tolist())}
    return vertex_owner, edge_owner, edge_index


def _culled_legitimately(fa: int, fb: int, node_id: np.ndarray, faces: np.ndarray, x: np.ndarray) -> bool:
    """A pscc DCD row may be missing when its two owner faces lie in one front node, or share a vertex
    or an edge and meet only there (float64 reference; ``pscc.collision.shared_vertex``)."""
    if node_id[fa] == node_id[fb]:
        return True
    return bool(shared_vertex_ids(faces[fa], faces[fb])) and meet_only_in_shared(faces[fa], faces[fb], x)


def _check_dcd_contract(faces, x, thickness, detectors):
    """spatial-hash == brute force; pscc is a subset whose missing pairs lie inside one front node or
    join two faces certified to meet only in a shared vertex or edge."""
    reference_vf, reference_ee = _rows(detectors["brute-force"].detect(x, thickness=thickness))
    _assert_same_contacts(detectors["spatial-hash"].detect(x, thickness=thickness),
                          detectors["brute-force"].detect(x, thickness=thickness), faces, x, None, thickness,
                          "spatial-hash")
    pscc = detectors["pscc"]
    culled_vf, culled_ee = _rows(pscc.detect(x, thickness=thickness))
    assert culled_vf <= reference_vf and culled_ee <= reference_ee
    node_id = pscc.front.node_id.numpy()
    vertex_owner, edge_owner, edge_index = _owners(faces, len(x))
    for v, f in reference_vf - culled_vf:
        assert _culled_legitimately(vertex_owner[v], f, node_id, faces, x), f"pair ({v}, {f}) culled"
    for a0, a1, b0, b1 in reference_ee - culled_ee:
        ea, eb = edge_index[(a0, a1)], edge_index[(b0, b1)]
        assert _culled_legitimately(edge_owner[ea], edge_owner[eb], node_id, faces, x), "edge pair culled"


def _detectors(faces, rest=None, object_ids=None, rigid=(), shrink_interval=5):
    return {method: CollisionDetector(faces, method=method, rest=rest, object_ids=object_ids,
                                      rigid_objects=rigid if method == "pscc" else (), shrink_interval=shrink_interval)
            for method in ("brute-force", "spatial-hash", "pscc")}


@pytest.mark.parametrize("maker", ["folded", "twisted"])
def test_ccd_equals_brute_force(maker: str) -> None:
    mesh = folded_sheet(1500, layers=3, seed=1) if maker == "folded" else twisted_sheet(1500, turns=1.5, seed=1)
    end = mesh.vertices_end
    if maker == "twisted":  # shake the twisted strip hard enough that parts of it pass through others
        scale = np.abs(mesh.vertices).max()
        end = (end + np.random.default_rng(1).normal(0.0, 0.03 * scale, end.shape)).astype(np.float32)
    mesh = type(mesh)(vertices=mesh.vertices, faces=mesh.faces, vertices_end=end, rest=mesh.rest,
                      object_ids=mesh.object_ids, source=mesh.source)
    detectors = _detectors(mesh.faces, mesh.rest)
    reference = detectors["brute-force"].detect(mesh.vertices, mesh.vertices_end)
    assert len(reference.vertex_face) + len(reference.edge_edge) > 0
    for method in ("spatial-hash", "pscc"):
        result = detectors[method].detect(mesh.vertices, mesh.vertices_end)
        _assert_same_contacts(result, reference, mesh.faces, mesh.vertices, mesh.vertices_end, 0.0, method)
        common = {tuple(r) for r in result.vertex_face}
        toi_ref = {tuple(r): t for r, t in zip(reference.vertex_face, reference.vertex_face_toi, strict=True)}
        for r, t in zip(result.vertex_face, result.vertex_face_toi, strict=True):
            assert t == toi_ref[tuple(r)], "the narrow phase is deterministic per pair"
        assert common
    pscc_stats = detectors["pscc"].detect(mesh.vertices, mesh.vertices_end).stats
    hash_stats = detectors["spatial-hash"].detect(mesh.vertices, mesh.vertices_end).stats
    assert pscc_stats["triangle_pairs"] < hash_stats["triangle_pairs"]
    assert pscc_stats["bv_tests"] < hash_stats["bv_tests"]
    assert 1 <= pscc_stats["front_size"] <= 2 * len(mesh.faces) + 1


@settings(max_examples=6, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), layers=st.integers(2, 4), thickness=st.sampled_from([0.0, 0.01, 0.05]))
def test_dcd_contract_on_random_folds(seed: int, layers: int, thickness: float) -> None:
    mesh = folded_sheet(600, layers=layers, seed=seed % 1000)
    rng = np.random.default_rng(seed)
    x = (mesh.vertices_end + rng.normal(0.0, 0.01, mesh.vertices.shape)).astype(np.float32)
    _check_dcd_contract(mesh.faces, x, thickness, _detectors(mesh.faces, mesh.rest))


@settings(max_examples=5, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), amplitude=st.sampled_from([0.05, 0.3, 1.0]))
def test_dcd_contract_on_crumpled_sheets(seed: int, amplitude: float) -> None:
    rng = np.random.default_rng(seed)
    vertices, faces, rest = grid_sheet(12, 12)
    x = vertices + rng.normal(0.0, amplitude * 0.1, vertices.shape)
    x[:, 2] += amplitude * np.sin(7 * vertices[:, 0]) * np.cos(5 * vertices[:, 1])
    _check_dcd_contract(faces, x.astype(np.float32), 0.02, _detectors(faces, rest))


def test_multi_object_and_rigid_obstacle() -> None:
    cloth = folded_sheet(800, layers=2, seed=3)
    sphere_like = folded_sheet(400, layers=3, seed=4)  # stands in for a rigid obstacle mesh
    offset = len(cloth.vertices)
    faces = np.concatenate([cloth.faces, sphere_like.faces + offset])
    object_ids = np.concatenate([np.zeros(len(cloth.faces)), np.ones(len(sphere_like.faces))]).astype(np.int32)
    rest = np.concatenate([cloth.rest, sphere_like.rest])
    x0 = np.concatenate([cloth.vertices, sphere_like.vertices + np.float32([0.1, 0.05, 0.25])])
    x1 = np.concatenate([cloth.vertices_end, sphere_like.vertices_end - np.float32([0.0, 0.0, 0.05])])
    detectors = _detectors(faces, rest, object_ids, rigid=(1,))
    reference = detectors["brute-force"].detect(x0, x1)
    pscc = detectors["pscc"]
    result = pscc.detect(x0, x1)
    node_id = pscc.front.node_id.numpy()
    rigid_nodes = np.unique(node_id[object_ids == 1])
    assert len(rigid_nodes) == 1, "a rigid object is one front node"
    assert not set(rigid_nodes) & set(node_id[object_ids == 0])
    ref_vf, ref_ee = _rows(reference)
    got_vf, got_ee = _rows(result)
    assert got_vf <= ref_vf and got_ee <= ref_ee
    # Everything the rigid node culls is the obstacle against itself; all cloth pairs are kept.
    rigid_vertices = set(np.unique(faces[object_ids == 1]))
    for v, f in ref_vf - got_vf:
        assert v in rigid_vertices and object_ids[f] == 1
    assert result.stats["inter_triangle_pairs"] > 0 and result.stats["self_triangle_pairs"] > 0
    assert {(v, f) for v, f in ref_vf if object_ids[f] != 1 or v not in rigid_vertices} <= got_vf


def test_front_sprouts_and_shrinks_over_a_fold_cycle() -> None:
    # From the flat sheet (its rest shape) to a three-layer accordion with rounded folds and back.
    # (A fold made of flat panels can still be a height field along a tilted direction, and PSCC
    # then rightly certifies it whole; rounded folds cannot.)
    mesh = folded_sheet(800, layers=3, seed=0)
    flat = np.concatenate([mesh.rest[:, :2], np.zeros((len(mesh.rest), 1), np.float32)], axis=1)
    faces = mesh.faces
    det = CollisionDetector(faces, method="pscc", rest=mesh.rest, shrink_interval=1)
    sizes = []
    for s in [0.0, 0.5, 1.0, 1.0, 0.5, 0.0, 0.0]:
        x = ((1 - s) * flat + s * mesh.vertices).astype(np.float32)
        result = det.detect(x, thickness=0.0)
        sizes.append(result.stats["front_size"])
        node_id = det.front.node_id.numpy()
        front = det.front.front.numpy()[: det.front.front_size]
        # The front is a cut: every face in exactly one front node's range.
        bvh = det.bvh
        covered = np.zeros(len(faces), dtype=int)
        for node in front:
            covered[bvh.face_order[bvh.face_begin[node]:bvh.face_end[node]]] += 1
        assert np.all(covered == 1)
        assert set(np.unique(node_id)) == set(front.tolist())
    assert sizes[0] == 1, "a flat sheet is one certified patch"
    assert max(sizes) > 1, "a sheet folded onto itself needs several front nodes"
    assert sizes[-1] == 1, "after unfolding, shrinking restores the single root node"


def test_deterministic_and_buffers_grow() -> None:
    mesh = folded_sheet(2000, layers=4, seed=7)
    first = CollisionDetector(mesh.faces, rest=mesh.rest)
    second = CollisionDetector(mesh.faces, rest=mesh.rest)
    a = first.detect(mesh.vertices, mesh.vertices_end, thickness=0.02)
    b = second.detect(mesh.vertices, mesh.vertices_end, thickness=0.02)
    assert np.array_equal(a.vertex_face, b.vertex_face) and np.array_equal(a.edge_edge, b.edge_edge)
    assert np.array_equal(a.vertex_face_toi, b.vertex_face_toi)
    # Heavy contact: a huge thickness overflows the initial candidate capacity; results still match.
    heavy = first.detect(mesh.vertices_end, thickness=0.2)
    reference = CollisionDetector(mesh.faces, method="spatial-hash").detect(mesh.vertices_end, thickness=0.2)
    assert first.candidates.capacity_vf >= first.candidates.vertex_face_count > 4 * len(mesh.faces)
    assert _rows(heavy)[0] <= _rows(reference)[0]


def test_stats_keys_for_every_method() -> None:
    mesh = folded_sheet(300, layers=2, seed=2)
    for method in ("pscc", "spatial-hash", "brute-force"):
        stats = CollisionDetector(mesh.faces, method=method).detect(mesh.vertices, mesh.vertices_end).stats
        for key in ("bv_tests", "triangle_pairs", "self_triangle_pairs", "inter_triangle_pairs", "front_size",
                    "vertex_face_pairs", "edge_edge_pairs", "seconds", "device_bytes"):
            assert key in stats, (method, key)
        assert stats["self_triangle_pairs"] + stats["inter_triangle_pairs"] == stats["triangle_pairs"]


def test_ownership_bits_cover_every_feature_once() -> None:
    vertices, faces, _ = grid_sheet(4, 3)
    topology = MeshTopology.from_faces(faces, len(vertices))
    vertex_bits, edge_bits = ownership_bits(faces, topology)
    owned_vertices = [faces[f][k] for f in range(len(faces)) for k in range(3) if vertex_bits[f] >> k & 1]
    owned_edges = [topology.face_edges[f][k] for f in range(len(faces)) for k in range(3) if edge_bits[f] >> k & 1]
    assert sorted(owned_vertices) == list(range(len(vertices)))
    assert sorted(owned_edges) == list(range(topology.edge_count))


def _spiral(turns: float, n_around: int = 60, n_across: int = 8) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A sheet rolled into a spiral (Archimedean cross-section), layers 0.05 apart."""
    vertices, faces, rest = grid_sheet(n_around, n_across)
    u = vertices[:, 0].astype(np.float64)  # in [0, 1] along the roll
    angle = 2 * np.pi * turns * u
    radius = 0.1 + 0.05 * angle / (2 * np.pi)
    x = np.stack([radius * np.cos(angle), vertices[:, 1], radius * np.sin(angle)], axis=1)
    return x.astype(np.float32), faces, rest


def _zigzag(folds: int, n: int = 40) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A tight accordion: a sawtooth cross-section with steep walls."""
    vertices, faces, rest = grid_sheet(n, 6)
    u = vertices[:, 0].astype(np.float64)
    phase = (u * folds) % 1.0
    z = np.where(phase < 0.5, phase, 1.0 - phase) * 0.6
    x = np.stack([u * 0.05, vertices[:, 1], z], axis=1)
    return x.astype(np.float32), faces, rest


def _twisted_stack() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A three-layer accordion twisted by half a turn about its long axis."""
    mesh = folded_sheet(900, layers=3, seed=11)
    x = mesh.vertices.astype(np.float64)
    centre = x.mean(axis=0)
    angle = np.pi * (x[:, 0] - x[:, 0].min()) / np.ptp(x[:, 0])
    y, z = x[:, 1] - centre[1], x[:, 2] - centre[2]
    x[:, 1] = centre[1] + np.cos(angle) * y - np.sin(angle) * z
    x[:, 2] = centre[2] + np.sin(angle) * y + np.cos(angle) * z
    return x.astype(np.float32), mesh.faces, mesh.rest


SHAPES = {
    "spiral": lambda: _spiral(2.5),
    "zigzag": lambda: _zigzag(6),
    "near-flat": lambda: grid_sheet(14, 14),
    "twisted": _twisted_stack,
}


@settings(max_examples=10, deadline=None)
@given(shape=st.sampled_from(sorted(SHAPES)), seed=st.integers(0, 2**31 - 1),
       motion=st.sampled_from([0.0, 0.02, 0.1]))
def test_certified_patches_never_hide_a_contact(shape: str, seed: int, motion: float) -> None:
    """CCD and touching DCD (thickness 0) of pscc equal brute force on spirals, tight zig-zags,
    near-flat sheets and twisted multi-layer stacks with random motions (up to near misses checked
    by float64 ipctk), i.e. a certified front node never contains a contact."""
    x0, faces, rest = SHAPES[shape]()
    rng = np.random.default_rng(seed)
    x0 = x0 + rng.normal(0.0, 1e-4, x0.shape).astype(np.float32)
    x1 = (x0 + rng.normal(0.0, motion, x0.shape)).astype(np.float32)
    detectors = _detectors(faces, rest)
    for positions, end in ((x0, x1), (x1, None)):
        reference = detectors["brute-force"].detect(positions, end)
        result = detectors["pscc"].detect(positions, end)
        _assert_same_contacts(result, reference, faces, positions, end, 0.0, shape)


def test_non_manifold_fin_and_boundaries() -> None:
    # A sheet with a "fin" glued along its interior row y = 1/2: the edges of that row have three
    # faces (non-manifold); the fin then swings down through the sheet.
    vertices, faces, rest = grid_sheet(6, 6)
    n = len(vertices)
    fin = vertices.copy()
    fin[:, 2] = fin[:, 1] - 0.5  # a slanted copy sharing the y = 1/2 row
    shared = np.isclose(vertices[:, 1], 0.5)
    remap = np.where(shared, np.arange(n), np.arange(n) + n)
    all_vertices = np.concatenate([vertices, fin])
    all_faces = np.concatenate([faces, remap[faces]]).astype(np.int32)
    all_rest = np.concatenate([rest, rest + np.float32([2.0, 0.0])])
    moved = all_vertices.copy()
    moved[n:, 2] = -(all_vertices[n:, 1] - 0.5)
    topology = MeshTopology.from_faces(all_faces, len(all_vertices))
    assert not topology.is_manifold
    detectors = _detectors(all_faces, all_rest)
    reference = detectors["brute-force"].detect(all_vertices, moved)
    result = detectors["pscc"].detect(all_vertices, moved)
    assert len(reference.vertex_face) + len(reference.edge_edge) > 0
    _assert_same_contacts(result, reference, all_faces, all_vertices, moved, 0.0, "fin")


def test_reused_broad_phase_serves_ccd_and_next_dcd() -> None:
    mesh = folded_sheet(1200, layers=3, seed=5)
    h = 0.01
    for method in ("spatial-hash", "pscc"):
        det = CollisionDetector(mesh.faces, method=method, rest=mesh.rest)
        det.broad_phase(mesh.vertices, mesh.vertices_end, thickness=h)
        ccd = det.narrow_phase(mesh.vertices, mesh.vertices_end)
        dcd = det.narrow_phase(mesh.vertices_end, thickness=h)
        fresh = CollisionDetector(mesh.faces, method="brute-force")
        _assert_same_contacts(ccd, fresh.detect(mesh.vertices, mesh.vertices_end), mesh.faces, mesh.vertices,
                              mesh.vertices_end, 0.0, method)
        reference_dcd = _rows(fresh.detect(mesh.vertices_end, thickness=h))
        if method == "spatial-hash":
            _assert_same_contacts(dcd, fresh.detect(mesh.vertices_end, thickness=h), mesh.faces, mesh.vertices_end,
                                  None, h, method)
        else:
            assert _rows(dcd)[0] <= reference_dcd[0] and _rows(dcd)[1] <= reference_dcd[1]


def test_narrow_phase_refuses_uncovered_queries() -> None:
    mesh = folded_sheet(300, layers=2, seed=6)
    det = CollisionDetector(mesh.faces, rest=mesh.rest)
    with pytest.raises(InputError, match="broad phase"):
        det.narrow_phase(mesh.vertices)
    det.broad_phase(mesh.vertices, thickness=0.01)
    with pytest.raises(InputError, match="positions_end"):
        det.narrow_phase(mesh.vertices, mesh.vertices_end)
    with pytest.raises(InputError, match="thickness"):
        det.narrow_phase(mesh.vertices, thickness=0.02)
    det.narrow_phase(mesh.vertices, thickness=0.005)
    with pytest.raises(InputError, match="positions_end"):
        CollisionDetector(mesh.faces).broad_phase(mesh.vertices, mesh.vertices_end[:-1])


def test_ccd_recheck_of_moved_vertices_equals_a_full_run() -> None:
    # The response loop changes some end positions and re-runs CCD with recheck=True: only pairs
    # with a changed vertex are tested again, and the result must be the full CCD of the new
    # trajectory, for every method.
    mesh = folded_sheet(1200, layers=3, seed=7)
    rng = np.random.default_rng(7)
    h = 0.01
    for method in ("pscc", "spatial-hash", "brute-force"):
        det = CollisionDetector(mesh.faces, method=method, rest=mesh.rest)
        det.broad_phase(mesh.vertices, mesh.vertices_end, thickness=h)
        first = det.narrow_phase(mesh.vertices, mesh.vertices_end, 0.0, recheck=True)  # nothing to reuse yet
        assert _rows(first) == _rows(CollisionDetector(mesh.faces, method="brute-force").detect(
            mesh.vertices, mesh.vertices_end))
        current = mesh.vertices_end
        for round_ in range(3):
            changed = current.copy()
            picked = rng.choice(len(changed), size=len(changed) // 10, replace=False)
            changed[picked] += rng.uniform(-0.3 * h, 0.3 * h, size=(len(picked), 3)).astype(np.float32)
            partial = det.narrow_phase(mesh.vertices, changed, 0.0, recheck=True)
            marked = int(det.narrow.moved.numpy().sum())
            full = det.narrow_phase(mesh.vertices, changed, 0.0)
            assert marked == len(picked), (method, round_)
            assert _rows(partial) == _rows(full), (method, round_)
            np.testing.assert_array_equal(partial.vertex_face_toi, full.vertex_face_toi)
            np.testing.assert_array_equal(partial.edge_edge_toi, full.edge_edge_toi)
            current = changed
        # The perturbations changed some results, so the partial runs had work to do.
        assert (_rows(first) != _rows(full) or not np.array_equal(first.vertex_face_toi, full.vertex_face_toi)
                or not np.array_equal(first.edge_edge_toi, full.edge_edge_toi))
        # A changed start position is marked too.
        start = mesh.vertices.copy()
        start[5] += np.float32(1e-4)
        partial = det.narrow_phase(start, current, 0.0, recheck=True)
        assert int(det.narrow.moved.numpy().sum()) == 1
        assert _rows(partial) == _rows(det.narrow_phase(start, current, 0.0))
        # After a new broad phase or a discrete narrow phase there is nothing to reuse: a full run.
        det.narrow_phase(current, thickness=h)
        det.broad_phase(mesh.vertices, current, thickness=h)
        assert _rows(det.narrow_phase(mesh.vertices, current, 0.0, recheck=True)) == _rows(full)


def _two_pieces() -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, int]:
    """A cloth and a second folded piece pushed into it: faces, rest, x0, x1 and the cloth's face count."""
    cloth = folded_sheet(300, layers=2, seed=3)
    other = folded_sheet(200, layers=3, seed=4)
    faces = np.concatenate([cloth.faces, other.faces + len(cloth.vertices)])
    rest = np.concatenate([cloth.rest, other.rest])
    x0 = np.concatenate([cloth.vertices, other.vertices + np.float32([0.1, 0.05, 0.25])])
    x1 = np.concatenate([cloth.vertices_end, other.vertices_end - np.float32([0.0, 0.0, 0.05])])
    return faces, rest, x0, x1, len(cloth.faces)


@pytest.mark.parametrize("method", ["brute-force", "spatial-hash", "pscc"])
def test_sparse_object_ids_give_the_same_pairs_in_the_same_memory(method: str) -> None:
    """Ids need not be contiguous: {7, 2**31 - 1} gives the pairs of {0, 1} with no table of max id + 1 rows."""
    faces, rest, x0, x1, cloth_faces = _two_pieces()
    results, memory = [], []
    for low, high in ((0, 1), (7, 2**31 - 1)):
        ids = np.concatenate([np.full(cloth_faces, low), np.full(len(faces) - cloth_faces, high)]).astype(np.int64)
        det = CollisionDetector(faces, method=method, object_ids=ids, rest=rest, device="cpu",
                                rigid_objects=(high,) if method == "pscc" else ())
        results.append(det.detect(x0, x1))
        memory.append(det.device_bytes()["total"])
        if method == "pscc":
            assert det.bvh.object_values.tolist() == [low, high]
            assert det.bvh.is_rigid[det.bvh.root_of(high)] and det.bvh.root_of(3) == -1
            assert max(getattr(det.bvh, name).nbytes for name in vars(det.bvh)
                       if isinstance(getattr(det.bvh, name), np.ndarray)) < 64 * len(faces)
    small, large = results
    assert len(small.vertex_face) + len(small.edge_edge) > 0
    for name in ("vertex_face", "edge_edge", "vertex_face_toi", "edge_edge_toi"):
        np.testing.assert_array_equal(getattr(small, name), getattr(large, name), err_msg=name)
    for key in ("self_triangle_pairs", "inter_triangle_pairs", "triangle_pairs", "candidate_pairs", "front_size"):
        assert small.stats[key] == large.stats[key], key
    assert memory[0] == memory[1]


@pytest.mark.parametrize("bad", [-1, 2**31, 2**40])
def test_object_ids_outside_int32_are_refused_at_construction(bad: int) -> None:
    faces, _, _, _, _ = _two_pieces()
    ids = np.zeros(len(faces), dtype=np.int64)
    ids[5] = bad
    with pytest.raises(InputError) as caught:
        CollisionDetector(faces, object_ids=ids)
    error = caught.value
    assert (error.source, error.field) == ("argument", "object_ids")
    assert f"row 5 has object id {bad}, outside [0, 2147483647]" in error.problem and error.fix


def test_short_positions_are_named_with_the_rows_they_need() -> None:
    mesh = folded_sheet(300, layers=2, seed=6)
    needed = int(mesh.faces.max()) + 1
    for call in ("detect", "broad_phase", "prepare"):
        det = CollisionDetector(mesh.faces, rest=mesh.rest)
        with pytest.raises(InputError) as caught:
            getattr(det, call)(mesh.vertices[:10])
        error = caught.value
        assert (error.source, error.field) == ("argument", "positions"), str(error)
        assert "(10, 3)" in error.problem and f"at least {needed} rows" in error.problem, str(error)
        assert f"({needed}, 3)" in error.problem and "faces:" not in str(error)


def test_faces_and_rigid_objects_that_overflow_are_refused() -> None:
    faces = np.array([[0, 1, 2], [1, 2, 2**32]], dtype=np.int64)  # 2**32 would wrap to vertex 0 in int32
    with pytest.raises(InputError, match=r"argument: faces: vertex id 4294967296 is outside"):
        CollisionDetector(faces)
    with pytest.raises(InputError, match=r"argument: rigid_objects: .*Fix: pass e\.g\."):
        CollisionDetector(faces[:1], rigid_objects=["glass"])


@pytest.mark.parametrize("swept", [False, True])
def test_ground_quad_far_larger_than_the_cloth(swept: bool) -> None:
    """Two ground triangles 50 times the cloth's extent, crossing its layers (as frames exported from other
    systems often hold): they stay out of the grid (wide faces) and every contact with them is found."""
    mesh = folded_sheet(1500, layers=3, seed=5)
    lo, hi = mesh.vertices.min(axis=0), mesh.vertices.max(axis=0)
    centre, half = 0.5 * (lo + hi), 50.0 * float((hi - lo).max())
    up = int(np.argmin(hi - lo))  # the ground lies across the layers, through the vertex nearest the centre
    a, b = [k for k in range(3) if k != up]
    height = mesh.vertices[np.argmin(np.linalg.norm(mesh.vertices - centre, axis=1)), up]
    n = len(mesh.vertices)
    ground = np.zeros((4, 3), dtype=np.float32)
    ground[:, up] = height
    ground[:, a] = centre[a] + np.float32([-half, half, half, -half])
    ground[:, b] = centre[b] + np.float32([-half, -half, half, half])
    faces = np.concatenate([mesh.faces, [[n, n + 1, n + 2], [n, n + 2, n + 3]]]).astype(np.int32)
    rest = np.concatenate([mesh.rest, ground[:, [a, b]] if mesh.rest.shape[1] == 2 else ground])
    object_ids = np.concatenate([np.zeros(len(mesh.faces)), [1, 1]]).astype(np.int32)
    x0 = np.concatenate([mesh.vertices, ground])
    x1 = np.concatenate([mesh.vertices_end, ground]) if swept else None
    detectors = _detectors(faces, rest, object_ids)
    thickness = 0.0 if swept else 0.01
    reference = detectors["brute-force"].detect(x0, x1, thickness=thickness)
    ground_rows = [r for r in reference.vertex_face if r[1] >= len(mesh.faces)]
    assert ground_rows, "the ground meets the cloth"
    for method in ("spatial-hash", "pscc"):
        result = detectors[method].detect(x0, x1, thickness=thickness)
        _assert_same_contacts(result, reference, faces, x0, x1, thickness, method)
        assert detectors[method].spatial_hash.stats.wide_faces == 2, method
