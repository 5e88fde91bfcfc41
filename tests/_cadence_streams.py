"""The two streams of the cadence-independence tests (issue 15, item 1;
tests/baselines/test_cadence.py, tests/stmds/test_stmds_cadence.py): a 60-step simulated run
of the paper's setup, and MRCLAM6 robot 3 as ``bomgraph import mrclam`` makes it (skipped
without the data)."""

from __future__ import annotations

import pytest

from bomgraph.sim import SimConfig, paper_design, simulate_run
from bomgraph.stream import Stream
from _shared_data import DATA, missing  # tests/_shared_data.py


def simulated_run() -> Stream:
    return simulate_run(paper_design(0)[1], SimConfig(n_steps=60))


def mrclam6_robot3() -> Stream:
    if not (DATA / "mrclam6").is_dir():
        pytest.skip(missing("mrclam6"))
    from bomgraph.datasets.mrclam import import_mrclam
    return import_mrclam(DATA / "mrclam6", 3)
