"""``bomgraph.processes.dispatch`` refuses a bad ``n_jobs`` as ``cluster.dispatch`` refuses a
bad ``n_local`` (h124), and :class:`~bomgraph.bench.Executor` takes what the command line and
a sweep file take.

From Python, ``n_jobs=0`` was joblib's ValueError ("n_jobs == 0 in Parallel has no meaning"),
``1.5`` and ``True`` were taken, ``"2"`` was a TypeError, ``-3`` was joblib's "all cores but
two" (``--jobs -3`` and a sweep file's ``jobs = -3`` are refused), and ``10**6`` started a
thousand worker processes for two tasks. Now one ConfigError line at the call, before any
worker starts, and never more workers than tasks."""

from __future__ import annotations

import os

import pytest

from bomgraph.bench import Executor
from bomgraph.errors import ConfigError
from bomgraph.processes import dispatch

BAD = [0, -3, 1.5, 2.0, True, None, "2"]


def _pid(k: int, t: str) -> tuple[int, dict]:
    return k, {"pid": os.getpid()}


def _failed(k: int, why: str) -> dict:
    return {"failed": why}


@pytest.mark.parametrize("n_jobs", BAD)
def test_dispatch_refuses_a_bad_number_of_workers_at_the_call(n_jobs: object) -> None:
    with pytest.raises(ConfigError) as err:
        dispatch(_pid, [0], ["a"], n_jobs, _failed)
    assert str(err.value) == (f"n_jobs must be an integer >= 1, or -1 for one process per "
                              f"core, got {n_jobs!r}")


@pytest.mark.parametrize("n_jobs", BAD)
def test_an_executor_takes_what_the_command_line_takes(n_jobs: object) -> None:
    with pytest.raises(ConfigError, match=r"^n_jobs must be an integer >= 1, or -1 for one"):
        Executor("processes", n_jobs=n_jobs)


def test_no_more_workers_than_tasks() -> None:
    from joblib.externals.loky import reusable_executor

    out = dict(dispatch(_pid, [0, 1], ["a", "b"], 40, _failed, fresh=True))
    assert sorted(out) == [0, 1] and all("pid" in r for r in out.values()), out
    kept = reusable_executor._executor
    assert kept is not None and len(kept._processes) == 2, len(kept._processes)
