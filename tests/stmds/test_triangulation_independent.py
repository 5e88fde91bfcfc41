"""Independent checks of the triangulation formulas (paper III-B, eq. 1-2).

The existing tests compare the analytic Jacobians with central differences; these compare the
first-order covariances with a Monte Carlo of the estimator itself at small noise, and check
that the results do not depend on the world frame (rotation, translation, reflection), on the
order of the landmarks, or on the branch of the bearings (angle wrap at +-pi).
"""

from __future__ import annotations

import numpy as np

from bomgraph.geometry import between, bearings_to, compose
from bomgraph.stmds.triangulation import (compose_odometry, gate_points, pair_squared_distances,
                                          point_covariance, range_variances, triangulate_rays)


def _scene(rng: np.random.Generator, k: int = 5):
    """Two poses 0.25 m apart and ``k`` landmarks 0.5-1.0 m from the first, alternately to
    the left and the right of the motion, spread over 55-125 degrees from it: every parallax
    is above 10 degrees and no two landmarks are close (a pair a few cm long has a squared
    distance whose second-order variance rivals the first-order one)."""
    pose_a = np.array([0.2, -0.1, 0.3])
    pose_b = np.array([0.45, -0.1, 0.5])         # moved 0.25 m along x, turned 0.2 rad
    side = np.where(np.arange(k) % 2 == 0, 1.0, -1.0)
    ang = (np.radians(np.linspace(55.0, 125.0, k)) + rng.uniform(-0.05, 0.05, k)) * side
    rad = rng.uniform(0.5, 1.0, k)
    pts = pose_a[:2] + rad[:, None] * np.column_stack([np.cos(ang), np.sin(ang)])
    return pose_a, pose_b, pts


def _noisy_points(odoms: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Points ``(n, k, 2)`` triangulated from ``n`` noisy draws: odometry ``(n, 3)``, bearings
    ``(n, k)`` (one vectorised call, one odometry row per ray)."""
    n, k = a.shape
    tri = triangulate_rays(np.repeat(odoms, k, axis=0), a.reshape(-1), b.reshape(-1))
    return tri.points_xy.reshape(n, k, 2)


N_MC = 40_000   # Monte Carlo draws: a sample variance's relative s.e. is sqrt(2 / N) = 0.7 %


def _mc_var_check(samples: np.ndarray, predicted: np.ndarray, n_se: float = 4.0,
                  slack: float = 0.01) -> None:
    """Sample variances against predictions: within ``n_se`` Monte Carlo standard errors
    (the s.e. of a sample variance of n near-Gaussian draws is ``var * sqrt(2 / (n - 1))``)
    plus ``slack`` (relative) for the higher-order terms the first-order formula leaves out
    (at these noise levels; at about three times the noise a pair 2 cm long came out 1.9x)."""
    n = samples.shape[0]
    var = samples.var(axis=0, ddof=1)
    se = predicted * np.sqrt(2.0 / (n - 1))
    assert np.all(np.abs(var - predicted) <= n_se * se + slack * predicted), (var, predicted)


def test_pair_variance_eq2_matches_a_monte_carlo_of_the_squared_distance() -> None:
    """eq. 2: the sample variance of ``|p_i - p_j|^2`` over noisy odometry and bearings is
    ``J Sigma J^T`` at small noise (sigmas a twentieth of the paper's)."""
    rng = np.random.default_rng(11)
    pose_a, pose_b, pts = _scene(rng)
    odom = between(pose_a, pose_b)
    a, b = bearings_to(pose_a, pts), bearings_to(pose_b, pts)
    sig_odo, sig_b = np.array([0.0015, 0.001, 0.0025]), 0.0025
    pe = pair_squared_distances(triangulate_rays(odom, a, b), sig_odo, sig_b)
    n = N_MC
    noisy_odom = odom + rng.normal(0.0, 1.0, (n, 3)) * sig_odo
    na = a + rng.normal(0.0, sig_b, (n, len(a)))
    nb = b + rng.normal(0.0, sig_b, (n, len(b)))
    p = _noisy_points(noisy_odom, na, nb)
    d2 = ((p[:, pe.first] - p[:, pe.second]) ** 2).sum(-1)
    # noise-free value first (exact), then the variance
    np.testing.assert_allclose(pe.squared_distance_m2,
                               ((pts[pe.first] - pts[pe.second]) ** 2).sum(1), rtol=1e-12)
    _mc_var_check(d2, pe.variance_m4)


def test_pair_variance_with_a_correlated_odometry_covariance_matches_monte_carlo() -> None:
    rng = np.random.default_rng(12)
    pose_a, pose_b, pts = _scene(rng, 4)
    odom = between(pose_a, pose_b)
    a, b = bearings_to(pose_a, pts), bearings_to(pose_b, pts)
    c = np.array([[9e-6, 3e-6, 1e-6], [3e-6, 4e-6, -2e-6], [1e-6, -2e-6, 2.5e-5]]) * 0.1
    pe = pair_squared_distances(triangulate_rays(odom, a, b), c, 0.0015)
    n = N_MC
    noisy_odom = odom + rng.multivariate_normal(np.zeros(3), c, n)
    na = a + rng.normal(0.0, 0.0015, (n, len(a)))
    nb = b + rng.normal(0.0, 0.0015, (n, len(b)))
    p = _noisy_points(noisy_odom, na, nb)
    d2 = ((p[:, pe.first] - p[:, pe.second]) ** 2).sum(-1)
    _mc_var_check(d2, pe.variance_m4)


def test_point_covariance_and_range_variances_match_monte_carlo() -> None:
    rng = np.random.default_rng(13)
    pose_a, pose_b, pts = _scene(rng, 3)
    odom = between(pose_a, pose_b)
    a, b = bearings_to(pose_a, pts), bearings_to(pose_b, pts)
    sig_odo, sig_b = np.array([0.002, 0.003, 0.004]), 0.004
    tri = triangulate_rays(odom, a, b)
    cov = point_covariance(tri, sig_odo, sig_b)
    v1, v2 = range_variances(tri, sig_odo, sig_b)
    n = N_MC
    t = triangulate_rays(np.repeat(odom + rng.normal(0, 1, (n, 3)) * sig_odo, 3, axis=0),
                         (a + rng.normal(0, sig_b, (n, 3))).reshape(-1),
                         (b + rng.normal(0, sig_b, (n, 3))).reshape(-1))
    xy = t.points_xy.reshape(n, 3, 2)
    r = np.stack([t.range_prev_m, t.range_now_m], -1).reshape(n, 3, 2)
    _mc_var_check(xy.reshape(n, -1), np.stack([cov[:, 0, 0], cov[:, 1, 1]], 1).reshape(-1))
    _mc_var_check(r.reshape(n, -1), np.column_stack([v1, v2]).reshape(-1))
    # the cross-covariance: sample correlation within 4 s.e. (1 / sqrt(n)) of the formula's
    for i in range(3):
        rho_mc = np.corrcoef(xy[:, i, 0], xy[:, i, 1])[0, 1]
        rho = cov[i, 0, 1] / np.sqrt(cov[i, 0, 0] * cov[i, 1, 1])
        assert abs(rho_mc - rho) < 4.0 / np.sqrt(n) + 0.005


def test_compose_odometry_covariance_matches_monte_carlo() -> None:
    rng = np.random.default_rng(14)
    odoms = np.column_stack([rng.uniform(0.1, 0.2, 6), rng.uniform(-0.02, 0.02, 6),
                             rng.uniform(-0.5, 0.5, 6)])
    sig = np.tile([0.004, 0.002, 0.01], (6, 1))
    u, cov = compose_odometry(odoms, sig)
    n = N_MC
    noisy = odoms[None] + rng.normal(0.0, 1.0, (n, 6, 3)) * sig
    ends = np.zeros((n, 3))
    for k in range(6):                           # pose composition, independent of the chain
        ends = compose(ends, noisy[:, k])
    ends[:, 2] = noisy[:, :, 2].sum(1)           # the unwrapped heading the function returns
    samp = np.cov(ends.T)
    np.testing.assert_allclose(ends.mean(0), u, atol=4 * np.sqrt(np.diag(cov) / n).max()
                               + 1e-4)
    _mc_var_check(ends, np.diag(cov))
    corr = samp / np.sqrt(np.outer(np.diag(samp), np.diag(samp)))
    pred = cov / np.sqrt(np.outer(np.diag(cov), np.diag(cov)))
    np.testing.assert_allclose(corr, pred, atol=4.0 / np.sqrt(n) + 0.005)


def _reflect_pose(p: np.ndarray) -> np.ndarray:
    return np.array([p[0], -p[1], -p[2]])


def test_pair_distances_do_not_depend_on_a_mirrored_world_the_order_or_the_wrap() -> None:
    rng = np.random.default_rng(15)
    pose_a, pose_b, pts = _scene(rng, 6)
    sig_odo, sig_b = np.array([0.03, 0.01, 0.05]), 0.05

    def estimate(pa, pb, q, shift=0.0):
        tri = triangulate_rays(between(pa, pb), bearings_to(pa, q) + shift,
                               bearings_to(pb, q) - shift)
        return pair_squared_distances(tri, sig_odo, sig_b)

    base = estimate(pose_a, pose_b, pts)
    # (a rotation or translation of the world is not checked here: the estimate takes only
    # the odometry and bearings, which such a move leaves equal to 2e-16 -- a check of
    # ``between`` and ``bearings_to``, not of the pair estimates, so it could not fail)
    # reflection (y -> -y): bearings, dy and dpsi change sign; distances and variances don't
    # (the odometry sigmas of dx and dy stay with their components)
    mirrored = estimate(_reflect_pose(pose_a), _reflect_pose(pose_b), pts * [1.0, -1.0])
    np.testing.assert_allclose(mirrored.squared_distance_m2, base.squared_distance_m2,
                               rtol=1e-9)
    np.testing.assert_allclose(mirrored.variance_m4, base.variance_m4, rtol=1e-8)
    # bearings on another branch (+-2 pi): the same numbers
    wrapped = estimate(pose_a, pose_b, pts, shift=2 * np.pi)
    np.testing.assert_allclose(wrapped.squared_distance_m2, base.squared_distance_m2,
                               rtol=1e-9)
    np.testing.assert_allclose(wrapped.variance_m4, base.variance_m4, rtol=1e-8)
    # relabelling the landmarks relabels the pairs
    perm = rng.permutation(len(pts))
    shuffled = estimate(pose_a, pose_b, pts[perm])
    key = {(min(perm[f], perm[s]), max(perm[f], perm[s])): (d, v) for f, s, d, v in zip(
        shuffled.first, shuffled.second, shuffled.squared_distance_m2, shuffled.variance_m4)}
    for f, s, d, v in zip(base.first, base.second, base.squared_distance_m2, base.variance_m4):
        dd, vv = key[(f, s)]
        assert abs(dd - d) <= 1e-12 * d and abs(vv - v) <= 1e-10 * v


def test_gates_refuse_a_point_behind_the_second_ray_and_compare_sigma_not_variance() -> None:
    """Hand-made rays: pose t-1 at the origin, moved 1 m ahead without turning, a landmark at
    (0.5, 1). With the second bearing reversed the rays still meet there, in front of ray 1
    (``r1 > 0``) but behind ray 2 (``r2 < 0``): refused. The relative gate compares the
    depth's std. dev. with ``max_relative_range_sigma * r1``: a std. dev. of 0.3 r1 passes at
    0.31 and is refused at 0.29."""
    odom = np.array([1.0, 0.0, 0.0])
    a = np.array([np.arctan2(1.0, 0.5)] * 2)
    b = np.array([np.arctan2(1.0, -0.5), np.arctan2(1.0, -0.5) - np.pi])
    tri = triangulate_rays(odom, a, b)
    np.testing.assert_allclose(tri.points_xy, [[0.5, 1.0], [0.5, 1.0]], atol=1e-12)
    assert tri.range_prev_m[1] > 0 > tri.range_now_m[1]
    assert gate_points(tri).tolist() == [True, False]
    front = tri.subset(np.array([0]))
    var = (0.3 * front.range_prev_m) ** 2
    assert gate_points(front, var, max_relative_range_sigma=0.31).tolist() == [True]
    assert gate_points(front, var, max_relative_range_sigma=0.29).tolist() == [False]
