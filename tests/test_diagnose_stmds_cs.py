"""``scripts/diagnose_stmds_cs.py``: its classical scaling of the final pairs is the method's own
map, and with the true distances it leaves only the completion's error."""

from __future__ import annotations

import pytest

from _scripts import load_script
from bomgraph.evaluate import score_estimate
from bomgraph.mapper import run
from bomgraph.sim import SimConfig, paper_design, simulate_run
from bomgraph.stmds.mapper import make_stmds_cs


@pytest.mark.parametrize("range_m", [1.0, 5.0])
def test_decomposition_reproduces_stmds_cs(range_m: float) -> None:
    mod = load_script("diagnose_stmds_cs")
    stream = simulate_run(paper_design(0)[0], SimConfig(n_landmarks=20, n_steps=120,
                                                        sensor_range_m=range_m))
    row = mod.diagnose(stream, "paper", n_draws=3)
    own = run(make_stmds_cs(stream.header), stream.steps).final
    assert row["cs"] == pytest.approx(100 * score_estimate(own, stream.truth).mpe_m, rel=1e-9)
    if range_m > 2.5 * 2 ** 0.5:      # every pair seen together: nothing to complete
        assert row["known %"] == 100.0 and row["cs true"] < 1e-6
    else:                             # shortest paths over a 1 m range: longer than the truth
        assert row["known %"] < 100.0 and row["cs true"] > 0.1
    assert row["synthetic"] > 0 and row["smacof 1/var"] > 0
