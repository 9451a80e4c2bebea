"""Normal-cone direction masks and the unprojected contour test (DCD and swept/CCD forms)."""

from __future__ import annotations

import math

import numpy as np
import pytest
import warp as wp

from pscc.geometry import normal_cone as nc

MARGIN = 1.0e-5
DEGENERATE = 1.0e-10


@wp.kernel
def _contour_kernel(
    loop: wp.array(dtype=wp.int32),
    positions_t0: wp.array(dtype=wp.vec3),
    positions_t1: wp.array(dtype=wp.vec3),
    o0: wp.vec3,
    o1: wp.vec3,
    l: wp.vec3,
    swept: int,
    out: wp.array(dtype=wp.int32),
):
    if swept == 1:
        ok = nc.contour_test_swept(loop, 0, loop.shape[0], positions_t0, positions_t1, o0, o1, l, MARGIN)
    else:
        ok = nc.contour_test(loop, 0, loop.shape[0], positions_t0, o0, l, MARGIN)
    out[0] = wp.where(ok, 1, 0)


@wp.kernel
def _mask_kernel(
    tris_t0: wp.array(dtype=wp.vec3),
    tris_t1: wp.array(dtype=wp.vec3),
    directions: wp.array(dtype=wp.vec3),
    swept: int,
    out: wp.array(dtype=nc.mask_type),
):
    i = wp.tid()
    a0 = tris_t0[3 * i]
    b0 = tris_t0[3 * i + 1]
    c0 = tris_t0[3 * i + 2]
    if swept == 1:
        out[i] = nc.face_mask_swept(a0, b0, c0, tris_t1[3 * i], tris_t1[3 * i + 1], tris_t1[3 * i + 2],
                                    directions, MARGIN, DEGENERATE)
    else:
        out[i] = nc.face_mask(a0, b0, c0, directions, MARGIN, DEGENERATE)


def _contour(points, o, l, points_t1=None, o1=None, device="cpu") -> bool:
    points = np.asarray(points, np.float32)
    swept = points_t1 is not None
    p1 = np.asarray(points_t1 if swept else points, np.float32)
    out = wp.zeros(1, dtype=wp.int32, device=device)
    wp.launch(_contour_kernel, dim=1, device=device, inputs=[
        wp.array(np.arange(len(points), dtype=np.int32), device=device),
        wp.array(points, dtype=wp.vec3, device=device), wp.array(p1, dtype=wp.vec3, device=device),
        wp.vec3(*o), wp.vec3(*(o1 if swept else o)), wp.vec3(*(np.asarray(l) / np.linalg.norm(l))),
        1 if swept else 0, out])
    return bool(out.numpy()[0])


def _polygon(angles, radii=None, z=None):
    radii = np.ones(len(angles)) if radii is None else np.asarray(radii)
    z = np.zeros(len(angles)) if z is None else np.asarray(z)
    return np.stack([radii * np.cos(angles), radii * np.sin(angles), z], axis=1)


SQUARE = [[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]]


@pytest.mark.parametrize("l", [[0, 0, 1], [0, 0, -1], [0.3, -0.2, 1.0]])
def test_flat_square_passes_both_orientations(l, device) -> None:
    o = [0.5, 0.5, 0.0]
    assert _contour(SQUARE, o, l, device=device)
    assert _contour(SQUARE[::-1], o, l, device=device)


def test_grid_boundary_with_collinear_vertices_passes(device) -> None:
    n = 10
    ring = [[i, 0, 0] for i in range(n)] + [[n, j, 0] for j in range(n)]
    ring += [[n - i, n, 0] for i in range(n)] + [[0, n - j, 0] for j in range(n)]
    assert _contour(ring, [n / 2, n / 2, 0.0], [0, 0, 1], device=device)
    assert _contour(ring, [n / 2 + 0.3, n / 2 - 0.2, 0.0], [0.1, 0.2, 1.0], device=device)


def test_pentagram_and_double_loop_fail(device) -> None:
    star = _polygon(np.arange(5) * 4 * math.pi / 5)
    assert not _contour(star, [0, 0, 0], [0, 0, 1], device=device)
    twice = _polygon(np.arange(12) * 4 * math.pi / 12)
    assert not _contour(twice, [0, 0, 0], [0, 0, 1], device=device)


def test_folded_contour_fails(device) -> None:
    # A strip folded over itself: its projection along z overlaps (contour self-intersects).
    folded = [[0, 0, 0], [2, 0, 0], [2, 1, 0], [0.5, 1, 0.2], [0.5, -0.5, 0.2], [1.5, -0.5, 0.2], [1.5, 2, 0]]
    assert not _contour(folded, [1.0, 0.5, 0.0], [0, 0, 1], device=device)


def test_vertex_on_the_ray_through_o_fails_safely(device) -> None:
    # o on the contour itself gives S = 0 for its edges: must fail, never pass by accident.
    assert not _contour(SQUARE, [0.0, 0.0, 0.0], [0, 0, 1], device=device)


def test_random_star_polygons(device) -> None:
    rng = np.random.default_rng(0)
    for _ in range(30):
        count = int(rng.integers(3, 20))
        angles = np.sort(rng.uniform(0, 2 * math.pi, count))
        gaps = np.diff(np.concatenate([angles, [angles[0] + 2 * math.pi]]))
        points = _polygon(angles, rng.uniform(0.5, 2.0, count), rng.normal(0, 0.05, count))
        passed = _contour(points, [0, 0, 0], [0, 0, 1], device=device)
        if gaps.max() < math.pi - 0.05:
            assert passed, "a star-shaped loop around o must pass"
        if gaps.max() > math.pi + 0.05:
            assert not passed, "o outside the loop's kernel must fail"


def test_swept_contour(device) -> None:
    o = [0.5, 0.5, 0.0]
    moved = [[x + 0.2, y + 0.1, z + 0.3 * x] for x, y, z in SQUARE]
    assert _contour(SQUARE, o, [0, 0, 1], points_t1=moved, o1=[0.7, 0.6, 0.15], device=device)
    # The square flips over during the step: its orientation reverses, the swept test must fail.
    flipped = [[x, 1 - y, 0.0] for x, y, _ in SQUARE]
    assert not _contour(SQUARE, o, [0, 0, 1], points_t1=flipped, o1=o, device=device)


def _masks(tris_t0, tris_t1=None, device="cpu"):
    t0 = np.asarray(tris_t0, np.float32).reshape(-1, 3)
    t1 = np.asarray(tris_t0 if tris_t1 is None else tris_t1, np.float32).reshape(-1, 3)
    directions = nc.sample_directions()
    out = wp.zeros(len(t0) // 3, dtype=nc.mask_type, device=device)
    wp.launch(_mask_kernel, dim=len(t0) // 3, device=device, inputs=[
        wp.array(t0, dtype=wp.vec3, device=device), wp.array(t1, dtype=wp.vec3, device=device),
        wp.array(directions, dtype=wp.vec3, device=device), 0 if tris_t1 is None else 1, out])
    bits = np.unpackbits(out.numpy().astype("<u4").view(np.uint8), bitorder="little").reshape(len(t0) // 3, -1)
    return bits.astype(bool), directions


def test_face_mask_is_exactly_the_front_facing_directions(device) -> None:
    rng = np.random.default_rng(1)
    tris = rng.normal(size=(50, 3, 3))
    bits, directions = _masks(tris, device=device)
    normals = np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0])
    dots = normals @ directions.T.astype(np.float64)
    limit = MARGIN * np.linalg.norm(normals, axis=1, keepdims=True)
    assert np.all(dots[bits] > 0), "a set direction must see the front of the face"
    assert np.all(bits[dots > 2 * limit]), "clearly front-facing directions must be set"


def test_swept_mask_holds_at_every_time(device) -> None:
    rng = np.random.default_rng(2)
    t0 = rng.normal(size=(40, 3, 3))
    t1 = t0 + rng.normal(scale=0.3, size=t0.shape)
    bits, directions = _masks(t0, t1, device=device)
    for ts in np.linspace(0, 1, 41):
        tri = (1 - ts) * t0 + ts * t1
        n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
        dots = n @ directions.T.astype(np.float64)
        assert np.all(dots[bits] > 0), f"direction loses the face's front at t={ts}"


def test_degenerate_face_has_empty_mask(device) -> None:
    bits, _ = _masks([[[0, 0, 0], [1, 1, 1], [2, 2, 2]], [[0, 0, 0], [0, 0, 0], [0, 0, 0]]], device=device)
    assert not bits.any()


def test_directions_cover_the_sphere() -> None:
    directions = nc.sample_directions().astype(np.float64)
    assert np.allclose(np.linalg.norm(directions, axis=1), 1.0, atol=1e-6)
    probe = np.random.default_rng(3).normal(size=(4000, 3))
    probe /= np.linalg.norm(probe, axis=1, keepdims=True)
    covering = np.degrees(np.arccos(np.clip((probe @ directions.T).max(axis=1), -1, 1))).max()
    assert covering < 15.0, f"covering radius {covering:.1f} degrees"


@wp.kernel
def _lookup_kernel(normals: wp.array(dtype=wp.vec3), table: wp.array(dtype=nc.mask_type), resolution: int,
                   out: wp.array(dtype=nc.mask_type)):
    i = wp.tid()
    out[i] = nc.lookup_mask(normals[i], table, resolution)


def test_lookup_table_masks_are_subsets_of_exact_masks(device) -> None:
    rng = np.random.default_rng(4)
    normals = rng.normal(size=(3000, 3))
    # Axis-aligned, diagonal and cube-edge directions, where cells meet.
    special = [[1, 0, 0], [0, -1, 0], [0, 0, 1], [1, 1, 0], [1, -1, 1], [0.5, 1, 1], [1, 1e-7, -1e-7]]
    normals = np.concatenate([normals, np.array(special, dtype=np.float64)]) * rng.uniform(1e-3, 1e3, (3007, 1))
    normals = normals.astype(np.float32)
    table = nc.direction_mask_table(nc.TABLE_RESOLUTION, MARGIN)
    out = wp.zeros(len(normals), dtype=nc.mask_type, device=device)
    wp.launch(_lookup_kernel, dim=len(normals), device=device,
              inputs=[wp.array(normals, dtype=wp.vec3, device=device),
                      wp.array(table, dtype=nc.mask_type, device=device), nc.TABLE_RESOLUTION, out])
    bits = np.unpackbits(out.numpy().astype("<u4").view(np.uint8), bitorder="little").reshape(len(normals), -1)
    directions = nc.sample_directions().astype(np.float64)
    dots = normals.astype(np.float64) @ directions.T / np.linalg.norm(normals.astype(np.float64), axis=1)[:, None]
    assert np.all(dots[bits.astype(bool)] > MARGIN), "a table direction does not see the normal"
    assert bits.sum(axis=1).min() >= 50, "the table keeps most of the hemisphere"
