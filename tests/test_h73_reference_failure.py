"""h73: a reference that failed on a stream is remembered in the process (h72) so that the
other arms' runs there fail at once with its error; that memory outlived the sweep. Each test
fails before h73's fix: a library user who fixed the reference (its module edited and
reloaded) or what it failed on (a file it reads) and ran compare again in the same Python
session got the old failure for every other arm, though a failure is never cached."""

from __future__ import annotations

import csv
import dataclasses
import importlib
import json
import sys
from pathlib import Path

import numpy as np
import pytest

from bomgraph import mapper, run_scoring
from bomgraph.bench import Executor
from bomgraph.experiments import compare_experiments
from bomgraph.figures import _results_data
from bomgraph.method_code import new_sweep
from bomgraph.report import compare
from bomgraph.sim import SimConfig, simulate
from bomgraph.stream_file import write_stream

FLAKY = '''\
import os

from baselines.triangulate import TriangulateMapper

BROKEN = {broken}


class Flaky(TriangulateMapper):
    """triangulate that raises at its first step while BROKEN or while a file is there"""

    def step(self, step):
        if BROKEN or os.path.exists({blocker!r}):
            raise RuntimeError("no map today")
        return super().step(step)
'''


def _streams(tmp_path: Path, n: int) -> list[str]:
    paths = []
    for seed in range(n):
        stream = simulate(SimConfig(n_steps=40), np.random.default_rng(seed))
        path = tmp_path / f"nt{seed}.jsonl"
        write_stream(dataclasses.replace(stream, truth=None), path)
        paths.append(str(path))
    return paths


@pytest.fixture
def flaky(tmp_path: Path, monkeypatch: pytest.MonkeyPatch):
    """Writes the run-time method ``flaky`` (``write(broken)``) and registers it; the file
    whose presence also makes it fail."""
    code = tmp_path / "code"
    code.mkdir()
    blocker = tmp_path / "blocker"
    module = code / "bomgraph_h73_flaky.py"
    monkeypatch.syspath_prepend(str(code))
    monkeypatch.setattr(mapper, "_REGISTRY", dict(mapper._REGISTRY))
    monkeypatch.setattr(run_scoring, "_REFERENCES", {})

    def write(broken: bool) -> None:
        module.write_text(FLAKY.format(broken=broken, blocker=str(blocker)))

    write(False)
    mapper.register_method("flaky", "bomgraph_h73_flaky:Flaky")
    yield write, blocker
    sys.modules.pop("bomgraph_h73_flaky", None)


def _compare(tmp_path: Path, paths: list[str], name: str) -> list[dict]:
    exps, _ = compare_experiments(streams=paths, methods="ekf,triangulate",
                                  reference="flaky")
    return list(compare(exps, tmp_path / name, executor=Executor("serial"),
                        figures=False).results)


def test_a_reference_fixed_and_reloaded_is_run_again(tmp_path: Path, flaky) -> None:
    write, _ = flaky
    paths = _streams(tmp_path, 2)
    write(True)
    import bomgraph_h73_flaky
    importlib.reload(bomgraph_h73_flaky)
    first = _compare(tmp_path, paths, "out1")
    assert not any(r["ok"] for r in first) and all("no map today" in r["error"] for r in first)
    write(False)  # the user fixes the method and reloads it
    importlib.reload(bomgraph_h73_flaky)
    second = _compare(tmp_path, paths, "out2")
    assert all(r["ok"] for r in second), {r.get("error") for r in second}  # the old failure
    assert {r["scored_against"] for r in second} == {"reference flaky"}


def test_a_failed_reference_is_run_again_by_the_next_compare(tmp_path: Path, flaky) -> None:
    _, blocker = flaky
    paths = _streams(tmp_path, 2)
    blocker.write_text("")  # what it fails on: not its code
    first = _compare(tmp_path, paths, "out1")
    assert not any(r["ok"] for r in first)
    blocker.unlink()
    second = _compare(tmp_path, paths, "out2")  # a failure is never cached: run again
    assert all(r["ok"] for r in second), {r.get("error") for r in second}


def test_a_failed_reference_run_is_no_self_score(tmp_path: Path, flaky) -> None:
    """Its own run failed: no "scored against its own map" in results or figure titles."""
    _, blocker = flaky
    blocker.write_text("")
    exps, _ = compare_experiments(streams=_streams(tmp_path, 2), methods="flaky,ekf",
                                  reference="flaky")
    out = tmp_path / "out"
    result = compare(exps, out, executor=Executor("serial"), figures=False)
    assert not any(r["ok"] for r in result.results)
    assert not any(r.get("self_scored") for r in result.results)  # was "itself"
    with open(out / "final_by_run.csv", newline="") as fh:
        assert {r["self_scored"] for r in csv.DictReader(fh)} == {""}
    saved = json.loads((out / "results.json").read_text())
    _, _, titles = _results_data(saved, out / "results.json", [])
    assert "not drawn" not in titles["streams"], titles  # `bomgraph plot --results`
    for r in saved["results"]:  # a results.json of h72, its failed runs marked
        r["self_scored"] = "itself" if r["arm"] == "flaky" else ""
    _, _, titles = _results_data(saved, out / "results.json", [])
    assert "not drawn" not in titles["streams"], titles


def test_a_worker_kept_from_an_earlier_sweep_runs_a_failed_reference_again(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """joblib keeps its worker processes between sweeps; one that saw the reference fail in
    an earlier sweep served that failure in the next. The worker is this process here (the
    dispatcher runs its function in it), the earlier sweep's failure kept in it."""
    from bomgraph import processes
    from bomgraph.bench import execute

    monkeypatch.setattr(run_scoring, "_REFERENCES", {})
    exps, _ = compare_experiments(streams=_streams(tmp_path, 2), methods="ekf",
                                  reference="triangulate")
    tasks = exps[0].tasks()

    def here(func, index, tasks, n_jobs, failed, *, fresh=False):
        for task in tasks:  # what the worker kept of a sweep where the reference failed
            run_scoring.keep_reference(task, run_scoring.ReferenceFailure(
                "reference triangulate failed: RuntimeError: an earlier sweep", ""))
        for k, t in zip(index, tasks):
            yield func(k, t)
    monkeypatch.setattr(processes, "dispatch", here)
    results = execute(tasks, Executor("processes", n_jobs=2))
    assert all(r["ok"] for r in results), {r.get("error") for r in results}


def test_a_kept_reference_map_is_not_served_after_its_code_changed(tmp_path: Path,
                                                                    flaky) -> None:
    """The same holds of a reference that ran: its map, kept for the other arms, was served
    after its module was edited and reloaded (kept maps were keyed without the code)."""
    write, _ = flaky
    import bomgraph_h73_flaky
    importlib.reload(bomgraph_h73_flaky)
    exps, _ = compare_experiments(streams=_streams(tmp_path, 1), methods="ekf",
                                  reference="flaky")
    task = exps[0].tasks()[0]
    stream = task.stream()
    first = run_scoring.reference_map(task, stream)
    assert run_scoring.reference_map(task, stream) is first  # kept
    write(False)
    (tmp_path / "code" / "bomgraph_h73_flaky.py").write_text(
        (tmp_path / "code" / "bomgraph_h73_flaky.py").read_text() + "\n# edited\n")
    importlib.reload(bomgraph_h73_flaky)
    new_sweep()  # as compare's next sweep does
    assert run_scoring.reference_map(task, stream) is not first
