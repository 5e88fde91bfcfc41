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


def test_a_worker_that_dies_once_as_the_cluster_starts_is_tried_again(
        tmp_path: Path, monkeypatch) -> None:
    """One worker of two killed once as the cluster started (the out-of-memory killer, a kill)
    failed all 16 runs of ``compare --quick --experiments exp1 --dask-local 2`` with "the
    local Dask cluster's workers could not start", where ``--jobs 2`` tries a pool whose
    workers died before any task once more and ran all 16 (h130). Now the cluster is started
    once more too; only twice in a row fails the runs."""
    from bomgraph.cluster import dispatch

    site = tmp_path / "site"
    site.mkdir()
    once = tmp_path / "killed-one"
    (site / "sitecustomize.py").write_text(textwrap.dedent(f"""\
        import os, sys
        if "--multiprocessing-fork" in sys.orig_argv:  # a worker of the local cluster
            try:
                os.close(os.open({str(once)!r}, os.O_CREAT | os.O_EXCL | os.O_WRONLY))
            except FileExistsError:
                pass
            else:
                os._exit(9)  # the first worker only
        """))
    monkeypatch.setenv("PYTHONPATH", os.pathsep.join([str(site), str(ROOT)]))
    out = dict(dispatch(_task, [0, 1, 2], ["a", "b", "c"], scheduler=None, n_local=2,
                        failed=lambda k, why: {"ok": False, "error": why}))
    assert once.exists()  # a worker did die
    assert out == {0: {"ok": True, "t": "a"}, 1: {"ok": True, "t": "b"},
                   2: {"ok": True, "t": "c"}}, out


def _task(k: int, t: str) -> tuple[int, dict]:
    return k, {"ok": True, "t": t}
