"""The elimination ordering computed once and shared (``baselines/lm_report.py``) changes no
number: :func:`polish` and :func:`solve_lm` against the same steps written out with GTSAM's
own per-call orderings (``linear.optimize()``, an LM optimizer left to order for itself). The
polish that reads its errors from its linearisations (``gaussian=True``) takes the same steps."""

from __future__ import annotations

import math

import gtsam
import numpy as np
import pytest

from baselines.bearing_graph import FactorGraphConfig
from baselines.factor_graph import BatchMapper
from baselines.lm_report import gauss_newton_check, lm_params, plain_gaussian, polish, solve_lm
from bomgraph.sim import SimConfig, simulate


def _raw_graph() -> tuple[gtsam.NonlinearFactorGraph, gtsam.Values,
                          gtsam.NonlinearFactorGraph]:
    """A noisy 60-step world at its dead-reckoned start (no solve): far from the minimum, so
    a polish takes several steps."""
    s = simulate(SimConfig(n_steps=60, n_landmarks=25), np.random.default_rng(5))
    m = BatchMapper(s.header, solve_every=10 ** 9)
    for st in s.steps:
        m.step(st)
    m.state.absorb()
    return m.state.graph, m.state.values, m.state.robust_graph


def _reference_polish(graph: gtsam.NonlinearFactorGraph, values: gtsam.Values, iterations: int,
                      decrease_tol: float) -> tuple[gtsam.Values, float, float, float, int]:
    """Kept-if-lower Gauss-Newton, each step ordered by its own ``optimize()``."""
    error = graph.error(values)
    steps = 0
    for _ in range(iterations):
        linear = graph.linearize(values)
        delta = linear.optimize()
        zero = gtsam.VectorValues(delta)
        zero.setZero()
        step = float(np.max(np.abs(delta.vector())))
        decrease = linear.error(zero) - linear.error(delta)
        trial = values.retract(delta)
        if not graph.error(trial) < error:
            break
        values, error, steps = trial, graph.error(trial), steps + 1
        if decrease <= decrease_tol:
            break
    return values, step, decrease, error, steps


def _same(a: gtsam.Values, b: gtsam.Values) -> bool:
    return list(a.keys()) == list(b.keys()) and all(np.array_equal(_vec(a, k), _vec(b, k))
                                                    for k in a.keys())


def _vec(v: gtsam.Values, key: int) -> np.ndarray:
    sym = chr(gtsam.Symbol(key).chr())
    if sym in "xm":
        p = v.atPose2(key)
        return np.array([p.x(), p.y(), p.theta()])
    return np.asarray(v.atPoint2(key))


def test_polish_takes_the_steps_of_plain_gauss_newton_bit_for_bit() -> None:
    graph, raw, _ = _raw_graph()
    params = lm_params(FactorGraphConfig())
    params.setMaxIterations(2)    # part of the way: Gauss-Newton converges from there
    start = gtsam.LevenbergMarquardtOptimizer(graph, raw, params).optimize()
    ref = _reference_polish(graph, start, 8, 1e-6)
    assert ref[4] >= 3   # several steps, so the shared ordering is used more than once
    values, step, decrease, cost = polish(graph, start, 8, 1e-6)
    assert _same(values, ref[0])
    assert (step, decrease, cost) == ref[1:4]


def test_polish_with_errors_from_its_linearisations_takes_the_same_steps() -> None:
    graph, raw, robust = _raw_graph()
    assert plain_gaussian(graph) and not plain_gaussian(robust)
    params = lm_params(FactorGraphConfig())
    params.setMaxIterations(2)
    start = gtsam.LevenbergMarquardtOptimizer(graph, raw, params).optimize()
    for iterations, tol in ((8, 1e-6), (2, 1e-6), (8, 1e3), (0, 1e-6)):
        ref = polish(graph, start, iterations, tol)
        values, step, decrease, cost = polish(graph, start, iterations, tol, gaussian=True)
        assert _same(values, ref[0])
        assert (step, decrease) == ref[1:3]
        assert cost == pytest.approx(ref[3], rel=1e-12)
    # from the dead-reckoned start: steps that raise the error are refused the same way
    ref = _reference_polish(graph, raw, 8, 1e-6)
    values, step, decrease, cost = polish(graph, raw, 8, 1e-6, gaussian=True)
    assert _same(values, ref[0]) and (step, decrease) == ref[1:3]
    assert cost == pytest.approx(ref[3], rel=1e-12)


def test_plain_gaussian_refuses_kernels_constraints_and_factors_without_a_noise_model() -> None:
    key = gtsam.symbol("x", 0)
    plain = gtsam.NonlinearFactorGraph()
    assert plain_gaussian(plain)
    plain.add(gtsam.PriorFactorPose2(key, gtsam.Pose2(), gtsam.noiseModel.Diagonal.Sigmas(
        [1.0, 2.0, 3.0])))
    assert plain_gaussian(plain)
    robust = gtsam.NonlinearFactorGraph(plain)
    robust.add(gtsam.PriorFactorPose2(key, gtsam.Pose2(), gtsam.noiseModel.Robust.Create(
        gtsam.noiseModel.mEstimator.Cauchy.Create(3.0), gtsam.noiseModel.Unit.Create(3))))
    assert not plain_gaussian(robust)
    hard = gtsam.NonlinearFactorGraph(plain)
    hard.add(gtsam.PriorFactorPose2(key, gtsam.Pose2(), gtsam.noiseModel.Constrained.All(3)))
    assert not plain_gaussian(hard)
    other = gtsam.NonlinearFactorGraph(plain)
    other.add(gtsam.LinearContainerFactor(gtsam.JacobianFactor(
        key, np.eye(3), np.zeros(3), gtsam.noiseModel.Unit.Create(3)), gtsam.Values()))
    assert not plain_gaussian(other)


def test_solve_lm_is_gtsam_lm_and_its_check_bit_for_bit() -> None:
    graph, start, robust = _raw_graph()
    cfg = FactorGraphConfig(huber_k=None)
    values, report = solve_lm(graph, start, cfg)
    opt = gtsam.LevenbergMarquardtOptimizer(graph, start, lm_params(cfg))
    ref = opt.optimize()
    assert _same(values, ref)
    assert report.iterations == opt.iterations() and report.final_error == opt.error()
    step, decrease = gauss_newton_check(graph, ref)
    assert math.isfinite(step)
    assert (report.gn_step, report.predicted_decrease) == (step, decrease)
    # with the robust pass first (ordered by itself), the plain pass from its result
    values, report = solve_lm(graph, start, FactorGraphConfig(), robust)
    assert report.passes == ("huber", "plain")
    opt = gtsam.LevenbergMarquardtOptimizer(robust, start, lm_params(FactorGraphConfig()))
    mid = opt.optimize()
    opt = gtsam.LevenbergMarquardtOptimizer(graph, mid, lm_params(FactorGraphConfig()))
    assert _same(values, opt.optimize())
    assert (report.gn_step, report.predicted_decrease) == gauss_newton_check(graph, values)
