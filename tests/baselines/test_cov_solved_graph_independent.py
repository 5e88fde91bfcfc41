"""The covariances a GTSAM mapper reports are those of the graph its solution solved.

Past ``lag_after_steps`` a whole-graph solve leaves out the bearings taken from nearly on top
of their landmark (:mod:`baselines.near_range`) and a window solve does not; ``hybrid`` solves
two starts at one update and keeps the lower cost. Before the twenty-first session its
``MapEstimate`` took the marginals of whichever graph the *last* solve used: when the warm
start (a whole-graph solve, near bearings out) won over the seed start (a window solve, every
bearing in), the covariances included bearings the solution was not fitted to (paper world,
seed 5003, lag 40/20: one landmark's variance 0.23 of its graph's).

The check does not use the mapper's bookkeeping: every call of ``solve_lm`` is recorded with
the graph it was given, and the kept solution's covariances are computed from that graph by
``marginal_covariances`` (itself checked against a numeric Jacobian in
``test_pose_cov_frame_independent.py``).
"""

from __future__ import annotations

import gtsam
import numpy as np
import pytest

from baselines import factor_graph
from baselines.lm_report import marginal_covariances
from bomgraph import create_mapper
from bomgraph.sim import SimConfig, simulate


def test_hybrid_covariances_are_those_of_the_kept_solutions_graph(
        monkeypatch: pytest.MonkeyPatch) -> None:
    solved: dict[int, tuple[gtsam.Values, gtsam.NonlinearFactorGraph]] = {}
    real = factor_graph.solve_lm

    def recording(graph, initial, config, robust_graph=None, **kw):
        values, report = real(graph, initial, config, robust_graph, **kw)
        solved[id(values)] = (values, graph)
        return values, report

    monkeypatch.setattr(factor_graph, "solve_lm", recording)
    stream = simulate(SimConfig(n_steps=100), np.random.default_rng(5003))
    mapper = create_mapper("hybrid", stream.header, covariances=True, lag_after_steps=40,
                           lag_steps=20, start_tol_m=0.0)
    for step in stream.steps[:41]:
        mapper.step(step)
    est = mapper.estimate()
    kept = mapper.state.values
    # the case: both starts solved at step 41, the warm one (a whole-graph solve, which left
    # near bearings out) kept
    assert est.info["starts"] == ["warm", "seed"] and est.info["start"] == "warm"
    assert est.info["near_bearings_left_out"] >= 1
    graph = solved[id(kept)][1]
    assert graph.nrFactors() < mapper.state.graph.nrFactors()
    marg = marginal_covariances(graph, kept, est.pose_t, est.landmark_ids)
    assert marg.complete
    lc, pc = marg.landmark_cov, marg.pose_cov
    assert est.landmark_cov is not None and est.pose_cov is not None
    np.testing.assert_allclose(est.landmark_cov, lc, rtol=1e-7, atol=1e-12)
    np.testing.assert_allclose(est.pose_cov, pc, rtol=1e-7, atol=1e-12)
