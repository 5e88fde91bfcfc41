"""What a local Dask cluster leaves in its caller's process after a sweep (h124).

The cluster is started with SIGINT and SIGTERM held (``cluster._workers_hold_signals``), so
the threads it starts keep them blocked. After the sweep the process keeps Dask's one
offload thread (``Dask-Offload_0``, process-wide, created on its first use, signals blocked:
the signal goes to the main thread, as it should), on Python 3.13 also Dask's profiler thread
(``Profile``, process-wide, sometimes started only by the second sweep), and multiprocessing's
resource tracker; a second sweep adds no other thread, process or descriptor, and Ctrl-C
(SIGINT) still raises KeyboardInterrupt in the main thread, in a blocking call. Just as a
sweep returns, Dask's thread that joins a worker process may still be there: it ends a moment
later (in 1 of 4 sweeps: 3 threads and 9 descriptors just after, 2 and 7 a second later)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

SCRIPT = '''\
import json, os, signal, threading, time

from bomgraph.cluster import dispatch


def task(k, t):
    return k, {"ok": True}


def held():
    out = []
    for tid in os.listdir("/proc/self/task"):
        with open(f"/proc/self/task/{tid}/status") as fh:
            mask = int(next(l for l in fh if l.startswith("SigBlk")).split()[1], 16)
        out.append(bool(mask & (1 << (signal.SIGINT - 1))))
    return out


def state():
    for _ in range(100):  # Dask's thread joining a worker process that is ending, and a
        tids = os.listdir("/proc/self/task")  # joined thread, end a moment after the sweep
        if len(tids) <= threading.active_count() and not any(
                "watch process join" in t.name for t in threading.enumerate()):
            break
        time.sleep(0.05)
    kids = sum(len(open(f"/proc/self/task/{t}/children").read().split()) for t in tids)
    return {"threads": len(tids), "children": kids, "fds": len(os.listdir("/proc/self/fd")),
            "main_held": held()[tids.index(str(os.getpid()))],
            "names": sorted(t.name for t in threading.enumerate())}


if __name__ == "__main__":
    # Python keeps SIGINT ignored when it started so (a job run in the background by a shell
    # without job control, as .ci/run runs pytest): Ctrl-C's handler, as in a terminal
    signal.signal(signal.SIGINT, signal.default_int_handler)
    seen = [state()]
    for _ in range(2):
        out = list(dispatch(task, [0, 1], ["a", "b"], scheduler=None, n_local=1,
                            failed=lambda k, why: {"ok": False, "error": why}))
        assert sorted(k for k, _ in out) == [0, 1], out
        seen.append(state())
    threading.Timer(0.2, os.kill, (os.getpid(), signal.SIGINT)).start()
    try:
        time.sleep(60)
        seen.append("no KeyboardInterrupt")
    except KeyboardInterrupt:
        seen.append("KeyboardInterrupt")
    print(json.dumps(seen))
'''


def test_a_second_sweep_leaks_nothing_and_ctrl_c_still_works(tmp_path: Path) -> None:
    script = tmp_path / "after.py"
    script.write_text(SCRIPT)
    proc = subprocess.run([sys.executable, str(script)], cwd=tmp_path, capture_output=True,
                          text=True, timeout=300, env={**os.environ, "OMP_NUM_THREADS": "1"})
    assert proc.returncode == 0, proc.stderr[-3000:]
    before, first, second, ctrl_c = json.loads(proc.stdout.strip().splitlines()[-1])
    assert ctrl_c == "KeyboardInterrupt"
    assert not before["main_held"] and not first["main_held"] and not second["main_held"]
    # Dask's process-wide threads, each started once per process: the offload thread, and
    # (seen with Python 3.13 in CI) its profiler's, which may start after either sweep
    once = {"Dask-Offload_0", "Profile"}
    for after in (first, second):
        assert set(after["names"]) - once == {"MainThread"}, (before, after)
        assert after["threads"] <= before["threads"] + len(once), (before, after)
        assert after["children"] <= before["children"] + 1, (before, after)  # resource tracker
    assert second["children"] == first["children"], (first, second)
    assert second["fds"] <= first["fds"], (first, second)
