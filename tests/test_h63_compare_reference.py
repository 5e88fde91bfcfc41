"""h63: ``compare --reference ARM`` where ARM is also one of the compared arms, on streams
without ground truth (each fails before h63's fix):

* the paired table came out empty: it paired every arm with ARM, whose runs are scored
  against its own map (no score), so "no run scored by both" on every row; now the other
  arms are paired with one another (their errors against ARM's map), and ARM's row says
  why it is no pair;
* a reference labelled otherwise than its arm (a sweep file's ``label``) was not seen to be
  scored against itself: ratios of ~1e15 came back (h58's bug, by another road);
* ARM ran twice on each stream (once as the arm, once as the reference), and arm by arm it
  ran again for each other arm once more than 8 streams were compared; now once a stream,
  the same rows bit for bit;
* ``bomgraph.cli.main(["compare", ..., "--dask-local", "1"])`` in the caller's process left
  Dask's loggers at CRITICAL for good.
"""

from __future__ import annotations

import dataclasses
import importlib
import json
import logging
import math
from pathlib import Path

import numpy as np
import pytest

from bomgraph import run_scoring
from bomgraph.bench import Executor
from bomgraph.cli import main
from bomgraph.evaluate import score_checkpoints
from bomgraph.experiments import compare_experiments
from bomgraph.mapper import create_mapper, run
from bomgraph.report import compare
from bomgraph.sim import SimConfig, simulate
from bomgraph.stream_file import read_stream, write_stream

from _runtime_method import runtime_method

COUNTED = '''\
from baselines.triangulate import TriangulateMapper

MADE = []


class Counted(TriangulateMapper):
    """triangulate, counting its runs"""

    def __init__(self, header, **options):
        super().__init__(header, **options)
        MADE.append(1)
'''


def _streams(tmp_path: Path, n: int, n_steps: int = 30) -> list[str]:
    """``n`` simulated streams written without their truth."""
    paths = []
    for seed in range(n):
        stream = simulate(SimConfig(n_steps=n_steps), np.random.default_rng(seed))
        path = tmp_path / f"notruth{seed}.jsonl"
        write_stream(dataclasses.replace(stream, truth=None), path)
        paths.append(str(path))
    return paths


@pytest.fixture
def counted(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> list:
    """The run-time method ``counted`` (triangulate); its list of runs."""
    for module in runtime_method(tmp_path, monkeypatch, "counted", "bomgraph_h63_counted", COUNTED, "Counted"):
        yield module.MADE


def _rows(checkpoints: list) -> list[dict]:
    return [{k: v for k, v in c.items() if k not in ("estimate_s", "bearing_rms_rad")}
            for c in checkpoints]


def _own_scores(path: str) -> list[dict]:
    """The rows of the reference's run scored against its own final map, from a run of its
    own (what compare did with a second run before)."""
    stream = read_stream(path)
    whole = run(create_mapper("triangulate", stream.header), stream.steps, checkpoint_every=10)
    return _rows([dataclasses.asdict(s) for s in score_checkpoints(whole, whole.final)])


def test_the_reference_arm_runs_once_a_stream_and_scores_as_before(
        tmp_path: Path, counted: list) -> None:
    paths = _streams(tmp_path, 9)  # more than the 8 reference maps a process keeps
    exps, _ = compare_experiments(streams=paths, methods="triangulate,counted,stmds-cs",
                                  reference="counted")
    result = compare(exps, tmp_path / "out", executor=Executor("serial"), figures=False)
    assert len(counted) == 9, f"{len(counted)} runs of the reference on 9 streams"  # was 36
    own = [r for r in result.results if r["arm"] == "counted"]
    assert {r["scored_against"] for r in own} == {"itself (reference counted)"}
    assert {r["scored_against"] for r in result.results if r["arm"] != "counted"} == {
        "reference counted"}
    first = next(r for r in own if r["run"] == Path(paths[0]).stem)
    assert json.dumps(_rows(first["checkpoints"])) == json.dumps(_own_scores(paths[0]))


def test_maps_too_large_to_keep_run_the_reference_again_for_the_same_rows(
        tmp_path: Path, counted: list, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(run_scoring, "MAX_KEPT_BYTES", 1)
    paths = _streams(tmp_path, 1)
    exps, _ = compare_experiments(streams=paths, methods="counted", reference="counted")
    result = compare(exps, tmp_path / "out", executor=Executor("serial"), figures=False)
    assert len(counted) == 2
    (res,) = result.results
    assert json.dumps(_rows(res["checkpoints"])) == json.dumps(_own_scores(paths[0]))


def test_the_others_are_paired_with_one_another_when_the_reference_is_an_arm(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    paths = _streams(tmp_path, 2, n_steps=60)
    out = tmp_path / "out"
    assert main(["compare", "--streams", *paths, "--methods", "stmds-cs,triangulate,"
                 "stmds-smacof", "--reference", "triangulate", "--jobs", "1", "--no-figures",
                 "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert "paired against stmds-cs" in text, text
    rows = {r["arm"]: r for r in json.loads((out / "results.json").read_text())["paired"]["rows"]}
    assert rows["stmds-smacof"]["reference"] == "stmds-cs"
    assert rows["stmds-smacof"]["n_pairs"] == 2 and rows["stmds-smacof"]["ratio_of_means"] > 0
    assert rows["triangulate"]["n_pairs"] == 0
    assert "triangulate is the --reference, scored against its own map on 2 of 2" in rows[
        "triangulate"]["note"]
    assert "reference (" in text  # the by-run table: its own run, no 0.0 error
    # asked for by name, it stays, and each row says why there is no pair
    assert main(["compare", "--streams", *paths, "--methods", "stmds-cs,triangulate,"
                 "stmds-smacof", "--reference", "triangulate", "--paired-reference",
                 "triangulate", "--jobs", "1", "--no-figures", "--out", str(out)]) == 0
    paired = json.loads((out / "results.json").read_text())["paired"]["rows"]
    assert {r["reference"] for r in paired} == {"triangulate"}
    assert all(r["n_pairs"] == 0 and "pair them with one another" in r["note"] for r in paired)
    capsys.readouterr()


def test_a_reference_labelled_otherwise_is_still_no_pair(tmp_path: Path) -> None:
    paths = _streams(tmp_path, 2, n_steps=60)
    (tmp_path / "sweep.toml").write_text(
        f'streams = {json.dumps(paths)}\nreference = "triangulate"\n'
        '[[methods]]\nname = "triangulate"\nlabel = "tri"\n'
        '[[methods]]\nname = "stmds-cs"\n[[methods]]\nname = "stmds-smacof"\n')
    exps, _ = compare_experiments(config=str(tmp_path / "sweep.toml"))
    result = compare(exps, tmp_path / "out", executor=Executor("serial"), figures=False)
    ratios = [p.ratio_of_means for p in result.paired if p.ratio_of_means is not None]
    assert ratios and all(math.isfinite(x) and x < 1e3 for x in ratios), ratios  # were 1e15
    assert {r["scored_against"] for r in result.results if r["arm"] == "tri"} == {
        "itself (reference triangulate)"}


def test_main_gives_back_the_callers_dask_logger_levels(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    importlib.import_module("distributed")  # the caller uses Dask: its loggers configured

    names = ["distributed", "distributed.client", "distributed.scheduler",
             "distributed.worker"]
    logging.getLogger("distributed.scheduler").setLevel(logging.DEBUG)  # the caller's own
    try:
        before = {n: logging.getLogger(n).level for n in names}
        assert main(["compare", "--streams", *_streams(tmp_path, 1), "--methods",
                     "triangulate", "--dask-local", "1", "--no-figures", "--out",
                     str(tmp_path / "out")]) == 0
        assert {n: logging.getLogger(n).level for n in names} == before  # were CRITICAL
    finally:
        logging.getLogger("distributed.scheduler").setLevel(logging.NOTSET)
    capsys.readouterr()
