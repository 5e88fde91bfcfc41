"""Tests of pose resection (baselines/resection.py): exact recovery without noise, the prior,
the analytic Jacobian, and a whole trajectory chained by the odometry where it cannot resect."""

from __future__ import annotations

import math

import numpy as np

from baselines.resection import resect_pose, resect_trajectory, resection_jacobian
from bomgraph.geometry import bearings_to, between, compose


def test_resection_is_exact_without_noise_from_a_bad_prior() -> None:
    rng = np.random.default_rng(0)
    lm = rng.uniform(-1, 1, (6, 2))
    true = np.array([0.1, -0.2, 2.5])
    b = bearings_to(true, lm)
    # the prior is far off (heading by 2.9 rad) and nearly uninformative
    prior = np.array([0.6, 0.4, 2.5 - 2.9])
    pose, cost = resect_pose(lm, b, math.radians(3), prior, np.array([1e4, 1e4, 1e4]))
    np.testing.assert_allclose(pose, true, atol=1e-9)
    assert cost < 1e-6


def test_resection_with_two_bearings_leans_on_the_prior() -> None:
    lm = np.array([[1.0, 0.0], [0.0, 1.0]])
    true = np.array([0.0, 0.0, 0.3])
    b = bearings_to(true, lm)
    pose, _ = resect_pose(lm, b, 0.01, true, np.array([0.01, 0.01, 0.01]))
    np.testing.assert_allclose(pose, true, atol=1e-9)
    pose, cost = resect_pose(np.zeros((0, 2)), np.zeros(0), 0.01, true, np.ones(3))
    np.testing.assert_allclose(pose, true, atol=1e-12)
    assert cost < 1e-20
    # one bearing and no prior: undetermined
    pose, cost = resect_pose(lm[:1], b[:1], 0.01)
    assert np.all(np.isnan(pose)) and math.isnan(cost)


def test_resection_jacobian_matches_numeric() -> None:
    rng = np.random.default_rng(1)
    lm = rng.uniform(-1, 1, (5, 2))
    pose = np.array([0.05, 0.1, -0.7])
    h = 1e-7
    num = np.column_stack([(bearings_to(pose + h * e, lm) - bearings_to(pose - h * e, lm))
                           / (2 * h) for e in np.eye(3)])
    np.testing.assert_allclose(resection_jacobian(pose, lm), num, atol=1e-6)


def test_trajectory_is_exact_without_noise_and_chains_the_unseen_poses() -> None:
    rng = np.random.default_rng(3)
    map_ids = np.arange(10, 18)
    ang = np.arange(8) * math.pi / 4 + rng.uniform(-0.2, 0.2, 8)
    map_xy = 3.0 * np.column_stack([np.cos(ang), np.sin(ang)])
    odoms = np.zeros((12, 3))
    odoms[1:] = np.column_stack([rng.uniform(0.1, 0.2, 11), np.zeros(11),
                                 rng.uniform(-0.3, 0.3, 11)])
    truth = [np.array([0.2, -0.1, 0.4])]
    for u in odoms[1:]:
        truth.append(compose(truth[-1], u))
    truth = np.array(truth)
    owner, ids, brg = [], [], []
    for t, pose in enumerate(truth):
        seen = map_ids[:2] if t in (0, 1, 6) else map_ids     # too few to resect alone
        owner += [t] * len(seen)
        ids += seen.tolist()
        brg += bearings_to(pose, map_xy[seen - 10]).tolist()
    poses = resect_trajectory(np.array(owner), np.array(ids), np.array(brg), math.radians(3),
                              map_ids, map_xy, odoms, np.full((12, 3), 0.01))
    np.testing.assert_allclose(poses, truth, atol=1e-8)
    # the unseen start is chained backwards: its odometry to the next pose is exact
    np.testing.assert_allclose(between(poses[0], poses[1]), odoms[1], atol=1e-12)
