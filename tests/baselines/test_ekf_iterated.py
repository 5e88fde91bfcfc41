"""The options of the EKF baselines against a wide or badly modelled prior (issue 15 item 5):

- ``wide_prior_heading_sd_rad`` / ``wide_prior_iterations``: the iterated update where the
  robot's heading prior is wide. An exactly linear model is solved by the first iterate (the
  iterated update equals the EKF update); bearings the prior mean predicts exactly leave it
  where it is; the trigger picks the iterated update exactly when the heading prior is wider
  than its bound (a bound of 0 is ``iterations = wide_prior_iterations``, a huge one changes
  nothing, bit for bit).
- ``path_heading_noise``: the translation noise of a heading error accumulated along a step
  (:func:`~baselines.ekf.models.path_heading_noise`) is the limit of predicting the step in
  many sub-steps; a Monte Carlo of long blind steps whose heading error does accumulate along
  the path is inconsistent with the per-component odometry covariance and consistent (pose
  NEES in its 99 % band) with the option.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.stats import chi2

from baselines.ekf import BearingEkf, EkfConfig, InverseDepthConfig
from baselines.ekf.filter import rows_from_dense
from baselines.ekf.models import bearing_and_jacobian, motion_jacobians, path_heading_noise
from bomgraph.angles import angle_residual
from bomgraph.errors import ConfigError
from bomgraph.geometry import compose
from bomgraph.mapper import create_mapper, run
from bomgraph.sim import SimConfig, simulate


def _filter() -> BearingEkf:
    """A pose and a poorly known landmark 2-3 m away (a strongly nonlinear bearing)."""
    f = BearingEkf(np.array([0.0, 0.0, 0.3]), np.diag([0.1, 0.1, 0.05]) ** 2, 0.02)
    f.augment(np.array([2.0, 1.0]), np.arange(3), np.zeros((2, 3)), np.diag([0.5, 0.8]) ** 2,
              np.array([False, False]))
    return f


def test_iterated_update_of_a_linear_model_is_the_ekf_update() -> None:
    a = np.array([[0.3, -0.2, -1.0, 0.1, 0.4], [-0.1, 0.5, -1.0, 0.2, -0.3]])
    z, var = np.array([0.05, -0.02]), np.array([0.02, 0.03]) ** 2

    def linear(x: np.ndarray):
        return a @ x, rows_from_dense(a)

    plain, iterated = _filter(), _filter()
    plain.update(z, linear, var)
    iterated.update(z, linear, var, iterations=8)
    np.testing.assert_allclose(iterated.x, plain.x, atol=1e-12)
    np.testing.assert_allclose(iterated.P, plain.P, atol=1e-12)
    assert not np.allclose(plain.x, _filter().x)              # the update did move the state


def test_iterated_update_of_bearings_the_prior_predicts_leaves_the_mean() -> None:
    def model(x: np.ndarray):
        h, j = bearing_and_jacobian(x[None, :3], x[None, 3:5])
        return h, rows_from_dense(j)

    f = _filter()
    x0 = f.x.copy()
    z = model(x0)[0]                                          # noise-free, at the prior mean
    plain = _filter()
    plain.update(z, model, np.array([0.02 ** 2]))
    f.update(z, model, np.array([0.02 ** 2]), iterations=10)
    np.testing.assert_allclose(f.x, x0, atol=1e-12)
    np.testing.assert_allclose(f.P, plain.P, atol=1e-12)
    assert np.trace(f.P) < np.trace(_filter().P)              # it did gain information


@pytest.mark.parametrize("method", ["ekf", "ekf-invdepth"])
def test_the_wide_prior_trigger_iterates_exactly_where_the_heading_prior_is_wide(
        method: str) -> None:
    s = simulate(SimConfig(n_landmarks=20, n_steps=60), np.random.default_rng(3))
    opts = {"initial_pose_sigma": (0.0, 0.0, 0.05)}

    def final(**kw):
        m = create_mapper(method, s.header, start_pose=tuple(s.truth.poses[0]), **opts, **kw)
        return run(m, s.steps).final

    base = final()
    never = final(wide_prior_heading_sd_rad=1e3)
    always = final(wide_prior_heading_sd_rad=0.0, wide_prior_iterations=4)
    iterated = final(iterations=4)
    np.testing.assert_array_equal(never.landmarks_xy, base.landmarks_xy)
    np.testing.assert_array_equal(never.poses, base.poses)
    np.testing.assert_array_equal(always.landmarks_xy, iterated.landmarks_xy)
    np.testing.assert_array_equal(always.poses, iterated.poses)
    assert not np.array_equal(always.poses, base.poses)       # iterating changes the run


def test_options_are_checked() -> None:
    for cls in (EkfConfig, InverseDepthConfig):
        for bad in ({"wide_prior_heading_sd_rad": -0.1}, {"wide_prior_heading_sd_rad": np.nan},
                    {"wide_prior_iterations": 0}):
            with pytest.raises(ConfigError):
                cls(**bad)
        for preset in ("paper", "real"):
            cfg = cls.preset(preset)
            assert cfg.wide_prior_heading_sd_rad is None


@pytest.mark.parametrize("odom", [[2.0, 0.0, 0.0], [0.3, -0.4, 0.0]])
def test_path_heading_noise_is_the_limit_of_many_sub_steps(odom: list[float]) -> None:
    sig = np.array([0.01, 0.005, 0.3])
    one = BearingEkf(np.array([1.0, -2.0, 0.7]), np.zeros((3, 3)), 0.02)
    one.predict(np.array(odom), sig, path_heading_noise(np.array(odom), sig[2]))
    _, g = motion_jacobians(np.array([1.0, -2.0, 0.7]), np.array(odom))
    k = 4000
    sub = BearingEkf(np.array([1.0, -2.0, 0.7]), np.zeros((3, 3)), 0.02)
    for _ in range(k):            # the heading noise split along the chord, nothing else
        sub.predict(np.array(odom) / k, np.array([0.0, 0.0, sig[2] / np.sqrt(k)]))
    np.testing.assert_allclose(one.x, sub.x, atol=1e-9)
    # the sub-steps' covariance plus the translation noise of the single step
    expected = sub.P + g @ np.diag([sig[0] ** 2, sig[1] ** 2, 0.0]) @ g.T
    np.testing.assert_allclose(one.P, expected, rtol=2e-3, atol=1e-12)
    assert path_heading_noise(np.array([0.0, 0.0, 1.0]), 0.3).tolist() == [[0.0] * 3] * 3


def _blind_steps_nees(path_noise: bool, rng: np.random.Generator, n: int = 2000) -> float:
    """Mean pose NEES of the predict over ``n`` long blind steps (2 m, heading sigma 0.1 rad)
    whose heading error accumulates along the way (50 sub-steps of the true motion)."""
    length, k = 2.0, 50
    sig = np.array([0.05, 0.02, 0.1])
    out = np.empty(n)
    for i in range(n):
        pose = np.zeros(3)
        for _ in range(k):        # the true motion: each sub-step's heading error carries on
            pose = compose(pose, [length / k + rng.normal(0.0, sig[0] / np.sqrt(k)),
                                  rng.normal(0.0, sig[1] / np.sqrt(k)),
                                  rng.normal(0.0, sig[2] / np.sqrt(k))])
        odom = np.array([length, 0.0, 0.0])
        f = BearingEkf(np.zeros(3), np.zeros((3, 3)), 0.02)
        f.predict(odom, sig, path_heading_noise(odom, sig[2]) if path_noise else None)
        e = pose - f.x
        e[2] = float(angle_residual(pose[2], f.x[2]))
        out[i] = e @ np.linalg.solve(f.P, e)
    return float(out.mean())


def test_long_blind_steps_are_consistent_only_with_the_path_heading_noise() -> None:
    n = 2000
    lo, hi = chi2.ppf([0.005, 0.995], 3 * n) / n              # the mean of n chi2(3) draws
    with_noise = _blind_steps_nees(True, np.random.default_rng(11), n)
    without = _blind_steps_nees(False, np.random.default_rng(11), n)
    assert lo < with_noise < hi
    assert without > 5 * hi
