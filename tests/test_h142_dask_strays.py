"""A local cluster whose start failed ends its own stray workers only (h142).

h137 SIGKILLed, after a failed start, every Dask worker process of this process that was not
there before the start: also one that a cluster of the caller's own, in the same process,
started meanwhile (its nanny restarting a worker that died, or a cluster started in another
thread). Here the caller's worker dies as ours hangs at its start; the caller's nanny starts
it again during our start; that new worker must live on."""

from __future__ import annotations

import os
from pathlib import Path

from _processes import alive

ROOT = Path(__file__).resolve().parents[1]

#: In the first local Dask worker to start after ``marker`` is made: kill the caller's worker
#: (its pid in ``marker``), wait for the caller's nanny to start another, write that one's pid
#: to ``restarted``, and hang (this start then times out)
_SITE = """\
import os, signal, sys, time
if "--multiprocessing-fork" in sys.orig_argv:
    try:
        os.rename({marker!r}, {marker!r} + ".taken")
    except FileNotFoundError:
        pass
    else:
        theirs = int(open({marker!r} + ".taken").read())
        os.kill(theirs, signal.SIGKILL)
        for _ in range(600):
            new = [int(p) for p in os.listdir("/proc") if p.isdigit()
                   and int(p) not in (theirs, os.getpid())]
            def sibling(pid):
                try:
                    stat = open(f"/proc/{{pid}}/stat").read().rsplit(")", 1)[1].split()
                    cmd = open(f"/proc/{{pid}}/cmdline", "rb").read()
                except OSError:
                    return False
                return int(stat[1]) == os.getppid() and b"--multiprocessing-fork" in cmd
            found = [p for p in new if sibling(p)]
            if found:
                open({restarted!r}, "w").write(str(found[0]))
                break
            time.sleep(0.1)
        time.sleep(120)
"""


def _task(k: int, t: str) -> tuple[int, dict]:
    return k, {"ok": True, "t": t}


def test_a_failed_start_kills_none_of_the_callers_own_workers(tmp_path: Path,
                                                              monkeypatch) -> None:
    import importlib

    import dask.config

    importlib.import_module("distributed")  # its configuration first: set() removes it after
    from distributed import Client, LocalCluster

    from bomgraph.cluster import LOCAL_SCHEDULER_HTTP, dispatch

    marker, restarted = str(tmp_path / "marker"), str(tmp_path / "restarted")
    site = tmp_path / "site"
    site.mkdir()
    (site / "sitecustomize.py").write_text(_SITE.format(marker=marker, restarted=restarted))
    monkeypatch.setenv("PYTHONPATH", os.pathsep.join([str(site), str(ROOT)]))
    theirs = tmp_path / "theirs"
    theirs.mkdir()
    with LocalCluster(n_workers=1, threads_per_worker=1, processes=True, host="127.0.0.1",
                      dashboard_address=None, local_directory=str(theirs),
                      scheduler_kwargs=LOCAL_SCHEDULER_HTTP) as own, \
            Client(own) as client:
        (first,) = client.run(os.getpid).values()
        Path(marker).write_text(str(first))
        with dask.config.set({"distributed.comm.timeouts.connect": "5s"}):
            out = dict(dispatch(_task, [0, 1], ["a", "b"], scheduler=None, n_local=1,
                                failed=lambda k, why: {"ok": False, "error": why}))
        assert os.path.exists(marker + ".taken"), "no worker of ours hung"
        assert out == {0: {"ok": True, "t": "a"}, 1: {"ok": True, "t": "b"}}, out  # 2nd start
        again = int(Path(restarted).read_text())
        assert not alive(first)
        assert alive(again), "the caller's worker, started again by its nanny, was killed"
        client.wait_for_workers(1, timeout=60)
        assert list(client.run(os.getpid).values()) == [again]
