"""A local Dask cluster whose workers die as they start fails the runs in one line (h124).

A worker killed while ``compare --dask-local N`` started its cluster (or ended by a
sitecustomize, a memory limit) was Dask's ``RuntimeError: Nanny failed to start.`` traceback
out of ``compare``, 30 lines on stderr. Now every run fails with the reason, as when
``--jobs N``'s workers cannot start, and the command says so in its one line (exit 1)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def test_workers_that_die_as_the_local_cluster_starts_fail_the_runs(tmp_path: Path) -> None:
    site = tmp_path / "site"
    site.mkdir()
    (site / "sitecustomize.py").write_text(textwrap.dedent("""\
        import os, sys
        if "--multiprocessing-fork" in sys.orig_argv:  # a worker of the local cluster
            os._exit(9)
        """))
    temp = tmp_path / "tmp"
    temp.mkdir()
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(site), str(ROOT)]),
           "OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1", "TMPDIR": str(temp)}
    out = tmp_path / "out"
    proc = subprocess.run([sys.executable, "-m", "bomgraph", "compare", "--quick",
                           "--experiments", "exp1", "--dask-local", "2", "--no-figures",
                           "--out", str(out)], env=env, cwd=tmp_path, capture_output=True,
                          text=True, timeout=300)
    assert "Traceback" not in proc.stderr, proc.stderr[-3000:]
    assert proc.returncode == 1, proc.stderr[-3000:]
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("bomgraph: error: "), proc.stderr
    results = json.loads((out / "results.json").read_text())
    runs = results["results"]
    assert runs and not any(r["ok"] for r in runs)
    assert all(r["error"].startswith("WorkerDied: the local Dask cluster's workers could not "
                                     "start") for r in runs), runs[0]["error"]
    assert sorted(p.name for p in temp.iterdir()) == []  # nor its scratch folder left
