"""Independent checks of the localisation distances (paper III-E, bomgraph/stmds/localisation).

``RobotPoses.robot_pairs`` (dead-reckoned robot-robot distances and their first-order
variances) and ``RobotPoses.all_pose_ranges`` (robot-landmark distances from all held rays,
``sigma^2 u^T A_w^-1 u``) had no test of their own. Here the distances are checked exact
without noise, the robot-robot variance against central differences over the odometry and a
Monte Carlo, and the robot-landmark variance against a Monte Carlo of the bearings.
"""

from __future__ import annotations

import math

import numpy as np

from bomgraph.geometry import bearings_to, dead_reckon
from bomgraph.stmds.localisation import RobotPoses


def _held(odoms: np.ndarray, sigmas: np.ndarray, bearings=None, idx=None) -> RobotPoses:
    """A window holding ``len(odoms) + 1`` poses (the first without odometry)."""
    win = RobotPoses(len(odoms) + 1, "scale-free")
    m = len(odoms) + 1
    for k in range(m):
        b = np.zeros(0) if bearings is None else bearings[k]
        i = np.zeros(0, np.int64) if idx is None else idx[k]
        win.push(k, None if k == 0 else odoms[k - 1], None if k == 0 else sigmas[k - 1], i, b)
    return win


def _odoms(rng: np.random.Generator, m: int) -> np.ndarray:
    return np.column_stack([rng.uniform(0.1, 0.2, m), rng.uniform(-0.02, 0.02, m),
                            rng.uniform(-0.5, 0.5, m)])


def test_robot_pair_distances_are_exact_and_their_variance_is_j_sigma_jt() -> None:
    rng = np.random.default_rng(71)
    odoms = _odoms(rng, 5)
    sig = np.tile([0.03, 0.01, 0.05], (5, 1)) * rng.uniform(0.5, 1.5, (5, 3))
    a, b, d, v = _held(odoms, sig).robot_pairs()
    poses = dead_reckon(odoms)
    np.testing.assert_allclose(d, np.linalg.norm(poses[b, :2] - poses[a, :2], axis=1),
                               rtol=1e-12)

    def dists(z: np.ndarray) -> np.ndarray:
        p = dead_reckon(z.reshape(-1, 3))
        return np.linalg.norm(p[b, :2] - p[a, :2], axis=1)

    eps = 1e-6
    z0 = odoms.reshape(-1)
    jac = np.stack([(dists(z0 + e) - dists(z0 - e)) / (2 * eps)
                    for e in np.eye(z0.size) * eps], -1)
    np.testing.assert_allclose(v, (jac ** 2) @ (sig.reshape(-1) ** 2), rtol=1e-6)


def test_robot_pair_variance_matches_a_monte_carlo() -> None:
    rng = np.random.default_rng(72)
    odoms = _odoms(rng, 5)
    odoms[:, 2] = [0.9, 0.8, -0.2, 1.0, 0.7]          # a curved path: the turns move distances
    sig = np.tile([0.001, 0.0005, 0.01], (5, 1))      # and their terms dominate
    a, b, d, v = _held(odoms, sig).robot_pairs()
    n = 40_000
    noisy = odoms[None] + rng.normal(0, 1, (n, 5, 3)) * sig
    xy = np.zeros((n, 6, 2))
    psi = np.zeros(n)
    for k in range(5):                            # dead reckoning, vectorised over draws
        c, s = np.cos(psi), np.sin(psi)
        xy[:, k + 1, 0] = xy[:, k, 0] + c * noisy[:, k, 0] - s * noisy[:, k, 1]
        xy[:, k + 1, 1] = xy[:, k, 1] + s * noisy[:, k, 0] + c * noisy[:, k, 1]
        psi = psi + noisy[:, k, 2]
    dd = np.linalg.norm(xy[:, b] - xy[:, a], axis=2)
    var = dd.var(axis=0, ddof=1)
    se = v * math.sqrt(2.0 / (n - 1))             # 0.7 % of each variance
    assert np.all(np.abs(var - v) <= 4 * se + 0.01 * v), np.c_[var, v]


def _landmark_scene(rng: np.random.Generator):
    odoms = _odoms(rng, 5)
    poses = dead_reckon(odoms)
    lms = poses[2, :2] + rng.uniform(0.5, 1.0, (4, 1)) * np.column_stack(
        [np.cos(t := poses[2, 2] + np.array([1.2, -1.3, 1.9, -2.0])), np.sin(t)])
    brg = [bearings_to(p, lms) for p in poses]
    idx = [np.arange(4, dtype=np.int64) for _ in poses]
    return odoms, poses, lms, brg, idx


def test_all_pose_ranges_are_exact_without_noise() -> None:
    odoms, poses, lms, brg, idx = _landmark_scene(np.random.default_rng(73))
    win = _held(odoms, np.zeros((5, 3)), brg, idx)
    k, lm, d, _ = win.all_pose_ranges(0.01, math.radians(2.0))
    assert len(k) == 24
    np.testing.assert_allclose(d, np.linalg.norm(poses[k, :2] - lms[lm], axis=1), atol=1e-9)


def test_all_pose_range_variance_matches_a_monte_carlo_of_the_bearings() -> None:
    """Odometry exact (zero sigmas: the dead-reckoning term is zero), bearings noisy: the
    sample variance of each robot-landmark distance is ``sigma^2 u^T A_w^-1 u``."""
    rng = np.random.default_rng(74)
    odoms, poses, lms, brg, idx = _landmark_scene(rng)
    sigma = 0.002
    win = _held(odoms, np.zeros((5, 3)), brg, idx)
    k0, lm0, _, v0 = win.all_pose_ranges(sigma, math.radians(2.0))
    n = 3000
    out = np.empty((n, len(k0)))
    for s in range(n):
        noisy = [b + rng.normal(0, sigma, b.size) for b in brg]
        k, lm, d, _ = _held(odoms, np.zeros((5, 3)), noisy, idx).all_pose_ranges(
            sigma, math.radians(2.0))
        assert np.array_equal(k, k0) and np.array_equal(lm, lm0)
        out[s] = d
    var = out.var(axis=0, ddof=1)
    se = v0 * math.sqrt(2.0 / (n - 1))            # 2.6 % of each variance
    assert np.all(np.abs(var - v0) <= 4 * se + 0.02 * v0), np.c_[var, v0]
