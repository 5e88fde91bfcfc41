"""The linearised-bearing kernel ``geometry.bearing_offsets``: its bearings are the bits of
``pair_bearings(..., wrapped=False)``, its offset and squared range are those of the pose to
the point, and the Jacobians its docstring builds from them match central differences of
``pair_bearings`` with respect to the point and to the pose."""

from __future__ import annotations

import math

import numpy as np

from bomgraph.angles import angle_residual
from bomgraph.geometry import bearing_offsets, pair_bearings


def _rows(rng: np.random.Generator, m: int) -> tuple[np.ndarray, np.ndarray]:
    poses = np.column_stack([rng.normal(0, 5, (m, 2)), rng.uniform(-3 * math.pi, 3 * math.pi, m)])
    return poses, rng.normal(0, 5, (m, 2))


def _jacobians(d: np.ndarray, r2: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The docstring's blocks: ``[-dy, dx] / r2`` for the point, ``[dy, -dx] / r2, -1`` for
    the pose."""
    point = np.stack([-d[..., 1] / r2, d[..., 0] / r2], -1)
    return np.concatenate([-point, -np.ones(r2.shape + (1,))], -1), point


def test_bearing_rows_are_pair_bearings_with_the_offset_and_squared_range() -> None:
    poses, points = _rows(np.random.default_rng(84), 300)
    bearing, d, r2 = bearing_offsets(poses, points)
    assert bearing.shape == r2.shape == (300,) and d.shape == (300, 2)
    assert np.array_equal(bearing, pair_bearings(poses, points, wrapped=False))
    assert np.abs(bearing).max() > math.pi                  # not wrapped
    assert np.array_equal(angle_residual(bearing, 0.0), pair_bearings(poses, points))
    assert np.array_equal(d, points - poses[:, :2])
    assert np.array_equal(r2, d[:, 0] * d[:, 0] + d[:, 1] * d[:, 1])


def test_bearing_rows_hand_computed() -> None:
    """A robot at (1, 1) facing +y sees (1, 3) straight ahead, 2 m away: moving the point to
    the robot's right (+x) turns the bearing clockwise by 1/2 rad per metre."""
    bearing, d, r2 = bearing_offsets(np.array([[1.0, 1.0, math.pi / 2]]), np.array([[1.0, 3.0]]))
    assert bearing[0] == 0.0 and d.tolist() == [[0.0, 2.0]] and r2[0] == 4.0
    pose_jac, point_jac = _jacobians(d, r2)
    assert point_jac.tolist() == [[-0.5, 0.0]]
    assert pose_jac.tolist() == [[0.5, -0.0, -1.0]]


def test_bearing_rows_jacobians_match_central_differences() -> None:
    poses, points = _rows(np.random.default_rng(85), 50)
    points[:, 0] += 2.0 * np.sign(points[:, 0] - poses[:, 0])        # each >= 2 m off its pose
    _, d, r2 = bearing_offsets(poses, points)
    pose_jac, point_jac = _jacobians(d, r2)
    h = 1e-6
    for j in range(2):
        e = np.zeros(2)
        e[j] = h
        num = angle_residual(pair_bearings(poses, points + e),
                             pair_bearings(poses, points - e)) / (2 * h)
        np.testing.assert_allclose(point_jac[:, j], num, rtol=1e-6, atol=1e-8)
    for j in range(3):
        e = np.zeros(3)
        e[j] = h
        num = angle_residual(pair_bearings(poses + e, points),
                             pair_bearings(poses - e, points)) / (2 * h)
        np.testing.assert_allclose(pose_jac[:, j], num, rtol=1e-6, atol=1e-8)


def test_bearing_rows_broadcast_every_pose_against_every_point() -> None:
    poses, _ = _rows(np.random.default_rng(86), 7)
    points = np.random.default_rng(87).normal(0, 5, (11, 2))
    bearing, d, r2 = bearing_offsets(poses[:, None, :], points[None, :, :])
    assert bearing.shape == r2.shape == (7, 11) and d.shape == (7, 11, 2)
    for k in range(7):
        row = bearing_offsets(np.tile(poses[k], (11, 1)), points)
        for got, want in zip((bearing[k], d[k], r2[k]), row):
            assert np.array_equal(got, want)


def test_bearing_rows_take_columns_of_a_wider_array() -> None:
    """Poses and points given as column views of one state array ``[x, y, psi, lx, ly]`` (as
    the EKF's rows are): the same bits as contiguous copies."""
    v = np.random.default_rng(88).normal(0, 5, (40, 5))
    got = bearing_offsets(v[:, 0:3], v[:, 3:5])
    want = bearing_offsets(v[:, 0:3].copy(), v[:, 3:5].copy())
    for a, b in zip(got, want):
        assert np.array_equal(a, b)
