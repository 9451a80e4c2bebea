"""The 26-DOP face test of the spatial hash (pscc.geometry.dop): the diagonal slabs only drop face
pairs that are farther apart than the distance (float64 ipctk distances on layered meshes, exact
float64 projections on random and degenerate triangles, discrete and over a step), they drop many
pairs between tilted layers, and the detector's colliding pairs do not change with them."""

from __future__ import annotations

import numpy as np
import pytest
import warp as wp
from hypothesis import given, settings
from hypothesis import strategies as st

from pscc.collision.boxes import PrimitiveBoxes
from pscc.collision.detector import CollisionDetector
from pscc.collision.spatial_hash import SpatialHash
from pscc.errors import InputError
from pscc.mesh import folded_sheet
from tests.collision.test_group_slab import _patch_nodes, _triangle_distance, _twist, _two_sheets
from tests.collision.test_spatial_hash import _reference

DEVICE = "cpu"


def _slabs(faces: np.ndarray, x0: np.ndarray, x1: np.ndarray | None, half: float) -> PrimitiveBoxes:
    """PrimitiveBoxes with diagonal slabs, computed for the step (or frame) at distance 2 half."""
    x0_wp = wp.array(x0, dtype=wp.vec3, device=DEVICE)
    x1_wp = x0_wp if x1 is None else wp.array(x1, dtype=wp.vec3, device=DEVICE)
    boxes = PrimitiveBoxes(wp.array(faces, dtype=wp.vec3i, device=DEVICE), wp.zeros(1, dtype=wp.vec2i, device=DEVICE),
                           x0.shape[0], DEVICE, face_diagonals=True)
    boxes.compute(x0_wp, x1_wp, 2.0 * half)
    return boxes


def _find(faces, x0, x1, node, half, *, diagonals: bool, cell_size=None):
    """Pairs of the plain hash (no group slab test), with or without the diagonal slabs, and the boxes."""
    boxes = _slabs(faces, x0, x1, half)
    hash_ = SpatialHash(faces.shape[0], DEVICE, faces=wp.array(faces, dtype=wp.vec3i, device=DEVICE),
                        group_slab_test=False)
    extra = {}
    if diagonals:
        extra = {"face_diagonal_lower": boxes.face_diagonal_lower, "face_diagonal_upper": boxes.face_diagonal_upper}
    hash_.find_pairs(boxes.face_lower, boxes.face_upper, wp.array(node, dtype=wp.int32, device=DEVICE), cell_size,
                     **extra)
    return hash_.pairs_numpy(), boxes.face_lower.numpy(), boxes.face_upper.numpy()


def _check_conservative(faces, x0, x1, node, half) -> int:
    """Diagonal-tested pairs = box pairs less some pairs, each farther than 2 half (at t0, t1 and
    seven times in between for a step); returns how many were dropped."""
    got, lower, upper = _find(faces, x0, x1, node, half, diagonals=True)
    box_set = {tuple(p) for p in _reference(lower, upper, np.asarray(node, dtype=np.int32)).tolist()}
    got_set = {tuple(p) for p in got.tolist()}
    assert got_set <= box_set
    assert len(got_set) == got.shape[0]
    times = [0.0] if x1 is None else np.linspace(0.0, 1.0, 9)
    for a, b in box_set - got_set:
        for t in times:
            x = x0 if x1 is None else (1.0 - t) * x0.astype(np.float64) + t * x1.astype(np.float64)
            distance = _triangle_distance(x[faces[a]], x[faces[b]])
            assert distance > 2.0 * half * (1.0 - 1e-9), f"pair ({a}, {b}) at distance {distance} was dropped"
    return len(box_set - got_set)


def test_twisted_layers_discrete() -> None:
    mesh = folded_sheet(1500, layers=3, seed=3)
    x = _twist(mesh.vertices_end, 0.5)
    half = 0.25 * float(np.linalg.norm(x[mesh.faces[:, 0]] - x[mesh.faces[:, 1]], axis=1).mean())
    node = np.arange(mesh.faces.shape[0], dtype=np.int32)
    dropped = _check_conservative(mesh.faces, x, None, node, half)
    box_pairs = _find(mesh.faces, x, None, node, half, diagonals=False)[0].shape[0]
    # Tilted stacked layers: the diagonals drop a large share of the box pairs.
    assert dropped > 0.2 * box_pairs


def test_twisted_layers_over_a_step() -> None:
    mesh = folded_sheet(1200, layers=3, seed=5)
    x0 = _twist(mesh.vertices, 0.5)
    x1 = _twist(mesh.vertices_end, 0.51)
    node = _patch_nodes(mesh.rest, mesh.faces, 5)
    assert _check_conservative(mesh.faces, x0, x1, node, 0.002) > 0


@pytest.mark.parametrize("tilt", [np.pi / 4, 0.6])
def test_sheets_at_the_distance_are_kept_and_farther_dropped(tilt: float) -> None:
    # At tilt pi/4 the sheets' normal is the diagonal y - z: the gap is measured exactly on a slab axis.
    half = 0.125
    faces, x, node = _two_sheets(gap=2.0 * half, tilt=tilt)
    got, lower, upper = _find(faces, x, None, node, half, diagonals=True, cell_size=10.0)
    box_pairs = _reference(lower, upper, node)
    close = [tuple(p) for p in box_pairs.tolist() if _triangle_distance(x[faces[p[0]]], x[faces[p[1]]]) <= 2 * half]
    assert close and set(close) <= {tuple(p) for p in got.tolist()}
    if tilt == np.pi / 4:
        faces, x, node = _two_sheets(gap=2.0 * half * 1.01, tilt=tilt)
        far, lower, upper = _find(faces, x, None, node, half, diagonals=True, cell_size=10.0)
        assert _reference(lower, upper, node).shape[0] > 0  # the boxes still overlap
        assert far.shape[0] == 0


_COORD = st.floats(-1.0, 1.0, allow_nan=False, width=32)
_AXES = np.array([[1, 1, 0], [1, -1, 0], [1, 0, 1], [1, 0, -1], [0, 1, 1], [0, 1, -1],
                  [1, 1, 1], [1, 1, -1], [1, -1, 1], [-1, 1, 1]], dtype=np.float64)


@settings(max_examples=200, deadline=None)
@given(first=st.lists(_COORD, min_size=9, max_size=9), second=st.lists(_COORD, min_size=9, max_size=9),
       motion=st.lists(_COORD, min_size=9, max_size=9),
       offset=st.sampled_from([0.0, 1.0, -1000.0, 1e5]), scale=st.sampled_from([1e-3, 1.0, 30.0]),
       flatten=st.sampled_from([1.0, 1e-4, 0.0]), half=st.sampled_from([0.0, 1e-4, 0.01, 0.2]),
       swept=st.booleans())
def test_disjoint_slabs_are_farther_apart_than_the_distance(first, second, motion, offset, scale, flatten,
                                                            half, swept) -> None:
    """Every axis on which the stored (float32) slabs miss each other separates the two faces' exact
    (float64) vertex projections by more than 2 h |a|: the faces, being in the hulls of those
    vertices, are farther apart than 2 h. Degenerate faces (flatten 0: a segment or a point) included.
    The slabs are in the call's local frame (origin: vertex 0 at t0), so the exact projections are of
    the vertices relative to it."""
    a = np.array(first, dtype=np.float64).reshape(3, 3)
    b = np.array(second, dtype=np.float64).reshape(3, 3)
    b = b.mean(axis=0) + flatten * (b - b.mean(axis=0))  # flatten 0: all three vertices at one point
    b = 0.5 * b + 0.5 * a.mean(axis=0)  # near a, so that many axes come close to the distance
    x0 = (np.concatenate([a, b]) * scale + offset).astype(np.float32)
    x1 = None
    if swept:
        step = 0.3 * scale * np.concatenate([np.zeros((3, 3)), np.array(motion).reshape(3, 3)])
        x1 = (x0.astype(np.float64) + step).astype(np.float32)
    h = half * scale
    faces = np.array([[0, 1, 2], [3, 4, 5]], dtype=np.int32)
    boxes = _slabs(faces, x0, x1, h)
    lo = boxes.face_diagonal_lower.numpy().astype(np.float64)
    hi = boxes.face_diagonal_upper.numpy().astype(np.float64)
    points = x0.astype(np.float64) if x1 is None else np.concatenate([x0, x1]).astype(np.float64)
    points = points - x0[0].astype(np.float64)
    owner = np.tile(np.array([0, 0, 0, 1, 1, 1]), points.shape[0] // 6)
    # The local-frame differences and projections in float64: exact for most inputs, else within 1e-16
    # relative, far below the float32 pads the assertions lean on.
    projections = points @ _AXES.T
    norms = np.linalg.norm(_AXES, axis=1)
    for k in range(_AXES.shape[0]):
        exact = [projections[owner == f, k] for f in (0, 1)]
        for f in (0, 1):
            assert lo[f, k] <= exact[f].min() - h * norms[k] and hi[f, k] >= exact[f].max() + h * norms[k]
        if lo[0, k] > hi[1, k] or lo[1, k] > hi[0, k]:
            gap = max(exact[0].min() - exact[1].max(), exact[1].min() - exact[0].max())
            assert gap > 2.0 * h * norms[k], f"axis {_AXES[k]} culls faces {gap / norms[k]} apart (distance {2 * h})"


@pytest.mark.parametrize("offset", [1000.0, -3000.0])
def test_a_frame_far_from_the_origin_keeps_its_diagonal_culling(offset: float) -> None:
    """The slabs' rounding pads scale with the scene's extent, not its distance from the origin (the local
    frame of :mod:`pscc.geometry.dop`): the twisted layers moved 1,000 or 3,000 units away keep within 1 %
    of the pairs they keep at the origin (in the world frame they kept 6 % more at 1,000), and every
    dropped pair there is still farther apart than the distance."""
    mesh = folded_sheet(1500, layers=3, seed=3)
    x = _twist(mesh.vertices_end, 0.5)
    half = 0.25 * float(np.linalg.norm(x[mesh.faces[:, 0]] - x[mesh.faces[:, 1]], axis=1).mean())
    node = np.arange(mesh.faces.shape[0], dtype=np.int32)
    near = _find(mesh.faces, x, None, node, half, diagonals=True)[0].shape[0]
    far_x = (x.astype(np.float64) + offset).astype(np.float32)
    far = _find(mesh.faces, far_x, None, node, half, diagonals=True)[0].shape[0]
    assert far <= 1.01 * near, f"{far} pairs kept at {offset} against {near} at the origin"
    assert _check_conservative(mesh.faces, far_x, None, node, half) > 0


@pytest.mark.parametrize("axis", range(10))
def test_points_exactly_the_distance_apart_along_an_axis_overlap(axis: int) -> None:
    # Two point faces 2 h apart along the axis (|a| h per unit of the scaled axis): touching, never culled.
    direction = _AXES[axis] / np.linalg.norm(_AXES[axis])
    half = 0.25
    first = np.full((3, 3), 3.0)
    second = first + 2.0 * half * direction
    x = np.concatenate([first, second]).astype(np.float32)
    boxes = _slabs(np.array([[0, 1, 2], [3, 4, 5]], dtype=np.int32), x, None, half)
    lo = boxes.face_diagonal_lower.numpy()
    hi = boxes.face_diagonal_upper.numpy()
    assert np.all(lo[0] <= hi[1]) and np.all(lo[1] <= hi[0])
    # Half again as far: the axis separates them.
    x = np.concatenate([first, first + 3.0 * half * direction]).astype(np.float32)
    boxes = _slabs(np.array([[0, 1, 2], [3, 4, 5]], dtype=np.int32), x, None, half)
    lo = boxes.face_diagonal_lower.numpy()
    hi = boxes.face_diagonal_upper.numpy()
    assert lo[1, axis] > hi[0, axis] or lo[0, axis] > hi[1, axis]


@pytest.mark.parametrize("method", ["pscc", "spatial-hash"])
@pytest.mark.parametrize("continuous", [False, True])
def test_detector_pairs_do_not_change(method: str, continuous: bool) -> None:
    mesh = folded_sheet(2000, layers=3, seed=2)
    x0 = _twist(mesh.vertices, 0.5)
    x1 = _twist(mesh.vertices_end, 0.505)
    results = {}
    for diagonals in (False, True):
        detector = CollisionDetector(mesh.faces, method=method, rest=mesh.rest, device=DEVICE,
                                     face_diagonals=diagonals)
        if continuous:
            results[diagonals] = detector.detect(x0, x1, thickness=0.001)
        else:
            results[diagonals] = detector.detect(x1, thickness=0.004)
    plain, tight = results[False], results[True]
    np.testing.assert_array_equal(plain.vertex_face, tight.vertex_face)
    np.testing.assert_array_equal(plain.edge_edge, tight.edge_edge)
    assert tight.stats["triangle_pairs"] < plain.stats["triangle_pairs"]
    assert plain.vertex_face.shape[0] + plain.edge_edge.shape[0] > 0


def test_defaults_and_bad_arguments() -> None:
    faces = np.array([[0, 1, 2], [3, 4, 5]], dtype=np.int32)
    x = np.random.default_rng(0).random((6, 3)).astype(np.float32)

    def diagonals(**options) -> bool:
        detector = CollisionDetector(faces, device=DEVICE, **options)
        detector.detect(x, thickness=0.1)
        return detector.boxes.has_face_diagonals

    assert diagonals() and not diagonals(method="spatial-hash")
    assert diagonals(method="spatial-hash", face_diagonals=True) and not diagonals(face_diagonals=False)
    with pytest.raises(InputError, match="face_diagonals"):
        CollisionDetector(faces, device=DEVICE, face_diagonals="yes")
    boxes = _slabs(faces, x, None, 0.1)
    hash_ = SpatialHash(2, DEVICE)
    with pytest.raises(InputError, match="face_diagonal_lower/face_diagonal_upper"):
        hash_.find_pairs(boxes.face_lower, boxes.face_upper, face_diagonal_lower=boxes.face_diagonal_lower)
    with pytest.raises(InputError, match="face_diagonal_upper"):
        hash_.find_pairs(boxes.face_lower, boxes.face_upper, face_diagonal_lower=boxes.face_diagonal_lower,
                         face_diagonal_upper=boxes.face_lower)


@pytest.mark.parametrize("continuous", [False, True])
@pytest.mark.parametrize("offset", [0.0, 1e4])
def test_faces_that_share_a_vertex_always_overlap(continuous: bool, offset: float) -> None:
    """The hash's face test skips the diagonal slabs for faces that share a vertex (only the certificate can
    drop those): both faces' boxes and slabs hold that vertex's own projections, computed alike, so they always
    overlap, on a jittered mesh far from the origin and over a step, at distance 0 too."""
    mesh = folded_sheet(800, layers=2, seed=3)
    rng = np.random.default_rng(1)
    x0 = (mesh.vertices + rng.normal(scale=0.02, size=mesh.vertices.shape) + offset).astype(np.float32)
    x1 = (x0 + rng.normal(scale=0.05, size=x0.shape)).astype(np.float32) if continuous else None
    faces = mesh.faces
    for half in (0.0, 0.01):
        boxes = _slabs(faces, x0, x1, half)
        lower, upper = boxes.face_lower.numpy(), boxes.face_upper.numpy()
        dl, du = boxes.face_diagonal_lower.numpy(), boxes.face_diagonal_upper.numpy()
        incident: dict[int, list[int]] = {}
        for f, tri in enumerate(faces):
            for v in tri:
                incident.setdefault(int(v), []).append(f)
        a, b = zip(*[(p, q) for fs in incident.values() for i, p in enumerate(fs) for q in fs[i + 1:]], strict=True)
        a, b = np.array(a), np.array(b)
        assert a.size > 3 * faces.shape[0]
        assert np.all((lower[a] <= upper[b]) & (lower[b] <= upper[a]))
        assert np.all((dl[a] <= du[b]) & (dl[b] <= du[a]))
