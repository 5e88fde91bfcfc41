"""scripts/bench_gtsam_arms.py: the warm-started oracle variant, the lambda carry and the
comparison table (issue 14)."""

from __future__ import annotations


import pytest

pytest.importorskip("gtsam")

import baselines.lm_report as lm_report  # noqa: E402
from bomgraph.mapper import create_mapper, run  # noqa: E402
from bomgraph.sim import SimConfig, paper_design, simulate_run  # noqa: E402

from _scripts import load_script  # noqa: E402  (tests/_scripts.py)

bench = load_script("bench_gtsam_arms")

SMALL = SimConfig(n_steps=60, n_landmarks=20)


@pytest.fixture(scope="module")
def stream():
    return simulate_run(paper_design(0)[0], SMALL)


def test_warm_oracle_starts_from_its_last_solution_and_reaches_the_cold_cost(stream) -> None:
    cold = run(create_mapper("oracle", stream.header, truth=stream.truth), stream.steps)
    warm_mapper = bench.WarmOracle(stream.header, truth=stream.truth)
    warm = run(warm_mapper, stream.steps)
    assert warm_mapper._solved_n == len(stream.steps)
    for a, b in zip(warm.checkpoints, cold.checkpoints):
        assert a.estimate.info["converged"] and b.estimate.info["converged"]
        # the same graph: the cold start's minimum is reached to 0.5 % of the cost
        assert a.estimate.info["cost"] == pytest.approx(b.estimate.info["cost"], rel=5e-3)
    # and the starts differ after the first checkpoint (not the cold run in disguise)
    assert any(a.estimate.info["initial_cost"] != b.estimate.info["initial_cost"]
               for a, b in zip(warm.checkpoints[1:], cold.checkpoints[1:]))


def test_lambda_carry_wraps_the_optimizer_only_inside_the_block(stream) -> None:
    # solve_lm (baselines/lm_report.py) builds the optimizers: the wrap must reach it there
    saved = lm_report.gtsam
    with bench.lambda_carry(1.0):
        assert lm_report.gtsam is not saved
        assert lm_report.gtsam.LevenbergMarquardtOptimizer.__name__ == "Carried"
        row = bench.one("gtsam-batch", "lambda-carry", stream, "small", 1.0)
    assert lm_report.gtsam is saved
    assert row["checkpoints"][-1]["iterations"] >= 1
    base = bench.one("gtsam-batch", "default", stream, "small", 1.0)
    assert [c["t"] for c in row["checkpoints"]] == [c["t"] for c in base["checkpoints"]]


def test_compare_counts_identical_runs_and_the_worst_mpe_change() -> None:
    def row(variant: str, name: str, mpes: list[float], tag: str) -> dict:
        return {"arm": "oracle", "variant": variant, "run": name, "cpu_s": 1.0,
                "checkpoints": [{"t": 10 * (k + 1), "mpe_m": m, "hash": f"{tag}{k}",
                                 "iterations": 2} for k, m in enumerate(mpes)]}
    rows = [row("default", "a", [0.01, 0.02], "x"), row("default", "b", [0.01, 0.01], "y"),
            row("oracle-warm", "a", [0.01, 0.02], "x"),
            row("oracle-warm", "b", [0.01, 0.013], "z")]
    text = bench.compare(rows)
    warm = [line for line in text.splitlines() if "oracle-warm" in line][0]
    assert "identical  1/2" in warm and "30.00% b" in warm


def _row(arm: str, variant: str, run_name: str, mpe: dict[int, float]) -> dict:
    return {"arm": arm, "variant": variant, "run": run_name, "cpu_s": 1.0,
            "checkpoints": [{"t": t, "mpe_m": m, "hash": f"{variant}{t}{m}",
                             "iterations": 3, "passes": ["plain"], "starts": None,
                             "cost": 1.0} for t, m in mpe.items()]}


def test_table_cells_are_the_mean_and_median_over_runs_at_the_table_checkpoints() -> None:
    rows = [_row("oracle", "default", f"r{k}", {50: 0.01 * (k + 1), 60: 9.0, 300: 0.02})
            for k in range(3)]
    cells = bench.table_cells(rows)[("oracle", "default")]
    assert cells["mean@50"] == pytest.approx(0.02) and cells["median@50"] == pytest.approx(0.02)
    assert cells["mean@300"] == pytest.approx(0.02)
    assert "mean@60" not in cells and "mean@100" not in cells   # not a table checkpoint


def test_compare_tables_reports_the_worst_cell_change_against_the_default() -> None:
    base = [_row("oracle", "default", f"r{k}", {50: 0.01, 300: 0.02}) for k in range(4)]
    # one run of four 40 % worse at t = 300: the mean cell moves by 10 %, the median by 0
    mine = [_row("oracle", "tol", f"r{k}", {50: 0.01, 300: 0.028 if k == 0 else 0.02})
            for k in range(4)]
    text = bench.compare_tables(base + mine)
    line = next(x for x in text.splitlines() if " tol " in x)
    assert "worst change +10.00% (mean@300)" in line
    assert "worst increase +10.00% (mean@300)" in line
    assert "2.20/2.00" in line        # the t = 300 cell, cm: mean / median
