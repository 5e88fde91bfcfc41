"""Consistency of the EKF baselines' linearisation (the ``jacobians`` option, baselines/ekf).

What is proved here: with ``jacobians="oc"`` (the observability-constrained EKF, the default)
and ``"fej"`` (first-estimate Jacobians) every bearing update adds no information along the
unobservable directions of bearing-only SLAM (global translation and rotation, the filter's
``nullspace`` ``N``): ``(H N)^T S^-1 (H N)`` is zero to 1e-9, on seeded simulations, for both
filters in both presets, and every predict carries ``N`` to the rigid-motion directions at the
new prior pose; the standard EKF (``"plain"``) gains information there (so the check can
fail). On a Monte Carlo of the paper's simulation the robot's heading NEES lies in the 95 %
chi-square band. A large turn predicted in sub-steps (``max_predict_turn_rad``) keeps the
step's end pose and heading variance.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.stats import chi2

from baselines.ekf import filter as ekf_filter
from baselines.ekf import EkfConfig
from bomgraph.angles import angle_residual
from bomgraph.errors import ConfigError
from bomgraph.geometry import compose
from bomgraph.mapper import create_mapper, run
from bomgraph.sim import SimConfig, simulate
from bomgraph.stream import Step, StreamHeader


def _information_along_nullspace(monkeypatch: pytest.MonkeyPatch, method: str, preset: str,
                                 jacobians: str, seed: int) -> tuple[float, float]:
    """Run ``method`` on a seeded simulation; the largest ``|(H N)^T S^-1 (H N)|`` over its
    bearing updates and the largest distance of the predicted ``N`` (pose rows) from the
    rigid-motion directions at the predicted pose."""
    worst = {"info": 0.0, "predict": 0.0}
    update, predict = ekf_filter.BearingEkf.update_compact, ekf_filter.BearingEkf.predict

    def checked_update(self, cols, hu, y, var):
        hn = hu @ self.nullspace[cols]
        s = hu @ self.P[np.ix_(cols, cols)] @ hu.T + np.diag(var)
        info = hn.T @ np.linalg.solve(s, hn)
        worst["info"] = max(worst["info"], float(np.abs(info).max()))
        return update(self, cols, hu, y, var)

    def checked_predict(self, odom, odom_sigma):
        predict(self, odom, odom_sigma)
        x, y = self.x[0], self.x[1]
        rigid = np.array([[1.0, 0.0, -y], [0.0, 1.0, x], [0.0, 0.0, 1.0]])
        worst["predict"] = max(worst["predict"], float(np.abs(self.nullspace[:3] - rigid).max()))

    monkeypatch.setattr(ekf_filter.BearingEkf, "update_compact", checked_update)
    monkeypatch.setattr(ekf_filter.BearingEkf, "predict", checked_predict)
    s = simulate(SimConfig(n_landmarks=20, n_steps=80), np.random.default_rng(seed))
    est = run(create_mapper(method, s.header, preset=preset, jacobians=jacobians), s.steps)
    assert est.final.info["used_bearings"] > 100
    return worst["info"], worst["predict"]


@pytest.mark.parametrize("method", ["ekf", "ekf-invdepth"])
@pytest.mark.parametrize("preset", ["paper", "real"])
@pytest.mark.parametrize("jacobians", ["oc", "fej"])
def test_no_information_is_gained_along_the_unobservable_directions(
        monkeypatch: pytest.MonkeyPatch, method: str, preset: str, jacobians: str) -> None:
    info, predict = _information_along_nullspace(monkeypatch, method, preset, jacobians, 31)
    assert info < 1e-9
    assert predict < 1e-9


@pytest.mark.parametrize("method", ["ekf", "ekf-invdepth"])
def test_the_standard_ekf_gains_spurious_information(monkeypatch: pytest.MonkeyPatch,
                                                     method: str) -> None:
    info, predict = _information_along_nullspace(monkeypatch, method, "paper", "plain", 31)
    assert info > 1e-3
    assert predict > 1e-3


@pytest.mark.parametrize("method", ["ekf", "ekf-invdepth"])
def test_heading_nees_of_a_monte_carlo_is_in_the_95_percent_band(method: str) -> None:
    # 10 runs x 80 steps of the paper's world and noise; the mapper starts at the true first
    # pose, so its frame is the truth's. The time average of the run-averaged heading NEES.
    n_runs = 10
    nees = []
    for seed in range(n_runs):
        s = simulate(SimConfig(n_steps=80), np.random.default_rng(100 + seed))
        est = run(create_mapper(method, s.header, start_pose=tuple(s.truth.poses[0])),
                  s.steps).final
        e = np.asarray(angle_residual(est.poses[5:, 2], s.truth.poses[5:, 2]))
        nees.append(e * e / est.pose_cov[5:, 2, 2])   # the first covariances are singular
    avg = np.mean(nees, axis=0).mean()
    assert chi2.ppf(0.025, n_runs) / n_runs < avg < chi2.ppf(0.975, n_runs) / n_runs


def test_unknown_jacobians_are_refused() -> None:
    with pytest.raises(ConfigError, match="jacobians"):
        EkfConfig(jacobians="first-estimates")


def test_a_large_turn_is_predicted_along_its_arc() -> None:
    # one blind step of 2.5 rad: in 25 sub-steps with max_predict_turn_rad = 0.1 the mean is
    # the step's exact end pose and the heading variance the step's; the heading noise enters
    # along the arc, so the position covariance differs from one predict's
    header = StreamHeader(bearing_sigma_rad=0.02, odometry_sigma=(0.05, 0.02, 0.3))
    odom = np.array([0.4, 0.9, 2.5])
    step = Step(t=1, odom=odom, landmark_ids=np.zeros(0, np.int64), bearings_rad=np.zeros(0))
    first = Step(t=0, odom=None, landmark_ids=np.zeros(0, np.int64), bearings_rad=np.zeros(0))
    one, arc = (create_mapper("ekf", header, max_predict_turn_rad=m) for m in (None, 0.1))
    for m in (one, arc):
        m.step(first)
        m.step(step)
    np.testing.assert_allclose(arc.filter.x[:3], one.filter.x[:3], atol=1e-12)
    np.testing.assert_allclose(one.filter.x[:3], compose(np.zeros(3), odom), atol=1e-12)
    assert abs(arc.filter.P[2, 2] - 0.3 ** 2) < 1e-12
    assert abs(one.filter.P[2, 2] - 0.3 ** 2) < 1e-12
    assert np.abs(arc.filter.P[:2, :2] - one.filter.P[:2, :2]).max() > 1e-3
    with pytest.raises(ConfigError, match="max_predict_turn_rad"):
        EkfConfig(max_predict_turn_rad=0.0)
