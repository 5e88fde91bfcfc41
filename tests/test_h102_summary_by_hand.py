"""The summary and the tables on results written by hand (h102's mutation audit).

The report tests run real sweeps, whose rows are fine for checking that failures are counted
but whose statistics are not worked out anywhere: a median computed as a mean, a wall time
median, a NEES median, the robot error over time of the last checkpoint only, landmarks
mapped of the first checkpoint, the experiment's last checkpoint of its shortest run, a CSV
or JSON table writing NaN as "nan" or its cells under the wrong column all passed them."""

from __future__ import annotations

import csv
import io
import json
import math

import pytest

from bomgraph.report import summarise
from bomgraph.tables import Column, format_table


def _run(run: str, cps: list[tuple], total_s: float, converged: bool | None = True,
         exp: str = "e", free: bool = False) -> dict:
    """A successful run; cps: (t, mpe_m, robot_last_m, nees_pose, n_mapped)."""
    keys = ("t", "mpe_m", "robot_last_m", "nees_pose", "n_mapped")
    rows = [dict(zip(keys, c), nees_landmark=math.nan) for c in cps]
    if free:
        for r in rows:
            r["bearing_rms_rad"] = 0.01
    return {"experiment": exp, "arm": "a", "method": "triangulate", "run": run, "ok": True,
            "checkpoints": rows, "total_s": total_s, "step_median_s": 0.001, "info": {},
            "converged": converged}


RESULTS = [
    _run("r1", [(10, 0.10, 0.5, 1.0, 3), (20, 0.01, 0.1, 2.0, 5)], 1.0),
    _run("r2", [(10, 0.20, 0.7, 3.0, 4), (20, 0.02, 0.3, 4.0, 6)], 2.0),
    _run("r3", [(10, 0.30, 0.9, 5.0, 5), (20, 0.09, 0.8, 9.0, 7)], 6.0, converged=False),
    {"experiment": "e", "arm": "a", "method": "triangulate", "run": "r4", "ok": False,
     "error": "ValueError: boom"},
]


def test_the_summary_row_by_hand() -> None:
    (row,) = summarise(RESULTS, times=(10,))
    assert (row["runs"], row["failed"], row["last_t"]) == (4, 1, 20)
    assert row["n_scored@10"] == 3 and row["n_scored@20"] == 3
    assert row["mpe_mean_m@20"] == pytest.approx(0.04)        # (0.01 + 0.02 + 0.09) / 3
    assert row["mpe_median_m@20"] == pytest.approx(0.02)
    assert row["mpe_std_m@20"] == pytest.approx(math.sqrt((0.03 ** 2 + 0.02 ** 2 + 0.05 ** 2) / 2))
    assert row["mpe_median_m@10"] == pytest.approx(0.20)
    assert row["robot_last_mean_m"] == pytest.approx(0.4)     # (0.1 + 0.3 + 0.8) / 3
    # each run's mean over its checkpoints (0.3, 0.5, 0.85), then their mean
    assert row["robot_over_time_mean_m"] == pytest.approx((0.3 + 0.5 + 0.85) / 3)
    assert row["nees_pose_mean"] == pytest.approx(5.0)        # (2 + 4 + 9) / 3
    assert row["converged_rate"] == pytest.approx(2 / 3)
    assert row["wall_s_mean"] == pytest.approx(3.0)           # (1 + 2 + 6) / 3


def test_the_last_checkpoint_is_the_experiments_longest_run() -> None:
    short = _run("r5", [(10, 0.4, 1.0, 1.0, 2)], 1.0)
    (row,) = summarise([*RESULTS[:3], short])
    assert row["last_t"] == 20
    # the short run's last value stands at t = 20 (its last checkpoint at or before 20)
    assert row["mpe_mean_m@20"] == pytest.approx((0.01 + 0.02 + 0.09 + 0.4) / 4)


def test_truth_free_runs_report_landmarks_mapped_at_the_end() -> None:
    free = [_run(f"f{k}", [(10, math.nan, math.nan, math.nan, 2 + k),
                           (20, math.nan, math.nan, math.nan, 10 + k)], 1.0, free=True)
            for k in range(2)]
    (row,) = summarise(free)
    assert row["n_mapped_mean"] == pytest.approx(10.5)


COLUMNS = [Column("arm", "arm"), Column("mpe_m", "MPE [cm]", 100.0, ".1f"),
           Column("n", "runs")]
ROWS = [{"arm": "a", "mpe_m": 0.0123, "n": 3}, {"arm": "b", "mpe_m": math.nan, "n": 0}]


def test_csv_and_json_tables_carry_raw_values_under_their_names() -> None:
    rows = list(csv.DictReader(io.StringIO(format_table(COLUMNS, ROWS, "csv"))))
    assert rows == [{"arm": "a", "mpe_m": "0.0123", "n": "3"}, {"arm": "b", "mpe_m": "", "n": "0"}]
    obj = json.loads(format_table(COLUMNS, ROWS, "json", meta={"title": "x"}))
    assert obj == {"title": "x", "rows": [{"arm": "a", "mpe_m": 0.0123, "n": 3},
                                          {"arm": "b", "mpe_m": None, "n": 0}]}


def test_write_csv_keeps_every_key_in_order_of_appearance(tmp_path) -> None:
    """summary.csv's columns: every key of every row, first seen first; lists joined by ';'
    (a key only a later row has, a failed run's errors, is a column too)."""
    from bomgraph.tables import write_csv

    rows = [{"arm": "a", "mpe_m": 0.01, "errors": []},
            {"arm": "b", "mpe_m": 0.02, "errors": ["E1: x", "E2: y"], "note": "late"}]
    write_csv(tmp_path / "s.csv", rows)
    text = (tmp_path / "s.csv").read_text()
    assert text.splitlines()[0] == "arm,mpe_m,errors,note"
    assert list(csv.DictReader(io.StringIO(text))) == [
        {"arm": "a", "mpe_m": "0.01", "errors": "", "note": ""},
        {"arm": "b", "mpe_m": "0.02", "errors": "E1: x;E2: y", "note": "late"}]
