"""Panels turned so that their mesh lines run along the axes before the BVH's cuts (panel_alignment)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial import Delaunay

from pscc.collision.panel_alignment import MIN_COHERENCE, aligned_face_corners
from pscc.mesh import grid_sheet
from tests.collision.test_bvh import full_check


def _turned(points: np.ndarray, degrees: float) -> np.ndarray:
    angle = np.radians(degrees)
    rotation = np.array([[np.cos(angle), -np.sin(angle)], [np.sin(angle), np.cos(angle)]])
    return points @ rotation.T + np.array([3.0, -2.0])


def _edge_angles(corners: np.ndarray) -> np.ndarray:
    """Angles of every face edge in the corners' first two coordinates, modulo 90 degrees, in (-45, 45]."""
    edges = corners[:, [1, 2, 0]] - corners
    angles = np.degrees(np.arctan2(edges[..., 1], edges[..., 0])).reshape(-1)
    return (angles + 45.0) % 90.0 - 45.0


@pytest.mark.parametrize("degrees", [10.0, 30.0, 45.0, -20.0])
def test_a_turned_grid_is_turned_back_onto_the_axes(degrees: float) -> None:
    _, faces, rest = grid_sheet(12, 7)
    turned = _turned(rest.astype(np.float64), degrees)
    corners = aligned_face_corners(faces.astype(np.int64), turned, np.zeros(faces.shape[0], np.int64))
    axis_edges = np.abs(_edge_angles(corners))
    # Cell sides on the axes (diagonals at about +-30 degrees for these 1/12 x 1/7 cells).
    assert np.sum(axis_edges < 1e-6) >= 2 * faces.shape[0]
    # Distances within the panel, and its centroid, are kept.
    np.testing.assert_allclose(np.linalg.norm(corners[:, 1] - corners[:, 0], axis=1),
                               np.linalg.norm(turned[faces[:, 1]] - turned[faces[:, 0]], axis=1), atol=1e-12)
    np.testing.assert_allclose(corners.mean(axis=(0, 1)), turned[faces].mean(axis=(0, 1)), atol=1e-12)


@pytest.mark.parametrize("degrees", [10.0, 30.0, 45.0])
def test_the_bvh_of_a_turned_grid_is_as_testable_as_the_axis_aligned_one(degrees: float) -> None:
    _, faces, rest = grid_sheet(16, 16)
    straight = full_check(faces, rest)
    turned = full_check(faces, _turned(rest.astype(np.float64), degrees).astype(np.float32))
    assert np.all(straight.testable) and np.all(turned.testable)
    # The same cuts: nodes of the same sizes at every depth.
    sizes = [sorted(zip(bvh.depth.tolist(), (bvh.face_end - bvh.face_begin).tolist(), strict=True))
             for bvh in (straight, turned)]
    assert sizes[0] == sizes[1]


def test_a_grid_on_the_axes_and_an_irregular_mesh_keep_their_coordinates_bit_for_bit() -> None:
    _, faces, rest = grid_sheet(9, 5)
    rest = rest.astype(np.float64)
    corners = aligned_face_corners(faces.astype(np.int64), rest, np.zeros(faces.shape[0], np.int64))
    np.testing.assert_array_equal(corners, rest[faces])
    points = np.random.default_rng(7).random((400, 2))
    irregular = Delaunay(points).simplices.astype(np.int64)
    turned = _turned(points, 25.0)
    edges = turned[irregular[:, [1, 2, 0]]] - turned[irregular]
    length = np.linalg.norm(edges, axis=2).reshape(-1)
    degrees = np.degrees(np.arctan2(edges[..., 1], edges[..., 0])).reshape(-1) % 90.0
    best = max(length[np.abs((degrees - d + 45.0) % 90.0 - 45.0) <= 2.5].sum() for d in range(90))
    assert best / length.sum() < MIN_COHERENCE  # no dominant direction
    corners = aligned_face_corners(irregular, turned, np.zeros(irregular.shape[0], np.int64))
    np.testing.assert_array_equal(corners, turned[irregular])


def test_each_panel_turns_on_its_own_and_three_d_panels_lie_in_the_xy_plane() -> None:
    _, faces, rest = grid_sheet(10, 6)
    faces = faces.astype(np.int64)
    n = rest.shape[0]
    flat = _turned(rest.astype(np.float64), 30.0)
    # A second copy of the sheet in a tilted plane in 3-D, its lines turned 20 degrees in that plane.
    tilt = np.radians(40.0)
    in_plane = _turned(rest.astype(np.float64), 20.0)
    tilted = np.stack([in_plane[:, 0], in_plane[:, 1] * np.cos(tilt), in_plane[:, 1] * np.sin(tilt)], axis=1)
    for material, second in ((np.concatenate([flat, flat + 5.0]), flat + 5.0),
                             (np.concatenate([np.c_[flat, np.zeros(n)], tilted]), tilted)):
        both = np.concatenate([faces, faces + n])
        panels = np.repeat([0, 1], faces.shape[0])
        corners = aligned_face_corners(both, material, panels)
        for panel in (0, 1):
            mine = corners[panels == panel]
            assert np.sum(np.abs(_edge_angles(mine)) < 1e-6) >= 2 * faces.shape[0]
            if material.shape[1] == 3:
                assert np.ptp(mine[..., 2]) < 1e-9  # the panel's plane is the x-y plane
        np.testing.assert_allclose(corners[panels == 1].mean(axis=(0, 1)), second[faces].mean(axis=(0, 1)),
                                   atol=1e-12)
