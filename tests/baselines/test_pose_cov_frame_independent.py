"""The GTSAM mappers' pose covariances are in the map's frame, as ``MapEstimate.pose_cov`` and
``pose_nees`` read them, checked against computations that do not use GTSAM's chart.

``gtsam.Marginals`` gives a ``Pose2`` covariance in the tangent space at the pose (the robot's
axes); before the twenty-first session ``marginal_covariances`` handed that on unturned, so a
pose heading along the world's y axis had its forward and lateral variances swapped.
"""

from __future__ import annotations

import dataclasses

import gtsam
import numpy as np
import pytest

from baselines import gtsam_tools as gt
from baselines.bearing_graph import FactorGraphConfig, landmark_key, pose_key
from baselines.lm_report import marginal_covariances
from bomgraph import create_mapper, run
from bomgraph.angles import angle_residual
from bomgraph.sim import SimConfig, simulate


def test_heading_along_y_swaps_forward_and_lateral() -> None:
    """Pose 1 is 1 m ahead of an anchored pose heading along +y, with a forward sigma of
    1 cm and a lateral one of 10 cm: forward is world y, lateral world x (plus the anchor's
    1 mrad heading times the 1 m lever)."""
    graph = gtsam.NonlinearFactorGraph()
    values = gtsam.Values()
    anchor = gtsam.Pose2(0.0, 0.0, np.pi / 2)
    graph.add(gtsam.PriorFactorPose2(pose_key(0), anchor,
                                     gtsam.noiseModel.Diagonal.Sigmas([1e-3, 1e-3, 1e-3])))
    graph.add(gtsam.BetweenFactorPose2(pose_key(0), pose_key(1), gtsam.Pose2(1.0, 0.0, 0.0),
                                       gtsam.noiseModel.Diagonal.Sigmas([0.01, 0.1, 1e-3])))
    values.insert(pose_key(0), anchor)
    values.insert(pose_key(1), gtsam.Pose2(0.0, 1.0, np.pi / 2))
    pc = marginal_covariances(graph, values, np.array([0, 1]), np.zeros(0, np.int64)).pose_cov
    var_x, var_y, var_psi = np.diag(pc[1])
    assert var_x == pytest.approx(0.1 ** 2 + 1e-6 + 1e-6, rel=1e-6)   # lateral
    assert var_y == pytest.approx(0.01 ** 2 + 1e-6, rel=1e-6)         # forward
    assert var_psi == pytest.approx(2e-6, rel=1e-6)
    # the lateral error comes with the heading error: x falls as psi grows at heading +y
    assert pc[1][0, 2] == pytest.approx(-1e-6, rel=1e-6)


def _world_covariance(graph: gtsam.NonlinearFactorGraph, values: gtsam.Values,
                      keys: list[int]) -> np.ndarray:
    """``(J^T J)^-1`` with ``J`` the whitened residuals' Jacobian in world coordinates (each
    pose moved as ``Pose2(x + h, y, psi)`` etc., each point as ``Point2(x + h, y)``), by
    central differences over the factors that hold the variable: no GTSAM chart involved."""
    factors = [graph.at(i) for i in range(graph.size())]
    rows = np.cumsum([0] + [f.dim() for f in factors])
    cols: list[tuple[int, int]] = []
    for k in keys:
        cols += [(k, j) for j in range(3 if values.exists(k) and _is_pose(values, k) else 2)]
    jac = np.zeros((rows[-1], len(cols)))
    touching = {k: [i for i, f in enumerate(factors) if k in f.keys()] for k in keys}
    h = 1e-6
    for c, (k, j) in enumerate(cols):
        for sign in (1.0, -1.0):
            moved = gtsam.Values(values)
            if _is_pose(values, k):
                p = values.atPose2(k)
                v = np.array([p.x(), p.y(), p.theta()])
                v[j] += sign * h
                moved.update(k, gtsam.Pose2(*v))
            else:
                v = np.array(values.atPoint2(k), float)
                v[j] += sign * h
                moved.update(k, v)
            for i in touching[k]:
                jac[rows[i]:rows[i + 1], c] += sign * factors[i].whitenedError(moved) / (2 * h)
    return np.linalg.inv(jac.T @ jac), cols


def _is_pose(values: gtsam.Values, key: int) -> bool:
    return gtsam.Symbol(key).chr() in (ord("x"), ord("m"))


def test_marginals_equal_a_world_frame_numeric_covariance() -> None:
    """A short noisy run solved by the public helpers: every pose's and landmark's covariance
    equals ``(J^T J)^-1`` of the world-coordinate Jacobian (the graph's own Gauss-Newton
    covariance at the minimum), to the finite differences' precision (1e-5 of each matrix's
    largest entry)."""
    stream = simulate(SimConfig(n_landmarks=6, n_steps=12, arena_m=1.5),
                      np.random.default_rng(4))
    config = dataclasses.replace(FactorGraphConfig(), covariances=True)
    state = gt.build_graph(stream.header, stream.steps, config=config)
    values, report = gt.checked_solve(state.graph, state.values, config)
    assert report.converged
    est = state.to_estimate(values, report.as_info())
    assert est.pose_cov is not None and len(est.landmark_ids) >= 3
    headings = est.poses[:, 2]
    assert np.ptp(np.cos(headings)) > 1.0          # the poses face many ways
    keys = [int(k) for k in gtsam.KeyVector(values.keys())]
    cov, cols = _world_covariance(state.graph, values, keys)
    at = {kj: c for c, kj in enumerate(cols)}
    for t in est.pose_t:
        idx = [at[(pose_key(int(t)), j)] for j in range(3)]
        want = cov[np.ix_(idx, idx)]
        np.testing.assert_allclose(est.pose_cov[t], want, rtol=1e-4,
                                   atol=1e-5 * np.abs(want).max())
    for n, lid in enumerate(est.landmark_ids):
        idx = [at[(landmark_key(int(lid)), j)] for j in range(2)]
        want = cov[np.ix_(idx, idx)]
        np.testing.assert_allclose(est.landmark_cov[n], want, rtol=1e-4,
                                   atol=1e-5 * np.abs(want).max())


def test_pose_nees_monte_carlo_in_the_start_frame() -> None:
    """A Monte Carlo of the estimator: 50 simulated 50-step runs of ``gtsam-batch`` with
    covariances, the final pose's error taken in the frame fixed by the first pose (the graph's
    anchor, so no alignment absorbs any error). Its NEES averages 3.03, inside the 95 % band of
    a 50-run mean of chi^2(3) (2.32-3.68); with the covariances unturned it was 5.08."""
    nees = []
    for seed in range(50):
        stream = simulate(SimConfig(n_steps=50, n_landmarks=25),
                          np.random.default_rng(1000 + seed))
        est = run(create_mapper("gtsam-batch", stream.header, covariances=True), stream.steps,
                  checkpoint_every=10 ** 6).final
        assert est.pose_cov is not None
        true = stream.truth.poses
        a = true[0][2] - est.poses[0][2]
        rot = np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]])
        shift = true[0][:2] - rot @ est.poses[0][:2]
        p, q = est.poses[-1], true[est.pose_t[-1]]
        err = np.r_[rot @ p[:2] + shift - q[:2], angle_residual(p[2] + a, q[2])]
        turn = np.eye(3)
        turn[:2, :2] = rot
        nees.append(err @ np.linalg.solve(turn @ est.pose_cov[-1] @ turn.T, err))
    half = 1.96 * np.sqrt(6 / len(nees))
    assert 3 - half < np.mean(nees) < 3 + half
