"""The runner: serial = processes = Dask, caching, failures reported, the cache key."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from bomgraph.bench import Executor, execute, run_task, strip_timings, task_key
from bomgraph.errors import ConfigError
from bomgraph.experiments import Arm, Experiment
from bomgraph.sim import SimConfig, paper_design, simulate_run

SMALL = SimConfig(n_steps=40, n_landmarks=20)


def _exp(arms: tuple[Arm, ...]) -> Experiment:
    return Experiment("t", "test", arms, SMALL, seed=3, n_layouts=2, n_starts=2)


def test_run_task_scores_every_checkpoint() -> None:
    task = _exp((Arm("tri", "triangulate"),)).tasks()[0]
    res = run_task(task)
    assert res["ok"] and [c["t"] for c in res["checkpoints"]] == [10, 20, 30, 40]
    assert 0 < res["checkpoints"][-1]["mpe_m"] < 1.0
    assert np.isfinite(res["checkpoints"][-1]["robot_last_m"])
    assert list(res["checkpoints"][0]) == ["t", "n_mapped", "estimate_s", "mpe_m", "rmse_m",
                                           "median_m", "max_m", "n_common", "robot_last_m",
                                           "robot_mean_m", "nees_landmark", "nees_pose",
                                           "ape_trans_rmse_m", "ape_heading_rmse_rad",
                                           "rpe_trans_rmse_m", "rpe_heading_rmse_rad"]
    fm = res["final_map"]   # the final map in the truth's frame, for the map figures
    assert len(fm["landmarks"]) == res["checkpoints"][-1]["n_mapped"]
    assert len(fm["poses"]) == 41


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


@pytest.mark.parametrize("corrupt", [b"\xff\xfe not utf-8", b"[1, 2, 3]", b'{"ok": true}',
                                     b'{"ok": tru', b""])
def test_a_corrupt_cache_file_is_a_miss_and_is_rewritten(tmp_path: Path, corrupt: bytes,
                                                         caplog: pytest.LogCaptureFixture
                                                         ) -> None:
    """Issue 13 items 6 and 13: a corrupt or foreign cache file is run again (logged with its
    name), never a crash; results are written under unique temporary names, none left."""
    tasks = _exp((Arm("tri", "triangulate"),)).tasks()[:2]
    first = strip_timings(execute(tasks, Executor("serial"), cache_dir=tmp_path))
    bad = tmp_path / f"{task_key(tasks[0])}.json"
    bad.write_bytes(corrupt)
    with caplog.at_level("WARNING", logger="bomgraph.result_cache"):
        again = strip_timings(execute(tasks, Executor("serial"), cache_dir=tmp_path))
    assert json.dumps(again) == json.dumps(first)
    assert str(bad) in caplog.text
    assert json.loads(bad.read_text())["key"] == task_key(tasks[0])
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(
        f"{task_key(t)}.json" for t in tasks)


def test_executor_validates() -> None:
    with pytest.raises(ConfigError):
        Executor("threads")
    with pytest.raises(ConfigError):
        Executor("dask")


def test_executor_choose_follows_the_command_line() -> None:
    assert Executor.choose(1) == Executor("serial")
    assert Executor.choose(-1) == Executor("processes", n_jobs=-1)
    assert Executor.choose(3, dask_local=2) == Executor("dask", dask_local=2)
    assert Executor.choose(1, scheduler="tcp://x:1").scheduler == "tcp://x:1"


def test_the_command_lines_executor_overrides_the_sweep_files_whole() -> None:
    """docs/USAGE.md, "Sweep files": "The command line's `--jobs`, `--dask-local` and
    `--scheduler` override `[executor]`". Before h89 a file's `dask_local = 2` (or
    `scheduler`) still won over `--jobs 1`: the sweep started a Dask cluster and printed
    "--jobs 1 is not used"."""
    file_dask = {"dask_local": 2}
    assert Executor.choose(1, defaults=file_dask) == Executor("serial")
    assert Executor.choose(3, defaults={"scheduler": "tcp://x:1"}) == Executor(
        "processes", n_jobs=3)
    assert Executor.choose(None, "tcp://y:2", None, defaults=file_dask) == Executor(
        "dask", scheduler="tcp://y:2")
    # nothing on the command line: the file's [executor], then the default
    assert Executor.choose(None, None, None, defaults=file_dask) == Executor("dask",
                                                                            dask_local=2)
    assert Executor.choose(None, None, None, defaults={"jobs": 1}) == Executor("serial")
    assert Executor.choose(defaults={"jobs": 1}) == Executor("serial")
    assert Executor.choose() == Executor("processes", n_jobs=-1)



def test_local_processes_are_bounded_by_the_tasks_and_the_cores(
        monkeypatch: pytest.MonkeyPatch) -> None:
    # `compare --jobs 100000` started 100,000 worker processes for one run (session 12);
    # -1 was passed on, one per core whatever the tasks (h137)
    import joblib

    from bomgraph import bench, processes

    asked: list[int] = []

    class Recorder:
        def __init__(self, n_jobs: int, **kw) -> None:
            asked.append(n_jobs)

        def __call__(self, jobs):  # a result a task, as joblib gives them
            return iter([(args[2], {}) for _, args, _ in jobs])

        def __enter__(self):  # bench uses Parallel as joblib's context manager
            return self

        def __exit__(self, *exc) -> None:
            pass

    monkeypatch.setattr(joblib, "Parallel", Recorder)
    monkeypatch.setattr(processes, "usable_cores", lambda: 2)
    task = _exp((Arm("tri", "triangulate"),)).tasks()[0]  # never run: the pool is fake
    for n_jobs in (100_000, 2, -1):
        list(bench._dispatch([task] * 3, [0, 1, 2], Executor("processes", n_jobs=n_jobs)))
    list(bench._dispatch([task] * 50, list(range(50)), Executor("processes", n_jobs=10**5)))
    # h137: -1 for one task is one worker (two taking one task at a time); was -1, two
    list(bench._dispatch([task], [0], Executor("processes", n_jobs=-1)))
    assert asked == [3, 2, 2, 8, 2]


def test_a_callers_sequential_joblib_backend_leaves_the_pool_its_workers(
        monkeypatch: pytest.MonkeyPatch) -> None:
    # under joblib.parallel_config(backend="sequential") effective_n_jobs said 1, and a pool
    # of 3 workers became 2 running one task at a time (h49)
    import joblib

    from bomgraph import processes

    kwargs: list[dict] = []

    class Recorder:
        def __init__(self, **kw) -> None:
            kwargs.append(kw)

        def __call__(self, jobs):
            return iter([(args[2], {}) for _, args, _ in jobs])

        def __enter__(self):
            return self

        def __exit__(self, *exc) -> None:
            pass

    monkeypatch.setattr(joblib, "Parallel", Recorder)
    with joblib.parallel_config(backend="sequential"):
        out = list(processes.dispatch(lambda k, t: (k, {}), [0, 1, 2], ["a", "b", "c"], 3,
                                      lambda k, why: {"failed": why}))
    assert sorted(k for k, _ in out) == [0, 1, 2]
    from joblib._parallel_backends import LokyBackend

    assert [(kw["n_jobs"], type(kw["backend"]), "pre_dispatch" in kw) for kw in kwargs] == [
        (3, LokyBackend, False)]


def test_a_pool_that_ends_without_every_result_fails_the_rest_and_ends(
        monkeypatch: pytest.MonkeyPatch) -> None:
    # dispatch ran the tasks without a result again in a new pool, forever: this test's
    # predecessor gave no result and hung the suite (it never happens with joblib's pool)
    import joblib

    from bomgraph import processes

    class Empty:
        def __init__(self, **kw) -> None:
            pass

        def __call__(self, jobs):
            return iter(())

        def __enter__(self):
            return self

        def __exit__(self, *exc) -> None:
            pass

    monkeypatch.setattr(joblib, "Parallel", Empty)
    out = list(processes.dispatch(lambda k, t: (k, {}), [4, 7], ["a", "b"], 2,
                                  lambda k, why: {"ok": False, "error": why}))
    assert out == [(k, {"ok": False, "error": "the worker pool ended without its result"})
                   for k in (4, 7)]

def test_task_key_is_stable_and_tells_tasks_apart() -> None:
    tasks = _exp((Arm("tri", "triangulate"), Arm("cs", "stmds-cs"))).tasks()
    keys = [task_key(t) for t in tasks]
    assert keys == [task_key(t) for t in tasks] and len(set(keys)) == len(tasks)
    assert run_task(tasks[0])["key"] == keys[0]


def test_existing_dask_scheduler_by_address() -> None:
    from distributed import LocalCluster

    from bomgraph.cluster import LOCAL_SCHEDULER_HTTP

    tasks = _exp((Arm("tri", "triangulate"),)).tasks()[:2]
    serial = strip_timings(execute(tasks, Executor("serial")))
    with LocalCluster(n_workers=1, threads_per_worker=1, processes=True, host="127.0.0.1",
                      dashboard_address=None,
                      scheduler_kwargs=LOCAL_SCHEDULER_HTTP) as cluster:  # not port 8787
        remote = strip_timings(execute(tasks, Executor("dask",
                                                       scheduler=cluster.scheduler_address)))
    assert json.dumps(serial) == json.dumps(remote)


def test_tasks_that_experiments_share_run_once(monkeypatch: pytest.MonkeyPatch) -> None:
    """Exp. 2 and "all" share the gtsam arms: a key seen twice in one sweep runs once, and
    each task gets the result under its own experiment name."""
    import bomgraph.bench as bench

    a = _exp((Arm("tri", "triangulate"),))
    b = Experiment("u", "again", a.arms, SMALL, seed=3, n_layouts=2, n_starts=2)
    tasks = a.tasks() + b.tasks()
    calls: list[str] = []
    real = bench.run_task
    monkeypatch.setattr(bench, "run_task", lambda t: calls.append(task_key(t)) or real(t))
    res = execute(tasks, Executor("serial"))
    assert len(calls) == len(a.tasks()) == len(set(calls))
    assert [r["experiment"] for r in res] == ["t"] * len(a.tasks()) + ["u"] * len(b.tasks())
    half = len(a.tasks())
    assert strip_timings(res[:half]) == [{**r, "experiment": "t"}
                                         for r in strip_timings(res[half:])]


WATCHED = '''\
"""Dead reckoning plus ray intersection, whose maps report how many of its earlier maps are
still held by someone (the runner) when it makes the next one."""
import gc
import weakref

from baselines.triangulate import TriangulateMapper


class Watched(TriangulateMapper):
    def __init__(self, header, **options):
        super().__init__(header, **options)
        self.made = []

    def estimate(self):
        gc.collect()
        alive = sum(r() is not None for r in self.made)
        est = super().estimate()
        est = type(est)(est.landmark_ids, est.landmarks_xy, est.pose_t, est.poses,
                        est.landmark_cov, est.pose_cov, {**est.info, "maps_alive": alive})
        self.made.append(weakref.ref(est))
        return est
'''


def test_run_task_scores_each_checkpoint_as_it_comes_and_keeps_one_map(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Every checkpoint's map holds the trajectory so far, so keeping them all until the end
    grows as T^2 (Victoria Park, 6,969 steps: 242 MB of arrays for ekf@real, enough for
    joblib to restart the worker with a "memory leak" warning). The runner scores each map
    as it is taken and keeps only the last; the rows are those of scoring the whole run."""
    from bomgraph import mapper
    from bomgraph.evaluate import score_checkpoints
    from bomgraph.mapper import create_mapper, run

    (tmp_path / "watched_mapper.py").write_text(WATCHED)
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.setattr(mapper, "_REGISTRY", dict(mapper._REGISTRY))
    mapper.register_method("watched", "watched_mapper:Watched", "triangulate, watched")
    task = _exp((Arm("w", "watched"),)).tasks()[0]
    res = run_task(task)
    assert res["ok"] and [c["t"] for c in res["checkpoints"]] == [10, 20, 30, 40]
    assert res["info"]["maps_alive"] <= 1  # was 3: every earlier checkpoint's map
    stream = task.stream()
    whole = run(create_mapper("triangulate", stream.header), stream.steps)
    expected = [{k: v for k, v in s.__dict__.items() if k != "estimate_s"}
                for s in score_checkpoints(whole, stream.truth)]
    got = [{k: v for k, v in c.items() if k != "estimate_s"} for c in res["checkpoints"]]
    assert json.dumps(got) == json.dumps(expected)


@pytest.mark.parametrize("kwargs,match", [
    ({"n_jobs": 0}, "n_jobs must be an integer >= 1, or -1"),
    ({"n_jobs": "2"}, "n_jobs must be an integer >= 1, or -1"),
    ({"n_jobs": 2.5}, "n_jobs must be an integer >= 1, or -1"),
    ({"backend": "dask", "dask_local": 1.5}, "dask_local must be an integer >= 0"),
])
def test_executor_refuses_worker_counts_that_are_not_integers(kwargs: dict, match: str) -> None:
    """Executor('processes', n_jobs='2') or n_jobs=0 was taken and failed inside joblib."""
    with pytest.raises(ConfigError, match=match):
        Executor(**{"backend": "processes", **kwargs})


def test_execute_and_run_file_refuse_arguments_of_the_wrong_type(tmp_path: Path) -> None:
    """execute() with a string executor or non-Task items, run_file() with options as a list:
    AttributeError / TypeError before."""
    from bomgraph.bench import run_file
    from bomgraph.stream_file import write_stream

    with pytest.raises(ConfigError, match="executor must be an Executor"):
        execute([], "serial")  # type: ignore[arg-type]
    with pytest.raises(ConfigError, match=r"tasks must be Task objects \(experiment.tasks\(\)\)"
                                          r", got int"):
        execute([1], Executor("serial"))  # type: ignore[list-item]
    path = tmp_path / "s.jsonl"
    write_stream(simulate_run(paper_design(0)[0], SimConfig(n_steps=12)), path)
    with pytest.raises(ConfigError, match="options must be a mapping"):
        run_file(path, "triangulate", options=["min_parallax_rad=0.1"])  # type: ignore[arg-type]
    assert run_file(path, "triangulate", options={}).checkpoints[-1].t == 12


def _retimed(text: str, scale: float) -> str:
    """An estimate file's text with every timing (``estimate_s``, ``timing_s``) scaled."""
    lines = []
    for line in text.splitlines():
        obj = json.loads(line)
        if "estimate_s" in obj:
            obj["estimate_s"] *= scale
        if "timing_s" in obj:
            obj["timing_s"] = {k: v * scale for k, v in obj["timing_s"].items()}
        lines.append(json.dumps(obj, separators=(",", ":")))
    return "\n".join(lines) + "\n"


def test_strip_timings_also_strips_the_timings_of_a_kept_estimate() -> None:
    """With ``keep_estimate`` (compare --estimates) a result carries its estimate file's
    text, whose checkpoint lines hold ``estimate_s`` and whose last line ``timing_s``:
    strip_timings left them, so two runs of the same task never compared equal."""
    from dataclasses import replace

    task = replace(_exp((Arm("tri", "triangulate"),)).tasks()[0], keep_estimate=True)
    res = run_task(task)
    text = res["estimate_file"]
    assert "timing_s" in text and "estimate_s" in text
    other = {**res, "estimate_file": _retimed(text, 2.0)}
    assert strip_timings([res]) == strip_timings([other])
    # a map that differs still differs
    first = json.loads(text.splitlines()[1])
    moved = {**first, "landmarks": [[i, x + 1e-12, y] for i, x, y in first["landmarks"]]}
    lines = text.splitlines()
    changed = {**res, "estimate_file": "\n".join([lines[0], json.dumps(moved)] + lines[2:])}
    assert strip_timings([res]) != strip_timings([changed])


@pytest.mark.parametrize("library", ["numpy", "scipy", "gtsam", "filterpy"])
def test_the_cache_key_covers_the_libraries_that_compute_the_numbers(
        monkeypatch: pytest.MonkeyPatch, library: str) -> None:
    """Another numpy, scipy, gtsam or filterpy can give other bits for the same code (GTSAM's
    last bits differ between machines, scripts/check_identical.py); the key held only the
    bomgraph and baselines sources, so a warm cache returned what a cold run would not."""
    from importlib import metadata

    import bomgraph.bench as bench

    task = _exp((Arm("tri", "triangulate"),)).tasks()[0]
    before = task_key(task)
    real = metadata.version
    monkeypatch.setattr(metadata, "version",
                        lambda name: "0.0.other" if name == library else real(name))
    bench.code_fingerprint.cache_clear()
    try:
        assert task_key(task) != before
    finally:
        bench.code_fingerprint.cache_clear()


def test_the_log_line_of_a_capped_pool_of_one_says_two_processes_start(
        caplog: pytest.LogCaptureFixture) -> None:
    """A pool of one is two worker processes taking one task at a time (joblib would run a
    pool of one in this process); the log line of ``--jobs 4`` for one run said "starting 1"
    while two processes started (h41)."""
    import logging

    task = _exp((Arm("tri", "triangulate"),)).tasks()[0]
    with caplog.at_level(logging.INFO, logger="bomgraph"):  # bomgraph.processes's (h137)
        (res,) = execute([task], Executor("processes", n_jobs=4))
    assert res["ok"], res.get("error")
    line = next(r.getMessage() for r in caplog.records if "asked for" in r.getMessage())
    assert line.endswith("starting 2, one task at a time (a pool of one would run it in this "
                         "process)"), line
