"""The hybrid's two starts at one update solve the same problem, so their costs compare.

Past ``lag_after_steps`` the schedule (:meth:`baselines.factor_graph.BatchState.solve`)
solves either the whole graph (each time it has grown by ``full_growth``) or a fixed-lag
window. Before the twenty-second session a warm whole-graph solve recorded the graph's size,
after which the seed start of the same update went to a window: its cost (the window's
factors and marginal) was not the whole graph's and always the lower, so the whole-graph
solution was dropped whatever it was worth. On MRCLAM1 robots 2 and 5 at 0.1 m / 10° this
happened at 3 updates (e.g. step 621 of robot 2: whole 570.3 against window 477.3).

The check records every solve of each update with its mode and the size of the graph it
solved (not through the hybrid's own bookkeeping). The test failed before the fix ("step 41:
warm whole, seed window").
"""

from __future__ import annotations

import gtsam
import numpy as np
import pytest

from baselines import factor_graph
from bomgraph import create_mapper
from bomgraph.sim import SimConfig, simulate


def test_both_starts_of_an_update_solve_the_same_graph(monkeypatch: pytest.MonkeyPatch) -> None:
    calls: list[tuple[int, bool, gtsam.Values, int]] = []
    real = factor_graph.BatchState.solve

    def recording(self, initial, warm=False, adopt=False):
        values, report = real(self, initial, warm, adopt)
        window = report.passes[:1] == ("window",)
        calls.append((self.problem.n_steps, window, values, self.solved_graph.nrFactors()))
        return values, report

    monkeypatch.setattr(factor_graph.BatchState, "solve", recording)
    stream = simulate(SimConfig(n_steps=120), np.random.default_rng(5003))
    # a short lag and every seed start solved: updates with a whole-graph warm solve and a
    # seed start, past the lag
    mapper = create_mapper("hybrid", stream.header, lag_after_steps=40, lag_steps=20,
                           start_tol_m=0.0)
    for step in stream.steps:
        mapper.step(step)
    mapper.estimate()
    by_update: dict[int, list[tuple[bool, gtsam.Values, int]]] = {}
    for n, window, values, n_factors in calls:
        by_update.setdefault(n, []).append((window, values, n_factors))
    both = {n: c for n, c in by_update.items() if len(c) == 2 and n > 40}
    whole_both = [n for n, c in both.items() if not c[0][0]]
    assert whole_both, "the case (a whole-graph warm solve and a seed start past the lag)"
    for n, ((w_warm, _, f_warm), (w_seed, _, f_seed)) in both.items():
        assert w_warm == w_seed, f"step {n}: warm {'window' if w_warm else 'whole'}, seed " \
                                 f"{'window' if w_seed else 'whole'}"
        assert f_warm == f_seed, f"step {n}: the starts solved graphs of {f_warm} and {f_seed}"
