"""A local worker process that dies (a crash in native code, the out-of-memory killer,
``os._exit`` in a plugin) fails the run it was running, not the sweep.

Before, joblib's ``TerminatedWorkerError`` came out of ``compare --jobs 2`` as a traceback and
every run not yet finished was lost. Now the runs in flight when a worker died are run again
one at a time, each in a pool of its own: the one whose worker dies again is a FAILED run
(``WorkerDied``, with the exit code), the others keep their results, and the sweep goes on.
The Dask path had this already (``KilledWorker``; ``tests/test_dask_cli_cluster.py``)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import pytest
from _plugin_dist import write_dist_info
from hostile_helpers import ENV, no_traceback

from bomgraph.bench import strip_timings
from bomgraph.processes import dispatch
from bomgraph.sim import SimConfig, simulate
from bomgraph.stream_file import write_stream

DYING = '''\
import os
import numpy as np
import pytest
from bomgraph.mapper import MapEstimate

class Dying:
    """ends its process at step 20, as a crash in native code would"""
    def __init__(self, header, **options):
        self.t = 0
    def step(self, step):
        self.t += 1
        if self.t == 20:
            os._exit(7)
    def estimate(self):
        return MapEstimate(np.zeros(0, np.int64), np.zeros((0, 2)))
'''


def _compare(tmp_path: Path, out: str, methods: str, jobs: str,
             streams: list[Path]) -> tuple[subprocess.CompletedProcess, list[dict]]:
    env = {**ENV, "PYTHONPATH": os.pathsep.join([str(tmp_path / "site"), ENV["PYTHONPATH"]])}
    proc = subprocess.run([sys.executable, "-m", "bomgraph", "compare", "--streams",
                           *map(str, streams), "--methods", methods, "--jobs", jobs, "--out",
                           str(tmp_path / out), "--no-progress", "--no-figures"],
                          env=env, capture_output=True, timeout=600, cwd=tmp_path)
    results = tmp_path / out / "results.json"
    return proc, (json.loads(results.read_text())["results"] if results.exists() else [])


def _dying_plugin(tmp_path: Path, n_streams: int) -> list[Path]:
    """The ``dying`` plugin in ``tmp_path/site``; ``n_streams`` simulated streams."""
    (tmp_path / "site" / "dyingplugin").mkdir(parents=True)
    (tmp_path / "site" / "dyingplugin" / "__init__.py").write_text(DYING)
    write_dist_info(tmp_path / "site", "dyingplugin", {"dying": "dyingplugin:Dying"})
    streams = []
    for seed in range(n_streams):
        streams.append(tmp_path / f"s{seed}.jsonl")
        write_stream(simulate(SimConfig(n_steps=40), np.random.default_rng(seed)), streams[-1])
    return streams


def test_a_dying_worker_fails_its_run_and_the_sweep_goes_on(tmp_path: Path) -> None:
    streams = _dying_plugin(tmp_path, 3)

    proc, results = _compare(tmp_path, "par", "dying,triangulate,ekf", "2", streams)
    err = no_traceback(proc)
    assert proc.returncode == 1, err     # runs failed: 1, as for a method that raises
    assert "3 of 9 runs failed" in err and "WorkerDied" in err, err
    assert len(results) == 9
    dying = [r for r in results if r["arm"] == "dying"]
    assert len(dying) == 3 and not any(r["ok"] for r in dying)
    assert all(r["error"].startswith("WorkerDied:") and "EXIT(7)" in r["error"] for r in dying)
    # its warnings were kept for its result, and died with it: how to see them (h106)
    assert all("its warnings died with it" in r["error"] and "run it alone with --jobs 1 or "
               "`bomgraph run STREAM --method NAME` to see them" in r["error"] for r in dying)
    # every other run has the result it has on its own, in this process, one at a time
    _, serial = _compare(tmp_path, "ser", "triangulate,ekf", "1", streams)
    mine = {(r["arm"], r["run"]): r for r in strip_timings(results) if r["arm"] != "dying"}
    alone = {(r["arm"], r["run"]): r for r in strip_timings(serial)}
    assert mine.keys() == alone.keys() and len(alone) == 6
    assert all(r["ok"] for r in mine.values())
    for k in alone:
        assert mine[k]["checkpoints"] == alone[k]["checkpoints"], k


def test_one_run_left_for_two_workers_still_runs_in_a_worker(tmp_path: Path) -> None:
    """``--jobs 2`` and one run to do (one stream; or all others cached): joblib was given one
    worker, which it runs in the calling process, and the dying method ended the command
    itself (exit 7, no line, no results)."""
    streams = _dying_plugin(tmp_path, 1)
    proc, results = _compare(tmp_path, "one", "dying", "2", streams)
    err = no_traceback(proc)
    assert proc.returncode == 1, (proc.returncode, err)
    assert "1 of 1 run failed" in err and "WorkerDied" in err, err
    assert [r["ok"] for r in results] == [False]


def _alone(k: int, lock: str) -> tuple[int, dict]:
    """In a worker: a task that fails when another runs beside it."""
    try:
        fd = os.open(lock, os.O_CREAT | os.O_EXCL)
    except FileExistsError:
        return k, {"pid": os.getpid(), "alone": False}
    time.sleep(0.05)
    os.close(fd)
    os.unlink(lock)
    return k, {"pid": os.getpid(), "alone": True}


@pytest.mark.parametrize("n_jobs", [1, 2])
def test_dispatch_never_runs_a_task_in_this_process(tmp_path: Path, n_jobs: int) -> None:
    """One worker asked for (``Executor('processes', n_jobs=1)``, ``--jobs -1`` on one core,
    ``--jobs N`` for one task): two worker processes, one task at a time."""
    lock = str(tmp_path / "running")
    out = dict(dispatch(_alone, [0, 1, 2, 3], [lock] * 4, n_jobs,
                        lambda k, why: {"failed": why}))
    assert sorted(out) == [0, 1, 2, 3]
    assert os.getpid() not in {r["pid"] for r in out.values()}
    if n_jobs == 1:
        assert all(r["alone"] for r in out.values()), out


@pytest.mark.parametrize("backend", ["threading", "multiprocessing", "sequential"])
def test_dispatch_keeps_its_processes_under_a_callers_joblib_backend(
        tmp_path: Path, backend: str) -> None:
    """A caller's ``joblib.parallel_config(backend=...)`` around a sweep (their own code's
    choice) ran every task in the caller's process (threading: a dying method would end the
    caller) or raised ValueError (multiprocessing refuses ``return_as``): dispatch names
    loky itself (h45)."""
    from joblib import parallel_config
    lock = str(tmp_path / "running")
    with parallel_config(backend=backend):
        out = dict(dispatch(_alone, [0, 1, 2], [lock] * 3, 2, lambda k, why: {"failed": why}))
    assert sorted(out) == [0, 1, 2] and not any("failed" in r for r in out.values()), out
    assert os.getpid() not in {r["pid"] for r in out.values()}


def test_workers_that_die_once_before_any_run_do_not_fail_the_sweep(tmp_path: Path) -> None:
    """The first worker process ends as it starts (before it takes a run: the out-of-memory
    killer, a crash at start): every run was failed, as if no worker could ever start; now a
    second pool is tried, and only workers that die before any run twice in a row fail
    the runs."""
    streams = _dying_plugin(tmp_path, 2)
    (tmp_path / "site" / "sitecustomize.py").write_text(textwrap.dedent(f"""\
        import os, sys
        if any("popen_loky" in a for a in sys.orig_argv):  # a joblib worker: the first one dies
            try:
                os.close(os.open({str(tmp_path / "died")!r}, os.O_CREAT | os.O_EXCL))
            except FileExistsError:
                pass
            else:
                os._exit(9)
        """))
    proc, results = _compare(tmp_path, "once", "triangulate", "2", streams)
    err = no_traceback(proc)
    assert (tmp_path / "died").exists()
    assert proc.returncode == 0, err
    assert len(results) == 2 and all(r["ok"] for r in results), err


def test_workers_that_never_start_say_so_not_that_a_worker_ran_the_run(tmp_path: Path) -> None:
    """Every worker process dies as it starts, in two pools in a row: every run fails, and
    its error said "the worker process that ran it died ... os._exit in the method; run it
    alone with `bomgraph run`", though no worker ran it (h41): now it says the workers
    cannot start, and what to do."""
    streams = _dying_plugin(tmp_path, 2)
    (tmp_path / "site" / "sitecustomize.py").write_text(textwrap.dedent("""\
        import os, sys
        if any("popen_loky" in a for a in sys.orig_argv):  # every joblib worker dies
            os._exit(9)
        """))
    proc, results = _compare(tmp_path, "never", "triangulate", "2", streams)
    err = no_traceback(proc)
    assert proc.returncode == 1, err
    assert len(results) == 2 and not any(r["ok"] for r in results), err
    for r in results:
        assert r["error"].startswith("WorkerDied: the worker processes died before any run "
                                     "began, twice in a row"), r["error"]
        assert "EXIT(9)" in r["error"] and "ran it" not in r["error"], r["error"]


def _pid_of(k: int, _: object) -> tuple[int, dict]:
    return k, {"pid": os.getpid()}


def test_marks_folders_of_a_killed_dispatch_are_removed_by_the_next_only(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """A compare ended by SIGKILL left its ``bomgraph-running-*`` folder in the temporary
    folder (h41, after ``kill -9`` of ``compare --jobs 2``: the folder and the marks of its
    two runs in flight). The next dispatch removes such a folder when its owner file names a
    process of this host and pid namespace that is gone, and no other."""
    import tempfile

    from bomgraph import owned_folders, processes

    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))
    me = owned_folders.owner()
    gone = subprocess.Popen([sys.executable, "-c", "pass"])
    gone.wait()
    folders = {"dead": {**me, "pid": gone.pid}, "live": me, "other-host": {
        **me, "pid": gone.pid, "host": me["host"] + "-x"}, "other-ns": {
        **me, "pid": gone.pid, "pid_ns": "pid:[1]"}, "no-owner": None}
    for name, owner in folders.items():
        folder = tmp_path / f"{processes.MARKS_PREFIX}{name}"
        folder.mkdir()
        (folder / "3").write_text("")  # a run's mark
        if owner is not None:
            (folder / owned_folders.OWNER).write_text(json.dumps(owner))
    out = dict(dispatch(_pid_of, [0, 1], [None, None], 2, lambda k, why: {"failed": why}))
    assert sorted(out) == [0, 1] and "failed" not in out[0], out
    left = sorted(p.name for p in tmp_path.iterdir() if p.name.startswith("bomgraph-running"))
    assert left == [f"{processes.MARKS_PREFIX}{n}" for n in sorted(folders) if n != "dead"]


def test_a_marks_folder_of_another_kernel_is_left_alone(tmp_path: Path,
                                                        monkeypatch: pytest.MonkeyPatch) -> None:
    """The pid namespace of every host's first processes is the same link
    (``pid:[4026531836]``, the kernel's constant for the initial namespace), so two machines
    of one name that share the temporary folder (a network file system) could not be told
    apart: a dispatch on one removed the live marks folder of a sweep on the other, whose
    next task then raised FileNotFoundError out of ``execute`` (h42). The owner file now
    names the kernel's boot id too, and a folder of another boot is left alone."""
    import tempfile

    from bomgraph import owned_folders, processes

    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))
    me = owned_folders.owner()
    gone = subprocess.Popen([sys.executable, "-c", "pass"])
    gone.wait()
    folders = {"dead": {**me, "pid": gone.pid},
               "other-boot": {**me, "pid": gone.pid, "boot_id": "another-machine"}}
    for name, owner in folders.items():
        folder = tmp_path / f"{processes.MARKS_PREFIX}{name}"
        folder.mkdir()
        (folder / owned_folders.OWNER).write_text(json.dumps(owner))
    out = dict(dispatch(_pid_of, [0], [None], 2, lambda k, why: {"failed": why}))
    assert "failed" not in out[0], out
    left = sorted(p.name for p in tmp_path.iterdir() if p.name.startswith("bomgraph-running"))
    assert left == [f"{processes.MARKS_PREFIX}other-boot"], left
