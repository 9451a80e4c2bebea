"""Procedural meshes: sizes, determinism, and the shape properties the demo and benchmarks rely on."""

from __future__ import annotations

import numpy as np
import pytest

from pscc.errors import InputError
from pscc.mesh import MeshData, MeshTopology, folded_sheet, grid_sheet, twisted_sheet


def mean_edge_length(mesh: MeshData) -> float:
    topo = MeshTopology.from_faces(mesh.faces, mesh.vertex_count)
    a, b = mesh.vertices[topo.edges[:, 0]], mesh.vertices[topo.edges[:, 1]]
    return float(np.linalg.norm(a - b, axis=1).mean())


def test_grid_sheet() -> None:
    vertices, faces, rest = grid_sheet(4, 3, width=2.0, height=1.5)
    assert vertices.shape == (20, 3) and vertices.dtype == np.float32
    assert faces.shape == (24, 3) and faces.dtype == np.int32
    assert rest.shape == (20, 2) and rest.dtype == np.float32
    assert np.all(vertices[:, 2] == 0)
    np.testing.assert_allclose(vertices[:, :2], rest)
    np.testing.assert_allclose(vertices[-1], [2.0, 1.5, 0.0])
    np.testing.assert_allclose(vertices[5], [0.0, 0.5, 0.0])  # j * (nx + 1) + i
    e1 = vertices[faces[:, 1]] - vertices[faces[:, 0]]
    e2 = vertices[faces[:, 2]] - vertices[faces[:, 0]]
    area2 = np.cross(e1, e2)[:, 2]
    assert np.all(area2 > 0)  # counter-clockwise, normal +z
    np.testing.assert_allclose(area2.sum() / 2, 3.0, rtol=1e-6)
    topo = MeshTopology.from_faces(faces, 20)
    assert topo.is_manifold and topo.boundary_edges.size == 2 * (4 + 3)


def test_grid_sheet_rejects_bad_sizes() -> None:
    with pytest.raises(InputError, match="nx"):
        grid_sheet(0, 3)
    with pytest.raises(InputError, match="width"):
        grid_sheet(2, 3, width=-1.0)


@pytest.mark.parametrize("count", [50, 120, 500, 2000, 20000])
@pytest.mark.parametrize("layers", [2, 3, 5])
def test_folded_sheet_triangle_count(count: int, layers: int) -> None:
    mesh = folded_sheet(count, layers=layers)
    assert abs(mesh.face_count - count) <= 0.05 * count
    assert mesh.vertices_end is not None and mesh.vertices_end.shape == mesh.vertices.shape
    assert mesh.rest is not None and mesh.rest.shape == (mesh.vertex_count, 2)
    assert mesh.object_count == 1
    assert MeshTopology.from_faces(mesh.faces, mesh.vertex_count).is_manifold


@pytest.mark.parametrize("count", [50, 120, 500, 2000, 20000])
def test_twisted_sheet_triangle_count(count: int) -> None:
    mesh = twisted_sheet(count)
    assert abs(mesh.face_count - count) <= 0.05 * count
    assert mesh.vertices_end is not None and mesh.rest is not None
    assert twisted_sheet(count, extra_turns=None).vertices_end is None


@pytest.mark.parametrize("layers", [2, 3, 4])
def test_folded_sheet_layers_are_separated(layers: int) -> None:
    gap = 0.08
    mesh = folded_sheet(3000, layers=layers, gap=gap, seed=3)
    v = mesh.vertices
    # Away from the folds (which bulge out beyond x = 0 and x = 1) every vertex lies on a layer.
    inner = v[(v[:, 0] > 0.05) & (v[:, 0] < 0.95)]
    z = np.sort(inner[:, 2])
    jumps = np.flatnonzero(np.diff(z) > gap / 2)
    assert jumps.size == layers - 1  # exactly `layers` clusters, each more than gap / 2 apart
    clusters = np.split(z, jumps + 1)
    for k, cluster in enumerate(clusters):
        assert np.all(np.abs(cluster - k * gap) < gap / 4)
    # The folds stay within the half-cylinders' reach.
    assert v[:, 0].min() > -gap and v[:, 0].max() < 1 + gap
    assert v[:, 2].min() > -gap / 4 and v[:, 2].max() < (layers - 1) * gap + gap / 4


def test_folded_sheet_default_gap_is_about_two_edges() -> None:
    mesh = folded_sheet(5000, layers=3)
    gap = (mesh.vertices[:, 2].max() - mesh.vertices[:, 2].min()) / 2
    assert 1.6 < gap / mean_edge_length(mesh) < 2.4


def test_folded_sheet_rest_is_the_flat_sheet() -> None:
    mesh = folded_sheet(2000, layers=3)
    topo = MeshTopology.from_faces(mesh.faces, mesh.vertex_count)
    rest3 = np.pad(mesh.rest, ((0, 0), (0, 1)))
    rest_len = np.linalg.norm(rest3[topo.edges[:, 0]] - rest3[topo.edges[:, 1]], axis=1)
    now_len = np.linalg.norm(mesh.vertices[topo.edges[:, 0]] - mesh.vertices[topo.edges[:, 1]], axis=1)
    assert np.all(rest_len > 0)
    assert np.abs(now_len / rest_len - 1).max() < 0.15  # nearly isometric folding


@pytest.mark.parametrize("layers", [2, 3])
def test_folded_sheet_end_state_collides_somewhere_not_everywhere(layers: int) -> None:
    gap = 0.08
    mesh = folded_sheet(4000, layers=layers, gap=gap, seed=1)
    v, e = mesh.vertices, mesh.vertices_end
    inner = (v[:, 0] > 0.05) & (v[:, 0] < 0.95)
    layer0 = inner & (v[:, 2] < gap / 2)
    layer1 = inner & (np.abs(v[:, 2] - gap) < gap / 2)
    # Layers are pressed together everywhere...
    assert e[layer0, 2].mean() > v[layer0, 2].mean()
    assert e[layer1, 2].mean() < v[layer1, 2].mean() + 1e-3 * gap
    # ...and pass through each other only near the bump: compare the end heights of vertices at
    # matching (x, y) (nearest neighbour; the noise is far smaller than the grid spacing).
    xy0, xy1 = v[layer0, :2], v[layer1, :2]
    nearest = np.argmin(((xy0[:, None, :] - xy1[None, :, :]) ** 2).sum(axis=2), axis=1)
    total = int(layer0.sum())
    crossed = int(np.sum(e[layer0, 2] > e[layer1][nearest, 2]))
    assert total > 50
    assert 0 < crossed < 0.5 * total


def test_generators_are_deterministic() -> None:
    a, b = folded_sheet(800, seed=5), folded_sheet(800, seed=5)
    np.testing.assert_array_equal(a.vertices, b.vertices)
    np.testing.assert_array_equal(a.vertices_end, b.vertices_end)
    c = folded_sheet(800, seed=6)
    assert not np.array_equal(a.vertices, c.vertices)
    np.testing.assert_array_equal(a.faces, c.faces)
    t1, t2 = twisted_sheet(800, seed=2), twisted_sheet(800, seed=2)
    np.testing.assert_array_equal(t1.vertices, t2.vertices)


def test_twisted_sheet_shape() -> None:
    mesh = twisted_sheet(4000, turns=0.5, extra_turns=0.1)
    v, rest = mesh.vertices, mesh.rest
    # Every cross-section keeps its width: distance from the x axis equals |y_rest - 1/2|.
    radius = np.hypot(v[:, 1], v[:, 2])
    np.testing.assert_allclose(radius, np.abs(rest[:, 1] - 0.5), atol=0.01)
    np.testing.assert_allclose(v[:, 0], rest[:, 0], atol=0.01)
    # Half a turn: the far end is the near end flipped.
    far = rest[:, 0] > 3.999
    np.testing.assert_allclose(v[far, 1], -(rest[far, 1] - 0.5), atol=0.01)
    assert not np.allclose(mesh.vertices_end, v)


def test_generators_reject_bad_arguments() -> None:
    with pytest.raises(InputError, match="triangle_count"):
        folded_sheet(10)
    with pytest.raises(InputError, match="layers"):
        folded_sheet(1000, layers=1)
    with pytest.raises(InputError, match="gap"):
        folded_sheet(1000, gap=0.0)
    with pytest.raises(InputError, match="triangle_count"):
        twisted_sheet(-5)
