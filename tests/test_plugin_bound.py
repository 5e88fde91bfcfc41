"""An installed plugin can be a benchmark bound, as ``oracle`` is: its factory says
``needs_truth = True`` (an entry point cannot carry the flag). It is then given ``truth=``,
listed as reading the truth, and refused where the truth is not allowed."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from _plugin_dist import installed

from bomgraph import mapper
from bomgraph.bench import run_file
from bomgraph.errors import ConfigError
from bomgraph.method_list import method_listing
from bomgraph.sim import SimConfig, simulate
from bomgraph.stream_file import write_stream

MODULE = '''
from bomgraph.mapper import MapEstimate


class TruthMap:
    """the true landmarks, seen or not (a bound)"""

    needs_truth = True

    def __init__(self, header, *, truth):
        self.truth = truth

    def step(self, step):
        pass

    def estimate(self):
        return MapEstimate(self.truth.landmark_ids, self.truth.landmarks_xy)


class Plain(TruthMap):
    needs_truth = "yes"             # not True: not a bound

    def __init__(self, header):
        self.truth = None
'''


@pytest.fixture()
def bound(tmp_path: Path, monkeypatch: pytest.MonkeyPatch):
    yield from installed(tmp_path, monkeypatch, "h20bound", MODULE,
                         {"truth-map": "h20bound:TruthMap", "plain-map": "h20bound:Plain"})


def test_a_plugin_bound_is_given_the_truth_and_refused_without_it(bound: Path) -> None:
    assert mapper.method_info("truth-map").needs_truth is True
    assert mapper.method_info("plain-map").needs_truth is False
    row = method_listing(mapper.method_info("truth-map"))
    assert row["needs_truth"] is True and row["origin"] == "plugin"
    stream = simulate(SimConfig(n_steps=10, n_landmarks=6), np.random.default_rng(1))
    with pytest.raises(ConfigError, match="reads the ground truth"):
        mapper.create_mapper("truth-map", stream.header)
    est = mapper.run(mapper.create_mapper("truth-map", stream.header, truth=stream.truth),
                     stream.steps).final
    assert (est.landmarks_xy == stream.truth.landmarks_xy).all()
    path = bound / "s.jsonl"
    write_stream(stream, path)
    with pytest.raises(ConfigError, match="benchmark bound"):
        run_file(path, "truth-map")
    assert len(run_file(path, "truth-map", allow_truth=True).final) == 6
