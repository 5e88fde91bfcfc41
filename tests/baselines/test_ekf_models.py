"""The EKF baselines' models (baselines/ekf/models.py): analytic against numeric Jacobians,
exact two-ray triangulation, textbook KL values, the robot-frame ray covariance (numeric, and
blind to a rotation of map and robot together), and Bailey's KL test on the inverse-depth
conversion (0 where the conversion is linear, growing with the depth uncertainty)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from baselines.ekf.models import (bearing_and_jacobian, gaussian_kl_2d,
                                  invdepth_bearing_and_jacobian, invdepth_conversion_kl,
                                  invdepth_to_xy, motion_jacobians, ray_covariance,
                                  triangulate_two_bearings, triangulation_kl)
from bomgraph.angles import angle_residual
from bomgraph.geometry import bearings_to, compose


def numeric_jacobian(f, x: np.ndarray, h: float = 1e-6) -> np.ndarray:
    """Central differences of ``f: (d,) -> (m,)``; angle outputs are differenced wrapped."""
    cols = []
    for k in range(len(x)):
        dx = np.zeros(len(x))
        dx[k] = h
        cols.append(np.asarray(angle_residual(f(x + dx), f(x - dx))) / (2 * h)
                    if getattr(f, "angles", False) else (f(x + dx) - f(x - dx)) / (2 * h))
    return np.stack(cols, -1)


def as_angle_fn(f):
    f.angles = True
    return f


# --------------------------------------------------------------------------------------------
# Analytic against numeric Jacobians
# --------------------------------------------------------------------------------------------

def test_motion_jacobians_match_numeric() -> None:
    rng = np.random.default_rng(0)
    for _ in range(5):
        pose = np.array([*rng.normal(size=2), rng.uniform(-3, 3)])
        odom = np.array([rng.uniform(0.1, 0.3), rng.normal(0, 0.05), rng.normal(0, 0.4)])
        f_pose, g_odom = motion_jacobians(pose, odom)
        np.testing.assert_allclose(
            f_pose, numeric_jacobian(as_angle_fn(lambda p: compose(p, odom)), pose), atol=1e-8)
        np.testing.assert_allclose(
            g_odom, numeric_jacobian(as_angle_fn(lambda u: compose(pose, u)), odom), atol=1e-8)


def test_bearing_jacobian_matches_numeric_and_geometry() -> None:
    rng = np.random.default_rng(1)
    poses = np.column_stack([rng.normal(size=(6, 2)), rng.uniform(-3, 3, 6)])
    pts = rng.normal(size=(6, 2)) * 2
    b, jac = bearing_and_jacobian(poses, pts)
    for k in range(6):
        np.testing.assert_allclose(b[k], bearings_to(poses[k], pts[k])[0], atol=1e-12)
        f = as_angle_fn(lambda v: bearing_and_jacobian(v[None, :3], v[None, 3:])[0])
        np.testing.assert_allclose(jac[k], numeric_jacobian(f, np.r_[poses[k], pts[k]])[0],
                                   atol=1e-7)


def test_invdepth_model_matches_numeric_and_euclidean() -> None:
    rng = np.random.default_rng(2)
    poses = np.column_stack([rng.normal(size=(5, 2)), rng.uniform(-3, 3, 5)])
    feats = np.column_stack([rng.normal(size=(5, 2)), rng.uniform(-3, 3, 5),
                             rng.uniform(0.3, 3, 5)])
    b, jac = invdepth_bearing_and_jacobian(poses, feats)
    pts, jconv = invdepth_to_xy(feats)
    # the inverse-depth bearing is the bearing to the Euclidean point
    np.testing.assert_allclose(b, bearing_and_jacobian(poses, pts)[0], atol=1e-12)
    for k in range(5):
        f = as_angle_fn(lambda v: invdepth_bearing_and_jacobian(v[None, :3], v[None, 3:])[0])
        np.testing.assert_allclose(jac[k], numeric_jacobian(f, np.r_[poses[k], feats[k]])[0],
                                   atol=1e-7)
        g = lambda v: invdepth_to_xy(v[None])[0][0]  # noqa: E731
        np.testing.assert_allclose(jconv[k], numeric_jacobian(g, feats[k]), atol=1e-7)


def test_two_ray_triangulation_recovers_the_point_and_its_jacobian() -> None:
    rng = np.random.default_rng(3)
    pa = np.column_stack([rng.normal(size=(6, 2)), rng.uniform(-3, 3, 6)])
    pb = pa + np.column_stack([rng.normal(size=(6, 2)), rng.normal(0, 0.5, 6)])
    truth = rng.normal(size=(6, 2)) * 3
    za = np.array([bearings_to(pa[k], truth[k])[0] for k in range(6)])
    zb = np.array([bearings_to(pb[k], truth[k])[0] for k in range(6)])
    pts, jac = triangulate_two_bearings(pa, pb, za, zb)
    np.testing.assert_allclose(pts, truth, atol=1e-9)
    u = np.column_stack([pa, pb, za, zb])
    f = lambda v: triangulate_two_bearings(v[None, 0:3], v[None, 3:6], v[None, 6],  # noqa
                                           v[None, 7])[0][0]
    for k in range(6):
        np.testing.assert_allclose(jac[k], numeric_jacobian(f, u[k]), atol=1e-6)


def test_triangulation_kl_is_near_zero_for_small_noise_and_grows_with_it() -> None:
    pa, pb = np.array([[0.0, 0.0, 0.2]]), np.array([[1.0, 0.0, -0.1]])
    truth = np.array([0.4, 1.5])
    u = np.r_[pa[0], pb[0], bearings_to(pa[0], truth)[0], bearings_to(pb[0], truth)[0]][None]
    kls = []
    for sigma in (1e-4, 1e-2, 1e-1):
        cov = np.diag([0.0] * 6 + [sigma ** 2] * 2)[None]
        pts, jac, kl = triangulation_kl(u, cov)
        np.testing.assert_allclose(pts[0], truth, atol=1e-12)
        np.testing.assert_array_equal(jac, triangulate_two_bearings(pa, pb, u[:, 6], u[:, 7])[1])
        kls.append(kl[0])
    assert kls[0] < 1e-6 and kls[0] < kls[1] < kls[2] < np.inf


@pytest.mark.filterwarnings("error::RuntimeWarning")
def test_parallel_rays_give_a_non_finite_point_and_an_infinite_kl_without_warnings() -> None:
    """Two rays along one line (s = sin(a2 - a1) = 0): the point and its Jacobian are not
    finite, the Gaussianity test says inf, and numpy is not asked to warn about it."""
    pa, pb = np.array([[0.0, 0.0, 0.0]]), np.array([[1.0, 0.0, 0.0]])
    u = np.array([[0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0]])
    pts, jac = triangulate_two_bearings(pa, pb, u[:, 6], u[:, 7])
    assert not np.all(np.isfinite(pts)) and not np.all(np.isfinite(jac))
    _, _, kl = triangulation_kl(u, np.diag([1e-4] * 8)[None])
    assert kl[0] == np.inf


def test_gaussian_kl_known_values() -> None:
    m = np.zeros((1, 2))
    c = np.eye(2)[None]
    assert gaussian_kl_2d(m, c, m, c)[0] == pytest.approx(0.0, abs=1e-15)
    # KL(N(mu, I) || N(0, I)) = |mu|^2 / 2; KL(N(0, a I) || N(0, I)) = a - 1 - ln a
    assert gaussian_kl_2d(np.array([[0.3, 0.4]]), c, m, c)[0] == pytest.approx(0.125)
    assert gaussian_kl_2d(m, 2 * c, m, c)[0] == pytest.approx(2 - 1 - math.log(2))
    assert gaussian_kl_2d(m, np.zeros((1, 2, 2)), m, c)[0] == np.inf


def test_ray_covariance_matches_numeric_jacobian_and_ignores_a_common_rotation() -> None:
    rng = np.random.default_rng(21)
    pose, lm = np.array([0.4, -0.3, 0.9]), np.array([2.5, 1.1])
    values = np.r_[pose, lm][None]
    r = lm - pose[:2]
    ray = math.atan2(r[1], r[0])

    def local(v: np.ndarray) -> np.ndarray:   # the landmark seen from the robot, ray axes
        d = v[3:5] - v[0:2]
        a = ray + v[2] - pose[2]               # the mean ray, turning with the robot
        c, s = math.cos(a), math.sin(a)
        return np.array([c * d[0] + s * d[1], -s * d[0] + c * d[1]])

    j = numeric_jacobian(local, np.r_[pose, lm])
    a = rng.normal(size=(5, 5))
    cov = a @ a.T
    _, c_rr, c_pp, c_rp = ray_covariance(values, cov[None])
    expected = j @ cov @ j.T
    np.testing.assert_allclose([c_rr[0], c_pp[0], c_rp[0]],
                               [expected[0, 0], expected[1, 1], expected[0, 1]], rtol=1e-7)
    # turn map and robot together about the robot: nothing moves for the robot
    w = np.array([-r[1], r[0]])
    v = np.r_[0.0, 0.0, 1.0, w][:, None]
    rotation = 0.3 ** 2 * v @ v.T
    _, c_rr, c_pp, c_rp = ray_covariance(values, rotation[None])
    np.testing.assert_allclose([c_rr[0], c_pp[0], c_rp[0]], 0.0, atol=1e-15)


def test_inverse_depth_conversion_kl_known_cases() -> None:
    feat = np.array([[0.5, -0.2, 0.7, 0.5]])
    # the conversion is linear in the anchor: unscented and linearised Gaussians agree
    anchor_only = np.diag([0.3, 0.2, 0.0, 0.0])[None]
    assert invdepth_conversion_kl(feat, anchor_only)[0] == pytest.approx(0.0, abs=1e-10)
    # more depth uncertainty, less Gaussian; a sigma point at rho <= 0 reaches infinity
    kls = [invdepth_conversion_kl(feat, np.diag([0.0, 0.0, 1e-4, s ** 2])[None])[0]
           for s in (0.005, 0.02, 0.08)]
    assert kls[0] < 1e-4 and kls[0] < kls[1] < kls[2] < np.inf
    assert invdepth_conversion_kl(feat, np.diag([0.0, 0.0, 1e-4, 0.3 ** 2])[None])[0] == np.inf


