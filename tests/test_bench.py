"""Experiments as data and the runner: serial = processes = Dask, caching, failures reported."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from bomgraph.bench import (REAL_VARIANTS, Arm, Executor, Experiment, compare, execute,
                            final_by_run, paper_experiments, real_experiments, run_task,
                            strip_timings, summarise)
from bomgraph.cli import format_by_run
from bomgraph.errors import ConfigError
from bomgraph.sim import SimConfig

SMALL = SimConfig(n_steps=40, n_landmarks=20)


def _exp(arms: tuple[Arm, ...]) -> Experiment:
    return Experiment("t", "test", arms, SMALL, seed=3, n_layouts=2, n_starts=2)


def test_paper_experiments_have_the_papers_design() -> None:
    exps = paper_experiments()
    assert set(exps) == {"exp1", "exp2", "exp3", "all"}
    assert all(len(e.runs()) == 25 and e.sim == SimConfig() for e in exps.values())
    assert {a.method for a in exps["exp2"].arms} >= {"stmds-cs-loc", "stmds-smacof-loc", "ekf",
                                                     "gtsam-batch", "gtsam-isam2", "hybrid"}
    assert any(a.prior_fraction == 0.1 for a in exps["exp3"].arms)
    quick = paper_experiments(quick=True)
    assert all(len(e.runs()) == 2 for e in quick.values())


def test_run_task_scores_every_checkpoint() -> None:
    task = _exp((Arm("tri", "triangulate"),)).tasks()[0]
    res = run_task(task)
    assert res["ok"] and [c["t"] for c in res["checkpoints"]] == [10, 20, 30, 40]
    assert 0 < res["checkpoints"][-1]["mpe_m"] < 1.0
    assert np.isfinite(res["checkpoints"][-1]["robot_last_m"])


def test_a_failing_method_is_reported_not_dropped() -> None:
    exp = _exp((Arm("tri", "triangulate"), Arm("bad", "triangulate",
                                                {"min_parallax_rad": -1.0})))
    results = execute(exp.tasks(), Executor("serial"))
    assert len(results) == 8
    bad = [r for r in results if r["arm"] == "bad"]
    assert all(not r["ok"] and "min_parallax_rad" in r["error"] for r in bad)
    rows = {r["arm"]: r for r in summarise(results)}
    assert rows["bad"]["failed"] == 4 and rows["tri"]["failed"] == 0
    # the per-run table names each failure and each run's own final score
    per_run = final_by_run(results)
    assert len(per_run) == 8
    assert all(not r["ok"] and "min_parallax_rad" in r["error"] for r in per_run
               if r["arm"] == "bad")
    tri = [r for r in per_run if r["arm"] == "tri"]
    assert all(r["t"] == 40 and 0 < r["mpe_m"] < 1.0 and r["n_mapped"] >= 3 for r in tri)
    text = format_by_run(per_run)
    bad_line = next(line for line in text.splitlines() if line.startswith("bad "))
    assert bad_line.split()[1:] == ["FAILED"] * 4
    assert f"{100 * tri[0]['mpe_m']:.1f} ({tri[0]['n_mapped']})" in text


def test_real_experiments_hold_every_method_and_its_real_variant(tmp_path: Path) -> None:
    for d in ("mrclam6", "bearing_only_sim_g2o"):
        (tmp_path / d).mkdir()
    exps = real_experiments(tmp_path)
    assert set(exps) == {"mrclam6", "g2o"} and len(exps["mrclam6"].sources) == 5
    labels = {a.label: a for a in exps["mrclam6"].arms}
    for method, variants in REAL_VARIANTS.items():
        for label, options in variants:
            assert method in labels and labels[label].method == method
            assert dict(labels[label].options) == options
    assert {"ekf-invdepth", "gtsam-isam2", "oracle"} <= set(labels)
    with pytest.raises(ConfigError, match="no dataset folders"):
        real_experiments(tmp_path / "nothing")


def test_serial_processes_and_dask_give_identical_results() -> None:
    tasks = _exp((Arm("tri", "triangulate"),)).tasks()
    serial = strip_timings(execute(tasks, Executor("serial")))
    procs = strip_timings(execute(tasks, Executor("processes", n_jobs=2)))
    assert json.dumps(serial) == json.dumps(procs)
    dask = strip_timings(execute(tasks, Executor("dask", dask_local=2)))
    assert json.dumps(serial) == json.dumps(dask)


def test_cache_resumes_an_interrupted_sweep(tmp_path: Path) -> None:
    tasks = _exp((Arm("tri", "triangulate"),)).tasks()
    first = execute(tasks[:2], Executor("serial"), cache_dir=tmp_path)
    assert len(list(tmp_path.glob("*.json"))) == 2
    seen = []
    again = execute(tasks, Executor("serial"), cache_dir=tmp_path,
                    progress=lambda d, n: seen.append((d, n)))
    assert seen[0] == (2, 4) and seen[-1] == (4, 4)
    assert json.dumps(again[:2]) == json.dumps(first)
    assert len(list(tmp_path.glob("*.json"))) == 4


def test_compare_writes_tables_and_figures(tmp_path: Path) -> None:
    exp = _exp((Arm("tri", "triangulate"),))
    res = compare([exp], tmp_path, executor=Executor("serial"))
    for name in ("results.json", "results.csv", "summary.csv", "t_error_vs_time.png"):
        assert (tmp_path / name).exists(), name
    assert res.summary[0]["runs"] == 4
    assert (tmp_path / "t_error_vs_time.png").stat().st_size > 10_000


def test_executor_validates() -> None:
    with pytest.raises(ConfigError):
        Executor("threads")
    with pytest.raises(ConfigError):
        Executor("dask")


def test_existing_dask_scheduler_by_address() -> None:
    from distributed import LocalCluster

    tasks = _exp((Arm("tri", "triangulate"),)).tasks()[:2]
    serial = strip_timings(execute(tasks, Executor("serial")))
    with LocalCluster(n_workers=1, threads_per_worker=1, processes=True, host="127.0.0.1",
                      dashboard_address=None) as cluster:
        remote = strip_timings(execute(tasks, Executor("dask",
                                                       scheduler=cluster.scheduler_address)))
    assert json.dumps(serial) == json.dumps(remote)
