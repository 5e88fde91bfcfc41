"""One function decides how many worker processes start (h137): local processes and a local
Dask cluster, from the command line and from the library alike.

Before, the cap (no more workers than tasks, nor :data:`MAX_WORKERS_PER_CORE` per core) was
decided twice: by the command line's path (``bench``, logged) and again by
``processes.dispatch`` (silent, so a library caller was never told); ``cluster.dispatch`` did
not cap at all; ``-1`` (one per core) was passed on to joblib as it was, whatever the tasks;
and the cap counted the machine's cores (``os.cpu_count()``), not those the process may use
(``taskset``, a container's quota), as joblib's ``-1`` does: ``--jobs 100`` for 8 tasks on
one usable core started 8 workers."""

from __future__ import annotations

import logging
import os
import subprocess
import sys
import textwrap

import numpy as np
import pytest

from bomgraph import cli
from bomgraph.bench import Executor, execute
from bomgraph.experiments import Arm, Experiment, FileSource
from bomgraph.processes import MAX_WORKERS_PER_CORE, dispatch, usable_cores, worker_count
from bomgraph.sim import SimConfig, simulate
from bomgraph.stream_file import write_stream
from bomgraph.tables import counted

CAPPED = " asked for "


def _pid(k: int, t: str) -> tuple[int, dict]:
    return k, {"pid": os.getpid()}


def _failed(k: int, why: str) -> dict:
    return {"failed": why}


def _capped(caplog: pytest.LogCaptureFixture) -> list[str]:
    return [r.getMessage() for r in caplog.records if CAPPED in r.getMessage()]


def test_minus_one_is_one_per_usable_core_and_no_more_than_the_tasks(
        caplog: pytest.LogCaptureFixture) -> None:
    cores = usable_cores()
    caplog.set_level(logging.INFO, logger="bomgraph")
    assert worker_count(-1, 10**6) == cores
    assert worker_count(-1, 1) == 1
    assert worker_count(10**6, 10**6) == MAX_WORKERS_PER_CORE * cores
    assert worker_count(3, 0) == 1 and worker_count(3, 2) == 2 and worker_count(1, 5) == 1
    said = _capped(caplog)
    start = [] if cores == 1 else [f"one worker process per core ({cores}) asked for 1 task "
                                   f"on {cores} usable cores: starting 1"]
    assert said[:len(start) + 1] == start + [
        f"{10**6} worker processes asked for {10**6} tasks on {counted(cores, 'usable core')}: "
        f"starting {MAX_WORKERS_PER_CORE * cores}"], said


def test_a_library_dispatch_says_what_it_started(caplog: pytest.LogCaptureFixture) -> None:
    """``processes.dispatch`` capped 40 to 2 without a word (the command line's path had
    said so before calling it)."""
    caplog.set_level(logging.INFO, logger="bomgraph")
    out = dict(dispatch(_pid, [0, 1], ["a", "b"], 40, _failed, fresh=True))
    assert sorted(out) == [0, 1] and all("pid" in r for r in out.values()), out
    assert _capped(caplog) == [f"40 worker processes asked for 2 tasks on "
                               f"{counted(usable_cores(), 'usable core')}: starting 2"], \
        caplog.text


def test_a_sweep_says_it_once(tmp_path, caplog: pytest.LogCaptureFixture) -> None:
    stream = tmp_path / "s.jsonl"
    write_stream(simulate(SimConfig(n_steps=20), np.random.default_rng(3)), stream)
    exp = Experiment("e", "e", (Arm("triangulate", "triangulate"),),
                     sources=(FileSource(str(stream)),))
    caplog.set_level(logging.INFO, logger="bomgraph")
    res = execute(exp.tasks(), Executor("processes", n_jobs=50))
    assert [r["ok"] for r in res] == [True], res
    assert _capped(caplog) == [f"50 worker processes asked for 1 task on "
                               f"{counted(usable_cores(), 'usable core')}: starting 2, one "
                               f"task at a time (a pool of one would run it in this process)"], \
        caplog.text


_ONE_CORE = textwrap.dedent("""
    import os, sys
    os.sched_setaffinity(0, {sorted(os.sched_getaffinity(0))[0]})
    from joblib.externals.loky import reusable_executor
    from bomgraph.processes import dispatch

    def pid(k, t):
        return k, {"pid": os.getpid()}

    out = dict(dispatch(pid, list(range(8)), ["a"] * 8, 100, lambda k, w: {"failed": w}))
    assert sorted(out) == list(range(8)) and all("pid" in r for r in out.values()), out
    print(len(reusable_executor._executor._processes))
""")


@pytest.mark.skipif(not hasattr(os, "sched_setaffinity"), reason="Linux's CPU affinity")
def test_the_cap_counts_the_cores_this_process_may_use(tmp_path) -> None:
    """On one usable core (``taskset -c 0``), 100 workers asked for 8 tasks are 4, not 8."""
    script = tmp_path / "one_core.py"
    script.write_text(_ONE_CORE, encoding="utf-8")
    done = subprocess.run([sys.executable, str(script)], capture_output=True, text=True,
                          timeout=120)
    assert done.returncode == 0, done.stderr
    assert done.stdout.split() == [str(MAX_WORKERS_PER_CORE)], (done.stdout, done.stderr)


@pytest.mark.parametrize("jobs, error", [
    ("0", "must be a number of processes >= 1, or -1 for one per core, got 0"),
    ("-2", "must be a number of processes >= 1, or -1 for one per core, got -2"),
    ("1.5", "invalid number of processes value: '1.5'"),
    ("abc", "invalid number of processes value: 'abc'"),
    ("", "invalid number of processes value: ''"),
])
def test_the_command_line_refuses_a_bad_jobs_in_one_line(
        jobs: str, error: str, tmp_path, capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as stop:
        cli.main(["compare", "--quick", "--jobs", jobs, "--out", str(tmp_path / "o")])
    assert stop.value.code == 2
    err = capsys.readouterr().err
    assert err == (f"bomgraph compare: error: argument --jobs: {error}; see bomgraph compare "
                   f"--help\n"), err
    assert not (tmp_path / "o").exists()
