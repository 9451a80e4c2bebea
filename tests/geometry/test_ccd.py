"""Conservative float32 CCD: exact benchmark queries, ipctk in float64, constructed contacts, degenerate cases."""

from __future__ import annotations

import glob
import os
from fractions import Fraction

import ipctk
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pscc.errors import InputError
from pscc.geometry.ccd import edge_edge_ccd, vertex_face_ccd
from pscc.tolerances import CCD_DISTANCE_TOLERANCE

DATA = os.path.join(os.path.dirname(__file__), "..", "data", "ccd-queries")


def _load_queries(folder: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Read the benchmark's rational CSV files: 8 rows per query, exact truth in column 7."""
    coords = []
    truth = []
    for path in sorted(glob.glob(os.path.join(folder, "*.csv"))):
        with open(path) as handle:
            for line in handle:
                n = [int(x) for x in line.strip().split(",")]
                coords.append([float(Fraction(n[0], n[1])), float(Fraction(n[2], n[3])),
                               float(Fraction(n[4], n[5]))])
                truth.append(n[6])
    points = np.array(coords, dtype=np.float64).reshape(-1, 8, 3)
    return points[:, :4], points[:, 4:], np.array(truth).reshape(-1, 8)[:, 0].astype(bool)


QUERY_SETS = sorted(
    os.path.relpath(d, DATA) for d in glob.glob(os.path.join(DATA, "*", "*")) if os.path.isdir(d)
)


def test_query_sets_are_present() -> None:
    assert len(QUERY_SETS) == 12


@pytest.mark.parametrize("query_set", QUERY_SETS)
def test_no_false_negative_on_benchmark_queries(query_set: str, device: str) -> None:
    x0, x1, truth = _load_queries(os.path.join(DATA, query_set))
    ccd = vertex_face_ccd if query_set.endswith("vertex-face") else edge_edge_ccd
    hit, toi = ccd(x0, x1, device=device)
    missed = np.flatnonzero(truth & ~hit)
    assert missed.size == 0, f"{query_set}: missed positive queries {missed.tolist()}"
    assert np.all((toi[hit] >= 0.0) & (toi[hit] <= 1.0))
    assert np.all(np.isinf(toi[~hit]))


def _ipc_ccd(
    kind: str, x0: np.ndarray, x1: np.ndarray, min_distance: float = 0.0, scale: float = 1.0
) -> tuple[bool, float]:
    # ipctk's tolerance is absolute (in the units of F): scale it with the query.
    ccd = ipctk.TightInclusionCCD(tolerance=1e-7 * scale, max_iterations=10_000_000, conservative_rescaling=1.0)
    fn = ccd.point_triangle_ccd if kind == "vf" else ccd.edge_edge_ccd
    args = [np.asarray(p, dtype=np.float64) for p in (*x0, *x1)]
    return fn(*args, min_distance=min_distance)


def _random_batch(rng: np.random.Generator, kind: str, count: int, scale: float, shift: np.ndarray):
    """Half random motions, half motions built to touch at a known time t_star."""
    x0 = rng.uniform(-1.0, 1.0, (count, 4, 3))
    x1 = x0 + rng.normal(0.0, 0.8, (count, 4, 3))
    t_star = np.full(count, np.inf)
    for i in range(count // 2):
        ts = rng.uniform(0.0, 1.0)
        velocity = rng.normal(0.0, 1.0, (4, 3))
        at = rng.uniform(-1.0, 1.0, (4, 3))
        if kind == "vf":
            w = rng.dirichlet([1.0, 1.0, 1.0])
            at[0] = w[0] * at[1] + w[1] * at[2] + w[2] * at[3]
        else:
            s, u = rng.uniform(0.0, 1.0, 2)
            # Move b so that its point at parameter u meets a's point at parameter s.
            pa = (1 - s) * at[0] + s * at[1]
            pb = (1 - u) * at[2] + u * at[3]
            at[2:] += pa - pb
        x0[i] = at - ts * velocity
        x1[i] = at + (1.0 - ts) * velocity
        t_star[i] = ts
    return x0 * scale + shift, x1 * scale + shift, t_star


@settings(max_examples=30, deadline=None)
@given(
    seed=st.integers(0, 2**31 - 1),
    kind=st.sampled_from(["vf", "ee"]),
    scale=st.sampled_from([1e-3, 1.0, 50.0]),
    offset=st.sampled_from([0.0, 1.0, 300.0]),
)
def test_against_ipctk_and_constructed_contacts(seed: int, kind: str, scale: float, offset: float) -> None:
    rng = np.random.default_rng(seed)
    shift = rng.uniform(-1.0, 1.0, 3) * offset
    x0, x1, t_star = _random_batch(rng, kind, 48, scale, shift)
    ccd = vertex_face_ccd if kind == "vf" else edge_edge_ccd
    hit, toi = ccd(x0, x1)
    # Built to touch at t_star: must be reported no later than t_star.
    built = np.isfinite(t_star)
    assert np.all(hit[built])
    assert np.all(toi[built] <= t_star[built] + 1e-7)
    for i in range(len(x0)):
        ipc_hit, ipc_toi = _ipc_ccd(kind, x0[i], x1[i], scale=scale)
        if ipc_hit:
            assert hit[i], f"query {i}: ipctk reports contact at {ipc_toi}, pscc misses it"
            assert toi[i] <= ipc_toi + 1e-3, f"query {i}: toi {toi[i]} later than ipctk's {ipc_toi}"
        elif hit[i]:
            # A false positive must be a near miss: within the documented tolerance band, which
            # includes the rounding of float64 input to float32 (2 u |x| per axis).
            local = np.abs(x0[i] - x0[i][0]).max() + np.abs(x1[i] - x0[i][0]).max()
            rounding = 2.0**-24 * max(np.abs(x0[i]).max(), np.abs(x1[i]).max())
            band = 1e-4 * local + 8.0 * rounding
            near, _ = _ipc_ccd(kind, x0[i], x1[i], min_distance=band, scale=scale)
            assert near, f"query {i}: pscc reports a contact that is not even a near miss"


def _vf(p0, a0, b0, c0, p1, a1, b1, c1):
    return np.array([[p0, a0, b0, c0]], np.float32), np.array([[p1, a1, b1, c1]], np.float32)


def _ee(a0, a1, b0, b1, c0, c1, d0, d1):
    return np.array([[a0, a1, b0, b1]], np.float32), np.array([[c0, c1, d0, d1]], np.float32)


TRI = ([0, 0, 0], [1, 0, 0], [0, 1, 0])


@pytest.mark.parametrize(
    "name, x0, x1, expect_hit, toi_at_most",
    [
        ("vertex through interior", *_vf([0.2, 0.2, 1], *TRI, [0.2, 0.2, -1], *TRI), True, 0.5),
        ("vertex misses beside", *_vf([2, 2, 1], *TRI, [2, 2, -1], *TRI), False, None),
        ("vertex on face at t=0", *_vf([0.3, 0.3, 0], *TRI, [0.3, 0.3, 1], *TRI), True, 0.0),
        ("vertex reaches face at t=1", *_vf([0.3, 0.3, 1], *TRI, [0.3, 0.3, 0], *TRI), True, 1.0),
        ("vertex hits face edge", *_vf([0.5, 0, 1], *TRI, [0.5, 0, -1], *TRI), True, 0.5),
        ("vertex hits face vertex", *_vf([1, 0, 1], *TRI, [1, 0, -1], *TRI), True, 0.5),
        ("vertex slides in face plane", *_vf([-1, 0.2, 0], *TRI, [2, 0.2, 0], *TRI), True, 1 / 3),
        ("zero-area face, vertex crosses its segment",
         *_vf([0.5, 0.5, 1], [0, 0, 0], [1, 1, 0], [2, 2, 0], [0.5, 0.5, -1], [0, 0, 0], [1, 1, 0], [2, 2, 0]),
         True, 0.5),
        ("zero-area face, vertex passes beside",
         *_vf([0.5, -0.5, 1], [0, 0, 0], [1, 1, 0], [2, 2, 0], [0.5, -0.5, -1], [0, 0, 0], [1, 1, 0], [2, 2, 0]),
         False, None),
        ("all face vertices coincide",
         *_vf([0, 0, 1], [0, 0, 0], [0, 0, 0], [0, 0, 0], [0, 0, -1], [0, 0, 0], [0, 0, 0], [0, 0, 0]),
         True, 0.5),
        ("one-ulp motion onto the face",
         *_vf([0.3, 0.3, np.float32(2**-24)], *TRI, [0.3, 0.3, 0], *TRI), True, 1.0),
        ("static, far", *_vf([0.3, 0.3, 1], *TRI, [0.3, 0.3, 1], *TRI), False, None),
    ],
)
def test_vertex_face_named_cases(name, x0, x1, expect_hit, toi_at_most, device) -> None:
    hit, toi = vertex_face_ccd(x0, x1, device=device)
    assert bool(hit[0]) == expect_hit, name
    if expect_hit:
        assert toi[0] <= toi_at_most + 1e-7, name
        assert toi[0] >= toi_at_most - 1e-3, f"{name}: toi {toi[0]} needlessly early"


@pytest.mark.parametrize(
    "name, x0, x1, expect_hit, toi_at_most",
    [
        ("crossing edges", *_ee([0, 0, 1], [1, 0, 1], [0.5, -1, 0], [0.5, 1, 0],
                                [0, 0, -1], [1, 0, -1], [0.5, -1, 0], [0.5, 1, 0]), True, 0.5),
        ("parallel edges meet at t=1", *_ee([0, 0, 1], [1, 0, 1], [0, 0, 0], [1, 0, 0],
                                            [0, 0, 0], [1, 0, 0], [0, 0, 0], [1, 0, 0]), True, 1.0),
        ("parallel edges stay apart", *_ee([0, 0, 1], [1, 0, 1], [0, 0, 0], [1, 0, 0],
                                           [0, 1, 1], [1, 1, 1], [0, 0, 0], [1, 0, 0]), False, None),
        ("collinear overlapping at t=0", *_ee([0, 0, 0], [1, 0, 0], [0.5, 0, 0], [2, 0, 0],
                                              [0, 0, 0], [1, 0, 0], [0.5, 0, 0], [2, 0, 0]), True, 0.0),
        ("collinear disjoint, approach", *_ee([0, 0, 0], [1, 0, 0], [2, 0, 0], [3, 0, 0],
                                              [0, 0, 0], [1, 0, 0], [0.5, 0, 0], [1.5, 0, 0]), True, 2 / 3),
        ("endpoint touches endpoint", *_ee([0, 0, 0], [1, 0, 0], [1, 1, 0], [1, 2, 0],
                                           [0, 0, 0], [1, 0, 0], [1, 0, 0], [1, 1, 0]), True, 1.0),
        ("zero-length edge crosses edge", *_ee([0.5, 0.5, 1], [0.5, 0.5, 1], [0, 0.5, 0], [1, 0.5, 0],
                                               [0.5, 0.5, -1], [0.5, 0.5, -1], [0, 0.5, 0], [1, 0.5, 0]),
         True, 0.5),
        ("skew edges pass", *_ee([0, 0, 1], [1, 0, 1], [2, -1, 0], [2, 1, 0],
                                 [0, 0, -1], [1, 0, -1], [2, -1, 0], [2, 1, 0]), False, None),
    ],
)
def test_edge_edge_named_cases(name, x0, x1, expect_hit, toi_at_most, device) -> None:
    hit, toi = edge_edge_ccd(x0, x1, device=device)
    assert bool(hit[0]) == expect_hit, name
    if expect_hit:
        assert toi[0] <= toi_at_most + 1e-7, name
        assert toi[0] >= toi_at_most - 1e-3, f"{name}: toi {toi[0]} needlessly early"


def test_minimum_distance(device: str) -> None:
    # The vertex stops 0.05 above the face.
    x0, x1 = _vf([0.2, 0.2, 1], *TRI, [0.2, 0.2, 0.05], *TRI)
    hit, toi = vertex_face_ccd(x0, x1, 0.1, device=device)
    assert hit[0] and toi[0] <= (1 - 0.1) / 0.95 + 1e-7
    hit, _ = vertex_face_ccd(x0, x1, 0.01, device=device)
    assert not hit[0]
    # Parallel edges 0.3 apart, static.
    e0, e1 = _ee([0, 0, 0.3], [1, 0, 0.3], [0, 0, 0], [1, 0, 0], [0, 0, 0.3], [1, 0, 0.3], [0, 0, 0], [1, 0, 0])
    assert edge_edge_ccd(e0, e1, 0.31, device=device)[0][0]
    assert not edge_edge_ccd(e0, e1, 0.29, device=device)[0][0]


def test_empty_batch_and_bad_input() -> None:
    hit, toi = vertex_face_ccd(np.zeros((0, 4, 3)), np.zeros((0, 4, 3)))
    assert hit.shape == (0,) and toi.shape == (0,)
    with pytest.raises(InputError, match="points_t0"):
        vertex_face_ccd(np.zeros((2, 3, 3)), np.zeros((2, 3, 3)))
    with pytest.raises(InputError, match="points_t1"):
        edge_edge_ccd(np.zeros((2, 4, 3)), np.zeros((3, 4, 3)))
    bad = np.zeros((1, 4, 3))
    bad[0, 1, 2] = np.nan
    with pytest.raises(InputError, match="NaN"):
        edge_edge_ccd(bad, np.zeros((1, 4, 3)))
    with pytest.raises(InputError, match="minimum_distance"):
        edge_edge_ccd(np.zeros((1, 4, 3)), np.zeros((1, 4, 3)), -1.0)
    for tolerance, problem in ((-0.1, "negative"), (float("nan"), "not finite"), (1.0, "not below 1")):
        with pytest.raises(InputError, match=f"distance_tolerance.*{problem}"):
            vertex_face_ccd(np.zeros((1, 4, 3)), np.zeros((1, 4, 3)), 0.1, distance_tolerance=tolerance)


def test_deterministic(device: str) -> None:
    rng = np.random.default_rng(7)
    x0 = rng.uniform(-1, 1, (500, 4, 3)).astype(np.float32)
    x1 = (x0 + rng.normal(0, 0.5, x0.shape)).astype(np.float32)
    first = vertex_face_ccd(x0, x1, device=device)
    second = vertex_face_ccd(x0, x1, device=device)
    assert np.array_equal(first[0], second[0]) and np.array_equal(first[1], second[1])


def _segment_distance(a0: np.ndarray, a1: np.ndarray, b0: np.ndarray, b1: np.ndarray) -> float:
    """Float64 segment-segment distance by dense sampling of one parameter and exact projection."""
    s = np.linspace(0.0, 1.0, 401)[:, None]
    points = a0 + s * (a1 - a0)
    d = b1 - b0
    t = np.clip(((points - b0) @ d) / max(d @ d, 1e-300), 0.0, 1.0)[:, None]
    return float(np.linalg.norm(points - (b0 + t * d), axis=1).min())


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), motion=st.floats(1e-4, 0.2), gap=st.floats(-0.02, 0.02))
def test_motion_bound_filter_never_drops_a_near_pair(seed: int, motion: float, gap: float) -> None:
    """Edge pairs resting or moving slowly near the minimum distance (the case the motion-bound filter
    skips): whenever densely sampled float64 distances come below d_min by a margin, CCD reports it."""
    rng = np.random.default_rng(seed)
    d_min = 0.1
    count = 64
    a0 = rng.normal(size=(count, 3))
    a1 = a0 + rng.normal(size=(count, 3))
    direction = rng.normal(size=(count, 3))
    direction /= np.linalg.norm(direction, axis=1, keepdims=True)
    # The b edge starts about d_min + motion + gap away and moves by about `motion`.
    offset = direction * (d_min + motion + gap)
    b0 = a0 + 0.3 * (a1 - a0) + offset + 0.01 * rng.normal(size=(count, 3))
    b1 = b0 + rng.normal(size=(count, 3))
    step = rng.normal(size=(count, 4, 3))
    step *= motion / np.maximum(np.linalg.norm(step, axis=2, keepdims=True), 1e-12)
    x0 = np.stack([a0, a1, b0, b1], axis=1)
    x1 = x0 + step
    hit, _ = edge_edge_ccd(x0, x1, d_min, device="cpu")
    for i in range(count):
        closest = min(_segment_distance(*((1 - t) * x0[i] + t * x1[i])) for t in np.linspace(0.0, 1.0, 41))
        if closest < d_min * (1 - 1e-3):
            assert hit[i], f"pair {i} comes within {closest:.6f} < {d_min} but CCD reports no contact"
    # Static pairs clearly farther than d_min are excluded (the filter's purpose), nearer ones kept.
    static, _ = edge_edge_ccd(x0, x0, d_min, device="cpu")
    for i in range(count):
        distance = _segment_distance(*x0[i])
        if distance < d_min * (1 - 1e-3):
            assert static[i]
        elif distance > d_min * 1.01:
            assert not static[i]



@settings(max_examples=60, deadline=None)
@given(
    kind=st.sampled_from(["vertex-face", "edge-edge"]),
    scale=st.sampled_from([1e-3, 1.0, 1e3]),
    shift=st.floats(-1e3, 1e3),
    relative=st.floats(-1e-3, 1e-3),
    exact_float32=st.booleans(),
)
def test_swept_box_filter_keeps_pairs_at_the_box_gap(kind: str, scale: float, shift: float, relative: float,
                                                      exact_float32: bool) -> None:
    """Axis-aligned pairs whose closest distance equals the gap between their swept boxes (the swept-box
    filter's tightest case): a pair that comes within d_min is reported, one ending 1.5 d_min away is not.

    The second feature sinks along z onto the first, to end d_min (1 + relative) above it: the boxes'
    z gap is then the closest distance, at every scale and translation, for float32 input and for float64
    input that float32 cannot hold (the input rounding bound)."""
    d_min = 0.01 * scale
    end = d_min * (1.0 + relative)
    if kind == "vertex-face":  # the face at z = 0, the vertex sinking onto its interior
        face = [[0.0, 0.0, 0.0], [scale, 0.0, 0.0], [0.0, scale, 0.0]]
        x0 = np.array([[0.25 * scale, 0.25 * scale, 3 * d_min]] + face)
        x1 = np.array([[0.25 * scale, 0.25 * scale, end]] + face)
        moving, resting, ccd = [0], [1, 2, 3], vertex_face_ccd
    else:  # edge a along x at z = 0, edge b along y sinking onto its middle
        a = [[0.0, 0.0, 0.0], [scale, 0.0, 0.0]]
        x0 = np.array(a + [[0.5 * scale, -0.5 * scale, 3 * d_min], [0.5 * scale, 0.5 * scale, 3 * d_min]])
        x1 = np.array(a + [[0.5 * scale, -0.5 * scale, end], [0.5 * scale, 0.5 * scale, end]])
        moving, resting, ccd = [2, 3], [0, 1], edge_edge_ccd
    x0, x1 = x0 + shift, x1 + shift
    if exact_float32:
        x0, x1 = x0.astype(np.float32).astype(np.float64), x1.astype(np.float32).astype(np.float64)
    # The closest distance of the coordinates as given: the z gap at the end of the step.
    closest = float(x1[moving, 2].min() - x1[resting, 2].max())
    hit, _ = ccd(x0[None], x1[None], d_min)
    if closest <= d_min:
        assert hit[0], f"comes within {closest!r} <= d_min {d_min!r} but no contact is reported"
    apart = x1.copy()
    apart[moving, 2] += 0.5 * d_min
    if abs(shift) * 1e-6 < 0.1 * d_min:  # the shift's rounding is far below the extra half d_min
        assert not ccd(x0[None], apart[None], d_min)[0][0]


def _exact_distance(kind: str, points: np.ndarray) -> float:
    """Float64 distance of one vertex-face (p, a, b, c) or edge-edge (a0, a1, b0, b1) configuration."""
    if kind == "vertex-face":
        return float(np.sqrt(ipctk.point_triangle_distance(*points)))
    return float(np.sqrt(ipctk.edge_edge_distance(*points)))


@settings(max_examples=25, deadline=None)
@given(kind=st.sampled_from(["vertex-face", "edge-edge"]), seed=st.integers(0, 2**31 - 1),
       d_min=st.sampled_from([1e-3, 0.02, 0.1]), tolerance=st.sampled_from([0.0, CCD_DISTANCE_TOLERANCE, 0.25]))
def test_thick_ccd_is_conservative_and_its_false_positives_stay_near_d_min(kind: str, seed: int, d_min: float,
                                                                            tolerance: float) -> None:
    """With d_min > 0 and a distance tolerance (0, the default and 0.25: conservative advancement for pairs
    that start clear of the band, boxes below tolerance x d_min refined only in t), the CCD never misses a
    contact nor reports one late (against float64 distances at 401 times), and a pair it reports came
    within d_min (1 + tolerance sqrt(3)) (plus the rounding term)."""
    rng = np.random.default_rng(seed)
    count = 48
    # Features that start 0.3-3 d_min apart along their common normal and approach by 0-3 d_min, with a
    # sideways drift and the other feature's corners jittered by up to d_min: grazing contacts and
    # near misses.
    x0 = np.empty((count, 4, 3))
    normal = np.empty((count, 3))
    for i in range(count):
        if kind == "vertex-face":
            a, b, c = rng.normal(size=(3, 3)) * 0.5
            weights = rng.dirichlet(np.ones(3))
            n = np.cross(b - a, c - a)
            n /= np.linalg.norm(n)
            x0[i, 1:] = a, b, c
            anchor = weights @ np.array([a, b, c])
            x0[i, 0] = anchor + n * d_min * rng.uniform(0.3, 3.0)
        else:
            a0, a1 = rng.normal(size=(2, 3)) * 0.5
            along = rng.normal(size=3)
            n = np.cross(a1 - a0, along)
            n /= np.linalg.norm(n)
            middle = a0 + rng.uniform(0.1, 0.9) * (a1 - a0) + n * d_min * rng.uniform(0.3, 3.0)
            along /= np.linalg.norm(along)
            x0[i] = a0, a1, middle - along * rng.uniform(0.1, 0.5), middle + along * rng.uniform(0.1, 0.5)
        normal[i] = n
    x1 = x0 + rng.uniform(-1.0, 1.0, size=(count, 4, 3)) * d_min
    moving = slice(0, 1) if kind == "vertex-face" else slice(2, 4)
    x1[:, moving] -= (normal * d_min * rng.uniform(0.0, 3.0, size=(count, 1)))[:, None, :]
    run = vertex_face_ccd if kind == "vertex-face" else edge_edge_ccd
    hit, toi = run(x0.astype(np.float32), x1.astype(np.float32), d_min, device="cpu", distance_tolerance=tolerance)
    x0 = x0.astype(np.float32).astype(np.float64)
    x1 = x1.astype(np.float32).astype(np.float64)
    times = np.linspace(0.0, 1.0, 401)
    scale = np.abs(np.concatenate([x0, x1], axis=1) - x0[:, :1]).max(axis=(1, 2))
    reached = 0
    for i in range(count):
        distances = np.array([_exact_distance(kind, (1 - t) * x0[i] + t * x1[i]) for t in times])
        inside = np.flatnonzero(distances < d_min * (1 - 1e-4))
        if inside.size:
            reached += 1
            assert hit[i], f"pair {i} comes within {distances.min():.3g} < {d_min} but CCD reports no contact"
            assert toi[i] <= times[inside[0]] + 1e-6, f"pair {i}: toi {toi[i]} after the contact at {times[inside[0]]}"
        if hit[i]:
            sampling = np.abs(x1[i] - x0[i]).max() * 2.0 / 400.0
            bound = d_min * (1 + tolerance * np.sqrt(3.0)) + 1e-5 * scale[i] + sampling
            assert distances.min() <= bound, f"pair {i} reported, but never closer than {distances.min():.4g}"
    assert reached > 0  # the construction makes contacts to find


@pytest.mark.parametrize("kind", ["vertex-face", "edge-edge"])
@pytest.mark.parametrize("gap", [1.02, 1.05, 1.15, 1.5])
def test_a_pair_resting_or_sliding_beyond_d_min_is_never_reported(kind: str, gap: float) -> None:
    """A pair that stays ``gap`` x d_min apart (at rest, or sliding by 0.3 of its size) never comes within
    d_min, so no distance tolerance may report it: reported at t = 0, no change of the end positions could
    resolve it (the endless response rounds of the first versions of the tolerance). Pairs that start
    within d_min (1 + sqrt 3 x tolerance) are therefore searched exactly, the others advanced.

    The closest points sit at a vertex beside the other feature's plane (below d_min from it), and the
    scene is turned by a fixed rotation, so neither the swept boxes, nor the motion bound, nor the plane
    filter excludes the sliding pair before the search."""
    d_min = 0.01
    g = gap * d_min
    if kind == "vertex-face":
        # A vertex beyond the edge y = 0 of the triangle, half of g above its plane, sliding along the edge.
        x0 = np.array([[0.3, -np.sqrt(0.75) * g, 0.5 * g], [0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
        moving, slide_by, press_by = slice(0, 1), [0.3, 0.0, 0.0], [0.0, 2.0 * np.sqrt(0.75) * g, -g]
    else:
        # Edge a leaves edge b at its first end, g from b's middle, heading away from b; it slides along b.
        x0 = np.array([[0.5, 0.8 * g, 0.6 * g], [0.5, 0.8 * g + 1.0, 0.6 * g - 0.5], [0.0, 0.0, 0.0], [1.0, 0.0, 0.0]])
        moving, slide_by, press_by = slice(0, 2), [0.3, 0.0, 0.0], [0.0, -1.6 * g, -1.2 * g]
    rotation = np.linalg.qr(np.random.default_rng(7).normal(size=(3, 3)))[0]
    slide = x0.copy()
    slide[moving] += slide_by
    pressed = x0.copy()
    pressed[moving] += press_by
    x0, slide, pressed = x0 @ rotation.T, slide @ rotation.T, pressed @ rotation.T
    run = vertex_face_ccd if kind == "vertex-face" else edge_edge_ccd
    for tolerance in (0.0, CCD_DISTANCE_TOLERANCE, 0.25):
        hit, _ = run(np.stack([x0, x0]).astype(np.float32), np.stack([x0, slide]).astype(np.float32), d_min,
                     device="cpu", distance_tolerance=tolerance)
        assert not hit.any(), f"tolerance {tolerance}: a pair {gap} d_min apart was reported"
    # The same pair moved straight through the other feature is found at every tolerance, never late.
    contact = (gap - 1.0) / (2.0 * gap)
    for tolerance in (0.0, CCD_DISTANCE_TOLERANCE, 0.25):
        hit, toi = run(x0[None].astype(np.float32), pressed[None].astype(np.float32), d_min, device="cpu",
                       distance_tolerance=tolerance)
        assert hit[0] and toi[0] <= contact + 1e-6, f"tolerance {tolerance}: toi {toi[0]} after {contact}"


@pytest.mark.parametrize("kind", ["vertex-face", "edge-edge"])
@pytest.mark.parametrize("seed", [0, 1])
def test_thick_ccd_advancement_on_thin_triangles_near_parallel_edges_and_fast_motion(kind: str, seed: int) -> None:
    """The conservative advancement's error bounds on the inputs that stress them: triangles down to
    flatness 1e-8 (whose float32 distance may err upwards by 1e-3 of their size, so the advancement must
    use the larger bound or leave them to the boxes), edges within 1e-3 rad of parallel, minimum distances
    from 1e-4 to 0.1 of the features' size and motions from 0.1 to 30 d_min. Against float64 distances
    at 801 times: no contact missed or reported late, with the default tolerance."""
    rng = np.random.default_rng(100 + seed)
    count = 256
    times = np.linspace(0.0, 1.0, 801)
    x0 = np.empty((count, 4, 3))
    x1 = np.empty((count, 4, 3))
    d_min = 10.0 ** rng.uniform(-4.0, -1.0, size=count)
    for i in range(count):
        d = d_min[i]
        if kind == "vertex-face":
            a, b = rng.normal(size=(2, 3)) * 0.5
            spread = 0.5 if i % 2 else 10.0 ** rng.uniform(-4.0, -1.0)  # every other triangle thin
            c = a + (b - a) * rng.uniform(0.2, 0.8) + rng.normal(size=3) * spread
            n = np.cross(b - a, c - a)
            n /= np.linalg.norm(n)
            x0[i] = rng.dirichlet(np.ones(3)) @ np.array([a, b, c]) + n * d * rng.uniform(1.0, 5.0), a, b, c
        else:
            a0, a1 = rng.normal(size=(2, 3)) * 0.5
            along = (a1 - a0) + rng.normal(size=3) * (1.0 if i % 2 else 1e-3)  # every other pair near parallel
            n = np.cross(a1 - a0, along)
            n /= np.linalg.norm(n)
            middle = a0 + rng.uniform(-0.2, 1.2) * (a1 - a0) + n * d * rng.uniform(1.0, 5.0)
            along /= np.linalg.norm(along)
            x0[i] = a0, a1, middle - along * rng.uniform(0.05, 0.5), middle + along * rng.uniform(0.05, 0.5)
        motion = rng.normal(size=(4, 3)) * d * 10.0 ** rng.uniform(-1.0, 1.5)
        motion[0 if kind == "vertex-face" else slice(0, 2)] -= n * d * rng.uniform(0.0, 8.0)
        x1[i] = x0[i] + motion
    x0 = x0.astype(np.float32)
    x1 = x1.astype(np.float32)
    run = vertex_face_ccd if kind == "vertex-face" else edge_edge_ccd
    reached = 0
    for i in range(count):  # one query per call: each has its own d_min
        hit, toi = run(x0[i:i + 1], x1[i:i + 1], float(d_min[i]), device="cpu")
        start, end = x0[i].astype(np.float64), x1[i].astype(np.float64)
        distances = np.array([_exact_distance(kind, (1 - t) * start + t * end) for t in times])
        inside = np.flatnonzero(distances < d_min[i] * (1 - 1e-4))
        if inside.size:
            reached += 1
            assert hit[0], f"query {i} comes within {distances.min():.3g} < {d_min[i]:.3g}: missed"
            assert toi[0] <= times[inside[0]] + 1e-6, f"query {i}: toi {toi[0]} after {times[inside[0]]}"
    assert reached >= 16  # contacts to find (20-24 of 256 edge pairs, more vertex-face pairs)
