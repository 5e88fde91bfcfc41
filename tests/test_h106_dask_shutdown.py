"""What a ``--dask-local`` compare's workers say as they end (h106).

A worker of the local cluster whose heartbeat met the scheduler closing logged "Failed to
communicate with scheduler during heartbeat." with a ``StreamClosedError`` /
``CommClosedError`` traceback on its stderr, which is the user's (a reviewer saw it once in 9
compares). Before the cluster is closed its workers' Dask log lines are quieted
(:func:`bomgraph.cluster._quiet_worker`). The race is made certain here: the task makes its
worker log such a traceback when it is closed."""

from __future__ import annotations

import logging
import subprocess
import sys
from pathlib import Path

SCRIPT = '''\
import logging

from bomgraph.cluster import dispatch


def task(k, t):
    from distributed import get_worker

    worker = get_worker()
    close = worker.close

    async def noisy_close(*args, **kwargs):  # what a heartbeat meeting the closed scheduler logs
        try:
            raise OSError("StreamClosedError: Stream is closed (made by the test)")
        except OSError:
            logging.getLogger("distributed.worker").exception(
                "Failed to communicate with scheduler during heartbeat.")
        return await close(*args, **kwargs)

    worker.close = noisy_close
    return k, {"ok": True, "t": t}


if __name__ == "__main__":
    out = list(dispatch(task, [0, 1], ["a", "b"], scheduler=None, n_local=2,
                        failed=lambda k, why: {"ok": False, "error": why}))
    assert sorted(k for k, _ in out) == [0, 1] and all(r["ok"] for _, r in out), out
    print("done")
'''


def test_a_local_clusters_workers_print_no_traceback_as_they_end(tmp_path: Path) -> None:
    script = tmp_path / "shutdown.py"
    script.write_text(SCRIPT)
    proc = subprocess.run([sys.executable, str(script)], cwd=tmp_path, capture_output=True,
                          text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert proc.stdout.strip() == "done"
    assert "Traceback" not in proc.stderr and "heartbeat" not in proc.stderr, proc.stderr


def test_the_callers_dask_loggers_are_left_alone_by_the_quieting(tmp_path: Path) -> None:
    """The workers are quieted in their own processes, not in the caller's."""
    import importlib

    from bomgraph.cluster import dispatch

    importlib.import_module("distributed")
    names = ("distributed", "distributed.worker", "distributed.client")
    levels = {n: logging.getLogger(n).level for n in names}
    out = list(dispatch(_task, [0], ["a"], scheduler=None, n_local=1,
                        failed=lambda k, why: {"ok": False, "error": why}))
    assert out == [(0, {"ok": True})]
    assert {n: logging.getLogger(n).level for n in names} == levels


def _task(k: int, t: str) -> tuple[int, dict]:
    return k, {"ok": True}
