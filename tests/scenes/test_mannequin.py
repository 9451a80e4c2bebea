"""The skinned mannequin (``pscc.scenes.mannequin``): one smooth closed surface that bends at the joints."""

from __future__ import annotations

import math

import ipctk
import numpy as np
import pytest

from pscc.errors import InputError, PsccError
from pscc.scenes.body import humanoid
from pscc.scenes.garments import kungfu_body
from pscc.scenes.mannequin import (
    mannequin,
    skinning_weights,
    smooth_union,
    surface_field,
    surface_nets,
)
from pscc.sim.obstacles import rotation_from_axis_angle


def _check_closed_sphere(vertices: np.ndarray, faces: np.ndarray) -> None:
    directed = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    assert np.unique(directed, axis=0).shape[0] == directed.shape[0]  # consistently oriented
    undirected, counts = np.unique(np.sort(directed, axis=1), axis=0, return_counts=True)
    assert np.all(counts == 2)  # closed, every edge in exactly two faces
    assert vertices.shape[0] - undirected.shape[0] + faces.shape[0] == 2  # one sphere (genus 0)
    tri = vertices[faces].astype(np.float64)
    volume = np.einsum("ij,ij->i", tri[:, 0], np.cross(tri[:, 1], tri[:, 2])).sum() / 6.0
    assert volume > 0.0  # outward


def test_surface_nets_meshes_a_sphere_closed_and_outward() -> None:
    def sphere(points: np.ndarray) -> np.ndarray:
        return np.linalg.norm(points - [0.1, 0.0, 0.0], axis=1) - 0.3

    vertices, faces = surface_nets(sphere, np.array([-0.4, -0.5, -0.5]), np.array([0.6, 0.5, 0.5]), 0.05)
    _check_closed_sphere(vertices, faces)
    assert np.abs(sphere(vertices)).max() < 0.05  # within a cell before projection
    with pytest.raises(InputError):  # the surface reaches the box: it would be cut open
        surface_nets(sphere, np.array([-0.1, -0.5, -0.5]), np.array([0.6, 0.5, 0.5]), 0.05)


def test_smooth_union_is_below_min_by_at_most_a_quarter_blend() -> None:
    a = np.linspace(-0.1, 0.1, 201)
    b = 0.02 - a
    union = smooth_union([a, b], 0.04)
    assert np.all(union <= np.minimum(a, b) + 1e-15)
    assert np.all(union >= np.minimum(a, b) - 0.01 - 1e-15)
    far = np.abs(a - b) >= 0.04
    np.testing.assert_array_equal(union[far], np.minimum(a, b)[far])


@pytest.mark.parametrize("cell", [0.02, 0.015])
def test_mannequin_is_one_smooth_closed_surface(cell: float) -> None:
    body = kungfu_body()
    skin = mannequin(body, cell=cell)
    vertices, faces = skin.rest_vertices, skin.faces
    _check_closed_sphere(vertices, faces)
    field = surface_field(body)
    assert np.abs(field(vertices)).max() < 1e-6  # on the level set
    for part in body.parts.values():  # encloses every part's capsule or slab
        assert field(np.asarray(part.core, np.float64)).max() < -0.03
    edge = np.linalg.norm(vertices[faces[:, [1, 2, 0]]] - vertices[faces], axis=2)
    assert edge.min() > 0.1 * cell and edge.max() < 2.0 * cell
    # Smooth: neighbouring faces turn by less than 60 degrees everywhere (the tightest creases, neck and
    # armpits, have a radius of curvature of about a cell at 2 cm; capsules joined at a gap would turn 90).
    tri = vertices[faces]
    normals = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    directed = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    owner = np.tile(np.arange(faces.shape[0]), 3)
    key = np.sort(directed, axis=1)
    order = np.lexsort((key[:, 1], key[:, 0]))
    pairs = owner[order].reshape(-1, 2)
    cosine = np.einsum("ij,ij->i", normals[pairs[:, 0]], normals[pairs[:, 1]])
    assert cosine.min() > math.cos(math.radians(60.0))
    x = skin.positions(0.0).astype(np.float64)
    mesh = ipctk.CollisionMesh(x, ipctk.edges(faces), faces)
    assert not ipctk.has_intersections(mesh, x)


def test_skinning_follows_the_joints() -> None:
    turn = rotation_from_axis_angle(np.array([math.radians(60.0), 0.0, 0.0]))
    body = humanoid({"knee_l": lambda t: turn if t > 0.5 else np.eye(3)})
    skin = mannequin(body, cell=0.02)
    joints, weights = skin.joints, skin.weights
    assert np.all(weights >= 0.0)
    np.testing.assert_allclose(weights.sum(axis=1), 1.0)
    np.testing.assert_allclose(skin.positions(0.0), skin.rest_vertices, atol=1e-6)
    moved = skin.positions(1.0).astype(np.float64)
    rotation, translation = body.pose(1.0)["knee_l"]
    shin = weights[:, joints.index("knee_l")] == 1.0
    thigh = weights[:, joints.index("hip_l")] == 1.0
    assert shin.sum() > 50 and thigh.sum() > 50
    np.testing.assert_allclose(moved[shin], skin.rest_vertices[shin] @ rotation.T + translation, atol=1e-5)
    np.testing.assert_allclose(moved[thigh], skin.rest_vertices[thigh], atol=1e-5)
    # Blended vertices lie between the two rigid motions: the knee bends, it does not tear.
    blended = ~shin & ~thigh & (weights[:, joints.index("knee_l")] > 0.001)
    assert blended.sum() > 20
    assert np.linalg.norm(moved[blended] - skin.rest_vertices[blended], axis=1).max() < 0.2
    with pytest.raises(PsccError):
        skin.transform(0.0)
    assert not skin.rigid


def test_skinning_weights_are_local() -> None:
    body = humanoid()
    head_top = np.array([[0.0, 0.0, 1.80]])
    joints, weights = skinning_weights(head_top, body)
    assert weights[0, joints.index("neck")] == pytest.approx(1.0)
    with pytest.raises(InputError):
        mannequin(body, cell=0.5)
