"""Cadence independence of the LM mappers (issue 15, item 1): ``gtsam-batch``, ``oracle`` and
``hybrid`` admit landmarks and solve on their own schedule (``solve_every``), so the map at the
last step is the same, within 5 % in MPE and with the same landmarks, whether ``estimate()`` was
called every step, every 10 steps or only at the end. On a simulated run of the paper's setup
and on MRCLAM6 robot 3 as ``bomgraph import mrclam`` makes it (skipped without the data)."""

from __future__ import annotations


import numpy as np
import pytest

from bomgraph.evaluate import score_estimate
from bomgraph.mapper import create_mapper, run
from bomgraph.stream import Stream

from _cadence_streams import mrclam6_robot3, simulated_run  # tests/_cadence_streams.py

METHODS = ("gtsam-batch", "oracle", "hybrid")
CADENCES = (1, 10, 10 ** 6)      # every step, the paper's, only at the end


simulated = pytest.fixture(simulated_run, scope="module", name="simulated")
mrclam6 = pytest.fixture(mrclam6_robot3, scope="module", name="mrclam6")


def final_maps(name: str, stream: Stream) -> dict[int, tuple[np.ndarray, float, dict]]:
    out = {}
    for every in CADENCES:
        est = run(create_mapper(name, stream.header, truth=stream.truth), stream.steps,
                  checkpoint_every=every, keep_checkpoints=False).final
        out[every] = (est.landmark_ids, score_estimate(est, stream.truth).mpe_m, est.info)
    return out


def check_cadence_independent(name: str, stream: Stream) -> None:
    maps = final_maps(name, stream)
    ids10, mpe10, _ = maps[10]
    assert ids10.size >= 5
    for every, (ids, mpe, info) in maps.items():
        assert info["n_landmarks"] >= maps[10][2]["n_landmarks"] - 1, every
        assert np.isin(ids10, ids).mean() >= 0.95, every
        assert abs(mpe - mpe10) <= 0.05 * mpe10, (every, mpe, mpe10)
    # asked only at the end, the solve is the scheduled one: the same map bit for bit
    np.testing.assert_array_equal(maps[10 ** 6][0], ids10)


@pytest.mark.parametrize("name", METHODS)
def test_simulated_map_does_not_depend_on_the_estimate_cadence(name: str,
                                                               simulated: Stream) -> None:
    check_cadence_independent(name, simulated)


@pytest.mark.parametrize("name", METHODS)
def test_recorded_map_does_not_depend_on_the_estimate_cadence(name: str,
                                                              mrclam6: Stream) -> None:
    check_cadence_independent(name, mrclam6)
