"""The local workers of a dispatch whose process is killed (``kill -9`` of ``compare --jobs
2``) end at once. Before (h43), nothing ended them: they hold SIGINT and SIGTERM by design,
so they finished the task they were running, re-parented to pid 1, and then waited out
joblib's idle timeout, five minutes and more of memory (and of CPU while in a task) nobody
asked for. Each worker now watches that the process that started it is still its parent
(:func:`bomgraph.processes._watch_parent`), busy in a task or idle between sweeps; started by
the parent's main thread, as here, Linux also kills it when that thread ends, which ends a
worker in a native call that holds the GIL (the watching thread cannot run then).

The bound below is on liveness (that they end), not on speed: they end in about half a
second, and lived over 300 s before."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from hostile_helpers import ENV

pytestmark = pytest.mark.skipif(not os.path.isdir("/proc/self"), reason="needs Linux /proc")

#: Two workers, two tasks; each task writes its worker's pid and waits for the other's (so
#: they ran in two workers), then sleeps (busy), runs a regular expression that holds the GIL
#: for hours (native: as GTSAM holds it through an optimisation), or returns (idle: the
#: workers are kept, and this process sleeps beside them), until the test kills this process.
SCRIPT = '''\
import os, re, sys, time
from bomgraph.processes import dispatch

def task(k, arg):
    folder, state = arg
    with open(os.path.join(folder, f"tmp{k}"), "w") as fh:
        fh.write(str(os.getpid()))
    os.replace(os.path.join(folder, f"tmp{k}"), os.path.join(folder, f"pid{k}"))
    while not os.path.exists(os.path.join(folder, f"pid{1 - k}")):
        time.sleep(0.05)
    while state == "busy":
        time.sleep(1)
    if state == "native":
        re.match(r"(a+)+$", "a" * 45 + "b")
    return k, {}

folder, state = sys.argv[1], sys.argv[2]
for _ in dispatch(task, [0, 1], [(folder, state)] * 2, 2, lambda k, why: {"failed": why}):
    pass
open(os.path.join(folder, "idle"), "w").close()
time.sleep(3600)
'''

#: A bound on how long the test waits for the workers to end (they take under a second).
WAIT_S = 30


def _start_time(pid: int) -> str | None:
    """The process ``pid``'s start time (its identity with the pid), or None when it is gone
    or a zombie (ended; its new parent has not reaped it yet)."""
    try:
        with open(f"/proc/{pid}/stat", encoding="ascii") as fh:
            fields = fh.read().rsplit(")", 1)[1].split()
    except OSError:
        return None
    return None if fields[0] == "Z" else fields[19]


def _wait_for(path: Path, proc: subprocess.Popen) -> None:
    deadline = time.monotonic() + 120
    while not path.exists():
        assert proc.poll() is None, (path.parent / "output").read_text()
        assert time.monotonic() < deadline, f"no {path.name} in 120 s"
        time.sleep(0.05)


@pytest.mark.parametrize("state", ["busy", "native", "idle"])
def test_workers_end_when_the_process_that_started_them_is_killed(tmp_path: Path,
                                                                   state: str) -> None:
    # output to a file: the workers inherit it, and a pipe would stay open while they live
    with open(tmp_path / "output", "wb") as out:
        # TMPDIR: the folder of the dispatch's marks that the kill leaves (bomgraph-running-*,
        # removed by a later dispatch) is this test's, not the session's $TMPDIR
        proc = subprocess.Popen([sys.executable, "-c", SCRIPT, str(tmp_path), state],
                                env={**ENV, "TMPDIR": str(tmp_path)}, stdout=out,
                                stderr=subprocess.STDOUT)
    workers: dict[int, str | None] = {}
    try:
        for k in (0, 1):
            _wait_for(tmp_path / f"pid{k}", proc)
            pid = int((tmp_path / f"pid{k}").read_text())
            workers[pid] = _start_time(pid)
        if state == "idle":
            _wait_for(tmp_path / "idle", proc)
        assert len(workers) == 2 and proc.pid not in workers, workers
        assert all(workers.values()), workers  # both alive, in a task or idle
        proc.kill()
        proc.wait()
        deadline = time.monotonic() + WAIT_S
        left = dict(workers)
        while left and time.monotonic() < deadline:
            left = {p: t for p, t in left.items() if _start_time(p) == t}
            time.sleep(0.1)
        assert not left, f"workers {sorted(left)} still alive {WAIT_S} s after their parent"
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
        for pid, started in workers.items():  # a failed test leaves no orphans behind
            if started is not None and _start_time(pid) == started:
                os.kill(pid, signal.SIGKILL)
