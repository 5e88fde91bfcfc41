"""scripts/bench_speed.py: the derived row that carries issue 14's STMDS reference over
through the warm LM loop, and the table it prints (issue 14 item 4)."""

from __future__ import annotations


import pytest

pytest.importorskip("gtsam")

from _scripts import load_script  # noqa: E402  (tests/_scripts.py)

bench = load_script("bench_speed")


def test_the_issue_machine_itself_gives_the_issue_ratio() -> None:
    # the issue's own numbers (stmds 0.13 s, loop 1.89 s) must come back as its 0.61x
    rows = [{"section": "paper", "method": "loop-warm-lm", "cpu_s": 1.89},
            {"section": "paper", "method": "stmds-smacof", "cpu_s": 0.13}]
    derived = bench.stmds_vs_issue_reference(rows)
    assert derived["ratio"] == pytest.approx(0.61)
    assert derived["reference_cpu_s"] == pytest.approx(0.13 / 0.61)


def test_a_machine_twice_as_fast_with_stmds_three_times_as_fast_gains_a_factor_of_1_5() -> None:
    rows = [{"section": "paper", "method": "loop-warm-lm", "cpu_s": 1.89 / 2},
            {"section": "paper", "method": "stmds-smacof", "cpu_s": 0.13 / 3}]
    assert bench.stmds_vs_issue_reference(rows)["ratio"] == pytest.approx(0.61 / 1.5)
    print(bench.table(rows + [bench.stmds_vs_issue_reference(rows)]))


def test_no_row_without_the_loop_or_the_method() -> None:
    assert bench.stmds_vs_issue_reference([{"method": "stmds-smacof", "cpu_s": 0.1}]) is None
    assert bench.stmds_vs_issue_reference([{"method": "loop-warm-lm", "cpu_s": 2.0}]) is None
