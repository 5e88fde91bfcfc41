"""Tests of the near-range rule of the LM mappers (baselines/near_range.py) and of the index of
bearing factors it relies on (baselines/bearing_log.py): the index against the graphs' own
factor keys, the rule's range, a world where a pose passes millimetres from a landmark, and
streams with no bearing that near left bit for bit as they were."""

from __future__ import annotations

import gtsam
import numpy as np
import pytest

from baselines.bearing_graph import FactorGraphConfig, landmark_key, pose_key
from baselines.near_range import near_bearings, near_range_of, without_factors
from bomgraph.errors import ConfigError
from bomgraph.mapper import create_mapper, run
from bomgraph.sim import SimConfig, simulate
from bomgraph.stream import Stream


#: The long mode (where the rule applies) from step 50, a whole-graph solve at every solve.
LONG_EARLY = {"lag_after_steps": 50, "lag_steps": 20, "full_growth": 1.01}


@pytest.fixture(scope="module")
def small() -> Stream:
    return simulate(SimConfig(n_steps=120, n_landmarks=30), np.random.default_rng(3))


@pytest.fixture(scope="module")
def close_pass() -> Stream:
    """The scale world of ``scripts/bench_scale.py`` (N = 1000, seed 11): pose 82 passes 3.2 mm
    from landmark 511 (the truth)."""
    side = 2.5 * np.sqrt(1000 / 50)
    return simulate(SimConfig(arena_m=side, n_landmarks=1000, n_steps=6000),
                    np.random.default_rng(11))


def test_the_index_names_every_bearing_factor_of_both_graphs(small: Stream) -> None:
    mapper = create_mapper("gtsam-batch", small.header, **LONG_EARLY)
    run(mapper, small.steps, checkpoint_every=10)
    state = mapper.state
    owner, lid, _ = state.bearings()
    inside = np.isin(lid, state.problem.landmark_ids)
    g, r = state._factors.find(owner[inside], lid[inside])
    assert g.size == r.size == state.problem.n_bearing_factors > 100
    for graph, at in ((state.graph, g), (state.robust_graph, r)):
        found = sorted((int(graph.at(int(i)).keys()[0]), int(graph.at(int(i)).keys()[1]))
                       for i in at)
        want = sorted((pose_key(int(t)), landmark_key(int(i)))
                      for t, i in zip(owner[inside], lid[inside]))
        assert found == want
    # one pair alone
    g1, r1 = state._factors.find(owner[inside][:1], lid[inside][:1])
    assert g1.size == 1 and list(state.graph.at(int(g1[0])).keys()) == [
        pose_key(int(owner[inside][0])), landmark_key(int(lid[inside][0]))]


def test_near_range_defaults_to_the_odometry_translation_sigma(small: Stream) -> None:
    sx, sy, _ = small.header.odometry_sigma
    assert near_range_of(small.header, None) == pytest.approx(np.hypot(sx, sy))
    assert near_range_of(small.header, 0.01) == 0.01
    with pytest.raises(ConfigError, match="near_range_m"):
        FactorGraphConfig(near_range_m=-1.0)
    with pytest.raises(ConfigError, match="near_range_m"):
        FactorGraphConfig(near_range_m=float("nan"))


def test_near_bearings_and_without_factors() -> None:
    owner = np.array([[0.0, 0.0], [1.0, 1.0], [2.0, 2.0]])
    points = np.array([[0.02, 0.0], [1.0, 1.5], [np.nan, 2.0]])
    assert near_bearings(owner, points, 0.03).tolist() == [True, False, False]
    graph = gtsam.NonlinearFactorGraph()
    noise = gtsam.noiseModel.Isotropic.Sigma(2, 1.0)
    for x in (0.0, 1.0, 2.0):
        graph.add(gtsam.PriorFactorPoint2(1, gtsam.Point2(x, 0.0), noise))
    values = gtsam.Values()
    values.insert(1, gtsam.Point2(0.0, 0.0))
    cut = without_factors(graph, np.array([2, 2]))
    assert graph.nrFactors() == 3 and cut.nrFactors() == 2
    assert cut.error(values) == pytest.approx(0.5)       # the prior at x = 1 only
    assert graph.error(values) == pytest.approx(2.5)


def test_a_bearing_taken_on_top_of_its_landmark_is_left_out(close_pass: Stream) -> None:
    """At step 101 the plain solve with every bearing puts landmark 511 on pose 82 with that
    bearing ~170 degrees off and calls for a Huber pass (test_factor_graph.py); with the rule
    (the long mode from step 50 here, every solve a whole-graph one) the bearing is out of
    the solve, its residual out of the checks, and no pass runs."""
    mapper = create_mapper("gtsam-batch", close_pass.header, **LONG_EARLY)
    for s in close_pass.steps[:101]:
        mapper.step(s)
    est = mapper.estimate()
    assert tuple(est.info["passes"]) == ("plain",)
    assert est.info["converged"]
    state = mapper.state
    owner, lid, _ = state.bearings()
    near = {(int(owner[i]), int(lid[i])) for i in state._near}
    assert (82, 511) in near
    assert est.info["near_bearings_left_out"] == len(state._near) < 10
    # the solved graph lacks exactly those factors; the state's graph keeps them
    assert state.solved_graph.nrFactors() == state.graph.nrFactors() - len(state._near)
    _, at = state.whitened_residuals(state.values)
    assert not np.isin(state._near, at).any()
    # every pose is within reach of the rule's range only where the truth says so too
    t, i = np.array(sorted(near)).T
    true_xy = close_pass.truth.landmarks_xy[np.searchsorted(close_pass.truth.landmark_ids, i)]
    d = np.hypot(*(true_xy - close_pass.truth.poses[t, :2]).T)
    assert np.all(d < 3 * near_range_of(close_pass.header, None))


def test_a_stream_with_no_near_bearing_is_solved_as_before(small: Stream) -> None:
    """Nothing near (the range at 0.1 mm; at the default 3 cm this stream has a few): the solves
    use the state's own graphs, bit for bit the rule switched off; and before the long mode
    the rule is not applied at all."""
    on = run(create_mapper("gtsam-batch", small.header, near_range_m=1e-4, **LONG_EARLY),
             small.steps, checkpoint_every=10)
    off = run(create_mapper("gtsam-batch", small.header, near_range_m=0.0, **LONG_EARLY),
              small.steps, checkpoint_every=10)
    short = run(create_mapper("gtsam-batch", small.header), small.steps, checkpoint_every=10)
    full = run(create_mapper("gtsam-batch", small.header, near_range_m=0.0), small.steps,
               checkpoint_every=10)
    assert "near_bearings_left_out" not in short.final.info
    for a, b in zip(short.checkpoints, full.checkpoints):
        assert np.array_equal(a.estimate.landmarks_xy, b.estimate.landmarks_xy)
    assert "near_bearings_left_out" not in on.final.info
    for a, b in zip(on.checkpoints, off.checkpoints):
        assert np.array_equal(a.estimate.landmarks_xy, b.estimate.landmarks_xy)
        assert np.array_equal(a.estimate.poses, b.estimate.poses)
