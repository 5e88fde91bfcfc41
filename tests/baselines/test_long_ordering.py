"""The elimination ordering of the LM mappers' whole-graph solves (``long_ordering``): METIS
past ``lag_after_steps``, COLAMD before it (the paper runs) and in every window; a METIS
solve reaches the minimum a COLAMD solve reaches."""

from __future__ import annotations

import gtsam
import numpy as np
import pytest

import baselines.factor_graph as fg
from baselines.bearing_graph import FactorGraphConfig
from baselines.lm_report import ORDERINGS, lm_params, solve_lm
from bomgraph.errors import ConfigError
from bomgraph.mapper import create_mapper
from bomgraph.sim import SimConfig, simulate
from bomgraph.stream import Stream

#: The long mode from step 60 (as tests/baselines/test_finish.py): windows, whole-graph solves
#: when the graph has doubled, and finish()'s whole-graph solves at the end.
LONG = {"lag_after_steps": 60, "lag_steps": 20, "full_growth": 2.0}


@pytest.fixture(scope="module")
def stream() -> Stream:
    return simulate(SimConfig(n_steps=200, n_landmarks=30), np.random.default_rng(5))


def _orderings_used(monkeypatch: pytest.MonkeyPatch, mapper, stream: Stream
                    ) -> list[tuple[int, str, bool]]:
    """(steps, ordering, whole graph?) of every solve_lm call of a run with finish()."""
    seen: list[tuple[int, str, bool]] = []
    real = fg.solve_lm

    def spy(graph, *a, **k):
        # a window solve has its own graph and never_off; finish()'s put-back the state's graph
        whole = k.get("looks_off") is not fg.never_off or graph is mapper.state.graph
        seen.append((mapper.state.problem.n_steps, k.get("ordering", "colamd"), whole))
        return real(graph, *a, **k)

    monkeypatch.setattr(fg, "solve_lm", spy)
    for s in stream.steps:
        mapper.step(s)
    mapper.finish()
    return seen


@pytest.mark.parametrize("name", ["gtsam-batch", "oracle"])
def test_whole_graph_solves_past_the_long_mode_use_metis(name: str, stream: Stream,
                                                         monkeypatch: pytest.MonkeyPatch
                                                         ) -> None:
    mapper = create_mapper(name, stream.header, truth=stream.truth, **LONG)
    seen = _orderings_used(monkeypatch, mapper, stream)
    late_whole = [o for n, o, whole in seen if whole and n > LONG["lag_after_steps"]]
    assert late_whole and set(late_whole) == {"metis"}     # finish()'s two solves at least
    assert len(late_whole) >= 2
    assert {o for n, o, whole in seen if n <= LONG["lag_after_steps"]} == {"colamd"}
    assert {o for n, o, whole in seen if not whole} == {"colamd"}      # the windows
    assert mapper.estimate().info["converged"] is True


def test_long_ordering_colamd_keeps_colamd_everywhere(stream: Stream,
                                                      monkeypatch: pytest.MonkeyPatch) -> None:
    mapper = create_mapper("gtsam-batch", stream.header, long_ordering="colamd", **LONG)
    seen = _orderings_used(monkeypatch, mapper, stream)
    assert {o for _, o, _ in seen} == {"colamd"}


def test_the_final_map_is_the_same_minimum_in_either_ordering(stream: Stream) -> None:
    """Only the rounding of the eliminations differs: the finished maps agree to far below
    the map's accuracy (the whole graph's minimum with every bearing either way)."""
    maps = []
    for order in ("metis", "colamd"):
        mapper = create_mapper("gtsam-batch", stream.header, long_ordering=order, **LONG)
        for s in stream.steps:
            mapper.step(s)
        mapper.finish()
        maps.append(mapper.estimate())
    a, b = maps
    assert np.array_equal(a.landmark_ids, b.landmark_ids)
    assert np.max(np.abs(a.landmarks_xy - b.landmarks_xy)) < 1e-6
    assert abs(a.info["cost"] - b.info["cost"]) < 1e-6 * a.info["cost"]


def test_solve_lm_with_metis_is_gtsams_lm_in_that_ordering(stream: Stream) -> None:
    """``ordering="metis"``: the plain pass is GTSAM's LM given METIS's ordering, bit for bit."""
    mapper = create_mapper("gtsam-batch", stream.header, solve_every=10 ** 9)
    for s in stream.steps[:80]:
        mapper.step(s)
    state = mapper.state
    state.absorb()
    config = FactorGraphConfig(huber_k=None)
    values, report = solve_lm(state.graph, state.values, config, ordering="metis")
    params = lm_params(config)
    params.setOrdering(gtsam.Ordering.MetisNonlinearFactorGraph(state.graph))
    ref = gtsam.LevenbergMarquardtOptimizer(state.graph, state.values, params).optimize()
    assert report.iterations > 2
    assert all(np.array_equal(values.atPoint2(k) if _is_point(k) else values.atPose2(k).matrix(),
                              ref.atPoint2(k) if _is_point(k) else ref.atPose2(k).matrix())
               for k in ref.keys())


def _is_point(key: int) -> bool:
    return chr(gtsam.Symbol(key).chr()) == "l"


def test_the_orderings_by_name() -> None:
    assert set(ORDERINGS) == {"metis", "colamd"}
    with pytest.raises(ConfigError, match="long_ordering must be 'metis' or 'colamd'"):
        FactorGraphConfig(long_ordering="amd")
    assert FactorGraphConfig().long_ordering == "metis"
