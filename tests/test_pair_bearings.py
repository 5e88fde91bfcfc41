"""The row-wise predicted-bearing kernel ``geometry.pair_bearings``, checked against
``math.atan2`` row by row, hand-computed bearings, the one-pose ``bearings_to``, invariance
under a rigid motion of the world, a reflection, and its wrapping at +-pi."""

from __future__ import annotations

import math

import numpy as np
import pytest

from bomgraph.angles import angle_residual, wrap_angle
from bomgraph.geometry import bearings_to, pair_bearings, rotation


def _rows(rng: np.random.Generator, m: int) -> tuple[np.ndarray, np.ndarray]:
    poses = np.column_stack([rng.normal(0, 5, (m, 2)), rng.uniform(-3 * math.pi, 3 * math.pi, m)])
    return poses, rng.normal(0, 5, (m, 2))


def _by_hand(pose: np.ndarray, point: np.ndarray) -> float:
    """One row with Python floats: atan2 of the offset less the heading, into (-pi, pi]."""
    b = math.atan2(point[1] - pose[1], point[0] - pose[0]) - pose[2]
    while b > math.pi:
        b -= 2 * math.pi
    while b <= -math.pi:
        b += 2 * math.pi
    return b


def test_pair_bearings_are_each_rows_bearing_from_its_own_pose() -> None:
    poses, points = _rows(np.random.default_rng(78), 200)
    got = pair_bearings(poses, points)
    assert got.shape == (200,)
    assert np.all((got > -math.pi) & (got <= math.pi))
    want = np.array([_by_hand(p, q) for p, q in zip(poses, points)])
    np.testing.assert_allclose(angle_residual(got, want), 0.0, atol=1e-12)
    # the one-pose form gives the same bits row by row
    each = np.array([bearings_to(p, q[None])[0] for p, q in zip(poses, points)])
    assert np.array_equal(got, each)


def test_pair_bearings_hand_computed() -> None:
    """A robot at (1, 1) facing +y: ahead is 0, its left +pi/2, its right -pi/2, behind +pi."""
    pose = [1.0, 1.0, math.pi / 2]
    points = np.array([[1.0, 3.0], [-2.0, 1.0], [4.0, 1.0], [1.0, 0.0], [2.0, 2.0]])
    got = pair_bearings(np.tile(pose, (5, 1)), points)
    np.testing.assert_allclose(got, [0.0, math.pi / 2, -math.pi / 2, math.pi, -math.pi / 4],
                               atol=1e-15)
    assert got[3] == math.pi         # behind is +pi, never -pi


def test_pair_bearings_unwrapped_is_atan2_less_the_heading_and_wraps_to_the_wrapped() -> None:
    poses, points = _rows(np.random.default_rng(79), 300)
    raw = pair_bearings(poses, points, wrapped=False)
    d = points - poses[:, :2]
    assert np.array_equal(raw, np.arctan2(d[:, 1], d[:, 0]) - poses[:, 2])
    assert np.abs(raw).max() > math.pi                      # some rows are outside (-pi, pi]
    assert np.array_equal(wrap_angle(raw), pair_bearings(poses, points))


def test_pair_bearings_are_unchanged_by_a_rigid_motion_and_negated_by_a_reflection() -> None:
    rng = np.random.default_rng(80)
    poses, points = _rows(rng, 100)
    before = pair_bearings(poses, points)
    for angle, shift in ((0.7, [3.0, -2.0]), (-2.9, [-40.0, 15.0]), (math.pi, [0.0, 0.0])):
        r = rotation(angle)
        moved = np.column_stack([poses[:, :2] @ r.T + shift, poses[:, 2] + angle])
        after = pair_bearings(moved, points @ r.T + shift)
        np.testing.assert_allclose(angle_residual(after, before), 0.0, atol=1e-10)
    mirrored = pair_bearings(poses * [1, -1, -1], points * [1, -1])
    np.testing.assert_allclose(angle_residual(mirrored, -before), 0.0, atol=1e-10)
    # relabelling the rows relabels the bearings
    perm = rng.permutation(100)
    assert np.array_equal(pair_bearings(poses[perm], points[perm]), before[perm])


@pytest.mark.parametrize("wrapped", [True, False])
def test_pair_bearings_broadcast_every_pose_against_every_point(wrapped: bool) -> None:
    poses, _ = _rows(np.random.default_rng(81), 7)
    points = np.random.default_rng(82).normal(0, 5, (11, 2))
    grid = pair_bearings(poses[:, None, :], points[None, :, :], wrapped=wrapped)
    assert grid.shape == (7, 11)
    for k in range(7):
        row = pair_bearings(np.tile(poses[k], (11, 1)), points, wrapped=wrapped)
        assert np.array_equal(grid[k], row)
