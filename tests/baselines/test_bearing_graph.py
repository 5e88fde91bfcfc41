"""Tests of the factor graph (baselines/bearing_graph.py): the exact split odometry factor,
chi^2 at the truth, landmark admission, the presets."""

from __future__ import annotations

import math

import gtsam
import numpy as np
import pytest

from baselines.bearing_graph import (BearingGraph, FactorGraphConfig, insert_pose,
                                     landmark_key, odometry_factors, pose_key)
from bomgraph.errors import ConfigError
from bomgraph.geometry import compose
from bomgraph.sim import SimConfig, simulate
from bomgraph.stream import Step, Stream

NOISE_FREE = SimConfig(n_steps=80, n_landmarks=20, noise_scale=0.0)
SMALL = SimConfig(n_steps=100, n_landmarks=25)


@pytest.fixture(scope="module")
def noise_free() -> Stream:
    return simulate(NOISE_FREE, np.random.default_rng(7))


def _values_at_truth(stream: Stream, graph: BearingGraph, config: FactorGraphConfig
                     ) -> gtsam.Values:
    v = gtsam.Values()
    poses = stream.truth.poses
    for t, pose in enumerate(poses):
        insert_pose(v, t, pose, poses[t - 1] if t else None)
    for i, xy in zip(stream.truth.landmark_ids, stream.truth.landmarks_xy):
        if int(i) in graph.landmark_ids:
            v.insert(landmark_key(int(i)), gtsam.Point2(*xy))
    return v


def _graph_at_truth(stream: Stream, config: FactorGraphConfig
                    ) -> tuple[gtsam.NonlinearFactorGraph, gtsam.NonlinearFactorGraph,
                               gtsam.Values, BearingGraph]:
    """All factors of ``stream`` (landmarks admitted on the true poses) and the truth as values;
    the odometry factors apart."""
    g = BearingGraph(stream.header, config, stream.truth.poses[0])
    for st in stream.steps:
        g.add_step(st)
    g.admit(lambda ts: stream.truth.poses[ts])
    new = g.take_new()
    full = gtsam.NonlinearFactorGraph(new.core)
    full.push_back(new.landmark)
    odo = gtsam.NonlinearFactorGraph()
    for t, st in enumerate(stream.steps[1:], start=1):
        for f in odometry_factors(t, st.odom, st.odometry_sigma(stream.header), config):
            odo.add(f)
    return full, odo, _values_at_truth(stream, g, config), g


# --------------------------------------------------------------------------------------------
# The odometry factor
# --------------------------------------------------------------------------------------------

def test_split_factor_error_is_exactly_the_component_noise() -> None:
    """At the truth, the split factors' chi^2 is the whitened component noise, to round-off."""
    cfg = FactorGraphConfig()
    sigma = np.array([0.03, 0.0, math.radians(3)])
    a = np.array([0.4, -1.2, 2.9])
    u_true = np.array([0.17, 0.0, -0.45])
    b = compose(a, u_true)
    noise = np.array([0.021, 0.0, -0.061])
    factors = odometry_factors(5, u_true + noise, sigma, cfg)
    v = gtsam.Values()
    v.insert(pose_key(4), gtsam.Pose2(*a))
    v.insert(pose_key(5), gtsam.Pose2(*b))
    v.insert(gtsam.symbol("m", 5), gtsam.Pose2(b[0], b[1], a[2]))
    chi2 = 2 * sum(f.error(v) for f in factors)
    assert chi2 == pytest.approx((noise[0] / 0.03) ** 2 + (noise[2] / sigma[2]) ** 2, rel=1e-10)


@pytest.fixture(scope="module")
def noisy_runs() -> list[Stream]:
    return [simulate(SMALL, np.random.default_rng(100 + k)) for k in range(4)]


def test_chi2_per_dof_at_truth_is_one_with_the_split_model(noisy_runs: list[Stream]) -> None:
    cfg = FactorGraphConfig()
    chi2 = dof = chi2_odo = dof_odo = 0.0
    for s in noisy_runs:
        full, odo, v, g = _graph_at_truth(s, cfg)
        n_odo = len(s.steps) - 1
        chi2 += 2 * full.error(v)
        dof += g.n_bearing_factors + 2 * n_odo   # dy is exactly 0 in the simulator
        chi2_odo += 2 * odo.error(v)
        dof_odo += 2 * n_odo
    # ~5000 residuals: chi^2/dof has std. dev. ~0.02
    assert 0.92 < chi2 / dof < 1.08
    # ~800 odometry residuals: std. dev. ~0.05
    assert 0.8 < chi2_odo / dof_odo < 1.2


# --------------------------------------------------------------------------------------------
# Landmark admission
# --------------------------------------------------------------------------------------------

def test_enter_refuses_a_landmark_with_one_bearing(noise_free: Stream) -> None:
    g = BearingGraph(noise_free.header, FactorGraphConfig(), np.zeros(3))
    g.add_step(Step(0, None, np.array([999]), np.array([0.4])))
    with pytest.raises(ConfigError, match="two"):
        g.enter(999, np.array([1.0, 1.0]))


def test_buffered_bearings_all_become_factors_on_entry(noise_free: Stream) -> None:
    g = BearingGraph(noise_free.header, FactorGraphConfig(), noise_free.truth.poses[0])
    for st in noise_free.steps[:20]:
        g.add_step(st)
    n_bearings = sum(len(st.landmark_ids) for st in noise_free.steps[:20])
    g.admit(lambda ts: noise_free.truth.poses[ts])
    pending = sum(g.pending().values())
    assert g.n_bearing_factors + pending == n_bearings
    assert g.n_bearing_factors > 0.8 * n_bearings


def test_presets_and_validation() -> None:
    robust = FactorGraphConfig.preset("robust")
    assert robust.odometry_cauchy_k == robust.bearing_cauchy_k == 3.0
    assert FactorGraphConfig.preset("paper") == FactorGraphConfig()
    with pytest.raises(ConfigError, match="unknown FactorGraphConfig preset"):
        FactorGraphConfig.preset("fast")
    with pytest.raises(ConfigError, match="unknown option"):
        FactorGraphConfig.preset("paper", lambda_upper=3)
    for bad in ({"odometry_cauchy_k": 0.0}, {"bearing_cauchy_k": -1.0}, {"range_gate": 0.5}):
        with pytest.raises(ConfigError):
            FactorGraphConfig(**bad)


def test_prior_and_bearing_factor_errors_are_the_residual_over_sigma_by_hand() -> None:
    """A distance prior (2 m, sigma 0.05 m) between landmarks 2.1 m apart has GTSAM error
    ``0.5 (0.1 / 0.05)^2 = 2``; a bearing factor (sigma 0.02 rad) 0.03 rad off has error
    ``0.5 (0.03 / 0.02)^2 = 1.125``: the sigmas are std. devs., not variances."""
    from baselines.bearing_graph import bearing_noise, prior_factor
    from bomgraph.stream import Prior, StreamHeader

    v = gtsam.Values()
    v.insert(landmark_key(3), gtsam.Point2(1.0, 1.0))
    v.insert(landmark_key(8), gtsam.Point2(1.0, 3.1))
    v.insert(pose_key(0), gtsam.Pose2(0.0, 0.0, 0.4))
    f = prior_factor(Prior(3, 8, 2.0, 0.05))
    assert f.error(v) == pytest.approx(0.5 * (0.1 / 0.05) ** 2, rel=1e-9)
    header = StreamHeader(bearing_sigma_rad=0.02, odometry_sigma=np.array([0.01, 0.0, 0.01]))
    true_bearing = math.atan2(1.0, 1.0) - 0.4
    b = gtsam.BearingFactor2D(pose_key(0), landmark_key(3), gtsam.Rot2(true_bearing + 0.03),
                              bearing_noise(header))
    assert b.error(v) == pytest.approx(0.5 * (0.03 / 0.02) ** 2, rel=1e-9)
