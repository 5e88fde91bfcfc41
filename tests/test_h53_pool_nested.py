"""A sweep started inside a joblib threading task (``joblib.parallel_config(backend=
"threading", n_jobs=2)`` and ``Parallel()(delayed(sweep)(...))``): the local pool names loky
itself, but joblib caps a loky pool nested below a threading worker at one job, so every task
ran in the caller's process, one after the other (``--jobs 2`` asked for), with two joblib
warnings printed, and a task that ended its process would end the caller (h53)."""

from __future__ import annotations

import os
import time
import warnings
from pathlib import Path

from joblib import Parallel, delayed, parallel_config

from bomgraph.processes import dispatch


def _pid(k: int, folder: str) -> tuple[int, dict]:
    """Mark this process in ``folder`` and wait (10 s at most) until two processes have: so
    that both workers take tasks however slowly the second one starts."""
    Path(folder, str(os.getpid())).touch()
    deadline = time.monotonic() + 10
    while len(os.listdir(folder)) < 2 and time.monotonic() < deadline:
        time.sleep(0.05)
    return k, {"pid": os.getpid()}


def _sweep(n_jobs: int, folder: str) -> list[int]:
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # joblib's "cannot be nested below threads"
        out = list(dispatch(_pid, range(4), [folder] * 4, n_jobs,
                            lambda k, why: {"pid": None, "error": why}))
    return [r["pid"] for _, r in sorted(out)]


def test_a_sweep_in_a_joblib_threading_task_runs_in_the_workers_it_asked_for(
        tmp_path: Path) -> None:
    with parallel_config(backend="threading", n_jobs=2):
        (pids,) = Parallel()(delayed(_sweep)(2, str(tmp_path)) for _ in range(1))
    assert None not in pids and os.getpid() not in pids, pids  # not in the caller
    assert len(set(pids)) == 2, pids
