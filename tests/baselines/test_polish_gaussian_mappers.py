"""``polish(..., gaussian=True)`` (errors read from the linearisations) against the plain
polish on the graphs the iSAM2 mappers build: normal, long mode with and without a window,
``hybrid-isam2`` with seeded landmarks and seed priors, the robust preset, external factors
and a failed update; from the mapper's estimate and from a start far off, where steps are
refused. The mapper's ``_gaussian`` must say whether its graph is plain Gaussian."""

from __future__ import annotations

import gtsam
import numpy as np
import pytest

from baselines.hybrid_isam2 import HybridIsam2Mapper
from baselines.isam2 import Isam2Mapper
from baselines.lm_report import plain_gaussian, polish
from bomgraph.mapper import MapEstimate
from bomgraph.sim import SimConfig, simulate
from bomgraph.stream import Step, Stream


@pytest.fixture(scope="module")
def small() -> Stream:
    return simulate(SimConfig(n_steps=120, n_landmarks=25), np.random.default_rng(3))


class _TruthSeed:
    def __init__(self, stream: Stream) -> None:
        self.map = MapEstimate(stream.truth.landmark_ids, stream.truth.landmarks_xy)

    def step(self, step: Step) -> None:
        pass

    def estimate(self) -> MapEstimate:
        return self.map


def _same(a: gtsam.Values, b: gtsam.Values) -> bool:
    return list(a.keys()) == list(b.keys()) and all(np.array_equal(_vec(a, k), _vec(b, k))
                                                    for k in a.keys())


def _vec(v: gtsam.Values, key: int) -> np.ndarray:
    if chr(gtsam.Symbol(key).chr()) in "xm":
        p = v.atPose2(key)
        return np.array([p.x(), p.y(), p.theta()])
    return np.asarray(v.atPoint2(key))


def _far(values: gtsam.Values, seed: int, scale: float) -> gtsam.Values:
    """``values`` with every variable moved at random (landmarks by ~``scale`` m, poses by a
    tenth of it): from ``scale`` = 20 the first step raises the error and is refused."""
    rng = np.random.default_rng(seed)
    delta = gtsam.VectorValues()
    for k in values.keys():
        n = 3 if chr(gtsam.Symbol(k).chr()) in "xm" else 2
        delta.insert(k, rng.normal(scale=scale if n == 2 else scale / 10, size=n))
    return values.retract(delta)


def _whole(m: Isam2Mapper) -> tuple[gtsam.NonlinearFactorGraph, gtsam.Values]:
    graph = gtsam.NonlinearFactorGraph(m.accepted)
    graph.push_back(m._buffer)
    graph.push_back(m._external)
    values = gtsam.Values(m.current_values() if m._window_b else m.estimate_values)
    values.insert(m._buffer_values)
    return graph, values


def _feed(m: Isam2Mapper, stream: Stream) -> Isam2Mapper:
    for st in stream.steps:
        m.step(st)
    return m


def _check(m: Isam2Mapper) -> int:
    """The mapper's flag is its graph's; on a plain graph both polishes agree bit for bit;
    returns how many steps the far-off polish refused (to check the case was reached)."""
    graph, values = _whole(m)
    assert m._gaussian == plain_gaussian(graph)
    if not m._gaussian:
        return 0
    refused = 0
    for start in (values, _far(values, 1, 2.0), _far(values, 2, 20.0)):
        for iterations, tol in ((0, 1e-6), (1, 1e-6), (3, 1e-6), (10, 0.0), (10, 1e3)):
            a = polish(graph, start, iterations, tol)
            b = polish(graph, start, iterations, tol, gaussian=True)
            assert _same(a[0], b[0]) and a[1:3] == b[1:3], (iterations, tol)
            assert b[3] == pytest.approx(a[3], rel=1e-12)
            if iterations and a[1] > 0 and _same(a[0], start) and np.isfinite(a[1]):
                refused += 1
    return refused


def test_normal_run(small: Stream) -> None:
    m = _feed(Isam2Mapper(small.header, long_after_steps=None), small)
    assert m._gaussian
    assert _check(m) > 0          # some far-off first step was refused


@pytest.mark.parametrize("window", [True, False])
def test_long_mode(small: Stream, window: bool) -> None:
    m = _feed(Isam2Mapper(small.header, long_after_steps=60, long_lag_steps=20,
                          long_shift_steps=20, long_growth=1.25, long_window=window), small)
    assert m._gaussian and (m._window_b > 0) == window
    _check(m)


def test_hybrid_isam2_with_seed_priors(small: Stream) -> None:
    m = HybridIsam2Mapper(small.header, seed_mapper=_TruthSeed(small), seed_sigma_m=0.5)
    _feed(m, small)
    assert m.seeded and m._gaussian
    _check(m)


@pytest.mark.parametrize("preset", ["robust", "real"])
def test_robust_presets_never_take_the_gaussian_path(small: Stream, preset: str) -> None:
    m = _feed(Isam2Mapper(small.header, preset=preset), small)
    assert not m._gaussian
    _check(m)


def test_an_external_robust_factor_turns_it_off(small: Stream) -> None:
    m = Isam2Mapper(small.header, long_after_steps=None)
    for st in small.steps[:50]:
        m.step(st)
    assert m._gaussian
    extra = gtsam.NonlinearFactorGraph()
    extra.add(gtsam.PriorFactorPose2(gtsam.symbol("x", 10), gtsam.Pose2(), gtsam.noiseModel.Robust
              .Create(gtsam.noiseModel.mEstimator.Huber.Create(1.0),
                      gtsam.noiseModel.Unit.Create(3))))
    m.add_factors(extra)
    for st in small.steps[50:]:
        m.step(st)
    assert not m._gaussian
    _check(m)
