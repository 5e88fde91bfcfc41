"""The order-sigma^2 bias of a window bundle (``tri_bias_correction``, issue 15): the analytic
Hessians against second differences, and a Monte Carlo of a low-parallax window -- its
landmark depth is biased long and Box's correction removes that bias, while the quantity the
``scale-free`` fusion averages (1 / d) is only slightly biased (short), made worse by
correcting the points and unbiased by correcting the distances."""

from __future__ import annotations

import math

import numpy as np
import pytest

from bomgraph.errors import ConfigError
from bomgraph.geometry import bearing_hessian, bearings_to, dead_reckon
from bomgraph.stmds.bundle import (_Problem, bundle_adjust_window,
                                   bundle_pair_squared_distances)
from bomgraph.stmds.bundle_bias import residual_hessian_traces
from bomgraph.stmds.mapper import StmdsConfig


def test_bearing_hessian_matches_second_differences():
    rng = np.random.default_rng(3)
    d = rng.uniform(-3.0, 3.0, (20, 2))
    d[np.hypot(*d.T) < 0.5] += 1.0
    h = 1e-4

    def f(x):
        return np.arctan2(x[:, 1], x[:, 0])

    num = np.empty((20, 2, 2))
    for a in range(2):
        for b in range(2):
            ea, eb = np.eye(2)[a] * h, np.eye(2)[b] * h
            num[:, a, b] = (f(d + ea + eb) - f(d + ea - eb) - f(d - ea + eb)
                            + f(d - ea - eb)) / (4 * h * h)
    np.testing.assert_allclose(bearing_hessian(d), num, atol=1e-5)


def _window(w=6, seed=0):
    """A curved window of ``w`` poses and four landmarks seen from most poses; noisy
    bearings and odometry. Returns (problem, poses, points) near, not at, its solution."""
    rng = np.random.default_rng(seed)
    odoms = np.column_stack([rng.uniform(0.2, 0.3, w - 1), rng.uniform(-0.03, 0.03, w - 1),
                             rng.uniform(-0.3, 0.3, w - 1)])
    poses = dead_reckon(odoms)
    pts = np.array([[1.0, 2.5], [2.0, -1.5], [0.5, -2.0], [3.0, 1.0]])
    brg = np.stack([bearings_to(p, pts) for p in poses]) + 0.01 * rng.standard_normal((w, 4))
    brg[rng.random((w, 4)) < 0.2] = np.nan
    brg[:2] = np.stack([bearings_to(p, pts) for p in poses[:2]])
    k, lm = np.nonzero(np.isfinite(brg))
    u = odoms + 0.01 * rng.standard_normal(odoms.shape)
    prob = _Problem(u, np.full_like(u, 0.02), 0.01, k, lm, brg[k, lm], 4)
    poses = poses.copy()
    poses[1:] += 0.02 * rng.standard_normal((w - 1, 3))
    return prob, poses, pts + 0.05 * rng.standard_normal(pts.shape)


def test_residual_hessian_traces_match_second_differences():
    """tr(S H_i) of every whitened residual (odometry rows, heading rows, bearing rows, rays
    from the fixed pose included) against the numeric Hessians of ``linearise``."""
    prob, poses, points = _window()
    n_p = prob.n_pose_vars

    def res(x):
        q = poses.copy()
        q[1:] = x[:n_p].reshape(-1, 3)
        return prob.linearise(q, x[n_p:].reshape(-1, 2))[0]

    x0 = np.concatenate([poses[1:].ravel(), points.ravel()])
    n, h = len(x0), 1e-4
    eye = np.eye(n) * h
    hess = np.empty((prob.rows, n, n))
    for a in range(n):
        for b in range(a, n):
            v = (res(x0 + eye[a] + eye[b]) - res(x0 + eye[a] - eye[b])
                 - res(x0 - eye[a] + eye[b]) + res(x0 - eye[a] - eye[b])) / (4 * h * h)
            hess[:, a, b] = hess[:, b, a] = v
    rng = np.random.default_rng(1)
    m = rng.standard_normal((n, n))
    cov = m @ m.T / n
    want = np.einsum("ab,rab->r", cov, hess)
    got = residual_hessian_traces(prob, poses, points, cov)
    assert np.abs(want[:3 * len(prob.odoms)]).max() > 1.0      # the odometry terms matter
    np.testing.assert_allclose(got, want, atol=1e-4 * np.abs(want).max())


def _monte_carlo(n_pairs=200, seed=1):
    """A 10-pose straight window (1.17 m), landmark 0 at 6.1 m seen over 0.19 rad, four near
    landmarks; bearing sigma 0.015 rad, odometry noise; antithetic draws (each noise and its
    negative: the first-order errors cancel in each pair's mean, the bias stays). Per pair
    of draws: errors of landmark 0's depth from pose 0 (least squares, corrected) and of the
    1 / d of its distance to landmark 1 (least squares, points corrected, distance
    corrected)."""
    rng = np.random.default_rng(seed)
    w, sigma = 10, 0.015
    u_true = np.tile([0.13, 0.0, 0.0], (w - 1, 1))
    poses = dead_reckon(u_true)
    pts = np.array([[1.0, 6.0], [0.3, 2.0], [1.0, -2.2], [0.2, -1.5], [1.2, 2.5]])
    brg = np.stack([bearings_to(p, pts) for p in poses])
    so = np.tile([0.01, 0.005, 0.005], (w - 1, 1))
    depth, inv_d = np.hypot(*pts[0]), 1.0 / np.hypot(*(pts[0] - pts[1]))
    err = np.zeros((n_pairs, 2, 5))
    for i in range(n_pairs):
        nb, nu = rng.standard_normal(brg.shape), rng.standard_normal(so.shape)
        for sign in (1.0, -1.0):
            tri, _ = bundle_adjust_window(u_true + sign * so * nu, so, brg + sign * sigma * nb,
                                          sigma, outlier_sigma=None, grow=w, bias="estimate")
            assert len(tri) == 5 and tri.points_bias_m is not None
            raw, fixed = tri.points_xy, tri.points_xy - tri.points_bias_m
            pairs = bundle_pair_squared_distances(tri, "scale-free")
            q = np.flatnonzero((pairs.first == 0) & (pairs.second == 1))[0]
            err[i, int(sign < 0)] = [np.hypot(*raw[0]) - depth, np.hypot(*fixed[0]) - depth,
                                     1 / np.hypot(*(raw[0] - raw[1])) - inv_d,
                                     1 / np.hypot(*(fixed[0] - fixed[1])) - inv_d,
                                     pairs.squared_distance_m2[q] ** -0.5 - inv_d]
    e = err.mean(axis=1)
    return e.mean(axis=0), e.std(axis=0) / math.sqrt(n_pairs)


def test_low_parallax_depth_bias_and_its_correction():
    mean, se = _monte_carlo()
    z = mean / se
    # the least-squares depth errs long (about 7 cm at 6.1 m, 0.1 of its std. dev.)...
    assert mean[0] > 0.03 and z[0] > 5
    # ...and Box's correction removes it to within the Monte Carlo's error
    assert abs(z[1]) < 3 and abs(mean[1]) < 0.3 * mean[0]
    # 1 / d, which the scale-free fusion averages: slightly too large (d short) as it is,
    # further off with the points corrected, unbiased with the distance corrected
    assert z[2] > 3 and mean[3] > 2 * mean[2] and abs(z[4]) < 3


def test_bias_options():
    assert StmdsConfig().tri_bias_correction is None
    for name in StmdsConfig.PRESETS:
        assert StmdsConfig.preset(name).tri_bias_correction is None
    with pytest.raises(ConfigError):
        StmdsConfig(tri_window=6, tri_method="ba", tri_bias_correction="both")
    with pytest.raises(ConfigError):
        StmdsConfig(tri_window=6, tri_method="lsq", tri_bias_correction="points")
    StmdsConfig(tri_window=6, tri_method="ba", tri_bias_correction="distances")
    with pytest.raises(ConfigError):
        bundle_adjust_window(np.zeros((1, 3)), np.ones((1, 3)), np.zeros((2, 1)), 0.01,
                             bias="yes")


def test_subtract_is_estimate_minus_bias():
    prob, poses, pts = _window(w=8, seed=2)
    brg = np.full((8, 4), np.nan)
    brg[prob.k, prob.lm] = prob.theta
    args = (prob.odoms, np.full_like(prob.odoms, 0.02), brg, 0.01)
    plain, _ = bundle_adjust_window(*args)
    est, _ = bundle_adjust_window(*args, bias="estimate")
    sub, _ = bundle_adjust_window(*args, bias="subtract")
    assert plain.points_bias_m is None and not est.bias_subtracted and sub.bias_subtracted
    np.testing.assert_array_equal(plain.points_xy, est.points_xy)
    np.testing.assert_allclose(sub.points_xy, est.points_xy - est.points_bias_m, atol=1e-12)
    np.testing.assert_array_equal(sub.covariance_m2, est.covariance_m2)
    # without a domain (or with the bias subtracted) the pairs are those of the points
    a = bundle_pair_squared_distances(est)
    b = bundle_pair_squared_distances(plain, "scale-free")
    np.testing.assert_array_equal(a.squared_distance_m2, b.squared_distance_m2)
