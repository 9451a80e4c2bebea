"""The normal-cone certificate of two faces that share a vertex or an edge, against a float64 reference."""

from __future__ import annotations

import math

import numpy as np
import pytest
import warp as wp
from hypothesis import given, settings
from hypothesis import strategies as st

from pscc import tolerances
from pscc.collision import shared_vertex as sv
from pscc.collision.spatial_hash import SpatialHash
from tests.collision.shared_oracle import meet_only_in_shared, shared_vertex_ids

DEVICE = "cpu"


@wp.kernel
def _certify_kernel(args: sv.SharedVertexArgs, face_a: wp.array(dtype=wp.vec3i), face_b: wp.array(dtype=wp.vec3i),
                    out: wp.array(dtype=wp.int32)):
    i = wp.tid()
    out[i] = wp.where(sv.shared_pair_certified(args, face_a[i], face_b[i]), 1, 0)


def certified(face_a: np.ndarray, face_b: np.ndarray, x0: np.ndarray, x1: np.ndarray | None = None) -> np.ndarray:
    """shared_pair_certified for each row of (k, 3) face_a / face_b over positions x0 (and x1: swept)."""
    args = sv.SharedVertexArgs()
    args.mode = sv.SHARED_CERTIFY
    args.faces = wp.array(np.asarray(face_a, np.int32), dtype=wp.vec3i, device=DEVICE)
    args.positions_t0 = wp.array(np.asarray(x0, np.float32), dtype=wp.vec3, device=DEVICE)
    args.positions_t1 = args.positions_t0 if x1 is None else wp.array(np.asarray(x1, np.float32), dtype=wp.vec3,
                                                                      device=DEVICE)
    args.swept = 0 if x1 is None else 1
    args.margin = tolerances.NORMAL_CONE_MARGIN
    a = wp.array(np.asarray(face_a, np.int32), dtype=wp.vec3i, device=DEVICE)
    b = wp.array(np.asarray(face_b, np.int32), dtype=wp.vec3i, device=DEVICE)
    out = wp.zeros(len(face_a), dtype=wp.int32, device=DEVICE)
    wp.launch(_certify_kernel, dim=len(face_a), inputs=[args, a, b], outputs=[out], device=DEVICE)
    return out.numpy().astype(bool)


def _hinge(opening_degrees: float) -> np.ndarray:
    """a b c d: faces (0, 1, 2) and (2, 1, 3) share edge 1-2 (consistently oriented); B turned about it
    so the two faces enclose ``opening_degrees`` (180: flat, 0: folded onto A)."""
    phi = math.radians(180.0 - opening_degrees)
    return np.array([[0.0, 0.0, 0.0], [1.0, -0.5, 0.0], [1.0, 0.5, 0.0],
                     [1.0 + math.cos(phi), 0.0, math.sin(phi)]], np.float32)


@pytest.mark.parametrize("opening", [180.0, 135.0, 90.0, 60.0, 40.0, 30.0])
def test_a_hinge_is_certified_until_it_folds_shut(opening: float) -> None:
    x = _hinge(opening)
    assert certified([[0, 1, 2]], [[2, 1, 3]], x)[0]
    assert meet_only_in_shared([0, 1, 2], [2, 1, 3], x)


@pytest.mark.parametrize("opening", [26.0, 10.0, 1.0])
def test_a_hinge_closed_past_the_cone_is_not_certified(opening: float) -> None:
    # Its faces still meet only along the edge, but their normals are over 2 x 76 degrees apart: the
    # certificate stops where a front node holding both would (sv.CONE_HALF_ANGLE_DEGREES).
    x = _hinge(opening)
    assert meet_only_in_shared([0, 1, 2], [2, 1, 3], x)
    assert not certified([[0, 1, 2]], [[2, 1, 3]], x)[0]


def test_a_hinge_folded_shut_is_not_certified() -> None:
    x = _hinge(0.0)  # B lies on A
    assert not meet_only_in_shared([0, 1, 2], [2, 1, 3], x)
    assert not certified([[0, 1, 2]], [[2, 1, 3]], x)[0]
    assert not certified([[0, 1, 2]], [[2, 1, 3]], _hinge(5.0), x)[0]  # closing onto A within the step


def test_inconsistent_orientation_three_shared_vertices_and_degenerate_faces_are_not_certified() -> None:
    x = _hinge(180.0)
    assert not certified([[0, 1, 2]], [[1, 2, 3]], x)[0]  # the edge runs 1 -> 2 in both faces
    assert not certified([[0, 1, 2]], [[1, 2, 0]], x)[0]  # the same face
    assert not certified([[0, 1, 2]], [[3, 4, 5]], np.concatenate([x, x[:2] + 5]))[0]  # nothing shared
    flat = x.copy()
    flat[3] = 0.5 * (flat[1] + flat[2])  # B of zero area
    assert not certified([[0, 1, 2]], [[2, 1, 3]], flat)[0]


def test_a_fan_around_a_vertex() -> None:
    # v = 0 at the origin; A spans the sector 0..60 degrees (facing +z), B 120..180 or 90..150.
    ring = [[math.cos(math.radians(t)), math.sin(math.radians(t)), 0.0] for t in (0, 60, 120, 180, 90, 150)]
    x = np.array([[0.0, 0.0, 0.0], *ring], np.float32)
    assert certified([[0, 1, 2]], [[0, 3, 4]], x)[0]
    assert certified([[0, 1, 2]], [[0, 5, 6]], x)[0]
    # B over A's sector, rising from v: it meets A only at v, but seen along the normals the sectors
    # overlap, so it is not certified (the certificate is sufficient, not necessary).
    above = x.copy()
    above[3:5] = x[[1, 2]] + [0.0, 0.0, 0.01]
    assert meet_only_in_shared([0, 1, 2], [0, 3, 4], above)
    assert not certified([[0, 1, 2]], [[0, 3, 4]], above)[0]
    # B through A: one free vertex above A's sector, one below; its edge crosses A at (0.6, 0.3, 0).
    through = x.copy()
    through[3] = [0.6, 0.25, 0.2]
    through[4] = [0.6, 0.35, -0.2]
    for face_b in ([0, 3, 4], [0, 4, 3]):
        assert not meet_only_in_shared([0, 1, 2], face_b, through)
        assert not certified([[0, 1, 2]], [face_b], through)[0]


def _random_pairs(rng: np.random.Generator, count: int, share_edge: bool, spread: float) -> tuple:
    """``count`` face pairs sharing one edge (consistently oriented) or one vertex, six vertices each."""
    x = rng.normal(0.0, 1.0, (6 * count, 3))
    base = 6 * np.arange(count)[:, None]
    if share_edge:
        face_a = base + np.array([0, 1, 2])
        face_b = base + np.array([2, 1, 3])
    else:
        face_a = base + np.array([0, 1, 2])
        face_b = base + np.array([0, 3, 4])
    # Pull B's free vertices towards A's plane side by side, so that many pairs are near each other.
    x[base[:, 0] + 3] = x[base[:, 0] + 3] * spread + (1 - spread) * x[base[:, 0] + 1]
    x[base[:, 0] + 4] = x[base[:, 0] + 4] * spread + (1 - spread) * x[base[:, 0] + 2]
    return face_a, face_b, x.astype(np.float32)


@settings(max_examples=12, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), share_edge=st.booleans(), spread=st.sampled_from([1.0, 0.5, 0.1, 0.01]))
def test_certified_pairs_meet_only_in_what_they_share(seed: int, share_edge: bool, spread: float) -> None:
    rng = np.random.default_rng(seed)
    face_a, face_b, x = _random_pairs(rng, 200, share_edge, spread)
    ok = certified(face_a, face_b, x)
    truth = np.array([meet_only_in_shared(a, b, x) for a, b in zip(face_a, face_b, strict=True)])
    assert not np.any(ok & ~truth), np.flatnonzero(ok & ~truth)


def test_random_vertex_pairs_are_mostly_decided_both_ways() -> None:
    # Not a vacuous certificate: of random vertex-sharing pairs that meet only at v, it certifies a
    # good share, and the reference finds intersecting ones (which must stay uncertified).
    rng = np.random.default_rng(7)
    face_a, face_b, x = _random_pairs(rng, 600, False, 1.0)
    ok = certified(face_a, face_b, x)
    truth = np.array([meet_only_in_shared(a, b, x) for a, b in zip(face_a, face_b, strict=True)])
    assert (~truth).sum() > 30
    assert not np.any(ok & ~truth)
    assert ok.sum() > 0.3 * truth.sum(), (ok.sum(), truth.sum())


@settings(max_examples=20, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), share_edge=st.booleans(), step=st.sampled_from([0.05, 0.3, 1.0]))
def test_swept_certificate_holds_at_every_time_of_the_step(seed: int, share_edge: bool, step: float) -> None:
    rng = np.random.default_rng(seed)
    face_a, face_b, x0 = _random_pairs(rng, 200, share_edge, 0.5)
    x1 = (x0 + rng.normal(0.0, step, x0.shape)).astype(np.float32)
    ok = certified(face_a, face_b, x0, x1)
    for i in np.flatnonzero(ok):
        for t in np.linspace(0.0, 1.0, 33):
            xt = (1.0 - t) * x0.astype(np.float64) + t * x1.astype(np.float64)
            assert meet_only_in_shared(face_a[i], face_b[i], xt), (i, t)


def test_small_steps_are_certified_and_hold_throughout() -> None:
    # Not a vacuous swept test: small random motions of near-flat pairs are mostly certified.
    rng = np.random.default_rng(11)
    for share_edge in (True, False):
        face_a, face_b, x0 = _random_pairs(rng, 300, share_edge, 1.0)
        static = certified(face_a, face_b, x0)
        x1 = (x0 + rng.normal(0.0, 0.002, x0.shape)).astype(np.float32)
        swept = certified(face_a, face_b, x0, x1)
        assert swept.sum() > 0.5 * static.sum() > 10, (share_edge, swept.sum(), static.sum())
        for i in np.flatnonzero(swept)[:40]:
            for t in np.linspace(0.0, 1.0, 9):
                xt = (1.0 - t) * x0.astype(np.float64) + t * x1.astype(np.float64)
                assert meet_only_in_shared(face_a[i], face_b[i], xt), (i, t)


@pytest.mark.parametrize(("scale", "offset"), [(1e-9, 1e-6), (1e8, 0.0)])
def test_decisions_hold_at_both_ends_of_the_coordinate_range(scale: float, offset: float) -> None:
    # The smallest edges the coordinate range admits (1e-9 at |x| ~ 1e-6, tolerances.MIN_COORDINATE_SCALE)
    # and the largest coordinates: the margins are products of two lengths (no squares, which would
    # flush to zero at 1e-9), and the clear-cut cases decide as at unit scale.
    ring = [[math.cos(math.radians(t)), math.sin(math.radians(t)), 0.0] for t in (0, 60, 120, 180)]
    fan = np.array([[0.0, 0.0, 0.0], *ring], np.float32)
    through = fan.copy()
    through[3] = [0.6, 0.25, 0.2]
    through[4] = [0.6, 0.35, -0.2]
    cases = [([0, 1, 2], [0, 3, 4], fan, True), ([0, 1, 2], [0, 3, 4], through, False),
             ([0, 1, 2], [2, 1, 3], _hinge(60.0), True), ([0, 1, 2], [2, 1, 3], _hinge(0.0), False)]
    for face_a, face_b, x, expected in cases:
        scaled = (x.astype(np.float64) * scale + offset).astype(np.float32)
        assert certified([face_a], [face_b], scaled)[0] == expected, (face_a, face_b, expected)
        assert certified([face_a], [face_b], scaled, scaled)[0] == expected, (face_a, face_b, expected)


def test_a_hinge_folding_through_within_the_step_is_not_certified() -> None:
    # B's free vertex moves straight down from 0.87 above A to 0.87 below it: at mid-step it lies
    # inside A. Both ends are hinges opened 60 degrees (certified at one instant); the step is not.
    start = _hinge(60.0)
    end = start.copy()
    end[3, 2] = -end[3, 2]
    assert certified([[0, 1, 2]], [[2, 1, 3]], start)[0] and certified([[0, 1, 2]], [[2, 1, 3]], end)[0]
    assert not meet_only_in_shared([0, 1, 2], [2, 1, 3], 0.5 * (start + end))
    assert not certified([[0, 1, 2]], [[2, 1, 3]], start, end)[0]
    assert certified([[0, 1, 2]], [[2, 1, 3]], start, _hinge(90.0))[0]


def test_the_hash_drops_only_certified_pairs_that_share_a_vertex() -> None:
    from pscc.mesh import twisted_sheet

    mesh = twisted_sheet(1200, turns=1.5, seed=2)
    faces = wp.array(mesh.faces.astype(np.int32), dtype=wp.vec3i, device=DEVICE)
    x = wp.array(mesh.vertices_end, dtype=wp.vec3, device=DEVICE)
    pad = 0.5 * float(np.linalg.norm(mesh.vertices_end[mesh.faces[:, 1]] - mesh.vertices_end[mesh.faces[:, 0]],
                                     axis=1).mean())
    tri = mesh.vertices_end[mesh.faces]
    lower = wp.array(tri.min(axis=1) - pad, dtype=wp.vec3, device=DEVICE)
    upper = wp.array(tri.max(axis=1) + pad, dtype=wp.vec3, device=DEVICE)
    found = {}
    for certify in (False, True):
        pairs, count = SpatialHash(len(mesh.faces), DEVICE, faces=faces).find_pairs(
            lower, upper, positions_t0=x, certify_shared=certify)
        found[certify] = {tuple(int(v) for v in p) for p in pairs.numpy()[:count]}
    assert found[True] <= found[False]
    dropped = found[False] - found[True]
    assert dropped
    for a, b in dropped:
        assert shared_vertex_ids(mesh.faces[a], mesh.faces[b])
        assert meet_only_in_shared(mesh.faces[a], mesh.faces[b], mesh.vertices_end)


def test_certify_shared_needs_faces_and_positions() -> None:
    from pscc.errors import InputError

    lower = wp.zeros(4, dtype=wp.vec3, device=DEVICE)
    upper = wp.ones(4, dtype=wp.vec3, device=DEVICE)
    with pytest.raises(InputError, match="certify_shared"):
        SpatialHash(4, DEVICE).find_pairs_device(lower, upper, certify_shared=True)
    faces = wp.array(np.array([[0, 1, 2], [2, 1, 3], [0, 2, 4], [4, 2, 3]], np.int32), dtype=wp.vec3i, device=DEVICE)
    with pytest.raises(InputError, match="positions_t0"):
        SpatialHash(4, DEVICE, faces=faces).find_pairs_device(lower, upper, certify_shared=True)
