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
from pathlib import Path

import numpy as np
from _plugin_dist import write_dist_info
from hostile_helpers import ENV, no_traceback

from bomgraph.bench import strip_timings
from bomgraph.sim import SimConfig, simulate
from bomgraph.stream_file import write_stream

DYING = '''\
import os
import numpy as np
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


def test_a_dying_worker_fails_its_run_and_the_sweep_goes_on(tmp_path: Path) -> None:
    (tmp_path / "site" / "dyingplugin").mkdir(parents=True)
    (tmp_path / "site" / "dyingplugin" / "__init__.py").write_text(DYING)
    write_dist_info(tmp_path / "site", "dyingplugin", {"dying": "dyingplugin:Dying"})
    streams = []
    for seed in range(3):
        streams.append(tmp_path / f"s{seed}.jsonl")
        write_stream(simulate(SimConfig(n_steps=40), np.random.default_rng(seed)), streams[-1])

    proc, results = _compare(tmp_path, "par", "dying,triangulate,ekf", "2", streams)
    err = no_traceback(proc)
    assert proc.returncode == 1, err     # runs failed: 1, as for a method that raises
    assert "3 of 9 runs failed" in err and "WorkerDied" in err, err
    assert len(results) == 9
    dying = [r for r in results if r["arm"] == "dying"]
    assert len(dying) == 3 and not any(r["ok"] for r in dying)
    assert all(r["error"].startswith("WorkerDied:") and "EXIT(7)" in r["error"] for r in dying)
    # every other run has the result it has on its own, in this process, one at a time
    _, serial = _compare(tmp_path, "ser", "triangulate,ekf", "1", streams)
    mine = {(r["arm"], r["run"]): r for r in strip_timings(results) if r["arm"] != "dying"}
    alone = {(r["arm"], r["run"]): r for r in strip_timings(serial)}
    assert mine.keys() == alone.keys() and len(alone) == 6
    assert all(r["ok"] for r in mine.values())
    for k in alone:
        assert mine[k]["checkpoints"] == alone[k]["checkpoints"], k
