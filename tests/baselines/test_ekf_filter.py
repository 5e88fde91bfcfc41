"""The filter wrapper (baselines/ekf/filter.py): it is filterpy's EKF, its state-sized arrays
grow and shrink together (also during a run of the mapper), augmenting is the exact covariance
of a linear map, predict propagates the odometry noise through the input Jacobian, and the
iterated update reaches the MAP estimate of prior and bearing (against a generic minimiser)."""

from __future__ import annotations

import numpy as np
import pytest
from filterpy.kalman import ExtendedKalmanFilter
from scipy.optimize import minimize

from baselines.ekf import BearingEkf, EkfMapper
from baselines.ekf.models import bearing_and_jacobian, motion_jacobians
from bomgraph.angles import angle_residual
from bomgraph.errors import ConfigError
from bomgraph.geometry import compose
from bomgraph.sim import SimConfig, simulate

SMALL = SimConfig(n_landmarks=20, n_steps=80)


def sized_arrays(f: BearingEkf) -> dict[str, tuple[int, ...]]:
    kf = f.kf
    return {"x": kf.x.shape, "P": kf.P.shape, "F": kf.F.shape, "Q": kf.Q.shape,
            "_I": kf._I.shape, "K": kf.K.shape[:1], "x_prior": kf.x_prior.shape,
            "x_post": kf.x_post.shape, "P_prior": kf.P_prior.shape,
            "P_post": kf.P_post.shape, "nullspace": f.nullspace.shape[:1]}


def assert_consistent_sizes(f: BearingEkf) -> None:
    n = f.dim
    expected = {"x": (n,), "P": (n, n), "F": (n, n), "Q": (n, n), "_I": (n, n), "K": (n,),
                "x_prior": (n,), "x_post": (n,), "P_prior": (n, n), "P_post": (n, n),
                "nullspace": (n,)}
    assert sized_arrays(f) == expected
    np.testing.assert_allclose(f.kf._I, np.eye(n))


def test_filter_is_filterpys_and_augment_is_the_exact_covariance_of_a_linear_map() -> None:
    f = BearingEkf(np.array([0.1, 0.2, 0.3]), np.diag([0.01, 0.02, 0.03]), 0.05)
    assert isinstance(f.kf, ExtendedKalmanFilter)
    p0 = f.P.copy()
    g = np.array([[1.0, 0.5, -2.0], [0.0, 2.0, 1.0]])
    w = np.array([[0.3, 0.1], [0.1, 0.2]])
    f.augment(np.array([1.0, 2.0]), np.arange(3), g, w, np.array([False, False]))
    a = np.vstack([np.eye(3), g])                     # [x; G x + w]
    expected = a @ p0 @ a.T
    expected[3:, 3:] += w
    np.testing.assert_allclose(f.P, expected, atol=1e-15)
    assert_consistent_sizes(f)
    f.remove(np.array([3]))
    np.testing.assert_allclose(f.P, expected[np.ix_([0, 1, 2, 4], [0, 1, 2, 4])], atol=1e-15)
    assert_consistent_sizes(f)
    with pytest.raises(ConfigError, match="robot pose"):
        f.remove(np.array([2]))


def test_predict_propagates_the_odometry_covariance_through_the_input_jacobian() -> None:
    f = BearingEkf(np.array([1.0, 2.0, 0.7]), np.zeros((3, 3)), 0.05)
    odom, sig = np.array([0.2, 0.01, 0.1]), np.array([0.03, 0.02, 0.05])
    f.predict(odom, sig)
    np.testing.assert_allclose(f.x, compose([1.0, 2.0, 0.7], odom), atol=1e-15)
    _, g = motion_jacobians(np.array([1.0, 2.0, 0.7]), odom)
    np.testing.assert_allclose(f.P, g @ np.diag(sig ** 2) @ g.T, atol=1e-15)


def test_state_arrays_grow_and_shrink_together_during_a_run() -> None:
    s = simulate(SMALL, np.random.default_rng(5))
    m = EkfMapper(s.header)
    dims = set()
    for st in s.steps[:40]:
        m.step(st)
        assert_consistent_sizes(m.filter)
        n_lm = sum(1 for k in m._sizes if k[0] == "lm")
        n_clone = sum(1 for k in m._sizes if k[0] == "clone")
        assert m.filter.dim == 3 + 2 * n_lm + 3 * n_clone
        assert n_clone <= len({t for sig in m._candidates.values() for t, _ in sig})
        np.testing.assert_allclose(m.filter.P, m.filter.P.T, atol=1e-12)
        assert np.linalg.eigvalsh(m.filter.P).min() > -1e-9
        dims.add(m.filter.dim)
    assert len(dims) > 3                                  # it did grow (and shrink)
    est = m.estimate()
    assert est.landmark_cov.shape == (len(est), 2, 2)
    assert est.pose_cov.shape == (40, 3, 3) and est.poses.shape == (40, 3)
    np.testing.assert_array_equal(est.pose_t, np.arange(40))


def _landmark_filter() -> tuple[BearingEkf, np.ndarray, np.ndarray]:
    """A pose and a poorly known landmark 2-3 m away (a strongly nonlinear bearing)."""
    f = BearingEkf(np.array([0.0, 0.0, 0.3]), np.diag([0.1, 0.1, 0.05]) ** 2, 0.02)
    f.augment(np.array([2.0, 1.0]), np.arange(3), np.zeros((2, 3)), np.diag([0.5, 0.8]) ** 2,
              np.array([False, False]))
    return f, f.x.copy(), f.P.copy()


def _bearing(x: np.ndarray) -> np.ndarray:
    return bearing_and_jacobian(x[None, :3], x[None, 3:5])[0]


def _bearing_jac(x: np.ndarray) -> np.ndarray:
    return bearing_and_jacobian(x[None, :3], x[None, 3:5])[1]


def test_iterated_update_is_the_map_estimate_of_prior_and_bearing() -> None:
    z, var = np.array([0.6]), np.array([0.02 ** 2])
    f, x0, p0 = _landmark_filter()
    info = np.linalg.inv(p0)

    def cost(x: np.ndarray) -> float:
        r = float(angle_residual(z[0], _bearing(x)[0]))
        return 0.5 * (x - x0) @ info @ (x - x0) + 0.5 * r * r / var[0]

    best = minimize(cost, x0, method="BFGS", options={"gtol": 1e-12}).x
    f.update(z, _bearing, _bearing_jac, var, iterations=30)
    np.testing.assert_allclose(f.x, best, atol=1e-6)
    # the covariance is (I - K H) P0 with H at the estimate: the inverse of the Gauss-Newton
    # Hessian there
    h = _bearing_jac(f.x)
    np.testing.assert_allclose(f.P, np.linalg.inv(info + h.T @ h / var[0]), atol=1e-12)
    plain, _, _ = _landmark_filter()
    plain.update(z, _bearing, _bearing_jac, var)              # one linearisation, at x0
    assert cost(plain.x) > cost(f.x) + 1.0


