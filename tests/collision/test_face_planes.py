"""Per-face plane slabs (pscc.collision.face_planes): a vertex they certify beyond a face is farther than
the thickness from it (float64 distances), on random, far-off, tiny and degenerate faces; the pass runs
only for calls with enough triangle pairs."""

from __future__ import annotations

import numpy as np
import pytest
import warp as wp

from pscc.collision.face_planes import FacePlane, FacePlanes, slab_sides


@wp.kernel
def _sides(
    planes: wp.array(dtype=FacePlane),
    faces: wp.array(dtype=wp.vec3i),
    positions: wp.array(dtype=wp.vec3),
    pairs: wp.array(dtype=wp.vec2i),
    out: wp.array(dtype=wp.vec3),
):
    i = wp.tid()
    a = pairs[i][0]
    b = pairs[i][1]
    tri = faces[b]
    out[i] = slab_sides(planes[a], planes[b], positions[tri[0]], positions[tri[1]], positions[tri[2]])


def _slab_sides(x: np.ndarray, faces: np.ndarray, pairs: np.ndarray, thickness: float) -> np.ndarray:
    """Sides of face b's vertices against face a's slab, per (a, b) row of ``pairs``."""
    faces_d = wp.array(faces.astype(np.int32), dtype=wp.vec3i, device="cpu")
    x_d = wp.array(x.astype(np.float32), dtype=wp.vec3, device="cpu")
    planes = FacePlanes(faces_d, wp.get_device("cpu"), min_pairs_per_face=0.0)
    planes.compute(x_d, thickness, wp.zeros(1, dtype=wp.int64, device="cpu"))
    out = wp.zeros(len(pairs), dtype=wp.vec3, device="cpu")
    wp.launch(_sides, dim=len(pairs), inputs=[planes.planes, faces_d, x_d,
                                              wp.array(pairs.astype(np.int32), dtype=wp.vec2i, device="cpu")],
              outputs=[out], device="cpu")
    return out.numpy()


def _point_face_distance(p: np.ndarray, tri: np.ndarray) -> float:
    import ipctk

    return float(np.sqrt(ipctk.point_triangle_distance(p, tri[0], tri[1], tri[2])))


def _random_pairs(rng: np.random.Generator, n: int, scale: float, offset: float) -> tuple[np.ndarray, np.ndarray]:
    """n pairs of triangles (tilted, near-parallel, touching, crossing), positions scaled and moved off the
    origin; faces (2 i, 2 i + 1) form pair i."""
    a = rng.uniform(-1, 1, (n, 3, 3))
    normal = rng.normal(size=(n, 3))
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    shift = normal[:, None, :] * rng.uniform(-0.5, 0.5, (n, 1, 1))
    b = a[:, rng.permutation(3)] * rng.uniform(0.5, 1.5, (n, 1, 1)) + shift
    b += rng.normal(size=(n, 3, 3)) * 10.0 ** rng.uniform(-7, -1, (n, 1, 1))
    x = (np.concatenate([a, b], axis=1) * scale + offset).reshape(-1, 3).astype(np.float32)
    faces = np.arange(6 * n).reshape(-1, 3)
    pairs = np.stack([np.arange(0, 2 * n, 2), np.arange(1, 2 * n, 2)], axis=1)
    return x, faces, np.concatenate([pairs, pairs[:, ::-1]])


@pytest.mark.parametrize("scale, offset", [(1.0, 0.0), (1.0, 1000.0), (1e-3, 5.0), (50.0, -3.0e4)])
def test_certified_vertices_are_farther_than_the_thickness(scale: float, offset: float) -> None:
    """Every vertex certified beyond a face's grown slab is farther than the thickness from the face (float64
    distance on the float32 positions); a vertex beyond the float64 plane by a clear margin is certified."""
    rng = np.random.default_rng(int(scale * 7 + abs(offset)))
    x, faces, pairs = _random_pairs(rng, 800, scale, offset)
    x64 = x.astype(np.float64)
    for thickness in (0.0, 0.05 * scale, 0.3 * scale):
        sides = _slab_sides(x, faces, pairs, thickness)
        certified = 0
        clear_missed = 0
        for (a, b), side in zip(pairs, sides, strict=True):
            tri = x64[faces[a]]
            normal = np.cross(tri[1] - tri[0], tri[2] - tri[0])
            normal /= np.linalg.norm(normal)
            for k in range(3):
                p = x64[faces[b][k]]
                if side[k] != 0.0:
                    certified += 1
                    assert _point_face_distance(p, tri) > thickness, (a, b, k)
                    assert np.sign(np.dot(normal, p - tri[0])) == side[k]
                elif abs(np.dot(normal, p - tri[0])) > thickness + 1e-5 * (scale + abs(offset)):
                    clear_missed += 1
        assert certified > 500
        assert clear_missed == 0


def test_degenerate_and_non_finite_faces_certify_nothing() -> None:
    """A face whose vertices coincide or are collinear, and a face with a NaN vertex, certify no vertex;
    nor is a NaN vertex certified against a good face."""
    x = np.array([[0, 0, 0], [0, 0, 0], [0, 0, 0],            # a point
                  [0, 0, 0], [1, 1, 1], [2, 2, 2],            # a segment
                  [0, 0, 0], [1, 0, 0], [np.nan, 1, 0],       # NaN vertex
                  [0, 0, 5], [1, 0, 5], [0, 1, 5],            # far above the others
                  [0, 0, 0], [1, 0, 0], [0, 1, 0]], np.float32)  # a good face at z = 0
    faces = np.arange(15).reshape(-1, 3)
    pairs = np.array([[0, 3], [1, 3], [2, 3], [4, 2], [4, 3]])
    sides = _slab_sides(x, faces, pairs, 0.1)
    assert np.all(sides[:3] == 0.0)
    assert sides[3][0] == 0.0 and sides[3][1] == 0.0 and sides[3][2] == 0.0  # the NaN face's vertices
    assert np.all(sides[4] == 1.0)  # the far face is certified above the good one


def test_slab_matches_the_thickness_at_the_boundary() -> None:
    """Parallel faces 1.0 apart: certified for thicknesses just below 1.0, never at or above it."""
    x = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 0, 1], [0, 1, 1]], np.float32)
    faces = np.arange(6).reshape(-1, 3)
    pairs = np.array([[0, 1], [1, 0]])
    assert np.all(_slab_sides(x, faces, pairs, 0.999)[0] == 1.0)
    assert np.all(_slab_sides(x, faces, pairs, 0.999)[1] == -1.0)
    for thickness in (1.0, 1.0001, 5.0):
        assert np.all(_slab_sides(x, faces, pairs, thickness) == 0.0)


@pytest.mark.parametrize("offset", [0.0, 1000.0])
def test_vertices_at_the_thickness_within_rounding(offset: float) -> None:
    """Vertices placed over a face at the thickness give or take a few rounding units of their coordinates
    (so the rounding of the float32 projection decides many): every certified one is farther than the thickness
    (float64 distances of the float32 positions). Without the rounding bounds this test fails."""
    rng = np.random.default_rng(5)
    n = 4000
    tri = rng.uniform(-1, 1, (n, 3, 3))
    normal = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    h = 0.01
    weights = rng.dirichlet(np.ones(3), (n, 3))
    inside = np.einsum("nkj,njd->nkd", weights, tri)
    ulp = np.spacing(np.float32(max(offset, 1.0)))
    shift = h + rng.uniform(-40, 40, (n, 3)) * ulp
    other = inside + normal[:, None, :] * shift[..., None] * rng.choice([-1.0, 1.0], (n, 1, 1))
    x = (np.concatenate([tri, other], axis=1) + offset).reshape(-1, 3).astype(np.float32)
    faces = np.arange(6 * n).reshape(-1, 3)
    pairs = np.stack([np.arange(0, 2 * n, 2), np.arange(1, 2 * n, 2)], axis=1)
    sides = _slab_sides(x, faces, pairs, h)
    x64 = x.astype(np.float64)
    certified = 0
    for (a, b), side in zip(pairs, sides, strict=True):
        for k in np.flatnonzero(side):
            certified += 1
            assert _point_face_distance(x64[faces[b][k]], x64[faces[a]]) > h, (a, b, k)
    assert certified > 0.1 * 3 * n


def test_slabs_are_written_only_for_calls_with_enough_pairs() -> None:
    """With fewer triangle pairs than min_pairs_per_face times the faces, the pass writes nothing (the feature
    pass then takes the six-vertex test); from that count on it writes every face."""
    faces_d = wp.array(np.array([[0, 1, 2], [0, 2, 3]], np.int32), dtype=wp.vec3i, device="cpu")
    x_d = wp.array(np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], np.float32), dtype=wp.vec3, device="cpu")
    planes = FacePlanes(faces_d, wp.get_device("cpu"), min_pairs_per_face=2.0)
    assert planes.min_pairs == 4
    planes.planes.zero_()
    planes.compute(x_d, 0.1, wp.array([3], dtype=wp.int64, device="cpu"))
    assert np.all(planes.planes.numpy()["upper"] == 0.0)
    planes.compute(x_d, 0.1, wp.array([4], dtype=wp.int64, device="cpu"))
    assert np.all(planes.planes.numpy()["upper"] > 0.1)
