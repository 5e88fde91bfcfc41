"""Independent checks of the EKF models' second-order variance and KL (baselines/ekf/models.py).

``second_order_variance`` was checked only against the fused kernel of rows.py (the same
formula in another order). Here the variance of the second-order Taylor term of a bearing,
``1/2 dx^T H dx`` with ``dx ~ N(0, C)``, is ``1/2 tr((H C)^2)`` with ``H`` a central-difference
Hessian: of ``atan2`` in the robot frame ``q = R(psi)^T (l - p)`` linearised (the derivation
the docstring gives), of the bearing in the state where the heading carries no variance, and
of the inverse-depth bearing in ``rho`` alone. ``gaussian_kl_2d`` is checked against the
general-dimension formula with numpy's linear algebra.
"""

from __future__ import annotations

import numpy as np
import pytest

from baselines.ekf.models import gaussian_kl_2d, second_order_variance


def _hessian(f, x: np.ndarray, eps: float = 1e-4) -> np.ndarray:
    n = len(x)
    h = np.zeros((n, n))
    e = np.eye(n) * eps
    for i in range(n):
        for j in range(n):
            h[i, j] = (f(x + e[i] + e[j]) - f(x + e[i] - e[j]) - f(x - e[i] + e[j])
                       + f(x - e[i] - e[j])) / (4 * eps * eps)
    return h


def _jacobian(f, x: np.ndarray, eps: float = 1e-6) -> np.ndarray:
    return np.stack([(f(x + d) - f(x - d)) / (2 * eps) for d in np.eye(len(x)) * eps], -1)


def _bearing(v: np.ndarray) -> float:
    return float(np.arctan2(v[4] - v[1], v[3] - v[0]) - v[2])


def _robot_frame(v: np.ndarray) -> np.ndarray:
    c, s = np.cos(v[2]), np.sin(v[2])
    r = v[3:5] - v[0:2]
    return np.array([c * r[0] + s * r[1], -s * r[0] + c * r[1]])


def _cases(seed: int, n: int = 8):
    rng = np.random.default_rng(seed)
    for _ in range(n):
        v = np.array([*rng.uniform(-1, 1, 2), rng.uniform(-3, 3), *rng.uniform(-1, 1, 2)])
        v[3:5] += 0.6 * np.sign(v[3:5] - v[0:2])          # the landmark 0.6 m or more away
        a = rng.normal(size=(5, 5))
        yield v, a @ a.T * 1e-3


def test_euclidean_second_order_variance_is_that_of_atan2_in_the_linearised_robot_frame() -> None:
    sigma = 0.02
    for v, c in _cases(61):
        extra = second_order_variance(v[None], c[None], sigma)[0][0] - sigma ** 2
        jq = _jacobian(_robot_frame, v)
        cq = jq @ c @ jq.T
        hq = _hessian(lambda q: float(np.arctan2(q[1], q[0])), _robot_frame(v))
        assert extra == pytest.approx(0.5 * np.trace(hq @ cq @ hq @ cq), rel=1e-6)


def test_without_heading_variance_it_is_the_second_order_term_of_the_bearing() -> None:
    sigma = 0.02
    for v, c in _cases(62):
        c[2, :] = c[:, 2] = 0.0
        extra = second_order_variance(v[None], c[None], sigma)[0][0] - sigma ** 2
        h = _hessian(_bearing, v)
        assert extra == pytest.approx(0.5 * np.trace(h @ c @ h @ c), rel=1e-6)


def test_second_order_variance_ignores_a_rotation_of_map_and_robot_together() -> None:
    """The documented choice of :func:`ray_covariance`: a heading error shared by the map (a
    rotation of map and robot together leaves every bearing unchanged) adds nothing, so only
    the radial variance is left and the second-order term vanishes.

    The other side of that choice (audit h20, ``docs/measurements.md``): a heading variance
    *independent* of the map still adds ``C_rr var_psi / |r|^2`` (1.8e-4 rad^2 for the case
    below with the heading's correlations removed), though the bearing ``atan2(l - p) - psi`` is
    linear in ``psi``; on the paper's runs most heading variance is shared with the map."""
    dist, var_psi, var_radial = 1.5, 0.01, 0.04
    v = np.array([0.0, 0.0, 0.0, dist, 0.0])
    j = np.array([0.0, 0.0, 1.0, 0.0, dist])          # d[x, y, psi, lx, ly] / d(rotation)
    shared = var_psi * np.outer(j, j)
    shared[3, 3] += var_radial
    extra = second_order_variance(v[None], shared[None], 0.01)[0][0] - 0.01 ** 2
    assert abs(extra) < 1e-15
    independent = np.diag([0.0, 0.0, var_psi, var_radial, 0.0])
    extra = second_order_variance(v[None], independent[None], 0.01)[0][0] - 0.01 ** 2
    assert extra == pytest.approx(var_radial * var_psi / dist ** 2, rel=1e-12)


def test_invdepth_second_order_variance_is_the_rho_rho_term() -> None:
    rng = np.random.default_rng(63)
    sigma = 0.02

    def bearing(x: np.ndarray) -> float:                   # [x, y, psi, x0, y0, theta, rho]
        v = x[6] * (x[3:5] - x[0:2]) + np.array([np.cos(x[5]), np.sin(x[5])])
        return float(np.arctan2(v[1], v[0]) - x[2])

    for _ in range(8):
        x = np.array([*rng.uniform(-1, 1, 2), rng.uniform(-3, 3), *rng.uniform(-1, 1, 2),
                      rng.uniform(-3, 3), rng.uniform(0.3, 2.0)])
        c = np.zeros((7, 7))
        c[6, 6] = rng.uniform(0.01, 0.3) ** 2
        extra = second_order_variance(x[None], c[None], sigma)[0][0] - sigma ** 2
        h = _hessian(bearing, x)
        assert extra == pytest.approx(0.5 * np.trace(h @ c @ h @ c), rel=1e-5)
        assert extra > 0


def test_gaussian_kl_2d_is_the_general_formula() -> None:
    rng = np.random.default_rng(64)
    m = 30
    a, b = rng.normal(size=(m, 2, 2)), rng.normal(size=(m, 2, 2))
    cp, cq = a @ a.transpose(0, 2, 1) + 0.1 * np.eye(2), b @ b.transpose(0, 2, 1) + 0.1 * np.eye(2)
    mp, mq = rng.normal(size=(m, 2)), rng.normal(size=(m, 2))
    got = gaussian_kl_2d(mp, cp, mq, cq)
    for k in range(m):
        qi = np.linalg.inv(cq[k])
        d = mq[k] - mp[k]
        want = 0.5 * (np.trace(qi @ cp[k]) + d @ qi @ d - 2
                      + np.log(np.linalg.det(cq[k]) / np.linalg.det(cp[k])))
        assert got[k] == pytest.approx(want, rel=1e-10, abs=1e-12)


def test_sigma_points_carry_the_mean_and_covariance_exactly() -> None:
    """The 2d symmetric, equally weighted sigma points of Bailey's test reproduce the
    Gaussian's mean and covariance (so a linear map gives KL 0)."""
    from baselines.ekf.models import _sample_moments, _sigma_points

    rng = np.random.default_rng(65)
    for d in (2, 4, 8):
        a = rng.normal(size=(5, d, d))
        cov = a @ a.transpose(0, 2, 1)
        mean = rng.normal(size=(5, d))
        pts = _sigma_points(mean, cov)
        assert pts.shape == (5, 2 * d, d)
        np.testing.assert_allclose(pts.mean(1), mean, atol=1e-12)
        dev = pts - mean[:, None]
        np.testing.assert_allclose(np.einsum("msi,msj->mij", dev, dev) / (2 * d), cov,
                                   atol=1e-10)
        if d == 2:
            m2, c2 = _sample_moments(pts)
            np.testing.assert_allclose(m2, mean, atol=1e-12)
            np.testing.assert_allclose(c2, cov, atol=1e-10)


def test_ekf_two_ray_triangulation_is_the_stmds_triangulation() -> None:
    """Two implementations of eq. 1 written apart (world frame here, the first pose's frame
    in bomgraph.stmds) give the same point."""
    from baselines.ekf.models import triangulate_two_bearings
    from bomgraph.geometry import between, bearings_to, to_world
    from bomgraph.stmds.triangulation import triangulate_rays

    rng = np.random.default_rng(66)
    pa = np.column_stack([rng.uniform(-1, 1, (20, 2)), rng.uniform(-3, 3, 20)])
    pb = pa + np.column_stack([rng.uniform(-0.3, 0.3, (20, 2)), rng.uniform(-0.5, 0.5, 20)])
    pts = rng.uniform(-2, 2, (20, 2))
    za = np.array([bearings_to(p, q[None])[0] for p, q in zip(pa, pts)])
    zb = np.array([bearings_to(p, q[None])[0] for p, q in zip(pb, pts)])
    zb = zb + rng.normal(0, 0.02, 20)
    ekf, _ = triangulate_two_bearings(pa, pb, za, zb)
    for k in range(20):
        local = triangulate_rays(between(pa[k], pb[k]), za[k:k + 1], zb[k:k + 1]).points_xy
        np.testing.assert_allclose(ekf[k], to_world(pa[k], local)[0], rtol=1e-9, atol=1e-9)
