"""Rigid impact zones move affinely, follow their kinematic group and refuse two motions; keyframes."""

from __future__ import annotations

import numpy as np
import pytest

from pscc.sim.impact_response import ImpactZoneFailure, ImpactZones
from pscc.sim.obstacles import KeyframedMotion, rotation_from_axis_angle, step_map


def test_free_zone_moves_affinely_and_keeps_momentum() -> None:
    rng = np.random.default_rng(0)
    x0 = rng.normal(size=(6, 3))
    x1 = x0 + 0.01 * rng.normal(size=(6, 3))
    masses = rng.uniform(0.5, 2.0, size=6)
    zones = ImpactZones(masses, np.full(6, -1))
    zones.merge(np.array([[0, 1, 2, 3], [2, 3, 4, 5]]))
    assert [z.tolist() for z in zones.zones()] == [[0, 1, 2, 3, 4, 5]]
    dt = 0.01
    result = zones.apply(x0, x1, dt, {}, scale=1.0).astype(np.float64)
    # Linear momentum is preserved and the map x0 -> result is affine: result = A x0 + b with A - I skew.
    np.testing.assert_allclose((masses[:, None] * (result - x0)).sum(0), (masses[:, None] * (x1 - x0)).sum(0),
                               atol=1e-5)
    design = np.concatenate([x0, np.ones((6, 1))], axis=1)
    solution, residual, *_ = np.linalg.lstsq(design, result, rcond=None)
    np.testing.assert_allclose(design @ solution, result, atol=1e-5)
    skew = solution[:3].T - np.eye(3)
    np.testing.assert_allclose(skew, -skew.T, atol=1e-5)


def test_zone_follows_its_kinematic_group_and_refuses_two_motions() -> None:
    x0 = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [2, 2, 2]], dtype=np.float64)
    x1 = x0 + 0.1
    masses = np.ones(5)
    groups = np.array([-1, -1, 0, 1, -1])
    motion = KeyframedMotion(times=np.array([0.0, 1.0]), translations=np.zeros((2, 3)),
                             rotations=np.array([[0, 0, 0], [0, 0, 0.5]]))
    rotate = step_map(motion(0.0), motion(0.1))
    static = (np.eye(3), np.zeros(3))
    zones = ImpactZones(masses, groups)
    zones.merge(np.array([[0, 1, 2, 2]]))
    result = zones.apply(x0, x1, 0.01, {0: rotate, 1: static}, scale=1.0)
    expected = x0[:2] @ rotate[0].T + rotate[1]
    np.testing.assert_allclose(result[:2], expected, atol=1e-6)
    np.testing.assert_allclose(result[2:], x1[2:], atol=1e-6)  # kinematic and outside vertices unchanged
    zones.merge(np.array([[1, 3, 3, 3]]))
    with pytest.raises(ImpactZoneFailure):
        zones.apply(x0, x1, 0.01, {0: rotate, 1: static}, scale=1.0)


def test_keyframed_motion_interpolates() -> None:
    motion = KeyframedMotion(times=np.array([0.0, 2.0]), translations=np.array([[0, 0, 0], [2, 0, 0]]),
                             rotations=np.array([[0, 0, 0], [0, 0, np.pi / 2]]))
    rotation, translation = motion(1.0)
    np.testing.assert_allclose(translation, [1, 0, 0])
    np.testing.assert_allclose(rotation, rotation_from_axis_angle(np.array([0, 0, np.pi / 4])), atol=1e-12)
    np.testing.assert_allclose(motion(5.0)[1], [2, 0, 0])
