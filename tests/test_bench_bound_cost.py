"""scripts/bench_bound_cost.py: a method's solution against the oracle's on the oracle's graph."""

from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np

from bomgraph.sim import SimConfig, simulate
from bomgraph.stream_file import write_stream

from _scripts import load_script  # noqa: E402  (tests/_scripts.py)

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "scripts"))
bench = load_script("bench_bound_cost")


def test_verdict_bands() -> None:
    assert bench.verdict(90.0, 100.0) == "lower cost than the oracle"
    assert bench.verdict(110.0, 100.0) == "higher cost than the oracle"
    assert bench.verdict(100.005, 100.0) == "the oracle's cost"      # within 0.01
    assert bench.verdict(1000.05, 1000.0) == "the oracle's cost"     # within 1e-4 relative
    assert bench.verdict(math.nan, 100.0).startswith("not comparable")


def test_compare_evaluates_both_graphs_at_both_solutions(tmp_path: Path) -> None:
    """On a small simulated stream ``gtsam-batch`` and the oracle build the same graph: each
    graph gives the same cost at either solution, and the verdict follows the costs."""
    stream = simulate(SimConfig(n_steps=60, n_landmarks=15), np.random.default_rng(2))
    path = tmp_path / "s.jsonl"
    write_stream(stream, path)
    (row,) = bench.compare(path, ["gtsam-batch"])
    assert row["same_graph"] and row["n_factors"] == row["oracle_n_factors"]
    assert math.isclose(row["cost"], row["oracle_cost_at_method"], rel_tol=1e-9)
    assert row["verdict"] == bench.verdict(row["oracle_cost_at_method"], row["oracle_cost"])
    assert row["n_mapped"] == row["oracle_n_mapped"] > 5
    assert 0 < row["mpe_m"] < 0.2 and math.isclose(row["ratio"],
                                                    row["mpe_m"] / row["oracle_mpe_m"])
