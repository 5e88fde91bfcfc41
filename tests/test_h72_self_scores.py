"""h72: ``compare --reference A`` on streams without ground truth, where A (or an arm of A's
method and options) is also compared; each test fails before h72's fix:

* the summary (printed and summary.csv) averaged the reference's scores against its own
  final map (``0.00/0.00±0.00``, ``mpe_median_m@60`` 1e-16: a perfect method), and the
  error-vs-time figures drew its curve falling to 0;
* an arm of the reference's method and options at another checkpoint cadence showed
  ``0.0 (n)`` in the by-run table, and its paired note called it "the --reference";
* a reference that raised on a stream was run again for each other arm on that stream.
"""

from __future__ import annotations

import csv
import dataclasses
import json
import math
from pathlib import Path

import numpy as np
import pytest

from bomgraph import run_scoring
from bomgraph.bench import Executor
from bomgraph.cli import main
from bomgraph.experiments import compare_experiments
from bomgraph.figures import _results_data
from bomgraph.report import compare, error_curves, final_by_run, format_by_run, summarise
from bomgraph.sim import SimConfig, simulate
from bomgraph.stream_file import write_stream

from _runtime_method import runtime_method

FAILING = '''\
from baselines.triangulate import TriangulateMapper

MADE = []


class Failing(TriangulateMapper):
    """triangulate that raises at its first step, counting its runs"""

    def __init__(self, header, **options):
        super().__init__(header, **options)
        MADE.append(1)

    def step(self, step):
        raise RuntimeError("no map today")
'''


def _streams(tmp_path: Path, n: int, *, truth: bool = False) -> list[str]:
    paths = []
    for seed in range(n):
        stream = simulate(SimConfig(n_steps=60), np.random.default_rng(seed))
        path = tmp_path / f"{'t' if truth else 'nt'}{seed}.jsonl"
        write_stream(stream if truth else dataclasses.replace(stream, truth=None), path)
        paths.append(str(path))
    return paths


def test_the_references_own_scores_are_no_summary_and_no_curve(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "out"
    assert main(["compare", "--streams", *_streams(tmp_path, 3), "--methods",
                 "triangulate,stmds-cs", "--reference", "triangulate", "--jobs", "1",
                 "--no-figures", "--out", str(out)]) == 0
    text = capsys.readouterr().out
    line = next(x for x in text.splitlines() if x.startswith("triangulate "))
    assert "0.00/0.00±0.00" not in line and line.split()[2:4] == ["-/-±-[0/3]"] * 2, line
    with open(out / "summary.csv", newline="") as fh:
        rows = {r["arm"]: r for r in csv.DictReader(fh)}
    assert rows["triangulate"]["n_scored@60"] == "0"
    for key in ("mpe_mean_m@60", "mpe_median_m@60", "robot_last_mean_m"):
        assert math.isnan(float(rows["triangulate"][key])), (key, rows["triangulate"][key])
    assert float(rows["stmds-cs"]["mpe_median_m@60"]) > 1e-3  # the others: scores
    assert rows["triangulate"]["n_mapped_mean"] and rows["triangulate"]["bearing_rms_mean_rad"]
    saved = json.loads((out / "results.json").read_text())
    own = [r for r in saved["results"] if r["arm"] == "triangulate"]
    assert {r["self_scored"] for r in own} == {"itself"}  # marked, its values kept there
    assert all(r["checkpoints"][-1]["mpe_m"] < 1e-9 for r in own)
    curves = error_curves(saved["results"])
    assert np.all(np.isnan(curves[("streams", "triangulate")][1]))  # was 1e-16 at the end
    assert np.all(np.isfinite(curves[("streams", "stmds-cs")][1][:, -1]))
    final, _, titles = _results_data(saved, out / "results.json", [])  # `bomgraph plot`
    assert "triangulate" not in final["streams"] and "not drawn: triangulate" in titles[
        "streams"]


def test_an_arm_of_the_references_method_at_another_cadence_is_no_score(
        tmp_path: Path) -> None:
    (tmp_path / "sweep.toml").write_text(
        f"streams = {json.dumps(_streams(tmp_path, 2))}\n"
        'reference = { name = "triangulate", checkpoint_every = 5 }\n'
        'methods = ["triangulate", "ekf", "stmds-cs"]\n')
    exps, _ = compare_experiments(config=str(tmp_path / "sweep.toml"))
    result = compare(exps, tmp_path / "out", executor=Executor("serial"), figures=False)
    table = format_by_run(final_by_run(result.results))
    line = next(x for x in table.splitlines() if x.startswith("triangulate "))
    assert line.split()[1::2] == ["reference", "reference"], line  # was 0.0 (47) 0.0 (48)
    tri = next(s for s in result.summary if s["arm"] == "triangulate")
    assert tri["n_scored@60"] == 0 and math.isnan(tri["mpe_median_m@60"])
    assert "no score" in tri["scored_against"]
    note = next(p.note for p in result.paired if p.arm == "triangulate")
    assert "runs the --reference's method and options at another checkpoint cadence" in note
    assert "is the --reference" not in note, note
    with open(tmp_path / "out" / "final_by_run.csv", newline="") as fh:
        rows = [r for r in csv.DictReader(fh) if r["arm"] == "triangulate"]
    assert {r["self_scored"] for r in rows} == {"method"} and {r["mpe_m"] for r in rows} == {
        "nan"}


@pytest.fixture
def failing(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> list:
    """The run-time method ``failing``; its list of runs."""
    for module in runtime_method(tmp_path, monkeypatch, "failing", "bomgraph_h72_failing", FAILING, "Failing"):
        yield module.MADE


@pytest.mark.parametrize("methods", ["triangulate,ekf,stmds-cs", "triangulate,failing,ekf"])
def test_a_failed_reference_runs_once_a_stream(tmp_path: Path, failing: list,
                                                methods: str) -> None:
    paths = _streams(tmp_path, 2)
    exps, _ = compare_experiments(streams=paths, methods=methods, reference="failing")
    result = compare(exps, tmp_path / "out", executor=Executor("serial"), figures=False)
    assert len(failing) == 2, f"{len(failing)} runs of the reference on 2 streams"  # 6
    others = [r for r in result.results if r["arm"] != "failing"]
    assert len(others) == 2 * len(set(methods.split(",")) - {"failing"})
    assert not any(r["ok"] for r in others)
    assert {r["error"] for r in others} == {
        "reference failing failed: RuntimeError: no map today (raised in Failing.step() "
        "at t = 0)"}
    assert all("no map today" in r["traceback"] for r in others)


def test_runs_with_truth_are_left_as_they_are(tmp_path: Path) -> None:
    exps, _ = compare_experiments(streams=_streams(tmp_path, 2, truth=True),
                                  methods="triangulate,stmds-cs", reference="triangulate")
    result = compare(exps, tmp_path / "out", executor=Executor("serial"), figures=False)
    assert not any("self_scored" in r or "scored_against" in r for r in result.results)
    assert all(run_scoring.scores_left_out(r) is r for r in result.results)
    tri = next(s for s in summarise(result.results) if s["arm"] == "triangulate")
    assert tri["n_scored@60"] == 2 and tri["mpe_median_m@60"] > 1e-3
